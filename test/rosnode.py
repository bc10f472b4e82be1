"""An rclpy node inside the test process, on the test's private ROS domain (shared by node tests)."""
from __future__ import annotations

import contextlib
import os
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor


@contextlib.contextmanager
def ros_node(rosenv: dict[str, str], name: str):
    """An rclpy node of the test process in the test's ROS domain (own context, env restored after)."""
    saved = dict(os.environ)
    os.environ.update({k: v for k, v in rosenv.items() if k.startswith(("ROS_", "RMW_", "FASTRTPS_", "FASTDDS_"))})
    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node(name, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        yield node, ex
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        os.environ.clear()
        os.environ.update(saved)


def spin_until(ex, cond, timeout: float, *, step_s: float = 0.01) -> bool:
    """Spin ``ex`` until ``cond()`` holds or ``timeout`` seconds pass; returns ``cond()``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        ex.spin_once(timeout_sec=step_s)
    return bool(cond())


def masks_by_stamp(bag) -> tuple[dict[int, dict], dict]:
    """A bag's ``/mask`` and ``/camera_info`` messages by stamp (stamp ns -> {topic: message}) and its latched
    ``/extrinsics`` (topic -> message), as the estimator's tests and the mask feeder publish them."""
    import msg_adapters as ma
    from isa_mocap_ros.bag import BagReader

    frames: dict[int, dict] = {}
    latched: dict = {}
    with BagReader(bag) as r:
        for m in r.messages():
            msg = ma.from_cdr(m.data, m.type)
            if m.topic.endswith("/extrinsics"):
                latched[m.topic] = msg
            elif m.topic.endswith(("/mask", "/camera_info")):
                frames.setdefault(ma.stamp_to_ns(msg.header), {})[m.topic] = msg
    return frames, latched


def mask_publishers(node, frames: dict[int, dict], latched: dict) -> dict:
    """Publishers for every mask and camera_info topic in ``frames`` (from :func:`masks_by_stamp`), with the latched
    extrinsics published once on transient-local publishers (kept alive on ``node``); topic -> publisher."""
    from geometry_msgs.msg import TransformStamped
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from sensor_msgs.msg import CameraInfo, Image

    pubs = {t: node.create_publisher(Image if t.endswith("mask") else CameraInfo, t, 10)
            for t in sorted({t for f in frames.values() for t in f})}
    qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    for topic, msg in latched.items():
        node.create_publisher(TransformStamped, topic, qos).publish(msg)
    return pubs
