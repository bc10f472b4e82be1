"""Which frames of a view the keypoint detector runs on, and the detection of one view's frame.

One rule for the keypoint node and the offline ``isa-mocap track``, so a lockstep replay through the node
network gives the offline tracker's estimates bit for bit (docs/keypoints.md):

* a frame whose mask is empty is never detected on (nobody to crop around);
* of a view's frames with a person, the first ``dense_frames`` are all detected on: the automatic
  initialization and the heading check that follows it (``TrackerConfig.init_confirm_frames`` frames) are
  where the keypoints tell front from back;
* after those, every ``every_k``-th frame with a person (counted from the view's first one).

The schedule counts frames per view from what the view shows, not from clocks or the tracker's state, so two
processes that see the same frames decide alike.

Pure (no ROS).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from .errors import VisionError
from .landmarks import Landmarks2D, PoseLandmarker, box_from_mask

__all__ = ["KeypointSchedule", "detect_in_mask", "DENSE_FRAMES", "EVERY_K"]

#: frames with a person detected on at the start of a view: the initialization's frame and the heading
#: check's 3 frames after it (TrackerConfig.init_confirm_frames' default)
DENSE_FRAMES = 4
#: after the dense start, every EVERY_K-th frame with a person (the keypoint node's and ``track``'s default;
#: the rate's cost and accuracy: docs/keypoints.md)
EVERY_K = 8


class KeypointSchedule:
    """Per-view frame choice (see the module docstring).

    Parameters
    ----------
    every_k : int
        After the dense start, detect on every ``every_k``-th frame with a person (1 = all; 0 = none after
        the dense start).
    dense_frames : int
        Frames with a person detected on at the start (>= 0).

    Examples
    --------
    >>> s = KeypointSchedule(every_k=4, dense_frames=2)
    >>> [s.due(m) for m in (False, True, True, True, True, True, True, False, True)]
    [False, True, True, False, False, True, False, False, False]
    """

    def __init__(self, every_k: int, *, dense_frames: int = DENSE_FRAMES) -> None:
        for name, value, lo in (("every_k", every_k, 0), ("dense_frames", dense_frames, 0)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
                raise VisionError(f"{name}: expected an integer >= {lo}, received {value!r}")
        self.every_k = int(every_k)
        self.dense_frames = int(dense_frames)
        self.person_frames = 0          # frames with a person seen so far

    def due(self, has_person: bool) -> bool:
        """Whether to detect on this frame (call once per frame, in order)."""
        if not has_person:
            return False
        c = self.person_frames
        self.person_frames += 1
        return c < self.dense_frames or (self.every_k > 0 and c % self.every_k == 0)


def detect_in_mask(detector: PoseLandmarker, image: Any, mask: Any, *, box_scale: float = 1.25,
                   min_score: float = 0.5, bgr: bool = False) -> Landmarks2D | None:
    """The landmarks of the person in the square around ``mask``'s foreground, or None (empty mask, or a pose
    score below ``min_score``: nobody there).

    Raises
    ------
    VisionError
        ``mask`` is not of ``image``'s size, or the image is not (H, W, 3) uint8.
    """
    img = np.asarray(image)
    m = np.asarray(mask)
    if m.ndim == 3:
        m = m[..., 0]
    if m.shape[:2] != img.shape[:2]:
        raise VisionError(f"mask: expected the image's size {img.shape[1]}x{img.shape[0]}, received "
                          f"{m.shape[1] if m.ndim > 1 else '?'}x{m.shape[0]}")
    box = box_from_mask(m, scale=box_scale)
    if box is None:
        return None
    lm = detector.detect(img, box, bgr=bgr)
    return lm if lm.score >= min_score else None
