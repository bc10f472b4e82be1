"""Model → reference-rig joint map (virtual markers): score an estimate against a skeleton that defines its
joints elsewhere.

A body model's joint centres are the ends of its capsules; another skeleton (the MakeHuman ``cmu_mb`` rig of the
mesh bodies, a peer system's keypoints) names points elsewhere in the body: its neck 6-7 cm higher, its hips
5 cm further forward (docs/decisions/012-joint-definitions.md). Motion-capture systems meet this with a joint
regressor: each reference point is a fixed point of the fitted model's segment. Here, per marker ``i``, a
constant offset ``o_i`` in the frame of the segment that ends at the marker's joint (the parent joint's frame,
``R_p``; the pelvis's own frame for the root)::

    m_i(x) = X_i(x) + R_p(i)(x) · (L_i o_i)          (virtual marker of joint i, pose x)

with ``L_i = 1`` (``scaled: false``) or ``L_i`` the length of that segment in the tracking model (``scaled:
true``: the offset grows with the subject's calibrated segment). The offsets are the least-squares fit
``o_i = mean over frames of R_pᵀ (T_i − X_i) / L_i`` over TRAINING runs (estimates against the reference's
points; :func:`fit_joint_map`); left and right are fitted as one (the right side mirrored, y negated: the model's
local y axis points left). A map is fitted once, saved (:func:`save_joint_map`) with what it was fitted on, and
applied unchanged to every run it scores; a run it was fitted on is no test of it.

The model's local axes at rest are the world's: x forward, y left, z up (``body/model.py``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

__all__ = ["JointMap", "JointMapError", "fit_joint_map", "save_joint_map", "load_joint_map", "mapped_markers",
           "segment_of", "mesh_rig_map", "MESH_RIG_MAP_FILE", "read_map_file"]

#: the shipped map of the mesh bodies' rig (``isa-mocap synth --body mesh``: MakeHuman/MPFB2 ``cmu_mb``), under config/
MESH_RIG_MAP_FILE = "joint_maps/makehuman_cmu_mb.yaml"


class JointMapError(ValueError):
    """A joint map that does not fit the model or the data (names the joint, the file or the field)."""


@dataclass(frozen=True)
class JointMap:
    """Per marker joint (model name) an offset in its parent segment's frame (metres, or segment lengths when
    ``scaled``); ``source``: what it was fitted on (free text, kept in the file)."""
    offsets: dict
    scaled: bool = False
    rig: str = ""
    source: dict = field(default_factory=dict)

    def offset(self, name: str) -> np.ndarray:
        return np.asarray(self.offsets.get(name, (0.0, 0.0, 0.0)), dtype=float)


def segment_of(model, name: str) -> tuple[int, float]:
    """The joint whose world frame carries marker ``name``'s offset (its parent; the root for the root), and
    that segment's length in ``model`` (metres; the root: half the hip width)."""
    if name not in model.joint_names:
        raise JointMapError(f"joint map: model {model.name!r} has no joint {name!r}")
    j = model.joint_names.index(name)
    p = int(model.parents[j])
    if p < 0:
        hips = [model.joint_names.index(h) for h in ("left_hip", "right_hip") if h in model.joint_names]
        L = float(np.mean([np.linalg.norm(model.offsets[h]) for h in hips])) if hips else 1.0
        return j, L
    return p, float(np.linalg.norm(model.offsets[j]))


def _mirror(name: str) -> str | None:
    if name.startswith("left_"):
        return "right_" + name[5:]
    if name.startswith("right_"):
        return "left_" + name[6:]
    return None


_FLIP = np.array([1.0, -1.0, 1.0])


def _local_residuals(model, poses, names, truth) -> dict:
    """Per marker the (F, 3) residuals ``R_pᵀ (T − X) / L`` (scaled later) and the segment length."""
    from isa_mocap_ros.body.kinematics import forward_kinematics

    W = forward_kinematics(model, np.asarray(poses, dtype=float))
    R, P = W[..., :3, :3], W[..., :3, 3]
    T = np.asarray(truth, dtype=float)
    out = {}
    for m, n in enumerate(names):
        if n not in model.joint_names:
            continue
        j = model.joint_names.index(n)
        p, L = segment_of(model, n)
        d = T[:, m] - P[:, j]
        out[n] = (np.einsum("fji,fj->fi", R[:, p], d), L)      # R_pᵀ d
    return out


def fit_joint_map(runs, *, scaled: bool = False, symmetric: bool = True, rig: str = "", source=None) -> JointMap:
    """Least-squares offsets from training runs.

    Parameters
    ----------
    runs : iterable of (model, poses (F, D), names, truth (F, M, 3))
        Tracked estimates with the shape they were tracked with, and the reference's points by name
        (frames with a missing point, NaN, are left out of that marker's mean).
    scaled : bool
        Offsets in units of the parent segment's length (:func:`segment_of`) instead of metres.
    symmetric : bool
        Fit each left/right pair as one offset (the right one mirrored).

    Every frame of every run weighs the same.
    """
    acc: dict = {}
    for model, poses, names, truth in runs:
        for n, (r, L) in _local_residuals(model, poses, [str(v) for v in names], truth).items():
            r = r / L if scaled else r
            acc.setdefault(n, []).append(r[np.all(np.isfinite(r), axis=1)])
    if not acc:
        raise JointMapError("fit_joint_map: expected runs whose reference names some of the model's joints, "
                            "received none")
    offsets = {}
    for n, parts in acc.items():
        rows = np.concatenate(parts)
        mir = _mirror(n)
        if symmetric and mir in acc:
            rows = np.concatenate([rows, np.concatenate(acc[mir]) * _FLIP])
        offsets[str(n)] = [float(v) for v in rows.mean(axis=0)]
    return JointMap(offsets=offsets, scaled=scaled, rig=rig, source=dict(source or {}))


def mapped_markers(jmap: JointMap, model, poses, names) -> np.ndarray:
    """Virtual markers ``(F, M, 3)`` of ``names`` (model joints) for poses ``(F, D)``: joint centre + its
    parent segment's rotation times the offset (× the segment length when the map is scaled)."""
    from isa_mocap_ros.body.kinematics import forward_kinematics

    W = forward_kinematics(model, np.asarray(poses, dtype=float))
    R, P = W[..., :3, :3], W[..., :3, 3]
    out = np.empty((P.shape[0], len(names), 3))
    for m, n in enumerate(names):
        if n not in model.joint_names:
            raise JointMapError(f"joint map: model {model.name!r} has no joint {n!r}")
        j = model.joint_names.index(n)
        p, L = segment_of(model, n)
        o = jmap.offset(n) * (L if jmap.scaled else 1.0)
        out[:, m] = P[:, j] + R[:, p] @ o
    return out


def save_joint_map(jmap: JointMap, path) -> None:
    """Write ``path`` (YAML: ``rig``, ``scaled``, ``offsets`` per joint as [forward, left, up], ``source``)."""
    data = {"rig": jmap.rig, "scaled": bool(jmap.scaled),
            "units": "segment lengths" if jmap.scaled else "metres",
            "axes": "parent segment frame: x forward, y left, z up at rest",
            "offsets": {n: [round(float(v), 5) for v in o] for n, o in jmap.offsets.items()},
            "source": jmap.source}
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False, allow_unicode=True))


def read_map_file(path, what: str, key: str, form: str) -> tuple[dict, dict]:
    """``(data, data[key])`` of the YAML file ``path`` whose ``key`` must be a mapping; :class:`JointMapError`
    names ``what`` (e.g. "joint map"), the file, and the expected ``form`` of an entry."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise JointMapError(f"{what} {path}: cannot read it ({exc})") from exc
    if not isinstance(data, dict) or not isinstance(data.get(key), dict):
        raise JointMapError(f"{what} {path}: expected a mapping with '{key}' ({form})")
    return data, data[key]


def load_joint_map(path) -> JointMap:
    """Read a map written by :func:`save_joint_map`; :class:`JointMapError` names the file and the field."""
    data, entries = read_map_file(path, "joint map", "offsets", "joint -> [x, y, z]")
    offsets = {}
    for n, o in entries.items():
        a = np.asarray(o, dtype=float) if isinstance(o, (list, tuple)) else np.full(0, np.nan)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise JointMapError(f"joint map {path}: offsets.{n}: expected three finite numbers, received {o!r}")
        offsets[str(n)] = [float(v) for v in a]
    return JointMap(offsets=offsets, scaled=bool(data.get("scaled", False)), rig=str(data.get("rig", "")),
                    source=dict(data.get("source") or {}))


def mesh_rig_map() -> JointMap:
    """The shipped map of the mesh bodies' rig (``config/joint_maps/makehuman_cmu_mb.yaml``)."""
    from isa_mocap_ros.resources import resource_dir

    return load_joint_map(resource_dir("config") / MESH_RIG_MAP_FILE)
