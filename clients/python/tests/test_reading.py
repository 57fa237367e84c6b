"""Decoding the daemon's reading and status messages: fixtures are real messages from `nusense serve --sim`
(tests/fixtures/README.md says how they were made)."""

from __future__ import annotations

import copy
import json
from typing import Any

import jsonschema
import numpy as np
import pytest
from conftest import FIXTURES, REPO, fixture_bytes

import nusense

READINGS = ["reading_inverse_two_contacts.json", "reading_fast.json", "reading_fast_no_contact.json"]


def raw(name: str) -> dict[str, Any]:
    value: dict[str, Any] = json.loads(fixture_bytes(name))
    return value


@pytest.mark.parametrize("name", READINGS)
def test_fixtures_are_reading_messages_of_the_daemons_schema(name: str) -> None:
    schema = json.loads((REPO / "host/daemon/schema/reading.schema.json").read_text())
    jsonschema.Draft202012Validator(schema).validate(raw(name))


def test_inverse_reading_with_two_contacts() -> None:
    message = raw("reading_inverse_two_contacts.json")
    e = message["estimate"]
    reading = nusense.decode_reading(fixture_bytes("reading_inverse_two_contacts.json"), serial="sim-0")

    assert reading.serial == "sim-0"
    assert reading.frame_id == message["frame_id"]
    assert reading.capture_time_us == message["capture_time_us"]
    assert reading.reference_frame_id == message["reference_frame_id"]
    assert reading.latency_ms == message["latency_ms"]
    assert reading.error is None
    estimate = reading.estimate
    assert estimate is not None
    assert estimate.mode == "inverse"
    assert estimate.contact
    assert estimate.force_n == e["force_n"]
    np.testing.assert_array_equal(estimate.force_vector_n, e["force_vector_n"])
    assert estimate.torque_nmm == e["torque_nmm"]

    # Two contacts, strongest first, each with its own force vector and area.
    assert len(estimate.contacts) == 2
    for contact, expected in zip(estimate.contacts, e["contacts"]):
        np.testing.assert_array_equal(contact.centre_px, expected["centre_px"])
        np.testing.assert_array_equal(contact.centre_mm, expected["centre_mm"])
        np.testing.assert_array_equal(contact.force_vector_n, expected["force_vector_n"])
        assert contact.force_n == expected["force_n"]
        assert contact.area_mm2 == expected["area_mm2"]
    np.testing.assert_array_equal(estimate.contact_centres_mm, [c["centre_mm"] for c in e["contacts"]])
    np.testing.assert_array_equal(estimate.contact_forces_n, [c["force_n"] for c in e["contacts"]])
    np.testing.assert_array_equal(estimate.contact_mm, e["contacts"][0]["centre_mm"])

    # The pressure map: row-major kPa on the wire, (rows, cols) here; cell centres from origin and step.
    pressure = estimate.pressure_map
    wire = e["pressure_map"]
    assert pressure is not None
    assert pressure.kpa.shape == (wire["rows"], wire["cols"]) == (12, 16)
    r, c = 7, 3
    assert pressure.kpa[r, c] == wire["kpa"][r * wire["cols"] + c]
    assert pressure.x_mm[c] == pytest.approx(wire["origin_mm"][0] + c * wire["step_mm"][0])
    assert pressure.y_mm[r] == pytest.approx(wire["origin_mm"][1] + r * wire["step_mm"][1])

    # The shear field: the pad's 165 corners, one row each, in the message's order.
    field = estimate.shear_field
    assert len(field) == len(e["shear_field"]) == 165
    for i in (0, 57, 164):
        corner = e["shear_field"][i]
        assert tuple(field.index[i]) == (corner["index"]["row"], corner["index"]["col"])
        np.testing.assert_array_equal(field.reference_px[i], corner["reference_px"])
        np.testing.assert_array_equal(field.current_px[i], corner["current_px"])
        np.testing.assert_array_equal(field.displacement_mm[i], corner["displacement_mm"])
        assert field.valid[i] == corner["valid"]
    assert estimate.counts.points_detected == e["points_detected"]

    # The board's state, per string.
    assert reading.led is not None
    np.testing.assert_array_equal(reading.led.setpoint_ma, message["led"]["setpoint_ma"])
    assert reading.led.faults == ((), (), (), ())


def test_fast_mode_has_no_force_vector_nor_pressure_map() -> None:
    e = raw("reading_fast.json")["estimate"]
    estimate = nusense.decode_reading(fixture_bytes("reading_fast.json")).estimate
    assert estimate is not None
    assert estimate.mode == "fast"
    assert estimate.contact and len(estimate.contacts) == len(e["contacts"]) == 1
    assert estimate.force_vector_n is None and estimate.torque_nmm is None
    assert estimate.contacts[0].force_vector_n is None and estimate.contacts[0].area_mm2 is None
    assert estimate.pressure_map is None
    assert estimate.force_n == e["force_n"]


def test_no_contact() -> None:
    estimate = nusense.decode_reading(fixture_bytes("reading_fast_no_contact.json")).estimate
    assert estimate is not None
    assert not estimate.contact
    assert estimate.contacts == ()
    assert estimate.force_n == 0.0
    assert estimate.contact_mm is None and estimate.edge_angle_deg is None
    assert estimate.contact_centres_mm.shape == (0, 2)
    assert estimate.contact_forces_n.shape == (0,)


def test_missing_corners_are_nan_and_arrays_are_read_only() -> None:
    message = raw("reading_fast.json")
    corner = message["estimate"]["shear_field"][10]
    corner["current_px"] = None
    corner["displacement_mm"] = None
    corner["valid"] = False
    field = nusense.decode_reading(json.dumps(message)).estimate.shear_field  # type: ignore[union-attr]
    assert np.isnan(field.current_px[10]).all() and np.isnan(field.displacement_mm[10]).all()
    np.testing.assert_array_equal(field.reference_px[10], corner["reference_px"])
    assert not field.valid[10]
    assert np.isfinite(field.current_px[11]).all()
    with pytest.raises(ValueError):
        field.current_px[0, 0] = 1.0


def test_a_frame_without_estimate_carries_the_daemons_reason() -> None:
    message = raw("reading_fast.json")
    message["estimate"] = None
    message["error"] = "no rest frame yet"
    reading = nusense.decode_reading(json.dumps(message))
    assert reading.estimate is None
    assert reading.error == "no rest frame yet"


def test_unknown_keys_are_ignored() -> None:
    message = raw("reading_fast.json")
    message["a_future_field"] = {"x": 1}
    message["estimate"]["another"] = [1, 2]
    reading = nusense.decode_reading(json.dumps(message).encode())
    assert reading.frame_id == message["frame_id"]


@pytest.mark.parametrize(
    ("change", "says"),
    [
        (lambda m: m.update(schema_version=2), "schema_version 2"),
        (lambda m: m.pop("frame_id"), "reading.frame_id: missing"),
        (lambda m: m["estimate"].update(force_n="5"), "reading.estimate.force_n: expected a number"),
        (lambda m: m["estimate"]["contacts"][0].update(centre_mm=[1.0]), "reading.estimate.contacts[0].centre_mm"),
        (lambda m: m["estimate"].update(mode="slow"), "unknown mode 'slow'"),
        (lambda m: m["led"].update(enabled=[1, 1, 1, 1]), "reading.led.enabled"),
        (lambda m: m["estimate"]["shear_field"][3].update(current_px=["1", 2]), "reading.estimate.shear_field"),
        (lambda m: m["estimate"]["shear_field"][3].update(current_px=[1.0]), "reading.estimate.shear_field"),
        (lambda m: m["estimate"]["shear_field"][3].pop("valid"), "reading.estimate.shear_field"),
        (lambda m: m["estimate"]["shear_field"][3].update(valid=None), "reading.estimate.shear_field"),
    ],
)
def test_malformed_messages_raise_protocol_errors_naming_the_field(change: Any, says: str) -> None:
    message = copy.deepcopy(raw("reading_fast.json"))
    change(message)
    with pytest.raises(nusense.ProtocolError, match=says.replace("[", r"\[").replace("]", r"\]")):
        nusense.decode_reading(json.dumps(message))


def test_not_json_is_a_protocol_error() -> None:
    with pytest.raises(nusense.ProtocolError, match="not a JSON message"):
        nusense.decode_reading(b"\xff\xd8 jpeg bytes")


def test_status() -> None:
    message = raw("status_sim.json")
    status = nusense.decode_status(fixture_bytes("status_sim.json"), "sim-0")
    assert status.serial == "sim-0"
    assert status.simulator
    assert status.mode == message["pipeline"]["mode"]
    assert status.frames_processed == message["pipeline"]["frames_processed"]
    assert status.latency_p99_ms == message["pipeline"]["latency_ms"]["p99"]
    assert status.board_connected
    assert status.problems == ()
    assert status.raw["board"]["led_limit_ma"] == 120


def test_fixture_folder_lists_every_fixture() -> None:
    readme = (FIXTURES / "README.md").read_text()
    for path in FIXTURES.glob("*.json"):
        assert path.name in readme, f"{path.name} is not described in tests/fixtures/README.md"
