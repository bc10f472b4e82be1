"""Model-guided refinement of a foreground mask: a graph cut seeded by the projected body model.

ISA §13.3.2 (eq. 13.29) segments each view with a level set whose energy adds a shape prior: the
silhouette of the body model at the predicted (or previous) pose, so the segmentation keeps what
looks like the person where the model says the person is, even where its colour is close to the
background's. This module does the equivalent with a graph cut (OpenCV's GrabCut: colour models of
foreground and background as Gaussian mixtures, a contrast-sensitive smoothness term, solved by
max-flow) whose labels are seeded by the model's silhouette and the background-subtraction mask:

* outside the model's silhouette dilated by ``margin`` (a fraction of the silhouette's height):
  sure background for the cut's colour models; the mask there is left as it is (``drop_far``
  removes it instead);
* inside the silhouette eroded by ``core`` (same unit): probably foreground, sure foreground
  where the background subtraction agrees;
* the band between: what the background subtraction says, as "probably"; the foreground the
  background subtraction found within the band is kept (``keep``), the cut adds to it.

The cut then decides the uncertain pixels from colour and contrast: the dark shorts over the dark
treadmill of the Pose2Sim demo come back where the model's legs are. The model is only a prior: a wrong pose
gives a mask biased towards it, which is why the refinement is an option of the tracker's input
(``isa-mocap track --refine-masks``), measured with and without (docs/real_cameras.md).

Pure OpenCV/numpy; works on a crop around the dilated silhouette (the cost grows with its area).
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["RefineError", "refine_mask"]


class RefineError(ValueError):
    """Bad input to :func:`refine_mask` (names the argument and what was expected)."""


def _disk(r: int) -> np.ndarray:
    r = max(1, int(r))
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def refine_mask(image: np.ndarray, mask: np.ndarray, prior: np.ndarray, *, margin: float = 0.12,
                core: float = 0.02, iterations: int = 2, max_side: int = 200, keep: bool = True,
                drop_far: bool = False) -> np.ndarray:
    """Refine ``mask`` with a graph cut seeded by the model silhouette ``prior``.

    Parameters
    ----------
    image : (H, W, 3) uint8 ndarray
        The view's colour image (RGB or BGR alike: the colour models are learnt from it).
    mask : (H, W) ndarray
        Background-subtraction foreground (nonzero = foreground).
    prior : (H, W) ndarray
        The body model's silhouette in this view (nonzero = inside), e.g.
        :func:`isa_mocap_ros.vision.render.render_mask` of the previous estimate.
    margin, core : float
        Dilation of the silhouette beyond which is sure background, and erosion of it within which
        is foreground, both as fractions of the silhouette's bounding-box height.
    iterations : int
        GrabCut iterations (colour model re-estimation and cut).
    max_side : int
        The cut runs on the crop scaled down to at most this many pixels on its longer side (the
        result is scaled back up): the cost then no longer grows with the image size.
    keep : bool
        Keep every foreground pixel of ``mask`` inside the dilated silhouette, so the cut only adds
        what the background subtraction missed there (default; on the Pose2Sim demo's first 12
        frames it covered 0.88 of the reference keypoints against 0.74 when the cut decides those
        pixels too, which cuts off limbs the previous estimate has not followed yet).
    drop_far : bool
        Also remove the foreground beyond the dilated silhouette. Off by default: on the demo a limb
        the previous estimate had lost was then removed from every later mask, and the track never
        came back to it (the tracker's own mask gate and visual-hull filter remove far foreground
        without that feedback).

    Returns
    -------
    (H, W) uint8 ndarray
        0/255 mask; ``mask`` unchanged (as 0/255) when the prior is empty (the model is out of view).
    """
    img = np.asarray(image)
    m = np.asarray(mask)
    p = np.asarray(prior)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise RefineError(f"image: expected an (H, W, 3) uint8 array, received {img.dtype} of shape {img.shape}")
    if m.shape != img.shape[:2] or p.shape != img.shape[:2]:
        raise RefineError(f"mask, prior: expected the image's size {img.shape[:2]}, received {m.shape} and {p.shape}")
    if not (0.0 < margin < 1.0) or not (0.0 <= core < 1.0) or int(iterations) < 1:
        raise RefineError(f"margin, core, iterations: expected 0 < margin < 1, 0 <= core < 1, iterations >= 1, "
                          f"received {margin}, {core}, {iterations}")
    fg = m > 0
    inside = p > 0
    if not inside.any():
        return np.where(fg, 255, 0).astype(np.uint8)
    ys, xs = np.nonzero(inside)
    height = float(ys.max() - ys.min() + 1)
    r_out = int(np.ceil(margin * height))
    r_in = int(round(core * height))
    H, W = fg.shape
    y0, y1 = max(0, ys.min() - r_out - 2), min(H, ys.max() + r_out + 3)
    x0, x1 = max(0, xs.min() - r_out - 2), min(W, xs.max() + r_out + 3)
    ins = inside[y0:y1, x0:x1].astype(np.uint8)
    f = fg[y0:y1, x0:x1]
    near = cv2.dilate(ins, _disk(r_out)) > 0
    kern = cv2.erode(ins, _disk(r_in)) > 0 if r_in > 0 else ins > 0
    lab = np.full(ins.shape, cv2.GC_BGD, np.uint8)
    lab[near & f] = cv2.GC_PR_FGD
    lab[near & ~f] = cv2.GC_PR_BGD
    lab[kern] = cv2.GC_PR_FGD
    lab[kern & f] = cv2.GC_FGD
    out = np.where(fg, 255, 0).astype(np.uint8)
    if drop_far:
        out[y0:y1, x0:x1][~near] = 0        # far from the model: not the person
    has_fg = np.any((lab == cv2.GC_FGD) | (lab == cv2.GC_PR_FGD))
    has_bg = np.any((lab == cv2.GC_BGD) | (lab == cv2.GC_PR_BGD))
    if not (has_fg and has_bg):              # GrabCut needs samples of both colour models
        return out
    crop = np.ascontiguousarray(img[y0:y1, x0:x1])
    h, w = lab.shape
    s = min(1.0, float(max_side) / max(h, w))
    if s < 1.0:                              # nearest for the labels, area averaging for the colours
        size = (max(2, int(round(w * s))), max(2, int(round(h * s))))
        crop = cv2.resize(crop, size, interpolation=cv2.INTER_AREA)
        lab = cv2.resize(lab, size, interpolation=cv2.INTER_NEAREST)
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(0)                        # GrabCut's k-means initialisation: deterministic
    cv2.grabCut(crop, lab, None, bgd, fgd, int(iterations), cv2.GC_INIT_WITH_MASK)
    cut = ((lab == cv2.GC_FGD) | (lab == cv2.GC_PR_FGD)).astype(np.uint8)
    if s < 1.0:
        cut = cv2.resize(cut * 255, (w, h), interpolation=cv2.INTER_LINEAR) >= 128
    else:
        cut = cut > 0
    cut &= near
    if keep:
        cut |= near & f
    if drop_far:
        out[:] = 0
    win = out[y0:y1, x0:x1]
    win[near] = 0                            # inside the dilated silhouette the cut decides
    win[cut] = 255
    return out
