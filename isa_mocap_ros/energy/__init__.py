"""isa_mocap_ros.energy."""
