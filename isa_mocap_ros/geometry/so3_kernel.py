"""Compiled twins of :mod:`.so3`'s ``exp_so3`` (13.20), ``log_so3`` (13.21) and ``nearest_rotvec`` for one rotation,
for compiled callers (the tracker's contour stage turns its root by ``log(exp(δ) exp(r))`` every step: with numpy
each call cost 30-50 µs of small-array overhead).

The same formulas in numpy's order, so the results are :mod:`.so3`'s bit for bit on this machine
(``test/test_so3_kernel.py``): elementwise operations as numpy evaluates them, ``sin``/``cos``/``sqrt`` the C
library's (numpy's agree with it), the logarithm's angle left to the caller as numpy's ``arctan2(s, c)`` of
:func:`log_args` (numpy's SIMD ``arctan2`` differs from the C library's in the last bit for ~8 % of arguments), the squared norm summed left to right (``axis=-1`` norms) or as OpenBLAS's ``ddot`` (``w @ w``), and 3x3 products accumulated
``C_ij = fma(A_i2, B_2j, fma(A_i1, B_1j, A_i0 B_0j))``, the order of the OpenBLAS ``dgemm`` numpy's ``@`` calls (as
:mod:`isa_mocap_ros.optim._fast_so3` found for the rotation mean; ``llvm.fma`` is correctly rounded on every CPU, so
the compiled results are deterministic everywhere, only their agreement with numpy depends on the BLAS kernel). No
fastmath. Pure numba.
"""
from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

__all__ = ["exp_into", "fma", "log_args", "log_into", "matmul3", "nearest_rotvec_into"]

_SMALL = 1e-4          # .so3._SMALL
_NEAR_PI = 1e-2        # .so3._NEAR_PI


@intrinsic
def fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (LLVM's ``llvm.fma.f64``), for compiled callers (also
    :mod:`isa_mocap_ros.optim._fast_so3`)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        f = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(f, args)
    return sig, codegen


@numba.njit(cache=True, inline="always")
def _dot3(a0, a1, a2, b0, b1, b2):  # pragma: no cover - compiled
    """``a @ b`` of two 3-vectors as numpy's ``@`` (OpenBLAS ddot) sums them: ``fma(a2, b2, fma(a1, b1, a0 b0))``."""
    return fma(a2, b2, fma(a1, b1, a0 * b0))


@numba.njit(cache=True)
def matmul3(A, B, C):  # pragma: no cover - compiled
    """``C = A @ B`` for 3x3 matrices, accumulated as numpy's ``@`` (OpenBLAS dgemm) does."""
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s = fma(A[i, k], B[k, j], s)
            C[i, j] = s


@numba.njit(cache=True)
def exp_into(w0, w1, w2, R):  # pragma: no cover - compiled
    """``R = exp_so3((w0, w1, w2))``: ``I + A ŵ + B ŵ²``, ``A = sin θ / θ``, ``B = (1 − cos θ) / θ²``
    (Taylor series below ``θ = 1e-4``)."""
    theta = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    t2 = theta * theta
    if theta < _SMALL:
        A = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        B = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
    else:
        A = np.sin(theta) / theta
        B = (1.0 - np.cos(theta)) / (theta * theta)
    W = np.zeros((3, 3))
    W[0, 1], W[0, 2] = -w2, w1
    W[1, 0], W[1, 2] = w2, -w0
    W[2, 0], W[2, 1] = -w1, w0
    W2 = np.empty((3, 3))
    matmul3(W, W, W2)
    for i in range(3):
        for j in range(3):
            R[i, j] = ((1.0 if i == j else 0.0) + A * W[i, j]) + B * W2[i, j]


@numba.njit(cache=True)
def log_args(R):  # pragma: no cover - compiled
    """``(s, c)`` of ``log_so3(R)``: ``s = ‖vee(R)‖``, ``c = clip((tr R − 1)/2, −1, 1)``; its angle is
    ``θ = numpy.arctan2(s, c)`` (:func:`log_into`)."""
    v0 = 0.5 * (R[2, 1] - R[1, 2])
    v1 = 0.5 * (R[0, 2] - R[2, 0])
    v2 = 0.5 * (R[1, 0] - R[0, 1])
    return np.sqrt(v0 * v0 + v1 * v1 + v2 * v2), min(max(0.5 * (((R[0, 0] + R[1, 1]) + R[2, 2]) - 1.0), -1.0), 1.0)


@numba.njit(cache=True)
def log_into(R, theta, out):  # pragma: no cover - compiled
    """``out = log_so3(R)`` given its angle ``theta = numpy.arctan2(*log_args(R))``: ``w = v θ / ‖v‖``,
    ``v = vee(R)`` (Taylor series below ``θ = 1e-4``); within ``1e-2`` of π the axis from the symmetric part,
    signed like ``v`` (canonical when ``v`` says nothing)."""
    v0 = 0.5 * (R[2, 1] - R[1, 2])
    v1 = 0.5 * (R[0, 2] - R[2, 0])
    v2 = 0.5 * (R[1, 0] - R[0, 1])
    s, c = log_args(R)
    small = theta < _SMALL
    if small:
        scale = 1.0 + theta * theta / 6.0 + 7.0 * np.power(theta, 4.0) / 360.0
    else:
        scale = theta / (1.0 if s <= 0.0 else s)
    out[0], out[1], out[2] = v0 * scale, v1 * scale, v2 * scale
    if theta > np.pi - _NEAR_PI:
        S = np.empty((3, 3))
        for i in range(3):
            for j in range(3):
                S[i, j] = 0.5 * (R[i, j] + R[j, i]) - c * (1.0 if i == j else 0.0)
        k = 0
        for i in range(1, 3):
            if S[i, i] > S[k, k]:
                k = i
        a0, a1, a2 = S[0, k], S[1, k], S[2, k]
        nrm = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        a0, a1, a2 = a0 / nrm, a1 / nrm, a2 / nrm
        dot = a0 * v0 + a1 * v1 + a2 * v2
        if abs(dot) > 1e-10:
            sign = np.sign(dot)
        else:
            m = 0
            if abs(a1) > abs(a0):
                m = 1
            if abs(a2) > abs(a0 if m == 0 else a1):
                m = 2
            sign = np.sign(a0 if m == 0 else (a1 if m == 1 else a2))
        t = sign * theta
        out[0], out[1], out[2] = a0 * t, a1 * t, a2 * t


@numba.njit(cache=True)
def nearest_rotvec_into(w, ref, out):  # pragma: no cover - compiled
    """``out = nearest_rotvec(w, ref)``: the rotation vector ``(θ + 2πm) ω`` of ``w = θ ω`` nearest to ``ref``."""
    theta = np.sqrt(_dot3(w[0], w[1], w[2], w[0], w[1], w[2]))
    out[0], out[1], out[2] = w[0], w[1], w[2]
    if theta < 1e-12:
        return
    a0, a1, a2 = w[0] / theta, w[1] / theta, w[2] / theta
    m = np.round((_dot3(a0, a1, a2, ref[0], ref[1], ref[2]) - theta) / (2.0 * np.pi))
    if m != 0:
        t = theta + 2.0 * np.pi * m
        out[0], out[1], out[2] = a0 * t, a1 * t, a2 * t
