"""Gate the foreground masks by the predicted silhouette (pure numpy/OpenCV, no ROS).

Occluding objects the segmentation reports as foreground (ISA §13.4.2's 35 random rectangles, a
chair, a second person) enter the silhouette energy's second term (EA-vs-PF Eq. 4-5: foreground
pixels the model misses) and drag the model towards them. :func:`gate_masks` keeps only the
foreground that can belong to the person: the 8-connected foreground components that touch the
predicted model silhouette dilated by ``margin_px`` pixels. A touching component is kept **whole**
(a limb that moved further than the margin from the prediction stays whole as long as it is
connected to the body), a component entirely outside the dilated silhouette is dropped.

Why components, not pixels (``rule="pixels"``: foreground ∩ grown silhouette): a clean person is one
component, so clean tracking is unchanged bit for bit, where the pixel rule trims whatever part of a
limb the prediction did not reach; with occluders the component rule tracked the walks better (the
figures: ``docs/decisions/003-mask-gate-and-hull.md``). The price: an occluder touching the person's
grown silhouette stays, whole.

The grown silhouette is drawn from the projected capsules with the margin added to their pixel
radii (:func:`predicted_silhouettes`: cheaper than rendering the exact silhouette with
:func:`isa_mocap_ros.vision.render_mask` and dilating it).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numba
import numpy as np

from isa_mocap_ros.body.kinematics import joint_positions
from isa_mocap_ros.vision.outline import camera_arrays, fill_capsules

__all__ = ["GateError", "GateResult", "gate_masks", "predicted_silhouettes", "visible_shares", "pose_joints", "RULES"]

RULES = ("components", "pixels")


class GateError(ValueError):
    """Bad argument of the gate (names it, the expected and the received value)."""


@dataclass(frozen=True, eq=False)
class GateResult:
    """What :func:`gate_masks` produced.

    Attributes
    ----------
    masks : list of (H, W) uint8 ndarray or None
        The gated masks (255 = foreground), None where the input was None.
    lost_px : (V,) int ndarray
        Foreground pixels each view lost (0 for a None view).
    total_px : (V,) int ndarray
        Foreground pixels of each input mask.
    """

    masks: list
    lost_px: np.ndarray
    total_px: np.ndarray

    @property
    def lost_share(self) -> np.ndarray:
        """Share of each view's foreground the gate removed (0 for an empty or None view)."""
        return np.where(self.total_px > 0, self.lost_px / np.maximum(self.total_px, 1), 0.0)


def pose_joints(model, pose) -> np.ndarray:
    """Joint positions ``(J, 3)`` of ``model`` at ``pose`` clipped into its limits: what the gate, the hull filter
    (its box and kept silhouette) and the view weights draw from. The tracker computes them once per frame for the
    frame's prediction (:func:`.frame_prediction.prediction_joints`) and passes them as ``joints=``."""
    x = np.clip(np.asarray(pose, dtype=float), model.lower, model.upper)
    return joint_positions(model, x[None])[0]


@numba.njit(cache=True)
def _touching(labels, sil, n):  # pragma: no cover - compiled
    """``(n,)`` bool: the components of ``labels`` (``cv2.connectedComponents``' ``n`` labels, 0 off the
    foreground, which is no component) with a pixel where ``sil`` (the same shape) is nonzero."""
    out = np.zeros(n, np.bool_)
    for j in range(labels.shape[0]):
        for i in range(labels.shape[1]):
            if sil[j, i] != 0:
                out[labels[j, i]] = True
    out[0] = False
    return out


def _disc(margin_px: int) -> np.ndarray:
    import cv2

    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin_px + 1, 2 * margin_px + 1))


def predicted_silhouettes(model, cameras: Sequence, pose, *, margin_px: int = 0,
                          exact: bool = False, joints=None) -> list[np.ndarray]:
    """The model's silhouette at ``pose`` in each camera, ``(H, W)`` uint8 (255 inside), grown by
    ``margin_px`` pixels (``joints``: :func:`pose_joints` of ``pose`` if known).

    ``exact=False`` (the gate's): each capsule filled as the hull of its projected end discs (radius
    ``f r / z + margin``) by scanlines (:func:`isa_mocap_ros.vision.outline.fill_capsules`, one compiled call
    per view; the scanline energy's approximation of the capsule's outline: at margin 0 it lies inside the exact
    silhouette and misses 0.2 % of it, 158 of 71,381 pixels on 10 random poses × 4 views of the default rig).
    ``exact=True``:
    :func:`isa_mocap_ros.vision.render_mask` (the energy's exact silhouette, 1-1.5 ms per view)
    dilated by a disc of radius ``margin_px``.
    """
    import cv2

    E = (pose_joints(model, pose) if joints is None else joints)[np.asarray(model.capsules)]     # (C, 2, 3)
    radii = np.ascontiguousarray(model.capsule_radii, dtype=float)   # (C, 2)
    out = []
    if exact:
        from isa_mocap_ros.vision import render_mask

        for cam in cameras:
            m = render_mask(cam, E, radii)
            out.append(cv2.dilate(m, _disc(margin_px)) if margin_px > 0 else m)
        return out
    E = np.ascontiguousarray(E)
    for cam in cameras:
        img = np.zeros((cam.height, cam.width), np.uint8)
        fill_capsules(E, radii, *camera_arrays(cam), float(margin_px), img, np.uint8(255))
        out.append(img)
    return out


def visible_shares(model, cameras: Sequence, pose, *, scale: float = 0.25, joints=None) -> np.ndarray:
    """``(V,)`` share of the model's silhouette at ``pose`` that falls inside each camera's image,
    in [0, 1] (0 when the model projects nowhere, e.g. behind the camera; ``joints``: :func:`pose_joints` of
    ``pose`` if known).

    The silhouette of :func:`predicted_silhouettes` is drawn at ``scale`` of the image's size on a
    canvas three times as wide and high, the image in its middle; the share is the drawn area
    inside the image over all drawn area. A silhouette reaching beyond the canvas (a person more
    than one image width off-image) counts only its part on the canvas. ≈ 0.07 CPU ms per view at
    320×240 (``bench speed``'s profile, a loaded 2-core machine); the canvases' cameras are made once per camera.
    """
    bigs = [_share_canvas(cam, scale) for cam in cameras]
    out = np.zeros(len(cameras))
    for v, img in enumerate(predicted_silhouettes(model, bigs, pose, joints=joints)):
        total = np.count_nonzero(img)
        if total:
            w, h = img.shape[1] // 3, img.shape[0] // 3
            out[v] = np.count_nonzero(img[h:2 * h, w:2 * w]) / total
    return out


_CANVASES: dict = {}


def _share_canvas(cam, scale: float):
    """``cam`` at ``scale`` on a canvas three times as wide and high, the image in its middle (cached
    per camera and scale: the calibration's, made once)."""
    key = (cam.key(), float(scale))
    big = _CANVASES.get(key)
    if big is None:
        s = cam.scaled(scale)
        w, h = s.width, s.height
        K = s.K.copy()
        K[0, 2] += w
        K[1, 2] += h
        big = type(cam)(cam.name, 3 * w, 3 * h, K, cam.dist, cam.R, cam.t)
        if len(_CANVASES) >= 64:
            _CANVASES.clear()
        _CANVASES[key] = big
    return big


def view_masks(masks: Sequence, cameras: Sequence, name: str = "masks", *, uint8: bool = False) -> list:
    """Each view's mask as a contiguous bool array (None stays None), its shape checked against its
    camera (GateError naming ``name[v]``). ``uint8``: as a C-contiguous writable uint8 array instead, nonzero =
    foreground: a uint8 mask as it is (no copy; 0/255 and 0/1 read alike), anything else the bool array viewed
    as uint8."""
    out = []
    for v, (cam, m) in enumerate(zip(cameras, masks)):
        if m is None:
            out.append(None)
            continue
        a = np.asarray(m)
        if a.shape != (cam.height, cam.width):
            raise GateError(f"{name}[{v}]: expected shape ({cam.height}, {cam.width}), received {a.shape}")
        if uint8 and a.dtype == np.uint8 and a.flags.c_contiguous and a.flags.writeable:
            out.append(a)
            continue
        b = np.ascontiguousarray(a > 0 if a.dtype != bool else a)
        out.append(b.view(np.uint8) if uint8 else b)
    return out


def gate_masks(masks: Sequence, cameras: Sequence, model, pose, margin_px: int, *,
               rule: str = "components", joints=None) -> GateResult:
    """Keep the foreground near the model's silhouette at ``pose`` (see the module docstring).

    Parameters
    ----------
    masks : sequence of (H, W) array_like or None
        One per camera, nonzero = foreground; None views pass through.
    cameras : sequence of Camera
    model : BodyModel
    pose : (D,) array_like
        The predicted pose (clipped into the model's limits).
    margin_px : int
        Dilation radius of the predicted silhouette, pixels; 0 = off (the masks come back as they are,
        as uint8 0/255).
    rule : {"components", "pixels"}
        ``"components"``: keep every 8-connected foreground component touching the dilated
        silhouette, whole; ``"pixels"``: keep the foreground inside the dilated silhouette.
    joints : (J, 3) ndarray, optional
        :func:`pose_joints` of ``pose`` if known.

    Returns
    -------
    GateResult

    Raises
    ------
    GateError
        A bad margin, rule, number of masks, mask shape or pose.
    """
    import cv2

    if isinstance(margin_px, bool) or not isinstance(margin_px, (int, np.integer)) or margin_px < 0:
        raise GateError(f"margin_px: expected an integer >= 0, received {margin_px!r}")
    if rule not in RULES:
        raise GateError(f"rule: expected one of {', '.join(RULES)}, received {rule!r}")
    masks, cameras = list(masks), list(cameras)
    if len(masks) != len(cameras):
        raise GateError(f"masks: expected {len(cameras)} (one per camera), received {len(masks)}")
    x = np.asarray(pose, dtype=float)
    if x.shape != (model.dof,) or not np.all(np.isfinite(x)):
        raise GateError(f"pose: expected a finite ({model.dof},) vector, received shape {x.shape}"
                        + ("" if x.shape != (model.dof,) else " with non-finite values"))
    fg = view_masks(masks, cameras)                 # viewed as uint8 0/1 below
    V = len(masks)
    total = np.array([0 if f is None else int(np.count_nonzero(f)) for f in fg], dtype=np.int64)
    if margin_px == 0 or not any(f is not None and t > 0 for f, t in zip(fg, total)):
        return GateResult([None if f is None else f.astype(np.uint8) * np.uint8(255) for f in fg],
                          np.zeros(V, np.int64), total)
    sil = predicted_silhouettes(model, [c for c, f in zip(cameras, fg) if f is not None], x, margin_px=int(margin_px),
                                joints=joints)
    out, lost, j = [], np.zeros(V, np.int64), 0
    for v, f in enumerate(fg):
        if f is None:
            out.append(None)
            continue
        s = sil[j]
        j += 1
        if rule == "pixels":
            kept = (f & (s > 0)).view(np.uint8) * np.uint8(255)
        else:
            # within the foreground's bounding box (it holds every component whole, so each is
            # kept or dropped as on the full image; the person is ~2 % of a 320x240 view)
            kept = np.zeros(f.shape, np.uint8)
            if total[v]:
                c0, r0, w, h = cv2.boundingRect(f.view(np.uint8))
                box = (slice(r0, r0 + h), slice(c0, c0 + w))
                fb = f[box]
                n, labels = cv2.connectedComponents(fb.view(np.uint8), connectivity=8)
                touching = _touching(labels, s[box], n)     # the components the grown silhouette meets
                if touching[1:].all():                  # every component kept (a clean person): f, nothing lost
                    kept[box] = fb.view(np.uint8) * np.uint8(255)
                    out.append(kept)
                    continue
                kept[box] = np.where(touching, np.uint8(255), np.uint8(0))[labels]
        out.append(kept)
        lost[v] = total[v] - int(np.count_nonzero(kept))
    return GateResult(out, lost, total)
