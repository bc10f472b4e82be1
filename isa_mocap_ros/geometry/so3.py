"""Rotations: Rodrigues exponential and logarithm, and the weighted mean of rotations.

Source: Gall et al., "Interacting and annealing particle filters" (ISA), §13.4.2:
Eq. 13.20 (rotation vector θω, ``exp(θω̂)`` by the Rodrigues formula), Eq. 13.21 (logarithm),
Eq. 13.22-13.24 (mean of rotations on the exponential chart, gradient-descent iteration).

Conventions: a rotation vector ``w = θ ω`` (``‖ω‖ = 1``) has angle ``θ = ‖w‖ ∈ [0, π]`` after
``log_so3``. All functions broadcast over leading axes: ``(..., 3)`` vectors, ``(..., 3, 3)``
matrices. Both maps are numerically robust at ``θ ≈ 0`` (Taylor series) and ``θ ≈ π`` (the axis is
read from the symmetric part of ``R``; at exactly ``θ = π`` the sign is made canonical: the
axis component of largest magnitude is positive).
"""
from __future__ import annotations

import numpy as np

__all__ = ["GeometryError", "hat", "vee", "exp_so3", "log_so3", "rotation_mean", "nearest_rotvec",
           "rot_x", "rot_y", "rot_z"]

_SMALL = 1e-4          # below this angle, Taylor series for the Rodrigues coefficients
_NEAR_PI = 1e-2        # within this of π, the axis comes from the symmetric part of R


class GeometryError(ValueError):
    """Bad input to a geometry function (wrong shape, non-finite values, bad weights)."""


def _as_vectors(w, name: str, size: int = 3) -> np.ndarray:
    w = np.asarray(w, dtype=float)
    if w.ndim < 1 or w.shape[-1] != size:
        raise GeometryError(f"{name}: expected shape (..., {size}), got {w.shape}")
    return w


def _as_matrices(R, name: str, size: int = 3) -> np.ndarray:
    R = np.asarray(R, dtype=float)
    if R.ndim < 2 or R.shape[-2:] != (size, size):
        raise GeometryError(f"{name}: expected shape (..., {size}, {size}), got {R.shape}")
    return R


def hat(w) -> np.ndarray:
    """Skew-symmetric matrix ``ŵ`` with ``ŵ v = w × v`` (Eq. 13.20).

    Parameters
    ----------
    w : (..., 3) array_like

    Returns
    -------
    W : (..., 3, 3) ndarray
    """
    w = _as_vectors(w, "w")
    W = np.zeros(w.shape + (3,))
    W[..., 0, 1] = -w[..., 2]
    W[..., 0, 2] = w[..., 1]
    W[..., 1, 0] = w[..., 2]
    W[..., 1, 2] = -w[..., 0]
    W[..., 2, 0] = -w[..., 1]
    W[..., 2, 1] = w[..., 0]
    return W


def vee(W) -> np.ndarray:
    """Inverse of :func:`hat`: ``(..., 3, 3) -> (..., 3)`` (the skew part ``(W - Wᵀ)/2`` is used)."""
    W = _as_matrices(W, "W")
    return 0.5 * np.stack([W[..., 2, 1] - W[..., 1, 2],
                           W[..., 0, 2] - W[..., 2, 0],
                           W[..., 1, 0] - W[..., 0, 1]], axis=-1)


def _rodrigues_coefficients(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``A = sin θ / θ`` and ``B = (1 - cos θ) / θ²`` with Taylor series near 0."""
    t2 = theta * theta
    small = theta < _SMALL
    safe = np.where(small, 1.0, theta)
    A = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, np.sin(safe) / safe)
    B = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, (1.0 - np.cos(safe)) / (safe * safe))
    return A, B


def exp_so3(w) -> np.ndarray:
    """Rotation matrix of a rotation vector by the Rodrigues formula (Eq. 13.20).

    ``R = I + (sin θ/θ) ŵ + ((1 - cos θ)/θ²) ŵ²`` with ``θ = ‖w‖``.

    Parameters
    ----------
    w : (..., 3) array_like
        Rotation vectors ``θ ω`` (radians).

    Returns
    -------
    R : (..., 3, 3) ndarray
    """
    w = _as_vectors(w, "w")
    theta = np.linalg.norm(w, axis=-1)
    A, B = _rodrigues_coefficients(theta)
    W = hat(w)
    return np.eye(3) + A[..., None, None] * W + B[..., None, None] * (W @ W)


def log_so3(R) -> np.ndarray:
    """Rotation vector of a rotation matrix (Eq. 13.21), robust at θ ≈ 0 and θ ≈ π.

    ``θ = atan2(‖v‖, (tr R - 1)/2)`` with ``v = vee(R - Rᵀ)/2 = sin θ · ω``; then
    ``w = v θ / sin θ`` (Taylor series at small θ). Near π the axis is the dominant column of
    ``(R + Rᵀ)/2 - cos θ I = (1 - cos θ) ω ωᵀ``, signed like ``v``.

    Parameters
    ----------
    R : (..., 3, 3) array_like
        Rotation matrices (not checked for orthogonality).

    Returns
    -------
    w : (..., 3) ndarray
        Rotation vectors with ``‖w‖ ∈ [0, π]``.
    """
    R = _as_matrices(R, "R")
    v = vee(R)
    s = np.linalg.norm(v, axis=-1)
    c = np.clip(0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
    theta = np.arctan2(s, c)
    small = theta < _SMALL
    safe_s = np.where(small | (s <= 0.0), 1.0, s)
    scale = np.where(small, 1.0 + theta * theta / 6.0 + 7.0 * theta ** 4 / 360.0, theta / safe_s)
    w = v * scale[..., None]
    near_pi = theta > np.pi - _NEAR_PI
    if np.any(near_pi):
        Rn = R[near_pi]
        vn = v[near_pi]
        cn = c[near_pi]
        tn = theta[near_pi]
        S = 0.5 * (Rn + np.swapaxes(Rn, -1, -2)) - cn[:, None, None] * np.eye(3)
        k = np.argmax(np.diagonal(S, axis1=-2, axis2=-1), axis=-1)
        axis = S[np.arange(len(k)), :, k]
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        dot = np.einsum("ni,ni->n", axis, vn)
        # Sign from v where it carries information, else canonical (largest component positive).
        big = np.take_along_axis(axis, np.argmax(np.abs(axis), axis=-1)[:, None], axis=-1)[:, 0]
        sign = np.where(np.abs(dot) > 1e-10, np.sign(dot), np.sign(big))
        w[near_pi] = axis * (sign * tn)[:, None]
    return w


def rot_x(a) -> np.ndarray:
    """Rotation about x by angles ``a``: ``(...) -> (..., 3, 3)``."""
    return _axis_rotation(a, 0)


def rot_y(a) -> np.ndarray:
    """Rotation about y by angles ``a``: ``(...) -> (..., 3, 3)``."""
    return _axis_rotation(a, 1)


def rot_z(a) -> np.ndarray:
    """Rotation about z by angles ``a``: ``(...) -> (..., 3, 3)``."""
    return _axis_rotation(a, 2)


def _axis_rotation(a, axis: int) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def nearest_rotvec(w: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The rotation vector ``(θ + 2πm) ω`` of the rotation ``w = θ ω`` that is nearest to ``ref``.

    ``w`` itself (the same object) when that is ``m = 0``. With ``ref = 0`` it is the canonical
    ``‖w‖ ≤ π`` one. Used where rotation vectors must stay continuous through ``θ = π`` (a body
    turning through 180°): predictions near the last estimate, means near their particles.

    Examples
    --------
    >>> nearest_rotvec(np.array([0.0, 0.0, -3.0]), np.array([0.0, 0.0, 3.1])).round(4).tolist()
    [0.0, 0.0, 3.2832]
    """
    theta = float(np.sqrt(w @ w))
    if theta < 1e-12:
        return w
    axis = w / theta
    m = np.round((float(axis @ ref) - theta) / (2.0 * np.pi))
    return w if m == 0 else axis * (theta + 2.0 * np.pi * m)


def rotation_mean(rotvecs, weights=None, *, iters: int = 10, tol: float = 1e-10) -> np.ndarray:
    """Weighted mean of rotations by the iteration of Eq. 13.24.

    ``r̂_{t+1} = r̂_t ⋆ (Σ π_i (r̂_t⁻¹ ⋆ r_i) / Σ π_i)`` with ``r2 ⋆ r1 = log(exp(r2) exp(r1))``;
    the fixed point satisfies Eq. 13.22 and minimises Eq. 13.23. Starts from the rotation with
    the largest weight; stops after ``iters`` steps or when the step is shorter than ``tol``.

    Parameters
    ----------
    rotvecs : (n, 3) array_like
        Rotation vectors ``r_i``.
    weights : (n,) array_like, optional
        Non-negative weights ``π_i`` with a positive sum; uniform when omitted.
    iters : int
        Maximum number of iterations (the paper reports about 5 suffice).
    tol : float
        Stop when the tangent step norm falls below this (radians).

    Returns
    -------
    r_mean : (3,) ndarray
    """
    r = np.asarray(rotvecs, dtype=float)
    if r.ndim != 2 or r.shape[1] != 3 or r.shape[0] == 0:
        raise GeometryError(f"rotvecs: expected shape (n, 3) with n >= 1, got {r.shape}")
    if not np.all(np.isfinite(r)):
        raise GeometryError("rotvecs: expected finite values, got NaN or inf")
    if weights is None:
        w = np.full(r.shape[0], 1.0 / r.shape[0])
    else:
        w = np.asarray(weights, dtype=float)
        if w.shape != (r.shape[0],):
            raise GeometryError(f"weights: expected shape ({r.shape[0]},), got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise GeometryError(f"weights: expected finite, non-negative values with a positive sum, "
                                f"got min {w.min() if w.size else None}, sum {w.sum()}")
        w = w / w.sum()
    if iters < 1:
        raise GeometryError(f"iters: expected >= 1, got {iters}")
    Ri = exp_so3(r)
    mean_R = Ri[int(np.argmax(w))]
    for _ in range(iters):
        d = log_so3(mean_R.T @ Ri)                  # r̂⁻¹ ⋆ r_i, (n, 3)
        step = w @ d                                 # Σ π_i (r̂⁻¹ ⋆ r_i) / Σ π_i
        mean_R = mean_R @ exp_so3(step)              # r̂ ⋆ step
        if np.linalg.norm(step) < tol:
            break
    return log_so3(mean_R)
