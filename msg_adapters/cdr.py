"""rclpy messages ⇄ CDR bytes, message types by name, and the header stamp read straight from CDR.

Source: the OMG DDS-XTypes 1.3 §7.4.3 encapsulation header (2 bytes representation id,
``00 00`` = CDR big endian, ``00 01`` = CDR little endian, then 2 option bytes) followed by
OMG CDR (CORBA 3.0 §15.3: primitives aligned to their size relative to the byte after the
encapsulation). ROS 2 (rmw_fastrtps, rmw_cyclonedds) and rosbag2/MCAP ``cdr`` channels use
XCDR1 plain CDR. A message whose first field is a ``std_msgs/msg/Header`` therefore starts
``[encapsulation:4][sec:int32][nanosec:uint32][frame_id length:uint32]...``, which lets the
player and recorder read a stamp from 12 bytes without deserializing the whole message.
"""
from __future__ import annotations

import functools
import importlib
import re
import struct
from typing import Any

from rclpy.serialization import deserialize_message, serialize_message

from .errors import AdapterError, Received

__all__ = ["to_cdr", "from_cdr", "message_type", "type_name_of", "header_stamp_ns_from_cdr"]

NS_PER_S = 1_000_000_000
_TYPE_RE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(?:(msg|srv|action)/)?([A-Z][A-Za-z0-9_]*)$")
_STAMP_LE = struct.Struct("<iI")
_STAMP_BE = struct.Struct(">iI")


def _is_message_class(cls: Any) -> bool:
    return isinstance(cls, type) and hasattr(type(cls), "__import_type_support__") \
        and hasattr(cls, "get_fields_and_field_types")


@functools.lru_cache(maxsize=256)
def _import_type(pkg: str, kind: str, name: str) -> type:
    module = importlib.import_module(f"{pkg}.{kind}")
    return getattr(module, name)


def message_type(type_name: str) -> type:
    """The rclpy message class for ``"pkg/msg/Name"`` (or ``"pkg/Name"``).

    The messages of services and actions that travel on topics (Jazzy service introspection
    ``"pkg/srv/Name_Event"``, ``"pkg/action/Name_FeedbackMessage"``) resolve too.

    Raises
    ------
    AdapterError
        Malformed name, package not installed, or no such message in it.
    """
    if not isinstance(type_name, str):
        raise AdapterError("type_name", "a str like 'sensor_msgs/msg/Image'", type_name)
    m = _TYPE_RE.match(type_name)
    if m is None:
        raise AdapterError("type_name", "'pkg/msg/Name' or 'pkg/Name'", type_name)
    pkg, kind, name = m.groups()
    try:
        cls = _import_type(pkg, kind or "msg", name)
    except Exception as exc:  # ImportError, AttributeError, or an error raised by the module itself
        raise AdapterError("type_name", "an installed ROS 2 message type",
                           Received(f"{type_name!r} ({type(exc).__name__}: {exc})")) from exc
    if not _is_message_class(cls):
        raise AdapterError("type_name", "an installed ROS 2 message type",
                           Received(f"{type_name!r} (not a message class)"))
    return cls


def type_name_of(msg_or_type: Any) -> str:
    """``"pkg/msg/Name"`` of an rclpy message or message class."""
    cls = msg_or_type if isinstance(msg_or_type, type) else type(msg_or_type)
    if not _is_message_class(cls):
        raise AdapterError("msg", "an rclpy message or message class", cls.__name__)
    parts = cls.__module__.split(".")
    kind = parts[1] if len(parts) > 2 and parts[1] in ("msg", "srv", "action") else "msg"
    return f"{parts[0]}/{kind}/{cls.__name__}"


def to_cdr(msg: Any) -> bytes:
    """The CDR bytes (with encapsulation header) of an rclpy message.

    Raises
    ------
    AdapterError
        Not an rclpy message, or a field value the type support cannot serialize.
    """
    if not _is_message_class(type(msg)):
        raise AdapterError("msg", "an rclpy message instance", type(msg).__name__)
    try:
        return serialize_message(msg)
    except Exception as exc:  # TypeError, SystemError, ... from the C type support
        raise AdapterError(f"{type_name_of(msg)} fields", "values matching the message definition",
                           Received(f"{type(exc).__name__}: {exc}")) from exc


def from_cdr(data: bytes, msg_type: type | str) -> Any:
    """The rclpy message of type ``msg_type`` encoded in ``data``.

    Parameters
    ----------
    data : bytes-like
        CDR with encapsulation header, e.g. from a bag or a raw subscription.
    msg_type : type or str
        A message class or its name (``"sensor_msgs/msg/Image"``).

    Raises
    ------
    AdapterError
        Unknown type, or bytes that do not deserialize as that type.
    """
    cls = message_type(msg_type) if isinstance(msg_type, str) else msg_type
    if not _is_message_class(cls):
        raise AdapterError("msg_type", "an rclpy message class or 'pkg/msg/Name'", msg_type)
    if isinstance(data, (bytearray, memoryview)):
        data = bytes(data)
    if not isinstance(data, bytes):
        raise AdapterError("data", "bytes", type(data).__name__)
    _encapsulation("data", data)
    try:
        return deserialize_message(data, cls)
    except Exception as exc:  # rclpy RMWError (a RuntimeError) and friends
        raise AdapterError("data", f"a serialized {type_name_of(cls)}",
                           Received(f"{len(data)} bytes that fail to deserialize ({str(exc).splitlines()[0]})")) from exc


def _encapsulation(field: str, data: bytes | memoryview) -> bool:
    """True for little-endian CDR, False for big-endian; anything else raises."""
    if len(data) < 4:
        raise AdapterError(field, "at least 4 bytes (CDR encapsulation header)", Received(f"{len(data)} bytes"))
    if data[0] != 0 or data[1] not in (0, 1):
        raise AdapterError(f"{field} encapsulation", "00 00 (CDR_BE) or 00 01 (CDR_LE)",
                           Received(f"{data[0]:02x} {data[1]:02x}"))
    return data[1] == 1


def header_stamp_ns_from_cdr(data: bytes) -> int:
    """``header.stamp`` in ns of a CDR message whose first field is a ``std_msgs/msg/Header``.

    Reads 12 bytes (encapsulation, ``int32 sec``, ``uint32 nanosec``); does not deserialize.
    Only meaningful for such types (Image, CameraInfo, JointState, TransformStamped,
    PoseStamped, ...); for other types the result is whatever their first 8 bytes hold.

    Raises
    ------
    AdapterError
        Fewer than 12 bytes, an unknown encapsulation, or ``nanosec >= 1e9``.
    """
    try:
        mv = memoryview(data)
    except TypeError:
        raise AdapterError("data", "bytes", type(data).__name__) from None
    if mv.ndim != 1 or mv.itemsize != 1:
        mv = mv.cast("B") if mv.c_contiguous else memoryview(mv.tobytes())
    little = _encapsulation("data", mv)
    if len(mv) < 12:
        raise AdapterError("data", "at least 12 bytes (encapsulation + header.stamp)", Received(f"{len(mv)} bytes"))
    sec, nanosec = (_STAMP_LE if little else _STAMP_BE).unpack_from(mv, 4)
    if nanosec >= NS_PER_S:
        raise AdapterError("header.stamp.nanosec", "< 1000000000", nanosec)
    return sec * NS_PER_S + nanosec
