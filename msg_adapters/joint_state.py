"""``sensor_msgs/msg/JointState`` ⇄ (joint names, positions), with reordering by name.

Source: the ROS 2 message definition ``sensor_msgs/msg/JointState`` (parallel arrays ``name``,
``position``, ``velocity``, ``effort``; ``velocity``/``effort`` may be empty) and REP-103 units
(radians for revolute, metres for prismatic joints). Publishers are free to order joints as
they like, so a consumer asks for the order of its model (``names``) and gets positions in
that order; a joint it needs but the message lacks, a duplicated name, or a non-finite value
is an error naming the joint.
"""
from __future__ import annotations

import array
from collections.abc import Sequence
from typing import Any

import numpy as np
from sensor_msgs.msg import JointState

from .errors import AdapterError, Received, as_float_array
from .stamp import make_header

__all__ = ["joint_state_to_arrays", "arrays_to_joint_state"]


def _names(field_name: str, names: Any) -> list[str]:
    if isinstance(names, (str, bytes)) or names is None:
        raise AdapterError(field_name, "a sequence of str", names)
    try:
        out = list(names)
    except TypeError:
        raise AdapterError(field_name, "a sequence of str", names) from None
    for i, n in enumerate(out):
        if not isinstance(n, str):
            raise AdapterError(f"{field_name}[{i}]", "a str", n)
        if "\x00" in n:
            # ROS strings are NUL-terminated on the wire: 'a\x00b' would arrive as 'a'
            raise AdapterError(f"{field_name}[{i}]", "a str without NUL characters", n)
    return out


def _duplicates(field_name: str, names: list[str]) -> None:
    if len(set(names)) != len(names):
        seen: set[str] = set()
        dup = ""
        for n in names:
            if n in seen:
                dup = n
                break
            seen.add(n)
        raise AdapterError(field_name, "unique joint names", Received(f"{dup!r} more than once"))


def _finite(field_name: str, names: list[str], values: np.ndarray) -> None:
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        i = int(bad[0])
        raise AdapterError(f"{field_name} of joint {names[i]!r}", "a finite number",
                           Received(f"{values[i]}" + (f" ({bad.size} non-finite)" if bad.size > 1 else "")))


def joint_state_to_arrays(msg: JointState, names: Sequence[str] | None = None) -> tuple[list[str], np.ndarray]:
    """Joint names and positions of a ``JointState``.

    Parameters
    ----------
    msg : sensor_msgs.msg.JointState
    names : sequence of str, optional
        The wanted joints in the wanted order; extra joints of the message are ignored.

    Returns
    -------
    names : list of str
        ``names`` if given, else the message's ``name``.
    positions : (n,) float64 ndarray
        In the order of ``names`` (a new writable array).

    Raises
    ------
    AdapterError
        ``len(name) != len(position)``; duplicated names in the message; a wanted joint
        missing (named); a NaN/inf position among the returned joints (named).
    """
    msg_names = _names("JointState.name", getattr(msg, "name", None))
    pos = as_float_array("JointState.position", getattr(msg, "position", None), finite=False)
    if pos.ndim != 1:
        raise AdapterError("JointState.position", "a flat sequence", Received(f"shape {pos.shape}"))
    if pos.size != len(msg_names):
        raise AdapterError("JointState.position", f"one value per name ({len(msg_names)})",
                           Received(f"{pos.size} values"))
    _duplicates("JointState.name", msg_names)
    if names is None:
        out = np.array(pos, dtype=np.float64)
        _finite("JointState.position", msg_names, out)
        return msg_names, out
    wanted = _names("names", names)
    index = {n: i for i, n in enumerate(msg_names)}
    missing = [n for n in wanted if n not in index]
    if missing:
        raise AdapterError("JointState.name", f"to contain joint {missing[0]!r}",
                           Received(f"{len(msg_names)} names without it"
                                    + (f" ({len(missing)} wanted joints missing)" if len(missing) > 1 else "")))
    out = pos[[index[n] for n in wanted]] if wanted else np.zeros(0)
    _finite("JointState.position", wanted, out)
    return wanted, out


def arrays_to_joint_state(names: Sequence[str], positions: Any, *, stamp_ns: int = 0, frame_id: str = "",
                          velocities: Any = None) -> JointState:
    """A ``JointState`` from names and positions (and optionally velocities).

    Parameters
    ----------
    names : sequence of str
        Unique joint names.
    positions : (n,) array_like
        Finite, one per name.
    stamp_ns, frame_id : keyword-only
        Header stamp (ns) and frame.
    velocities : (n,) array_like, optional
        Finite; ``velocity`` stays empty when omitted.

    Raises
    ------
    AdapterError
        Lengths disagree, duplicated or non-str names, non-finite values.
    """
    names = _names("names", names)
    _duplicates("names", names)
    pos = as_float_array("positions", positions, finite=False)
    if pos.ndim != 1 or pos.size != len(names):
        raise AdapterError("positions", f"shape ({len(names)},) (one per name)", Received(f"shape {pos.shape}"))
    _finite("positions", names, pos)
    msg = JointState(header=make_header(stamp_ns, frame_id), name=names)
    msg.position = array.array("d", pos.tolist())
    if velocities is not None:
        vel = as_float_array("velocities", velocities, finite=False)
        if vel.ndim != 1 or vel.size != len(names):
            raise AdapterError("velocities", f"shape ({len(names)},) (one per name)", Received(f"shape {vel.shape}"))
        _finite("velocities", names, vel)
        msg.velocity = array.array("d", vel.tolist())
    return msg
