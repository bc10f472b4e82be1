"""Small real bags for tests: V views of a moving blob, camera infos, latched extrinsics, joint states.

Messages are real rclpy messages serialized to CDR; all views of a frame share one header stamp
and one log time, as ``isa-mocap synth`` writes them.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, Image, JointState
from geometry_msgs.msg import TransformStamped

from isa_mocap_ros.bag import QOS_LATCHED, BagWriter

T0_NS = 1_700_000_000_000_000_000


def frame_stamps(n_frames: int, fps: float = 30.0) -> list[int]:
    return [T0_NS + int(round(k * 1e9 / fps)) for k in range(n_frames)]


def _stamp(msg, ns: int, frame_id: str) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
    msg.header.frame_id = frame_id


def write_test_bag(path: Path, *, views: int = 2, frames: int = 10, width: int = 64, height: int = 48,
                   fps: float = 30.0, seed: int = 0, version: int = 9) -> dict[str, int]:
    """Write a rosbag2 MCAP bag; returns the message count per topic."""
    rng = np.random.default_rng(seed)
    counts: dict[str, int] = {}
    with BagWriter(path, version=version) as w:
        for v in range(views):
            w.add_topic(f"/mocap/cam{v}/image_raw", "sensor_msgs/msg/Image")
            w.add_topic(f"/mocap/cam{v}/camera_info", "sensor_msgs/msg/CameraInfo")
            w.add_topic(f"/mocap/cam{v}/extrinsics", "geometry_msgs/msg/TransformStamped", qos=[QOS_LATCHED])
        w.add_topic("/mocap/ground_truth/joint_states", "sensor_msgs/msg/JointState")

        def put(topic: str, msg, ns: int) -> None:
            w.write(topic, bytes(serialize_message(msg)), ns)
            counts[topic] = counts.get(topic, 0) + 1

        stamps = frame_stamps(frames, fps)
        for v in range(views):
            tf = TransformStamped()
            _stamp(tf, stamps[0], "world")
            tf.child_frame_id = f"cam{v}_optical_frame"
            tf.transform.translation.x = float(v)
            tf.transform.rotation.w = 1.0
            put(f"/mocap/cam{v}/extrinsics", tf, stamps[0])
        yy, xx = np.mgrid[0:height, 0:width]
        for k, ns in enumerate(stamps):
            for v in range(views):
                img = rng.integers(0, 40, size=(height, width, 3), dtype=np.uint8)
                cx, cy = (k * 3 + v * 7) % width, height / 2
                img[((xx - cx) ** 2 / 36 + (yy - cy) ** 2 / 100) < 1] = (200, 60, 40)
                msg = Image(height=height, width=width, encoding="rgb8", is_bigendian=0, step=width * 3)
                msg.data = img.tobytes()
                _stamp(msg, ns, f"cam{v}_optical_frame")
                put(f"/mocap/cam{v}/image_raw", msg, ns)
                info = CameraInfo(height=height, width=width, distortion_model="plumb_bob")
                info.k = [100.0, 0.0, width / 2, 0.0, 100.0, height / 2, 0.0, 0.0, 1.0]
                info.d = [0.0] * 5
                info.p = [100.0, 0.0, width / 2, 0.0, 0.0, 100.0, height / 2, 0.0, 0.0, 0.0, 1.0, 0.0]
                info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
                _stamp(info, ns, f"cam{v}_optical_frame")
                put(f"/mocap/cam{v}/camera_info", info, ns)
            js = JointState(name=["left_knee", "right_knee"], position=[0.1 * k, -0.1 * k])
            _stamp(js, ns, "")
            put("/mocap/ground_truth/joint_states", js, ns)
    return counts
