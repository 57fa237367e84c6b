"""The client's logic over Zenoh, against a fake daemon in this process (tests/fake_daemon.py) on the contract's
keys: listing and watching sensors, streaming from one or several, queries and their errors."""

from __future__ import annotations

import json

import pytest
from conftest import eventually, fixture_bytes
from fake_daemon import FakeDaemon

import nusense

STATUS = fixture_bytes("status_sim.json")


def reading_payload(frame_id: int, name: str = "reading_fast.json") -> bytes:
    message = json.loads(fixture_bytes(name))
    message["frame_id"] = frame_id
    return json.dumps(message).encode()


def test_lists_the_sensors_and_drops_those_that_stop(fake: FakeDaemon, client: nusense.Client) -> None:
    fake.add_sensor("NUS-A", STATUS)
    fake.add_sensor("NUS-B", STATUS)
    assert eventually(lambda: client.sensors() == ["NUS-A", "NUS-B"]), client.sensors()
    fake.remove_sensor("NUS-A")
    assert eventually(lambda: client.sensors() == ["NUS-B"]), client.sensors()


def test_watch_reports_present_sensors_then_arrivals_and_departures(fake: FakeDaemon, client: nusense.Client) -> None:
    fake.add_sensor("NUS-A", STATUS)
    assert eventually(lambda: client.sensors() == ["NUS-A"])
    with client.watch_sensors() as watch:
        assert watch.get(timeout=5) == nusense.SensorEvent("NUS-A", alive=True)
        fake.add_sensor("NUS-B", STATUS)
        assert watch.get(timeout=5) == nusense.SensorEvent("NUS-B", alive=True)
        fake.remove_sensor("NUS-A")
        assert watch.get(timeout=5) == nusense.SensorEvent("NUS-A", alive=False)
        with pytest.raises(TimeoutError):
            watch.get(timeout=0.2)


def test_watch_with_a_callback(fake: FakeDaemon, client: nusense.Client) -> None:
    events: list[nusense.SensorEvent] = []
    with client.watch_sensors(events.append):
        fake.add_sensor("NUS-C", STATUS)
        assert eventually(lambda: events == [nusense.SensorEvent("NUS-C", alive=True)]), events
        fake.remove_sensor("NUS-C")
        assert eventually(lambda: len(events) == 2), events
    assert events[1] == nusense.SensorEvent("NUS-C", alive=False)


MARKER = 10**9


def wait_until_subscribed(fake: FakeDaemon, stream: nusense.Stream[nusense.Reading], serial: str) -> None:
    """Publishes marker readings (frame id MARKER) until the stream sees one: the subscription has reached the
    fake. Markers still on their way are skipped by ``next_reading``."""

    def seen() -> bool:
        fake.publish_reading(serial, reading_payload(MARKER))
        try:
            return stream.get(timeout=0.05).frame_id == MARKER
        except TimeoutError:
            return False

    assert eventually(seen)


def next_reading(stream: nusense.Stream[nusense.Reading], timeout: float = 5.0) -> nusense.Reading:
    while True:
        reading = stream.get(timeout=timeout)
        if reading.frame_id != MARKER:
            return reading


def no_more_readings(stream: nusense.Stream[nusense.Reading]) -> bool:
    try:
        next_reading(stream, timeout=0.2)
    except TimeoutError:
        return True
    return False


def test_streams_one_sensor_and_not_the_others(fake: FakeDaemon, client: nusense.Client) -> None:
    with client.readings("NUS-A") as stream:
        wait_until_subscribed(fake, stream, "NUS-A")
        for frame_id in range(5):
            fake.publish_reading("NUS-B", reading_payload(100 + frame_id))
            fake.publish_reading("NUS-A", reading_payload(frame_id))
        got = [next_reading(stream) for _ in range(5)]
        assert [(r.serial, r.frame_id) for r in got] == [("NUS-A", i) for i in range(5)]
        assert no_more_readings(stream)
    # The decoded reading is the published one, arrays included.
    expected = nusense.decode_reading(fixture_bytes("reading_fast.json"))
    assert got[0].estimate is not None and expected.estimate is not None
    assert got[0].estimate.force_n == expected.estimate.force_n
    assert (got[0].estimate.shear_field.current_px == expected.estimate.shear_field.current_px).all()


def test_streams_several_sensors_at_once(fake: FakeDaemon, client: nusense.Client) -> None:
    with client.readings(["NUS-A", "NUS-B"]) as stream:
        wait_until_subscribed(fake, stream, "NUS-A")
        wait_until_subscribed(fake, stream, "NUS-B")
        for frame_id in range(3):
            fake.publish_reading("NUS-A", reading_payload(frame_id))
            fake.publish_reading("NUS-B", reading_payload(frame_id, "reading_inverse_two_contacts.json"))
            fake.publish_reading("NUS-C", reading_payload(frame_id))
        got = [next_reading(stream) for _ in range(6)]
        assert no_more_readings(stream)
    by_sensor = {s: [r for r in got if r.serial == s] for s in ("NUS-A", "NUS-B")}
    assert [r.frame_id for r in by_sensor["NUS-A"]] == [0, 1, 2]
    assert [r.frame_id for r in by_sensor["NUS-B"]] == [0, 1, 2]
    assert all(r.estimate is not None and r.estimate.mode == "inverse" for r in by_sensor["NUS-B"])
    assert all(r.estimate is not None and r.estimate.mode == "fast" for r in by_sensor["NUS-A"])


def test_every_sensor_and_iteration_until_closed(fake: FakeDaemon, client: nusense.Client) -> None:
    stream = client.readings()
    wait_until_subscribed(fake, stream, "NUS-Z")
    while not no_more_readings(stream):  # markers still on their way
        pass
    fake.publish_reading("NUS-X", reading_payload(1))
    fake.publish_reading("NUS-Y", reading_payload(2))
    assert eventually(lambda: stream._inbox._queue.qsize() == 2)
    stream.close()
    assert [(r.serial, r.frame_id) for r in stream] == [("NUS-X", 1), ("NUS-Y", 2)]


def test_a_slow_reader_keeps_the_newest_readings(fake: FakeDaemon, client: nusense.Client) -> None:
    with client.readings("NUS-A", capacity=2) as stream:
        wait_until_subscribed(fake, stream, "NUS-A")
        while not no_more_readings(stream):  # markers still on their way
            pass
        dropped_markers = stream.dropped
        for frame_id in range(5):
            fake.publish_reading("NUS-A", reading_payload(frame_id))
        assert eventually(lambda: stream.dropped - dropped_markers == 3), stream.dropped
        assert [stream.get(timeout=1).frame_id for _ in range(2)] == [3, 4]


def test_a_garbled_reading_raises_and_the_stream_goes_on(fake: FakeDaemon, client: nusense.Client) -> None:
    with client.readings("NUS-A") as stream:
        wait_until_subscribed(fake, stream, "NUS-A")
        fake.publish_reading("NUS-A", b'{"schema_version": 1, "frame_id": "seven"}')
        fake.publish_reading("NUS-A", reading_payload(8))
        with pytest.raises(nusense.ProtocolError, match="frame_id: expected an integer"):
            next_reading(stream)
        assert next_reading(stream).frame_id == 8


def test_contacts_stream(fake: FakeDaemon, client: nusense.Client) -> None:
    reading = json.loads(fixture_bytes("reading_inverse_two_contacts.json"))
    message = {
        "schema_version": 1,
        "frame_id": reading["frame_id"],
        "capture_time_us": reading["capture_time_us"],
        "contacts": reading["estimate"]["contacts"],
    }
    with client.contacts("NUS-A") as stream:

        def arrived() -> nusense.Contacts | None:
            fake.session.put("nusense/NUS-A/contacts", json.dumps(message))
            try:
                return stream.get(timeout=0.05)
            except TimeoutError:
                return None

        contacts = eventually(arrived)
    assert contacts is not None
    assert contacts.serial == "NUS-A"
    assert contacts.frame_id == reading["frame_id"]
    assert contacts.centres_mm.tolist() == [c["centre_mm"] for c in reading["estimate"]["contacts"]]
    assert contacts.forces_n.tolist() == [c["force_n"] for c in reading["estimate"]["contacts"]]


def test_status(fake: FakeDaemon, client: nusense.Client) -> None:
    fake.add_sensor("NUS-A", STATUS)
    status = served(client, "NUS-A")
    assert status.serial == "NUS-A"
    assert status.frames_processed == json.loads(STATUS)["pipeline"]["frames_processed"]


def test_led_sends_the_http_apis_body(fake: FakeDaemon, client: nusense.Client) -> None:
    sensor = fake.add_sensor("NUS-A", STATUS)
    served(client, "NUS-A")
    reply = client.set_leds("NUS-A", all=60)
    assert reply == {"schema_version": 1, "board": {"connected": True}}
    client.set_leds("NUS-A", top=10, left=0, enabled=False)
    assert sensor.led_requests[-2:] == [{"all": 60}, {"top": 10, "left": 0, "enabled": False}]


def test_a_refused_led_request_raises_the_daemons_message(fake: FakeDaemon, client: nusense.Client) -> None:
    sensor = fake.add_sensor("NUS-A", STATUS)
    sensor.led_error = "Top LED current 500 mA is above the 120 mA limit"
    served(client, "NUS-A")
    with pytest.raises(nusense.DaemonError) as refused:
        client.set_leds("NUS-A", all=500)
    assert refused.value.message == "Top LED current 500 mA is above the 120 mA limit"
    assert refused.value.serial == "NUS-A"
    assert refused.value.key == "nusense/NUS-A/led"
    assert str(refused.value) == "NUS-A: Top LED current 500 mA is above the 120 mA limit"


def test_tare(fake: FakeDaemon, client: nusense.Client) -> None:
    sensor = fake.add_sensor("NUS-A", STATUS)
    served(client, "NUS-A")
    message = client.tare("NUS-A")
    assert message == "the next frame becomes the rest frame"
    assert sensor.tares == 1


def test_frame(fake: FakeDaemon, client: nusense.Client) -> None:
    sensor = fake.add_sensor("NUS-A", STATUS)
    served(client, "NUS-A")
    frame = client.frame("NUS-A")
    assert frame == sensor.frame_jpeg


def test_a_sensor_nobody_serves_raises_no_reply(fake: FakeDaemon, client: nusense.Client) -> None:
    fake.add_sensor("NUS-A", STATUS)
    served(client, "NUS-A")
    with pytest.raises(nusense.NoReplyError, match="no reply from sensor 'NUS-B' on nusense/NUS-B/tare"):
        client.tare("NUS-B", timeout=0.3)


def test_a_sensor_that_does_not_answer_in_time_raises_no_reply(fake: FakeDaemon, client: nusense.Client) -> None:
    sensor = fake.add_sensor("NUS-A", STATUS)
    sensor.tare_silent = True
    served(client, "NUS-A")
    with pytest.raises(nusense.NoReplyError, match="no reply from sensor 'NUS-A' on nusense/NUS-A/tare within 0.3 s"):
        client.tare("NUS-A", timeout=0.3)
    assert sensor.tares == 1


def test_serials_that_are_not_one_key_chunk_are_refused(client: nusense.Client) -> None:
    for bad in ("", "a/b", "*", "**", "a?b", "a#b", "..", "a b", "\u00e9"):
        with pytest.raises(ValueError, match="is not a sensor serial"):
            client.readings(bad)
    with client.readings("board-2_v1.0"):
        pass


def served(client: nusense.Client, serial: str) -> nusense.Status:
    """The sensor's status once its queryables have reached the client (the fake declares status last)."""

    def status() -> nusense.Status | None:
        try:
            return client.status(serial, timeout=0.3)
        except nusense.NoReplyError:
            return None

    found = eventually(status)
    assert found is not None, f"{serial} never answered status"
    return found
