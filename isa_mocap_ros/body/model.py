"""Articulated body models: 39-DOF and 28-DOF full body, 18-DOF lower body.

Sources: Yeguas et al., EA-vs-PF, §3.1 and Table 1 (16 joints, 39 DOF; the reduced 28-DOF model
drops UpperSpine, wrists and ankles, the starred rows) and §3.3 (6-step hierarchy: root, torso and
head, then each limb); ISA §13.4.2 (18-DOF lower body: 6 rigid-body DOF, hips 3+3, knees 1+1,
"feet" 2+2). The pose vector follows DESIGN §3: root translation (3), root rotation vector (3,
ISA Eq. 13.20), then joint angles in model order.

Frames and rest pose: world z up, metres. With all angles zero the person stands upright facing
+x with the arms hanging at the sides; every joint frame is then aligned with the world, so the
joint axes are named in the body frame (x forward, y left, z up, as REP-103). A joint with axes
``(a1, a2, a3)`` has the local rotation ``R = R_a1(q1) R_a2(q2) R_a3(q3)`` (intrinsic, in that
order), exactly the chain of revolute joints in the URDF export. See ``docs/body_models.md``.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

import numpy as np
import yaml

__all__ = ["BodyError", "BodyModel", "make_model", "load_shape", "save_shape", "default_shape",
           "DEFAULT_SHAPE_PATH", "FULL_BODY_JOINTS", "ROOT_DOF_NAMES"]

DEFAULT_SHAPE_PATH = Path(__file__).resolve().parents[2] / "config" / "body" / "default.yaml"
ROOT_DOF_NAMES = ("root_tx", "root_ty", "root_tz", "root_rx", "root_ry", "root_rz")

_PI = np.pi
_ROOT_LIMITS = [(-10.0, 10.0), (-10.0, 10.0), (-2.0, 4.0),
                (-2 * _PI, 2 * _PI), (-2 * _PI, 2 * _PI), (-2 * _PI, 2 * _PI)]


class BodyError(ValueError):
    """Bad input to a body model, kinematics, shape file or BVH function."""


# ---------------------------------------------------------------------------------------------
# The joint tree. Each joint: (name, parent, axes in the 39-DOF model, axes in the 28-DOF model,
# limits per axis for the left side / centre). Right-side joints mirror the left: x and z limits
# are negated and swapped (a reflection through the sagittal plane flips those rotations).
# Signs follow the right-hand rule about the body axes: knee flexion is +y, elbow flexion -y,
# hip/shoulder flexion (limb forward) -y, left abduction +x, spine flexion (bend forward) +y.
# ---------------------------------------------------------------------------------------------
_D = np.deg2rad
_JOINTS = [
    # name, parent, axes39, axes28, {axis: (lo, hi)}
    ("pelvis", None, "", "", {}),
    ("spine_lower", "pelvis", "yxz", "yxz", {"y": (_D(-30), _D(70)), "x": (_D(-35), _D(35)),
                                             "z": (_D(-40), _D(40))}),
    ("spine_upper", "spine_lower", "yxz", "", {"y": (_D(-25), _D(45)), "x": (_D(-30), _D(30)),
                                               "z": (_D(-35), _D(35))}),
    ("neck", "spine_upper", "yxz", "yxz", {"y": (_D(-60), _D(70)), "x": (_D(-45), _D(45)),
                                           "z": (_D(-80), _D(80))}),
    ("head", "neck", "", "", {}),
    ("head_top", "head", "", "", {}),
    ("left_shoulder", "spine_upper", "yxz", "yxz", {"y": (_D(-180), _D(60)), "x": (_D(-40), _D(170)),
                                                    "z": (_D(-100), _D(100))}),
    ("left_elbow", "left_shoulder", "y", "y", {"y": (_D(-150), _D(5))}),
    ("left_wrist", "left_elbow", "xy", "", {"x": (_D(-80), _D(80)), "y": (_D(-35), _D(35))}),
    ("left_hand", "left_wrist", "", "", {}),
    ("left_hip", "pelvis", "yxz", "yxz", {"y": (_D(-130), _D(35)), "x": (_D(-35), _D(60)),
                                          "z": (_D(-50), _D(50))}),
    ("left_knee", "left_hip", "y", "y", {"y": (_D(-5), _D(155))}),
    ("left_ankle", "left_knee", "yz", "", {"y": (_D(-35), _D(55)), "z": (_D(-40), _D(40))}),
    ("left_toe", "left_ankle", "", "", {}),
]
_LOWER_BODY = {"pelvis", "left_hip", "left_knee", "left_ankle", "left_toe",
               "right_hip", "right_knee", "right_ankle", "right_toe"}

# Capsules: name -> (joint a, joint b); radii come from the shape.
_CAPSULES = [
    ("pelvis", "left_hip", "right_hip"),
    ("abdomen", "pelvis", "spine_lower"),
    ("torso", "spine_lower", "spine_upper"),
    ("chest", "spine_upper", "neck"),
    ("shoulders", "left_shoulder", "right_shoulder"),
    ("neck", "neck", "head"),
    ("head", "head", "head_top"),
    ("left_upper_arm", "left_shoulder", "left_elbow"),
    ("left_forearm", "left_elbow", "left_wrist"),
    ("left_hand", "left_wrist", "left_hand"),
    ("left_thigh", "left_hip", "left_knee"),
    ("left_shin", "left_knee", "left_ankle"),
    ("left_foot", "left_ankle", "left_toe"),
]
_MARKERS = ["pelvis", "neck", "head", "left_shoulder", "left_elbow", "left_wrist", "left_hip",
            "left_knee", "left_ankle"]


def _mirror_name(name: str) -> str:
    return "right_" + name[5:] if name.startswith("left_") else name


def _full_joint_table() -> list[tuple]:
    """Joint table with right-side joints appended in the same (parent-first) order."""
    table = list(_JOINTS)
    for name, parent, a39, a28, lim in _JOINTS:
        if name.startswith("left_"):
            mirrored = {}
            for ax, (lo, hi) in lim.items():
                mirrored[ax] = (-hi, -lo) if ax in "xz" else (lo, hi)
            table.append((_mirror_name(name), _mirror_name(parent), a39, a28, mirrored))
    # Order: centre and left arm, right arm, left leg, right leg (parents always first).
    order = ["pelvis", "spine_lower", "spine_upper", "neck", "head", "head_top"]
    for side in ("left", "right"):
        order += [f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist", f"{side}_hand"]
    for side in ("left", "right"):
        order += [f"{side}_hip", f"{side}_knee", f"{side}_ankle", f"{side}_toe"]
    by_name = {row[0]: row for row in table}
    return [by_name[n] for n in order]


FULL_BODY_JOINTS = tuple(row[0] for row in _full_joint_table())


def _full_capsules() -> list[tuple[str, str, str]]:
    caps = []
    for name, a, b in _CAPSULES:
        caps.append((name, a, b))
    for name, a, b in _CAPSULES:
        if name.startswith("left_"):
            caps.append((_mirror_name(name), _mirror_name(a), _mirror_name(b)))
    return caps


def _full_markers() -> list[str]:
    out = list(_MARKERS)
    out += [_mirror_name(m) for m in _MARKERS if m.startswith("left_")]
    return out


# ---------------------------------------------------------------------------------------------
# Shapes
# ---------------------------------------------------------------------------------------------
def load_shape(path) -> dict:
    """Read a body-shape YAML file (``offsets`` per joint, ``radii`` per capsule; metres).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    shape : dict
        ``{"name": str, "offsets": {joint: [x, y, z]}, "radii": {capsule: [r0, r1]}, "axis_offsets":
        {capsule: [[x, y, z], [x, y, z]]}}`` with right sides mirrored from left sides where missing;
        validated. ``axis_offsets`` (optional, limb capsules and the pelvis only) moves each end of a capsule
        off its joint centre, in the capsule's first joint's frame (the pelvis capsule: the root's; x forward,
        y left, z up at rest), as fractions of the capsule's rest length: a capsule then follows the limb's
        volume rather than its bone (a calf lies behind the knee-ankle line; a pelvis in front of the hip
        joints). Absent = on the joint line.
    """
    path = Path(path)
    if not path.is_file():
        raise BodyError(f"shape: file not found: {path}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise BodyError(f"shape: {path} is not valid YAML: {exc}") from exc
    return complete_shape(data, source=str(path))


def save_shape(shape: Mapping, path) -> None:
    """Write a body shape (as returned by :func:`load_shape` or ``model.shape``) to YAML, every number exactly
    (``load_shape`` gives the same floats back: a shape calibrated by ``isa-mocap run`` and handed to the
    estimator as a file tracks as the same shape in ``isa-mocap track``; rounding to micrometres made the two
    part from the first frame)."""
    shape = complete_shape(shape, source="shape")
    data = {"name": shape["name"],
            "offsets": {k: [float(v) for v in val] for k, val in shape["offsets"].items()},
            "radii": {k: [float(v) for v in val] for k, val in shape["radii"].items()}}
    if shape["axis_offsets"]:
        data["axis_offsets"] = {k: [[float(v) for v in end] for end in val]
                                for k, val in shape["axis_offsets"].items()}
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False))


def default_shape() -> dict:
    """The default shape from ``config/body/default.yaml`` (about 1.75 m)."""
    return load_shape(DEFAULT_SHAPE_PATH)


def complete_shape(data, *, source: str) -> dict:
    """A body-shape mapping (``offsets``, ``radii``) checked and completed (an offset given for one side only is
    mirrored to the other); raises :class:`BodyError` naming ``source`` and the field."""
    if not isinstance(data, Mapping):
        raise BodyError(f"{source}: expected a mapping with 'offsets' and 'radii', got {type(data).__name__}")
    for key in ("offsets", "radii"):
        if not isinstance(data.get(key), Mapping):
            raise BodyError(f"{source}: expected a mapping under '{key}', got {data.get(key)!r}")
    offsets = {}
    for name, val in data["offsets"].items():
        if name not in FULL_BODY_JOINTS or name == "pelvis":
            raise BodyError(f"{source}: offsets: unknown joint '{name}' "
                            f"(expected one of {', '.join(FULL_BODY_JOINTS[1:])})")
        arr = np.asarray(val, dtype=float)
        if arr.shape != (3,) or not np.all(np.isfinite(arr)):
            raise BodyError(f"{source}: offsets.{name}: expected 3 finite numbers, got {val!r}")
        offsets[name] = arr
    for name in list(offsets):
        r = _mirror_name(name)
        if r != name and r not in offsets:
            offsets[r] = offsets[name] * np.array([1.0, -1.0, 1.0])
    missing = [n for n in FULL_BODY_JOINTS[1:] if n not in offsets]
    if missing:
        raise BodyError(f"{source}: offsets: missing joints {missing}")
    cap_names = [c[0] for c in _full_capsules()]
    radii = {}
    for name, val in data["radii"].items():
        if name not in cap_names:
            raise BodyError(f"{source}: radii: unknown capsule '{name}' (expected one of {', '.join(cap_names)})")
        arr = np.asarray(val, dtype=float)
        if arr.shape != (2,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
            raise BodyError(f"{source}: radii.{name}: expected 2 positive numbers, got {val!r}")
        radii[name] = arr
    for name in list(radii):
        r = _mirror_name(name)
        if r not in radii:
            radii[r] = radii[name].copy()
    missing = [n for n in cap_names if n not in radii]
    if missing:
        raise BodyError(f"{source}: radii: missing capsules {missing}")
    return {"name": str(data.get("name", "custom")), "offsets": offsets, "radii": radii,
            "axis_offsets": _axis_offsets(data.get("axis_offsets"), source=source)}


#: capsules whose ends may leave the joint line (``axis_offsets``): one joint and its child, both ends rigid in
#: the first joint's frame
_LIMB_CAPSULES = tuple(n for n, a, b in _full_capsules() if n.startswith(("left_", "right_")))
#: ... and the pelvis (hip to hip): two children of the root, both ends rigid in the root's frame (its volume
#: placed apart from the hip joints, the thighs' pivots)
_OFFSET_CAPSULES = _LIMB_CAPSULES + ("pelvis",)


def _axis_offsets(data, *, source: str) -> dict:
    """``axis_offsets`` checked (``(2, 3)`` finite fractions per limb capsule), right sides mirrored where
    missing, all-zero entries dropped."""
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise BodyError(f"{source}: expected a mapping under 'axis_offsets', got {data!r}")
    out = {}
    for name, val in data.items():
        if name not in _OFFSET_CAPSULES:
            raise BodyError(f"{source}: axis_offsets: unknown or non-limb capsule '{name}' "
                            f"(expected one of {', '.join(_OFFSET_CAPSULES)})")
        arr = np.asarray(val, dtype=float)
        if arr.shape != (2, 3) or not np.all(np.isfinite(arr)) or np.any(np.abs(arr) > 0.5):
            raise BodyError(f"{source}: axis_offsets.{name}: expected two [x, y, z] fractions of the capsule's "
                            f"length in [-0.5, 0.5] (one per end), got {val!r}")
        out[name] = arr
    for name in list(out):
        r = _mirror_name(name)
        if r not in out:
            out[r] = out[name] * np.array([1.0, -1.0, 1.0])
    return {k: v for k, v in out.items() if np.any(v != 0)}


# ---------------------------------------------------------------------------------------------
# The model
# ---------------------------------------------------------------------------------------------
def _frozen(a, dtype=None) -> np.ndarray:
    a = np.array(a, dtype=dtype)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class BodyModel:
    """An immutable articulated body model (built by :func:`make_model` / ``model_from_bvh``).

    Attributes
    ----------
    name : str
        ``"body39"``, ``"body28"`` or ``"lower18"`` (plus ``"@<shape name>"``).
    dof : int
        Pose-vector length ``D``.
    dof_names : tuple of str
        JointState names: ``root_tx, root_ty, root_tz, root_rx, root_ry, root_rz``, then
        ``<joint>_<axis>`` (e.g. ``left_knee_y``) in chain order.
    joint_names : tuple of str
        ``J`` joints, parents before children; end sites (``head_top``, ``*_hand``, ``*_toe``)
        and fixed joints carry no DOF.
    parents : (J,) int ndarray
        Parent index, ``-1`` for the root (``pelvis``).
    offsets : (J, 3) ndarray
        Rest offset of each joint from its parent, metres, parent frame (root: zeros).
    lower, upper : (D,) ndarray
        Limits (root translation ±10 m / z in [-2, 4] m; root rotation vector ±2π; angles rad).
    rotation_blocks : tuple of tuple of int
        ``((3, 4, 5),)``: index triples holding rotation vectors.
    dof_joint : (D,) int ndarray
        Joint moved by each DOF (``0`` for the six root DOF).
    dof_axis : (D,) int ndarray
        Axis 0/1/2 (x/y/z) of each joint-angle DOF (``-1`` for the root DOF).
    capsules : (C, 2) int ndarray
        Joint indices of each capsule's two ends.
    capsule_radii : (C, 2) ndarray
        Radius at each end, metres.
    capsule_names : tuple of str
    markers : (M,) int ndarray
        Joint indices used as marker points (joint centres) for the Eq. 20 error.
    knee_dofs : (2,) int ndarray
        Indices of ``left_knee_y`` and ``right_knee_y`` (flexion, radians).
    partitions : mapping str -> (k,) int ndarray
        DOF indices per hierarchy step (EA-vs-PF §3.3): ``root``, ``torso`` (spine + neck),
        ``left_arm``, ``right_arm``, ``left_leg``, ``right_leg``; only non-empty ones.
    shape : mapping
        The body shape the model was built from.
    joint_dofs : tuple of tuple of int
        DOF indices of each joint in chain order (root: ``(0, ..., 5)``).
    pelvis_height : float
        Root height of :meth:`rest_pose` (feet on the floor), metres.
    """

    name: str
    dof: int
    dof_names: tuple
    joint_names: tuple
    parents: np.ndarray
    offsets: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    rotation_blocks: tuple
    dof_joint: np.ndarray
    dof_axis: np.ndarray
    capsules: np.ndarray
    capsule_radii: np.ndarray
    capsule_names: tuple
    markers: np.ndarray
    knee_dofs: np.ndarray
    partitions: Mapping
    shape: Mapping = field(repr=False)
    joint_dofs: tuple = field(repr=False, default=())   # per joint: tuple of DOF indices (chain order)
    pelvis_height: float = 1.0

    def rest_pose(self) -> np.ndarray:
        """The standing rest pose ``(D,)``: all angles zero, upright, facing +x, pelvis above the
        world origin at ``pelvis_height`` so that the lowest capsule touches the floor ``z = 0``."""
        x = np.zeros(self.dof)
        x[2] = self.pelvis_height
        return x

    def joint_index(self, name: str) -> int:
        """Index of a joint by name (raises :class:`BodyError` naming the known joints)."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise BodyError(f"joint: unknown joint '{name}' for model {self.name} "
                            f"(expected one of {', '.join(self.joint_names)})") from None

    def validate_pose(self, x, *, name: str = "x") -> np.ndarray:
        """Check a pose ``(D,)`` or a batch ``(n, D)``; return it as a float array.

        Raises
        ------
        BodyError
            Wrong length (naming expected ``D`` and the received shape) or non-finite entries
            (naming the first offending DOF).
        """
        x = np.asarray(x, dtype=float)
        if x.ndim not in (1, 2) or x.shape[-1] != self.dof:
            raise BodyError(f"{name}: expected a pose of length {self.dof} for model {self.name} "
                            f"(shape ({self.dof},) or (n, {self.dof})), got shape {x.shape}")
        bad = ~np.isfinite(x)
        if bad.any():
            idx = np.argwhere(bad)[0]
            col = idx[-1]
            where = f" in row {idx[0]}" if x.ndim == 2 else ""
            raise BodyError(f"{name}: expected finite values, got {x[tuple(idx)]} at DOF {col} "
                            f"('{self.dof_names[col]}'){where}")
        return x

    def __repr__(self) -> str:
        return f"BodyModel(name={self.name!r}, dof={self.dof}, joints={len(self.joint_names)})"


def make_model(dof: int = 39, *, shape=None) -> BodyModel:
    """Build the 39-, 28- or 18-DOF model.

    Parameters
    ----------
    dof : {39, 28, 18}
        39/28: full body of EA-vs-PF Table 1 (28 drops UpperSpine, wrists and ankles);
        18: lower body of ISA §13.4.2.
    shape : str, Path, dict or None
        Body shape: a YAML path, a dict like :func:`load_shape` returns, or ``None`` for
        ``config/body/default.yaml``.

    Returns
    -------
    BodyModel
    """
    if dof not in (18, 28, 39):
        raise BodyError(f"dof: expected 18, 28 or 39, got {dof!r}")
    if shape is None:
        shp = default_shape()
    elif isinstance(shape, (str, Path)):
        shp = load_shape(shape)
    elif isinstance(shape, Mapping):
        shp = complete_shape(copy.deepcopy(dict(shape)), source="shape")
    else:
        raise BodyError(f"shape: expected a path, a mapping or None, got {type(shape).__name__}")

    table = _full_joint_table()
    if dof == 18:
        table = [row for row in table if row[0] in _LOWER_BODY]
    joint_names = tuple(row[0] for row in table)
    index = {n: i for i, n in enumerate(joint_names)}
    parents = np.array([-1 if row[1] is None else index[row[1]] for row in table], dtype=int)
    offsets = np.array([np.zeros(3) if row[1] is None else shp["offsets"][row[0]] for row in table])

    dof_names = list(ROOT_DOF_NAMES)
    lower = [lo for lo, _ in _ROOT_LIMITS]
    upper = [hi for _, hi in _ROOT_LIMITS]
    dof_joint = [0] * 6
    dof_axis = [-1] * 6
    joint_dofs = []
    for j, (name, _parent, a39, a28, lim) in enumerate(table):
        axes = a28 if dof == 28 else a39
        ids = []
        for ax in axes:
            ids.append(len(dof_names))
            dof_names.append(f"{name}_{ax}")
            lo, hi = lim[ax]
            lower.append(lo)
            upper.append(hi)
            dof_joint.append(j)
            dof_axis.append("xyz".index(ax))
        joint_dofs.append(tuple(ids) if j else (0, 1, 2, 3, 4, 5))
    if len(dof_names) != dof:  # pragma: no cover - guards the tables above
        raise AssertionError(f"model table gives {len(dof_names)} DOF, expected {dof}")

    caps = [(n, a, b) for n, a, b in _full_capsules() if a in index and b in index]
    # a capsule off its joint line joins two fixed end sites of its first joint, appended after every real
    # joint (the real joints keep their indices); they scale with the segment's offset, so the calibration's
    # length factors move them too
    # (the pelvis capsule joins two children of the root: its end sites are the root's, at the hips moved by
    # the fractions of the hip width)
    ends = []
    for n, a, b in caps:
        if n in shp["axis_offsets"] and parents[index[b]] == index[a]:
            length = float(np.linalg.norm(offsets[index[b]]))
            off = shp["axis_offsets"][n] * length
            ends.append((n, (f"{n}_end0", index[a], off[0]), (f"{n}_end1", index[a], offsets[index[b]] + off[1])))
        elif n in shp["axis_offsets"]:
            p = int(parents[index[a]])
            length = float(np.linalg.norm(offsets[index[b]] - offsets[index[a]]))
            off = shp["axis_offsets"][n] * length
            ends.append((n, (f"{n}_end0", p, offsets[index[a]] + off[0]), (f"{n}_end1", p, offsets[index[b]] + off[1])))
    for _n, *pair in ends:
        for jn, parent, off in pair:
            index[jn] = len(joint_names)
            joint_names += (jn,)
            parents = np.append(parents, parent)
            offsets = np.vstack([offsets, off])
            joint_dofs.append(())
    caps = [(n, f"{n}_end0", f"{n}_end1") if n in shp["axis_offsets"] else (n, a, b) for n, a, b in caps]
    capsules = np.array([[index[a], index[b]] for _, a, b in caps], dtype=int)
    radii = np.array([shp["radii"][n] for n, _, _ in caps])
    markers = np.array([index[m] for m in _full_markers() if m in index], dtype=int)
    knee_dofs = np.array([dof_names.index("left_knee_y"), dof_names.index("right_knee_y")])

    groups = {"root": [], "torso": [], "left_arm": [], "right_arm": [], "left_leg": [], "right_leg": []}
    for d, name in enumerate(dof_names):
        jn = joint_names[dof_joint[d]]
        if d < 6:
            groups["root"].append(d)
        elif jn.startswith(("spine", "neck", "head")):
            groups["torso"].append(d)
        elif jn.endswith(("shoulder", "elbow", "wrist")):
            groups[("left" if jn.startswith("left") else "right") + "_arm"].append(d)
        else:
            groups[("left" if jn.startswith("left") else "right") + "_leg"].append(d)
    partitions = MappingProxyType({k: _frozen(v, int) for k, v in groups.items() if v})

    rest = np.zeros((len(joint_names), 3))
    for j in range(1, len(joint_names)):
        rest[j] = rest[parents[j]] + offsets[j]
    pelvis_height = float(-np.min(rest[capsules][..., 2] - radii))

    label = {39: "body39", 28: "body28", 18: "lower18"}[dof]
    return BodyModel(
        name=f"{label}@{shp['name']}", dof=dof, dof_names=tuple(dof_names), joint_names=joint_names,
        parents=_frozen(parents), offsets=_frozen(offsets), lower=_frozen(lower, float),
        upper=_frozen(upper, float), rotation_blocks=((3, 4, 5),), dof_joint=_frozen(dof_joint, int),
        dof_axis=_frozen(dof_axis, int), capsules=_frozen(capsules), capsule_radii=_frozen(radii),
        capsule_names=tuple(n for n, _, _ in caps), markers=_frozen(markers), knee_dofs=_frozen(knee_dofs),
        partitions=partitions, shape=MappingProxyType(shp), joint_dofs=tuple(joint_dofs),
        pelvis_height=pelvis_height)
