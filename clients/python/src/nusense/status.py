"""A sensor's status: the daemon's status message (the same JSON as ``GET /api/v1/status``), its most used fields
typed and the whole message in ``raw``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from .errors import ProtocolError
from .reading import _versioned


@dataclass(frozen=True)
class Status:
    serial: str
    #: The daemon's version.
    version: str
    #: The sensor is the simulator.
    simulator: bool
    #: The estimator's variant: ``fast``, ``paper`` or ``inverse``.
    mode: str
    frames_captured: int
    frames_processed: int
    #: Capture to reading, ms: median and 99th percentile over the daemon's recent frames (``None`` before any).
    latency_p50_ms: float | None
    latency_p99_ms: float | None
    #: An LED board is connected (real or virtual).
    board_connected: bool
    #: What is wrong now, in words; empty when all is well.
    problems: tuple[str, ...]
    #: The whole status message, as JSON.
    raw: Mapping[str, Any]


def decode_status(payload: bytes | str, serial: str) -> Status:
    """A status message as a :class:`Status`; :class:`ProtocolError` when it is not one."""
    message = _versioned(payload, "status")
    pipeline = message.child("pipeline")
    latency = pipeline.child("latency_ms")
    samples = latency.integer("samples")
    problems = message.items("problems")
    if not all(isinstance(p, str) for p in problems):
        raise ProtocolError(f"status.problems: expected strings, got {problems!r}")
    return Status(
        serial=serial,
        version=message.text("version"),
        simulator=message.boolean("simulator"),
        mode=pipeline.text("mode"),
        frames_captured=pipeline.integer("frames_captured"),
        frames_processed=pipeline.integer("frames_processed"),
        latency_p50_ms=latency.number("p50") if samples else None,
        latency_p99_ms=latency.number("p99") if samples else None,
        board_connected=message.child("board").boolean("connected"),
        problems=tuple(problems),
        raw=message.value,
    )
