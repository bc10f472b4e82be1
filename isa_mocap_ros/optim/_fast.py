"""Compiled helpers of the optimizers (numba), bit-identical to the numpy code they replace.

A tracker frame runs ~54 small generations (30 particles); with numpy each generation paid ~100
small-array calls of Python overhead (~0.7 ms), more than the silhouette energy of the generation.
Here the per-generation arithmetic of ISA (gall_isa_introduction Alg. 6) runs compiled:

* :func:`adaptive_beta` -- the adaptive schedule (:func:`.schedules.beta_for_ess`, yeguas Eq. 8),
  bisecting on ``log10 beta`` about 25 times, each step ``ess(normalise_log(-beta * E)) / n``;
* :func:`annealed_weights` -- the weights ``exp(-beta (E - min E))`` log-sum-exp normalised and
  their ESS (:meth:`.isa.Isa.weights`, :func:`.resampling.ess`);
* :func:`keep_mask` / :func:`select_mutate` -- selection kernels S1-S3 (13.8-13.10) with multinomial
  replacement, the dynamic variance (13.16) and the clipped Gaussian mutation, fused. The random
  numbers are drawn by the caller from the optimizer's ``numpy.random.Generator``, in the order the
  numpy code draws them, and passed in;
* :func:`generation_stats` -- the diagnostics of :class:`._base.GenerationInfo` (mean finite energy,
  mean per-coordinate standard deviation).

Bit equality with numpy holds because the same operations run in the same order:

* ``exp`` is the C library's, as numpy's float64 ``exp`` on this (AVX2) machine;
* sums along a 1-D array follow numpy's pairwise summation (``pairwise_sum`` in numpy's
  ``loops_utils``: plain loop below 8 elements, eight accumulators up to 128, halves beyond),
  starting from the identity 0; column sums of a C-ordered ``(n, d)`` array (``axis=0``) are plain
  row-by-row sums, as numpy reduces a non-contiguous axis (pairwise again for ``d = 1`` and for
  F-ordered arrays, e.g. the columns a hierarchical run hands its inner optimizer);
* max, negation, products, divisions, square roots and clips are exact operations in the same
  order; no fastmath (no reassociation, no contraction into FMA).

``test/test_optim_fast.py`` and ``test/test_optim_compiled.py`` check bit equality with the numpy
formulation on random inputs and whole runs, and a process that compiles these functions against
one that loads them from numba's cache.
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["pairwise_sum", "ess_fraction", "bisect_log_beta", "adaptive_beta", "annealed_weights",
           "keep_mask", "select_mutate", "generation_stats", "column_sums"]


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
def column_sums(A, by_column):  # pragma: no cover - compiled
    """``A.sum(axis=0)`` of an ``(n, d)`` array, bit-identical to numpy's: row by row when the rows are
    contiguous (C order), each column pairwise when the columns are (``by_column``: F order, or
    ``d = 1``), as numpy reduces along the contiguous axis."""
    n, d = A.shape
    if by_column:
        out = np.empty(d)
        for q in range(d):
            out[q] = pairwise_sum(A[:, q].copy())
        return out
    out = A[0].copy()
    for i in range(1, n):
        for q in range(d):
            out[q] += A[i, q]
    return out


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


@numba.njit(cache=True)
def adaptive_beta(E, target, beta_max, tol):  # pragma: no cover - compiled
    """:func:`.schedules.beta_for_ess` on raw energies ``E (n,)`` (non-finite ones get weight 0)."""
    n = E.size
    m = 0
    e_min = np.inf
    for i in range(n):
        if np.isfinite(E[i]):
            m += 1
            if E[i] < e_min:
                e_min = E[i]
    if m < 2:
        return 0.0
    Ef = np.empty(m)
    j = 0
    e_max = -np.inf
    n_pos = 0
    for i in range(n):
        if np.isfinite(E[i]):
            Ef[j] = E[i] - e_min
            if Ef[j] > e_max:
                e_max = Ef[j]
            if Ef[j] > 0:
                n_pos += 1
            j += 1
    if e_max <= 0:
        return 0.0
    buf = np.empty(m)
    if ess_fraction(Ef, 0.0, n, buf) <= target:   # non-finite rows already cost more than the target
        return 0.0
    pos = np.empty(n_pos)                          # np.median(Ef[Ef > 0]): the energy scale
    j = 0
    for i in range(m):
        if Ef[i] > 0:
            pos[j] = Ef[i]
            j += 1
    pos.sort()
    h = n_pos // 2
    median = pos[h] if n_pos % 2 == 1 else (pos[h - 1] + pos[h]) / 2.0
    lo = -12.0 + np.log10(1.0 / median)
    hi = max(np.log10(beta_max), lo + 1)
    if ess_fraction(Ef, 10.0 ** hi, n, buf) >= target:
        return 10.0 ** hi
    return bisect_log_beta(Ef, target, n, lo, hi, tol)


@numba.njit(cache=True)
def annealed_weights(E, beta, W):  # pragma: no cover - compiled
    """``W = normalise_log(where(isfinite(E), -beta * (E - E0), -inf))`` with ``E0`` the least finite
    energy (0 if none); returns ``ess(W)`` (:func:`.resampling.ess`)."""
    n = E.size
    e0 = np.inf
    for i in range(n):
        if np.isfinite(E[i]) and E[i] < e0:
            e0 = E[i]
    if e0 == np.inf:
        e0 = 0.0
    nb = -beta
    mx = -np.inf
    for i in range(n):
        lw = -np.inf
        if np.isfinite(E[i]):
            lw = nb * (E[i] - e0)
            if np.isnan(lw):
                lw = -np.inf
        W[i] = lw
        if lw > mx:
            mx = lw
    if not np.isfinite(mx):
        for i in range(n):
            W[i] = 1.0 / n
    else:
        for i in range(n):
            W[i] = np.exp(W[i] - mx)
        s = pairwise_sum(W)
        for i in range(n):
            W[i] = W[i] / s
    sq = np.empty(n)
    for i in range(n):
        sq[i] = W[i] * W[i]
    return 1.0 / pairwise_sum(sq)


@numba.njit(cache=True)
def _renormalised(W):  # pragma: no cover - compiled
    """``W / W.sum()`` (what :func:`.resampling._check_W` hands on)."""
    s = pairwise_sum(W)
    out = np.empty(W.size)
    for i in range(W.size):
        out[i] = W[i] / s
    return out


@numba.njit(cache=True)
def keep_mask(W, u, relative, keep):  # pragma: no cover - compiled
    """Survivors of selection kernel S2 (``relative=False``: keep ``i`` if ``u_i <= W_i``) or S3
    (``relative=True``: if ``u_i <= W_i / max W``), ``W`` renormalised first; writes ``keep (n,)``
    and returns the number of replaced particles."""
    W2 = _renormalised(W)
    top = W2.max()
    k = 0
    for i in range(W2.size):
        keep[i] = u[i] <= (W2[i] / top if relative else W2[i])
        if not keep[i]:
            k += 1
    return k


@numba.njit(cache=True)
def select_mutate(X, W, keep, v, Z, c, rho, lo, hi, population):  # pragma: no cover - compiled
    """Selection, dynamic variance (13.16) and mutation of one ISA generation; returns the next
    particles ``(n, d)``.

    Particle ``i`` with ``keep[i]`` stays, the others in order take the multinomial draws of the
    sorted uniforms ``v`` from the renormalised ``W`` (:func:`.resampling.multinomial`).
    ``population=True`` (13.16 as printed): ``Sigma_jj = c / (n - 1) * sum_i max(X_ij - mean_j, rho)^2``
    over the generation's particles ``X``; ``False``: ``... max(|Xs_ij - mean_j|, rho)^2`` over the
    selected ``Xs``. The next particles are ``clip(Xs + Z * sqrt(Sigma_jj), lo, hi)``.
    """
    n, d = X.shape
    W3 = _renormalised(_renormalised(W))          # select_s*'s _check_W, then multinomial's
    cdf = np.empty(n)
    acc = 0.0
    for i in range(n):
        acc = W3[i] if i == 0 else acc + W3[i]
        cdf[i] = acc
    cdf[n - 1] = 1.0
    A = np.empty(n, np.int64)
    j = 0
    for i in range(n):
        if keep[i]:
            A[i] = i
        else:
            a = 0                                   # searchsorted(cdf, v[j], side="right")
            while a < n and cdf[a] <= v[j]:
                a += 1
            A[i] = min(a, n - 1)
            j += 1
    Xs = np.empty((n, d))
    for i in range(n):
        for q in range(d):
            Xs[i, q] = X[A[i], q]
    S = X if population else Xs
    # numpy reduces along the contiguous axis: Xs = X[A] is C-ordered, X may come F-ordered
    by_column = d == 1 or (population and X.strides[0] == X.itemsize and n > 1)
    mean = column_sums(S, by_column)
    for q in range(d):
        mean[q] = mean[q] / n
    sq = np.empty((n, d))
    for i in range(n):
        for q in range(d):
            dev = max(S[i, q] - mean[q], rho) if population else max(abs(S[i, q] - mean[q]), rho)
            sq[i, q] = dev * dev
    ssq = column_sums(sq, by_column)
    scale = c / max(n - 1, 1)
    sd = np.empty(d)
    for q in range(d):
        sd[q] = np.sqrt(scale * ssq[q])
    out = np.empty((n, d))
    for i in range(n):
        for q in range(d):
            out[i, q] = min(max(Xs[i, q] + Z[i, q] * sd[q], lo[q]), hi[q])
    return out


@numba.njit(cache=True)
def generation_stats(E, P):  # pragma: no cover - compiled
    """``(mean of the finite E, mean over coordinates of P's standard deviation)``, nan when empty:
    ``E[isfinite(E)].mean()`` and ``np.mean(np.std(P, axis=0))``."""
    m = 0
    for i in range(E.size):
        if np.isfinite(E[i]):
            m += 1
    fin = np.empty(m)
    j = 0
    for i in range(E.size):
        if np.isfinite(E[i]):
            fin[j] = E[i]
            j += 1
    mean_energy = pairwise_sum(fin) / m if m else np.nan
    n, d = P.shape
    if n == 0:
        return mean_energy, np.nan
    by_column = d == 1 or (n > 1 and P.strides[0] < P.strides[1])   # np.std keeps P's order
    mean = column_sums(P, by_column)
    for q in range(d):
        mean[q] = mean[q] / n
    sq = np.empty((n, d))
    for i in range(n):
        for q in range(d):
            dev = P[i, q] - mean[q]
            sq[i, q] = dev * dev
    ssq = column_sums(sq, by_column)
    std = np.empty(d)
    for q in range(d):
        std[q] = np.sqrt(ssq[q] / n)
    return mean_energy, pairwise_sum(std) / d
