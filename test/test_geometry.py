"""Property tests for isa_mocap_ros.geometry (ISA Eq. 13.20-13.27), seeded random + hypothesis."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm, logm

from isa_mocap_ros.geometry import (GeometryError, adjoint, exp_se3, exp_so3, hat, log_se3, log_so3,
                                    matrix_to_pose, pose_to_matrix, rotation_mean, vee)

vec3 = st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=3).map(np.array)


def random_rotvecs(rng, n, max_angle=np.pi):
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return axis * rng.uniform(0, max_angle, size=(n, 1))


def test_hat_vee_cross_product():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 50, 3))
    np.testing.assert_allclose(hat(a) @ b[..., None], np.cross(a, b)[..., None], atol=1e-12)
    np.testing.assert_allclose(vee(hat(a)), a, atol=1e-15)


def test_exp_matches_matrix_exponential():
    rng = np.random.default_rng(1)
    w = random_rotvecs(rng, 20)
    R = exp_so3(w)
    for wi, Ri in zip(w, R):
        np.testing.assert_allclose(Ri, expm(hat(wi)), atol=1e-12)
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(vec3)
def test_log_exp_round_trip(w):
    theta = np.linalg.norm(w)
    if theta > np.pi - 1e-6:  # outside the principal range: compare rotations instead
        np.testing.assert_allclose(exp_so3(log_so3(exp_so3(w))), exp_so3(w), atol=1e-9)
        return
    np.testing.assert_allclose(log_so3(exp_so3(w)), w, atol=1e-9)


@pytest.mark.parametrize("theta", [0.0, 1e-12, 1e-9, 1e-6, 1e-5, 1e-4, 2e-4, 1e-3, 0.1])
def test_round_trip_near_zero(theta):
    rng = np.random.default_rng(2)
    w = random_rotvecs(rng, 30, 1.0)
    w = w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300) * theta
    R = exp_so3(w)
    np.testing.assert_allclose(R, np.stack([expm(hat(x)) for x in w]), atol=1e-15 + 1e-12 * theta)
    np.testing.assert_allclose(log_so3(R), w, atol=1e-14 + 1e-10 * theta, rtol=1e-9)


@pytest.mark.parametrize("delta", [0.0, 1e-12, 1e-8, 1e-5, 1e-3, 5e-3, 2e-2])
def test_round_trip_near_pi(delta):
    rng = np.random.default_rng(3)
    axis = random_rotvecs(rng, 40, 1.0)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    w = axis * (np.pi - delta)
    R = exp_so3(w)
    back = log_so3(R)
    np.testing.assert_allclose(exp_so3(back), R, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(back, axis=1), np.pi - delta, atol=1e-9)
    if delta >= 1e-8:  # the sign of the axis is determined: exact round trip
        np.testing.assert_allclose(back, w, atol=1e-7)
    else:  # exactly π: canonical sign (largest axis component positive)
        big = back[np.arange(len(back)), np.argmax(np.abs(back), axis=1)]
        assert np.all(big > 0)


def test_log_pi_rotation_about_coordinate_axes():
    for k in range(3):
        R = -np.eye(3)
        R[k, k] = 1.0
        w = log_so3(R)
        expected = np.zeros(3)
        expected[k] = np.pi
        np.testing.assert_allclose(w, expected, atol=1e-12)


def test_log_matches_matrix_logarithm():
    rng = np.random.default_rng(4)
    for w in random_rotvecs(rng, 10, 3.0):
        np.testing.assert_allclose(hat(log_so3(exp_so3(w))), logm(exp_so3(w)).real, atol=1e-9)


def test_rotation_mean_of_identical_rotations():
    rng = np.random.default_rng(5)
    for r in random_rotvecs(rng, 5, 3.0):
        np.testing.assert_allclose(rotation_mean(np.tile(r, (7, 1)), rng.uniform(0.1, 1, 7)), r, atol=1e-12)


def test_rotation_mean_satisfies_fixed_point_and_is_left_invariant():
    rng = np.random.default_rng(6)
    center = random_rotvecs(rng, 1, 2.0)[0]
    spread = random_rotvecs(rng, 25, 0.6)
    R = exp_so3(center) @ exp_so3(spread)
    r = log_so3(R)
    weights = rng.uniform(0, 1, 25)
    mean = rotation_mean(r, weights, iters=50, tol=1e-14)
    # Eq. 13.22 (weighted): Σ π_i log(exp(mean)ᵀ R_i) = 0
    resid = weights @ log_so3(exp_so3(mean).T @ R)
    np.testing.assert_allclose(resid, 0.0, atol=1e-9)
    # Left-multiplying every rotation by Q left-multiplies the mean
    Q = exp_so3(random_rotvecs(rng, 1, 3.0)[0])
    mean_q = rotation_mean(log_so3(Q @ R), weights, iters=50, tol=1e-14)
    np.testing.assert_allclose(exp_so3(mean_q), Q @ exp_so3(mean), atol=1e-9)
    # Small spread: close to the weighted Euclidean mean in the chart around the centre
    assert np.linalg.norm(log_so3(exp_so3(center).T @ exp_so3(mean))) < 0.6


def test_rotation_mean_weights_select():
    r = np.array([[0.1, 0, 0], [0, 0.5, 0]])
    np.testing.assert_allclose(rotation_mean(r, np.array([1.0, 0.0])), r[0], atol=1e-12)
    mean = rotation_mean(np.array([[0, 0, 0.2], [0, 0, 0.6]]))  # same axis: arithmetic mean
    np.testing.assert_allclose(mean, [0, 0, 0.4], atol=1e-12)


def test_rotation_mean_bad_input():
    with pytest.raises(GeometryError, match=r"rotvecs: expected shape \(n, 3\)"):
        rotation_mean(np.zeros((3, 4)))
    with pytest.raises(GeometryError, match=r"weights: expected shape \(2,\)"):
        rotation_mean(np.zeros((2, 3)), np.ones(3))
    with pytest.raises(GeometryError, match="weights: expected finite, non-negative"):
        rotation_mean(np.zeros((2, 3)), np.array([1.0, -1.0]))
    with pytest.raises(GeometryError, match="NaN"):
        rotation_mean(np.array([[np.nan, 0, 0]]))
    with pytest.raises(GeometryError, match=r"w: expected shape \(\.\.\., 3\)"):
        exp_so3(np.zeros(4))
    with pytest.raises(GeometryError, match=r"R: expected shape \(\.\.\., 3, 3\)"):
        log_so3(np.eye(4))


def twists(rng, n, max_angle=3.0):
    return np.concatenate([rng.normal(size=(n, 3)), random_rotvecs(rng, n, max_angle)], axis=1)


def test_exp_se3_matches_matrix_exponential():
    rng = np.random.default_rng(7)
    xi = twists(rng, 20)
    T = exp_se3(xi)
    for x, Ti in zip(xi, T):
        M = np.zeros((4, 4))
        M[:3, :3] = hat(x[3:])
        M[:3, 3] = x[:3]
        np.testing.assert_allclose(Ti, expm(M), atol=1e-10)


@pytest.mark.parametrize("theta", [0.0, 1e-9, 1e-5, 3e-4, 0.5, 2.0, np.pi - 1e-4])
def test_se3_round_trip(theta):
    rng = np.random.default_rng(8)
    xi = twists(rng, 30)
    xi[:, 3:] *= theta / np.maximum(np.linalg.norm(xi[:, 3:], axis=1, keepdims=True), 1e-300)
    np.testing.assert_allclose(log_se3(exp_se3(xi)), xi, atol=1e-8)
    T = exp_se3(xi)
    np.testing.assert_allclose(exp_se3(log_se3(T)), T, atol=1e-10)


def test_log_se3_agrees_with_paper_formula():
    """Eq. 13.26-13.27: v_paper = A⁻¹ t with unit ω; our v carries θ: v = θ v_paper."""
    rng = np.random.default_rng(9)
    for xi in twists(rng, 10, 3.0):
        T = exp_se3(xi)
        w = log_so3(T[:3, :3])
        theta = np.linalg.norm(w)
        om = w / theta
        A = (np.eye(3) - exp_so3(w)) @ hat(om) + np.outer(om, om) * theta
        v_paper = np.linalg.solve(A, T[:3, 3])
        np.testing.assert_allclose(log_se3(T)[:3], theta * v_paper, atol=1e-9)


def test_adjoint_identity():
    rng = np.random.default_rng(10)
    for _ in range(20):
        T = exp_se3(twists(rng, 1)[0])
        xi = twists(rng, 1, 2.0)[0]
        lhs = T @ exp_se3(xi) @ np.linalg.inv(T)
        np.testing.assert_allclose(lhs, exp_se3(adjoint(T) @ xi), atol=1e-10)


def test_pose_matrix_round_trip():
    rng = np.random.default_rng(11)
    x6 = np.concatenate([rng.normal(size=(40, 3)), random_rotvecs(rng, 40, 3.0)], axis=1)
    T = pose_to_matrix(x6)
    np.testing.assert_allclose(T[:, :3, 3], x6[:, :3])
    np.testing.assert_allclose(T[:, :3, :3], exp_so3(x6[:, 3:]))
    np.testing.assert_allclose(matrix_to_pose(T), x6, atol=1e-10)
    with pytest.raises(GeometryError, match=r"x6: expected shape \(\.\.\., 6\)"):
        pose_to_matrix(np.zeros(5))
