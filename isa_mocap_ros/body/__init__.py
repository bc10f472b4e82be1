"""isa_mocap_ros.body."""
