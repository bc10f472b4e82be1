"""Per-pixel mode of a few image samples (the robust background estimate), plain numpy and compiled.

Used by the segmentation's robust mode (:mod:`.segmentation`, "Robust mode") and by the background of a
recording without empty frames (:mod:`.stable_background`). Samples agree when every channel differs
by at most ``radius``; the sample agreeing with the most others (ties: the tightest group, then the
first) defines the inliers, whose mean and variance are returned with their count.
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["_robust_background_numpy", "_robust_pairs_numpy", "_robust_finish_numpy", "_robust_pairs_numba",
           "_robust_finish_numba", "_robust_pairs_rows_numba", "_robust_finish_rows_numba", "_robust_background_numba",
           "_masked_mode_numpy", "_masked_mode_numba"]


def _robust_background_numpy(stack, radius):
    """Per-pixel mode of K samples: ``(mu, var, count)`` over the samples agreeing with the best one.

    ``stack`` (K, H, W, C) uint8. Samples ``i`` and ``j`` agree when ``max_c |I_ic - I_jc| <= radius``.
    The sample agreeing with the most others defines the inliers (the samples agreeing with it,
    itself included, ``count`` of them); on equal counts the one whose inliers are closest (smallest
    sum of distances) wins, then the first: two random colours that happen to agree are usually
    farther apart than two camera-noise copies of the background. ``mu`` is the inliers' mean,
    ``var`` their unbiased variance (0 for a single inlier).
    """
    x = stack.astype(np.int16)
    K = x.shape[0]
    agree = np.ones((K, K) + x.shape[1:3], bool)
    spread = np.zeros((K,) + x.shape[1:3], np.int64)
    for i in range(K):
        for j in range(i + 1, K):
            dist = np.abs(x[i] - x[j]).max(axis=-1)
            a = dist <= radius
            agree[i, j] = agree[j, i] = a
            spread[i] += np.where(a, dist, 0)
            spread[j] += np.where(a, dist, 0)
    key = agree.sum(axis=1).astype(np.int64) * (256 * K + 1) - spread      # count first, then spread
    best = key.argmax(axis=0)                                                # (H, W), first on ties
    inl = np.take_along_axis(agree, best[None, None], axis=1)[:, 0]          # (K, H, W)
    count = inl.sum(axis=0)
    w = inl[..., None].astype(np.float64)
    mu = (w * x).sum(axis=0) / count[..., None]
    var = (w * (x - mu) ** 2).sum(axis=0) / np.maximum(count - 1, 1)[..., None]
    return mu.astype(np.float32), var.astype(np.float32), count.astype(np.int32)


def _robust_pairs_numpy(stack, k, n, spread, radius):
    """Add the agreements of sample ``k`` with samples ``0..k-1`` to ``n`` and ``spread`` (K, H, W).

    ``n`` starts at 1 (a sample agrees with itself), ``spread`` at 0: after every sample is added
    they are the counts and distance sums of :func:`_robust_background_numpy`. Adding each sample
    as it arrives spreads the K² / 2 pair work over the learning frames.
    """
    x = stack[:k + 1].astype(np.int16)       # the samples so far (the buffer may hold more)
    for j in range(k):
        dist = np.abs(x[k] - x[j]).max(axis=-1)
        a = dist <= radius
        n[k] += a
        n[j] += a
        d = np.where(a, dist, 0).astype(n.dtype)
        spread[k] += d
        spread[j] += d


def _robust_finish_numpy(stack, n, spread, radius):
    """``(mu, var, count)`` of :func:`_robust_background_numpy` from the accumulated pairs."""
    x = stack.astype(np.int16)
    K = x.shape[0]
    key = n.astype(np.int64) * (256 * K + 1) - spread          # count first, then spread
    best = key.argmax(axis=0)                                    # (H, W), first on ties
    xb = np.take_along_axis(x, best[None, ..., None], axis=0)    # (1, H, W, C)
    inl = np.abs(x - xb).max(axis=-1) <= radius                  # (K, H, W)
    count = inl.sum(axis=0)
    w = inl[..., None].astype(np.float64)
    mu = (w * x).sum(axis=0) / count[..., None]
    var = (w * (x - mu) ** 2).sum(axis=0) / np.maximum(count - 1, 1)[..., None]
    return mu.astype(np.float32), var.astype(np.float32), count.astype(np.int32)


def _robust_pairs_numba(stack, k, n, spread, radius):
    """:func:`_robust_pairs_numpy`, compiled (:func:`_robust_pairs_rows_numba` over every row)."""
    _robust_pairs_rows_numba(stack, k, n, spread, float(radius), 0, stack.shape[1])


@numba.njit(cache=True, nogil=True, parallel=True)
def _robust_pairs_rows_numba(stack, k, n, spread, radius, y0, y1):  # pragma: no cover
    # _robust_pairs_numpy on rows y0..y1-1, branch-free along a row of one channel plane, rows in parallel (a row's
    # arithmetic does not depend on the others: a band at a time gives the same bits)
    K, H, W, C = stack.shape
    for y in numba.prange(y0, y1):
        pk = np.empty((C, W), np.int32)
        for x in range(W):
            for c in range(C):
                pk[c, x] = stack[k, y, x, c]
        d = np.empty(W, np.int32)
        for j in range(k):
            for x in range(W):
                d[x] = abs(pk[0, x] - np.int32(stack[j, y, x, 0]))
            for c in range(1, C):
                for x in range(W):
                    d[x] = max(d[x], abs(pk[c, x] - np.int32(stack[j, y, x, c])))
            for x in range(W):
                ok = np.int32(d[x] <= radius)
                n[k, y, x] += ok
                n[j, y, x] += ok
                spread[k, y, x] += ok * d[x]
                spread[j, y, x] += ok * d[x]


def _robust_finish_numba(stack, n, spread, radius):
    """:func:`_robust_finish_numpy`, compiled (:func:`_robust_finish_rows_numba` over every row)."""
    K, H, W, C = stack.shape
    mu = np.zeros((H, W, C), np.float32)
    var = np.zeros((H, W, C), np.float32)
    count = np.zeros((H, W), np.int32)
    _robust_finish_rows_numba(stack, n, spread, float(radius), 0, H, mu, var, count)
    return mu, var, count


@numba.njit(cache=True, nogil=True, parallel=True)
def _robust_finish_rows_numba(stack, n, spread, radius, y0, y1, mu, var, count):  # pragma: no cover
    # _robust_finish_numpy on rows y0..y1-1, written into mu, var, count; rows in parallel. A row's samples are first
    # copied into channel planes, and an outlier adds 0.0 (the same sums, in the same order per pixel, as skipping
    # it), so the inner loops run along x without branches (SIMD)
    K, H, W, C = stack.shape
    for y in numba.prange(y0, y1):
        P = np.empty((K, C, W), np.int32)
        for j in range(K):
            for x in range(W):
                for c in range(C):
                    P[j, c, x] = stack[j, y, x, c]
        ref = np.empty((C, W), np.int32)
        for x in range(W):
            best, best_spread, b = -1, 0, 0
            for i in range(K):
                if n[i, y, x] > best or (n[i, y, x] == best and spread[i, y, x] < best_spread):
                    best, best_spread, b = n[i, y, x], spread[i, y, x], i
            count[y, x] = best
            for c in range(C):
                ref[c, x] = P[b, c, x]
        inl = np.empty((K, W), np.float64)
        d = np.empty(W, np.int32)
        for j in range(K):
            for x in range(W):
                d[x] = abs(ref[0, x] - P[j, 0, x])
            for c in range(1, C):
                for x in range(W):
                    d[x] = max(d[x], abs(ref[c, x] - P[j, c, x]))
            for x in range(W):
                inl[j, x] = 1.0 if d[x] <= radius else 0.0
        m = np.empty(W, np.float64)
        v = np.empty(W, np.float64)
        for c in range(C):
            m[:] = 0.0
            for j in range(K):
                for x in range(W):
                    m[x] += inl[j, x] * np.float64(P[j, c, x])
            for x in range(W):
                m[x] /= count[y, x]
            v[:] = 0.0
            for j in range(K):
                for x in range(W):
                    e = np.float64(P[j, c, x]) - m[x]
                    v[x] += inl[j, x] * (e * e)
            for x in range(W):
                mu[y, x, c] = m[x]
                var[y, x, c] = v[x] / max(count[y, x] - 1, 1)


def _robust_background_numba(stack, radius):
    """:func:`_robust_background_numpy` with the compiled pair and finish kernels."""
    n = np.ones(stack.shape[:3], np.int32)
    spread = np.zeros(stack.shape[:3], np.int32)
    for k in range(1, stack.shape[0]):
        _robust_pairs_numba(stack, k, n, spread, float(radius))
    return _robust_finish_numba(stack, n, spread, float(radius))


def _masked_mode_numpy(stack, valid, radius):
    """Per-pixel mode of the samples ``valid`` there: ``(mu, count, n_valid)``.

    ``stack`` (K, H, W, C) uint8, ``valid`` (K, H, W) bool. Among the valid samples of a pixel the one agreeing
    with the most others (ties: the tightest group, then the first) defines the inliers; ``mu`` is their mean
    (0 where no sample is valid), ``count`` their number, ``n_valid`` the valid samples.
    """
    x = stack.astype(np.int16)
    K = x.shape[0]
    dist = np.abs(x[:, None] - x[None]).max(axis=-1)                              # (K, K, H, W)
    both = valid[:, None] & valid[None]
    agree = both & (dist <= radius)
    key = agree.sum(axis=1).astype(np.int64) * (256 * K + 1) - np.where(agree, dist, 0).sum(axis=1)
    key = np.where(valid, key, -1)
    best = key.argmax(axis=0)
    inl = np.take_along_axis(agree, best[None, None], axis=1)[:, 0] & valid.any(axis=0)[None]
    count = inl.sum(axis=0)
    mu = (inl[..., None] * x).sum(axis=0) / np.maximum(count, 1)[..., None]
    return mu.astype(np.float32), count.astype(np.int32), valid.sum(axis=0).astype(np.int32)


@numba.njit(cache=True, nogil=True, inline="always")
def _sample_distance(stack, i, j, y, x):  # pragma: no cover
    """``max_c |stack[i, y, x, c] - stack[j, y, x, c]|``: how far samples ``i`` and ``j`` of pixel ``(y, x)`` differ."""
    dd = 0
    for c in range(stack.shape[3]):
        dd = max(dd, abs(np.int32(stack[i, y, x, c]) - np.int32(stack[j, y, x, c])))
    return dd


@numba.njit(cache=True, nogil=True, parallel=True)
def _masked_mode_numba(stack, valid, radius):  # pragma: no cover
    # _masked_mode_numpy, pixels of a row in turn, rows in parallel
    K, H, W, C = stack.shape
    mu = np.zeros((H, W, C), np.float32)
    count = np.zeros((H, W), np.int32)
    n_valid = np.zeros((H, W), np.int32)
    for y in numba.prange(H):
        idx = np.empty(K, np.int64)
        for x in range(W):
            n = 0
            for i in range(K):
                if valid[i, y, x]:
                    idx[n] = i
                    n += 1
            n_valid[y, x] = n
            if n == 0:
                continue
            best, best_spread, b = -1, 0, 0
            for a in range(n):
                i = idx[a]
                c, sp = 0, 0
                for bb in range(n):
                    j = idx[bb]
                    dd = _sample_distance(stack, i, j, y, x)
                    if dd <= radius:
                        c += 1
                        sp += dd
                if c > best or (c == best and sp < best_spread):
                    best, best_spread, b = c, sp, i
            count[y, x] = best
            for ch in range(C):
                s = 0.0
                for bb in range(n):
                    j = idx[bb]
                    if _sample_distance(stack, b, j, y, x) <= radius:
                        s += np.float64(stack[j, y, x, ch])
                mu[y, x, ch] = s / best
    return mu, count, n_valid
