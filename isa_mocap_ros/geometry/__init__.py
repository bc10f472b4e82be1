"""isa_mocap_ros.geometry."""
