"""The frame's masks: checks (each unusable view skipped with a note), the mask gate and the visual-hull
filter around the prediction (before the first estimate: the largest blob of the visual hull), and handing the usable masks (with view weights) to the energy.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from . import frame_prediction
from .gate import gate_masks, predicted_silhouettes
from .hull import hull_filter, pose_box
from .init_hull import person_masks
from .config import GATE_NOTE_SHARE, frame_rng


def check_masks(tr, masks) -> tuple[list, list[str]]:
    """Per view a usable mask or None, and notes on what was skipped."""
    V = len(tr.cameras)
    notes: list[str] = []
    if masks is None:
        return [None] * V, ["masks: none given"]
    try:
        masks = list(masks)
    except TypeError:
        return [None] * V, [f"masks: expected a sequence of {V} masks, received {type(masks).__name__}"]
    if len(masks) != V:
        notes.append(f"masks: expected {V} views, received {len(masks)}"
                     + ("; missing views skipped" if len(masks) < V else "; extra views ignored"))
        masks = (masks + [None] * V)[:V]
    out: list = []
    for v, (cam, m) in enumerate(zip(tr.cameras, masks)):
        if m is None:
            notes.append(f"view {v}: no mask; skipped")
            out.append(None)
            continue
        try:
            a = np.asarray(m)
        except Exception as exc:  # noqa: BLE001 - anything unreadable is skipped, with its reason
            notes.append(f"view {v}: unreadable mask ({type(exc).__name__}); skipped")
            out.append(None)
            continue
        if a.ndim != 2 or a.shape != (cam.height, cam.width):
            notes.append(f"view {v}: mask shape {a.shape}, expected ({cam.height}, {cam.width}); skipped")
            out.append(None)
            continue
        if a.dtype != np.uint8:
            if not np.issubdtype(a.dtype, np.number) and a.dtype != bool:
                notes.append(f"view {v}: mask dtype {a.dtype}, expected numbers; skipped")
                out.append(None)
                continue
            a = np.where(np.nan_to_num(a.astype(float)) > 0, 255, 0).astype(np.uint8)
        if not a.any():
            notes.append(f"view {v}: empty mask (nobody in view); skipped")
            out.append(None)
            continue
        out.append(a)
    return out, notes


def set_masks(tr, ctx) -> int:
    """Give the frame's usable masks ``ctx.masks`` to the energy (with the view weights ``ctx.weights``, if
    any, and if the energy takes them; the energy samples its foreground pixels from the frame's stream 2);
    returns the number of views it uses (0: none)."""
    masks, notes, frame_index, weights = ctx.masks, ctx.notes, ctx.frame_index, ctx.weights
    if not any(m is not None for m in masks):
        return 0
    if frame_index is not None and isinstance(getattr(tr.energy, "rng", None), np.random.Generator):
        # the energy samples foreground pixels at set_masks: draw them from this frame's stream
        tr.energy.rng = frame_rng(tr.config.search.seed, frame_index, 2)
    from isa_mocap_ros.energy.silhouette import SilhouetteEnergy, mask_problem

    try:
        if weights is not None and isinstance(tr.energy, SilhouetteEnergy):
            if not any(w > 0 and mask_problem(m, c) is None for w, m, c in zip(weights, masks, tr.cameras)):
                weights = None             # no usable view sees the predicted body: count them alike
            tr.energy.set_masks(masks, weights)
        else:
            tr.energy.set_masks(masks)
    except ValueError as exc:          # EnergyError and friends: nothing usable after all
        notes.append(f"energy: masks rejected ({exc})")
        return 0
    for s in getattr(tr.energy, "skipped_views", None) or ():
        notes.append(f"energy skipped view {s[0]}: {s[1]}" if isinstance(s, tuple) and len(s) == 2
                     else f"energy skipped view {s}")
    used = getattr(tr.energy, "n_views_used", None)
    return int(used) if used is not None else sum(m is not None for m in masks)


def filter_masks(tr, ctx) -> None:
    """``ctx.masks``: the frame's checked masks ``ctx.raw_masks`` after the mask gate
    (``config.masks.gate_margin_px``: foreground far from the predicted silhouette dropped) and the visual-hull
    filter (``config.masks.hull_filter``: foreground the other views do not confirm), both around the frame's
    prediction (made here when they run: ``ctx.prediction``; not when neither runs: off, no estimate yet or
    no usable view). ``tr.track.masks_now`` becomes ``ctx.masks``: the contour stage fits what the energy
    scores, and a later re-centring starts from the person's foreground (the prediction itself re-centres on
    the unfiltered ones)."""
    cfg = tr.config
    usable = ctx.raw_masks
    ctx.masks = tr.track.masks_now = usable
    if cfg.masks.hull_filter and cfg.masks.first_frame_hull and tr.track.last is None \
            and sum(m is not None for m in usable) >= 2:
        # no estimate yet: the person is the largest blob of the visual hull (.init_hull)
        usable, note = person_masks(usable, tr.cameras)
        if note:
            ctx.notes.append(note)
        usable = [None if m is not None and not np.any(m) else m for m in usable]     # a view left empty: skipped
        ctx.masks = tr.track.masks_now = usable
        return
    if not (cfg.masks.gate_margin_px > 0 or cfg.masks.hull_filter) or tr.track.last is None \
            or not any(m is not None for m in usable):
        return
    pred = frame_prediction.prediction(tr, ctx)
    joints = frame_prediction.prediction_joints(tr, ctx)
    if cfg.masks.gate_margin_px > 0:
        usable = gate(tr, usable, pred, ctx.notes, joints)
    if cfg.masks.hull_filter:
        usable = hull(tr, usable, pred, ctx.notes, joints)
    ctx.masks = tr.track.masks_now = usable


def gate(tr, usable: list, pred: np.ndarray, notes: list[str], joints=None) -> list:
    """The usable masks gated around ``pred`` (:func:`.gate.gate_masks`; ``joints``: its joint positions if known);
    views left empty become None."""
    g = gate_masks(usable, tr.cameras, tr.model, pred, tr.config.masks.gate_margin_px, joints=joints)
    return _noted(g, notes, "the gate", lambda total: f"all {total} foreground pixels farther than "
                  f"{tr.config.masks.gate_margin_px} px from the predicted silhouette")


def hull(tr, usable: list, pred: np.ndarray, notes: list[str], joints=None) -> list:
    """The usable masks through the visual-hull filter (:func:`.hull.hull_filter`) in the box of
    ``pred`` (``joints``: its joint positions if known), keeping ``pred``'s silhouette grown by ``hull_keep_px``;
    views left empty become None."""
    cfg = tr.config
    if sum(m is not None for m in usable) < 2:
        return usable
    idx = [v for v, m in enumerate(usable) if m is not None]
    keep: list = [None] * len(usable)
    for v, s in zip(idx, predicted_silhouettes(tr.model, [tr.cameras[v] for v in idx], pred,
                                               margin_px=cfg.masks.hull_keep_px, joints=joints)):
        keep[v] = s
    g = hull_filter(usable, tr.cameras, pose_box(tr.model, pred, cfg.masks.hull_pad_m, joints=joints),
                    dilate_px=cfg.masks.hull_dilate_px, keep=keep)
    return _noted(g, notes, "the hull filter", lambda total: "no foreground pixel confirmed by the other views")


def _noted(g, notes: list[str], what: str, why_empty: Callable[[int], str]) -> list:
    """The masks of a mask filter's :class:`.gate.GateResult` ``g`` for the energy: a view it emptied
    becomes None (note: ``why_empty(total)``), one it cut by more than :data:`GATE_NOTE_SHARE` gets a note.
    (The views given to the filters are never empty: :func:`check_masks` skips empty ones.)"""
    out = []
    for v, (m, lost, total) in enumerate(zip(g.masks, g.lost_px, g.total_px)):
        if m is not None and lost >= total:
            notes.append(f"view {v}: empty mask after {what} ({why_empty(total)}); skipped")
            m = None
        elif m is not None and lost > GATE_NOTE_SHARE * total:
            notes.append(f"view {v}: {what} removed {lost} of {total} foreground pixels ({100 * lost / total:.0f} %)")
        out.append(m)
    return out
