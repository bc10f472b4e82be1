"""A background model for a recording without empty frames (pure numpy / OpenCV / numba).

Source: issue 34 item 4; the per-pixel colour model of EA-vs-PF §3.2 needs background samples, and
a real recording may never show the scene without the person. :func:`estimate_background` finds,
per pixel, the frames in which the background is visible:

1. **Temporal mode.** The sample (of at most ``max_samples`` frames spread over the recording)
   that agrees with the most others (every channel within ``radius``) and the mean of those that
   agree with it (the robust estimate of :mod:`.segmentation`); ``support`` = the share of frames
   agreeing. Where the person moves on, the background wins the vote.
2. **Person region.** Pixels where the mode's support is below ``active_support`` changed during
   the recording; the largest connected region of them (dilated by ``margin`` of the image width),
   joined by the still parts where a background image (step 3) differs from the mode and that touch
   it, holes filled by the convex hull, is where the person is. A plain temporal mode or median keeps a
   body part that barely moves (the torso and standing leg of the Pose2Sim demo) as background.
3. **Background images** (``plates``: the empty scene, e.g. calibration scene shots, possibly with
   other people or drawings in them). Their colours are matched to the video's (per-channel gain
   and offset fitted where the plate agrees with the mode outside the person region). Inside the
   person region a pixel takes the mean of the frames agreeing with the plate when at least
   ``min_plate_agree`` of them do (the person left it sometimes); else, where nothing changed
   (support >= ``active_support``: the person covered it in every frame), the plate itself; where
   something changed, the temporal mode (the background seen while the person was elsewhere: a plate
   disagreeing there shows something else, e.g. an operator or drawings). Outside the region, the
   temporal mode.

Without plates, a pixel the person covers in every frame cannot be learnt and stays in the
background; :attr:`BackgroundEstimate.source` says which rule decided each pixel.

**With the person found in each frame** (``person``: e.g. :func:`.person_masks.find_person`, a learned
segmentation) the rules above are replaced by one: per pixel the temporal mode of the frames where the
person is not (grown by ``person_grow`` of the width); where fewer than ``min_free`` frames show the pixel,
the first plate that shows no person there (``plate_people``), colour-matched; else the surroundings
inpainted (OpenCV Telea). Scene shots with other people in them then matter only where the recording's
person never moves away, and only where those people stand.

:meth:`BackgroundEstimate.frames` turns the estimate into ``K`` background frames for the existing
learn-from-empty-frames segmentation: per pixel, frames in which the background is visible there,
spread over the recording, so the learnt variance is the camera's noise at that pixel; the plate value
where no frame shows it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from .errors import VisionError
from .robust_mode import _masked_mode_numba, _robust_background_numba

__all__ = ["BackgroundEstimate", "estimate_background", "SOURCE_PLATE_FRAMES", "SOURCE_MODE", "SOURCE_PLATE",
           "SOURCE_INPAINTED"]

#: :attr:`BackgroundEstimate.source` codes
SOURCE_PLATE_FRAMES, SOURCE_MODE, SOURCE_PLATE, SOURCE_INPAINTED = 0, 1, 2, 3


@dataclass(frozen=True, eq=False)
class BackgroundEstimate:
    """Result of :func:`estimate_background`.

    Attributes
    ----------
    image : (H, W, 3) uint8
        The background.
    visible : (N, H, W) bool
        ``visible[k, y, x]``: frame ``k`` shows the background at ``(x, y)`` (agrees with ``image``).
    source : (H, W) uint8
        Which rule decided the pixel (``SOURCE_PLATE_FRAMES``: frames agreeing with a plate,
        ``SOURCE_MODE``: temporal mode, ``SOURCE_PLATE``: the plate itself, ``SOURCE_INPAINTED``: the
        surroundings, with ``person`` only).
    person_region : (H, W) uint8
        0/255: where the person was found to move (step 2); with ``person``: every pixel it covered.
    support : (H, W) float
        Share of the sampled frames agreeing with the temporal mode (with ``person``: of the frames
        where the person is not).
    """

    image: np.ndarray
    visible: np.ndarray
    source: np.ndarray
    person_region: np.ndarray
    support: np.ndarray

    def frames(self, count: int, frames: np.ndarray) -> np.ndarray:
        """``(count, H, W, 3)`` uint8 background frames drawn per pixel from ``frames`` (the ones given
        to :func:`estimate_background`) where :attr:`visible`, cycling; :attr:`image` elsewhere."""
        n = self.visible.sum(axis=0)
        cums = np.cumsum(self.visible, axis=0)
        out = np.empty((count,) + self.image.shape, np.uint8)
        yy, xx = np.indices(n.shape)
        for k in range(count):
            want = np.where(n > 0, (k * n) // count % np.maximum(n, 1) + 1, 0)   # spread over the recording
            idx = np.argmax(self.visible & (cums == want[None]), axis=0)
            img = frames[idx, yy, xx]
            out[k] = np.where((n > 0)[..., None], img, self.image)
        return out


def _mode(frames: np.ndarray, radius: float, max_samples: int) -> tuple[np.ndarray, np.ndarray]:
    N = frames.shape[0]
    pick = np.unique(np.linspace(0, N - 1, min(N, max_samples)).round().astype(int))
    mu, _, count = _robust_background_numba(np.ascontiguousarray(frames[pick]), float(radius))
    return mu, count / len(pick)


def _agree(frames: np.ndarray, ref: np.ndarray, radius: float) -> np.ndarray:
    """(N, H, W) bool: every channel of frame k within ``radius`` of ``ref``."""
    r = ref.astype(np.int16)
    return np.stack([np.abs(f.astype(np.int16) - r).max(axis=-1) <= radius for f in frames])


def _person_region(support: np.ndarray, active_support: float, margin: float,
                   differs: np.ndarray | None = None) -> np.ndarray:
    """Convex hull of the largest dilated region of changing pixels, joined by the parts of ``differs``
    (plate != mode: a still body part) that touch it."""
    H, W = support.shape
    k3 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
    active = (support < active_support).astype(np.uint8) * 255
    active = cv2.morphologyEx(active, cv2.MORPH_OPEN, k3)
    m = max(1, int(round(margin * W)))
    grown = cv2.dilate(active, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * m + 1, 2 * m + 1)))
    n, lab, stats, _ = cv2.connectedComponentsWithStats(grown, connectivity=8)
    region = np.zeros((H, W), np.uint8)
    if n <= 1:
        return region
    big = (lab == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)
    if differs is not None:
        d = cv2.morphologyEx(differs.astype(np.uint8) * 255, cv2.MORPH_OPEN, k3)
        nd, dlab = cv2.connectedComponents(d, connectivity=8)
        touching = np.unique(dlab[(big > 0) & (dlab > 0)])
        big = (big > 0) | np.isin(dlab, touching[touching > 0])
    pts = cv2.findNonZero(big.astype(np.uint8))
    cv2.fillConvexPoly(region, cv2.convexHull(pts), 255)
    return region


def _match_colours(plate: np.ndarray, mode: np.ndarray, where: np.ndarray) -> np.ndarray:
    """``plate`` with a per-channel gain and offset fitted to ``mode`` on the pixels ``where``."""
    out = plate.astype(np.float32)
    if np.count_nonzero(where) < 100:
        return out
    for c in range(3):
        x, y = plate[..., c][where].astype(np.float64), mode[..., c][where].astype(np.float64)
        A = np.stack([x, np.ones_like(x)], axis=1)
        (g, o), *_ = np.linalg.lstsq(A, y, rcond=None)
        out[..., c] = g * out[..., c] + o
    return np.clip(out, 0, 255)


def _check_masks(name: str, masks, shape: tuple) -> np.ndarray:
    m = np.asarray(masks)
    if m.shape != shape:
        raise VisionError(f"{name}: expected shape {shape} (the frames'), received {m.shape}")
    return m.astype(bool)


def _with_person(frames: np.ndarray, person: np.ndarray, plates: Sequence[np.ndarray], plate_people,
                 radius: float, min_free: int, grow: float) -> BackgroundEstimate:
    """:func:`estimate_background` with the person given in every frame (module docstring)."""
    N, H, W, _ = frames.shape
    g = max(0, int(round(grow * W)))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * g + 1, 2 * g + 1))   # 1x1 for g = 0: no growth
    covered = np.stack([cv2.dilate(p.view(np.uint8), kernel) for p in person]).astype(bool)
    mu, count, n_free = _masked_mode_numba(np.ascontiguousarray(frames), ~covered, float(radius))
    unknown = n_free < min_free
    ever = covered.any(axis=0)
    image = mu
    source = np.full((H, W), SOURCE_MODE, np.uint8)
    for i, p in enumerate(plates):
        fill = unknown & (source == SOURCE_MODE)
        if not fill.any():
            break
        ok = ~cv2.dilate(plate_people[i].view(np.uint8), kernel).astype(bool) if plate_people is not None else \
            np.ones((H, W), bool)
        pc = _match_colours(p, mu, ~ever & (np.abs(p.astype(np.float32) - mu).max(axis=-1) <= radius))
        use = fill & ok
        image[use] = pc[use]
        source[use] = SOURCE_PLATE
    image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    rest = unknown & (source == SOURCE_MODE)
    if rest.any():
        image = cv2.inpaint(image, rest.view(np.uint8), max(3, g), cv2.INPAINT_TELEA)
        source[rest] = SOURCE_INPAINTED
    visible = _agree(frames, image, radius) & ~covered
    visible[:, source != SOURCE_MODE] = False
    return BackgroundEstimate(image, visible, source, ever.astype(np.uint8) * 255,
                              count / np.maximum(n_free, 1))


def estimate_background(frames: np.ndarray, *, plates: Sequence[np.ndarray] = (), radius: float = 20.0,
                        min_plate_agree: float = 0.1, active_support: float = 0.9, margin: float = 0.04,
                        max_samples: int = 25, person: np.ndarray | None = None,
                        plate_people: Sequence[np.ndarray] | None = None, min_free: int = 5,
                        person_grow: float = 0.015) -> BackgroundEstimate:
    """Background of one view from its frames (and optional background images), see the module docstring.

    Parameters
    ----------
    frames : (N, H, W, 3) uint8 ndarray
        The recording of one view (``N >= 3``).
    plates : sequence of (H, W, 3) uint8
        Images of the scene without the person, same size.
    radius : float
        Two colours agree when every channel differs by at most this (intensity levels).
    min_plate_agree : float
        Share of frames that must agree with a plate for their mean to be used.
    active_support : float
        A pixel whose temporal mode has less support changed during the recording.
    margin : float
        Dilation of the changing pixels, as a fraction of the image width.
    max_samples : int
        Frames used for the temporal mode (spread evenly; with ``person`` every frame given is used).
    person : (N, H, W) bool, optional
        Where the person is in each frame (e.g. :func:`.person_masks.find_person` ``> 0.5``): the
        person-masked rule of the module docstring replaces the rules above.
    plate_people : sequence of (H, W) bool, optional
        Per plate, where it shows a person (:func:`.person_masks.people_in_plates`); with ``person`` only.
    min_free : int
        With ``person``: a pixel shown by fewer frames takes a plate or the inpainted surroundings.
    person_grow : float
        With ``person``: the person grown by this fraction of the image width (its edges, shadows).
    """
    frames = np.asarray(frames)
    if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] < 3:
        raise VisionError(f"frames: expected (N >= 3, H, W, 3) uint8, received {frames.dtype} {frames.shape}")
    N, H, W, _ = frames.shape
    for i, p in enumerate(plates):
        if not isinstance(p, np.ndarray) or p.shape != (H, W, 3) or p.dtype != np.uint8:
            raise VisionError(f"plates[{i}]: expected ({H}, {W}, 3) uint8 (the frames' size), received "
                              f"{getattr(p, 'dtype', type(p).__name__)} {getattr(p, 'shape', '')}")
    if person is not None:
        pm = _check_masks("person", person, (N, H, W))
        pp = None if plate_people is None else [_check_masks(f"plate_people[{i}]", q, (H, W))
                                                 for i, q in enumerate(plate_people)]
        if pp is not None and len(pp) != len(plates):
            raise VisionError(f"plate_people: expected one mask per plate ({len(plates)}), received {len(pp)}")
        return _with_person(frames, pm, plates, pp, radius, int(min_free), float(person_grow))
    mode, support = _mode(frames, radius, max_samples)
    moving = _person_region(support, active_support, margin) > 0
    matched = []
    differs = np.zeros((H, W), bool)
    for p in plates:
        ok_out = (np.abs(p.astype(np.float32) - mode).max(axis=-1) <= radius) & ~moving
        pc = _match_colours(p, mode, ok_out)
        matched.append(pc)
        differs |= (np.abs(pc - mode).max(axis=-1) > radius) & (support >= active_support)
    region = _person_region(support, active_support, margin, differs if plates else None)
    inside = region > 0
    image = mode.copy()
    source = np.full((H, W), SOURCE_MODE, np.uint8)
    best_share = np.zeros((H, W))
    for pc in matched:
        ag = _agree(frames, pc, radius)
        share = ag.mean(axis=0)
        use_frames = inside & (share >= min_plate_agree) & (share > best_share)
        if use_frames.any():
            cnt = np.maximum(ag.sum(axis=0), 1)[..., None]
            mean = (ag[..., None] * frames.astype(np.float32)).sum(axis=0) / cnt
            image[use_frames] = mean[use_frames]
            source[use_frames] = SOURCE_PLATE_FRAMES
            best_share[use_frames] = share[use_frames]
        # the plate itself only where nothing changed (the person stood still there, or it is background
        # that the mode has right anyway); where something moved, the mode is the background seen when
        # the person was elsewhere, and a disagreeing plate is what is wrong (another person, drawings)
        use_plate = inside & (support >= active_support) & (source != SOURCE_PLATE_FRAMES) & (source != SOURCE_PLATE)
        image[use_plate] = pc[use_plate]
        source[use_plate] = SOURCE_PLATE
    image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    visible = _agree(frames, image, radius)
    visible[:, source == SOURCE_PLATE] = False
    return BackgroundEstimate(image, visible, source, region, support)
