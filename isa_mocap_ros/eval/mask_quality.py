"""Foreground-mask quality measured against a reference skeleton (evaluation only; pure numpy / OpenCV).

A real recording has no true silhouettes, but a peer's 3-D keypoints (Pose2Sim's, ``docs/real_cameras.md``)
projected into a view give a 2-D stick figure of the person. Per view and frame:

* **beyond** — the share of mask pixels farther than ``far_px`` from the stick figure: foreground that is
  not the person (a ghost of another person in the background model, shadows, furniture);
* **core missed** — the share of the stick figure's core (its bones drawn ``core_px`` wide) that the mask
  misses: the person taken as background;
* **keypoints on** — the share of the projected keypoints that fall on the mask.

The stick figure is not a silhouette (limbs are wider than ``core_px``, the torso wider than its bones), so
the figures are comparisons between masks of one recording, not absolute truths. Used by
``isa-mocap bench real`` and the background tests; never by the tracker.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["SKELETON", "MaskQuality", "skeleton_image", "mask_quality", "mean_quality"]

#: bones of the reference's stick figure, by the joint names of :data:`isa_mocap_ros.eval.trc.POSE2SIM_TO_JOINTS`
#: (and Pose2Sim's names for the points we do not score); a bone whose end is missing is left out
SKELETON = (
    ("right_hip", "right_knee"), ("right_knee", "right_ankle"), ("right_ankle", "RBigToe"), ("right_ankle", "RHeel"),
    ("left_hip", "left_knee"), ("left_knee", "left_ankle"), ("left_ankle", "LBigToe"), ("left_ankle", "LHeel"),
    ("right_hip", "left_hip"), ("right_shoulder", "left_shoulder"), ("right_hip", "right_shoulder"),
    ("left_hip", "left_shoulder"), ("neck", "head"), ("right_shoulder", "right_elbow"),
    ("right_elbow", "right_wrist"), ("left_shoulder", "left_elbow"), ("left_elbow", "left_wrist"),
)


@dataclass(frozen=True)
class MaskQuality:
    """One view's mask against the stick figure (module docstring); NaN where undefined."""

    beyond: float
    core_missed: float
    keypoints_on: float


def skeleton_image(cam, points: np.ndarray, names, *, width_px: int) -> tuple[np.ndarray, np.ndarray]:
    """``(figure, uv)``: the stick figure of the world ``points`` ``(M, 3)`` (NaN = missing) drawn
    ``width_px`` wide in ``cam``'s image as a (H, W) uint8 0/255 image, and the projected points ``(M, 2)``
    (NaN where missing or behind the camera)."""
    P = np.asarray(points, float)
    ok = np.all(np.isfinite(P), axis=1)
    uv = np.full((len(P), 2), np.nan)
    if ok.any():
        front = cam.depth(P[ok]) > 0
        idx = np.flatnonzero(ok)[front]
        uv[idx] = cam.project(P[idx])
    img = np.zeros((cam.height, cam.width), np.uint8)
    pos = {str(n): i for i, n in enumerate(names)}
    for a, b in SKELETON:
        if a in pos and b in pos and np.all(np.isfinite(uv[[pos[a], pos[b]]])):
            p, q = (tuple(int(round(c)) for c in uv[pos[k]]) for k in (a, b))
            cv2.line(img, p, q, 255, int(width_px), cv2.LINE_8)
    return img, uv


def mask_quality(cam, points: np.ndarray, names, mask: np.ndarray, *, far_px: float = 18.0,
                 core_px: int = 5) -> MaskQuality:
    """:class:`MaskQuality` of ``mask`` (H, W; nonzero = foreground) in view ``cam`` against the reference
    ``points`` (M, 3, world; NaN = missing) named ``names``. ``far_px`` and ``core_px`` are in the mask's
    pixels (the defaults suit a 320-px-wide portrait view of a whole person)."""
    m = np.asarray(mask) > 0
    if m.shape != (cam.height, cam.width):
        raise ValueError(f"mask: expected {(cam.height, cam.width)} (camera {cam.name}), received {m.shape}")
    core, uv = skeleton_image(cam, points, names, width_px=core_px)
    thin, _ = skeleton_image(cam, points, names, width_px=1)
    if not thin.any():
        return MaskQuality(float("nan"), float("nan"), float("nan"))
    dist = cv2.distanceTransform((thin == 0).astype(np.uint8), cv2.DIST_L2, 5)
    n_mask = int(m.sum())
    beyond = float((m & (dist > far_px)).sum() / n_mask) if n_mask else float("nan")
    core_on = core > 0
    missed = float((core_on & ~m).sum() / max(int(core_on.sum()), 1))
    good = np.all(np.isfinite(uv), axis=1)
    ij = np.round(uv[good]).astype(int)
    inside = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < m.shape[1]) & (ij[:, 1] < m.shape[0])
    on = float(m[ij[inside, 1], ij[inside, 0]].mean()) if inside.any() else float("nan")
    return MaskQuality(beyond, missed, on)


def mean_quality(qualities) -> MaskQuality:
    """Mean of several :class:`MaskQuality` (frames of one view), NaNs left out."""
    a = np.array([[q.beyond, q.core_missed, q.keypoints_on] for q in qualities], float)
    with np.errstate(invalid="ignore"):
        m = np.nanmean(a, axis=0) if len(a) else np.full(3, np.nan)
    return MaskQuality(*map(float, m))
