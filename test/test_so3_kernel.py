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
        assert np.array_equal(out, nearest_rotvec(w, near))
        d = rng.standard_normal(3) * 0.02
        K.exp_into(d[0], d[1], d[2], C)
        P = np.empty((3, 3))
        K.matmul3(C, R, P)
        assert np.array_equal(P, exp_so3(d) @ exp_so3(w))
