"""Subscribe to the estimated body pose from your own rclpy node.

Run it beside `isa-mocap run` (same ROS_DOMAIN_ID) or any live network:

    ROS_DOMAIN_ID=42 isa-mocap run --lockstep &
    ROS_DOMAIN_ID=42 python examples/subscribe_joint_states.py --count 10

Each message is a sensor_msgs/JointState: root_tx/ty/tz (metres), root_rx/ry/rz (roll/pitch/yaw,
radians, R = Rz Ry Rx), then one angle per body DOF (e.g. left_knee_y), stamped with the frame's
camera stamp.
"""
import argparse

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import JointState


class PoseListener(Node):
    def __init__(self, count: int) -> None:
        super().__init__("pose_listener")
        self.count = count
        self.received = 0
        self.create_subscription(JointState, "/mocap/joint_states", self.on_pose, 10)

    def on_pose(self, msg: JointState) -> None:
        pose = dict(zip(msg.name, msg.position))
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self.get_logger().info(
            f"t={stamp:.3f} root=({pose['root_tx']:.3f}, {pose['root_ty']:.3f}, {pose['root_tz']:.3f}) m "
            f"left knee={pose.get('left_knee_y', float('nan')):.3f} rad")
        self.received += 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=0, help="exit after this many poses (0 = run forever)")
    args = parser.parse_args()
    rclpy.init()
    node = PoseListener(args.count)
    try:
        while rclpy.ok() and (args.count == 0 or node.received < args.count):
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
