"""isa_mocap_ros: markerless multi-view human motion capture as a ROS 2 node network.

The core (``body``, ``geometry``, ``vision``, ``energy``, ``optim``, ``tracking``, ``bag``,
``eval``) is plain numpy/numba/OpenCV and imports no ROS; ``nodes`` and ``cli`` are the thin
rclpy layer, and the top-level ``msg_adapters`` package converts messages.
"""

__version__ = "0.1.0"
