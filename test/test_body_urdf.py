"""URDF export (joint names = JointState names) and the published root angles."""
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from isa_mocap_ros.body import joint_positions, make_model
from isa_mocap_ros.body.urdf import (euler_to_root_rotvec, joint_state_to_pose, pose_to_joint_state,
                                     root_rotvec_to_euler, to_urdf)
from isa_mocap_ros.geometry import exp_so3, rot_x, rot_y, rot_z


@pytest.mark.parametrize("dof", [39, 28, 18])
def test_urdf_joint_names_and_tree(dof):
    m = make_model(dof)
    root = ET.fromstring(to_urdf(m, name="person"))
    assert root.tag == "robot" and root.get("name") == "person"
    joints = root.findall("joint")
    movable = [j.get("name") for j in joints if j.get("type") != "fixed"]
    assert sorted(movable) == sorted(m.dof_names)
    types = {j.get("name"): j.get("type") for j in joints}
    assert [types[n] for n in ("root_tx", "root_ty", "root_tz")] == ["prismatic"] * 3
    assert all(types[n] == "revolute" for n in m.dof_names[6:])
    links = {l.get("name") for l in root.findall("link")}
    assert set(m.joint_names) <= links
    # a tree: every link except world is the child of exactly one joint, parents exist
    children = [j.find("child").get("link") for j in joints]
    assert sorted(children) == sorted(links - {"world"})
    assert all(j.find("parent").get("link") in links for j in joints)
    for j in joints:
        if j.get("name") in m.dof_names[6:]:
            d = m.dof_names.index(j.get("name"))
            lim = j.find("limit")
            assert float(lim.get("lower")) == pytest.approx(m.lower[d], abs=1e-5)
            assert float(lim.get("upper")) == pytest.approx(m.upper[d], abs=1e-5)
            axis = np.array(j.find("axis").get("xyz").split(), float)
            np.testing.assert_array_equal(axis, np.eye(3)[m.dof_axis[d]])
    n_visuals = len(root.findall("link/visual"))
    assert n_visuals >= 2 * len(m.capsules)


def urdf_fk(urdf: str, q: dict) -> dict:
    """Independent URDF chain evaluation (origin xyz, zero rpy; axes from the file)."""
    root = ET.fromstring(urdf)
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    cache = {"world": np.eye(4)}

    def world(link):
        if link in cache:
            return cache[link]
        j = by_child[link]
        T = world(j.find("parent").get("link")).copy()
        M = np.eye(4)
        M[:3, 3] = np.array(j.find("origin").get("xyz").split(), float)
        T = T @ M
        if j.get("type") != "fixed":
            axis = np.array(j.find("axis").get("xyz").split(), float)
            J = np.eye(4)
            if j.get("type") == "prismatic":
                J[:3, 3] = axis * q[j.get("name")]
            else:
                J[:3, :3] = exp_so3(axis * q[j.get("name")])
            T = T @ J
        cache[link] = T
        return T

    return {l.get("name"): world(l.get("name"))[:3, 3] for l in root.findall("link")}


def test_urdf_driven_by_joint_state_matches_fk():
    m = make_model(39)
    rng = np.random.default_rng(0)
    x = rng.uniform(m.lower, m.upper) * 0.7
    x[:3] = [0.3, -1.2, 0.9]
    x[3:6] = [0.4, -0.3, 2.5]
    q = dict(zip(m.dof_names, pose_to_joint_state(m, x)))
    pos = urdf_fk(to_urdf(m), q)
    P = joint_positions(m, x)[0]
    for name, p in zip(m.joint_names, P):
        np.testing.assert_allclose(pos[name], p, atol=1e-5, err_msg=name)


def test_root_euler_round_trip_and_convention():
    rng = np.random.default_rng(1)
    rpy = rng.uniform([-np.pi, -1.5, -np.pi], [np.pi, 1.5, np.pi], size=(50, 3))
    w = euler_to_root_rotvec(rpy)
    np.testing.assert_allclose(exp_so3(w), rot_z(rpy[:, 2]) @ rot_y(rpy[:, 1]) @ rot_x(rpy[:, 0]), atol=1e-12)
    np.testing.assert_allclose(root_rotvec_to_euler(w), rpy, atol=1e-9)
    # gimbal lock still reproduces the rotation
    w_lock = euler_to_root_rotvec(np.array([0.3, np.pi / 2, -0.2]))
    np.testing.assert_allclose(exp_so3(euler_to_root_rotvec(root_rotvec_to_euler(w_lock))), exp_so3(w_lock),
                               atol=1e-7)
    m = make_model(18)
    x = m.rest_pose()
    x[3:6] = w[0]
    np.testing.assert_allclose(joint_state_to_pose(m, pose_to_joint_state(m, x)), x, atol=1e-9)
