"""The compiled rigid body motions (geometry/se3_kernel.py), the predictor's compiled 13.28 root and the compiled
roll/pitch/yaw conversions agree with geometry's numpy formulas: near 0 (Taylor series), near π, in between. Within
1e-12, not bit for bit: numpy's sums of products follow the CPU's BLAS and einsum kernels (on the AMD EPYC the
kernels were written on they are equal; the tracks hash the same there, docs/history/issue35_speed.md)."""
import numpy as np
import pytest

from isa_mocap_ros.body.urdf import euler_to_root_rotvec, root_rotvec_to_euler
from isa_mocap_ros.geometry import adjoint, exp_se3, exp_so3, log_se3, log_so3, matrix_to_pose, nearest_rotvec, \
    pose_to_matrix
from isa_mocap_ros.geometry import se3_kernel as K
from isa_mocap_ros.tracking.predict import ArPredictor


def _rotvecs(n, seed):
    rng = np.random.default_rng(seed)
    W = rng.standard_normal((n, 3))
    k = np.arange(n) % 4
    scale = np.select([k == 0, k == 1, k == 2],
                      [1e-5 * rng.random(n), (np.pi - 2e-2 * rng.random(n)) / np.linalg.norm(W, axis=1),
                       0.1 * rng.random(n)], 3.0)
    return W * scale[:, None], rng


def _close(a, b):
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_se3_functions_agree_with_numpy():
    W, rng = _rotvecs(2000, 0)
    T, Ti, A, C, out = np.empty((4, 4)), np.empty((4, 4)), np.empty((6, 6)), np.empty((4, 4)), np.empty(6)
    for w in W:
        x6 = np.concatenate([rng.standard_normal(3), w])
        K.pose_to_matrix_into(x6, T)
        _close(T, pose_to_matrix(x6))
        K.inverse_into(T, Ti)
        _close(Ti, np.linalg.inv(pose_to_matrix(x6)))
        K.adjoint_into(T, A)
        _close(A, adjoint(T))
        K.exp_se3_into(x6, T)
        _close(T, exp_se3(x6))
        K.log_se3_into(exp_se3(x6), out)
        _close(out, log_se3(exp_se3(x6)))
        K.log_so3_into(exp_so3(w), out[:3])
        _close(out[:3], log_so3(exp_so3(w)))
        y = rng.standard_normal(6)
        K.gemv6(A, y, out)
        _close(out, A @ y)
        B = pose_to_matrix(rng.standard_normal(6))
        K.matmul4(T, B, C)
        _close(C, T @ B)
        ref = rng.standard_normal(3) * 4
        K.nearest_rotvec_into(w, ref, out[:3])
        _close(out[:3], nearest_rotvec(w, ref))


def _ar_root_numpy(X, lam):
    """13.28's root in geometry's numpy functions (the predictor's reference)."""
    P = pose_to_matrix(X)
    M = T = P[-1]
    for i in range(1, len(X)):
        Pinv = np.linalg.inv(P[i - 1])
        T = exp_se3(adjoint(M @ Pinv) @ (lam[i - 1] * log_se3(P[i] @ Pinv))) @ T
    root = matrix_to_pose(T)
    root[3:] = nearest_rotvec(root[3:], X[-1, 3:])
    return root


@pytest.mark.parametrize("seed", [0, 1])
def test_ar_predictor_root_agrees_with_the_numpy_formula(seed):
    rng = np.random.default_rng(seed)
    for trial in range(60):
        order = int(rng.integers(1, 5))
        ar = ArPredictor(order=order)
        x = rng.standard_normal(9) * 0.5
        x[3:6] *= rng.uniform(0, 3.3) / np.linalg.norm(x[3:6]) * (1e-5 if trial % 5 == 0 else 1.0)
        step = rng.standard_normal(9) * rng.choice([1e-6, 0.02, 0.3])
        for _ in range(6):
            ar.update(x)
            K_ = min(order, ar.n_estimates - 1)
            if K_:
                lam = ar.damping[-K_:] / ar.damping[-K_:].sum()
                _close(ar.predict()[:6], _ar_root_numpy(ar.history[-(K_ + 1):, :6], lam))
            x = x + step + rng.standard_normal(9) * 0.01


def test_roll_pitch_yaw_agree_with_numpy_and_keep_shapes():
    W, _ = _rotvecs(3000, 2)
    R = exp_so3(W)
    pitch = np.arcsin(np.clip(-R[:, 2, 0], -1.0, 1.0))
    ref = np.stack([np.arctan2(R[:, 2, 1], R[:, 2, 2]), pitch, np.arctan2(R[:, 1, 0], R[:, 0, 0])], axis=-1)
    rpy = root_rotvec_to_euler(W)
    _close(rpy, ref)
    z = np.zeros(len(W))
    back = log_so3(exp_so3(np.stack([z, z, rpy[:, 2]], -1)) @ exp_so3(np.stack([z, rpy[:, 1], z], -1))
                   @ exp_so3(np.stack([rpy[:, 0], z, z], -1)))
    _close(euler_to_root_rotvec(rpy), back)
    assert root_rotvec_to_euler(W[:6].reshape(2, 3, 3)).shape == (2, 3, 3)
    np.testing.assert_array_equal(root_rotvec_to_euler(W[0]), rpy[0])
    with pytest.raises(ValueError, match=r"rotvec: expected shape \(\.\.\., 3\)"):
        root_rotvec_to_euler(np.zeros(4))
    with pytest.raises(ValueError, match=r"rpy: expected shape \(\.\.\., 3\)"):
        euler_to_root_rotvec(np.zeros((2, 2)))
