"""Metrics: Eq. 20 joint error, knee RMSE, per-joint angle RMSE, on hand-made data."""
import numpy as np
import pytest

from isa_mocap_ros.body import joint_positions, make_model
from isa_mocap_ros.eval import (MetricsError, angle_difference, frame_errors_mm, joint_errors_mm, knee_errors_deg,
                                knee_rmse_deg, marker_positions, max_frame_error_mm, mpjpe_mm,
                                per_joint_angle_rmse_deg, shared_markers)


def test_eq20_by_hand():
    T = np.zeros((3, 2, 3))
    P = T.copy()
    P[0, 0] = [0.003, 0.004, 0.0]        # 5 mm on marker 0, frame 0
    P[1, :] = [0.0, 0.0, 0.010]          # 10 mm on both markers, frame 1
    P[2, 1] = [0.0, -0.02, 0.0]          # 20 mm on marker 1, frame 2
    np.testing.assert_allclose(joint_errors_mm(P, T), [[5, 0], [10, 10], [0, 20]], atol=1e-9)
    np.testing.assert_allclose(frame_errors_mm(P, T), [2.5, 10.0, 10.0], atol=1e-9)
    assert mpjpe_mm(P, T) == pytest.approx((2.5 + 10 + 10) / 3)
    assert max_frame_error_mm(P, T) == pytest.approx(10.0)
    assert mpjpe_mm(T, T) == 0.0


def test_eq20_is_symmetric_and_translation_invariant():
    rng = np.random.default_rng(3)
    P, T = rng.normal(size=(2, 5, 4, 3))
    s = rng.normal(size=3)
    assert mpjpe_mm(P, T) == pytest.approx(mpjpe_mm(T, P))
    assert mpjpe_mm(P + s, T + s) == pytest.approx(mpjpe_mm(P, T))


@pytest.mark.parametrize("bad, match", [
    (np.zeros((2, 3)), r"pred_joints: expected joint positions of shape \(F, M, 3\).*received shape \(2, 3\)"),
    (np.zeros((2, 3, 2)), r"pred_joints: expected .*received shape \(2, 3, 2\)"),
    (np.full((2, 3, 3), np.nan), r"pred_joints: expected finite positions.*frame 0, marker 0"),
])
def test_position_shape_checks(bad, match):
    with pytest.raises(MetricsError, match=match):
        mpjpe_mm(bad, np.zeros((2, 3, 3)))


def test_position_mismatch():
    with pytest.raises(MetricsError, match=r"true_joints: expected the shape of pred_joints \(2, 3, 3\), "
                                           r"received \(2, 4, 3\)"):
        frame_errors_mm(np.zeros((2, 3, 3)), np.zeros((2, 4, 3)))


def test_knee_rmse_by_hand():
    m = make_model(39)
    T = np.zeros((4, m.dof))
    P = T.copy()
    lk, rk = m.knee_dofs
    P[:, lk] = np.deg2rad([1, -1, 1, -1])      # left: 1 deg every frame
    P[:, rk] = np.deg2rad([3, 3, -3, -3])      # right: 3 deg
    P[:, 20] = 1.0                             # another DOF: not a knee, ignored
    np.testing.assert_allclose(knee_errors_deg(P, T, m)[:, 0], [1, -1, 1, -1])
    assert knee_rmse_deg(P, T, m) == pytest.approx(np.sqrt((1 + 9) / 2))


def test_knee_rmse_across_models_and_wrapping():
    m39, m18 = make_model(39), make_model(18)
    P = np.zeros((2, 18))
    T = np.zeros((2, 39))
    P[:, m18.knee_dofs[0]] = np.pi - 0.01
    T[:, m39.knee_dofs[0]] = -np.pi + 0.01        # 0.02 rad apart across the wrap
    e = knee_errors_deg(P, T, m18, true_model=m39)
    np.testing.assert_allclose(e[:, 0], np.rad2deg(-0.02), atol=1e-9)
    np.testing.assert_allclose(angle_difference([0.1], [2 * np.pi]), [0.1], atol=1e-12)


def test_per_joint_angle_rmse():
    m = make_model(28)
    T = np.zeros((3, m.dof))
    P = T.copy()
    i = m.dof_names.index("left_elbow_y")
    P[:, i] = np.deg2rad([2, 2, 2])
    P[:, 0] = 5.0                              # root translation: not a joint angle
    r = per_joint_angle_rmse_deg(P, T, m)
    assert list(r) == list(m.dof_names[6:])
    assert r["left_elbow_y"] == pytest.approx(2.0)
    assert sum(v for k, v in r.items() if k != "left_elbow_y") == 0.0
    # against the 18-DOF lower body: only the shared (leg) DOFs
    m18 = make_model(18)
    r18 = per_joint_angle_rmse_deg(np.zeros((3, 18)), np.zeros((3, 18)), m18)
    assert set(r18) == set(m18.dof_names[6:])


def test_pose_shape_checks():
    m = make_model(18)
    with pytest.raises(MetricsError, match=r"pred_poses: expected pose vectors of shape \(F, 18\).*\(3, 17\)"):
        knee_rmse_deg(np.zeros((3, 17)), np.zeros((3, 18)), m)
    with pytest.raises(MetricsError, match=r"true_poses: expected 3 frames .*received 2"):
        knee_rmse_deg(np.zeros((3, 18)), np.zeros((2, 18)), m)
    bad = np.zeros((2, 18))
    bad[1, 9] = np.inf
    with pytest.raises(MetricsError, match=r"true_poses: expected finite values.*frame 1, DOF 9"):
        knee_rmse_deg(np.zeros((2, 18)), bad, m)


def test_marker_helpers():
    m39, m18 = make_model(39), make_model(18)
    names = shared_markers(m39, m18)
    assert names == tuple(m18.joint_names[j] for j in m18.markers if m18.joint_names[j] in names)
    assert "left_knee" in names and "head" not in names
    x = m39.rest_pose()[None]
    P = marker_positions(m39, x)
    np.testing.assert_allclose(P, joint_positions(m39, x)[:, m39.markers])
    P18 = marker_positions(m39, x, joints=names)
    assert P18.shape == (1, len(names), 3)
    with pytest.raises(MetricsError, match="unknown 'nose'"):
        marker_positions(m39, x, joints=["nose"])


def test_offset_removed_error_by_hand():
    """A constant offset per joint disappears; what changes over the frames stays; NaN = missing."""
    from isa_mocap_ros.eval import offset_removed_errors_mm

    rng = np.random.default_rng(0)
    T = rng.normal(size=(6, 3, 3))
    off = np.array([[0.05, 0, 0], [0, -0.02, 0.01], [0, 0, 0]])
    P = T + off
    P[2, 1, 0] += 0.010                             # one joint 10 mm off in one frame
    e, o = offset_removed_errors_mm(P, T)
    mean_off = np.array([0.010 / 6, 0, 0])          # that frame's 10 mm shifts the joint's mean offset too
    want = np.zeros((6, 3))
    want[:, 1] = 1e3 * np.linalg.norm(np.array([0.010, 0, 0]) * (np.arange(6) == 2)[:, None] - mean_off, axis=1)
    np.testing.assert_allclose(e, want, atol=1e-9)
    np.testing.assert_allclose(o[0], 1e3 * off[0], atol=1e-9)
    T2 = T.copy()
    T2[0, 0] = np.nan                              # missing in one frame: left out of the mean, NaN error
    e2 = offset_removed_errors_mm(P, T2)[0]
    assert np.isnan(e2[0, 0]) and np.allclose(e2[1:, 0], 0, atol=1e-9)
    T2[:, 2] = np.nan                              # missing everywhere: NaN offset
    assert np.all(np.isnan(offset_removed_errors_mm(P, T2)[1][2]))
    with pytest.raises(MetricsError, match="true_joints: expected finite positions or NaN"):
        offset_removed_errors_mm(P, np.where(T2 == T2, T2, np.inf))
    with pytest.raises(MetricsError, match="pred_joints: expected finite"):
        offset_removed_errors_mm(np.where(T2 == T2, T2, np.nan), T)


def test_score_markers_reports_offsets_and_skips_missing_points():
    """Against the model's own joint centres moved by a constant offset: raw error = the offset,
    offset removed = 0; a missing (NaN) reference point is left out, not an error."""
    from isa_mocap_ros.eval import marker_positions, score_markers

    m = make_model(39)
    rng = np.random.default_rng(1)
    X = np.zeros((5, m.dof))
    X[:, 2] = 1.0
    X[:, 6:] = rng.normal(0, 0.2, size=(5, m.dof - 6))
    names = ["left_knee", "right_knee", "head", "Nose"]     # Nose: no joint of ours, not scored
    T = np.concatenate([marker_positions(m, X, joints=names[:3]), np.zeros((5, 1, 3))], axis=1)
    T[:, 0] += [0.03, 0.0, 0.04]                   # 50 mm constant offset of the left knee
    T[3, 1] = np.nan
    sc = score_markers(m, X, names, T)
    assert sc["markers"] == ["head", "left_knee", "right_knee"]
    assert sc["per_marker_mm"]["left_knee"] == pytest.approx(50.0)
    assert sc["per_marker_mm"]["right_knee"] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(sc["per_marker_offset_mm"]["left_knee"], [-30.0, 0.0, -40.0])  # no hips: world axes
    assert sc["offset_removed_mpjpe_mm"] == pytest.approx(0.0, abs=1e-9)
    # frame 3 has two points; the others three
    np.testing.assert_allclose(sc["frame_errors_mm"], [50 / 3, 50 / 3, 50 / 3, 25.0, 50 / 3])
    assert sc["worst_frame"] == 3
    with pytest.raises(MetricsError, match="NaN \\(missing\\) in every frame"):
        score_markers(m, X, names, np.full_like(T, np.nan))


def test_score_markers_counts_frames_facing_backwards():
    from isa_mocap_ros.eval import marker_positions, score_markers

    m = make_model(39)
    X = np.zeros((4, m.dof))
    X[:, 2] = 1.0
    names = ["left_hip", "right_hip", "left_shoulder", "right_shoulder"]
    T = marker_positions(m, X, joints=names)
    X[2, 5] = np.pi                            # frame 2 turned about the vertical by 180 deg
    X[3, 5] = np.radians(60)
    sc = score_markers(m, X, names, T)
    assert sc["frames_facing_backwards"] == 1
    assert sc["backwards_share"] == pytest.approx(0.25)
    np.testing.assert_allclose(sc["heading_errors_deg"], [0, 0, 180, 60], atol=1e-6)
