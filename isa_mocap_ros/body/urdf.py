"""URDF export of a body model, and the root rotation as published joint angles.

Source: DESIGN §3 (published root: 3 prismatic + 3 revolute virtual joints; URDF joint names equal
the JointState names). The model's joints follow EA-vs-PF Table 1 (see :mod:`.model`).

Virtual root chain: ``world → root_tx → root_ty → root_tz`` (prismatic along x, y, z), then
``root_rz → root_ry → root_rx`` (continuous, about z, y, x) to the ``pelvis`` link, so the root
rotation is ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (the ROS roll-pitch-yaw convention). The pose
vector keeps the rotation *vector* internally; :func:`root_rotvec_to_euler` gives the
``(root_rx, root_ry, root_rz) = (roll, pitch, yaw)`` values to publish, and
:func:`pose_to_joint_state` / :func:`joint_state_to_pose` convert whole vectors. Every other DOF is
a revolute joint named like the DOF, in the joint's chain order (``R = R_a1 R_a2 R_a3``), between
helper links ``<dof>_link``; each body joint ends in a link named like the joint, which carries
the capsule visuals (a cylinder plus a sphere per end; the cylinder uses the mean radius).

The two conversions are compiled (``_rotvec_to_rpy``, ``_rpy_to_rotvec``: every published estimate and prediction
goes through them twice, a few µs per numpy call on 3-vectors), in :mod:`isa_mocap_ros.geometry.se3_kernel`'s
arithmetic, the definition (there equal to numpy's ``exp_so3``/``log_so3`` bit for bit).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numba
import numpy as np

from isa_mocap_ros.numba_cache import register_dependent_cache

from ..geometry import exp_so3, se3_kernel, so3_kernel
from ..geometry.se3_kernel import log_so3_into
from ..geometry.so3_kernel import exp_into, matmul3
from .model import BodyError, BodyModel

__all__ = ["to_urdf", "root_rotvec_to_euler", "euler_to_root_rotvec", "pose_to_joint_state",
           "joint_state_to_pose"]

register_dependent_cache(__file__, (so3_kernel, se3_kernel))


@numba.njit(cache=True)
def _rotvec_to_rpy(W, out):  # pragma: no cover - compiled
    """``out (n, 3)``: roll, pitch, yaw of the rotation vectors ``W (n, 3)`` (:func:`root_rotvec_to_euler`)."""
    R = np.empty((3, 3))
    for k in range(W.shape[0]):
        exp_into(W[k, 0], W[k, 1], W[k, 2], R)
        pitch = np.arcsin(min(max(-R[2, 0], -1.0), 1.0))
        if np.cos(pitch) < 1e-9:                 # gimbal lock: roll 0
            out[k, 0], out[k, 2] = 0.0, np.arctan2(-R[0, 1], R[1, 1])
        else:
            out[k, 0], out[k, 2] = np.arctan2(R[2, 1], R[2, 2]), np.arctan2(R[1, 0], R[0, 0])
        out[k, 1] = pitch


@numba.njit(cache=True)
def _rpy_to_rotvec(Q, out):  # pragma: no cover - compiled
    """``out (n, 3)``: the rotation vectors ``log(Rz(yaw) Ry(pitch) Rx(roll))`` of ``Q (n, 3)`` (:func:`euler_to_root_rotvec`)."""
    Rx, Ry, Rz, A, B = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    for k in range(Q.shape[0]):
        exp_into(Q[k, 0], 0.0, 0.0, Rx)
        exp_into(0.0, Q[k, 1], 0.0, Ry)
        exp_into(0.0, 0.0, Q[k, 2], Rz)
        matmul3(Rz, Ry, A)
        matmul3(A, Rx, B)
        log_so3_into(B, out[k])


def _per_triple(kernel, values, name: str) -> np.ndarray:
    """``kernel(in (n, 3), out (n, 3))`` over the last axis of ``values (..., 3)``; a clear error for another shape."""
    a = np.asarray(values, dtype=float)
    if a.ndim < 1 or a.shape[-1] != 3:
        raise BodyError(f"{name}: expected shape (..., 3), got {a.shape}")
    out = np.empty(a.shape)
    kernel(np.ascontiguousarray(a.reshape(-1, 3)), out.reshape(-1, 3))
    return out


def root_rotvec_to_euler(rotvec) -> np.ndarray:
    """Rotation vectors to ``(roll, pitch, yaw)`` with ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

    Parameters
    ----------
    rotvec : (..., 3) array_like

    Returns
    -------
    rpy : (..., 3) ndarray
        ``pitch ∈ [-π/2, π/2]``; at ``|pitch| = π/2`` (gimbal lock) roll is set to 0.
    """
    return _per_triple(_rotvec_to_rpy, rotvec, "rotvec")


def euler_to_root_rotvec(rpy) -> np.ndarray:
    """Inverse of :func:`root_rotvec_to_euler`: ``(roll, pitch, yaw) (..., 3) -> rotvec (..., 3)``."""
    return _per_triple(_rpy_to_rotvec, rpy, "rpy")


def pose_to_joint_state(model: BodyModel, X) -> np.ndarray:
    """Pose vectors ``(..., D)`` to JointState positions (root rotation vector → roll/pitch/yaw)."""
    X = np.array(model.validate_pose(X, name="X"), dtype=float)
    X[..., 3:6] = root_rotvec_to_euler(X[..., 3:6])
    return X


def joint_state_to_pose(model: BodyModel, Q) -> np.ndarray:
    """JointState positions ``(..., D)`` (in ``model.dof_names`` order) to pose vectors."""
    Q = np.array(model.validate_pose(Q, name="Q"), dtype=float)
    Q[..., 3:6] = euler_to_root_rotvec(Q[..., 3:6])
    return Q


def _fmt(v) -> str:
    return " ".join(f"{float(a):.6g}" for a in np.atleast_1d(v))


def _rpy_z_to(direction: np.ndarray) -> np.ndarray:
    """URDF rpy (fixed-axis XYZ, R = Rz Ry Rx) turning +z onto ``direction``."""
    d = direction / np.linalg.norm(direction)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s, c = np.linalg.norm(axis), float(d @ z)
    if s < 1e-12:
        R = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        R = exp_so3(axis / s * np.arctan2(s, c))
    pitch = np.arcsin(np.clip(-R[2, 0], -1, 1))
    if np.cos(pitch) < 1e-9:
        return np.array([0.0, pitch, np.arctan2(-R[0, 1], R[1, 1])])
    return np.array([np.arctan2(R[2, 1], R[2, 2]), pitch, np.arctan2(R[1, 0], R[0, 0])])


def _joint(robot, name, jtype, parent, child, *, xyz=(0, 0, 0), axis=None, limits=None):
    j = ET.SubElement(robot, "joint", name=name, type=jtype)
    ET.SubElement(j, "parent", link=parent)
    ET.SubElement(j, "child", link=child)
    ET.SubElement(j, "origin", xyz=_fmt(xyz), rpy="0 0 0")
    if axis is not None:
        ET.SubElement(j, "axis", xyz=_fmt(axis))
    if limits is not None:
        ET.SubElement(j, "limit", lower=f"{limits[0]:.6g}", upper=f"{limits[1]:.6g}", effort="100",
                      velocity="10")
    return j


def _visual(link, geometry: str, xyz, rpy=(0, 0, 0), **attrs):
    v = ET.SubElement(link, "visual")
    ET.SubElement(v, "origin", xyz=_fmt(xyz), rpy=_fmt(rpy))
    g = ET.SubElement(v, "geometry")
    ET.SubElement(g, geometry, **{k: f"{val:.6g}" for k, val in attrs.items()})
    ET.SubElement(v, "material", name="skin")


def to_urdf(model: BodyModel, *, name: str = "human") -> str:
    """URDF (XML string) of the model whose movable joint names equal ``model.dof_names``.

    Parameters
    ----------
    model : BodyModel
    name : str
        Robot name.

    Returns
    -------
    urdf : str
    """
    if not name or not isinstance(name, str):
        raise BodyError(f"name: expected a non-empty string, got {name!r}")
    robot = ET.Element("robot", name=name)
    mat = ET.SubElement(robot, "material", name="skin")
    ET.SubElement(mat, "color", rgba="0.85 0.7 0.6 1")
    ET.SubElement(robot, "link", name="world")
    links = {"world"}
    prev = "world"
    root_chain = [("root_tx", "prismatic", (1, 0, 0)), ("root_ty", "prismatic", (0, 1, 0)),
                  ("root_tz", "prismatic", (0, 0, 1)), ("root_rz", "continuous", (0, 0, 1)),
                  ("root_ry", "continuous", (0, 1, 0)), ("root_rx", "continuous", (1, 0, 0))]
    for k, (dof_name, jtype, axis) in enumerate(root_chain):
        child = model.joint_names[0] if k == len(root_chain) - 1 else f"{dof_name}_link"
        d = model.dof_names.index(dof_name)
        lim = (model.lower[d], model.upper[d]) if jtype == "prismatic" else None
        _joint(robot, dof_name, jtype, prev, child, axis=axis, limits=lim)
        if child not in links:
            ET.SubElement(robot, "link", name=child)
            links.add(child)
        prev = child

    link_elems = {model.joint_names[0]: robot.find(f"link[@name='{model.joint_names[0]}']")}
    for j in range(1, len(model.joint_names)):
        jname = model.joint_names[j]
        parent = model.joint_names[model.parents[j]]
        dofs = model.joint_dofs[j]
        if not dofs:
            _joint(robot, f"{jname}_fixed", "fixed", parent, jname, xyz=model.offsets[j])
        else:
            prev = parent
            for k, d in enumerate(dofs):
                child = jname if k == len(dofs) - 1 else f"{model.dof_names[d]}_link"
                axis = np.eye(3)[model.dof_axis[d]]
                _joint(robot, model.dof_names[d], "revolute", prev, child,
                       xyz=model.offsets[j] if k == 0 else (0, 0, 0), axis=axis,
                       limits=(model.lower[d], model.upper[d]))
                if child != jname:
                    ET.SubElement(robot, "link", name=child)
                prev = child
        link_elems[jname] = ET.SubElement(robot, "link", name=jname)

    # Capsules: rigid in the link of a joint frame that holds both end points.
    for c, (a, b) in enumerate(model.capsules):
        home = None
        for cand in (a, model.parents[a]):
            if cand >= 0 and (b == cand or model.parents[b] == cand):
                home = cand
                break
        if home is None:  # pragma: no cover - guarded by the model tables
            raise BodyError(f"capsule '{model.capsule_names[c]}': no common rigid link for its ends")

        def local(jj, home=home):
            return np.zeros(3) if jj == home else model.offsets[jj]

        pa, pb = local(a), local(b)
        ra, rb = model.capsule_radii[c]
        link = link_elems[model.joint_names[home]]
        length = float(np.linalg.norm(pb - pa))
        if length > 1e-9:
            _visual(link, "cylinder", (pa + pb) / 2, _rpy_z_to(pb - pa), radius=(ra + rb) / 2, length=length)
        _visual(link, "sphere", pa, radius=ra)
        _visual(link, "sphere", pb, radius=rb)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"
