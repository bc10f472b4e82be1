"""Per-pixel kernels of the background segmentation (:mod:`.segmentation`): the colour-model
foreground test and update, the colour agreement of neighbours, the Gaussian window sum of the vote and
the fill of unreliable pixels from reliable ones, each as a plain numpy reference and, where it pays, a
compiled numba kernel (the default); test/test_segmentation.py checks that they agree. The robust-mode
kernels are in :mod:`.robust_mode`.
"""
from __future__ import annotations

import cv2
import numba
import numpy as np

from .robust_mode import _robust_finish_numba, _robust_finish_numpy, _robust_pairs_numba, _robust_pairs_numpy


# --------------------------------------------------------------------------- colour-model kernels
# Two implementations of the same per-pixel steps: a plain numpy reference and a single-pass numba
# kernel (the default, ~10x faster); test/test_segmentation.py checks that they agree.

def _foreground_numpy(img, mu, var, min_var, thr2, shadow, a_lo, a_hi, cd2_max):
    """Raw foreground (H, W) uint8 0/1: ``d^2 = sum_c (I-mu)^2 / s^2 > thr2``, minus shadows."""
    imgf = img.astype(np.float32)
    inv_var = 1.0 / np.maximum(var, min_var)
    diff = imgf - mu
    d2 = np.einsum("hwc,hwc->hw", diff * diff, inv_var)          # d^2 = sum_c (I-mu)^2 / s^2
    fg = d2 > thr2
    if shadow:
        num = np.einsum("hwc,hwc->hw", imgf * mu, inv_var)
        den = np.maximum(np.einsum("hwc,hwc->hw", mu * mu, inv_var), np.float32(1e-6))
        alpha = num / den                                           # brightness distortion
        r = imgf - alpha[:, :, None] * mu
        cd2 = np.einsum("hwc,hwc->hw", r * r, inv_var)              # chromaticity distortion^2
        fg &= ~((alpha >= a_lo) & (alpha <= a_hi) & (cd2 < cd2_max))
    return fg.view(np.uint8)


def _update_numpy(img, mu, var, frozen, rho):
    """In place, where ``frozen == 0``: ``mu += rho (I - mu)``, ``s^2 += rho ((I - mu)^2 - s^2)``."""
    diff = img.astype(np.float32) - mu
    where = (frozen == 0)[:, :, None]
    np.add(mu, rho * diff, out=mu, where=where)
    np.add(var, rho * (diff * diff - var), out=var, where=where)


@numba.njit(cache=True, nogil=True, boundscheck=False)
def _foreground3_numba(img, mu, var, min_var, thr2):  # pragma: no cover - compiled
    # _foreground_numba for colour images without shadow suppression: the three channels written out (the same
    # operations in the same order, so the same bits), a row at a time; ~25 % less time than the channel loop
    H, W, _ = img.shape
    out = np.empty((H, W), np.uint8)
    one = np.float32(1.0)
    for y in range(H):
        im, m, v, o = img[y], mu[y], var[y], out[y]
        for x in range(W):
            e0 = np.float32(im[x, 0]) - m[x, 0]
            e1 = np.float32(im[x, 1]) - m[x, 1]
            e2 = np.float32(im[x, 2]) - m[x, 2]
            d2 = np.float32(0.0)
            d2 += e0 * e0 * (one / max(v[x, 0], min_var))
            d2 += e1 * e1 * (one / max(v[x, 1], min_var))
            d2 += e2 * e2 * (one / max(v[x, 2], min_var))
            o[x] = d2 > thr2
    return out


@numba.njit(cache=True, nogil=True)
def _foreground_numba(img, mu, var, min_var, thr2, shadow, a_lo, a_hi, cd2_max):  # pragma: no cover
    H, W, C = img.shape
    if C == 3 and not shadow:
        return _foreground3_numba(img, mu, var, min_var, thr2)
    out = np.zeros((H, W), np.uint8)
    for y in range(H):
        for x in range(W):
            d2 = np.float32(0.0)
            num = np.float32(0.0)
            den = np.float32(0.0)
            for c in range(C):
                iv = np.float32(1.0) / max(var[y, x, c], min_var)
                i = np.float32(img[y, x, c])
                m = mu[y, x, c]
                d = i - m
                d2 += d * d * iv
                num += i * m * iv
                den += m * m * iv
            out[y, x] = d2 > thr2   # stored without a branch: under pixel noise it is a coin flip
            if shadow and d2 > thr2:
                alpha = num / max(den, np.float32(1e-6))
                if alpha >= a_lo and alpha <= a_hi:
                    cd2 = np.float32(0.0)
                    for c in range(C):
                        iv = np.float32(1.0) / max(var[y, x, c], min_var)
                        r = np.float32(img[y, x, c]) - alpha * mu[y, x, c]
                        cd2 += r * r * iv
                    if cd2 < cd2_max:
                        out[y, x] = 0
    return out


@numba.njit(cache=True, nogil=True, boundscheck=False)
def _update3_numba(img, mu, var, frozen, rho):  # pragma: no cover - compiled
    # _update_numba for colour images, the three channels written out (the same operations: the same bits)
    H, W, _ = img.shape
    for y in range(H):
        im, m, v, f = img[y], mu[y], var[y], frozen[y]
        for x in range(W):
            if f[x] == 0:
                for c in range(3):
                    d = np.float32(im[x, c]) - m[x, c]
                    m[x, c] += rho * d
                    v[x, c] += rho * (d * d - v[x, c])


@numba.njit(cache=True, nogil=True)
def _update_numba(img, mu, var, frozen, rho):  # pragma: no cover
    H, W, C = img.shape
    if C == 3:
        _update3_numba(img, mu, var, frozen, rho)
        return
    for y in range(H):
        for x in range(W):
            if frozen[y, x] == 0:
                for c in range(C):
                    d = np.float32(img[y, x, c]) - mu[y, x, c]
                    mu[y, x, c] += rho * d
                    var[y, x, c] += rho * (d * d - var[y, x, c])


def _accumulate_numpy(img, total, total_sq):
    """In place: ``total += img``, ``total_sq += img**2`` (int64, exact: the learning images' sums)."""
    np.add(total, img, out=total, casting="unsafe")
    total_sq += np.square(img, dtype=np.int64)


@numba.njit(cache=True, nogil=True)
def _accumulate_numba(img, total, total_sq):  # pragma: no cover - compiled
    H, W, C = img.shape
    for y in range(H):
        for x in range(W):
            for c in range(C):
                v = np.int64(img[y, x, c])
                total[y, x, c] += v
                total_sq[y, x, c] += v * v


@numba.njit(cache=True, nogil=True)
def _label_counts(labels, n):  # pragma: no cover - compiled
    """``np.bincount(labels.ravel(), minlength=n)`` for the (H, W) int32 labels of ``cv2.connectedComponents``
    (its pixel count per label; ~4x less time than bincount, which first converts the labels to intp)."""
    counts = np.zeros(n, np.int64)
    H, W = labels.shape
    for y in range(H):
        for x in range(W):
            counts[labels[y, x]] += 1
    return counts


def _agree_numpy(img, fg, radius):
    """``(H, W)`` uint8: 1 where ``fg`` is set and one of the 8 neighbours is set too with every
    colour channel within ``radius`` levels (two random colours rarely agree: ~0.4 % at 20 levels)."""
    H, W = fg.shape
    im = img.astype(np.int16)
    D = fg > 0
    out = np.zeros((H, W), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == 0 and dx == 0:
                continue
            ys, ye, xs, xe = max(0, dy), H + min(0, dy), max(0, dx), W + min(0, dx)
            a, b = im[ys:ye, xs:xe], im[ys - dy:ye - dy, xs - dx:xe - dx]
            ok = (np.abs(a - b).max(axis=2) <= radius) & D[ys:ye, xs:xe] & D[ys - dy:ye - dy, xs - dx:xe - dx]
            out[ys:ye, xs:xe] |= ok
    return out.astype(np.uint8)


@numba.njit(cache=True, nogil=True)
def _agree_numba(img, fg, radius):  # pragma: no cover - compiled
    # agreement is symmetric: each pair of 8-neighbours is tested once (its forward half: right,
    # down-left, down, down-right) and marks both pixels
    H, W, C = img.shape
    out = np.zeros((H, W), np.uint8)
    for y in range(H):
        for x in range(W):
            if fg[y, x] == 0:
                continue
            for k in range(4):
                dy = 0 if k == 0 else 1
                dx = 1 if k == 0 else k - 2
                yy, xx = y + dy, x + dx
                if yy >= H or xx < 0 or xx >= W or fg[yy, xx] == 0:
                    continue
                if out[y, x] and out[yy, xx]:
                    continue
                ok = True
                for c in range(C):
                    if abs(np.int32(img[y, x, c]) - np.int32(img[yy, xx, c])) > radius:
                        ok = False
                        break
                if ok:
                    out[y, x] = 1
                    out[yy, xx] = 1
    return out


#: per kernel: foreground, model update, robust pairs (one new sample), robust finish, colour agreement
_KERNELS = {"numpy": (_foreground_numpy, _update_numpy, _robust_pairs_numpy, _robust_finish_numpy, _agree_numpy),
            "numba": (_foreground_numba, _update_numba, _robust_pairs_numba, _robust_finish_numba, _agree_numba)}
#: per kernel: the learning images' exact sums (one image)
_LEARN_KERNELS = {"numpy": (_accumulate_numpy,), "numba": (_accumulate_numba,)}


def _window_sum(a: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian-weighted window sum (truncated at 2.5 sigma)."""
    k = 2 * int(np.ceil(2.5 * sigma)) + 1
    return cv2.GaussianBlur(a, (k, k), sigma, borderType=cv2.BORDER_REFLECT)


def _fill_from_reliable(arr: np.ndarray, reliable: np.ndarray, side: int, *, smooth: bool = False) -> np.ndarray:
    """Box mean of ``arr`` over reliable pixels; used at unreliable pixels (everywhere if ``smooth``).

    The box sums are OpenCV's; the rest is :func:`_fill_numpy`'s arithmetic, compiled
    (:func:`_fill_numba`, the same float32 operations: the same bits; ~4x less time)."""
    shape = arr.shape
    a = np.ascontiguousarray(arr.reshape(shape[0], shape[1], -1), dtype=np.float32)
    r = reliable.astype(np.float32)
    num = cv2.boxFilter(_masked(a, r), -1, (side, side), normalize=False).reshape(a.shape)
    den = cv2.boxFilter(r, -1, (side, side), normalize=False)
    return _fill_numba(a, r, np.ascontiguousarray(num), den, smooth).reshape(shape)


def _fill_numpy(a, r, num, den, smooth):
    """The reference of :func:`_fill_numba` (what :func:`_fill_from_reliable` computed in numpy)."""
    den = den[:, :, None]
    mean = np.where(den > 0, num / np.maximum(den, 1e-6), a)
    out = mean if smooth else np.where(r[:, :, None] > 0, a, mean)
    return out.astype(np.float32)


@numba.njit(cache=True, nogil=True)
def _masked(a, r):  # pragma: no cover - compiled
    """``a * r[:, :, None]`` (float32)."""
    H, W, C = a.shape
    out = np.empty_like(a)
    for y in range(H):
        for x in range(W):
            for c in range(C):
                out[y, x, c] = a[y, x, c] * r[y, x]
    return out


@numba.njit(cache=True, nogil=True)
def _fill_numba(a, r, num, den, smooth):  # pragma: no cover - compiled
    H, W, C = a.shape
    out = np.empty_like(a)
    tiny = np.float32(1e-6)
    for y in range(H):
        for x in range(W):
            dn = den[y, x]
            for c in range(C):
                if not smooth and r[y, x] > 0:
                    out[y, x, c] = a[y, x, c]
                elif dn > 0:
                    out[y, x, c] = num[y, x, c] / max(dn, tiny)
                else:
                    out[y, x, c] = a[y, x, c]
    return out
