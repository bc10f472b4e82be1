"""isa_mocap_ros.bag."""
