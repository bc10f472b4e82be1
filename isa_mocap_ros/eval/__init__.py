"""isa_mocap_ros.eval."""
