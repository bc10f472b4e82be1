"""The REP-155 (ROS4HRI) view of a body model: ROS4HRI joint names and a matching URDF.

ROS4HRI's ``human_description`` names a body's joints ``waist``, ``{r,p,y}_head``,
``{l,r}_{y,p,r}_shoulder``, ``{l,r}_elbow``, ``{l,r}_{y,p,r}_hip``, ``{l,r}_knee``, each suffixed
with ``_<body id>``, where ``y``/``p``/``r`` are the yaw/pitch/roll parts of a 3-DOF joint. Our
body frame is x forward, y left, z up, so roll is about x, pitch about y and yaw about z:

==================  =========================
ROS4HRI             our DOF
==================  =========================
waist               spine_lower_y (flexion)
r/p/y_head          neck_x / neck_y / neck_z
l_r/p/y_shoulder    left_shoulder_x / _y / _z
l_elbow             left_elbow_y
l_r/p/y_hip         left_hip_x / _y / _z
l_knee              left_knee_y
==================  =========================

(right side alike). DOFs without a ROS4HRI name (root, upper spine, wrists, ankles) keep our
names. :func:`hri_urdf` renames the joints of our own URDF (axes and limits untouched), so the URDF
and :func:`hri_joint_names` agree exactly: ``robot_state_publisher`` fed with the HRI joint states
draws the same body as with ours. Pure module (no ROS).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

from .model import BodyModel
from .urdf import to_urdf

_BASE = {"spine_lower_y": "waist", "neck_x": "r_head", "neck_y": "p_head", "neck_z": "y_head"}
for _side, _s in (("left", "l"), ("right", "r")):
    for _j in ("shoulder", "hip"):
        for _axis, _p in (("x", "r"), ("y", "p"), ("z", "y")):
            _BASE[f"{_side}_{_j}_{_axis}"] = f"{_s}_{_p}_{_j}"
    _BASE[f"{_side}_elbow_y"] = f"{_s}_elbow"
    _BASE[f"{_side}_knee_y"] = f"{_s}_knee"
HRI_NAMES = dict(_BASE)


def hri_joint_names(model: BodyModel, body_id: str) -> tuple[str, ...]:
    """``model.dof_names`` with ROS4HRI names (``<name>_<body_id>``) where one exists."""
    if not body_id or not body_id.replace("_", "").isalnum():
        raise ValueError(f"body_id must be a non-empty alphanumeric id, got {body_id!r}")
    return tuple(f"{HRI_NAMES[n]}_{body_id}" if n in HRI_NAMES else n for n in model.dof_names)


def hri_urdf(model: BodyModel, body_id: str) -> str:
    """Our URDF with ROS4HRI joint names (see the module docstring) and robot name ``human_<id>``."""
    names = dict(zip(model.dof_names, hri_joint_names(model, body_id)))
    root = ET.fromstring(to_urdf(model, name=f"human_{body_id}"))
    for joint in root.iter("joint"):
        new = names.get(joint.get("name"))
        if new is not None:
            joint.set("name", new)
    return ET.tostring(root, encoding="unicode")
