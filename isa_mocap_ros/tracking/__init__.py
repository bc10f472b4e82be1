"""isa_mocap_ros.tracking."""
