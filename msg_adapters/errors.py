"""The one exception type of the message adapters, and the small validators behind it.

Every rejection in :mod:`msg_adapters` raises :class:`AdapterError` (a ``ValueError``) whose
message reads ``"<field>: expected <what>, received <value>"``, so a log line alone says which
field of which message was wrong and how. Field names follow the ROS 2 message definitions
(``sensor_msgs/msg/Image.step``, ``sensor_msgs/msg/CameraInfo.k``, ...).
"""
from __future__ import annotations

import math
import operator
from typing import Any

import numpy as np

__all__ = ["AdapterError"]

_MAX_REPR = 80


def _short(value: Any) -> str:
    """``repr(value)`` cut to a readable length (images and CDR blobs can be megabytes)."""
    if isinstance(value, (bytes, bytearray, memoryview)):
        return f"<{len(value) if not isinstance(value, memoryview) else value.nbytes} bytes>"
    try:
        text = repr(value)
    except Exception:  # a broken __repr__ must not hide the real error
        text = f"<unprintable {type(value).__name__}>"
    text = " ".join(text.split())
    return text if len(text) <= _MAX_REPR else text[: _MAX_REPR - 3] + "..."


class AdapterError(ValueError):
    """A message or array that the adapters cannot convert.

    Parameters
    ----------
    field : str
        The offending field or argument, e.g. ``"Image.step"`` or ``"R"``.
    expected : str
        What would have been accepted.
    received : object
        What was received (shown through a shortened ``repr``; pass a ``str`` subclass
        :class:`Received` to show text verbatim).
    """

    def __init__(self, field: str, expected: str, received: Any):
        super().__init__(field, expected, received)
        self.field = field
        self.expected = expected
        self.received = received

    def __str__(self) -> str:
        rec = self.received if isinstance(self.received, Received) else _short(self.received)
        return f"{self.field}: expected {self.expected}, received {rec}"


class Received(str):
    """Text shown verbatim as the 'received' part of an :class:`AdapterError`."""


# ---------------------------------------------------------------------------------------------
# validators (internal)

def as_int(field: str, value: Any, *, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` as a Python int within ``[lo, hi]`` (bools and floats are refused)."""
    if isinstance(value, (bool, np.bool_)):
        raise AdapterError(field, "an integer", value)
    try:
        v = operator.index(value)
    except TypeError:
        raise AdapterError(field, "an integer", value) from None
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        lo_s = "-inf" if lo is None else str(lo)
        hi_s = "inf" if hi is None else str(hi)
        raise AdapterError(field, f"an integer in [{lo_s}, {hi_s}]", v)
    return v


def as_str(field: str, value: Any) -> str:
    """``value`` if it is a ``str``."""
    if not isinstance(value, str):
        raise AdapterError(field, "a str", value)
    return value


def as_float(field: str, value: Any, *, finite: bool = True) -> float:
    """``value`` as a Python float (finite unless ``finite=False``)."""
    if isinstance(value, (bool, np.bool_, str, bytes)):
        raise AdapterError(field, "a real number", value)
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise AdapterError(field, "a real number", value) from None
    if finite and not math.isfinite(v):
        raise AdapterError(field, "a finite number", v)
    return v


def as_float_array(field: str, value: Any, *, shape: tuple[int, ...] | None = None,
                   size: int | None = None, finite: bool = True) -> np.ndarray:
    """``value`` as a float64 array (new or shared), checked for shape/size and finiteness.

    ``shape`` compares the array's shape exactly; ``size`` only its number of elements (the
    array is then flattened).
    """
    if isinstance(value, (str, bytes)):
        raise AdapterError(field, "an array of real numbers", value)
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise AdapterError(field, "an array of real numbers", value) from None
    if size is not None:
        if arr.size != size:
            raise AdapterError(field, f"{size} numbers", Received(f"{arr.size} numbers (shape {arr.shape})"))
        arr = arr.reshape(-1)
    if shape is not None and arr.shape != shape:
        raise AdapterError(field, f"shape {shape}", Received(f"shape {arr.shape}"))
    if finite and arr.size and not np.isfinite(arr).all():
        bad = np.flatnonzero(~np.isfinite(arr.reshape(-1)))
        raise AdapterError(field, "finite numbers",
                           Received(f"{arr.reshape(-1)[bad[0]]} at flat index {int(bad[0])}"
                                    f" ({bad.size} non-finite)"))
    return arr


def readonly(arr: np.ndarray) -> np.ndarray:
    """``arr`` as its own read-only float64 copy."""
    out = np.array(arr, dtype=np.float64, copy=True)
    out.flags.writeable = False
    return out
