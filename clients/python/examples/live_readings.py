#!/usr/bin/env python3
"""Every NUSense sensor on the network, live: each one's status, then its readings for a few seconds (force,
contacts, the largest shear of the pad), and how many readings per second arrived.

    nusense serve --sim --zenoh              # one terminal: a simulated sensor
    python3 examples/live_readings.py        # another: this script
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

import nusense

def describe(reading: nusense.Reading) -> str:
    head = f"{reading.serial} frame {reading.frame_id:6d} ({reading.latency_ms:5.1f} ms)"
    estimate = reading.estimate
    if estimate is None:
        return f"{head}: no estimate: {reading.error}"
    # The pad's own motion at each lattice corner, mm; NaN where a frame missed the corner.
    shear_mm = np.linalg.norm(estimate.shear_field.displacement_mm, axis=1)
    largest_shear = np.nanmax(shear_mm) if np.isfinite(shear_mm).any() else float("nan")
    if not estimate.contact:
        return f"{head}: no contact, largest shear {largest_shear:.3f} mm"
    centres = "; ".join(f"({x:+.1f}, {y:+.1f}) mm" for x, y in estimate.contact_centres_mm)
    return (
        f"{head}: {estimate.force_n:5.2f} N, {len(estimate.contacts)} contact(s) at {centres}, "
        f"largest shear {largest_shear:.3f} mm"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"Zenoh endpoint of a daemon or a router, repeatable (default: {nusense.DEFAULT_ENDPOINT})",
    )
    parser.add_argument("--seconds", type=float, default=5.0, help="how long to stream (default: 5)")
    parser.add_argument("--every", type=int, default=10, help="print every Nth reading of each sensor (default: 10)")
    parser.add_argument("--tare", action="store_true", help="tare every sensor before streaming")
    args = parser.parse_args()

    with nusense.connect(args.connect or [nusense.DEFAULT_ENDPOINT]) as client:
        serials = client.sensors()
        if not serials:
            print("no sensor answered: is `nusense serve --zenoh` running?", file=sys.stderr)
            return 1
        for serial in serials:
            status = client.status(serial)
            kind = "simulated" if status.simulator else "camera"
            problems = "; ".join(status.problems) or "none"
            print(f"{serial}: nusense {status.version}, {kind}, {status.mode} mode, problems: {problems}")
            if args.tare:
                print(f"{serial}: tare: {client.tare(serial)}")

        counts = dict.fromkeys(serials, 0)
        start = time.monotonic()
        with client.readings(serials) as stream:
            while (left := start + args.seconds - time.monotonic()) > 0:
                try:
                    reading = stream.get(timeout=left)
                except TimeoutError:
                    break
                assert reading.serial is not None
                counts[reading.serial] += 1
                if counts[reading.serial] % args.every == 1 or args.every == 1:
                    print(describe(reading))
            dropped = stream.dropped
        elapsed = time.monotonic() - start
        for serial, count in counts.items():
            print(f"{serial}: {count} readings in {elapsed:.1f} s ({count / elapsed:.1f} per second)")
        if dropped:
            print(f"{dropped} readings dropped: this script printed slower than they came")
    return 0


if __name__ == "__main__":
    sys.exit(main())
