"""Capsules off their joint line (``axis_offsets`` in a body shape): the calf behind the knee-ankle line."""
import numpy as np
import pytest

from isa_mocap_ros.body import (BodyError, capsule_endpoints, default_shape, forward_kinematics, joint_positions,
                                load_shape, make_model, save_shape)
from isa_mocap_ros.tracking.shape_calibration import shape_from_params

OFFS = {"left_thigh": [[0.05, 0.0, 0.0], [0.025, 0.01, 0.0]], "left_shin": [[-0.05, 0.0, 0.0], [-0.015, 0.0, 0.0]]}


def shifted_shape():
    shape = default_shape()
    shape["axis_offsets"] = OFFS
    return shape


def poses(model, n, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.uniform(model.lower, model.upper, size=(n, model.dof))
    X[:, :3] = rng.normal(size=(n, 3))
    return X


@pytest.mark.parametrize("dof", [39, 28, 18])
def test_capsule_ends_move_in_the_first_joints_frame(dof):
    plain, moved = make_model(dof), make_model(dof, shape=shifted_shape())
    X = poses(plain, 5)
    J = len(plain.joint_names)
    assert moved.joint_names[:J] == plain.joint_names and len(moved.joint_names) == J + 8
    assert np.array_equal(joint_positions(moved, X)[:, :J], joint_positions(plain, X))
    T = forward_kinematics(plain, X)
    E0, E1 = capsule_endpoints(plain, X), capsule_endpoints(moved, X)
    assert np.allclose(capsule_endpoints(moved, X, backend="numpy"), E1, atol=1e-12)
    for side, flip in (("left", 1.0), ("right", -1.0)):
        for cap, joint, child in (("thigh", "hip", "knee"), ("shin", "knee", "ankle")):
            c = moved.capsule_names.index(f"{side}_{cap}")
            j = plain.joint_index(f"{side}_{joint}")
            length = np.linalg.norm(plain.offsets[plain.joint_index(f"{side}_{child}")])
            local = np.array(OFFS[f"left_{cap}"]) * length * np.array([1.0, flip, 1.0])   # (2, 3)
            want = E0[:, c] + np.einsum("nij,ej->nei", T[:, j, :3, :3], local)
            assert np.allclose(E1[:, c], want, atol=1e-12)
    others = [c for c, n in enumerate(plain.capsule_names) if not n.endswith(("thigh", "shin"))]
    assert np.array_equal(E1[:, others], E0[:, others])


def test_axis_offsets_round_trip_and_errors(tmp_path):
    save_shape(shifted_shape(), tmp_path / "s.yaml")
    back = load_shape(tmp_path / "s.yaml")
    assert back["axis_offsets"]["left_shin"].tolist() == OFFS["left_shin"]
    assert back["axis_offsets"]["right_thigh"].tolist() == [[0.05, -0.0, 0.0], [0.025, -0.01, 0.0]]
    assert load_shape(tmp_path / "s.yaml")["axis_offsets"].keys() == back["axis_offsets"].keys()
    assert default_shape()["axis_offsets"] == {} and len(make_model(39).joint_names) == 22
    for bad, match in (({"torso": [[0, 0, 0], [0, 0, 0.1]]}, "non-limb capsule 'torso'"),
                       ({"left_shin": [-0.05, 0, 0]}, r"axis_offsets.left_shin: expected two \[x, y, z\]"),
                       ({"left_shin": [[-0.9, 0, 0], [0, 0, 0]]}, "in \\[-0.5, 0.5\\]")):
        shape = default_shape()
        shape["axis_offsets"] = bad
        with pytest.raises(BodyError, match=match):
            make_model(39, shape=shape)


def test_calibrated_shape_keeps_the_offsets_and_they_scale_with_the_leg():
    base = shifted_shape()
    long_legs = shape_from_params(base, {"thigh": 1.2, "shin": 1.2, "scale": 1.1})
    assert long_legs["axis_offsets"]["left_shin"].tolist() == OFFS["left_shin"]
    m0, m1 = make_model(39, shape=shape_from_params(base, {})), make_model(39, shape=long_legs)
    c = m0.capsule_names.index("left_shin")
    X = m0.rest_pose()[None]
    d0 = np.diff(capsule_endpoints(m0, X)[0, c], axis=0)
    d1 = np.diff(capsule_endpoints(m1, X)[0, c], axis=0)
    assert np.allclose(d1, d0 * 1.2 * 1.1)


def test_a_default_shape_with_offsets_reaches_bvh_models_and_the_model_yaml(tmp_path, monkeypatch):
    from isa_mocap_ros.body import model as model_module
    from isa_mocap_ros.body.bvh import parse_bvh
    from isa_mocap_ros.body.retarget import model_from_bvh
    from isa_mocap_ros.sequence import model_from_yaml, model_to_yaml
    from test_bvh import MB_NAMES, model_poses, write_bvh_from_model

    source = make_model(39)
    X = model_poses(source, 3, np.random.default_rng(2))
    bvh = parse_bvh(write_bvh_from_model(source, X, MB_NAMES, unit=0.01, order="YXZ"))
    save_shape(shifted_shape(), tmp_path / "default.yaml")
    monkeypatch.setattr(model_module, "DEFAULT_SHAPE_PATH", tmp_path / "default.yaml")
    for dof in (39, 18):
        m = model_from_bvh(bvh, dof)
        assert m.shape["axis_offsets"].keys() == {"left_thigh", "right_thigh", "left_shin", "right_shin"}
        back = model_from_yaml(model_to_yaml(m))[0]
        assert back.joint_names == m.joint_names
        assert np.allclose(capsule_endpoints(back, m.rest_pose()), capsule_endpoints(m, m.rest_pose()), atol=1e-8)


@pytest.mark.parametrize("dof", [39, 18])
def test_a_pelvis_off_the_hip_line_moves_with_the_root_only(dof):
    """The pelvis capsule (hip to hip) with its ends moved forward: two end sites of the root, so the hips'
    rotations (the thighs) leave it in place; hip joints moved back by the same amount keep the rest volume."""
    shape = default_shape()
    width = 2 * shape["offsets"]["left_hip"][1]
    d = 0.03
    shape["axis_offsets"] = {"pelvis": [[d / width, 0.0, 0.0], [d / width, 0.0, 0.0]]}
    plain, moved = make_model(dof), make_model(dof, shape=shape)
    assert moved.joint_names[-2:] == ("pelvis_end0", "pelvis_end1")
    assert all(moved.parents[moved.joint_index(n)] == 0 for n in ("pelvis_end0", "pelvis_end1"))
    X = poses(plain, 4)
    c = plain.capsule_names.index("pelvis")
    T = forward_kinematics(plain, X)
    want = capsule_endpoints(plain, X)[:, c] + T[:, 0, None, :3, 0] * d       # both ends d along the root's x
    assert np.allclose(capsule_endpoints(moved, X)[:, c], want, atol=1e-12)
    Y = X.copy()
    hips = [i for i, n in enumerate(plain.dof_names) if n.startswith(("left_hip", "right_hip"))]
    Y[:, hips] += 0.3
    assert np.allclose(capsule_endpoints(moved, Y)[:, c], want, atol=1e-12)
    back = default_shape()
    back["offsets"]["left_hip"] = back["offsets"]["left_hip"] - np.array([d, 0.0, 0.0])
    back["offsets"]["right_hip"] = back["offsets"]["right_hip"] - np.array([d, 0.0, 0.0])
    back["axis_offsets"] = shape["axis_offsets"]
    R = plain.rest_pose()[None]
    assert np.allclose(capsule_endpoints(make_model(dof, shape=back), R)[0, c], capsule_endpoints(plain, R)[0, c],
                       atol=1e-12)
