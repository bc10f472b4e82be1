"""Pose prediction for the next frame: autoregression on twists (ISA 13.28) and two baselines.

Source: Gall et al., ISA §13.4.2, "Pose prediction". The root's rigid body motions ``P_i`` of
the last frames give relative motions as twists ``ξ_i = log(P_i P_{i-1}^{-1})`` (13.26); each is
moved into the current frame ``M`` by the adjoint of ``G_i = M P_{i-1}^{-1}`` and damped by
``λ_i`` (``0 ≤ λ_i ≤ 1``, ``Σ λ_i = 1``), and the prediction is the rigid body motion

    exp(ξ'_N) exp(ξ'_{N-1}) ... exp(ξ'_1) M,    ξ'_i = Ad_{G_i} (λ_i ξ_i)            (13.28)

Formula implemented by :class:`ArPredictor` (``N = order``; with ``K + 1`` estimates
``x_{k-K}, ..., x_k`` stored, ``K = min(order, n_estimates - 1)``):

* root (``root_slice``: translation ``t`` then rotation vector ``w``, DESIGN §3), with
  ``P_j = [exp(ŵ_j) t_j; 0 1]`` (:func:`~isa_mocap_ros.geometry.pose_to_matrix`),
  ``M = P_k``, twists ``ξ_i = log(P_i P_{i-1}^{-1})`` for the last ``K`` steps, ``G_i =
  M P_{i-1}^{-1}``, ``ξ'_i = Ad_{G_i} λ_i ξ_i`` and ``P_pred = exp(ξ'_K) ... exp(ξ'_1) M``
  (oldest motion applied first, index ``i = 1`` the oldest). Because
  ``exp(Ad_G ξ) = G exp(ξ) G^{-1}``, this equals
  ``P_pred = M exp(λ_K ζ_K) ... exp(λ_1 ζ_1)`` with the body-frame increments
  ``ζ_i = log(P_{i-1}^{-1} P_i)``: the recent relative motions, re-applied at the current pose;
* joint angles ``q`` (every other coordinate) by the same weights on first differences:
  ``q_pred = q_k + Σ_i λ_i (q_i - q_{i-1})``;
* ``λ``: ``damping`` given oldest first (``λ_1 ... λ_N``), normalised to sum 1; default
  ``λ_i ∝ i`` (the newest motion weighs most). With fewer than ``N`` motions known, the newest
  ``K`` weights ``λ_{N-K+1} ... λ_N`` are renormalised.

Since ``Σ λ_i = 1``, a constant-twist motion ``P_j = exp(ξ)^j P_0`` with constant joint
velocities is extrapolated exactly. The predicted rotation vector is chosen among its
equivalents ``(θ + 2πm) ω`` as the one nearest the last estimate's, so a root turning through
``θ = π`` does not jump.

**Gaps.** Estimates need not come from consecutive frames: a real-time network drops frame sets it
cannot keep up with. ``update(x, frames=g)`` says ``g`` frame periods passed since the previous
estimate, ``predict(frames=h)`` asks for the pose ``h`` periods after the last one. Each motion is
then taken per period and re-applied for ``h`` periods: ``λ_i`` becomes ``λ_i h / g_i`` in both
formulas (root: ``exp(λ_i (h / g_i) ζ_i)``; joints: ``Σ_i λ_i (h / g_i) (q_i - q_{i-1})``), so a
constant-twist motion sampled at any gaps is still extrapolated exactly. With every gap 1 (the
default) the arithmetic is the plain formula's, bit for bit (the factors are exactly 1.0).

The root's motions are computed in one compiled call (``_ar_root``, in
:mod:`isa_mocap_ros.geometry.se3_kernel`'s arithmetic: the definition; it was ~2 ms of numpy calls on 3-vectors and 4x4
matrices a frame under load), the joints' sum in numpy.

Baselines: :class:`ConstantPosePredictor` (the last estimate) and
:class:`ConstantVelocityPredictor` (``2 x_k - x_{k-1}`` in pose-vector space; ``ArPredictor``
with ``order=1`` is the constant velocity on SE(3)).
"""
from __future__ import annotations

from collections import deque
from typing import Sequence

import numba
import numpy as np

from isa_mocap_ros.geometry import se3_kernel
from isa_mocap_ros.geometry.se3_kernel import (adjoint_into, exp_se3_into, gemv6, inverse_into, log_se3_into,
                                               log_so3_into, matmul4, nearest_rotvec_into, pose_to_matrix_into)
from isa_mocap_ros.numba_cache import register_dependent_cache

__all__ = ["PredictionError", "ArPredictor", "ConstantPosePredictor", "ConstantVelocityPredictor", "frames_kwargs",
           "frame_periods", "periods_between"]


register_dependent_cache(__file__, (se3_kernel,))


class PredictionError(ValueError):
    """Bad estimate given to a predictor, bad settings, or a prediction asked of an empty history."""


def frame_periods(name: str, value) -> float:
    """``value`` as a number of frame periods (a real number, finite and > 0), else PredictionError."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not (0 < float(value) < np.inf):
        raise PredictionError(f"{name}: expected a number of frame periods > 0, got {value!r}")
    return float(value)


def periods_between(prev_ns: int | None, ns: int, period_s: float) -> int:
    """Whole frame periods from stamp ``prev_ns`` to ``ns`` (at least 1; 1 without a previous stamp or
    when ``ns`` is not newer): what a node that dropped frame sets tells the tracker or predictor."""
    if prev_ns is None or ns <= prev_ns:
        return 1
    return max(1, round((ns - prev_ns) / (period_s * 1e9)))


def frames_kwargs(frames) -> dict:
    """``frames`` as the keyword of ``update`` / ``predict``, only when it is not the default 1: a
    predictor of one's own written without gaps (``update(x)``, ``predict()``) keeps working
    wherever the frames are consecutive."""
    return {} if (not isinstance(frames, bool) and frames == 1) else {"frames": frames}


@numba.njit(cache=True)
def _ar_root(X, lam, out):  # pragma: no cover - compiled
    """``out`` (6,): the root of 13.28, ``P_pred = exp(ξ'_K) ... exp(ξ'_1) M``, from the root poses ``X (K+1, 6)``
    (``(t, w)``, oldest first) and the weights ``lam (K,)``: ``P_j = [exp(ŵ_j) t_j; 0 1]``, ``M = P_K``,
    ``ξ_i = log(P_i P_{i-1}⁻¹)``, ``G_i = M P_{i-1}⁻¹``, ``ξ'_i = Ad_{G_i} (λ_i ξ_i)``; the rotation vector nearest
    the last one's (:mod:`isa_mocap_ros.geometry.se3_kernel`'s arithmetic, the definition)."""
    K = X.shape[0] - 1
    P = np.empty((K + 1, 4, 4))
    for j in range(K + 1):
        pose_to_matrix_into(X[j], P[j])
    M = P[K]
    T, T2, E = M.copy(), np.empty((4, 4)), np.empty((4, 4))
    Pinv, Q, G, Ad = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((6, 6))
    xi, y, xc = np.empty(6), np.empty(6), np.empty(6)
    for i in range(1, K + 1):                    # oldest motion first (rightmost)
        inverse_into(P[i - 1], Pinv)
        matmul4(P[i], Pinv, Q)
        log_se3_into(Q, xi)                      # ξ_i = log(P_i P_{i-1}^{-1})
        matmul4(M, Pinv, G)                      # G_i = M P_{i-1}^{-1}
        adjoint_into(G, Ad)
        for d in range(6):
            y[d] = lam[i - 1] * xi[d]
        gemv6(Ad, y, xc)                         # ξ'_i = Ad_G λ_i ξ_i
        exp_se3_into(xc, E)
        matmul4(E, T, T2)                        # exp(ξ'_i) ... exp(ξ'_1) M
        T[:] = T2
    w = np.empty(3)
    log_so3_into(T[:3, :3], w)
    for d in range(3):
        out[d] = T[d, 3]
    nearest_rotvec_into(w, X[K, 3:], out[3:])


class _HistoryPredictor:
    """Keeps the last ``history`` estimates; subclasses implement :meth:`predict`."""

    def __init__(self, history: int) -> None:
        self._hist: deque[np.ndarray] = deque(maxlen=history)
        self._gaps: deque[float] = deque(maxlen=history)    # periods between an estimate and the one before
        self._n_dof: int | None = None

    @property
    def n_estimates(self) -> int:
        """Number of estimates held (at most the history length)."""
        return len(self._hist)

    @property
    def capacity(self) -> int:
        """Estimates the predictor looks back on (its history length)."""
        return int(self._hist.maxlen)

    @property
    def n_dof(self) -> int | None:
        """Length ``D`` of the pose vectors (fixed by the first estimate; None before)."""
        return self._n_dof

    @property
    def history(self) -> np.ndarray:
        """(k, D) ndarray: the held estimates, oldest first (a copy)."""
        if not self._hist:
            return np.empty((0, self._n_dof or 0))
        return np.array(self._hist)

    def _check(self, x) -> np.ndarray:
        try:
            x = np.array(x, dtype=float)
        except (TypeError, ValueError) as exc:
            raise PredictionError(f"x: expected a 1-D array of floats, got {x!r}") from exc
        if x.ndim != 1 or x.size == 0:
            raise PredictionError(f"x: expected shape (D,), got {x.shape}")
        if self._n_dof is not None and x.size != self._n_dof:
            raise PredictionError(f"x: expected shape ({self._n_dof},) like the earlier estimates, "
                                  f"got {x.shape}")
        if not np.all(np.isfinite(x)):
            bad = int(np.flatnonzero(~np.isfinite(x))[0])
            raise PredictionError(f"x: expected finite values, got {x[bad]} at index {bad}")
        return x

    def update(self, x, frames: float = 1) -> None:
        """Append the estimate of the frame just finished.

        Parameters
        ----------
        x : (D,) array_like
            Pose vector; ``D`` must match the earlier estimates.
        frames : float
            Frame periods since the previous estimate (> 0; default 1, consecutive frames).

        Raises
        ------
        PredictionError
            Non-finite values, a wrong shape or a bad ``frames``; the history is left untouched.
        """
        x = self._check(x)
        g = frame_periods("frames", frames)
        if self._n_dof is None:
            self._validate_dof(x.size)
        self._n_dof = x.size
        self._hist.append(x)
        self._gaps.append(g)

    def _validate_dof(self, n_dof: int) -> None:
        pass

    def reset(self) -> None:
        """Forget every estimate (the pose length may change afterwards)."""
        self._hist.clear()
        self._gaps.clear()
        self._n_dof = None

    def _last(self) -> np.ndarray:
        if not self._hist:
            raise PredictionError("predict: no estimate yet; call update(x) first")
        return self._hist[-1]

    def predict(self, frames: float = 1) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError


class ConstantPosePredictor(_HistoryPredictor):
    """Predicts the last estimate again (the "no motion model" baseline)."""

    def __init__(self) -> None:
        super().__init__(1)

    def predict(self, frames: float = 1) -> np.ndarray:
        """Return ``x_k`` as a (D,) ndarray (a copy), however many ``frames`` ahead."""
        frame_periods("frames", frames)
        return self._last().copy()


class ConstantVelocityPredictor(_HistoryPredictor):
    """Predicts ``x_k + (x_k - x_{k-1})`` coordinate-wise (rotation vectors included).

    A naive baseline: it treats the root rotation vector as Euclidean. With one estimate it
    returns that estimate.
    """

    def __init__(self) -> None:
        super().__init__(2)

    def predict(self, frames: float = 1) -> np.ndarray:
        """Return the (D,) prediction ``x_k + (h / g) (x_k - x_{k-1})`` for ``h = frames`` periods
        ahead, ``g`` the periods between the two estimates (``2 x_k - x_{k-1}`` for consecutive
        frames; ``x_k`` with a single estimate)."""
        h = frame_periods("frames", frames)
        last = self._last()
        if len(self._hist) < 2:
            return last.copy()
        return last + (h / self._gaps[-1]) * (last - self._hist[-2])


class ArPredictor(_HistoryPredictor):
    """Autoregressive prediction on twists with damping (ISA 13.28); see the module docstring.

    Parameters
    ----------
    order : int
        ``N``, the number of past relative motions used (``N + 1`` estimates kept).
    damping : sequence of float, optional
        ``λ_1 ... λ_N``, oldest first, non-negative with a positive sum; normalised to sum 1.
        Default ``λ_i = i / Σ_j j``.
    root_slice : slice or None
        The 6 root coordinates (translation, rotation vector) in the pose vector; None treats
        every coordinate as a joint angle.

    Attributes
    ----------
    damping : (N,) ndarray
        The normalised ``λ``.

    Examples
    --------
    >>> ar = ArPredictor(order=2)
    >>> for k in range(3):
    ...     ar.update([0.1 * k, 0, 1.0, 0, 0, 0, 0.5 + 0.05 * k])
    >>> np.round(ar.predict(), 12).tolist()
    [0.3, 0.0, 1.0, 0.0, 0.0, 0.0, 0.65]
    """

    def __init__(self, *, order: int = 3, damping: Sequence[float] | None = None,
                 root_slice: slice | None = slice(0, 6)) -> None:
        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
            raise PredictionError(f"order: expected an integer >= 1, got {order!r}")
        if damping is None:
            lam = np.arange(1, order + 1, dtype=float)
        else:
            lam = np.asarray(damping, dtype=float)
            if lam.shape != (order,):
                raise PredictionError(f"damping: expected {order} weights (one per motion, oldest "
                                      f"first), got shape {lam.shape}")
            if not np.all(np.isfinite(lam)) or np.any(lam < 0) or lam.sum() <= 0:
                raise PredictionError(f"damping: expected finite non-negative weights with a "
                                      f"positive sum, got {lam.tolist()}")
        if root_slice is not None and not isinstance(root_slice, slice):
            raise PredictionError(f"root_slice: expected a slice of 6 coordinates or None, "
                                  f"got {root_slice!r}")
        super().__init__(order + 1)
        self.order = int(order)
        self.damping = lam / lam.sum()
        self.root_slice = root_slice

    def _validate_dof(self, n_dof: int) -> None:
        if self.root_slice is not None:
            idx = range(n_dof)[self.root_slice]
            if len(idx) != 6:
                raise PredictionError(f"root_slice: expected 6 coordinates of a pose of length "
                                      f"{n_dof}, got {len(idx)} ({self.root_slice})")

    def predict(self, frames: float = 1) -> np.ndarray:
        """Prediction for the frame ``frames`` periods after the last estimate (default the next).

        Returns
        -------
        (D,) ndarray
            The 13.28 prediction; the last estimate while only one is known.

        Raises
        ------
        PredictionError
            No estimate yet.
        """
        h = frame_periods("frames", frames)
        last = self._last()
        K = min(self.order, len(self._hist) - 1)
        if K == 0:
            return last.copy()
        X = np.array(self._hist)[-(K + 1):]                 # x_{k-K} ... x_k, oldest first
        lam = self.damping[-K:] / self.damping[-K:].sum()    # λ of the newest K motions
        lam = lam * (h / np.array(self._gaps)[-K:])          # per period, h periods ahead (1.0 each: unchanged)
        out = np.empty_like(last)
        joint = np.ones(last.size, bool)
        if self.root_slice is not None:
            joint[self.root_slice] = False
            root = np.empty(6)
            _ar_root(np.ascontiguousarray(X[:, self.root_slice]), lam, root)     # 13.28, compiled
            out[self.root_slice] = root
        # q_pred = q_k + Σ λ_i (q_i - q_{i-1})
        out[joint] = X[-1, joint] + lam @ np.diff(X[:, joint], axis=0)
        return out
