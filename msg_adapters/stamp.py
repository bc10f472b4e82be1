"""``builtin_interfaces/msg/Time`` and ``std_msgs/msg/Header`` ⇄ integer nanoseconds.

Source: the ROS 2 message definitions ``builtin_interfaces/msg/Time`` (``int32 sec``,
``uint32 nanosec`` with ``nanosec < 1e9``) and ``std_msgs/msg/Header`` (``stamp``, ``frame_id``).
Integer nanoseconds are exact where float seconds are not (a float64 holds only ~16 digits, so
stamps of today lose sub-microsecond resolution); the core and the bags use ints.
"""
from __future__ import annotations

from typing import Any

from builtin_interfaces.msg import Time
from std_msgs.msg import Header

from .errors import AdapterError, as_int, as_str

__all__ = ["stamp_to_ns", "ns_to_stamp", "make_header"]

NS_PER_S = 1_000_000_000
INT32_MAX = 2**31 - 1
INT32_MIN = -(2**31)
MAX_STAMP_NS = INT32_MAX * NS_PER_S + NS_PER_S - 1


def stamp_to_ns(stamp_or_header: Any) -> int:
    """Nanoseconds of a ``Time`` or of a ``Header``'s stamp.

    Parameters
    ----------
    stamp_or_header : builtin_interfaces.msg.Time or std_msgs.msg.Header
        Also accepts anything with ``.stamp`` or ``.sec``/``.nanosec`` (rosbags messages).

    Returns
    -------
    int
        ``sec * 10**9 + nanosec`` (negative for a negative ``sec``, which ``int32`` allows).

    Raises
    ------
    AdapterError
        Neither a stamp nor a header, ``sec`` outside int32, ``nanosec`` outside [0, 1e9).
    """
    obj = stamp_or_header
    name = "stamp"
    if hasattr(obj, "stamp"):
        obj = obj.stamp
        name = "header.stamp"
    if not (hasattr(obj, "sec") and hasattr(obj, "nanosec")):
        raise AdapterError(name, "a builtin_interfaces/msg/Time or std_msgs/msg/Header",
                           type(stamp_or_header).__name__)
    sec = as_int(f"{name}.sec", obj.sec, lo=INT32_MIN, hi=INT32_MAX)
    nanosec = as_int(f"{name}.nanosec", obj.nanosec, lo=0, hi=NS_PER_S - 1)
    return sec * NS_PER_S + nanosec


def ns_to_stamp(ns: int) -> Time:
    """A ``builtin_interfaces/msg/Time`` for ``ns`` nanoseconds since the epoch.

    Raises
    ------
    AdapterError
        ``ns`` not an integer, negative, or beyond int32 seconds.
    """
    ns = as_int("stamp_ns", ns, lo=0, hi=MAX_STAMP_NS)
    sec, nanosec = divmod(ns, NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def make_header(stamp_ns: int, frame_id: str = "") -> Header:
    """A ``std_msgs/msg/Header`` with the stamp ``stamp_ns`` (ns) and ``frame_id``."""
    return Header(stamp=ns_to_stamp(stamp_ns), frame_id=as_str("frame_id", frame_id))
