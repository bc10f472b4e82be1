"""The frame's prediction: the external one (the prediction node's) when usable, else the tracker's
own predictor looking as many periods ahead as passed, damped towards the last estimate; after a long
gap the predicted root follows the foreground's triangulated centroid (:func:`recentre`) and the search starts
from the better of the prediction and its limbs' other side (:func:`better_side`), or after a longer one from the
better leg assignment of the limbs as last seen, each searched briefly (:func:`side_check`).
"""
from __future__ import annotations

import numpy as np

from isa_mocap_ros.geometry import nearest_rotvec

from .config import ROOT_VELOCITY_GAIN
from .gate import pose_joints
from .init import InitError, root_from_masks
from .predict import frames_kwargs


def prediction(tr, ctx) -> np.ndarray:
    """The frame's prediction ``ctx.prediction``, made by :func:`predict` at the first need (once per frame)."""
    if ctx.prediction is None:
        ctx.prediction = predict(tr, ctx)
    return ctx.prediction


def prediction_joints(tr, ctx) -> np.ndarray:
    """The joint positions ``(J, 3)`` of the frame's prediction (:func:`.gate.pose_joints`), computed once per frame
    (``ctx.prediction_joints``) for the mask gate, the hull filter (its box and kept silhouette) and the view
    weights."""
    if ctx.prediction_joints is None:
        ctx.prediction_joints = pose_joints(tr.model, prediction(tr, ctx))
    return ctx.prediction_joints


def predict(tr, ctx) -> np.ndarray:
    """The (damped) prediction of the frame ``ctx`` (:class:`~.frame_context.FrameContext`): its external
    one (e.g. the prediction node's) or the tracker's own. Both are damped the same way towards the last
    estimate (``root/joint_velocity_gain``), so the node network (prediction from the prediction node) and
    ``isa-mocap track`` (own predictor, same conversions) give identical numbers; notes go to ``ctx.notes``.
    """
    D = tr.model.dof
    external, notes = ctx.external_prediction, ctx.notes
    p = None
    if external is not None and tr.heading_check.own_prediction_frames > 0:
        notes.append("prediction: the external one follows the estimates from before the heading check's "
                     "switch; using the tracker's own")
        external = None
    if external is not None:
        try:
            p = np.asarray(external, dtype=float)
        except (TypeError, ValueError):
            p = None
        if p is None or p.shape != (D,):
            notes.append(f"prediction: expected shape ({D},), received "
                         f"{None if p is None else p.shape}; using the tracker's own")
            p = None
        elif not np.all(np.isfinite(p)):
            notes.append("prediction: non-finite values; using the tracker's own")
            p = None
    if p is None:
        try:
            ahead = min(tr.track.elapsed or 1, tr.config.prediction.max_frames_ahead)
            p = np.asarray(tr.predictor.predict(**frames_kwargs(ahead)), dtype=float)
        except ValueError as exc:      # PredictionError: empty history (cannot happen once initialized)
            notes.append(f"prediction: {exc}; using the last estimate")
            return tr.track.last.copy()
        if p.shape != (D,) or not np.all(np.isfinite(p)):
            notes.append("prediction: non-finite values; using the last estimate")
            return tr.track.last.copy()
    cfg = tr.config
    for blk in tr.model.rotation_blocks:
        # a prediction that went through a JointState (roll/pitch/yaw) has |r| <= pi: near a
        # half turn it can lie on the other side of pi from the last estimate (demo, frame 127:
        # 174° vs -179° gave -72° after damping, and the track was lost)
        idx = list(blk)
        p = p.copy() if p is external else p
        p[idx] = nearest_rotvec(p[idx], tr.track.last[idx])
    gain = np.full(D, cfg.prediction.joint_velocity_gain)
    gain[:6] = ROOT_VELOCITY_GAIN
    out = tr.track.last + gain * (p - tr.track.last)        # damped extrapolation
    if tr.track.elapsed > cfg.prediction.max_frames_ahead or (tr.track.elapsed > 1 and motion_unknown(tr)):
        ctx.after_gap = recentre(tr, out, ctx.raw_masks, notes)
    return out


def motion_unknown(tr) -> bool:
    """True when the predictor holds a single estimate (no motion to extrapolate: the frame after
    the first, e.g. in real time after the sets that came during the initialization were dropped)."""
    n = getattr(tr.predictor, "n_estimates", None)
    return n is not None and int(n) < 2


def recentre(tr, pred: np.ndarray, masks_now: list, notes: list[str]) -> bool:
    """After more frames than ``max_frames_ahead`` unseen — or after any gap when the predictor holds
    a single estimate (the first estimate's frame: no motion to extrapolate) — move the predicted
    root position (x, y) by how far the foreground moved: the triangulated mask centroid
    (:func:`.init.root_from_masks`) of this frame minus that of the last estimate's frame.
    Extrapolating the last motion over such a gap says little (in real time the automatic
    initialization alone takes 4-10 frame periods, and a person walking moves 0.2-0.5 m
    meanwhile), the foreground says where the body is. ``masks_now``: this frame's checked masks (before
    the mask filters, which work around the prediction)."""
    if tr.track.masks_last is None or masks_now is None:
        return
    try:
        c_last = root_from_masks(tr.model, tr.cameras, tr.track.masks_last)[0]
        c_now = root_from_masks(tr.model, tr.cameras, masks_now)[0]
    except InitError:
        return
    pred[:2] = tr.track.last[:2] + (c_now[:2] - c_last[:2])
    notes.append(f"prediction: {tr.track.elapsed:g} frame periods since the last estimate; root moved with the "
                 f"foreground by {1e3 * float(np.hypot(*(c_now[:2] - c_last[:2]))):.0f} mm")
    return True


#: The side swaps :func:`better_side` tries: the legs' angles exchanged, and legs and arms together (a walk
#: swings each arm with the other side's leg).
SIDE_SWAPS = (("left_leg", "right_leg"), ("left_leg", "right_leg", "left_arm", "right_arm"))


def swapped_sides(model, x: np.ndarray, limbs) -> np.ndarray:
    """``x`` with the angles of each limb in ``limbs`` and its other side's exchanged, mirrored through the
    sagittal plane (a joint's x and z rotations change sign, its y rotation keeps it: ``body/model.py``)."""
    out = np.array(x, dtype=float)
    names = model.dof_names
    index = {n: i for i, n in enumerate(names)}
    for limb in limbs:
        if not limb.startswith("left_") or limb not in model.partitions:
            continue
        for i in model.partitions[limb]:
            j = index.get("right_" + names[i][5:])
            if j is None:
                continue
            sign = -1.0 if names[i][-1] in "xz" else 1.0
            out[i], out[j] = sign * x[j], sign * x[i]
    return out


def better_side(tr, ctx, pred: np.ndarray) -> np.ndarray:
    """After a gap (``ctx.after_gap``) the limbs' phase is unknown: a walker unseen for half a second has swapped
    which leg is in front. Of the prediction and its :data:`SIDE_SWAPS` the lowest energy under the frame's
    objective starts the search (a few evaluations); a swap taken is noted. The own predictor keeps its history
    (restarting it there measured worse: docs/history/issue35_speed.md, session 27)."""
    cands = [pred] + [swapped_sides(tr.model, pred, limbs) for limbs in SIDE_SWAPS]
    E = np.asarray(ctx.objective(np.stack(cands)), dtype=float)
    k = int(np.nanargmin(np.where(np.isfinite(E), E, np.inf))) if np.any(np.isfinite(E)) else 0
    if k:
        what = "legs" if len(SIDE_SWAPS[k - 1]) == 2 else "legs and arms"
        ctx.notes.append(f"prediction: after the gap the search starts with the {what} swapped "
                         f"(energy {E[k]:.4g} vs {E[0]:.4g})")
    return cands[k]


#: The side check after a long gap (:func:`side_check`): from this many frame periods unseen (0 = never: below it,
#: :func:`better_side`), and each leg assignment's share of the frame's evaluations.
SIDE_CHECK_GAP = 8
SIDE_CHECK_SHARE = 0.5


def side_check(tr, ctx, pred: np.ndarray) -> tuple[np.ndarray, int]:
    """After a gap of :data:`SIDE_CHECK_GAP` frame periods or more: which leg is in front, searched, not guessed.
    Both leg assignments of the limbs as last seen — the prediction's root (re-centred on the foreground), the last
    estimate's joint angles, and the same with the legs exchanged (:func:`swapped_sides`) — are searched briefly
    (:data:`SIDE_CHECK_SHARE` of the frame's evaluations each, no stage); the lower energy starts the frame's search.
    The prediction's own limbs are not a candidate: extrapolated over 15-25 frames from the few estimates a fresh
    track holds they put the legs anywhere, and after a short search they could still win (docs/history/
    issue35_speed.md, session 34). Returns the start and the evaluations spent (beside the frame's budget)."""
    from .plan import FrameBudget

    held = np.array(pred, dtype=float)
    held[6:] = tr.track.last[6:]
    cands = (held, swapped_sides(tr.model, held, SIDE_SWAPS[0]))
    brief = FrameBudget(max(1, int(SIDE_CHECK_SHARE * ctx.budget.evals)), False)
    runs = [tr.optimize(ctx, c, ctx.rng(11, j), stages=False, budget=brief) for j, c in enumerate(cands)]
    E = [r.energy if np.isfinite(r.energy) else np.inf for r in runs]
    k = int(E[1] < E[0])
    ctx.notes.append(f"prediction: after the gap the side check took the limbs as last seen"
                     f"{' with the legs exchanged' if k else ''} (energy {E[k]:.4g} vs {E[1 - k]:.4g} after a brief "
                     "search each)")
    x, _ = tr.final_pose(runs[k])
    return x, int(sum(r.n_evals for r in runs))


def gap_start(tr, ctx, pred: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The search's start after a gap (``ctx.after_gap``), the evaluations spent on it and those of them charged to
    the frame's budget: :func:`side_check` after :data:`SIDE_CHECK_GAP` frame periods or more (when its brief searches
    fit their share: not at the lowest budgets), else :func:`better_side`."""
    if SIDE_CHECK_GAP and tr.track.elapsed >= SIDE_CHECK_GAP:
        try:
            x, n = side_check(tr, ctx, pred)
            return x, n, 0               # spent beside the frame's budget
        except ValueError as exc:          # a budget below the brief searches' generations
            ctx.notes.append(f"prediction: no side check after the gap ({exc})")
    return better_side(tr, ctx, pred), len(SIDE_SWAPS) + 1, len(SIDE_SWAPS) + 1
