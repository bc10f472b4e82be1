"""The silhouette energy's coarse level: the sampled kernel's argument bundles restricted to two of the views, the
scanline kernel's to every second pixel row (:meth:`.silhouette.SilhouetteEnergy.coarse_kernel_args`, docs/energy.md
"What the resolution buys")."""
from __future__ import annotations

import numpy as np

from . import silhouette_kernel as _k

__all__ = ["coarse_views", "view_subset", "raster_rows_subset"]


def coarse_views(cameras, view_w: np.ndarray, second: bool = False) -> np.ndarray:
    """Positions of the two views among ``cameras`` (the used ones, with weights ``view_w``) whose optical axes
    are closest to perpendicular (two views see depth best that way; the larger weight product among equals),
    or all positions with fewer than three views or fewer than two of positive weight. ``second``: the pair
    chosen the same way among the pairs with at least one view outside the first pair (the other two views
    of a ring of four), so that alternating the two pairs uses every view."""
    n = len(cameras)
    if n < 3:
        return np.arange(n)
    first = coarse_views(cameras, view_w) if second else None
    axes = [np.asarray(c.R)[2] for c in cameras]      # the optical axis in the world: row 3 of world -> camera
    best, pick = None, None
    for a in range(n):
        for b in range(a + 1, n):
            if view_w[a] <= 0 or view_w[b] <= 0:
                continue
            if first is not None and (a in first) + (b in first) > (0 if n - len(first) >= 2 else 1):
                continue
            key = (round(abs(float(np.dot(axes[a], axes[b]))), 6), -float(view_w[a] * view_w[b]))
            if best is None or key < best:
                best, pick = key, (a, b)
    return np.arange(n) if pick is None else np.array(pick, np.int64)


def view_subset(kernel_args: tuple, k: np.ndarray) -> tuple:
    """The full kernel's bundles ``(Body, Views, Template, Foreground)`` restricted to the views at positions
    ``k`` (their rows of every per-view array, their strips of the foreground sample)."""
    body, views, tmpl, f = kernel_args
    V = views.cam_R.shape[0]
    S = f.fg_tab.shape[0] // V

    def rows(a):    # the strips' rows of views k
        return np.ascontiguousarray(a.reshape(V, S, *a.shape[1:])[k].reshape(len(k) * S, *a.shape[1:]))

    sub = _k.Views(*(np.ascontiguousarray(a[k]) for a in views))
    fg = _k.Foreground(np.ascontiguousarray(f.fg_x.reshape(V, -1)[k].ravel()),
                       np.ascontiguousarray(f.fg_y.reshape(V, -1)[k].ravel()), np.ascontiguousarray(f.fg_n[k]),
                       rows(f.fg_tab), rows(f.fg_bins), rows(f.fg_xr), np.ascontiguousarray(f.fg_area[k]))
    return body, sub, tmpl, fg


def raster_rows_subset(raster):
    """The scanline kernel's :data:`.raster_kernel.Raster` on every second of its sampled rows (row stride ``2 s``):
    the same bits as :func:`.raster_kernel.foreground_bits` of the masks at that stride (the rows ``0, 2 s, 4 s, ...``
    taken from the packed words, the foreground recounted on them). The scanline energy's coarse level
    (:meth:`.silhouette.SilhouetteEnergy.coarse_kernel_args`)."""
    from .raster_kernel import Raster

    fbits, nfg, nw, stride = raster
    V = fbits.shape[0]
    Hs = (fbits.shape[1] - 8) // nw
    rows = fbits[:, :nw * Hs].reshape(V, nw, Hs)[:, :, ::2]        # word-plane major: (view, word column, row)
    Hs2 = rows.shape[2]
    fb = np.zeros((V, nw * Hs2 + 8), np.uint64)
    fb[:, :nw * Hs2] = rows.reshape(V, nw * Hs2)
    return Raster(fb, np.bitwise_count(fb).sum(axis=1).astype(np.int64), nw, 2 * stride)
