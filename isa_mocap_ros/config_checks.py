"""Checks of one setting of a frozen config dataclass, shared by :class:`~.tracking.config.TrackerConfig`'s
groups and :class:`~.vision.segmentation_config.SegmentationConfig`: each raises the caller's error class
with a message naming the setting, what it expects and what it received. Pure: imports nothing of the package.
"""
from __future__ import annotations

import math
from typing import Iterable

import numpy as np

__all__ = ["check_number", "check_bool", "check_choice"]


def _bound(lo, hi, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f" in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
    if lo is not None:
        return f" {'>' if lo_open else '>='} {lo}"
    if hi is not None:
        return f" {'<' if hi_open else '<='} {hi}"
    return ""


def check_number(name: str, value, *, lo: float | None = None, hi: float | None = None, lo_open: bool = False,
                 hi_open: bool = False, integer: bool = False, error: type[Exception] = ValueError) -> None:
    """``error("NAME: expected an integer >= 1, received 0")`` unless ``value`` is a finite number (an integer
    when ``integer``; never a bool) within ``[lo, hi]`` (``lo_open`` / ``hi_open``: that end excluded;
    ``None``: unbounded)."""
    ok_type = (int, np.integer) if integer else (int, float, np.integer, np.floating)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, ok_type) or not math.isfinite(value) \
            or (lo is not None and (value <= lo if lo_open else value < lo)) \
            or (hi is not None and (value >= hi if hi_open else value > hi)):
        kind = "an integer" if integer else "a finite number"
        raise error(f"{name}: expected {kind}{_bound(lo, hi, lo_open, hi_open)}, received {value!r}")


def check_bool(name: str, value, *, error: type[Exception] = ValueError) -> None:
    """``error("NAME: expected true or false, received 'yes'")`` unless ``value`` is a bool."""
    if not isinstance(value, (bool, np.bool_)):
        raise error(f"{name}: expected true or false, received {value!r}")


def check_choice(name: str, value, choices: Iterable, *, error: type[Exception] = ValueError) -> None:
    """``error("NAME: expected one of a, b, received 'c'")`` unless ``value`` is one of ``choices``."""
    choices = tuple(choices)
    if value not in choices:
        raise error(f"{name}: expected one of {', '.join(map(str, choices))}, received {value!r}")
