"""The frame's keypoints screened against the views' own evidence before they enter the energy.

A learned detector's landmark on a crop that something covers is wrong, and its confidence does not say so
(issue 33: 35 occluding rectangles made the keypoint term cost 23 mm). Two tests drop such detections from
the frame's :class:`~isa_mocap_ros.energy.KeypointEnergy` (:meth:`~isa_mocap_ros.energy.KeypointEnergy.subset`):

1. **Foreground** (:func:`off_foreground`): a landmark farther than :data:`MASK_MARGIN_PX` from the frame's
   filtered foreground (after the mask gate and the visual-hull filter, or the first frame's hull) lies on
   nothing the views agree is the person.
2. **Multi-view consensus** (:func:`consensus`): the rays of one landmark seen in several views meet near one
   point when the detections are right. For every pair of views the midpoint of the rays' common
   perpendicular is a candidate; a view's ray is an inlier of a candidate when it passes within
   :data:`CONSENSUS_M` of it (the Plücker distance ‖X × n − m‖, ISA 13.30). The candidate with the most
   inliers (ties: the smaller sum of distances capped at :data:`CONSENSUS_M`) wins; when at least
   :data:`MIN_CONSENSUS` views agree, the views outside its inliers are dropped. A landmark fewer views agree
   on goes entirely: seen in one view only, or in views whose rays miss each other (which one is wrong cannot
   be told). Under 35 occluders the detector found the person in one or two views of a frame at most, and 93 %
   of those landmarks were more than 10 cm off the true joint's ray.

Pure numpy/OpenCV; the tracker applies it after filtering the frame's masks (``Tracker.track_frame``).
"""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

__all__ = ["MASK_MARGIN_PX", "CONSENSUS_M", "MIN_CONSENSUS", "off_foreground", "consensus", "screen"]

#: a landmark farther than this (pixels) from the filtered foreground is dropped (BlazePose's joints lie
#: inside the limb; 3 px allows for a thin limb the segmentation shaved)
MASK_MARGIN_PX = 3.0
#: a view's ray agrees with a landmark's consensus point within this distance (m; a little above the keypoint term's
#: σ = 0.1, where its loss already flattens; 0.08 dropped more of the real recording's landmarks: decision 016)
CONSENSUS_M = 0.12
#: views that must agree on a landmark for it to be used (2: every kept detection is confirmed by another view)
MIN_CONSENSUS = 2


def off_foreground(pixels: np.ndarray, views: np.ndarray, masks: Sequence, *,
                   margin_px: float = MASK_MARGIN_PX) -> np.ndarray:
    """``(K,)`` bool: the correspondences whose pixel ``pixels[k]`` lies farther than ``margin_px`` from the
    foreground of ``masks[views[k]]`` (nonzero = foreground), or outside that image. Views whose mask is None
    are not judged (False)."""
    pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(len(pixels), dtype=bool)
    for v in np.unique(views):
        m = masks[v] if 0 <= v < len(masks) else None
        if m is None:
            continue
        m = np.asarray(m)
        idx = np.flatnonzero(views == v)
        h, w = m.shape
        u = np.rint(pixels[idx, 0]).astype(np.int64)
        r = np.rint(pixels[idx, 1]).astype(np.int64)
        inside = (u >= 0) & (u < w) & (r >= 0) & (r < h)
        far = ~inside
        if inside.any():
            # distance of every background pixel to the nearest foreground pixel (0 on the foreground)
            dist = cv2.distanceTransform((m == 0).astype(np.uint8), cv2.DIST_L2, 3)
            far[inside] = dist[r[inside], u[inside]] > margin_px
        out[idx] = far
    return out


def _midpoint(c1, n1, c2, n2):
    """The midpoint of the common perpendicular of rays ``c + t n`` (unit ``n``), or None when (nearly) parallel
    or behind either camera."""
    b = float(n1 @ n2)
    den = 1.0 - b * b
    if den < 1e-6:
        return None
    w = c1 - c2
    d, e = float(n1 @ w), float(n2 @ w)
    t1, t2 = (b * e - d) / den, (e - b * d) / den
    if t1 <= 0 or t2 <= 0:
        return None
    return 0.5 * (c1 + t1 * n1 + c2 + t2 * n2)


def consensus(joints: np.ndarray, centres: np.ndarray, directions: np.ndarray, moments: np.ndarray, *,
              tolerance_m: float = CONSENSUS_M, min_views: int = MIN_CONSENSUS) -> np.ndarray:
    """``(K,)`` bool: the correspondences outside their landmark's multi-view consensus (module docstring): all
    of a landmark's correspondences when fewer than ``min_views`` views agree on it.

    ``joints (K,)`` groups the correspondences (one landmark per model joint, one correspondence per view);
    ``centres (K, 3)`` are their cameras' centres, ``directions``/``moments (K, 3)`` their rays' Plücker lines
    (unit ``n``, ``m = c × n``)."""
    joints = np.asarray(joints)
    out = np.ones(len(joints), dtype=bool)
    n_all, m_all = np.asarray(directions, dtype=np.float64), np.asarray(moments, dtype=np.float64)
    c_all = np.asarray(centres, dtype=np.float64)
    for j in np.unique(joints):
        idx = np.flatnonzero(joints == j)
        if len(idx) < min_views:
            continue
        n, m, c = n_all[idx], m_all[idx], c_all[idx]
        best = None
        for a in range(len(idx)):
            for b in range(a + 1, len(idx)):
                X = _midpoint(c[a], n[a], c[b], n[b])
                if X is None:
                    continue
                d = np.linalg.norm(np.cross(X, n) - m, axis=1)       # ‖X × n − m‖ (13.30)
                inl = d < tolerance_m
                key = (int(inl.sum()), -float(np.minimum(d, tolerance_m).sum()))
                if best is None or key > best[0]:
                    best = (key, inl)
        if best is not None and best[0][0] >= min_views:
            out[idx] = ~best[1]
    return out


def screen(term, masks: Sequence | None):
    """``(term, note)``: the frame's keypoint term without the detections that fail the foreground test on
    ``masks`` (the frame's filtered masks, one per camera, None = not judged) or the multi-view consensus;
    ``term`` itself when nothing is dropped, None when nothing is left; the note (or None) counts what went."""
    if term is None or term.n_correspondences == 0:
        return term, None
    off = off_foreground(term.pixels, term.views, masks) if masks is not None else \
        np.zeros(term.n_correspondences, dtype=bool)
    keep = ~off
    outliers = np.zeros_like(off)
    if keep.any():
        centres = np.array([term.cameras[v].center for v in term.views[keep]]).reshape(-1, 3)
        outliers[keep] = consensus(term.joints[keep], centres, term.directions[keep], term.moments[keep])
    keep &= ~outliers
    if keep.all():
        return term, None
    note = (f"keypoints screened: {int(off.sum())} off the foreground, {int(outliers.sum())} outside the views' "
            f"consensus, {int(keep.sum())} of {term.n_correspondences} kept")
    return (term.subset(keep) if keep.any() else None), note
