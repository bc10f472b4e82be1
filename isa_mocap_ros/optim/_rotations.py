"""Private rotation-vector helpers for the ISA weighted estimate (gall_isa_introduction §13.4.2).

Rodrigues exponential (13.20) and logarithm (13.21), vectorised and robust at ``theta ~ 0`` (Taylor
terms) and ``theta ~ pi``; the weighted Karcher mean by the fixed-point iteration (13.24)
``r_{k+1} = r_k * (sum_i pi_i (r_k^{-1} * r_i) / sum_i pi_i)``, with ``a * b = log(exp(a) exp(b))``.
Kept small and private: the project's geometry package owns the public SO(3) API.

``exp_so3``/``log_so3`` here are the vectorised numpy reference; :func:`rotation_mean` runs their
compiled per-rotation twins from :mod:`._fast_so3` (bit-identical, ~50x less overhead), keeping only
the weighted sum of the tangent vectors in numpy.
"""
from __future__ import annotations

import numpy as np

from isa_mocap_ros.geometry import nearest_rotvec

from . import _fast_so3


def _hat(r: np.ndarray) -> np.ndarray:
    K = np.zeros(r.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -r[..., 2], r[..., 1]
    K[..., 1, 0], K[..., 1, 2] = r[..., 2], -r[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -r[..., 1], r[..., 0]
    return K


def exp_so3(r) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of rotation vectors ``r : (..., 3)`` (13.20)."""
    r = np.asarray(r, dtype=float)
    th2 = np.sum(r * r, axis=-1)[..., None, None]
    th = np.sqrt(th2)
    small = th2 < 1e-8
    safe = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    K = _hat(r)
    return np.eye(3) + a * K + b * (K @ K)


def log_so3(R) -> np.ndarray:
    """Rotation vectors ``(..., 3)`` of rotation matrices ``R : (..., 3, 3)`` (13.21)."""
    R = np.asarray(R, dtype=float)
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(cos)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0],
                  R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    sin = np.sin(th)
    small = th < 1e-4
    f = np.where(small, 0.5 + th * th / 12.0, th / (2.0 * np.where(small, 1.0, sin)))
    out = f[..., None] * v
    # near pi: sin ~ 0, take the axis from the symmetric part
    near_pi = th > np.pi - 1e-3
    if np.any(near_pi):
        Rp = R[near_pi]
        thp = th[near_pi]
        B = (Rp + np.swapaxes(Rp, -1, -2)) / 2.0 - cos[near_pi][:, None, None] * np.eye(3)
        diag = np.diagonal(B, axis1=-2, axis2=-1)
        k = np.argmax(diag, axis=-1)
        col = B[np.arange(len(k)), :, k]
        axis = col / np.linalg.norm(col, axis=-1, keepdims=True)
        vp = v[near_pi]
        sgn = np.where(np.sum(axis * vp, axis=-1) < 0, -1.0, 1.0)
        out[near_pi] = axis * (sgn * thp)[:, None]
    return out


def rotation_mean(rotvecs, weights, *, n_iter: int = 20, tol: float = 1e-12) -> np.ndarray:
    """Weighted mean rotation ``(3,)`` of rotation vectors ``(n, 3)`` by iteration (13.24).

    Starts from the rotation vector of largest weight; stops when the update is below ``tol``.
    The result is the representative ``(θ + 2πm) ω`` of the mean rotation nearest to that start,
    so rotation vectors near ``|r| = π`` (a body turning through 180°) keep their side: the
    composition itself returns ``|r| ≤ π``, and a mean of particles at ``(0, 0, 3.1)`` came back as
    ``(0, 0, −3.18)``, which a search box around the particles then clipped 30° away.
    """
    r = np.ascontiguousarray(rotvecs, dtype=float)
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    Ri = _fast_so3.exp_many(r)
    start = r[int(np.argmax(w))]
    mean = start.copy()
    for _ in range(n_iter):
        delta = _fast_so3.relative_logs(mean, Ri)  # r_hat^{-1} * r_i
        step = w @ delta
        mean = _fast_so3.compose(mean, step)       # r_hat * step
        if step @ step < tol:
            break
    return nearest_rotvec(mean, start)
