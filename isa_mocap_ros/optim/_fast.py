"""Compiled helpers of the optimizers (numba), bit-identical to the numpy code they replace.

The adaptive annealing schedule (:func:`.schedules.beta_for_ess`) bisects on ``log10 beta`` about 25
times per generation; each step is ``ess(normalise_log(-beta * E)) / n``. With numpy that is a dozen
small-array calls per step, ~0.4 ms per generation, more than a 30-particle generation of the
silhouette energy. Here the same arithmetic runs compiled:

* ``exp`` is the C library's, as numpy's float64 ``exp`` on this (AVX2) machine;
* sums follow numpy's pairwise summation (``pairwise_sum`` in numpy's ``loops_utils``: plain loop
  below 8 elements, eight accumulators up to 128, halves beyond), starting from the identity 0;
* max, negation, products and divisions are exact operations in the same order.

``test/test_optim_protocol.py`` checks bit equality with the numpy formulation on random inputs.
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["pairwise_sum", "ess_fraction", "bisect_log_beta"]


@numba.njit(cache=True)
def _block(a, lo, n):  # pragma: no cover - compiled
    """numpy's pairwise_sum for ``n <= 128`` elements ``a[lo:lo + n]``."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    m = n - n % 8
    while i < m:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@numba.njit(cache=True)
def _pairwise(a, lo, n):  # pragma: no cover - compiled
    """numpy's pairwise_sum of ``a[lo:lo + n]``: above 128 elements ``sum(first n2) + sum(rest)`` with
    ``n2 = n // 2`` rounded down to a multiple of 8; the recursion runs on an explicit stack (numba's
    cache does not reload self-recursive functions safely)."""
    if n <= 128:
        return _block(a, lo, n)
    s_lo = np.empty(128, np.int64)
    s_n = np.empty(128, np.int64)
    s_st = np.empty(128, np.int64)
    vals = np.empty(128)
    sp = 1
    s_lo[0], s_n[0], s_st[0] = lo, n, 0
    vp = 0
    while sp > 0:
        t = sp - 1
        m = s_n[t]
        if m <= 128:
            vals[vp] = _block(a, s_lo[t], m)
            vp += 1
            sp -= 1
            continue
        n2 = m // 2
        n2 -= n2 % 8
        if s_st[t] == 0:
            s_st[t] = 1
            s_lo[sp], s_n[sp], s_st[sp] = s_lo[t], n2, 0
            sp += 1
        elif s_st[t] == 1:
            s_st[t] = 2
            s_lo[sp], s_n[sp], s_st[sp] = s_lo[t] + n2, m - n2, 0
            sp += 1
        else:
            vals[vp - 2] = vals[vp - 2] + vals[vp - 1]
            vp -= 1
            sp -= 1
    return vals[0]


@numba.njit(cache=True)
def pairwise_sum(a):  # pragma: no cover - compiled
    """``a.sum()`` of a 1-D float64 array, bit-identical to numpy's (identity 0, pairwise)."""
    return 0.0 + _pairwise(a, 0, a.size)


@numba.njit(cache=True)
def ess_fraction(Ef, beta, n, buf):  # pragma: no cover - compiled
    """``ess(normalise_log(-beta * Ef)) / n`` for finite ``Ef`` (``buf``: scratch of ``Ef``'s size)."""
    m = Ef.size
    nb = -beta
    mx = -np.inf
    for i in range(m):
        buf[i] = nb * Ef[i]
        if buf[i] > mx:
            mx = buf[i]
    for i in range(m):
        buf[i] = np.exp(buf[i] - mx)
    s = pairwise_sum(buf)
    for i in range(m):
        w = buf[i] / s
        buf[i] = w * w
    return (1.0 / pairwise_sum(buf)) / n


@numba.njit(cache=True)
def bisect_log_beta(Ef, target, n, lo, hi, tol):  # pragma: no cover - compiled
    """The bisection of :func:`.schedules.beta_for_ess` on ``log10 beta`` in ``[lo, hi]``."""
    buf = np.empty(Ef.size)
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if ess_fraction(Ef, 10.0 ** mid, n, buf) > target:
            lo = mid
        else:
            hi = mid
        if hi - lo < tol:
            break
    return 10.0 ** (0.5 * (lo + hi))
