"""The client against the real daemon: `nusense serve --sim --sensors 2 --zenoh` on a loopback port, started from
the binary in NUSENSE_BIN (host/cli/tests/python_client.rs passes this build's; without it these tests are
skipped, and that test fails on any skip)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import eventually

import nusense

NUSENSE_BIN = os.environ.get("NUSENSE_BIN")

pytestmark = pytest.mark.skipif(
    not NUSENSE_BIN, reason="NUSENSE_BIN is not set (host/cli/tests/python_client.rs sets it to this build's nusense)"
)

#: Small frames: the tests are about what reaches the client, not the estimator's accuracy at full size.
SIM = ["--sim", "--width", "320", "--height", "240", "--fps", "20"]
STARTUP_S = 60.0
DEFAULT_LED_MA = 100


@dataclass
class Daemon:
    process: subprocess.Popen[bytes]
    endpoint: str
    #: The HTTP API (it serves the first sensor).
    http: str
    log: Path

    def stop(self) -> int:
        self.process.send_signal(signal.SIGTERM)
        return self.process.wait(timeout=30)

    def log_text(self) -> str:
        return self.log.read_text(errors="replace")

    def http_json(self, method: str, path: str, body: dict[str, Any] | None = None) -> tuple[int, Any]:
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(self.http + path, data=data, method=method)
        # The daemon takes changes only from its own page: say we are it.
        request.add_header("Origin", self.http)
        if data is not None:
            request.add_header("Content-Type", "application/json")
        try:
            with urllib.request.urlopen(request, timeout=10) as response:
                return response.status, json.loads(response.read())
        except urllib.error.HTTPError as error:
            return error.code, json.loads(error.read())


def start_daemon(sensors: int, tmp: Path) -> Daemon:
    assert NUSENSE_BIN is not None
    log = tmp / "serve.log"
    # The HTTP and Zenoh ports are the daemon's own picks (port 0), read from the addresses it prints: a port found
    # free here and passed on can be taken in between by any other process's connection (CI saw "Address already in
    # use"). It prints the Zenoh line before the dashboard's.
    process = subprocess.Popen(
        [NUSENSE_BIN, "serve", *SIM, "--sensors", str(sensors), "--zenoh", "tcp/127.0.0.1:0"]
        + ["--listen", "127.0.0.1:0", "--recordings", str(tmp / "recordings")],
        stdout=log.open("wb"),
        stderr=subprocess.STDOUT,
    )
    deadline = time.monotonic() + STARTUP_S
    while time.monotonic() < deadline:
        text = log.read_text(errors="replace")
        rest = text.split("dashboard at http://", 1)[1] if "dashboard at http://" in text else ""
        if "/" in rest:  # the address is whole once the slash after it is written
            if "Zenoh listening on " not in text:
                break
            zenoh_endpoints = text.split("Zenoh listening on ", 1)[1].split("\n", 1)[0].split()
            return Daemon(process, zenoh_endpoints[0], f"http://{rest.split('/', 1)[0]}", log)
        if process.poll() is not None:
            break
        time.sleep(0.05)
    if process.poll() is None:
        process.kill()
        process.wait(timeout=30)
    raise AssertionError(
        f"the daemon never said where its dashboard and Zenoh endpoint are; its log:\n{log.read_text(errors='replace')}"
    )


def connect(daemon: Daemon) -> nusense.Client:
    return nusense.connect([daemon.endpoint])


def serials_when_served(client: nusense.Client, daemon: Daemon, count: int) -> list[str]:
    deadline = time.monotonic() + STARTUP_S
    while time.monotonic() < deadline:
        assert daemon.process.poll() is None, f"the daemon exited early:\n{daemon.log_text()}"
        serials = client.sensors(timeout=0.5)
        if len(serials) == count:
            return serials
        time.sleep(0.1)
    raise AssertionError(f"{count} sensors never appeared; daemon log:\n{daemon.log_text()}")


@pytest.fixture(scope="module")
def daemon() -> Iterator[Daemon]:
    with tempfile.TemporaryDirectory() as tmp:
        running = start_daemon(2, Path(tmp))
        try:
            yield running
        finally:
            if running.process.poll() is None:
                running.stop()


@pytest.fixture(scope="module")
def client(daemon: Daemon) -> Iterator[nusense.Client]:
    with connect(daemon) as c:
        yield c


@pytest.fixture(scope="module")
def serials(client: nusense.Client, daemon: Daemon) -> list[str]:
    return serials_when_served(client, daemon, 2)


def collect(stream: nusense.Stream[nusense.Reading], until: Any, timeout: float = 20.0) -> list[nusense.Reading]:
    """Readings from ``stream`` until ``until(readings)`` holds."""
    readings: list[nusense.Reading] = []
    deadline = time.monotonic() + timeout
    while not until(readings):
        left = deadline - time.monotonic()
        assert left > 0, f"timed out; got {len(readings)} readings"
        readings.append(stream.get(timeout=left))
    return readings


def of(readings: list[nusense.Reading], serial: str) -> list[nusense.Reading]:
    return [r for r in readings if r.serial == serial]


def test_lists_both_sensors_by_their_boards_serial_numbers(client: nusense.Client, serials: list[str]) -> None:
    assert serials == sorted(serials) and len(set(serials)) == 2
    for serial in serials:
        status = client.status(serial)
        assert status.serial == serial
        assert status.simulator and status.mode == "inverse" and status.board_connected
        # The serial names the sensor's LED board: its MCU's unique id in upper-case hex.
        uid = status.raw["board"]["link"]["info"]["mcu_uid"]
        assert serial == "".join(f"{byte:02X}" for byte in uid)
        # A live sensor: its frame count goes on.
        assert eventually(lambda: client.status(serial).frames_processed > status.frames_processed)


def test_streams_readings_of_both_sensors_at_once(client: nusense.Client, serials: list[str]) -> None:
    with client.readings(serials) as stream:
        readings = collect(stream, lambda rs: all(len(of(rs, s)) >= 10 for s in serials))
    for serial in serials:
        mine = of(readings, serial)
        frame_ids = [r.frame_id for r in mine]
        assert frame_ids == sorted(frame_ids) and len(set(frame_ids)) == len(frame_ids), frame_ids
        for reading in mine:
            assert reading.estimate is not None, reading.error
            assert reading.estimate.shear_field.index.shape == (165, 2)
            assert reading.led is not None and reading.led.enabled.all()
    assert {r.serial for r in readings} == set(serials)


def test_a_reading_is_the_one_the_http_api_gives_for_that_frame(
    client: nusense.Client, daemon: Daemon, serials: list[str]
) -> None:
    """The first sensor's newest reading from the HTTP API, and the same frame through Zenoh: equal in every
    field the client decodes (the HTTP API serves the daemon's first sensor)."""
    with client.readings(serials) as stream:
        # The HTTP API's newest reading may have reached the stream before the request: keep what came before it.
        earlier = collect(stream, lambda rs: len(rs) >= 4)
        status, message = daemon.http_json("GET", "/api/v1/reading")
        assert status == 200, message
        expected = nusense.decode_reading(json.dumps(message))
        same = earlier + collect(
            stream, lambda rs: any(r.capture_time_us == expected.capture_time_us for r in earlier + rs)
        )
    got = next(r for r in same if r.capture_time_us == expected.capture_time_us)
    assert got.frame_id == expected.frame_id
    assert got.reference_frame_id == expected.reference_frame_id
    assert got.latency_ms == expected.latency_ms
    assert got.estimate is not None and expected.estimate is not None
    assert got.estimate.force_n == expected.estimate.force_n
    np.testing.assert_array_equal(got.estimate.contact_centres_mm, expected.estimate.contact_centres_mm)
    np.testing.assert_array_equal(got.estimate.shear_field.current_px, expected.estimate.shear_field.current_px)
    np.testing.assert_array_equal(
        got.estimate.shear_field.displacement_mm, expected.estimate.shear_field.displacement_mm
    )


def test_tare_rests_only_that_sensor_on_a_new_frame(client: nusense.Client, serials: list[str]) -> None:
    tared, other = serials
    with client.readings(serials) as stream:
        before = collect(stream, lambda rs: all(len(of(rs, s)) >= 2 for s in serials))
        last_before = max(r.frame_id for r in of(before, tared))
        other_before = of(before, other)[-1]
        assert other_before.estimate is not None
        assert client.tare(tared) == "the next frame becomes the rest frame"
        after = collect(
            stream,
            lambda rs: any((r.reference_frame_id or 0) > last_before for r in of(rs, tared)),
        )
    rested = next(r for r in of(after, tared) if (r.reference_frame_id or 0) > last_before)
    assert rested.reference_frame_id is not None and rested.reference_frame_id <= rested.frame_id
    # The other sensor keeps its rest frame, unless its own estimator re-tared (counted in retare_count).
    for reading in of(after, other):
        assert reading.estimate is not None
        if reading.estimate.retare_count == other_before.estimate.retare_count:
            assert reading.reference_frame_id == other_before.reference_frame_id


def test_led_currents_reach_that_sensors_readings(client: nusense.Client, serials: list[str]) -> None:
    lit, other = serials
    reply = client.set_leds(lit, all=60)
    try:
        assert reply["board"]["connected"] is True
        with client.readings(serials) as stream:
            readings = collect(
                stream,
                lambda rs: any(
                    r.led is not None and (r.led.setpoint_ma == 60).all() for r in of(rs, lit)
                )
                and len(of(rs, other)) >= 5,
            )
        for reading in of(readings, other):
            assert reading.led is not None
            assert (reading.led.setpoint_ma == DEFAULT_LED_MA).all(), reading.led.setpoint_ma
    finally:
        client.set_leds(lit, all=DEFAULT_LED_MA)


@pytest.mark.parametrize(
    ("request_body", "message"),
    [
        ({"all": 500}, "Top LED current 500 mA is above the 120 mA limit"),
        ({"all": 50, "top": 3}, "give either `all` or per-side currents, not both"),
        ({}, "nothing to set: give currents in mA as `top`, `right`, `bottom`, `left` or `all`, and/or `enabled`"),
    ],
)
def test_an_invalid_led_request_raises_the_daemons_message_as_http_words_it(
    client: nusense.Client, daemon: Daemon, serials: list[str], request_body: dict[str, Any], message: str
) -> None:
    with pytest.raises(nusense.DaemonError) as refused:
        client.set_leds(serials[0], **request_body)
    assert refused.value.message == message
    assert refused.value.serial == serials[0]
    status, http_reply = daemon.http_json("PUT", "/api/v1/led", request_body)
    assert status == 422 and http_reply["error"] == message


def test_frame_is_the_cameras_jpeg(client: nusense.Client, serials: list[str]) -> None:
    jpeg = client.frame(serials[1])
    assert jpeg[:2] == b"\xff\xd8" and jpeg[-2:] == b"\xff\xd9"
    assert jpeg_size(jpeg) == (320, 240)


def test_a_serial_nobody_serves_gets_no_reply(client: nusense.Client, serials: list[str]) -> None:
    with pytest.raises(nusense.NoReplyError):
        client.status("NOT-A-SENSOR", timeout=0.5)


def test_the_example_script_runs_as_a_researcher_runs_it(daemon: Daemon, serials: list[str]) -> None:
    example = Path(__file__).resolve().parents[1] / "examples" / "live_readings.py"
    run = subprocess.run(
        [sys.executable, str(example), "--connect", daemon.endpoint, "--seconds", "2", "--every", "1", "--tare"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    for serial in serials:
        assert any(line.startswith(f"{serial}: nusense ") and "simulated, inverse mode" in line for line in lines), lines
        assert f"{serial}: tare: the next frame becomes the rest frame" in lines
        assert sum(line.startswith(f"{serial} frame ") for line in lines) >= 5, lines
        summary = next(line for line in lines if line.startswith(f"{serial}: ") and " readings in " in line)
        assert int(summary.split()[1]) >= 5, summary


def test_sensors_leave_the_list_when_the_daemon_stops(tmp_path: Path) -> None:
    daemon = start_daemon(2, tmp_path)
    try:
        with connect(daemon) as client:
            serials = serials_when_served(client, daemon, 2)
            with client.watch_sensors() as watch:
                arrived = {watch.get(timeout=10) for _ in serials}
                assert arrived == {nusense.SensorEvent(s, alive=True) for s in serials}
                assert daemon.stop() == 0, daemon.log_text()
                left = {watch.get(timeout=10) for _ in serials}
                assert left == {nusense.SensorEvent(s, alive=False) for s in serials}
            assert eventually(lambda: client.sensors(timeout=0.3) == [])
    finally:
        if daemon.process.poll() is None:
            daemon.stop()


def jpeg_size(jpeg: bytes) -> tuple[int, int]:
    """Width and height from a JPEG's start-of-frame marker."""
    i = 2
    while i + 9 < len(jpeg):
        assert jpeg[i] == 0xFF, f"not a JPEG marker at {i}"
        marker, length = jpeg[i + 1], int.from_bytes(jpeg[i + 2 : i + 4], "big")
        if marker in (0xC0, 0xC1, 0xC2):
            return int.from_bytes(jpeg[i + 7 : i + 9], "big"), int.from_bytes(jpeg[i + 5 : i + 7], "big")
        i += 2 + length
    raise AssertionError("no start-of-frame marker")
