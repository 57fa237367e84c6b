#!/usr/bin/env python3
"""Golden CDR bytes for the ROS 2 messages `nusense serve --ros2` publishes, made by an implementation that
shares no code with ours: the pure-Python `rosbags` package, its ROS 2 Jazzy message definitions and its CDR
serializer. host/ros2/src/messages/golden_tests.rs builds the same messages from the same values and checks that
its bytes (encapsulation header included) equal these byte for byte.

Regenerate (only needed when the values below change):
    python3 -m venv /tmp/rosbags && /tmp/rosbags/bin/pip install rosbags==0.11.9
    /tmp/rosbags/bin/python host/ros2/testdata/generate_golden.py
"""

import math
import struct
from pathlib import Path

from rosbags.typesys import Stores, get_typestore

HERE = Path(__file__).resolve().parent
STORE = get_typestore(Stores.ROS2_JAZZY)
T = STORE.types

FRAME_ID = "nusense_VB0001_pad"
# 2026-11-23 17:55:00.123456 UTC: a capture time in microseconds as the daemon has it.
CAPTURE_TIME_US = 1_795_456_500_123_456


def stamp():
    return T["builtin_interfaces/msg/Time"](
        sec=CAPTURE_TIME_US // 1_000_000, nanosec=(CAPTURE_TIME_US % 1_000_000) * 1000
    )


def header():
    return T["std_msgs/msg/Header"](stamp=stamp(), frame_id=FRAME_ID)


def vector3(x, y, z):
    return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def wrench_stamped():
    wrench = T["geometry_msgs/msg/Wrench"](
        force=vector3(0.25, -0.5, 3.75), torque=vector3(0.0375, 0.01875, -0.000125)
    )
    return T["geometry_msgs/msg/WrenchStamped"](header=header(), wrench=wrench)


def compressed_image():
    # A JPEG's first and last bytes, 7 of them: an odd length shows that nothing pads the end.
    data = bytes([0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0xFF, 0xD9])
    import numpy

    return T["sensor_msgs/msg/CompressedImage"](
        header=header(), format="jpeg", data=numpy.frombuffer(data, dtype=numpy.uint8)
    )


CONTACT_FIELDS = ["x", "y", "z", "fx", "fy", "fz", "tz", "area"]


def contacts():
    """Two contacts as the point cloud the daemon publishes: float32 fields in this order, 32 bytes a point."""
    import numpy

    PointField = T["sensor_msgs/msg/PointField"]
    fields = [
        PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
        for i, name in enumerate(CONTACT_FIELDS)
    ]
    points = [
        # centre (m), force vector (N), torque about the normal (N m), area (m^2)
        [0.0125, -0.004, 0.0, 0.125, -0.25, 2.5, 0.0005, 0.00003],
        # a mode without the traction inverse: tangential force, torque and area not measured (NaN)
        [-0.002, 0.0075, 0.0, math.nan, math.nan, 1.25, math.nan, math.nan],
    ]
    data = b"".join(struct.pack("<8f", *p) for p in points)
    return T["sensor_msgs/msg/PointCloud2"](
        header=header(),
        height=1,
        width=len(points),
        fields=fields,
        is_bigendian=False,
        point_step=32,
        row_step=32 * len(points),
        data=numpy.frombuffer(data, dtype=numpy.uint8),
        is_dense=False,
    )


def main():
    messages = {
        "time": (stamp(), "builtin_interfaces/msg/Time"),
        "header": (header(), "std_msgs/msg/Header"),
        "wrench_stamped": (wrench_stamped(), "geometry_msgs/msg/WrenchStamped"),
        "compressed_image": (compressed_image(), "sensor_msgs/msg/CompressedImage"),
        "contacts": (contacts(), "sensor_msgs/msg/PointCloud2"),
    }
    for name, (message, typename) in messages.items():
        data = bytes(STORE.serialize_cdr(message, typename, little_endian=True))
        (HERE / f"{name}.cdr").write_bytes(data)
        print(f"{name}.cdr: {typename}, {len(data)} bytes")


if __name__ == "__main__":
    main()
