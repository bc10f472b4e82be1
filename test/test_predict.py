"""Pose prediction: AR on twists (ISA 13.28) and the constant-pose / constant-velocity baselines."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.geometry import exp_se3, log_se3, matrix_to_pose, pose_to_matrix
from isa_mocap_ros.tracking.predict import (
    ArPredictor,
    ConstantPosePredictor,
    ConstantVelocityPredictor,
    PredictionError,
)

N_JOINTS = 9


def constant_twist_motion(rng: np.random.Generator, n_frames: int) -> np.ndarray:
    """Poses x_k (n_frames + 1, 6 + N_JOINTS): P_k = exp(ξ)^k P_0, joint angles q_0 + k v."""
    xi = np.concatenate([rng.normal(0, 0.05, 3), rng.normal(0, 0.12, 3)])   # (v, ω)
    P0 = pose_to_matrix(np.concatenate([rng.normal(0, 1, 3), rng.normal(0, 0.8, 3)]))
    step = exp_se3(xi)
    q0, v = rng.normal(0, 0.5, N_JOINTS), rng.normal(0, 0.03, N_JOINTS)
    out, P = [], P0
    for k in range(n_frames + 1):
        root = matrix_to_pose(P)
        if out:   # keep the rotation vector continuous (|w| may exceed π), as a tracker's would be
            root[3:] = unwrap_rotvec(root[3:], out[-1][3:6])
        out.append(np.concatenate([root, q0 + k * v]))
        P = step @ P
    return np.array(out)


def unwrap_rotvec(w: np.ndarray, ref: np.ndarray) -> np.ndarray:
    theta = np.linalg.norm(w)
    cands = [w / theta * (theta + 2 * np.pi * m) for m in range(-2, 3)]
    return min(cands, key=lambda c: np.linalg.norm(c - ref))


@pytest.mark.parametrize("order", [1, 2, 3, 5])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ar_extrapolates_constant_twist_motion_exactly(order, seed):
    X = constant_twist_motion(np.random.default_rng(seed), 8)
    damping = np.random.default_rng(seed + 10).uniform(0.1, 1.0, order)
    for ar in (ArPredictor(order=order), ArPredictor(order=order, damping=damping)):
        for k in range(8):
            ar.update(X[k])
            want = X[k + 1] if k >= 1 else X[k]
            pred = ar.predict()
            np.testing.assert_allclose(pred, want, rtol=0, atol=1e-9)
            np.testing.assert_allclose(pose_to_matrix(pred[:6]), pose_to_matrix(want[:6]), atol=1e-9)


def test_damping_is_normalised_and_defaults_to_recent_first():
    ar = ArPredictor(order=3, damping=[1, 1, 2])
    np.testing.assert_allclose(ar.damping, [0.25, 0.25, 0.5])
    default = ArPredictor(order=4)
    assert default.damping.sum() == pytest.approx(1.0, abs=1e-15)
    assert np.all(np.diff(default.damping) > 0)
    np.testing.assert_allclose(default.damping, np.arange(1, 5) / 10)


def body_frame_reference(X: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Independent form of 13.28: P_pred = M exp(λ_K ζ_K) ... exp(λ_1 ζ_1), ζ_i = log(P_{i-1}^-1 P_i)."""
    P = pose_to_matrix(X[:, :6])
    T = P[-1].copy()
    for i in range(len(X) - 1, 0, -1):               # newest increment leftmost
        zeta = log_se3(np.linalg.inv(P[i - 1]) @ P[i])
        T = T @ exp_se3(lam[i - 1] * zeta)
    q = X[-1, 6:] + lam @ np.diff(X[:, 6:], axis=0)
    return np.concatenate([matrix_to_pose(T), q])


def test_ar_on_irregular_motion_matches_the_body_frame_form():
    rng = np.random.default_rng(5)
    X = np.cumsum(rng.normal(0, 0.1, (4, 6 + N_JOINTS)), axis=0)   # no constant twist
    lam = np.array([0.2, 0.3, 0.5])
    ar = ArPredictor(order=3, damping=lam)
    for x in X:
        ar.update(x)
    np.testing.assert_allclose(ar.predict(), body_frame_reference(X, lam), rtol=0, atol=1e-12)
    # and it differs from the naive pose-vector constant velocity
    cv = ConstantVelocityPredictor()
    for x in X:
        cv.update(x)
    assert np.abs(ar.predict()[:6] - cv.predict()[:6]).max() > 1e-3


def test_ar_with_short_history_uses_newest_weights():
    rng = np.random.default_rng(6)
    X = np.cumsum(rng.normal(0, 0.1, (3, 6 + N_JOINTS)), axis=0)
    ar = ArPredictor(order=4, damping=[5.0, 1.0, 1.0, 2.0])
    for x in X:
        ar.update(x)
    np.testing.assert_allclose(ar.predict(), body_frame_reference(X, np.array([1.0, 2.0]) / 3),
                               rtol=0, atol=1e-12)


def test_ar_history_is_bounded_by_order():
    ar = ArPredictor(order=2)
    for k in range(6):
        ar.update(np.full(8, float(k)))
    assert ar.n_estimates == 3
    np.testing.assert_array_equal(ar.history[:, 0], [3.0, 4.0, 5.0])


def test_ar_rotation_vector_stays_continuous_through_pi():
    ar = ArPredictor(order=2, root_slice=slice(0, 6))
    for angle in (2.9, 3.1, 3.3):     # about z, past π: a valid, continuous rotation vector
        ar.update([0, 0, 0, 0, 0, angle, 0.0])
    pred = ar.predict()
    np.testing.assert_allclose(pred[3:6], [0, 0, 3.5], atol=1e-9)


def test_root_slice_elsewhere_and_none():
    rng = np.random.default_rng(7)
    X = constant_twist_motion(rng, 4)
    moved = np.hstack([X[:, 6:9], X[:, :6], X[:, 9:]])            # root at columns 3..8
    ar = ArPredictor(order=2, root_slice=slice(3, 9))
    for x in moved[:4]:
        ar.update(x)
    np.testing.assert_allclose(ar.predict(), moved[4], atol=1e-9)
    flat = ArPredictor(order=1, root_slice=None)                 # pure constant velocity
    flat.update([0.0, 1.0])
    flat.update([1.0, 3.0])
    np.testing.assert_allclose(flat.predict(), [2.0, 5.0])


def test_constant_pose_and_velocity_baselines():
    a, b = np.array([0.0, 1.0, 2.0]), np.array([1.0, 1.5, 2.0])
    cp, cv = ConstantPosePredictor(), ConstantVelocityPredictor()
    for p in (cp, cv):
        p.update(a)
        np.testing.assert_array_equal(p.predict(), a)
        p.update(b)
    np.testing.assert_array_equal(cp.predict(), b)
    np.testing.assert_array_equal(cv.predict(), [2.0, 2.0, 2.0])
    out = cp.predict()
    out[0] = 99.0                                                # returns copies
    np.testing.assert_array_equal(cp.predict(), b)


@pytest.mark.parametrize("make", [ArPredictor, ConstantPosePredictor, ConstantVelocityPredictor])
def test_nan_is_rejected_and_history_untouched(make):
    p = make()
    x0, x1 = np.arange(8.0) * 0.1, np.arange(8.0) * 0.12
    p.update(x0)
    p.update(x1)
    before = p.predict()
    bad = x1.copy()
    bad[5] = np.nan
    with pytest.raises(PredictionError, match=r"x: expected finite values, got nan at index 5"):
        p.update(bad)
    with pytest.raises(PredictionError, match=r"x: expected shape \(8,\) like the earlier estimates, got \(7,\)"):
        p.update(x1[:7])
    np.testing.assert_array_equal(p.predict(), before)
    assert p.n_estimates == min(2, p.history.shape[0])


@pytest.mark.parametrize("make", [ArPredictor, ConstantPosePredictor, ConstantVelocityPredictor])
def test_empty_and_reset(make):
    p = make()
    with pytest.raises(PredictionError, match="no estimate yet"):
        p.predict()
    p.update(np.zeros(7))
    p.reset()
    assert p.n_estimates == 0 and p.n_dof is None
    with pytest.raises(PredictionError, match="no estimate yet"):
        p.predict()
    p.update(np.ones(9))                                         # a new length after reset
    assert p.n_dof == 9


def test_bad_settings_raise():
    with pytest.raises(PredictionError, match=r"order: expected an integer >= 1, got 0"):
        ArPredictor(order=0)
    with pytest.raises(PredictionError, match=r"damping: expected 3 weights"):
        ArPredictor(order=3, damping=[1, 1])
    with pytest.raises(PredictionError, match=r"damping: expected finite non-negative"):
        ArPredictor(order=2, damping=[1, -1])
    ar = ArPredictor(root_slice=slice(0, 6))
    with pytest.raises(PredictionError, match=r"root_slice: expected 6 coordinates of a pose of length 4"):
        ar.update(np.zeros(4))
    assert ar.n_estimates == 0


@pytest.mark.parametrize("order", [1, 2, 3])
@pytest.mark.parametrize("seed", [0, 1])
def test_ar_extrapolates_constant_twist_motion_sampled_at_irregular_gaps(order, seed):
    """Estimates of frames 0, 1, 3, 4, 7, 9 (a network dropping frame sets): told the gaps, the
    prediction of any frame ahead is exact; not told, it is off."""
    X = constant_twist_motion(np.random.default_rng(seed), 16)
    seen = [0, 1, 3, 4, 7, 9]
    ar, naive = ArPredictor(order=order), ArPredictor(order=order)
    for i, k in enumerate(seen):
        ar.update(X[k], frames=1 if i == 0 else k - seen[i - 1])
        naive.update(X[k])
    for ahead in (1, 2, 3.0, 5):
        want = X[9 + int(ahead)]
        pred = ar.predict(frames=ahead)
        np.testing.assert_allclose(pose_to_matrix(pred[:6]), pose_to_matrix(want[:6]), atol=1e-9)
        np.testing.assert_allclose(pred[6:], want[6:], atol=1e-9)
    assert np.abs(naive.predict() - X[10]).max() > 1e-3


def test_gaps_of_one_are_the_plain_formula_bit_for_bit():
    """Uniform gaps g with h = g periods ahead give the same bits as the gapless predictor (the
    factors h / g are exactly 1.0): consecutive frames and lockstep replays are unchanged."""
    X = constant_twist_motion(np.random.default_rng(5), 6) + np.random.default_rng(6).normal(0, 0.01, (7, 6 + N_JOINTS))
    for make in (lambda: ArPredictor(order=3), ConstantVelocityPredictor, ConstantPosePredictor):
        plain, gapped = make(), make()
        for k in range(7):
            plain.update(X[k])
            gapped.update(X[k], frames=3)
            assert np.array_equal(plain.predict(), gapped.predict(frames=3))
            assert np.array_equal(plain.predict(), plain.predict(frames=1))


def test_constant_velocity_with_gaps():
    cv = ConstantVelocityPredictor()
    cv.update([0.0, 1.0])
    cv.update([0.4, 1.2], frames=2)                  # 0.2 / 0.1 per period
    np.testing.assert_allclose(cv.predict(frames=3), [1.0, 1.5])
    np.testing.assert_allclose(cv.predict(), [0.6, 1.3])


@pytest.mark.parametrize("bad", [0, -1, float("nan"), float("inf"), True, "2", None])
def test_bad_frame_counts_are_rejected_and_history_untouched(bad):
    for p in (ArPredictor(order=2), ConstantVelocityPredictor(), ConstantPosePredictor()):
        p.update([0.0] * 7)
        with pytest.raises(PredictionError, match="frames: expected a number of frame periods > 0"):
            p.update([0.1] * 7, frames=bad)
        assert p.n_estimates == 1
        with pytest.raises(PredictionError, match="frames"):
            p.predict(frames=bad)


def test_periods_between_stamps():
    from isa_mocap_ros.tracking.predict import periods_between
    p = 1 / 30
    assert periods_between(None, 5, p) == 1
    assert periods_between(0, 33_333_333, p) == 1
    assert periods_between(0, 3 * 33_333_333 + 1, p) == 3
    assert periods_between(0, 20_000_000, p) == 1          # closer than a period: still 1
    assert periods_between(10**9, 10**9, p) == 1 and periods_between(10**9, 5, p) == 1   # not newer
