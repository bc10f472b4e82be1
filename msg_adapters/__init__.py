"""ROS 2 message adapters (filled in by the adapters work)."""
