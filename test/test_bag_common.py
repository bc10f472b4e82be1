"""Shared builders for the bag tests: real messages serialized by rclpy (tests only)."""
from __future__ import annotations

from pathlib import Path

from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image, JointState

from isa_mocap_ros.bag import QOS_DEFAULT, QOS_LATCHED, BagWriter, QosProfile

BEST_EFFORT = QosProfile(history="keep_last", depth=5, reliability="best_effort", durability="volatile",
                         deadline=(1, 500), lifespan=(9223372036, 854775807), liveliness="automatic",
                         liveliness_lease_duration=(2, 0))


def image_msg(i: int) -> Image:
    m = Image()
    m.header.stamp.sec = 100 + i
    m.header.stamp.nanosec = 1000 * i
    m.header.frame_id = f"cam{i % 3}"
    m.height, m.width, m.step = 2, 3, 3
    m.encoding = "mono8"
    m.data = bytes((i + k) % 256 for k in range(6))
    return m


def joint_msg(i: int) -> JointState:
    m = JointState()
    m.header.stamp.sec = 100 + i
    m.name = ["hip", "knee"]
    m.position = [0.5 * i, -0.25 * i]
    return m


def write_sample_bag(path: Path, *, n: int = 12, version: int = 9, compression: str = "zstd",
                     chunk_size: int = 600) -> list[tuple[str, int, bytes]]:
    """Write ``n`` images and ``n`` joint states, interleaved and slightly out of order.

    Returns the written ``(topic, log_time_ns, data)`` in log-time order (ties: write order).
    """
    written = []
    with BagWriter(path, version=version, compression=compression, chunk_size=chunk_size) as w:
        w.add_topic("/cam/image", "sensor_msgs/msg/Image", qos=[QOS_DEFAULT, BEST_EFFORT])
        w.add_topic("/joint_states", "sensor_msgs/msg/JointState", qos=[QOS_LATCHED])
        w.add_topic("/unused", "sensor_msgs/msg/JointState")
        for i in range(n):
            t = 1_700_000_000_000_000_000 + i * 10_000_000
            img = serialize_message(image_msg(i))
            js = serialize_message(joint_msg(i))
            # the joint state of frame i is logged before the image of frame i
            w.write("/cam/image", img, t + 5, publish_time_ns=t)
            w.write("/joint_states", js, t + 1)
            written += [("/cam/image", t + 5, img), ("/joint_states", t + 1, js)]
    return sorted(written, key=lambda x: x[1])
