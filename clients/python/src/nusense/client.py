"""The client: sensors on the network, their readings, status, LEDs and tare, over Zenoh.

Every sensor a daemon serves lives under ``nusense/<serial>/``: a liveliness token ``alive`` while it is served,
publications ``reading`` per processed frame, queryables ``status``, ``led``, ``tare`` and ``frame``.
"""

from __future__ import annotations

import json
import queue
import re
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Generic, TypeVar

import zenoh

from .errors import DaemonError, NoReplyError, ProtocolError
from .reading import Contacts, Reading, decode_contacts, decode_reading
from .status import Status, decode_status

#: Where every key of every sensor lives.
ROOT = "nusense"


#: Where ``nusense serve --zenoh`` listens when given no endpoint.
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"

# The daemon's rule for serials that name keys: ASCII letters, digits, '-', '_' and '.', at least one alphanumeric.
_SERIAL = re.compile(r"(?=.*[A-Za-z0-9])[A-Za-z0-9._-]+", re.ASCII)


def key(serial: str, leaf: str) -> str:
    """The Zenoh key of one sensor's ``leaf`` (``reading``, ``status``, ``led``...)."""
    if not _SERIAL.fullmatch(serial):
        raise ValueError(f"{serial!r} is not a sensor serial (ASCII letters, digits, '-', '_' and '.')")
    return f"{ROOT}/{serial}/{leaf}"


def serial_of(key_expr: str) -> str:
    """The serial in a key ``nusense/<serial>/...``."""
    parts = str(key_expr).split("/")
    if len(parts) < 3 or parts[0] != ROOT:
        raise ProtocolError(f"{key_expr}: not a nusense key")
    return parts[1]


def config(connect: Sequence[str] = (), *, listen: Sequence[str] = (), scouting: bool = False) -> zenoh.Config:
    """A peer's Zenoh configuration: ``connect`` to these endpoints (``tcp/HOST:PORT``, e.g. a daemon or a router),
    ``listen`` on these, and with ``scouting`` find other peers by multicast."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(scouting))
    return conf


@dataclass(frozen=True)
class SensorEvent:
    """A sensor appeared (``alive``) or disappeared from the network."""

    serial: str
    alive: bool


_T = TypeVar("_T")


class _Inbox(Generic[_T]):
    """What a Zenoh callback hands to the user's thread: a bounded queue that drops the oldest item when the user
    falls behind (counting them in ``dropped``), read by ``get`` or by iteration, closed by ``close``."""

    def __init__(self, capacity: int) -> None:
        self._queue: queue.Queue[_T | None] = queue.Queue(capacity)
        self._lock = threading.Lock()
        self._closed = False
        self.dropped = 0

    def put(self, item: _T | None) -> None:
        with self._lock:
            while True:
                try:
                    self._queue.put_nowait(item)
                    return
                except queue.Full:
                    try:
                        self._queue.get_nowait()
                        self.dropped += 1
                    except queue.Empty:
                        pass

    def get(self, timeout: float | None) -> _T:
        if self._closed and self._queue.empty():
            raise StopIteration
        try:
            item = self._queue.get(timeout=timeout)
        except queue.Empty:
            raise TimeoutError(f"nothing arrived within {timeout:g} s") from None
        if item is None:
            self._closed = True
            raise StopIteration
        return item

    def close(self) -> None:
        if not self._closed:
            self.put(None)


class Stream(Generic[_T]):
    """Messages of one or several sensors as they arrive, oldest first (:meth:`Client.readings` gives
    :class:`Reading`\s, :meth:`Client.contacts` :class:`Contacts`): iterate over it (blocks until the next message;
    ends when the stream is closed) or call :meth:`get` with a timeout. Holds at most ``capacity`` messages; when the
    reader falls behind, the oldest are dropped and counted in :attr:`dropped`."""

    def __init__(
        self, session: zenoh.Session, keys: Sequence[str], decode: Callable[[bytes, str], _T], capacity: int
    ) -> None:
        self._decode = decode
        self._inbox: _Inbox[tuple[str, bytes]] = _Inbox(capacity)
        self._subscribers = [session.declare_subscriber(k, self._on_sample) for k in keys]

    def _on_sample(self, sample: zenoh.Sample) -> None:
        # Decoding waits for the reader's thread: Zenoh's own threads only copy the bytes.
        self._inbox.put((str(sample.key_expr), sample.payload.to_bytes()))

    @property
    def dropped(self) -> int:
        """Messages dropped because the reader fell behind."""
        return self._inbox.dropped

    def get(self, timeout: float | None = None) -> _T:
        """The next message; :class:`TimeoutError` when none arrives within ``timeout`` seconds,
        :class:`ProtocolError` when one does not decode (the stream goes on with the next)."""
        try:
            key_expr, payload = self._inbox.get(timeout)
        except StopIteration:
            raise RuntimeError("the stream is closed") from None
        return self._decode(payload, serial_of(key_expr))

    def __iter__(self) -> Iterator[_T]:
        while True:
            try:
                key_expr, payload = self._inbox.get(None)
            except StopIteration:
                return
            yield self._decode(payload, serial_of(key_expr))

    def close(self) -> None:
        """Stops receiving; iteration ends after the messages already received."""
        for subscriber in self._subscribers:
            subscriber.undeclare()
        self._subscribers = []
        self._inbox.close()

    def __enter__(self) -> Stream[_T]:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


class SensorWatch:
    """Sensors coming and going, starting with those already there (each reported once as alive): iterate over it,
    call :meth:`get` with a timeout, or give :meth:`Client.watch_sensors` a callback."""

    def __init__(
        self, session: zenoh.Session, callback: Callable[[SensorEvent], None] | None, capacity: int = 1024
    ) -> None:
        self._inbox: _Inbox[SensorEvent] = _Inbox(capacity)
        self._callback = callback if callback is not None else self._inbox.put
        self._subscriber = session.liveliness().declare_subscriber(
            f"{ROOT}/*/alive", self._on_sample, history=True
        )

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self._callback(SensorEvent(serial_of(str(sample.key_expr)), sample.kind == zenoh.SampleKind.PUT))

    def get(self, timeout: float | None = None) -> SensorEvent:
        """The next event; :class:`TimeoutError` when none comes within ``timeout`` seconds."""
        try:
            return self._inbox.get(timeout)
        except StopIteration:
            raise RuntimeError("the sensor watch is closed") from None

    def __iter__(self) -> Iterator[SensorEvent]:
        while True:
            try:
                yield self._inbox.get(None)
            except StopIteration:
                return

    def close(self) -> None:
        self._subscriber.undeclare()
        self._inbox.close()

    def __enter__(self) -> SensorWatch:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


class Client:
    """A Zenoh session that talks to nusense daemons. Open one with :func:`nusense.connect` (or wrap a session of
    your own); close it with :meth:`close` or a ``with`` block."""

    def __init__(self, session: zenoh.Session, *, close_session: bool = False) -> None:
        self.session = session
        self._close_session = close_session

    def sensors(self, timeout: float = 1.0) -> list[str]:
        """Serials of the sensors served on the network now, sorted; waits up to ``timeout`` seconds for answers."""
        replies = self.session.liveliness().get(f"{ROOT}/*/alive", timeout=timeout)
        return sorted({serial_of(str(r.ok.key_expr)) for r in replies if r.ok is not None})

    def watch_sensors(self, callback: Callable[[SensorEvent], None] | None = None) -> SensorWatch:
        """Sensors coming and going: each event goes to ``callback`` (on a Zenoh thread: keep it short), or, without
        one, into the returned watch to iterate over. Close the watch to stop."""
        return SensorWatch(self.session, callback)

    def readings(self, serials: str | Iterable[str] | None = None, *, capacity: int = 256) -> Stream[Reading]:
        """Streams the readings of one sensor, several, or (``None``) every sensor on the network."""
        return Stream(self.session, _keys(serials, "reading"), decode_reading, capacity)

    def contacts(self, serials: str | Iterable[str] | None = None, *, capacity: int = 256) -> Stream[Contacts]:
        """Streams only the contacts of every processed frame (a much smaller message than the reading)."""
        return Stream(self.session, _keys(serials, "contacts"), decode_contacts, capacity)

    def status(self, serial: str, timeout: float = 2.0) -> Status:
        return decode_status(self._query(serial, "status", None, timeout), serial)

    def set_leds(
        self,
        serial: str,
        *,
        top: int | None = None,
        right: int | None = None,
        bottom: int | None = None,
        left: int | None = None,
        all: int | None = None,  # noqa: A002 - the daemon's own name for it
        enabled: bool | None = None,
        timeout: float = 2.0,
    ) -> dict[str, Any]:
        """Sets LED currents in mA (per side, or ``all``) and/or switches the addressed strings on or off; returns
        the board's status as the daemon answers it. The daemon validates the request as its HTTP API does
        (currents above the board's limit, ``all`` with per-side currents, nothing to set): a refusal raises
        :class:`DaemonError` with its message."""
        body = {
            name: value
            for name, value in (
                ("top", top),
                ("right", right),
                ("bottom", bottom),
                ("left", left),
                ("all", all),
                ("enabled", enabled),
            )
            if value is not None
        }
        return self._query_json(serial, "led", json.dumps(body).encode(), timeout)

    def tare(self, serial: str, timeout: float = 2.0) -> str:
        """Makes the sensor's next frame its rest frame; returns the daemon's words for it."""
        reply = self._query_json(serial, "tare", None, timeout)
        message = reply.get("tare")
        if not isinstance(message, str):
            raise ProtocolError(f"tare reply: expected a `tare` message, got {reply!r}")
        return message

    def frame(self, serial: str, timeout: float = 2.0) -> bytes:
        """The sensor's newest processed camera frame, as the camera's JPEG bytes."""
        return self._query(serial, "frame", None, timeout)

    def _query_json(self, serial: str, leaf: str, payload: bytes | None, timeout: float) -> dict[str, Any]:
        text = self._query(serial, leaf, payload, timeout)
        try:
            reply = json.loads(text)
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            raise ProtocolError(f"{key(serial, leaf)}: the reply is not JSON: {e}") from e
        if not isinstance(reply, dict):
            raise ProtocolError(f"{key(serial, leaf)}: expected a JSON object, got {reply!r}")
        return reply

    def _query(self, serial: str, leaf: str, payload: bytes | None, timeout: float) -> bytes:
        key_expr = key(serial, leaf)
        if payload is None:
            replies = self.session.get(key_expr, timeout=timeout)
        else:
            replies = self.session.get(key_expr, payload=payload, encoding="application/json", timeout=timeout)
        for reply in replies:
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
            if reply.err is not None:
                error = reply.err.payload.to_bytes()
                # Zenoh's own words when a queryable exists but has not answered in time (the daemon's are JSON).
                if error == b"Timeout":
                    break
                raise DaemonError(_error_message(error), serial=serial, key=key_expr)
        raise NoReplyError(serial, key_expr, timeout)

    def close(self) -> None:
        if self._close_session:
            self.session.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(
        self, _type: type[BaseException] | None, _value: BaseException | None, _traceback: TracebackType | None
    ) -> None:
        self.close()


def _keys(serials: str | Iterable[str] | None, leaf: str) -> list[str]:
    if serials is None:
        return [f"{ROOT}/*/{leaf}"]
    return [key(s, leaf) for s in ([serials] if isinstance(serials, str) else serials)]


def _error_message(payload: bytes) -> str:
    """The daemon's words in an error reply ``{"error": "..."}``; the text as it is when it is not that."""
    text = payload.decode("utf-8", errors="replace")
    try:
        message = json.loads(text)
    except json.JSONDecodeError:
        return text
    error = message.get("error") if isinstance(message, dict) else None
    return error if isinstance(error, str) else text


def connect(
    connect: Sequence[str] = (DEFAULT_ENDPOINT,),
    *,
    listen: Sequence[str] = (),
    scouting: bool = False,
    zenoh_config: zenoh.Config | None = None,
) -> Client:
    """Opens a Zenoh peer session and a :class:`Client` on it: ``connect`` to these endpoints (``tcp/HOST:PORT``: a
    daemon's or a router's; by default the daemon's own on this machine), and with ``scouting`` also find peers on
    the local networks by multicast. ``zenoh_config`` replaces all of that with a configuration of your own."""
    conf = zenoh_config if zenoh_config is not None else config(connect, listen=listen, scouting=scouting)
    return Client(zenoh.open(conf), close_session=True)
