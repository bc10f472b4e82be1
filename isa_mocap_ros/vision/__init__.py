"""isa_mocap_ros.vision."""
