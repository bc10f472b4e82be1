"""ROS 2 environment for child processes: localhost-only discovery, a private domain, our Fast DDS profile.

Pure (no rclpy import): it only shapes environment variables, so the CLI, the launcher and the
tests use one rule. A caller's ``ROS_DOMAIN_ID`` is honoured when ``keep_caller_domain`` is set
(``isa-mocap run`` does that so a user can subscribe while it runs).
"""
from __future__ import annotations

import os

# ROS 2 domain ids 0-101 are safe on Linux with the default port mapping (higher ids
# collide with ephemeral ports). Private ids are drawn from 10..99.
_PRIVATE_LO, _PRIVATE_HI = 10, 99


def private_domain_id(salt: int = 0) -> int:
    """A domain id for this process tree, derived from the pid so parallel runs rarely collide."""
    span = _PRIVATE_HI - _PRIVATE_LO + 1
    return _PRIVATE_LO + (os.getpid() * 7 + salt) % span


def ros_env(domain_id: int | None = None, *, keep_caller_domain: bool = False,
            base: dict[str, str] | None = None) -> dict[str, str]:
    """Return a copy of ``base`` (default ``os.environ``) set up for a private local ROS graph."""
    env = dict(os.environ if base is None else base)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(int(domain_id))
    elif not (keep_caller_domain and env.get("ROS_DOMAIN_ID")):
        env["ROS_DOMAIN_ID"] = str(private_domain_id())
    env.setdefault("PYTHONUNBUFFERED", "1")
    profile = fastdds_profile()
    if profile is not None and not (env.get("FASTRTPS_DEFAULT_PROFILES_FILE") or env.get("FASTDDS_DEFAULT_PROFILES_FILE")):
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile)
    return env


def fastdds_profile():
    """The package's Fast DDS profile (``config/fastdds.xml``: large shared-memory segment and socket
    buffers, 100 ms writer heartbeat, so multi-view image bursts are not repaired only every 3 s),
    or None where it is not installed."""
    from isa_mocap_ros.resources import resource_dir
    try:
        path = resource_dir("config") / "fastdds.xml"
    except FileNotFoundError:
        return None
    return path if path.is_file() else None
