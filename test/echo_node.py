"""A tiny downstream node for lockstep tests: echoes each image's stamp as a JointState.

``python echo_node.py IN_TOPIC OUT_TOPIC DELAY_S`` — waits DELAY_S per message (a slow estimator).
"""
import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import Image, JointState


def main() -> None:
    in_topic, out_topic, delay_s = sys.argv[1], sys.argv[2], float(sys.argv[3])
    rclpy.init()
    node = Node("echo")
    pub = node.create_publisher(JointState, out_topic, 10)

    def on_image(msg: Image) -> None:
        time.sleep(delay_s)
        pub.publish(JointState(header=msg.header, name=["x"], position=[0.0]))

    node.create_subscription(Image, in_topic, on_image, 10)
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
