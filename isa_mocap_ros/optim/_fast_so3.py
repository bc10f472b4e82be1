"""Compiled Rodrigues exponential (13.20) and logarithm (13.21) for the rotation mean (13.24).

The same formulas as the numpy reference in :mod:`._rotations` (``exp_so3``, ``log_so3``), per
rotation instead of per array, for :func:`._rotations.rotation_mean`: with numpy each fixed-point
step cost ~0.25 ms of small-array overhead (the tracker calls the mean ~15 times per frame).

The results are bit-identical to the numpy reference on this machine: elementwise operations run in
numpy's order, ``sin``/``cos``/``arccos``/``sqrt`` are the C library's, sums of three terms add left
to right (numpy's pairwise sum below 8 elements), and 3x3 products accumulate
``C_ij = fma(A_i2, B_2j, fma(A_i1, B_1j, A_i0 B_0j))``, the order of OpenBLAS's Haswell ``dgemm``
that numpy's ``@`` calls (measured; ``test/test_optim_rotations.py`` checks it;
:func:`isa_mocap_ros.geometry.so3_kernel.matmul3`, shared with the contour stage's rotations). ``llvm.fma`` is
correctly rounded on every CPU, so the compiled results are deterministic everywhere; only the
agreement with numpy depends on the BLAS kernel. No fastmath.
"""
from __future__ import annotations

import numba
import numpy as np

from isa_mocap_ros.geometry import so3_kernel
from isa_mocap_ros.geometry.so3_kernel import matmul3 as _matmul
from isa_mocap_ros.numba_cache import register_dependent_cache

__all__ = ["exp_many", "relative_logs", "compose"]

# the 3x3 product (``fma`` chains) is geometry's: this module's cache keyed on that file too
register_dependent_cache(__file__, (so3_kernel,))


@numba.njit(cache=True)
def _exp(r, R):  # pragma: no cover - compiled
    """``R = exp(r)`` (13.20): ``I + a K + b K^2`` with ``K = hat(r)``, Taylor terms for small angles."""
    th2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    if th2 < 1e-8:
        a = 1.0 - th2 / 6.0
        b = 0.5 - th2 / 24.0
    else:
        th = np.sqrt(th2)
        a = np.sin(th) / th
        b = (1.0 - np.cos(th)) / (th * th)
    K = np.zeros((3, 3))
    K[0, 1], K[0, 2] = -r[2], r[1]
    K[1, 0], K[1, 2] = r[2], -r[0]
    K[2, 0], K[2, 1] = -r[1], r[0]
    K2 = np.empty((3, 3))
    _matmul(K, K, K2)
    for i in range(3):
        for j in range(3):
            R[i, j] = ((1.0 if i == j else 0.0) + a * K[i, j]) + b * K2[i, j]


@numba.njit(cache=True)
def _log(R, out):  # pragma: no cover - compiled
    """``out = log(R)`` (13.21), with the axis from the symmetric part near ``theta = pi``."""
    cos = min(max(((R[0, 0] + R[1, 1] + R[2, 2]) - 1.0) / 2.0, -1.0), 1.0)
    th = np.arccos(cos)
    v0 = R[2, 1] - R[1, 2]
    v1 = R[0, 2] - R[2, 0]
    v2 = R[1, 0] - R[0, 1]
    if th > np.pi - 1e-3:
        B = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                B[i, j] = (R[i, j] + R[j, i]) / 2.0 - cos * (1.0 if i == j else 0.0)
        k = 0
        for i in range(1, 3):
            if B[i, i] > B[k, k]:
                k = i
        c0, c1, c2 = B[0, k], B[1, k], B[2, k]
        norm = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        a0, a1, a2 = c0 / norm, c1 / norm, c2 / norm
        sgn = -1.0 if a0 * v0 + a1 * v1 + a2 * v2 < 0 else 1.0
        t = sgn * th
        out[0], out[1], out[2] = a0 * t, a1 * t, a2 * t
        return
    if th < 1e-4:
        f = 0.5 + th * th / 12.0
    else:
        f = th / (2.0 * np.sin(th))
    out[0], out[1], out[2] = f * v0, f * v1, f * v2


@numba.njit(cache=True)
def exp_many(r):  # pragma: no cover - compiled
    """Rotation matrices ``(n, 3, 3)`` of rotation vectors ``r : (n, 3)``."""
    n = r.shape[0]
    R = np.empty((n, 3, 3))
    for i in range(n):
        _exp(r[i], R[i])
    return R


@numba.njit(cache=True)
def relative_logs(mean, Ri):  # pragma: no cover - compiled
    """``log(exp(mean)^T R_i)`` for each ``R_i`` of ``Ri : (n, 3, 3)``, i.e. ``r^{-1} * r_i``, ``(n, 3)``."""
    M = np.empty((3, 3))
    _exp(mean, M)
    MT = M.T.copy()
    n = Ri.shape[0]
    D = np.empty((3, 3))
    out = np.empty((n, 3))
    for i in range(n):
        _matmul(MT, Ri[i], D)
        _log(D, out[i])
    return out


@numba.njit(cache=True)
def compose(a, b):  # pragma: no cover - compiled
    """``a * b = log(exp(a) exp(b))``, ``(3,)``."""
    A = np.empty((3, 3))
    B = np.empty((3, 3))
    C = np.empty((3, 3))
    _exp(a, A)
    _exp(b, B)
    _matmul(A, B, C)
    out = np.empty(3)
    _log(C, out)
    return out
