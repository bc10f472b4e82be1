"""A tiny downstream node for lockstep tests: echoes each image's stamp as a JointState.

``python echo_node.py IN_TOPIC OUT_TOPIC DELAY_S [TOPIC:TYPE ...]`` — answers each image DELAY_S later (a slow
estimator) without blocking, and prints ``image <stamp> <t>`` on arrival and ``echo <stamp> <t>``
on publication (``t`` = monotonic seconds), so a test can check causality. ``TOPIC:TYPE`` (TYPE one of
CameraInfo, TransformStamped, JointState): also subscribed, ignored, so a player that waits for a subscriber on
every topic of its bag (``play --wait-for-subscribers``) starts once it sees this node, not at its time limit.
"""
import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from geometry_msgs.msg import TransformStamped
from sensor_msgs.msg import CameraInfo, Image, JointState

ALSO_TYPES = {"CameraInfo": CameraInfo, "TransformStamped": TransformStamped, "JointState": JointState}


def main() -> None:
    in_topic, out_topic, delay_s = sys.argv[1], sys.argv[2], float(sys.argv[3])
    rclpy.init()
    node = Node("echo")
    pub = node.create_publisher(JointState, out_topic, 10)
    pending = []

    def stamp_ns(header) -> int:
        return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec

    def on_image(msg: Image) -> None:
        now = time.monotonic()
        print(f"image {stamp_ns(msg.header)} {now:.6f}", flush=True)
        pending.append((now + delay_s, msg.header))

    def on_timer() -> None:
        now = time.monotonic()
        for item in list(pending):
            if item[0] <= now:
                pending.remove(item)
                pub.publish(JointState(header=item[1], name=["x"], position=[0.0]))
                print(f"echo {stamp_ns(item[1])} {time.monotonic():.6f}", flush=True)

    node.create_subscription(Image, in_topic, on_image, 10)
    for spec in sys.argv[4:]:
        topic, kind = spec.rsplit(":", 1)
        node.create_subscription(ALSO_TYPES[kind], topic, lambda msg: None, 10)
    node.create_timer(0.005, on_timer)
    print("echo ready", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
