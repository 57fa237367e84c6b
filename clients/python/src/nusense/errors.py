"""The exceptions the client raises: every one is a :class:`NusenseError`."""

from __future__ import annotations


class NusenseError(Exception):
    """Base class of every error this package raises."""


class DaemonError(NusenseError):
    """The daemon refused a request (an invalid LED setting, no board...): ``message`` is the daemon's own words,
    the same the HTTP API gives for that request."""

    def __init__(self, message: str, *, serial: str, key: str) -> None:
        super().__init__(f"{serial}: {message}")
        self.message = message
        self.serial = serial
        self.key = key


class NoReplyError(NusenseError, TimeoutError):
    """Nothing answered a request in time: no daemon serves that sensor on the network this client reaches."""

    def __init__(self, serial: str, key: str, timeout: float) -> None:
        super().__init__(f"no reply from sensor {serial!r} on {key} within {timeout:g} s")
        self.serial = serial
        self.key = key
        self.timeout = timeout


class ProtocolError(NusenseError):
    """A message from the daemon is not what this client understands: not JSON, another ``schema_version``, or a
    field missing or of the wrong type (``path`` says which)."""
