"""Where the person is in each frame of a recording, from a learned segmentation (pure: numpy, OpenCV, LiteRT).

Used to estimate a background from a recording without empty frames (:mod:`.stable_background`): a pixel
shows the background in the frames where the person is not, whatever the person does elsewhere, so the
temporal mode over those frames is the background even where the person stands still for most of the
recording, and images of the empty scene are needed only where the person never leaves.

The person comes from the BlazePose landmark model's segmentation output
(:meth:`~isa_mocap_ros.vision.landmarks.PoseLandmarker.person_probability`), run twice per frame as
MediaPipe's pose pipeline places its region: first on a square around the pixels that differ from the
temporal mode (within the region where something moved), then on a square around the landmarks found,
turned so the body is upright in the crop. The learned segmentation is used for the background only:
the tracker's masks still come from background subtraction (the segmentation node, EA-vs-PF §3.2).
"""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from .errors import VisionError
from .landmarks import PoseLandmarker, box_from_mask, box_from_points, upright_angle
from .stable_background import _mode, _person_region

__all__ = ["find_person", "people_in_plates", "PERSON_THRESHOLD"]

#: a pixel is the person where the model's probability exceeds this
PERSON_THRESHOLD = 0.5
_HIPS, _SHOULDERS = [23, 24], [11, 12]          # BlazePose landmark indices


def _second_look(landmarker: PoseLandmarker, img: np.ndarray, prob: np.ndarray, lm, min_score: float) -> np.ndarray:
    """The probability again on an upright square around the landmarks ``lm`` (kept when the model still
    sees a person there)."""
    if lm.score < min_score or not np.all(np.isfinite(lm.uv)):
        return prob
    sure = lm.confidence > 0.3
    uv = lm.uv[sure] if sure.sum() >= 8 else lm.uv
    angle = upright_angle(lm.uv[_HIPS].mean(axis=0), lm.uv[_SHOULDERS].mean(axis=0))
    p2, lm2 = landmarker.person_probability(img, box_from_points(uv, scale=1.35, angle_rad=angle))
    return p2 if lm2.score >= min_score else prob


def find_person(frames: np.ndarray, *, landmarker: PoseLandmarker, radius: float = 20.0, active_support: float = 0.9,
                margin: float = 0.04, min_score: float = 0.5) -> np.ndarray:
    """``(N, H, W)`` float32: the probability that the person covers each pixel of each frame.

    Parameters
    ----------
    frames : (N, H, W, 3) uint8 ndarray
        The recording of one view, RGB (``N >= 3``).
    landmarker : PoseLandmarker
    radius, active_support, margin :
        As in :func:`~isa_mocap_ros.vision.stable_background.estimate_background`: the temporal mode and
        the region where something moved, which place the first region of interest.
    min_score : float
        A frame whose pose presence score is lower has no person (probability 0 everywhere).
    """
    frames = np.asarray(frames)
    if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] < 3:
        raise VisionError(f"frames: expected (N >= 3, H, W, 3) uint8, received {frames.dtype} {frames.shape}")
    mode, support = _mode(frames, radius, 25)
    region = _person_region(support, active_support, margin)
    fallback = box_from_mask(region, scale=1.1) if region.any() else \
        np.array([frames.shape[2] / 2, frames.shape[1] / 2, float(max(frames.shape[1:3])), 0.0])
    k3 = np.ones((3, 3), np.uint8)
    out = np.zeros(frames.shape[:3], np.float32)
    for k, img in enumerate(frames):
        diff = (np.abs(img.astype(np.float32) - mode).max(axis=-1) > radius).astype(np.uint8) * 255
        diff = cv2.morphologyEx(diff, cv2.MORPH_OPEN, k3)
        diff[region == 0] = 0
        roi = box_from_mask(diff, scale=1.25, min_pixels=200)
        prob, lm = landmarker.person_probability(img, fallback if roi is None else roi)
        prob = _second_look(landmarker, img, prob, lm, min_score)
        if lm.score >= min_score or prob.max() > PERSON_THRESHOLD:
            out[k] = prob
    return out


def people_in_plates(plates: Sequence[np.ndarray], where: np.ndarray, *, landmarker: PoseLandmarker,
                     min_score: float = 0.5) -> list[np.ndarray]:
    """Per background image, ``(H, W)`` bool: a person the model finds in the square around ``where``
    ((H, W) bool, e.g. every pixel the recording's person covered); all False where it finds none.
    A scene shot taken with people in it (the Pose2Sim demo's) is no background where they stand."""
    roi = box_from_mask(np.asarray(where, np.uint8), scale=1.2)
    out = []
    for p in plates:
        if roi is None:
            out.append(np.zeros(p.shape[:2], bool))
            continue
        prob, lm = landmarker.person_probability(p, roi)
        prob = _second_look(landmarker, p, prob, lm, min_score)
        out.append((prob > PERSON_THRESHOLD) if lm.score >= min_score else np.zeros(p.shape[:2], bool))
    return out
