"""A ROS 2 subscriber that is not ours: Eclipse Cyclone DDS (the `cyclonedds` package, its C library inside the
wheel), reading `geometry_msgs/msg/WrenchStamped` from `nusense serve --ros2` as any DDS participant would. The
structs below are the ROS 2 types as rosidl maps them to DDS (type `geometry_msgs::msg::dds_::WrenchStamped_`,
topic `rt/<ros topic>`); nothing is shared with the daemon's encoder.

With --image-topic it also reads `sensor_msgs/msg/CompressedImage` (large: many RTPS fragments per frame).

Prints one JSON line per sample to stdout; exits after --count wrenches from each reader (and --images frames), or
fails after --timeout.

Usage: ros2_subscriber.py --domain D --topic /nusense/<sensor>/wrench [--count N] [--timeout S] [--localhost]
           [--image-topic /nusense/<sensor>/image/compressed --images N]
"""

import argparse
import base64
import json
import os
import sys
import time
from dataclasses import dataclass


def cyclone_config(localhost):
    # What ROS 2 Jazzy's rmw_cyclonedds does for ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST: loopback only, no
    # multicast, unicast discovery to this machine's well-known ports.
    if not localhost:
        return None
    return (
        "<CycloneDDS><Domain><General><Interfaces><NetworkInterface address=\"127.0.0.1\"/></Interfaces>"
        "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
        "<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex><Peers><Peer address=\"127.0.0.1\"/></Peers>"
        "</Discovery></Domain></CycloneDDS>"
    )


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--topic", required=True)
    parser.add_argument("--count", type=int, default=10)
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument("--localhost", action="store_true")
    parser.add_argument("--image-topic")
    parser.add_argument("--images", type=int, default=1)
    args = parser.parse_args()

    config = cyclone_config(args.localhost)
    if config is not None:
        os.environ["CYCLONEDDS_URI"] = config

    # Imported after CYCLONEDDS_URI is set: the C library reads it when the domain is created.
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.idl import IdlStruct
    from cyclonedds.idl.types import float64, int32, sequence, uint8, uint32
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    @dataclass
    class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
        sec: int32
        nanosec: uint32

    @dataclass
    class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
        stamp: Time
        frame_id: str

    @dataclass
    class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
        x: float64
        y: float64
        z: float64

    @dataclass
    class Wrench(IdlStruct, typename="geometry_msgs::msg::dds_::Wrench_"):
        force: Vector3
        torque: Vector3

    @dataclass
    class WrenchStamped(IdlStruct, typename="geometry_msgs::msg::dds_::WrenchStamped_"):
        header: Header
        wrench: Wrench

    @dataclass
    class CompressedImage(IdlStruct, typename="sensor_msgs::msg::dds_::CompressedImage_"):
        header: Header
        format: str
        data: sequence[uint8]

    participant = DomainParticipant(args.domain)
    topic = Topic(participant, "rt" + args.topic, WrenchStamped)
    # ROS's default subscription (reliable, keep last 10) and SensorDataQoS (best effort, keep last 5): a driver
    # that follows REP 2003 reaches both.
    readers = {
        "reliable": DataReader(
            participant,
            topic,
            qos=Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(10)),
        ),
        "best_effort": DataReader(
            participant, topic, qos=Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
        ),
    }
    received = {name: 0 for name in readers}
    images = None
    images_received = 0
    if args.image_topic:
        image_topic = Topic(participant, "rt" + args.image_topic, CompressedImage)
        images = DataReader(
            participant,
            image_topic,
            qos=Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(10)),
        )
    deadline = time.monotonic() + args.timeout
    while min(received.values()) < args.count or (images is not None and images_received < args.images):
        if time.monotonic() > deadline:
            print(f"timed out; wrenches per reader: {received}, images: {images_received}", file=sys.stderr)
            return 1
        for name, reader in readers.items():
            for sample in reader.take(N=100):
                if received[name] >= args.count:
                    continue
                received[name] += 1
                w = sample.wrench
                print(
                    json.dumps(
                        {
                            "reader": name,
                            "sec": sample.header.stamp.sec,
                            "nanosec": sample.header.stamp.nanosec,
                            "frame_id": sample.header.frame_id,
                            "force": [w.force.x, w.force.y, w.force.z],
                            "torque": [w.torque.x, w.torque.y, w.torque.z],
                        }
                    ),
                    flush=True,
                )
        if images is not None:
            for sample in images.take(N=10):
                if images_received >= args.images:
                    continue
                images_received += 1
                print(
                    json.dumps(
                        {
                            "reader": "image",
                            "sec": sample.header.stamp.sec,
                            "nanosec": sample.header.stamp.nanosec,
                            "frame_id": sample.header.frame_id,
                            "format": sample.format,
                            "data": base64.b64encode(bytes(sample.data)).decode(),
                        }
                    ),
                    flush=True,
                )
        time.sleep(0.01)
    return 0


if __name__ == "__main__":
    sys.exit(main())
