"""Rigid body motions: twists (exp/log), the adjoint, and root-pose conversion.

Source: ISA §13.4.2, Eq. 13.20 (rigid body motion ``M = [exp(θω̂) t; 0 1]`` from the 6-D vector
``(θω, t)``), Eq. 13.25 (twist ``θξ̂ = θ [ω̂ v; 0 0]``), Eq. 13.26-13.27 (logarithm,
``v = A⁻¹ t`` with ``A = (I - exp(θω̂)) ω̂ + ω ωᵀ θ``).

Ordering: a twist is ``xi = (v, ω)`` — translational part first, rotational part second — and
carries the magnitude: ``xi = θ (v_paper, ω_paper)`` with ``‖ω_paper‖ = 1``. So ``xi[3:]`` is the
rotation vector of ``exp_se3(xi)`` and ``xi[:3] = θ A⁻¹ t``. The root pose ``x6 = (t, w)``
(translation, rotation vector; DESIGN §3) is *not* a twist: :func:`pose_to_matrix` builds
``[exp(ŵ) t; 0 1]`` directly (Eq. 13.20).
"""
from __future__ import annotations

import numpy as np

from .so3 import _as_matrices, _as_vectors, _rodrigues_coefficients, exp_so3, hat, log_so3

__all__ = ["exp_se3", "log_se3", "adjoint", "pose_to_matrix", "matrix_to_pose", "twist_hat"]

_SMALL = 1e-4


def twist_hat(xi) -> np.ndarray:
    """4×4 twist matrix ``[ω̂ v; 0 0]`` of ``xi = (v, ω)``: ``(..., 6) -> (..., 4, 4)`` (Eq. 13.25)."""
    xi = _as_vectors(xi, "xi", 6)
    M = np.zeros(xi.shape[:-1] + (4, 4))
    M[..., :3, :3] = hat(xi[..., 3:])
    M[..., :3, 3] = xi[..., :3]
    return M


def _left_jacobian_coefficient(theta: np.ndarray) -> np.ndarray:
    """``C = (θ - sin θ)/θ³`` with a Taylor series near 0."""
    t2 = theta * theta
    small = theta < _SMALL
    safe = np.where(small, 1.0, theta)
    return np.where(small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0,
                    (safe - np.sin(safe)) / safe ** 3)


def exp_se3(xi) -> np.ndarray:
    """Rigid body motion of a twist ``xi = (v, ω)`` (Eq. 13.25).

    ``exp(xi) = [R  V v; 0 1]`` with ``R = exp(ω̂)`` and ``V = I + B ω̂ + C ω̂²``.

    Parameters
    ----------
    xi : (..., 6) array_like

    Returns
    -------
    T : (..., 4, 4) ndarray
    """
    xi = _as_vectors(xi, "xi", 6)
    v, w = xi[..., :3], xi[..., 3:]
    theta = np.linalg.norm(w, axis=-1)
    A, B = _rodrigues_coefficients(theta)
    C = _left_jacobian_coefficient(theta)
    W = hat(w)
    W2 = W @ W
    I = np.eye(3)
    R = I + A[..., None, None] * W + B[..., None, None] * W2
    V = I + B[..., None, None] * W + C[..., None, None] * W2
    T = np.zeros(xi.shape[:-1] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = np.einsum("...ij,...j->...i", V, v)
    T[..., 3, 3] = 1.0
    return T


def log_se3(T) -> np.ndarray:
    """Twist ``xi = (v, ω)`` of a rigid body motion (Eq. 13.26): ``ω = log R``, ``v = V⁻¹ t``.

    ``V⁻¹ = I - ω̂/2 + (1/θ²)(1 - A/(2B)) ω̂²``; equivalent to Eq. 13.26-13.27 with ``v = θ A⁻¹ t``.

    Parameters
    ----------
    T : (..., 4, 4) array_like

    Returns
    -------
    xi : (..., 6) ndarray
    """
    T = _as_matrices(T, "T", 4)
    w = log_so3(T[..., :3, :3])
    theta = np.linalg.norm(w, axis=-1)
    A, B = _rodrigues_coefficients(theta)
    small = theta < _SMALL
    t2 = np.where(small, 1.0, theta * theta)
    D = np.where(small, 1.0 / 12.0 + theta ** 2 / 720.0 + theta ** 4 / 30240.0,
                 (1.0 - A / (2.0 * np.where(small, 1.0, B))) / t2)
    W = hat(w)
    Vinv = np.eye(3) - 0.5 * W + D[..., None, None] * (W @ W)
    v = np.einsum("...ij,...j->...i", Vinv, T[..., :3, 3])
    return np.concatenate([v, w], axis=-1)


def adjoint(T) -> np.ndarray:
    """Adjoint of a rigid body motion for ``(v, ω)`` twists: ``T exp(ξ) T⁻¹ = exp(Ad_T ξ)``.

    ``Ad_T = [R  t̂R; 0  R]``.

    Parameters
    ----------
    T : (4, 4) array_like (leading batch axes are allowed)

    Returns
    -------
    Ad : (6, 6) ndarray
    """
    T = _as_matrices(T, "T", 4)
    R, t = T[..., :3, :3], T[..., :3, 3]
    Ad = np.zeros(T.shape[:-2] + (6, 6))
    Ad[..., :3, :3] = R
    Ad[..., :3, 3:] = hat(t) @ R
    Ad[..., 3:, 3:] = R
    return Ad


def pose_to_matrix(x6) -> np.ndarray:
    """Homogeneous matrix of a root pose ``(t, w)``: translation then rotation vector (Eq. 13.20).

    Parameters
    ----------
    x6 : (..., 6) array_like

    Returns
    -------
    T : (..., 4, 4) ndarray
    """
    x6 = _as_vectors(x6, "x6", 6)
    T = np.zeros(x6.shape[:-1] + (4, 4))
    T[..., :3, :3] = exp_so3(x6[..., 3:])
    T[..., :3, 3] = x6[..., :3]
    T[..., 3, 3] = 1.0
    return T


def matrix_to_pose(T) -> np.ndarray:
    """Inverse of :func:`pose_to_matrix`: ``(..., 4, 4) -> (..., 6)`` as ``(t, log R)``."""
    T = _as_matrices(T, "T", 4)
    return np.concatenate([T[..., :3, 3], log_so3(T[..., :3, :3])], axis=-1)

