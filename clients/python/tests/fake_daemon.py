"""A stand-in for `nusense serve --zenoh` in the client's unit tests: a Zenoh peer of its own (listening on a
loopback port, no scouting) that announces sensors, publishes the readings a test gives it and answers status, LED,
tare and frame queries on the keys of docs/integrations/zenoh.md, recording what it was asked."""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field
from typing import Any

import zenoh

import nusense


def bound_endpoint(session: zenoh.Session) -> str:
    """The endpoint a session listening on ``tcp/127.0.0.1:0`` was given, from its own admin space (the Python API
    has no call for a session's locators): a port chosen free beforehand and passed on could be taken in between by
    another process, and the fake would fail to start."""
    key = f"@/{session.info.zid()}/peer"
    for reply in session.get(key, timeout=10.0):
        if reply.ok is not None:
            locators: list[str] = json.loads(reply.ok.payload.to_bytes())["locators"]
            return next(locator for locator in locators if locator.startswith("tcp/127.0.0.1:"))
    raise AssertionError(f"no answer from the session's admin space at {key}")


@dataclass
class FakeSensor:
    serial: str
    status_json: bytes
    frame_jpeg: bytes = b"\xff\xd8fake jpeg\xff\xd9"
    #: What the led queryable received, one decoded JSON body per query.
    led_requests: list[Any] = field(default_factory=list)
    tares: int = 0
    #: When set, the led queryable answers with this error message (as the daemon does for an invalid request).
    led_error: str | None = None
    #: When set, tare queries are held and never answered (a daemon too busy to answer in time).
    tare_silent: bool = False
    held_queries: list[Any] = field(default_factory=list)
    handles: list[Any] = field(default_factory=list)


class FakeDaemon:
    def __init__(self) -> None:
        config = nusense.config(listen=["tcp/127.0.0.1:0"], scouting=False)
        config.insert_json5("adminspace/enabled", "true")
        self.session = zenoh.open(config)
        self.endpoint = bound_endpoint(self.session)
        self.sensors: dict[str, FakeSensor] = {}
        self._lock = threading.Lock()

    def add_sensor(self, serial: str, status_json: bytes) -> FakeSensor:
        sensor = FakeSensor(serial, status_json)
        base = f"nusense/{serial}"
        sensor.handles = [
            self.session.declare_queryable(f"{base}/frame", lambda q: q.reply(q.key_expr, sensor.frame_jpeg)),
            self.session.declare_queryable(f"{base}/led", lambda q: self._led(sensor, q)),
            self.session.declare_queryable(f"{base}/tare", lambda q: self._tare(sensor, q)),
            # Declared after the others, which reach a client first: a sensor that answers status answers all.
            self.session.declare_queryable(f"{base}/status", lambda q: q.reply(q.key_expr, sensor.status_json)),
            self.session.liveliness().declare_token(f"{base}/alive"),
        ]
        self.sensors[serial] = sensor
        return sensor

    def remove_sensor(self, serial: str) -> None:
        sensor = self.sensors.pop(serial)
        for query in sensor.held_queries:
            query.drop()
        for handle in sensor.handles:
            handle.undeclare()

    def publish_reading(self, serial: str, payload: bytes) -> None:
        self.session.put(f"nusense/{serial}/reading", payload, encoding="application/json")

    def _led(self, sensor: FakeSensor, query: zenoh.Query) -> None:
        body = json.loads(query.payload.to_bytes()) if query.payload is not None else None
        with self._lock:
            sensor.led_requests.append(body)
        if sensor.led_error is not None:
            query.reply_err(json.dumps({"error": sensor.led_error}), encoding="application/json")
        else:
            query.reply(query.key_expr, json.dumps({"schema_version": 1, "board": {"connected": True}}))

    def _tare(self, sensor: FakeSensor, query: zenoh.Query) -> None:
        with self._lock:
            sensor.tares += 1
        if sensor.tare_silent:
            sensor.held_queries.append(query)
            return
        reply = {"schema_version": 1, "tare": "the next frame becomes the rest frame"}
        query.reply(query.key_expr, json.dumps(reply))

    def close(self) -> None:
        for serial in list(self.sensors):
            self.remove_sensor(serial)
        self.session.close()
