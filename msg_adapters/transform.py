"""``geometry_msgs/msg/TransformStamped`` ⇄ rotation matrix and translation.

Source: the ROS 2 message definitions ``geometry_msgs/msg/TransformStamped`` /
``Transform`` (translation ``Vector3``, rotation ``Quaternion`` x, y, z, w; Hamilton
convention as in tf2) and REP-103. A transform from ``header.frame_id`` (parent) to
``child_frame_id`` maps child coordinates into the parent: ``p_parent = R p_child + t``.

Quaternion → matrix: the unit quaternion ``q = (w, x, y, z)`` gives
``R = I + 2 w [v]_x + 2 [v]_x^2`` with ``v = (x, y, z)``; the input is first scaled by its
largest component and normalised, so any non-zero finite quaternion is accepted.
Matrix → quaternion: Shepperd's method (S. W. Shepperd, "Quaternion from rotation matrix",
J. Guidance and Control 1(3), 1978): pick the largest of ``4w², 4x², 4y², 4z²`` from the trace
and diagonal, divide the off-diagonal sums by it; returned with ``w >= 0``.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from geometry_msgs.msg import Quaternion, Transform, TransformStamped, Vector3

from .errors import AdapterError, Received, as_float, as_float_array, as_str
from .stamp import make_header

__all__ = ["ORTHONORMAL_TOL", "quaternion_to_matrix", "matrix_to_quaternion", "transform_to_rt",
           "rt_to_transform"]

#: max |R^T R - I| accepted by :func:`rt_to_transform` and :func:`matrix_to_quaternion`
ORTHONORMAL_TOL = 1e-6


def quaternion_to_matrix(q: Any, *, field_name: str = "q") -> np.ndarray:
    """Rotation matrix of a quaternion given as ``(x, y, z, w)`` (ROS order).

    Parameters
    ----------
    q : (4,) array_like
        Any non-zero finite quaternion; it is normalised.

    Returns
    -------
    (3, 3) float64 ndarray
        Proper rotation matrix.

    Raises
    ------
    AdapterError
        Zero or non-finite quaternion, wrong size.
    """
    q = as_float_array(field_name, q, size=4)
    scale = np.abs(q).max()
    if scale == 0.0:
        raise AdapterError(field_name, "a non-zero quaternion (x, y, z, w)", q.tolist())
    q = q / scale
    x, y, z, w = q / np.sqrt(q @ q)
    # R = I + 2w[v]x + 2[v]x^2, written out
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _check_rotation(field_name: str, R: Any) -> np.ndarray:
    R = as_float_array(field_name, R, shape=(3, 3))
    with np.errstate(over="ignore", invalid="ignore"):  # huge entries: err = inf, rejected below
        err = float(np.abs(R.T @ R - np.eye(3)).max())
    if not err <= ORTHONORMAL_TOL:
        raise AdapterError(field_name, f"an orthonormal matrix (max |R^T R - I| <= {ORTHONORMAL_TOL:g})",
                           Received(f"max |R^T R - I| = {err:.3g}"))
    det = float(np.linalg.det(R))
    if det < 0:
        raise AdapterError(field_name, "a rotation (det R = +1)", Received(f"det R = {det:.6g} (a reflection)"))
    return R


def matrix_to_quaternion(R: Any, *, field_name: str = "R") -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` with ``w >= 0`` of a rotation matrix (Shepperd 1978).

    Parameters
    ----------
    R : (3, 3) array_like
        Orthonormal with det +1 (tolerance :data:`ORTHONORMAL_TOL`).

    Returns
    -------
    (4,) float64 ndarray

    Raises
    ------
    AdapterError
        Wrong shape, non-finite, not orthonormal, or a reflection.
    """
    R = _check_rotation(field_name, R)
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    cands = (tr, R[0, 0], R[1, 1], R[2, 2])  # 4w²-1, 4x²-1... up to a common offset
    k = int(np.argmax(cands))
    if k == 0:  # w largest: 4w² = 1 + tr
        s = 2.0 * np.sqrt(max(1.0 + tr, 0.0))
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4])
    elif k == 1:  # x largest: 4x² = 1 + R00 - R11 - R22
        s = 2.0 * np.sqrt(max(1.0 + R[0, 0] - R[1, 1] - R[2, 2], 0.0))
        q = np.array([s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s])
    elif k == 2:
        s = 2.0 * np.sqrt(max(1.0 - R[0, 0] + R[1, 1] - R[2, 2], 0.0))
        q = np.array([(R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s])
    else:
        s = 2.0 * np.sqrt(max(1.0 - R[0, 0] - R[1, 1] + R[2, 2], 0.0))
        q = np.array([(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4, (R[1, 0] - R[0, 1]) / s])
    q /= np.sqrt(q @ q)
    return -q if q[3] < 0 else q


def transform_to_rt(msg: TransformStamped) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation of a ``TransformStamped`` (or a bare ``Transform``).

    Returns
    -------
    R : (3, 3) float64 ndarray
        From the normalised ``transform.rotation``.
    t : (3,) float64 ndarray
        ``transform.translation`` in metres.

    Raises
    ------
    AdapterError
        Zero or non-finite quaternion, non-finite translation, missing fields.
    """
    tf = getattr(msg, "transform", msg)
    prefix = "TransformStamped.transform" if hasattr(msg, "transform") else "Transform"
    rot = getattr(tf, "rotation", None)
    tr = getattr(tf, "translation", None)
    if rot is None or tr is None:
        raise AdapterError(prefix, "a geometry_msgs/msg/Transform(Stamped)", type(msg).__name__)
    q = [as_float(f"{prefix}.rotation.{c}", getattr(rot, c, None), finite=False) for c in "xyzw"]
    R = quaternion_to_matrix(q, field_name=f"{prefix}.rotation")
    t = np.array([as_float(f"{prefix}.translation.{c}", getattr(tr, c, None)) for c in "xyz"])
    return R, t


def rt_to_transform(R: Any, t: Any, *, parent_frame: str, child_frame: str,
                    stamp_ns: int = 0) -> TransformStamped:
    """A ``TransformStamped`` from ``parent_frame`` to ``child_frame``: ``p_parent = R p_child + t``.

    Parameters
    ----------
    R : (3, 3) array_like
        Rotation, orthonormal within :data:`ORTHONORMAL_TOL`, det +1.
    t : (3,) array_like
        Translation in metres, finite.
    parent_frame, child_frame : str, keyword-only
        ``header.frame_id`` and ``child_frame_id``.
    stamp_ns : int, keyword-only
        ``header.stamp`` in nanoseconds.

    Raises
    ------
    AdapterError
        Non-orthonormal or reflecting ``R``, wrong shapes, non-finite values.
    """
    x, y, z, w = matrix_to_quaternion(R)
    t = as_float_array("t", t, size=3)
    header = make_header(stamp_ns, as_str("parent_frame", parent_frame))
    return TransformStamped(
        header=header, child_frame_id=as_str("child_frame", child_frame),
        transform=Transform(translation=Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
                            rotation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))))
