"""Resampling schemes and the selection kernels of interacting simulated annealing.

Resampling schemes (``scheme(W, rng, m) -> indices``) follow particles' ``resampling.py``:
multinomial, residual, stratified and systematic. Selection kernels implement step 2 of
Algorithm 6 (gall_isa_introduction §13.3.1): particle ``i`` is kept with probability
``eps_t * pi_i`` and otherwise replaced by a multinomial draw from the normalised weights, with

* S1: ``eps_t = 0`` (13.8) -- plain multinomial resampling;
* S2: ``eps_t = 1 / (n <eta_t, exp(-beta V)>)`` (13.9), i.e. keep with probability
  ``pi_i / sum_k pi_k``;
* S3: ``eps_t = 1 / ess sup exp(-beta V)`` (13.10), i.e. keep with probability ``pi_i / max_k pi_k``.

Weights come from log-weights through a log-sum-exp (:func:`normalise_log`).
"""
from __future__ import annotations

import numpy as np

from ._base import OptimError

__all__ = ["normalise_log", "ess", "multinomial", "residual", "stratified", "systematic",
           "select_s1", "select_s2", "select_s3", "SELECTION_KERNELS"]


def _check_W(W, m=None) -> tuple[np.ndarray, int]:
    W = np.asarray(W, dtype=float)
    if W.ndim != 1 or W.size == 0:
        raise OptimError(f"W: expected a non-empty (n,) array of weights, got shape {W.shape}")
    if not np.all(np.isfinite(W)) or np.any(W < 0) or W.sum() <= 0:
        raise OptimError("W: expected finite non-negative weights with a positive sum")
    m = W.size if m is None else int(m)
    if m < 0:
        raise OptimError(f"m: expected >= 0, got {m}")
    return W / W.sum(), m


def normalise_log(logw) -> np.ndarray:
    """Normalised weights ``(n,)`` from log-weights ``(n,)``; ``-inf`` entries get weight 0.

    If every log-weight is ``-inf`` (or NaN) the weights are uniform.
    """
    lw = np.array(logw, dtype=float)
    lw[np.isnan(lw)] = -np.inf
    mx = lw.max()
    if not np.isfinite(mx):
        return np.full(lw.size, 1.0 / lw.size)
    w = np.exp(lw - mx)
    return w / w.sum()


def ess(W) -> float:
    """Effective sample size ``1 / sum W_i^2`` of normalised weights ``W : (n,)``."""
    W = np.asarray(W, dtype=float)
    return float(1.0 / np.sum(W * W))


def _inverse_cdf(su: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Indices ``A`` with ``cumsum(W)[A-1] <= su < cumsum(W)[A]`` for sorted uniforms ``su``."""
    c = np.cumsum(W)
    c[-1] = 1.0
    return np.minimum(np.searchsorted(c, su, side="right"), W.size - 1)


def multinomial(W, rng: np.random.Generator, m: int | None = None) -> np.ndarray:
    """``m`` i.i.d. indices drawn with probabilities ``W : (n,)`` (default ``m = n``)."""
    W, m = _check_W(W, m)
    return _inverse_cdf(np.sort(rng.random(m)), W)


def stratified(W, rng: np.random.Generator, m: int | None = None) -> np.ndarray:
    """Stratified resampling: one uniform per stratum ``[k/m, (k+1)/m)``."""
    W, m = _check_W(W, m)
    return _inverse_cdf((np.arange(m) + rng.random(m)) / max(m, 1), W)


def systematic(W, rng: np.random.Generator, m: int | None = None) -> np.ndarray:
    """Systematic resampling: one shared uniform; particle ``i`` gets ``floor(m W_i)`` or
    ``ceil(m W_i)`` copies."""
    W, m = _check_W(W, m)
    return _inverse_cdf((np.arange(m) + rng.random()) / max(m, 1), W)


def residual(W, rng: np.random.Generator, m: int | None = None) -> np.ndarray:
    """Residual resampling: ``floor(m W_i)`` deterministic copies, the rest multinomially."""
    W, m = _check_W(W, m)
    counts = np.floor(m * W).astype(int)
    A = np.repeat(np.arange(W.size), counts)
    r = m - A.size
    if r > 0:
        R = m * W - counts
        A = np.concatenate([A, multinomial(R, rng, r)])
    return A


SCHEMES = {"multinomial": multinomial, "residual": residual, "stratified": stratified,
           "systematic": systematic}


def _select(W, keep_prob, rng, scheme):
    n = W.size
    keep = rng.random(n) <= keep_prob
    A = np.arange(n)
    k = int((~keep).sum())
    if k:
        A[~keep] = scheme(W, rng, k)
    return A


def select_s1(W, rng: np.random.Generator, *, scheme=multinomial) -> np.ndarray:
    """Selection kernel S1 (13.8, ``eps = 0``): ``n`` indices resampled from ``W : (n,)``."""
    W, n = _check_W(W)
    return scheme(W, rng, n)


def select_s2(W, rng: np.random.Generator, *, scheme=multinomial) -> np.ndarray:
    """Selection kernel S2 (13.9): keep particle ``i`` with probability ``W_i`` (normalised),
    otherwise replace it by a draw from ``W``. Returns ``(n,)`` indices."""
    W, _ = _check_W(W)
    return _select(W, W, rng, scheme)


def select_s3(W, rng: np.random.Generator, *, scheme=multinomial) -> np.ndarray:
    """Selection kernel S3 (13.10): keep particle ``i`` with probability ``W_i / max W``
    (the best particle always survives), otherwise replace it by a draw from ``W``."""
    W, _ = _check_W(W)
    return _select(W, W / W.max(), rng, scheme)


SELECTION_KERNELS = {"s1": select_s1, "s2": select_s2, "s3": select_s3}
