"""isa_mocap_ros.bag: rosbag2 MCAP bags without ROS -- read, write, inspect, repair.

Pure library (no rclpy, no ``*_msgs``): the container is MCAP (``mcap``), message definitions
come from the rosbags Jazzy typestore, messages stay CDR bytes. Format conventions follow
rosbag2's jazzy MCAP storage plugin and ``metadata.yaml`` layout (versions 8 and 9); see
``docs/bags.md``.
"""
from .info import bag_info, format_bag_info
from .metadata import BagMetadata, read_metadata, write_metadata
from .model import QOS_DEFAULT, QOS_LATCHED, BagError, BagMessage, QosProfile, TopicInfo
from .reader import BagReader
from .repair import repair_bag
from .writer import BagWriter, msgdef_for

__all__ = [
    "BagError", "QosProfile", "QOS_DEFAULT", "QOS_LATCHED", "TopicInfo", "BagMessage",
    "BagReader", "BagWriter", "bag_info", "format_bag_info", "repair_bag",
    "BagMetadata", "read_metadata", "write_metadata", "msgdef_for",
]
