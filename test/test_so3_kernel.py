"""The compiled SO(3) twins (geometry/so3_kernel.py) give geometry.so3's numbers bit for bit: near 0 (Taylor series),
near π (the axis from the symmetric part), in between, and composed."""
import numpy as np

from isa_mocap_ros.geometry import exp_so3, log_so3
from isa_mocap_ros.geometry import so3_kernel as K
from isa_mocap_ros.geometry.so3 import nearest_rotvec


def _rotvecs(n, seed):
    rng = np.random.default_rng(seed)
    W = rng.standard_normal((n, 3))
    scale = np.select([np.arange(n) % 4 == 0, np.arange(n) % 4 == 1, np.arange(n) % 4 == 2],
                      [1e-5 * rng.random(n), (np.pi - 2e-2 * rng.random(n)) / np.linalg.norm(W, axis=1),
                       0.1 * rng.random(n)], 3.0)
    return W * scale[:, None], rng


def test_exp_log_nearest_and_products_equal_numpy():
    W, rng = _rotvecs(8000, 0)
    R, C, out = np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
    for w in W:
        K.exp_into(w[0], w[1], w[2], R)
        ref = exp_so3(w)
        assert np.array_equal(R, ref)
        K.log_into(ref, float(np.arctan2(*K.log_args(ref))), out)
        assert np.array_equal(out, log_so3(ref))
        near = rng.standard_normal(3) * 4
        K.nearest_rotvec_into(w, near, out)
        # numpy's `w @ w` in nearest_rotvec is the BLAS's dot kernel, whose summation order depends on the CPU (the
        # twin follows the Xeon kernel's; on an AMD EPYC with AVX2, 448 of these 8000 differ by <= 3.6e-14 relative)
        np.testing.assert_allclose(out, nearest_rotvec(w, near), rtol=1e-13, atol=1e-15)
        d = rng.standard_normal(3) * 0.02
        K.exp_into(d[0], d[1], d[2], C)
        P = np.empty((3, 3))
        K.matmul3(C, R, P)
        assert np.array_equal(P, exp_so3(d) @ exp_so3(w))
