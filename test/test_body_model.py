"""Body models (EA-vs-PF Table 1, ISA §13.4.2), shapes and batch forward kinematics."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from isa_mocap_ros.body import (BodyError, capsule_endpoints, default_shape, forward_kinematics,
                                joint_positions, load_shape, make_model, position_jacobian, save_shape)


@pytest.fixture(scope="module", params=[39, 28, 18])
def model(request):
    return make_model(request.param)


def random_poses(model, rng, n):
    X = rng.uniform(model.lower, model.upper, size=(n, model.dof))
    X[:, :3] = rng.normal(size=(n, 3))
    X[:, 3:6] = rng.normal(size=(n, 3))
    return X


def test_table1_dof_counts_and_names():
    m39, m28, m18 = make_model(39), make_model(28), make_model(18)
    assert (m39.dof, m28.dof, m18.dof) == (39, 28, 18)
    for m in (m39, m28, m18):
        assert m.dof_names[:6] == ("root_tx", "root_ty", "root_tz", "root_rx", "root_ry", "root_rz")
        assert len(set(m.dof_names)) == m.dof
        assert all(n.replace("_", "").isalnum() and n.islower() for n in m.dof_names)
    per_joint = {}
    for name in m39.dof_names[6:]:
        joint = name.rsplit("_", 1)[0]
        per_joint[joint] = per_joint.get(joint, 0) + 1
    assert per_joint == {"spine_lower": 3, "spine_upper": 3, "neck": 3, "left_shoulder": 3,
                         "right_shoulder": 3, "left_elbow": 1, "right_elbow": 1, "left_wrist": 2,
                         "right_wrist": 2, "left_hip": 3, "right_hip": 3, "left_knee": 1, "right_knee": 1,
                         "left_ankle": 2, "right_ankle": 2}
    # 28 = 39 minus the starred rows (UpperSpine 3, wrists 2+2, ankles 2+2)
    dropped = set(m39.dof_names) - set(m28.dof_names)
    assert {n.rsplit("_", 1)[0] for n in dropped} == {"spine_upper", "left_wrist", "right_wrist",
                                                       "left_ankle", "right_ankle"}
    assert set(m28.dof_names) < set(m39.dof_names)
    assert m28.joint_names == m39.joint_names  # same skeleton, fewer axes
    assert set(m18.dof_names[6:]) == {n for n in m39.dof_names if n.split("_")[1] in ("hip", "knee", "ankle")}


def test_model_structure(model):
    J = len(model.joint_names)
    assert model.parents[0] == -1 and all(0 <= p < j for j, p in enumerate(model.parents) if j)
    assert model.offsets.shape == (J, 3) and model.lower.shape == model.upper.shape == (model.dof,)
    assert np.all(model.lower < model.upper)
    assert model.rotation_blocks == ((3, 4, 5),)
    assert model.capsules.shape[1] == 2 and model.capsule_radii.shape == model.capsules.shape
    assert np.all(model.capsule_radii > 0)
    assert [model.dof_names[i] for i in model.knee_dofs] == ["left_knee_y", "right_knee_y"]
    parts = np.concatenate(list(model.partitions.values()))
    assert sorted(parts.tolist()) == list(range(model.dof))  # the hierarchy covers every DOF once
    with pytest.raises(ValueError):
        model.offsets[1, 0] = 3.0  # immutable
    with pytest.raises(Exception):
        model.dof = 3


def test_rest_pose_standing_facing_x():
    m = make_model(39)
    P = joint_positions(m, m.rest_pose())[0]
    j = m.joint_index
    assert P[j("head_top"), 2] > P[j("neck"), 2] > P[j("pelvis"), 2] > P[j("left_knee"), 2] > P[j("left_ankle"), 2]
    assert P[j("left_hip"), 1] > 0 > P[j("right_hip"), 1]         # left is +y
    assert P[j("left_toe"), 0] > P[j("left_ankle"), 0]             # feet point to +x
    ends = capsule_endpoints(m, m.rest_pose())[0]
    assert np.min(ends[..., 2] - m.capsule_radii) == pytest.approx(0.0, abs=1e-12)  # on the floor
    assert 1.65 < P[:, 2].max() < 1.85
    assert m.rest_pose()[2] == pytest.approx(m.pelvis_height)


def reference_fk(model, x):
    """Straightforward per-pose loop with scipy rotations and 4x4 matrices."""
    T = [None] * len(model.joint_names)
    for j in range(len(model.joint_names)):
        M = np.eye(4)
        if j == 0:
            M[:3, :3] = Rotation.from_rotvec(x[3:6]).as_matrix()
            M[:3, 3] = x[:3]
            T[0] = M
            continue
        M[:3, 3] = model.offsets[j]
        dofs = model.joint_dofs[j]
        if dofs:
            seq = "".join("XYZ"[model.dof_axis[d]] for d in dofs)  # upper case: intrinsic
            M[:3, :3] = Rotation.from_euler(seq, [x[d] for d in dofs]).as_matrix()
        T[j] = T[model.parents[j]] @ M
    return np.stack(T)


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_fk_matches_per_pose_reference(model, backend):
    rng = np.random.default_rng(0)
    X = random_poses(model, rng, 25)
    X[0, 3:6] = [1e-7, 0, 0]          # root rotation near 0 (Taylor branch of the kernel)
    X[1, 3:6] = [0, np.pi, 0]         # and at π
    T = forward_kinematics(model, X, backend=backend)
    assert T.shape == (25, len(model.joint_names), 4, 4)
    for x, Tx in zip(X, T):
        np.testing.assert_allclose(Tx, reference_fk(model, x), atol=1e-12)
    np.testing.assert_allclose(joint_positions(model, X, backend=backend), T[..., :3, 3])
    ends = capsule_endpoints(model, X, backend=backend)
    np.testing.assert_allclose(ends[:, :, 0], T[..., :3, 3][:, model.capsules[:, 0]])
    np.testing.assert_allclose(ends[:, :, 1], T[..., :3, 3][:, model.capsules[:, 1]])
    np.testing.assert_allclose(forward_kinematics(model, X[3], backend=backend), T[3:4])  # single pose
    with pytest.raises(BodyError, match="backend: expected 'numba' or 'numpy', got 'gpu'"):
        joint_positions(model, X, backend="gpu")


def test_fk_small_batches_on_the_calling_thread_give_the_parallel_kernels_bits(model):
    from isa_mocap_ros.body import kinematics as kin

    rng = np.random.default_rng(1)
    X = random_poses(model, rng, 2 * kin.SERIAL_BELOW + 3)
    tables = kin.kernel_tables(model)
    J = len(model.joint_names)
    outs = []
    for kernel in (kin._fk_kernel, kin._fk_kernel_serial):
        R, P = np.empty((len(X), J, 3, 3)), np.empty((len(X), J, 3))
        kernel(X, *tables, R, P)
        outs.append((R, P))
    np.testing.assert_array_equal(outs[0][0], outs[1][0])
    np.testing.assert_array_equal(outs[0][1], outs[1][1])
    for n in (1, kin.SERIAL_BELOW - 1, kin.SERIAL_BELOW):       # both sides of the switch: the same bits
        np.testing.assert_array_equal(joint_positions(model, X[:n]), outs[0][1][:n])


def test_fk_backends_agree_on_large_batch():
    m = make_model(39)
    X = random_poses(m, np.random.default_rng(9), 2000)
    np.testing.assert_allclose(forward_kinematics(m, X), forward_kinematics(m, X, backend="numpy"), atol=1e-12)


def test_bone_lengths_preserved(model):
    rng = np.random.default_rng(1)
    P = joint_positions(model, random_poses(model, rng, 10))
    lengths = np.linalg.norm(P[:, 1:] - P[:, model.parents[1:]], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(np.linalg.norm(model.offsets[1:], axis=1), lengths.shape),
                               atol=1e-12)


def test_knee_and_elbow_flexion_signs():
    m = make_model(39)
    x = m.rest_pose()
    x[m.dof_names.index("left_knee_y")] = 1.0
    x[m.dof_names.index("left_elbow_y")] = -1.0
    x[m.dof_names.index("right_hip_y")] = -0.5
    P = joint_positions(m, x)[0]
    j = m.joint_index
    assert P[j("left_ankle"), 0] < P[j("left_knee"), 0] - 0.2       # foot goes back
    assert P[j("left_wrist"), 0] > P[j("left_elbow"), 0] + 0.2      # forearm comes forward
    assert P[j("right_knee"), 0] > 0.15                              # thigh forward


def test_position_jacobian_matches_finite_differences():
    m = make_model(39)
    rng = np.random.default_rng(2)
    X = random_poses(m, rng, 3) * 0.5
    joints = np.arange(len(m.joint_names))
    P, Jac = position_jacobian(m, X, joints)
    eps = 1e-6
    from isa_mocap_ros.geometry import exp_so3, log_so3
    for d in range(m.dof):
        Xp, Xm = X.copy(), X.copy()
        if 3 <= d < 6:
            e = np.zeros(3)
            e[d - 3] = eps
            Xp[:, 3:6] = log_so3(exp_so3(e) @ exp_so3(X[:, 3:6]))
            Xm[:, 3:6] = log_so3(exp_so3(-e) @ exp_so3(X[:, 3:6]))
        else:
            Xp[:, d] += eps
            Xm[:, d] -= eps
        fd = (joint_positions(m, Xp) - joint_positions(m, Xm)) / (2 * eps)
        np.testing.assert_allclose(Jac[..., d], fd, atol=1e-7, err_msg=m.dof_names[d])


def test_validate_pose_errors():
    m = make_model(28)
    with pytest.raises(BodyError, match=r"X: expected a pose of length 28 .* got shape \(39,\)"):
        joint_positions(m, np.zeros(39))
    x = m.rest_pose()
    x[m.dof_names.index("left_knee_y")] = np.nan
    with pytest.raises(BodyError, match=r"expected finite values, got nan at DOF \d+ \('left_knee_y'\)"):
        m.validate_pose(x)
    with pytest.raises(BodyError, match="row 1"):
        m.validate_pose(np.stack([m.rest_pose(), x]))
    with pytest.raises(BodyError, match="dof: expected 18, 28 or 39, got 40"):
        make_model(40)
    with pytest.raises(BodyError, match="unknown joint 'nose'"):
        m.joint_index("nose")


def test_shape_round_trip_and_errors(tmp_path):
    shape = default_shape()
    shape["offsets"]["left_knee"] = np.array([0.0, 0.0, -0.5])
    del shape["offsets"]["right_knee"]
    shape["name"] = "tall"
    path = tmp_path / "tall.yaml"
    save_shape(shape, path)
    loaded = load_shape(path)
    np.testing.assert_allclose(loaded["offsets"]["right_knee"], [0, 0, -0.5])  # mirrored from left
    # every number comes back exactly (a calibrated shape handed on as a file is the same shape)
    odd = default_shape()
    odd["offsets"]["left_elbow"] = np.array([0.0, 1e-9 / 3, -0.2912345678912345])
    odd["radii"]["left_thigh"] = np.array([0.0812345678912345, 0.055])
    save_shape(odd, tmp_path / "odd.yaml")
    back = load_shape(tmp_path / "odd.yaml")
    assert back["offsets"]["left_elbow"].tolist() == odd["offsets"]["left_elbow"].tolist()
    assert back["radii"]["left_thigh"].tolist() == odd["radii"]["left_thigh"].tolist()
    m = make_model(39, shape=path)
    assert m.name == "body39@tall"
    assert np.linalg.norm(m.offsets[m.joint_index("right_knee")]) == pytest.approx(0.5)
    assert make_model(18, shape=shape).pelvis_height > make_model(18).pelvis_height
    bad = tmp_path / "bad.yaml"
    bad.write_text("offsets: {left_knee: [0, 0]}\nradii: {}\n")
    with pytest.raises(BodyError, match=r"offsets.left_knee: expected 3 finite numbers, got \[0, 0\]"):
        load_shape(bad)
    bad.write_text("offsets: {tail: [0, 0, 1]}\nradii: {}\n")
    with pytest.raises(BodyError, match="offsets: unknown joint 'tail'"):
        load_shape(bad)
    with pytest.raises(BodyError, match="file not found"):
        load_shape(tmp_path / "nope.yaml")
