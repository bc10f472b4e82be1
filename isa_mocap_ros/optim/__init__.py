"""isa_mocap_ros.optim."""
