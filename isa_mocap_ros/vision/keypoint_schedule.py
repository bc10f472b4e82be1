"""Which frames of a view the keypoint detector runs on, and the detection of one view's frame.

One rule for the keypoint node and the offline ``isa-mocap track``, so a lockstep replay through the node
network gives the offline tracker's estimates bit for bit (docs/keypoints.md):

* a frame whose mask is empty is never detected on (nobody to crop around);
* of a view's frames with a person, the first ``dense_frames`` are all detected on: the automatic
  initialization and the heading check that follows it (``TrackerConfig.init_confirm_frames`` frames) are
  where the keypoints tell front from back;
* after those, every ``every_k``-th frame with a person (counted from the view's first one);
* an option (``KeypointSchedule(extra_gap=G)``): a frame the caller wants (``due(..., wanted=True)``, e.g. where
  :func:`forearms_over_trunk` says a forearm of the previous estimate lies over its trunk in some view, which the
  silhouettes cannot place) is detected on too, at most every ``G``-th frame with a person;
* the detector's square is placed around the mask's foreground (:func:`crop_box`, :data:`CROP`); the crop around
  the person's components only (``"person"``) is an option, and ``"person_checked"`` takes it only where the
  model finds a person there whose segmentation agrees with those components, then detects again in a square
  turned by that detection's own hips and shoulders (:func:`detect_in_mask`).

The schedule counts frames per view from what the view shows, not from clocks or the tracker's state, so two
processes that see the same frames decide alike.

Pure (no ROS).
"""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from .errors import VisionError
from .landmarks import LANDMARK_NAMES, Landmarks2D, PoseLandmarker, box_from_mask, box_from_points, upright_angle

__all__ = ["KeypointSchedule", "forearms_over_trunk", "ARM_TRUNK_JOINTS", "detect_in_mask", "crop_box", "person_pixels",
           "body_axis_angle", "segmentation_iou", "CROP", "CROPS", "DETECT_CROPS", "AGREE_IOU", "DENSE_FRAMES",
           "EVERY_K"]

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
    extra_gap : int
        0 (the default): the frames above only. ``G`` > 0: a frame with a person that the caller wants
        (``due(..., wanted=True)``) is detected on as well when the view's last detection is ``G`` or more
        frames with a person back; the frames above stay as they are.

    Examples
    --------
    >>> s = KeypointSchedule(every_k=4, dense_frames=2)
    >>> [s.due(m) for m in (False, True, True, True, True, True, True, False, True)]
    [False, True, True, False, False, True, False, False, False]
    >>> s = KeypointSchedule(every_k=8, dense_frames=1, extra_gap=2)
    >>> [s.due(True, wanted=w) for w in (False, True, True, True, False, True)]
    [True, False, True, False, False, True]
    """

    def __init__(self, every_k: int, *, dense_frames: int = DENSE_FRAMES, extra_gap: int = 0) -> None:
        for name, value, lo in (("every_k", every_k, 0), ("dense_frames", dense_frames, 0),
                                ("extra_gap", extra_gap, 0)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
                raise VisionError(f"{name}: expected an integer >= {lo}, received {value!r}")
        self.every_k = int(every_k)
        self.dense_frames = int(dense_frames)
        self.extra_gap = int(extra_gap)
        self.person_frames = 0          # frames with a person seen so far
        self.last_detected = None       # the person frame count of the last detection
        self.extra = 0                  # detections made because the caller wanted them

    def due(self, has_person: bool, *, wanted: bool = False) -> bool:
        """Whether to detect on this frame (call once per frame, in order; ``wanted``: see ``extra_gap``)."""
        if not has_person:
            return False
        c = self.person_frames
        self.person_frames += 1
        due = c < self.dense_frames or (self.every_k > 0 and c % self.every_k == 0)
        if not due and wanted and self.extra_gap > 0 and (self.last_detected is None
                                                          or c - self.last_detected >= self.extra_gap):
            due = True
            self.extra += 1
        if due:
            self.last_detected = c
        return due


#: :func:`forearms_over_trunk`'s points, in this order (the model's joint names)
ARM_TRUNK_JOINTS = ("left_shoulder", "right_shoulder", "right_hip", "left_hip",
                    "left_elbow", "left_wrist", "left_hand", "right_elbow", "right_wrist", "right_hand")


def forearms_over_trunk(cameras: Any, points: Any) -> np.ndarray:
    """``(V,)`` bool: the views in which a forearm or hand lies over the trunk, where a silhouette cannot tell
    where it is (issue 34: a forearm in front of the trunk drifts between keypoint frames).

    ``points`` ``(10, 3)`` (m, world) are the joints :data:`ARM_TRUNK_JOINTS` of a pose (the previous estimate or
    the prediction). In each camera the trunk is the convex hull of the projected shoulders and hips; a forearm
    is over it when its middle, its wrist or its hand projects strictly inside (points behind a camera count as not)."""
    P = np.asarray(points, dtype=np.float64)
    if P.shape != (len(ARM_TRUNK_JOINTS), 3):
        raise VisionError(f"points: expected shape ({len(ARM_TRUNK_JOINTS)}, 3), received {P.shape}")
    arm = np.concatenate([0.5 * (P[4] + P[5])[None], P[5:7], 0.5 * (P[7] + P[8])[None], P[8:10]])
    pts = np.concatenate([P[:4], arm])                                  # the trunk's 4 corners, the arms' 6 points
    out = np.zeros(len(cameras), dtype=bool)
    for v, cam in enumerate(cameras):
        Xc = cam.to_camera(pts)
        if np.any(Xc[:4, 2] <= 0):
            continue
        uv = cam.project(pts)
        quad = cv2.convexHull(uv[:4].astype(np.float32).reshape(-1, 1, 2))
        out[v] = any(cv2.pointPolygonTest(quad, (float(p[0]), float(p[1])), False) > 0
                     for p, z in zip(uv[4:], Xc[4:, 2]) if z > 0)
    return out


#: ``detect_in_mask``'s crops: the square around every foreground pixel (``"mask"``, the default), around the
#: person's components only (``"person"``), and around those turned to the components' long axis
#: (``"person_turned"``); the last two measured and not the default (docs/keypoints.md "The crop around the person")
CROPS = ("mask", "person", "person_turned")
#: the crop of the keypoint node and ``track`` (one rule, so a lockstep run equals ``track``): the square around every
#: foreground pixel. ``"person"`` reads the real recording's landmarks better but lets the detector find a partly
#: hidden person among occluders, whose landmarks then pull the fit off (docs/keypoints.md)
CROP = "mask"
#: ``"person"``: foreground components smaller than this share of the largest are not the person (a shadow,
#: a reflection, a ghost in the background model) and do not widen the crop
PERSON_COMPONENT_SHARE = 0.2
#: ``"person_turned"``: the largest turn of the crop from upright, rad; a longer axis farther from vertical
#: (arms spread, lying down) is no body axis, and the crop stays upright
MAX_TURN_RAD = np.radians(45.0)
#: :func:`detect_in_mask`'s crops: :data:`CROPS` (a region from the mask alone) and ``"person_checked"``: the
#: ``"person"`` square where it differs from the ``"mask"`` one is kept only when the model finds a person in it
#: (pose score >= ``min_score``) whose segmentation agrees with the mask's person components (intersection over
#: union >= :data:`AGREE_IOU`), and then refined by a second detection in the square around its landmarks turned
#: by its hips and shoulders (as MediaPipe places its next region); else the ``"mask"`` square is detected on
#: (a second model call either way)
DETECT_CROPS = CROPS + ("person_checked",)
#: ``"person_checked"``: the least intersection over union of the model's person segmentation (probability > 0.5)
#: with the mask's person components. Measured (every 3rd frame, the views where the two squares differ): the real
#: recording 0.63-0.90 (median 0.85); the 35-occluder mesh bags 0.00-0.41 (median 0.14-0.21), where the person is
#: partly hidden and the mask's components hold occluding rectangles (docs/keypoints.md)
AGREE_IOU = 0.5


def person_pixels(mask: Any, *, share: float = PERSON_COMPONENT_SHARE) -> np.ndarray:
    """The foreground of ``mask`` ((H, W), nonzero = foreground) in components (8-connected) of at least
    ``share`` of the largest one's area, as a (H, W) uint8 0/1 image."""
    fg = (np.asarray(mask) > 0).view(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8, ltype=cv2.CV_16U)
    if n <= 2:
        return fg
    area = stats[1:, cv2.CC_STAT_AREA]
    keep = np.zeros(n, np.uint8)
    keep[1:] = area >= share * area.max()
    if keep.all() or n > 256:
        return keep[lab]
    return cv2.LUT(lab.astype(np.uint8), np.pad(keep, (0, 256 - n)))


def body_axis_angle(fg: np.ndarray, *, max_turn_rad: float = MAX_TURN_RAD) -> float:
    """Angle (rad, positive = leaning to the image's right, as :func:`~.landmarks.upright_angle`) of the
    foreground's longer principal axis (second moments) from image up; 0 when it lies farther than
    ``max_turn_rad`` from vertical or the foreground is empty."""
    M = cv2.moments(fg, binaryImage=True)
    if M["m00"] <= 0:
        return 0.0
    theta = 0.5 * np.arctan2(2.0 * M["mu11"], M["mu20"] - M["mu02"])      # longer axis, from image +u
    du, dv = np.cos(theta), np.sin(theta)
    if dv > 0:                                                               # the end pointing up
        du, dv = -du, -dv
    angle = float(np.arctan2(du, -dv))
    return angle if abs(angle) <= max_turn_rad else 0.0


#: fewest foreground pixels a crop square is made of (:func:`crop_box`'s default)
MIN_CROP_PIXELS = 20


def crop_box(mask: Any, *, crop: str = "mask", box_scale: float = 1.25,
             min_pixels: int = MIN_CROP_PIXELS) -> np.ndarray | None:
    """The detector's region ``(cu, cv, side, angle_rad)`` for a view's ``mask`` (:data:`CROPS`), or None when the
    mask has fewer than ``min_pixels`` foreground pixels."""
    if crop not in CROPS:
        raise VisionError(f"crop: expected one of {', '.join(CROPS)}, received {crop!r}")
    m = np.asarray(mask)
    if m.ndim == 3:
        m = m[..., 0]
    fg = (m > 0).view(np.uint8)
    if crop == "mask" or cv2.countNonZero(fg) < min_pixels:
        return box_from_mask(m, scale=box_scale, min_pixels=min_pixels)
    x, y, fg = _person_in_rectangle(fg)
    if crop == "person":
        return _person_box(x, y, fg, box_scale=box_scale, min_pixels=min_pixels)
    angle = body_axis_angle(_whole(m.shape, x, y, fg))  # moments over the whole image (the rectangle: other last bits)
    # a linear function's extremes over the pixels lie on their outer boundary: the turned box of the contours'
    # points (segment ends) is the box of every pixel
    contours, _ = cv2.findContours(fg, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    pts = np.concatenate([c.reshape(-1, 2) for c in contours]).astype(np.float64) + np.array([x, y], np.float64)
    return box_from_points(pts, scale=box_scale, angle_rad=angle)


def _person_in_rectangle(fg: np.ndarray) -> tuple[int, int, np.ndarray]:
    """:func:`person_pixels` of ``fg`` ((H, W) uint8 0/1) on its foreground's bounding rectangle only (the same
    components: none reaches outside it), as the rectangle's corner ``x, y`` and its (h, w) uint8 0/1 image."""
    x, y, w, h = cv2.boundingRect(fg)
    return x, y, person_pixels(fg[y:y + h, x:x + w])


def _person_box(x: int, y: int, fg: np.ndarray, *, box_scale: float, min_pixels: int) -> np.ndarray | None:
    """:func:`crop_box`'s ``"person"`` square for :func:`_person_in_rectangle`'s ``x, y, fg``."""
    box = box_from_mask(fg, scale=box_scale, min_pixels=min_pixels)
    return None if box is None else box + np.array([x, y, 0.0, 0.0])


def _whole(shape: tuple[int, ...], x: int, y: int, fg: np.ndarray) -> np.ndarray:
    """:func:`_person_in_rectangle`'s ``fg`` placed at ``x, y`` in a zero image of ``shape[:2]``: :func:`person_pixels`
    of the whole mask."""
    whole = np.zeros(shape[:2], np.uint8)
    whole[y:y + fg.shape[0], x:x + fg.shape[1]] = fg
    return whole


def segmentation_iou(probability: np.ndarray, person: np.ndarray) -> float:
    """Intersection over union of ``probability > 0.5`` ((H, W), the model's person segmentation) with the
    foreground of ``person`` ((H, W), nonzero = foreground); 0 when both are empty."""
    seg = np.asarray(probability) > 0.5
    fg = np.asarray(person) > 0
    union = int(np.count_nonzero(seg | fg))
    return int(np.count_nonzero(seg & fg)) / union if union else 0.0


def detect_in_mask(detector: PoseLandmarker, image: Any, mask: Any, *, box_scale: float = 1.25,
                   min_score: float = 0.5, bgr: bool = False, crop: str | None = None) -> Landmarks2D | None:
    """The landmarks of the person in the square around ``mask``'s foreground (``crop``: :data:`DETECT_CROPS`,
    default :data:`CROP`), or None (empty mask, or a pose score below ``min_score``: nobody there).

    ``"person_checked"``: where the ``"person"`` square is the ``"mask"`` one (the mask is the person), one
    detection, the ``"mask"`` crop's; elsewhere the detection in the ``"person"`` square is accepted when it
    finds a person (score >= ``min_score``) and the model's person segmentation of the square agrees with the
    mask's person components (:func:`segmentation_iou` >= :data:`AGREE_IOU`; the segmentation alone also covers
    a plain grey block where nobody is), and then detected again in the square around its 33 landmarks turned
    so that its hips-to-shoulders direction points up (:func:`~.landmarks.upright_angle`); not accepted, the
    ``"mask"`` square is detected on (a model without the segmentation output: always).

    Raises
    ------
    VisionError
        ``mask`` is not of ``image``'s size, the image is not (H, W, 3) uint8, or ``crop`` is unknown.
    """
    img = np.asarray(image)
    m = np.asarray(mask)
    if m.ndim == 3:
        m = m[..., 0]
    if m.shape[:2] != img.shape[:2]:
        raise VisionError(f"mask: expected the image's size {img.shape[1]}x{img.shape[0]}, received "
                          f"{m.shape[1] if m.ndim > 1 else '?'}x{m.shape[0]}")
    crop = CROP if crop is None else crop
    if crop not in DETECT_CROPS:
        raise VisionError(f"crop: expected one of {', '.join(DETECT_CROPS)}, received {crop!r}")
    if crop != "person_checked":
        box = crop_box(m, crop=crop, box_scale=box_scale)
        lm = None if box is None else detector.detect(img, box, bgr=bgr)
    else:
        box = crop_box(m, crop="mask", box_scale=box_scale)
        lm = None if box is None else _detect_checked(detector, img, m, box, box_scale=box_scale, bgr=bgr,
                                                      min_score=min_score)
    return lm if lm is not None and lm.score >= min_score else None


def _detect_checked(detector: PoseLandmarker, img: np.ndarray, m: np.ndarray, box_mask: np.ndarray, *,
                    box_scale: float, bgr: bool, min_score: float) -> Landmarks2D:
    """``"person_checked"``'s detection (:func:`detect_in_mask`) for a mask with a ``"mask"`` square."""
    x, y, person = _person_in_rectangle((m > 0).view(np.uint8))    # once: for the square and the agreement
    box = _person_box(x, y, person, box_scale=box_scale, min_pixels=MIN_CROP_PIXELS)
    if box is None or np.array_equal(box, box_mask) or not detector.has_segmentation:
        return detector.detect(img, box_mask, bgr=bgr)
    probability, lm = detector.person_probability(img, box, bgr=bgr)
    if lm.score < min_score or segmentation_iou(probability, _whole(m.shape, x, y, person)) < AGREE_IOU:
        return detector.detect(img, box_mask, bgr=bgr)
    uv = lm.uv
    turn = upright_angle(0.5 * (uv[_HIPS[0]] + uv[_HIPS[1]]), 0.5 * (uv[_SHOULDERS[0]] + uv[_SHOULDERS[1]]))
    return detector.detect(img, box_from_points(uv, scale=box_scale, angle_rad=turn), bgr=bgr)


_HIPS = (LANDMARK_NAMES.index("left_hip"), LANDMARK_NAMES.index("right_hip"))
_SHOULDERS = (LANDMARK_NAMES.index("left_shoulder"), LANDMARK_NAMES.index("right_shoulder"))
