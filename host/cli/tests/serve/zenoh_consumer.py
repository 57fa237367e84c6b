"""A Zenoh consumer of `nusense serve --zenoh`, run as its own process by tests/serve/zenoh.rs with the project's
.venv (eclipse-zenoh, jsonschema).

It connects to the daemon's loopback endpoint, finds the sensors by liveliness, checks what every key of the
layout (docs/integrations/zenoh.md) says against what it should say, prints one JSON line {"event": "checked",
...} and then {"event": "ready_to_stop"}, and waits for every sensor's liveliness to end (the test stops the
daemon), printing {"event": "gone", "serials": [...]}. A failed check raises: non-zero exit, reason on stderr.
"""

import argparse
import json
import queue
import sys
import threading
import time

import jsonschema
import zenoh

PATIENCE_S = 120.0


def emit(event, **fields):
    print(json.dumps({"event": event, **fields}), flush=True)


def serial_of(board_status):
    """The USB serial number of the board a status describes: its MCU's unique id in upper-case hex."""
    return "".join(f"{byte:02X}" for byte in board_status["link"]["info"]["mcu_uid"])


class Collector:
    """Samples of one key expression, by the serial in their key, as they arrive."""

    def __init__(self):
        self.lock = threading.Condition()
        self.by_serial = {}

    def __call__(self, sample):
        serial = str(sample.key_expr).split("/")[1]
        with self.lock:
            self.by_serial.setdefault(serial, []).append(sample)
            self.lock.notify_all()

    def wait(self, what, done):
        """Waits until done(by_serial) is true; returns a copy of what arrived."""
        deadline = time.monotonic() + PATIENCE_S
        with self.lock:
            while not done(self.by_serial):
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"timed out waiting for {what}; got {self.counts()}")
                self.lock.wait(left)
            return {serial: list(samples) for serial, samples in self.by_serial.items()}

    def counts(self):
        return {serial: len(samples) for serial, samples in self.by_serial.items()}


def query(session, key, payload=None):
    """One query: ("ok", bytes, encoding) or ("err", bytes, encoding) from the single replier."""
    replies = list(session.get(key, payload=payload, timeout=30.0))
    assert len(replies) == 1, f"{key}: expected one reply, got {len(replies)}"
    reply = replies[0]
    if reply.ok is not None:
        return "ok", reply.ok.payload.to_bytes(), str(reply.ok.encoding)
    return "err", reply.err.payload.to_bytes(), str(reply.err.encoding)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--connect", required=True)
    parser.add_argument("--sensors", type=int, required=True)
    parser.add_argument("--schema", required=True)
    parser.add_argument("--readings", type=int, default=6)
    parser.add_argument("--http-errors", required=True, help="JSON: [[led body, the HTTP API's error text], ...]")
    args = parser.parse_args()
    with open(args.schema) as f:
        validator = jsonschema.Draft202012Validator(json.load(f))

    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", json.dumps([args.connect]))
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)

    alive = Collector()
    session.liveliness().declare_subscriber("nusense/*/alive", alive, history=True)
    readings = Collector()
    session.declare_subscriber("nusense/*/reading", readings)
    contacts = Collector()
    session.declare_subscriber("nusense/*/contacts", contacts)
    telemetry = Collector()
    session.declare_subscriber("nusense/*/telemetry", telemetry)

    present = alive.wait(f"{args.sensors} liveliness tokens", lambda got: len(got) >= args.sensors)
    serials = sorted(present)
    assert len(serials) == args.sensors, f"sensors {serials}"
    for serial in serials:
        assert present[serial][0].kind == zenoh.SampleKind.PUT, f"{serial}: {present[serial][0].kind}"

    # Readings from every sensor at once, each a valid reading message, frame ids increasing.
    got = readings.wait(
        f"{args.readings} readings from each sensor",
        lambda got: all(len(got.get(s, [])) >= args.readings for s in serials),
    )
    frames_seen = {}
    for serial in serials:
        messages = [json.loads(s.payload.to_bytes()) for s in got[serial]]
        for sample, message in zip(got[serial], messages):
            assert str(sample.encoding) == "application/json", sample.encoding
            validator.validate(message)
        ids = [m["frame_id"] for m in messages]
        assert ids == sorted(set(ids)), f"{serial}: frame ids not increasing: {ids}"
        frames_seen[serial] = ids

    # Contacts carry the frame id and capture time of a reading of the same sensor.
    got_contacts = contacts.wait("contacts of each sensor", lambda got: all(s in got for s in serials))
    reading_times = {
        (serial, m["frame_id"]): m["capture_time_us"]
        for serial in serials
        for m in (json.loads(s.payload.to_bytes()) for s in readings.wait("", lambda _: True)[serial])
    }
    for serial in serials:
        message = json.loads(got_contacts[serial][-1].payload.to_bytes())
        assert message["schema_version"] == 1 and isinstance(message["contacts"], list), message
        key = (serial, message["frame_id"])
        if key in reading_times:
            assert reading_times[key] == message["capture_time_us"], (message, reading_times[key])

    # Status and telemetry under each key describe that key's board.
    for serial in serials:
        kind, body, encoding = query(session, f"nusense/{serial}/status")
        status = json.loads(body)
        assert kind == "ok" and encoding == "application/json", (kind, encoding, status)
        assert status["schema_version"] == 1 and status["simulator"] is True, status
        assert serial_of(status["board"]) == serial, (serial, status["board"])
    got_telemetry = telemetry.wait("telemetry of each sensor", lambda got: all(s in got for s in serials))
    for serial in serials:
        board = json.loads(got_telemetry[serial][-1].payload.to_bytes())
        assert board["kind"] == "virtual" and board["connected"] is True, board
        assert serial_of(board) == serial, (serial, board)

    # Frames: the camera's JPEG, while subscribed; and the latest one on request.
    first, second = serials[0], serials[1]
    frames = Collector()
    frame_subscriber = session.declare_subscriber(f"nusense/{first}/frame", frames)
    frame = frames.wait("a published frame", lambda got: first in got)[first][0]
    assert frame.payload.to_bytes()[:2] == b"\xff\xd8" and str(frame.encoding) == "image/jpeg", frame.encoding
    frame_subscriber.undeclare()
    kind, body, encoding = query(session, f"nusense/{second}/frame")
    assert kind == "ok" and body[:2] == b"\xff\xd8" and encoding == "image/jpeg", (kind, encoding)

    # Invalid LED bodies: the HTTP API's error text, word for word.
    led_errors = []
    for body, http_error in json.loads(args.http_errors):
        kind, reply, encoding = query(session, f"nusense/{first}/led", payload=json.dumps(body).encode())
        message = json.loads(reply)
        assert kind == "err" and encoding == "application/json", (kind, encoding, message)
        assert message == {"schema_version": 1, "error": http_error}, (body, message, http_error)
        led_errors.append(message["error"])

    # A valid LED command on the second sensor reaches that sensor's board only.
    kind, reply, _ = query(session, f"nusense/{second}/led", payload=b'{"all": 37}')
    assert kind == "ok", reply
    assert [r["current_ma"] for r in json.loads(reply)["board"]["link"]["requested"]] == [37] * 4, reply
    mark = readings.counts()
    got = readings.wait(
        "a reading of the second sensor at 37 mA",
        lambda got: any(
            json.loads(s.payload.to_bytes())["led"]["setpoint_ma"] == [37] * 4 for s in got[second][mark[second] :]
        ),
    )
    first_led = json.loads(got[first][-1].payload.to_bytes())["led"]["setpoint_ma"]
    assert first_led == [100] * 4, f"the first sensor's LEDs left their nominal 100 mA: {first_led}"

    # A tare on the first sensor: its next frame becomes its rest frame; the second sensor keeps its own.
    def status_of(serial):
        return json.loads(query(session, f"nusense/{serial}/status")[1])

    tares_before = {serial: status_of(serial)["pipeline"]["tares"] for serial in serials}
    mark = readings.counts()
    last_before = json.loads(readings.wait("", lambda _: True)[first][-1].payload.to_bytes())
    kind, reply, _ = query(session, f"nusense/{first}/tare")
    assert kind == "ok", reply
    assert json.loads(reply) == {"schema_version": 1, "tare": "the next frame becomes the rest frame"}, reply

    def retared(got):
        later = [json.loads(s.payload.to_bytes()) for s in got[first][mark[first] :]]
        return any(m["reference_frame_id"] is not None and m["reference_frame_id"] > last_before["frame_id"] for m in later)

    got = readings.wait("a reading measured against the new rest frame", retared)
    new_reference = next(
        m["reference_frame_id"]
        for m in (json.loads(s.payload.to_bytes()) for s in got[first][mark[first] :])
        if m["reference_frame_id"] is not None and m["reference_frame_id"] > last_before["frame_id"]
    )
    tares_after = {serial: status_of(serial)["pipeline"]["tares"] for serial in serials}
    assert tares_after[first] == tares_before[first] + 1, (tares_before, tares_after)
    assert tares_after[second] == tares_before[second], (tares_before, tares_after)

    emit(
        "checked",
        serials=serials,
        frames=frames_seen,
        led_errors=led_errors,
        reference_before=last_before["reference_frame_id"],
        reference_after=new_reference,
    )

    # The test stops the daemon now: every sensor's liveliness must end.
    emit("ready_to_stop")
    alive.wait(
        "every sensor's liveliness to end",
        lambda got: all(any(s.kind == zenoh.SampleKind.DELETE for s in got[serial]) for serial in serials),
    )
    emit("gone", serials=serials)
    session.close()


if __name__ == "__main__":
    try:
        main()
    except AssertionError as error:
        print(f"zenoh consumer: check failed: {error}", file=sys.stderr)
        raise
