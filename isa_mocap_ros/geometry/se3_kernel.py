"""Compiled rigid body motions for one pose at a time: :mod:`.se3`'s ``exp_se3`` (13.25), ``log_se3`` (13.26),
``adjoint``, ``pose_to_matrix`` / ``matrix_to_pose`` (13.20) and :mod:`.so3`'s ``nearest_rotvec``, for compiled callers
(the predictor's 13.28 root, :mod:`isa_mocap_ros.tracking.predict`, and the JointState's roll/pitch/yaw,
:mod:`isa_mocap_ros.body.urdf`: with numpy each of their ~150 calls on 3-vectors and 4x4 matrices cost a few µs).

These functions *are* the definition where they are used. They follow :mod:`.se3`'s and :mod:`.so3`'s formulas in
numpy's order of operations (elementwise arithmetic as numpy writes it, ``sin``/``cos``/``atan2``/``asin``/``pow`` the C
library's), and accumulate each sum of products in the order of the BLAS and einsum kernels numpy called on the
machine this was written on (an AMD EPYC with AVX2, OpenBLAS): 3x3 and 4x4 products as fma chains (:func:`.so3_kernel.matmul3`,
:func:`matmul4`), a 6x6 matrix times a vector as OpenBLAS's ``dgemv_t`` (:func:`gemv6`), 3-dots left to right, a
contiguous 3x3 matrix times a contiguous vector by einsum as ``(p0 + p2) + p1``. There they give numpy's results bit
for bit (the tracks hash the same); on a CPU whose numpy kernels sum otherwise they differ from numpy's in the last
bits (``test/test_se3_kernel.py`` holds them to 1e-12), and the network and ``isa-mocap track`` still agree, since
both call these. No fastmath. Pure numba.
"""
from __future__ import annotations

import numba
import numpy as np

from isa_mocap_ros.numba_cache import register_dependent_cache

from . import so3_kernel
from .so3_kernel import exp_into, fma, log_args, log_into, matmul3

__all__ = ["matmul4", "gemv6", "exp_se3_into", "log_so3_into", "log_se3_into", "inverse_into", "adjoint_into",
           "pose_to_matrix_into", "nearest_rotvec_into"]

register_dependent_cache(__file__, (so3_kernel,))

_SMALL = 1e-4          # .se3._SMALL


@numba.njit(cache=True, inline="always")
def _dot3(a0, a1, a2, b0, b1, b2):  # pragma: no cover - compiled
    """``a @ b`` of two 3-vectors (numpy's dot; also einsum's order with a strided operand): left to right."""
    return (a0 * b0 + a1 * b1) + a2 * b2


@numba.njit(cache=True)
def matmul4(A, B, C):  # pragma: no cover - compiled
    """``C = A @ B`` for 4x4 matrices, accumulated as numpy's ``@`` (OpenBLAS dgemm): an fma chain."""
    for i in range(4):
        for j in range(4):
            s = 0.0
            for k in range(4):
                s = fma(A[i, k], B[k, j], s)
            C[i, j] = s


@numba.njit(cache=True)
def gemv6(A, y, out):  # pragma: no cover - compiled
    """``out = A @ y`` for a C-contiguous (6, 6) ``A`` as numpy's ``@`` (OpenBLAS ``dgemv_t``): per row the first four
    products summed as two lanes ``(p0 + p2) + (p1 + p3)``, then the last two as ``fma(a4, y4, a5 y5)`` added."""
    for i in range(6):
        head = (A[i, 0] * y[0] + A[i, 2] * y[2]) + (A[i, 1] * y[1] + A[i, 3] * y[3])
        out[i] = head + fma(A[i, 4], y[4], A[i, 5] * y[5])


@numba.njit(cache=True)
def _rodrigues(theta):  # pragma: no cover - compiled
    """``A = sin θ / θ``, ``B = (1 − cos θ) / θ²`` (Taylor series below ``θ = 1e-4``), as ``so3._rodrigues_coefficients``."""
    t2 = theta * theta
    if theta < _SMALL:
        return 1.0 - t2 / 6.0 + t2 * t2 / 120.0, 0.5 - t2 / 24.0 + t2 * t2 / 720.0
    return np.sin(theta) / theta, (1.0 - np.cos(theta)) / (theta * theta)


@numba.njit(cache=True)
def _hat_sq(w0, w1, w2, W, W2):  # pragma: no cover - compiled
    """``W = ŵ`` and ``W2 = ŵ ŵ`` (the 3x3 product as numpy's ``@``)."""
    W[0, 0], W[0, 1], W[0, 2] = 0.0, -w2, w1
    W[1, 0], W[1, 1], W[1, 2] = w2, 0.0, -w0
    W[2, 0], W[2, 1], W[2, 2] = -w1, w0, 0.0
    matmul3(W, W, W2)


@numba.njit(cache=True)
def log_so3_into(R, out):  # pragma: no cover - compiled
    """``out = log_so3(R)`` (13.21) for a 3x3 ``R`` (any strides), its angle ``atan2(s, c)``."""
    s, c = log_args(R)
    log_into(R, np.arctan2(s, c), out)


@numba.njit(cache=True)
def exp_se3_into(xi, T):  # pragma: no cover - compiled
    """``T = exp_se3(xi)`` (13.25) for a contiguous ``xi = (v, ω)``: ``[R  V v; 0 1]``, ``V = I + B ω̂ + C ω̂²``."""
    w0, w1, w2 = xi[3], xi[4], xi[5]
    theta = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    A, B = _rodrigues(theta)
    t2 = theta * theta
    if theta < _SMALL:
        C = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0
    else:
        C = (theta - np.sin(theta)) / np.power(theta, 3.0)
    W, W2, V = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    _hat_sq(w0, w1, w2, W, W2)
    for i in range(3):
        for j in range(3):
            e = 1.0 if i == j else 0.0
            T[i, j] = (e + A * W[i, j]) + B * W2[i, j]
            V[i, j] = (e + B * W[i, j]) + C * W2[i, j]
    for i in range(3):              # einsum's V v, both contiguous: (p0 + p2) + p1
        T[i, 3] = (V[i, 0] * xi[0] + V[i, 2] * xi[2]) + V[i, 1] * xi[1]
    T[3, 0], T[3, 1], T[3, 2], T[3, 3] = 0.0, 0.0, 0.0, 1.0


@numba.njit(cache=True)
def log_se3_into(T, out):  # pragma: no cover - compiled
    """``out = log_se3(T)`` (13.26): ``ω = log R``, ``v = V⁻¹ t``, ``V⁻¹ = I − ω̂/2 + D ω̂²``."""
    w = out[3:]
    log_so3_into(T[:3, :3], w)
    w0, w1, w2 = w[0], w[1], w[2]
    theta = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    A, B = _rodrigues(theta)
    if theta < _SMALL:
        D = 1.0 / 12.0 + theta * theta / 720.0 + np.power(theta, 4.0) / 30240.0
    else:
        D = (1.0 - A / (2.0 * B)) / (theta * theta)
    W, W2 = np.empty((3, 3)), np.empty((3, 3))
    _hat_sq(w0, w1, w2, W, W2)
    Vi = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            Vi[i, j] = ((1.0 if i == j else 0.0) - 0.5 * W[i, j]) + D * W2[i, j]
    for i in range(3):              # einsum's V⁻¹ t, t a strided column: left to right
        out[i] = _dot3(Vi[i, 0], Vi[i, 1], Vi[i, 2], T[0, 3], T[1, 3], T[2, 3])


@numba.njit(cache=True)
def inverse_into(T, Ti):  # pragma: no cover - compiled
    """``Ti = T⁻¹ = [Rᵀ  −Rᵀ t; 0 1]`` (``−Rᵀ t`` left to right, as numpy's strided product)."""
    for i in range(3):
        for j in range(3):
            Ti[i, j] = T[j, i]
        Ti[i, 3] = _dot3(-T[0, i], -T[1, i], -T[2, i], T[0, 3], T[1, 3], T[2, 3])
    Ti[3, 0], Ti[3, 1], Ti[3, 2], Ti[3, 3] = 0.0, 0.0, 0.0, 1.0


@numba.njit(cache=True)
def adjoint_into(T, Ad):  # pragma: no cover - compiled
    """``Ad = Ad_T = [R  t̂R; 0  R]`` (6, 6) for ``(v, ω)`` twists."""
    Ad[:] = 0.0
    H, HR = np.empty((3, 3)), np.empty((3, 3))
    H[0, 0], H[0, 1], H[0, 2] = 0.0, -T[2, 3], T[1, 3]
    H[1, 0], H[1, 1], H[1, 2] = T[2, 3], 0.0, -T[0, 3]
    H[2, 0], H[2, 1], H[2, 2] = -T[1, 3], T[0, 3], 0.0
    matmul3(H, T[:3, :3], HR)
    for i in range(3):
        for j in range(3):
            Ad[i, j] = T[i, j]
            Ad[i, 3 + j] = HR[i, j]
            Ad[3 + i, 3 + j] = T[i, j]


@numba.njit(cache=True)
def pose_to_matrix_into(x6, T):  # pragma: no cover - compiled
    """``T = pose_to_matrix(x6)``: ``[exp(ŵ) t; 0 1]`` of a root pose ``(t, w)`` (13.20)."""
    exp_into(x6[3], x6[4], x6[5], T[:3, :3])
    for i in range(3):
        T[i, 3] = x6[i]
        T[3, i] = 0.0
    T[3, 3] = 1.0


@numba.njit(cache=True)
def nearest_rotvec_into(w, ref, out):  # pragma: no cover - compiled
    """``out = nearest_rotvec(w, ref)`` with numpy's 3-dots (left to right; :func:`.so3_kernel.nearest_rotvec_into`,
    the contour stage's, sums as fma chains): ``(θ + 2πm) ω`` of ``w = θ ω`` nearest to ``ref``."""
    theta = np.sqrt(_dot3(w[0], w[1], w[2], w[0], w[1], w[2]))
    out[0], out[1], out[2] = w[0], w[1], w[2]
    if theta < 1e-12:
        return
    a0, a1, a2 = w[0] / theta, w[1] / theta, w[2] / theta
    m = np.round((_dot3(a0, a1, a2, ref[0], ref[1], ref[2]) - theta) / (2.0 * np.pi))
    if m != 0:
        t = theta + 2.0 * np.pi * m
        out[0], out[1], out[2] = a0 * t, a1 * t, a2 * t
