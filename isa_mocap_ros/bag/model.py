"""Value types of the bag library: errors, offered QoS profiles, topics and messages.

The QoS vocabulary is the one rosbag2 stores (``rosbag2_storage/src/rosbag2_storage/qos.cpp``,
jazzy): metadata version 9 writes policy *names* (``keep_last``, ``reliable``,
``transient_local``, ...), version 8 and older write the rmw enum *integers*
(``rmw/types.h``: history SYSTEM_DEFAULT=0, KEEP_LAST=1, KEEP_ALL=2, UNKNOWN=3; reliability
SYSTEM_DEFAULT=0, RELIABLE=1, BEST_EFFORT=2, UNKNOWN=3, BEST_AVAILABLE=4; durability
SYSTEM_DEFAULT=0, TRANSIENT_LOCAL=1, VOLATILE=2, UNKNOWN=3, BEST_AVAILABLE=4; liveliness
SYSTEM_DEFAULT=0, AUTOMATIC=1, MANUAL_BY_NODE=2, MANUAL_BY_TOPIC=3, UNKNOWN=4,
BEST_AVAILABLE=5). Durations are ``{sec, nsec}`` pairs. Both spellings are read; each version
is written in its own spelling so a profile round-trips unchanged.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import yaml


class BagError(ValueError):
    """Every failure of the bag library; the message names the file or field, expected and received."""


HISTORY = ("system_default", "keep_last", "keep_all", "unknown")
RELIABILITY = ("system_default", "reliable", "best_effort", "unknown", "best_available")
DURABILITY = ("system_default", "transient_local", "volatile", "unknown", "best_available")
LIVELINESS = ("system_default", "automatic", "manual_by_node", "manual_by_topic", "unknown",
              "best_available")
_POLICIES = {"history": HISTORY, "reliability": RELIABILITY, "durability": DURABILITY,
             "liveliness": LIVELINESS}
_DURATIONS = ("deadline", "lifespan", "liveliness_lease_duration")


def _check_duration(name: str, value: Any) -> tuple[int, int]:
    if (not isinstance(value, (tuple, list)) or len(value) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value)):
        raise BagError(f"QosProfile.{name}: expected a (sec, nsec) pair of non-negative ints, "
                       f"received {value!r}")
    return int(value[0]), int(value[1])


@dataclass(frozen=True)
class QosProfile:
    """One offered QoS profile, in rosbag2's metadata vocabulary.

    Durations are ``(sec, nsec)`` pairs; ``(0, 0)`` is rmw's "default/unspecified" and
    ``(9223372036, 854775807)`` its "infinite", both kept as recorded.
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline: tuple[int, int] = (0, 0)
    lifespan: tuple[int, int] = (0, 0)
    liveliness: str = "system_default"
    liveliness_lease_duration: tuple[int, int] = (0, 0)
    avoid_ros_namespace_conventions: bool = False

    def __post_init__(self) -> None:
        for name, allowed in _POLICIES.items():
            value = getattr(self, name)
            if value not in allowed:
                raise BagError(f"QosProfile.{name}: expected one of {list(allowed)}, received {value!r}")
        if not isinstance(self.depth, int) or isinstance(self.depth, bool) or self.depth < 0:
            raise BagError(f"QosProfile.depth: expected an int >= 0, received {self.depth!r}")
        for name in _DURATIONS:
            object.__setattr__(self, name, _check_duration(name, getattr(self, name)))
        if not isinstance(self.avoid_ros_namespace_conventions, bool):
            raise BagError("QosProfile.avoid_ros_namespace_conventions: expected a bool, received "
                           f"{self.avoid_ros_namespace_conventions!r}")

    @property
    def latched(self) -> bool:
        """True when the publisher keeps its last messages for late joiners (transient_local)."""
        return self.durability == "transient_local"

    def to_dict(self, *, version: int = 9) -> dict[str, Any]:
        """The rosbag2 metadata mapping: policy names for version >= 9, rmw integers before."""
        out: dict[str, Any] = {}
        for key in ("history", "depth", "reliability", "durability", "deadline", "lifespan",
                    "liveliness", "liveliness_lease_duration", "avoid_ros_namespace_conventions"):
            value = getattr(self, key)
            if key in _POLICIES:
                value = value if version >= 9 else _POLICIES[key].index(value)
            elif key in _DURATIONS:
                value = {"sec": value[0], "nsec": value[1]}
            out[key] = value
        return out

    @classmethod
    def from_dict(cls, item: Mapping[str, Any], *, where: str = "offered_qos_profiles") -> "QosProfile":
        """Parse one profile written by any rosbag2 version (names or rmw integers).

        Raises
        ------
        BagError
            When a field is missing or has a value outside rosbag2's vocabulary; ``where`` names
            the place (file and topic) in the message.
        """
        if not isinstance(item, Mapping):
            raise BagError(f"{where}: expected a mapping per QoS profile, received {item!r}")
        kwargs: dict[str, Any] = {}
        for key, allowed in _POLICIES.items():
            if key not in item:
                continue
            value = item[key]
            if isinstance(value, int) and not isinstance(value, bool):
                if not 0 <= value < len(allowed):
                    raise BagError(f"{where}: {key} expected an rmw enum value in 0..{len(allowed) - 1}, "
                                   f"received {value!r}")
                value = allowed[value]
            elif isinstance(value, str):
                value = value.strip().lower()
                if value not in allowed:
                    raise BagError(f"{where}: {key} expected one of {list(allowed)}, received {item[key]!r}")
            else:
                raise BagError(f"{where}: {key} expected a name or an int, received {value!r}")
            kwargs[key] = value
        if "depth" in item:
            kwargs["depth"] = item["depth"]
        for key in _DURATIONS:
            if key in item:
                d = item[key]
                if not isinstance(d, Mapping) or "sec" not in d or "nsec" not in d:
                    raise BagError(f"{where}: {key} expected {{sec: int, nsec: int}}, received {d!r}")
                kwargs[key] = (d["sec"], d["nsec"])
        if "avoid_ros_namespace_conventions" in item:
            kwargs["avoid_ros_namespace_conventions"] = bool(item["avoid_ros_namespace_conventions"])
        try:
            return cls(**kwargs)
        except BagError as exc:
            raise BagError(f"{where}: {exc}") from None


QOS_DEFAULT = QosProfile()
QOS_LATCHED = QosProfile(depth=1, durability="transient_local")


def qos_to_yaml(profiles: Sequence[QosProfile], *, version: int = 9) -> str:
    """The YAML text rosbag2 stores in MCAP channel metadata (and in v8 metadata.yaml)."""
    if not profiles:
        return ""
    return yaml.safe_dump([p.to_dict(version=version) for p in profiles], sort_keys=False,
                          default_flow_style=False).strip()


def qos_from_yaml(value: Any, *, where: str = "offered_qos_profiles") -> tuple[QosProfile, ...]:
    """Parse offered QoS profiles given as a YAML string (v8, MCAP channels) or a list (v9)."""
    if value is None or value == "" or value == []:
        return ()
    if isinstance(value, str):
        try:
            value = yaml.safe_load(value)
        except yaml.YAMLError as exc:
            raise BagError(f"{where}: expected YAML text, could not parse it: {exc}") from None
        if value is None:
            return ()
    if not isinstance(value, list):
        raise BagError(f"{where}: expected a list of QoS profiles, received {value!r}")
    return tuple(QosProfile.from_dict(item, where=where) for item in value)


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: name, ROS type (``sensor_msgs/msg/Image``), encoding, QoS and count."""

    name: str
    type: str
    serialization_format: str = "cdr"
    offered_qos: tuple[QosProfile, ...] = ()
    message_count: int = 0
    type_description_hash: str = ""

    @property
    def latched(self) -> bool:
        """True when any recorded publisher offered transient_local durability."""
        return any(q.latched for q in self.offered_qos)


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: its topic and type, times in ns, and the CDR bytes as recorded."""

    topic: str
    type: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes = field(repr=False)
