"""A 2-D keypoint model's surface points (head top, nose, heels, toes) as virtual markers of our body model,
defined on the mesh bodies, never on a recording they score.

Pose2Sim (the peer of ``docs/real_cameras.md``) triangulates the keypoints of a HALPE_26-like 2-D detector.
Besides joints it names points on the body's surface: ``Head`` (the top of the head), ``Nose``, ``LHeel`` /
``RHeel``, ``LBigToe`` / ``RBigToe``, ``LSmallToe`` / ``RSmallToe``. Our model has no such points (its ``head``
joint is the centre of the head). Each is a fixed point of the segment that carries it::

    p(x) = X_a(x) + R_parent(a)(x) · o_a  +  R_a(x) · v_p          (keypoint p on anchor joint a, pose x)

* ``a`` the anchor joint: ``head`` for the head's points, ``left_ankle`` / ``right_ankle`` for the foot's;
* ``X_a + R_parent(a) o_a`` the mesh rig's joint that our joint stands for: the shipped model → rig map of the
  mesh bodies (:mod:`.joint_map`, decision 012; fitted on tracked mesh runs; ``o_a = 0`` without a rig map);
* ``R_a`` the world rotation of the segment that begins at ``a`` (the head turns with our neck, the foot with our
  ankle's own rotation);
* ``v_p`` the mesh vertex's offset from the mesh joint ``a`` in that segment's frame at rest: each mesh subject
  turned to face our model's rest and its segment's axis aligned with our model's (as
  :func:`isa_mocap_ros.body.mesh.pose_mesh` aligns it), averaged over several subjects, left and right as one
  (mirrored).

The vertices (:data:`POINT_RULES`), on the rest mesh, among the vertices the carrying segment skins most:
``top``, the highest; ``nose``, the most forward within 1 cm of the mid-plane; ``heel``, the rearmost;
``big_toe`` / ``small_toe``, the most forward of the medial half / the lateral 40 % of the foot's width.

:func:`fit_keypoint_points` defines them from mesh subjects (the MakeHuman assets of ``make venv``);
``config/joint_maps/halpe26_mesh_points.yaml`` is the shipped result (``tools/fit_keypoint_points.py``);
:func:`keypoint_positions` places them on estimates.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .joint_map import JointMap, JointMapError, mapped_markers, read_map_file

__all__ = ["POINT_RULES", "KEYPOINT_POINTS_FILE", "KeypointPoints", "fit_keypoint_points", "keypoint_positions",
           "save_keypoint_points", "load_keypoint_points", "mesh_keypoint_points"]

#: keypoint (Pose2Sim / HALPE_26 name) -> (anchor joint of our model, the mesh segment that carries it, vertex rule)
POINT_RULES = {
    "Head": ("head", "head", "top"),
    "Nose": ("head", "head", "nose"),
    "LHeel": ("left_ankle", "left_foot", "heel"),
    "LBigToe": ("left_ankle", "left_foot", "big_toe"),
    "LSmallToe": ("left_ankle", "left_foot", "small_toe"),
    "RHeel": ("right_ankle", "right_foot", "heel"),
    "RBigToe": ("right_ankle", "right_foot", "big_toe"),
    "RSmallToe": ("right_ankle", "right_foot", "small_toe"),
}
#: the shipped definition, under config/
KEYPOINT_POINTS_FILE = "joint_maps/halpe26_mesh_points.yaml"
_FLIP = np.array([1.0, -1.0, 1.0])


@dataclass(frozen=True)
class KeypointPoints:
    """Per keypoint its anchor joint and offset ``v_p`` (metres, the anchor's own segment frame: x forward, y left,
    z up at rest); ``spread_mm``: per keypoint the standard deviation of the subjects' offsets (mm); ``source``:
    what it was defined on."""
    points: dict
    spread_mm: dict = field(default_factory=dict)
    source: dict = field(default_factory=dict)

    def anchor(self, name: str) -> str:
        return str(self.points[name][0])

    def offset(self, name: str) -> np.ndarray:
        return np.asarray(self.points[name][1], dtype=float)


def _pick(rule: str, V: np.ndarray, side: float) -> int:
    """Index into ``V`` ((N, 3) rest vertices of one segment, facing +x, z up) of the vertex ``rule`` names;
    ``side``: +1 for a left foot, -1 for a right one (lateral = +side y)."""
    x, y, z = V[:, 0], V[:, 1], V[:, 2]
    if rule == "top":
        return int(np.argmax(z))
    if rule == "nose":
        mid = 0.5 * (y.min() + y.max())
        near = np.flatnonzero(np.abs(y - mid) < 0.01)
        return int(near[np.argmax(x[near])])
    if rule == "heel":
        return int(np.argmin(x))
    lo, hi = y.min(), y.max()
    lat = side * (y - 0.5 * (lo + hi)) / (0.5 * (hi - lo))          # -1 medial edge .. +1 lateral edge
    sel = np.flatnonzero(lat < 0.0) if rule == "big_toe" else np.flatnonzero(lat > 0.2)
    if rule not in ("big_toe", "small_toe"):
        raise JointMapError(f"keypoint points: unknown vertex rule {rule!r}")
    return int(sel[np.argmax(x[sel])])


def _subject_offsets(model, subject) -> dict:
    """``{keypoint: v_p (3,)}`` of one mesh subject (module docstring)."""
    from isa_mocap_ros.body.mesh import SEGMENTS, driver_from_model, mesh_body, plan

    body = mesh_body(subject)
    pl = plan(body, driver_from_model(model, model.rest_pose()[None]))
    seg_names = list(SEGMENTS)
    owner = np.argmax(body.seg_weights, axis=1)
    out = {}
    for name, (anchor, seg, rule) in POINT_RULES.items():
        mine = np.flatnonzero(owner == seg_names.index(seg))
        V = pl.rest[mine]
        v = V[_pick(rule, V, 1.0 if anchor.startswith("left_") else -1.0)]
        out[name] = pl.A[seg] @ (v - pl.joints[anchor])
    return out


def fit_keypoint_points(model, subjects, *, source=None) -> KeypointPoints:
    """The points of :data:`POINT_RULES` defined on mesh ``subjects`` (:class:`isa_mocap_ros.body.mesh.Subject`),
    aligned to ``model``'s rest segments; every subject weighs the same; left and right fitted as one."""
    per = [_subject_offsets(model, s) for s in subjects]
    if not per:
        raise JointMapError("fit_keypoint_points: expected some mesh subjects, received none")
    points, spread = {}, {}
    for name, (anchor, _seg, _rule) in POINT_RULES.items():
        if name[0] in "LR" and {"L" + name[1:], "R" + name[1:]} <= set(POINT_RULES):
            # left and right as one: the right side's offsets mirrored (y negated) into the left's, and back
            left = [p["L" + name[1:]] for p in per] + [p["R" + name[1:]] * _FLIP for p in per]
            A = np.array(left) * (_FLIP if name[0] == "R" else 1.0)
        else:
            A = np.array([p[name] for p in per])
        points[name] = [anchor, [float(v) for v in A.mean(axis=0)]]
        spread[name] = float(1e3 * np.sqrt(np.mean(np.sum((A - A.mean(axis=0)) ** 2, axis=1))))
    return KeypointPoints(points, spread, dict(source or {}))


def keypoint_positions(points: KeypointPoints, model, poses, names, *, rig_map: JointMap | None = None) -> np.ndarray:
    """``(F, M, 3)`` positions of keypoints ``names`` (of ``points``) for poses ``(F, D)`` of ``model``
    (module docstring's formula; ``rig_map`` moves each anchor joint to the mesh rig's joint first)."""
    from isa_mocap_ros.body.kinematics import forward_kinematics

    W = forward_kinematics(model, np.asarray(poses, dtype=float))
    out = np.empty((W.shape[0], len(names), 3))
    for m, n in enumerate(names):
        if n not in points.points:
            raise JointMapError(f"keypoint points: no point {n!r} (defined: {', '.join(points.points)})")
        a = points.anchor(n)
        if a not in model.joint_names:
            raise JointMapError(f"keypoint points: model {model.name!r} has no joint {a!r} (the anchor of {n})")
        j = model.joint_names.index(a)
        base = (mapped_markers(rig_map, model, poses, [a])[:, 0] if rig_map is not None else W[:, j, :3, 3])
        out[:, m] = base + W[:, j, :3, :3] @ points.offset(n)
    return out


def save_keypoint_points(points: KeypointPoints, path) -> None:
    """Write ``path`` (YAML: ``points`` keypoint -> [anchor, [forward, left, up]], ``spread_mm``, ``source``)."""
    data = {"units": "metres", "axes": "the anchor joint's own segment frame: x forward, y left, z up at rest",
            "points": {n: [a, [round(float(v), 5) for v in o]] for n, (a, o) in points.points.items()},
            "spread_mm": {n: round(float(v), 1) for n, v in points.spread_mm.items()}, "source": points.source}
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False, allow_unicode=True))


def load_keypoint_points(path) -> KeypointPoints:
    """Read a file written by :func:`save_keypoint_points`; :class:`JointMapError` names the file and the field."""
    data, entries = read_map_file(path, "keypoint points", "points", "name -> [joint, [x, y, z]]")
    points = {}
    for n, v in entries.items():
        ok = isinstance(v, (list, tuple)) and len(v) == 2 and isinstance(v[0], str) and isinstance(v[1], (list, tuple))
        o = np.asarray(v[1], dtype=float) if ok else np.full(0, np.nan)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise JointMapError(f"keypoint points {path}: points.{n}: expected [joint, [x, y, z]], received {v!r}")
        points[str(n)] = [v[0], [float(c) for c in o]]
    return KeypointPoints(points, {str(k): float(s) for k, s in (data.get("spread_mm") or {}).items()},
                          dict(data.get("source") or {}))


def mesh_keypoint_points() -> KeypointPoints:
    """The shipped definition (``config/joint_maps/halpe26_mesh_points.yaml``)."""
    from isa_mocap_ros.resources import resource_dir

    return load_keypoint_points(resource_dir("config") / KEYPOINT_POINTS_FILE)
