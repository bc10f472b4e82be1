"""``geometry_msgs/msg/PolygonStamped`` ⇄ per-view 2-D keypoints ``(uv (N, 2), confidence (N,))``.

Wire format of ``/mocap/cam<i>/keypoints`` (docs/keypoints.md): a ``PolygonStamped`` (a message of
``common_interfaces``, so ``ros2 topic echo`` and ``ros2 bag`` read it without our own interface
package) whose ``header`` is the source image's (stamp and optical frame id) and whose
``polygon.points`` are the N landmarks in the detector's order (BlazePose: 33) with

    x = u (pixel column), y = v (pixel row), z = confidence in [0, 1].

An empty ``points`` list means "looked, found nobody" (the frame set stays complete downstream).
``Point32`` is float32: pixel coordinates keep 1/100 px up to 100,000 px. A message with another
count than N, a non-finite pixel or a confidence outside [0, 1] is rejected naming the point.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from geometry_msgs.msg import Point32, PolygonStamped

from .errors import AdapterError, Received

__all__ = ["keypoints_to_polygon", "polygon_to_keypoints"]


def keypoints_to_polygon(uv: Any, confidence: Any, header: Any = None) -> PolygonStamped:
    """``PolygonStamped`` with one point per keypoint (``uv=None`` → no points: nobody found)."""
    msg = PolygonStamped()
    if header is not None:
        msg.header = header
    if uv is None:
        return msg
    try:
        p = np.asarray(uv, dtype=np.float64)
        c = np.asarray(confidence, dtype=np.float64)
    except (TypeError, ValueError):
        raise AdapterError("uv, confidence", "numeric arrays", (uv, confidence)) from None
    if p.ndim != 2 or p.shape[1] != 2 or c.shape != (p.shape[0],):
        raise AdapterError("uv, confidence", "shapes (N, 2) and (N,)", Received(f"{p.shape} and {c.shape}"))
    _check(p, c, "uv")
    msg.polygon.points = [Point32(x=float(u), y=float(v), z=float(w)) for (u, v), w in zip(p, c)]
    return msg


def _check(p: np.ndarray, c: np.ndarray, field: str) -> None:
    bad = np.flatnonzero(~np.all(np.isfinite(p), axis=1))
    if bad.size:
        raise AdapterError(f"{field}[{int(bad[0])}]", "finite pixel coordinates", Received(str(p[bad[0]].tolist())))
    bad = np.flatnonzero(~((c >= 0.0) & (c <= 1.0)))
    if bad.size:
        raise AdapterError(f"confidence of point {int(bad[0])}", "a number in [0, 1]", Received(str(c[bad[0]])))


def polygon_to_keypoints(msg: PolygonStamped, *, n_points: int = 33) -> tuple[np.ndarray, np.ndarray] | None:
    """``(uv (n, 2) float64, confidence (n,) float64)``, or ``None`` for an empty polygon (nobody found)."""
    if not isinstance(msg, PolygonStamped):
        raise AdapterError("msg", "a geometry_msgs/PolygonStamped", Received(type(msg).__name__))
    pts = msg.polygon.points
    if len(pts) == 0:
        return None
    if len(pts) != n_points:
        raise AdapterError("PolygonStamped.polygon.points", f"0 or {n_points} points (one per keypoint)",
                           Received(f"{len(pts)} points"))
    a = np.array([(q.x, q.y, q.z) for q in pts], dtype=np.float64)
    uv, c = a[:, :2], a[:, 2]
    try:
        _check(uv, c, "PolygonStamped.polygon.points")
    except AdapterError as exc:
        raise AdapterError(exc.field.replace("confidence of point", "PolygonStamped.polygon.points z of point"),
                           exc.expected, exc.received) from None
    return uv, c
