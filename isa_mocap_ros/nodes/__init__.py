"""isa_mocap_ros.nodes."""
