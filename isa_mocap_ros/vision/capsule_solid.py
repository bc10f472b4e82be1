"""The capsule solid of the renderer (:mod:`.render`): the checks of a body's capsules, the per-capsule numbers
and bounding spheres its ray kernels take, and a slow reference point-in-solid test.

A capsule with end points ``p0, p1`` and end radii ``r0, r1`` is the convex hull of the balls ``B(p0, r0)`` and
``B(p1, r1)`` (the module docstring of :mod:`.render` gives the geometry and its sources). Pure numpy, and the
per-capsule numbers also compiled (:func:`capsule_data`'s, once per pose: the numpy version's small-array calls
cost ~0.1 ms; the same bits, tested).
"""
from __future__ import annotations

from typing import Any

import numba
import numpy as np

from .errors import VisionError

__all__ = ["capsule_data", "capsule_contains"]

#: most bounding spheres per capsule (the tile culling's)
_MAX_BOUND = 4


def _check_capsules(endpoints: Any, radii: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        E = np.asarray(endpoints, dtype=np.float64)
        Rr = np.asarray(radii, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise VisionError(f"endpoints/radii: expected numeric arrays, received {endpoints!r}, {radii!r}") from exc
    if E.ndim != 3 or E.shape[1:] != (2, 3):
        raise VisionError(f"endpoints: expected shape (C, 2, 3), received shape {E.shape}")
    if Rr.shape != (E.shape[0], 2):
        raise VisionError(f"radii: expected shape ({E.shape[0]}, 2) to match endpoints, received shape {Rr.shape}")
    if not np.all(np.isfinite(E)):
        raise VisionError("endpoints: expected finite numbers, received NaN or inf")
    if not np.all(np.isfinite(Rr)) or np.any(Rr <= 0):
        raise VisionError(f"radii: expected finite positive radii, received min {Rr.min() if Rr.size else None}")
    return E, Rr


def _capsule_params(E: np.ndarray, Rr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per capsule: 16 numbers for the intersection kernel, bounding spheres (C, 4, 4) and their count (C,)."""
    C = E.shape[0]
    a, b = E[:, 0], E[:, 1]
    ra, rb = Rr[:, 0], Rr[:, 1]
    ba = b - a
    L = np.linalg.norm(ba, axis=1)
    cone_ok = L > np.abs(ra - rb) * (1.0 + 1e-9) + 1e-12
    u = np.where(L[:, None] > 0, ba / np.where(L > 0, L, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
    s = np.where(cone_ok, (ra - rb) / np.where(cone_ok, L, 1.0), 0.0)
    ca = np.sqrt(np.maximum(0.0, 1.0 - s * s))
    caps = np.zeros((C, 16))
    caps[:, 0:3], caps[:, 3:6], caps[:, 6] = a, u, L
    caps[:, 7], caps[:, 8], caps[:, 9], caps[:, 10], caps[:, 11] = ra, rb, s, ca, ca * ca
    caps[:, 12] = cone_ok
    caps[:, 13:16] = b
    # bounding spheres: k sub-segments, radius = half sub-length + the larger end radius
    nb = np.clip(np.ceil(L / (2.0 * np.maximum(ra, rb))), 1, _MAX_BOUND).astype(np.int64)
    j = np.arange(_MAX_BOUND)[None, :]
    k = nb[:, None].astype(np.float64)
    s0, s1 = np.minimum(j, k) / k, np.minimum(j + 1, k) / k  # (C, 4); unused slots (j >= k) are never read
    bs = np.zeros((C, _MAX_BOUND, 4))
    bs[:, :, :3] = a[:, None] + ((s0 + s1) / 2.0)[..., None] * ba[:, None]
    dr = (rb - ra)[:, None]
    bs[:, :, 3] = (L[:, None] / (2.0 * k)) + np.maximum(ra[:, None] + s0 * dr, ra[:, None] + s1 * dr)
    # the hull of the two balls is also inside the bigger ball when one contains the other
    for c in np.nonzero(~cone_ok)[0]:
        big = 0 if ra[c] >= rb[c] else 1
        nb[c] = 1
        bs[c, 0, :3] = E[c, big]
        bs[c, 0, 3] = Rr[c, big]
    return caps, bs, nb


@numba.njit(cache=True)
def _capsule_params_compiled(E, Rr):  # pragma: no cover - compiled
    """:func:`_capsule_params` per capsule, in numpy's order of operations (the same bits)."""
    C = E.shape[0]
    caps = np.zeros((C, 16))
    bs = np.zeros((C, _MAX_BOUND, 4))
    nb = np.empty(C, np.int64)
    for c in range(C):
        ra, rb = Rr[c, 0], Rr[c, 1]
        b0, b1, b2 = E[c, 1, 0] - E[c, 0, 0], E[c, 1, 1] - E[c, 0, 1], E[c, 1, 2] - E[c, 0, 2]
        L = np.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
        cone_ok = L > np.abs(ra - rb) * (1.0 + 1e-9) + 1e-12
        if L > 0:
            u0, u1, u2 = b0 / L, b1 / L, b2 / L
        else:
            u0, u1, u2 = 0.0, 0.0, 1.0
        sl = (ra - rb) / L if cone_ok else 0.0
        ca = np.sqrt(max(0.0, 1.0 - sl * sl))
        for q in range(3):
            caps[c, q] = E[c, 0, q]
            caps[c, 13 + q] = E[c, 1, q]
        caps[c, 3], caps[c, 4], caps[c, 5], caps[c, 6] = u0, u1, u2, L
        caps[c, 7], caps[c, 8], caps[c, 9], caps[c, 10], caps[c, 11] = ra, rb, sl, ca, ca * ca
        caps[c, 12] = 1.0 if cone_ok else 0.0
        k = min(max(np.ceil(L / (2.0 * max(ra, rb))), 1.0), float(_MAX_BOUND))
        nb[c] = int(k)
        k = float(nb[c])
        dr = rb - ra
        for j in range(_MAX_BOUND):
            s0, s1 = min(float(j), k) / k, min(float(j + 1), k) / k
            m = (s0 + s1) / 2.0
            bs[c, j, 0] = E[c, 0, 0] + m * b0
            bs[c, j, 1] = E[c, 0, 1] + m * b1
            bs[c, j, 2] = E[c, 0, 2] + m * b2
            bs[c, j, 3] = (L / (2.0 * k)) + max(ra + s0 * dr, ra + s1 * dr)
        if not cone_ok:                     # the hull of the two balls is inside the bigger one
            big = 0 if ra >= rb else 1
            nb[c] = 1
            for q in range(3):
                bs[c, 0, q] = E[c, big, q]
            bs[c, 0, 3] = Rr[c, big]
    return caps, bs, nb


def capsule_data(endpoints: Any, radii: Any) -> tuple:
    """The capsules checked and turned into the ray kernel's data, once for several views of one pose:
    pass it as ``capsules=`` to :func:`.render.render_mask` / :func:`.render.render_labels_at` (``endpoints`` and
    ``radii`` are then ignored)."""
    E, Rr = _check_capsules(endpoints, radii)
    # writable C-order copies: one compiled signature for every caller (a read-only model array would load a second)
    return _capsule_params_compiled(np.array(E, order="C"), np.array(Rr, order="C"))


def capsule_contains(X: Any, endpoints: Any, radii: Any) -> np.ndarray:
    """Reference point-in-solid test (pure numpy): ``(..., C)`` bool, X inside the hull of the two balls.

    ``min_s |X - p(s)| - r(s) <= 0`` over ``s in [0, 1]``; the function of ``s`` is convex, so the
    minimum is found by golden-section search (60 steps). For tests and slow references.
    """
    E, Rr = _check_capsules(endpoints, radii)
    X = np.asarray(X, dtype=np.float64)[..., None, :]
    a, ba = E[:, 0], E[:, 1] - E[:, 0]
    ra, dr = Rr[:, 0], Rr[:, 1] - Rr[:, 0]

    def f(s):
        return np.linalg.norm(X - (a + s[..., None] * ba), axis=-1) - (ra + s * dr)

    lo = np.zeros(X.shape[:-1])
    hi = np.ones(X.shape[:-1])
    g = (np.sqrt(5.0) - 1.0) / 2.0
    for _ in range(60):
        m1, m2 = hi - g * (hi - lo), lo + g * (hi - lo)
        left = f(m1) < f(m2)
        hi = np.where(left, m2, hi)
        lo = np.where(left, lo, m1)
    return f((lo + hi) / 2.0) <= 0.0
