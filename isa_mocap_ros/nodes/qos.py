"""Conversions between rclpy QoS profiles and the bag library's ``QosProfile`` (rosbag2 vocabulary).

Recorder and player use them so offered QoS survives a record/replay round trip: a latched
(transient-local) topic stays latched on replay, as ``ros2 bag`` does.
"""
from __future__ import annotations

from typing import Iterable

from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)

from isa_mocap_ros.bag import QosProfile

_HISTORY = {"keep_last": HistoryPolicy.KEEP_LAST, "keep_all": HistoryPolicy.KEEP_ALL,
            "system_default": HistoryPolicy.SYSTEM_DEFAULT}
_RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT,
                "system_default": ReliabilityPolicy.SYSTEM_DEFAULT}
_DURABILITY = {"volatile": DurabilityPolicy.VOLATILE, "transient_local": DurabilityPolicy.TRANSIENT_LOCAL,
               "system_default": DurabilityPolicy.SYSTEM_DEFAULT}

LATCHED = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
RELIABLE = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
SENSOR_DATA = qos_profile_sensor_data


def _name(policy) -> str:
    return policy.name.lower()


def to_rclpy(profile: QosProfile) -> QoSProfile:
    """Our bag ``QosProfile`` -> rclpy ``QoSProfile`` (unknown policies fall back to system default)."""
    depth = max(1, int(getattr(profile, "depth", 10) or 10))
    return QoSProfile(
        depth=depth,
        history=_HISTORY.get(profile.history, HistoryPolicy.KEEP_LAST),
        reliability=_RELIABILITY.get(profile.reliability, ReliabilityPolicy.RELIABLE),
        durability=_DURABILITY.get(profile.durability, DurabilityPolicy.VOLATILE),
    )


def from_rclpy(profile: QoSProfile) -> QosProfile:
    """rclpy ``QoSProfile`` (e.g. a discovered publisher's) -> our bag ``QosProfile``."""
    return QosProfile(
        history=_name(profile.history) if profile.history != HistoryPolicy.UNKNOWN else "keep_last",
        depth=int(profile.depth),
        reliability=_name(profile.reliability),
        durability=_name(profile.durability),
    )


def subscription_qos_for(offered: Iterable[QoSProfile]) -> QoSProfile:
    """The subscription QoS that matches every offered profile and still receives latched data.

    Like rosbag2's adaptive QoS: reliable only if every publisher is reliable, transient-local only
    if every publisher is transient-local (otherwise a volatile publisher would not match).
    """
    offered = list(offered)
    if not offered:
        return RELIABLE
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in offered)
    latched = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered)
    return QoSProfile(
        depth=100,
        history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def playback_qos(profiles: Iterable[QosProfile]) -> QoSProfile:
    """The QoS the player offers for a recorded topic: the recorded one, latched if any was latched."""
    profiles = list(profiles)
    if not profiles:
        return RELIABLE
    chosen = next((p for p in profiles if p.durability == "transient_local"), profiles[0])
    qos = to_rclpy(chosen)
    if qos.durability != DurabilityPolicy.TRANSIENT_LOCAL and qos.history == HistoryPolicy.KEEP_LAST:
        # A replay publishes bursts (all views of a frame at once, or faster than real time): a
        # deeper writer history lets a briefly busy reliable subscriber catch up instead of losing
        # samples. Depth is not part of QoS matching, so compatibility is unchanged.
        qos.depth = max(qos.depth, 100)
    return qos
