"""The reading message as typed objects: what the daemon publishes for every processed frame.

The JSON this decodes is the daemon's one reading message (``host/daemon/schema/reading.schema.json`` in the
repository; the estimate's fields are those of ``nusense analyze --json``). Points are numpy arrays in the units
their names say (``_px`` raw image pixels, ``_mm`` pad millimetres, ``_n`` newtons); a value the daemon did not
have (a corner missing from a frame) is NaN in an array, ``None`` elsewhere. Arrays are read-only. Keys this
client does not know are ignored, as the daemon's schema asks of clients.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Literal, Mapping

import numpy as np
import numpy.typing as npt

from .errors import ProtocolError

#: The ``schema_version`` of the messages this client reads.
SCHEMA_VERSION = 1

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

Mode = Literal["fast", "paper", "inverse"]


@dataclass(frozen=True, eq=False)
class Contact:
    """One contact region."""

    #: The pattern's point under the contact's centre, raw px of this frame, [x, y].
    centre_px: FloatArray
    centre_undistorted_px: FloatArray
    #: The centre on the pad, mm, [x, y] (x right, y down as seen in the raw image).
    centre_mm: FloatArray
    #: Normal force, N.
    force_n: float
    #: [fx, fy, fz], N, pad frame; ``None`` in modes without the traction inverse.
    force_vector_n: FloatArray | None
    #: Moment about the pad normal through the centre, N mm; traction inverse only.
    torque_nmm: float | None
    #: Area that carries the load, mm^2; traction inverse only.
    area_mm2: float | None


@dataclass(frozen=True, eq=False)
class ShearField:
    """Every lattice corner's motion, one row per corner (165 on the NUSense pad)."""

    #: [row, col] of each corner in the pattern's lattice, shape (n, 2).
    index: IntArray
    #: The corner in the rest frame, raw px, shape (n, 2); NaN where that frame missed it.
    reference_px: FloatArray
    #: The corner in this frame, raw px, shape (n, 2); NaN where this frame missed it.
    current_px: FloatArray
    #: The pad's own motion at the corner since the rest frame, camera motion removed, mm, shape (n, 2); NaN where
    #: either frame missed the corner.
    displacement_mm: FloatArray
    #: Seen in both frames with a plausible motion, shape (n,).
    valid: BoolArray

    def __len__(self) -> int:
        return len(self.valid)


@dataclass(frozen=True, eq=False)
class PressureMap:
    """The pressure over the pad on a grid of the pattern's cells (traction inverse only)."""

    #: Centre of the first cell (top-left as the camera sees it), mm, [x, y].
    origin_mm: FloatArray
    #: Cell pitch along x and y, mm.
    step_mm: FloatArray
    #: Pressure, kPa, shape (rows, cols): ``kpa[r, c]`` is the cell centred at ``origin_mm + step_mm * [c, r]``.
    kpa: FloatArray

    @property
    def x_mm(self) -> FloatArray:
        """The cells' centres along x, mm, shape (cols,)."""
        return _frozen(self.origin_mm[0] + self.step_mm[0] * np.arange(self.kpa.shape[1]))

    @property
    def y_mm(self) -> FloatArray:
        """The cells' centres along y, mm, shape (rows,)."""
        return _frozen(self.origin_mm[1] + self.step_mm[1] * np.arange(self.kpa.shape[0]))


@dataclass(frozen=True, eq=False)
class CameraMotion:
    """How the camera (or the whole pad) moved between the rest frame and this frame."""

    #: Rotation of the pattern in the image, degrees from +x towards +y.
    rotation_deg: float
    #: Motion of the pad centre's image, raw px, [dx, dy].
    shift_px: FloatArray
    #: Apparent size now / at rest.
    scale: float


@dataclass(frozen=True)
class ContactTest:
    """The contact decision and what it rests on."""

    statistic: float
    threshold: float
    p_value: float
    #: This frame's corner noise, mm (1 sigma per axis).
    noise_mm: float
    #: Smallest normal force at the pad's centre the test detects at this noise, N.
    detection_floor_n: float


@dataclass(frozen=True)
class LatticeCounts:
    """What the lattice detection found and used."""

    points_detected: int
    points_expected: int
    squares_detected: int
    squares_expected: int
    #: Corners seen in both frames with a plausible motion.
    points_valid: int
    #: Corners seen in both frames but masked as implausible.
    points_implausible: int


@dataclass(frozen=True, eq=False)
class Estimate:
    """The estimator's measurement of one frame."""

    mode: Mode
    #: Something touches the pad (above the detection floor).
    contact: bool
    #: Total normal force, N: 0 without contact.
    force_n: float
    #: Total [fx, fy, fz], N; ``None`` without contact or without the traction inverse.
    force_vector_n: FloatArray | None
    #: Total moment about the pad normal, N mm; ``None`` without contact or without the traction inverse.
    torque_nmm: float | None
    #: Every contact, strongest first; empty without contact.
    contacts: tuple[Contact, ...]
    #: The strongest contact's centre, raw px; ``None`` without contact.
    contact_px: FloatArray | None
    contact_undistorted_px: FloatArray | None
    contact_mm: FloatArray | None
    #: Direction of an elongated contact, degrees in [0, 180); ``None`` for a round one or without contact.
    edge_angle_deg: float | None
    edge_confidence: float
    #: The paper's shear measure with the camera's motion removed, and as published.
    gamma: float
    gamma_uncompensated: float
    #: The calibration line a * gamma + b, N, whether or not there is contact.
    force_model_n: float
    camera_motion: CameraMotion
    contact_test: ContactTest
    pressure_map: PressureMap | None
    counts: LatticeCounts
    samples_used: int
    samples_total: int
    contact_score_mm: float
    recovered: bool
    retared: bool
    retare_count: int
    shear_field: ShearField
    elapsed_ms: float

    @property
    def contact_centres_mm(self) -> FloatArray:
        """Every contact's centre, mm, shape (contacts, 2), strongest first."""
        return _centres_mm(self.contacts)

    @property
    def contact_forces_n(self) -> FloatArray:
        """Every contact's normal force, N, shape (contacts,), strongest first."""
        return _forces_n(self.contacts)


@dataclass(frozen=True, eq=False)
class LedState:
    """The LED board's state when the reading was made; one entry per string: top, right, bottom, left."""

    setpoint_ma: IntArray
    measured_ma: FloatArray
    enabled: BoolArray
    #: What the board reports wrong with each string (``open_string``, ``over_current``...); empty when healthy.
    faults: tuple[tuple[str, ...], ...]
    any_fault: bool
    temperature_c: float
    supply_mv: int


@dataclass(frozen=True, eq=False)
class Reading:
    """One frame, measured: the daemon's reading message."""

    #: The sensor that published it (``None`` when decoded from JSON alone).
    serial: str | None
    schema_version: int
    #: Frames counted from 0 since the daemon's source started.
    frame_id: int
    #: When the frame was captured, microseconds since the Unix epoch.
    capture_time_us: int
    #: When the reading was ready, microseconds since the Unix epoch.
    processed_time_us: int
    #: Capture to reading, decoding and estimation included, ms.
    latency_ms: float
    #: Time the frame waited for the estimator, ms.
    queue_ms: float
    #: The rest frame the estimate is measured against.
    reference_frame_id: int | None
    #: ``None`` when the frame could not be measured: ``error`` says why.
    estimate: Estimate | None
    error: str | None
    #: ``None`` without an LED board.
    led: LedState | None
    #: The image file the frame came from (``nusense analyze``); ``None`` from a live daemon.
    file: str | None


@dataclass(frozen=True, eq=False)
class Contacts:
    """One processed frame's contacts alone (the daemon's ``contacts`` message): empty without contact."""

    serial: str | None
    schema_version: int
    frame_id: int
    capture_time_us: int
    #: Strongest first.
    contacts: tuple[Contact, ...]

    @property
    def centres_mm(self) -> FloatArray:
        """Every contact's centre, mm, shape (contacts, 2), strongest first."""
        return _centres_mm(self.contacts)

    @property
    def forces_n(self) -> FloatArray:
        """Every contact's normal force, N, shape (contacts,), strongest first."""
        return _forces_n(self.contacts)


def decode_contacts(payload: bytes | str, serial: str | None = None) -> Contacts:
    """A contacts message as :class:`Contacts`; :class:`ProtocolError` when it is not one."""
    message = _versioned(payload, "contacts")
    return Contacts(
        serial=serial,
        schema_version=SCHEMA_VERSION,
        frame_id=message.integer("frame_id"),
        capture_time_us=message.integer("capture_time_us"),
        contacts=tuple(_contact(c) for c in message.children("contacts")),
    )


def decode_reading(payload: bytes | str, serial: str | None = None) -> Reading:
    """A reading message (JSON bytes or text) as a :class:`Reading`; :class:`ProtocolError` when it is not one."""
    message = _versioned(payload, "reading")
    estimate = message.optional("estimate")
    led = message.optional("led")
    return Reading(
        serial=serial,
        schema_version=SCHEMA_VERSION,
        frame_id=message.integer("frame_id"),
        capture_time_us=message.integer("capture_time_us"),
        processed_time_us=message.integer("processed_time_us"),
        latency_ms=message.number("latency_ms"),
        queue_ms=message.number("queue_ms"),
        reference_frame_id=message.optional_int("reference_frame_id"),
        estimate=None if estimate is None else _estimate(message.child("estimate")),
        error=message.optional_str("error"),
        led=None if led is None else _led(message.child("led")),
        file=message.optional_str("file"),
    )


def _estimate(e: _Object) -> Estimate:
    mode = e.text("mode")
    if mode not in ("fast", "paper", "inverse"):
        raise ProtocolError(f"{e.path}.mode: unknown mode {mode!r}")
    motion = e.child("camera_motion")
    test = e.child("contact_test")
    pressure = e.optional("pressure_map")
    return Estimate(
        mode=mode,  # type: ignore[arg-type]  # checked against Mode just above
        contact=e.boolean("contact"),
        force_n=e.number("force_n"),
        force_vector_n=e.optional_array("force_vector_n", 3),
        torque_nmm=e.optional_float("torque_nmm"),
        contacts=tuple(_contact(c) for c in e.children("contacts")),
        contact_px=e.optional_array("contact_px", 2),
        contact_undistorted_px=e.optional_array("contact_undistorted_px", 2),
        contact_mm=e.optional_array("contact_mm", 2),
        edge_angle_deg=e.optional_float("edge_angle_deg"),
        edge_confidence=e.number("edge_confidence"),
        gamma=e.number("gamma"),
        gamma_uncompensated=e.number("gamma_uncompensated"),
        force_model_n=e.number("force_model_n"),
        camera_motion=CameraMotion(
            rotation_deg=motion.number("rotation_deg"),
            shift_px=motion.array("shift_px", 2),
            scale=motion.number("scale"),
        ),
        contact_test=ContactTest(
            statistic=test.number("statistic"),
            threshold=test.number("threshold"),
            p_value=test.number("p_value"),
            noise_mm=test.number("noise_mm"),
            detection_floor_n=test.number("detection_floor_n"),
        ),
        pressure_map=None if pressure is None else _pressure_map(e.child("pressure_map")),
        counts=LatticeCounts(
            points_detected=e.integer("points_detected"),
            points_expected=e.integer("points_expected"),
            squares_detected=e.integer("squares_detected"),
            squares_expected=e.integer("squares_expected"),
            points_valid=e.integer("points_valid"),
            points_implausible=e.integer("points_implausible"),
        ),
        samples_used=e.integer("samples_used"),
        samples_total=e.integer("samples_total"),
        contact_score_mm=e.number("contact_score_mm"),
        recovered=e.boolean("recovered"),
        retared=e.boolean("retared"),
        retare_count=e.integer("retare_count"),
        shear_field=_shear_field(e),
        elapsed_ms=e.number("elapsed_ms"),
    )


def _contact(c: _Object) -> Contact:
    return Contact(
        centre_px=c.array("centre_px", 2),
        centre_undistorted_px=c.array("centre_undistorted_px", 2),
        centre_mm=c.array("centre_mm", 2),
        force_n=c.number("force_n"),
        force_vector_n=c.optional_array("force_vector_n", 3),
        torque_nmm=c.optional_float("torque_nmm"),
        area_mm2=c.optional_float("area_mm2"),
    )


def _shear_field(e: _Object) -> ShearField:
    # One reading carries 165 corners of 4 fields each: read column by column with numpy, which checks the
    # types of a whole column at once (a string or a missing value leaves a column that is not numeric).
    path = f"{e.path}.shear_field"
    vectors = e.items("shear_field")
    missing = (np.nan, np.nan)
    try:
        index = _numeric([(v["index"]["row"], v["index"]["col"]) for v in vectors], "i")
        points = {
            name: _numeric([missing if v[name] is None else v[name] for v in vectors], "fi").astype(np.float64)
            for name in ("reference_px", "current_px", "displacement_mm")
        }
        valid = np.array([v["valid"] for v in vectors])
    except (KeyError, TypeError, ValueError) as error:
        raise ProtocolError(f"{path}: not a list of corners with index, points and valid ({error!r})") from None
    n = len(vectors)
    if (
        index.shape != (n, 2)
        or any(p.shape != (n, 2) for p in points.values())
        or valid.shape != (n,)
        or (n and valid.dtype != np.bool_)
    ):
        raise ProtocolError(f"{path}: every corner needs a [row, col] index, [x, y] points and a boolean valid")
    return ShearField(
        index=_frozen(index.reshape(n, 2).astype(np.int64)),
        reference_px=_frozen(points["reference_px"].reshape(n, 2)),
        current_px=_frozen(points["current_px"].reshape(n, 2)),
        displacement_mm=_frozen(points["displacement_mm"].reshape(n, 2)),
        valid=_frozen(valid.reshape(n).astype(np.bool_)),
    )


def _numeric(rows: list[Any], kinds: str) -> npt.NDArray[Any]:
    """``rows`` as one array whose dtype is of one of ``kinds`` (numpy's: ``i`` integer, ``f`` float)."""
    array = np.array(rows)
    if array.size and array.dtype.kind not in kinds:
        raise ValueError(f"values of type {array.dtype} where numbers belong")
    return array


def _pressure_map(m: _Object) -> PressureMap:
    cols, rows = m.integer("cols"), m.integer("rows")
    kpa = m.array("kpa", rows * cols)
    return PressureMap(
        origin_mm=m.array("origin_mm", 2),
        step_mm=m.array("step_mm", 2),
        kpa=_frozen(kpa.reshape(rows, cols)),
    )


def _led(led: _Object) -> LedState:
    faults = led.items("faults")
    if len(faults) != 4 or not all(isinstance(f, list) and all(isinstance(s, str) for s in f) for f in faults):
        raise ProtocolError(f"{led.path}.faults: expected 4 lists of names, got {faults!r}")
    return LedState(
        setpoint_ma=led.array("setpoint_ma", 4, np.int64),
        measured_ma=led.array("measured_ma", 4),
        enabled=led.array("enabled", 4, np.bool_),
        faults=tuple(tuple(f) for f in faults),
        any_fault=led.boolean("any_fault"),
        temperature_c=led.number("temperature_c"),
        supply_mv=led.integer("supply_mv"),
    )


def _versioned(payload: bytes | str, name: str) -> _Object:
    """The message as an object, once its ``schema_version`` is one this client reads."""
    message = _Object(_parse_json(payload), name)
    version = message.integer("schema_version")
    if version != SCHEMA_VERSION:
        raise ProtocolError(
            f"{name}: schema_version {version}, this client reads {SCHEMA_VERSION} (update the nusense package)"
        )
    return message


def _centres_mm(contacts: tuple[Contact, ...]) -> FloatArray:
    return _frozen(np.array([c.centre_mm for c in contacts], dtype=np.float64).reshape(-1, 2))


def _forces_n(contacts: tuple[Contact, ...]) -> FloatArray:
    return _frozen(np.array([c.force_n for c in contacts], dtype=np.float64))


def _parse_json(payload: bytes | str) -> Any:
    try:
        return json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ProtocolError(f"not a JSON message: {e}") from e


def _frozen(array: npt.NDArray[Any]) -> npt.NDArray[Any]:
    array.setflags(write=False)
    return array


class _Object:
    """A JSON object read field by field, each read checking the field's type; errors name the field's path."""

    def __init__(self, value: Any, path: str) -> None:
        if not isinstance(value, dict):
            raise ProtocolError(f"{path}: expected an object, got {type(value).__name__}")
        self.value: Mapping[str, Any] = value
        self.path = path

    def _get(self, key: str) -> Any:
        try:
            return self.value[key]
        except KeyError:
            raise ProtocolError(f"{self.path}.{key}: missing") from None

    def _wrong(self, key: str, expected: str, got: Any) -> ProtocolError:
        return ProtocolError(f"{self.path}.{key}: expected {expected}, got {got!r}")

    def optional(self, key: str) -> Any:
        return self.value.get(key)

    def integer(self, key: str) -> int:
        v = self._get(key)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self._wrong(key, "an integer", v)
        return v

    def number(self, key: str) -> float:
        v = self._get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self._wrong(key, "a number", v)
        return float(v)

    def boolean(self, key: str) -> bool:
        v = self._get(key)
        if not isinstance(v, bool):
            raise self._wrong(key, "true or false", v)
        return v

    def text(self, key: str) -> str:
        v = self._get(key)
        if not isinstance(v, str):
            raise self._wrong(key, "a string", v)
        return v

    def items(self, key: str) -> list[Any]:
        v = self._get(key)
        if not isinstance(v, list):
            raise self._wrong(key, "a list", v)
        return v

    def child(self, key: str) -> _Object:
        return _Object(self._get(key), f"{self.path}.{key}")

    def children(self, key: str) -> list[_Object]:
        return [_Object(item, f"{self.path}.{key}[{i}]") for i, item in enumerate(self.items(key))]

    def optional_int(self, key: str) -> int | None:
        return None if self.value.get(key) is None else self.integer(key)

    def optional_float(self, key: str) -> float | None:
        return None if self.value.get(key) is None else self.number(key)

    def optional_str(self, key: str) -> str | None:
        return None if self.value.get(key) is None else self.text(key)

    def array(self, key: str, length: int, dtype: type[np.generic] = np.float64) -> npt.NDArray[Any]:
        items = self.items(key)
        if len(items) != length:
            raise self._wrong(key, f"{length} values", items)
        kinds = {np.float64: (int, float), np.int64: (int,), np.bool_: (bool,)}[dtype]
        if any(not isinstance(x, kinds) or (dtype is not np.bool_ and isinstance(x, bool)) for x in items):
            raise self._wrong(key, f"{length} values of type {dtype.__name__}", items)
        return _frozen(np.array(items, dtype=dtype))

    def optional_array(self, key: str, length: int) -> FloatArray | None:
        return None if self.value.get(key) is None else self.array(key, length)
