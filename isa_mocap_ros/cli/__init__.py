"""isa_mocap_ros.cli."""
