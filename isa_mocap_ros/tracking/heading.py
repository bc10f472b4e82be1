"""The heading check: a standing silhouette looks nearly the same from the front and from the back, so
a rival hypothesis heading the other way is tracked beside the track for a few frames and the energy
sums decide (``TrackerConfig.heading.init_confirm_frames``); re-checks when more views see the person, after an
undecided check, or when the track travels backwards (the travel cue, ``heading_travel_cue``). The functions
take the tracker and its frame (:class:`~.frame_context.FrameContext`).
"""
from __future__ import annotations

import copy
import dataclasses
import math
import time
from typing import Sequence

import numpy as np

from . import first_frame, frame_masks
from .plan import FrameBudget
from .config import (UNDECIDED_RECHECK_FRAMES, TRAVEL_FRAMES, TRAVEL_MIN_M_PER_FRAME,
                     TRAVEL_BACKWARDS_DEG, TRAVEL_RECHECK_FRAMES, FrameResult)

#: The initialization's heading-check rival must head within this many degrees of the winner's opposite (front and
#: back are what the check tells apart); a rival further off, the best opposite run of the first frame's pruned runs
#: ended side-on, is searched for again from the standing variants at the winner's heading + 180 deg (the re-check's
#: search) and the lower-energy rival of the two is checked. 35-occluder mesh bag, slim woman: 3 of 8 seeds kept a
#: backwards winner over a rival 46-48 deg off the opposite for 6 frames (docs/history/issue33_mesh_accuracy_s29.md).
RIVAL_OPPOSITE_DEG = 30.0


def heading_recheck_pending(tr, masks: Sequence) -> bool:
    """True when stepping ``masks`` next may start a heading re-check (more views with foreground
    than the heading was checked with, an undecided check's re-check due, or estimates that travel
    backwards): a caller that drops frames (the estimator node in real time) should hand the tracker
    the frames that follow in sequence, as for :attr:`checking_heading`, or the check ends at the
    first gap (and a check that a gap ended is re-checked, :func:`recheck_heading`)."""
    hc = tr.heading_check
    if tr.config.heading.init_confirm_frames <= 0 or tr.track.last is None or hc.rival is not None:
        return False
    if any(at is not None and tr.frames + 1 >= at for at in (hc.recheck_at, hc.gap_recheck_at)):
        return True
    if travel_recheck_due(tr) is not None:
        return True
    if tr.heading_check.views >= len(tr.cameras):      # every view counted: no need to look at the masks
        return False
    usable, _ = frame_masks.check_masks(tr, masks)
    return sum(m is not None for m in usable) > tr.heading_check.views


def init_rival(tr, ctx, runs: list, winner, x: np.ndarray, energy: float, notes: list[str]) -> tuple:
    """The heading check's rival after the automatic initialization (``TrackerConfig.heading.init_confirm_frames``):
    :func:`.first_frame.pick_rival` of the initialized frame ``ctx``'s ``runs`` (``winner`` the result of the
    winner's pose ``x``, energy ``energy``); when that rival heads more than :data:`RIVAL_OPPOSITE_DEG` away from the
    winner's opposite, the frame's search from the standing variants at the opposite (stream 8, as
    :func:`recheck_heading`'s) gives another and the lower-energy one is the rival. Returns ``(rival start or
    None, evaluations spent here)``; a replacement is noted in ``notes``."""
    from .init import wrap_angle, yaw_of, standing_poses

    rival = first_frame.pick_rival(tr, runs, winner, x, energy)
    if rival is None:
        return None, 0
    yaw = yaw_of(x[3:6])
    off = math.degrees(abs(float(wrap_angle(yaw_of(rival[0][3:6]) - yaw - np.pi))))
    if off <= RIVAL_OPPOSITE_DEG:
        return rival, 0
    starts, _ = standing_poses(tr.model, x[:3], [yaw + np.pi])
    try:
        turned, n = first_frame.initial_runs(tr, ctx, list(starts), None, FrameBudget(ctx.budget.evals), stream=(8,))
    except ValueError as exc:
        notes.append(f"heading check: the rival heads {off:.0f} deg off the winner's opposite; its search from the "
                     f"opposite failed ({exc})")
        return rival, 0
    xr, er = min((tr.final_pose(r) for _, r, _ in turned), key=lambda t: t[1])
    turned_away = abs(float(wrap_angle(yaw_of(xr[3:6]) - yaw))) > np.pi / 2
    better = turned_away and np.isfinite(er) and er < rival[1]
    notes.append(f"heading check: the rival heads {off:.0f} deg off the winner's opposite ({rival[1]:.4g}); a search "
                 f"from the opposite ended {er:.4g}{'' if turned_away else ' turned back'}"
                 f"{' and is the rival' if better else '; kept the first'}")
    return ((xr, er, energy) if better else rival), n


def start_rival(tr, frame_index: int) -> None:
    """A second tracker (same model, cameras, configuration and energy; a fresh predictor of this
    one's kind) at the rival's pose of the initialized frame."""
    xr, _, _ = tr.heading_check.rival_start
    tr.heading_check.rival_start = None
    predictor = copy.deepcopy(tr.predictor, memo={id(tr.model): tr.model})
    predictor.reset()
    rival = type(tr)(tr.model, tr.cameras, tr.config.replace(init_confirm_frames=0),
                     prior=tr.prior, energy=tr.energy, predictor=predictor)
    first_frame.initialize(rival, pose=xr, frame_index=frame_index)
    rival.track.elapsed = tr.track.elapsed
    rival.track.masks_last = tr.track.masks_last
    tr.heading_check.rival = rival
    tr.heading_check.confirm = [0, 0.0, 0.0]


def travel(tr, min_periods: float = 0.0) -> tuple[float, float, float] | None:
    """The travel cue (:data:`TRAVEL_FRAMES`): ``(direction in radians, distance in m, frame periods)`` of the
    root's horizontal travel over the last estimates, or None when they span fewer than ``min_periods``
    periods (or none), the root moved less than :data:`TRAVEL_MIN_M_PER_FRAME` per period, or the model
    has no 3-DOF root rotation."""
    if len(tr.track.roots) < 2 or not tr.has_heading:
        return None
    (ta, xa, ya), (tb, xb, yb) = tr.track.roots[0], tr.track.roots[-1]
    span, dist = tb - ta, math.hypot(xb - xa, yb - ya)
    if span <= 0 or span < min_periods or dist < TRAVEL_MIN_M_PER_FRAME * span:
        return None
    return math.atan2(yb - ya, xb - xa), dist, span


def off_travel(direction: float, x) -> float:
    """Degrees between pose ``x``'s heading and a travel ``direction`` (radians)."""
    from .init import wrap_angle, yaw_of

    return math.degrees(abs(float(wrap_angle(direction - yaw_of(np.asarray(x, dtype=float)[3:6])))))


def travel_recheck_due(tr) -> tuple[float, float, float] | None:
    """The travel cue's trigger of a re-check: ``(degrees off the heading, m, periods)`` of :meth:`travel`
    over :data:`TRAVEL_FRAMES` periods when it points backwards (beyond :data:`TRAVEL_BACKWARDS_DEG`) and no
    re-check ran in the last :data:`TRAVEL_RECHECK_FRAMES` frames; else None."""
    if not tr.config.heading.heading_travel_cue or tr.frames < tr.heading_check.travel_recheck_after \
            or tr.track.last is None:
        return None
    t = travel(tr, TRAVEL_FRAMES)
    if t is None:
        return None
    off = off_travel(t[0], tr.track.last)
    return (off, t[1], t[2]) if off > TRAVEL_BACKWARDS_DEG else None


def recheck_heading(tr, ctx, res: FrameResult, frames_elapsed: float) -> FrameResult:
    """The heading re-check (``TrackerConfig.heading.init_confirm_frames``): on a tracked frame where more
    views use the person's foreground than when the heading was last checked (or an undecided
    check's re-check is due, or the travel cue finds the track moving backwards,
    ``TrackerConfig.heading.heading_travel_cue``), the frame's search from each standing variant heading the
    other way (at the estimate's root position, the automatic initialization's spreads, pruned as
    :meth:`_initial_runs` does); when the lowest-energy run's estimate heads more than 90° away and
    its energy is within ``init_confirm_ratio`` of this frame's, it becomes the rival of a heading
    check as after the initialization. ``ctx``: the tracker's frame; ``res``: its result."""
    from .init import wrap_angle, yaw_of, standing_poses

    cfg = tr.config
    due = tr.heading_check.recheck_at is not None and tr.frames >= tr.heading_check.recheck_at
    after_gap = tr.heading_check.gap_recheck_at is not None and tr.frames >= tr.heading_check.gap_recheck_at
    if cfg.heading.init_confirm_frames <= 0 or res.fell_back or res.initialized or frames_elapsed != 1 \
            or not np.isfinite(res.energy) or not tr.has_heading:
        return res                      # (a due re-check waits for a frame that follows its previous one)
    more_views = res.views_used > tr.heading_check.views
    travel = None if due or after_gap or more_views else travel_recheck_due(tr)
    if not (due or after_gap or more_views or travel):
        return res
    if after_gap:
        tr.heading_check.gap_recheck_at = None
    if due:
        tr.heading_check.recheck_at, tr.heading_check.rechecked_undecided = None, True
    tr.heading_check.travel_recheck_after = tr.frames + TRAVEL_RECHECK_FRAMES
    before, tr.heading_check.views = tr.heading_check.views, max(tr.heading_check.views, res.views_used)
    x = np.asarray(res.x, dtype=float)
    yaw = yaw_of(x[3:6])
    starts, _ = standing_poses(tr.model, x[:3], [yaw + np.pi])
    if travel:
        head = (f"heading re-check: the person moves backwards ({travel[1]:.2f} m in {travel[2]:g} frames, "
                f"{travel[0]:.0f} deg from the heading)")
    elif after_gap and not more_views:
        head = "heading re-check: the last check ended at a gap"
    elif not more_views:
        head = "heading re-check: the last check was undecided"
    else:
        head = f"heading re-check: {res.views_used} views see the person ({before} when the heading was checked)"
    try:
        runs, n = first_frame.initial_runs(tr, ctx, list(starts), None, FrameBudget(cfg.search.evals), stream=(5,))
    except ValueError as exc:
        return dataclasses.replace(res, time_s=time.perf_counter() - ctx.t0,
                                   notes=res.notes + (f"{head}; its search failed ({exc}); kept this heading",))
    xr, er = min((tr.final_pose(r) for _, r, _ in runs), key=lambda t: t[1])
    turned = abs(float(wrap_angle(yaw_of(xr[3:6]) - yaw))) > np.pi / 2
    if turned and np.isfinite(er) and er <= cfg.heading.init_confirm_ratio * max(res.energy, 0.0):
        tr.heading_check.rival_start = (xr, er, res.energy)
        start_rival(tr, ctx.frame_index)
        note = (f"{head}: a run heading the other way ended {er:.4g} (estimate {res.energy:.4g}); both tracked for "
                f"up to {cfg.heading.init_confirm_frames} frames")
    else:
        note = (f"{head}: a run heading the other way ended {er:.4g}"
                f"{'' if turned else ' turned back'} (estimate {res.energy:.4g}); kept this heading")
    return dataclasses.replace(res, n_evals=res.n_evals + n, time_s=time.perf_counter() - ctx.t0,
                               notes=res.notes + (note,))


def confirm_heading(tr, ctx, res: FrameResult, masks, frames_elapsed: float) -> FrameResult:
    """One frame of the heading check: step the rival on the same masks (its own frame context, with the
    tracker's plan and keypoint term), add both energies, decide (see
    ``TrackerConfig.heading.init_confirm_frames``); the frame's result (the rival's when it wins). ``ctx``:
    the tracker's frame; ``res``: its result."""
    cfg = tr.config
    rival = tr.heading_check.rival
    other = rival.track_frame(masks, rival.frame_context(ctx.frame_index, ctx.budget,
                                                         keypoint_term=ctx.objective.keypoint_term),
                              frames_elapsed=frames_elapsed)
    n_evals = res.n_evals + other.n_evals
    if res.fell_back and other.fell_back:       # nothing to compare this frame
        return dataclasses.replace(res, n_evals=n_evals, time_s=time.perf_counter() - ctx.t0)
    if res.fell_back != other.fell_back or not (np.isfinite(res.energy) and np.isfinite(other.energy)):
        tr.heading_check.rival = None
        return dataclasses.replace(res, n_evals=n_evals, time_s=time.perf_counter() - ctx.t0, notes=res.notes + (
            "heading check ended: no decision (only one hypothesis could be tracked); kept this one",))
    c = tr.heading_check.confirm
    c[0] += 1
    c[1] += res.energy
    c[2] += other.energy
    margin = cfg.heading.init_confirm_margin
    sums = f"energy sums over {c[0]} frame(s) {c[1]:.4g} vs {c[2]:.4g} for the other heading"
    # keeping may be decided early, switching only on all the frames: a wrong keep leaves the
    # track as it would be without the check, a wrong switch loses a good one (and one frame's
    # sums misled on some first frames of generated motions, docs/decisions/010-heading-check.md)
    last = c[0] >= cfg.heading.init_confirm_frames
    # the travel cue (TRAVEL_FRAMES): when this heading moves backwards and the other forwards, the check
    # runs to its last frame and keeps this heading only if the energies clearly prefer it
    t = travel(tr) if cfg.heading.heading_travel_cue else None
    off = off_travel(t[0], res.x) if t is not None else None
    contra = off is not None and off > TRAVEL_BACKWARDS_DEG \
        and off_travel(t[0], other.x) < 180.0 - TRAVEL_BACKWARDS_DEG
    by_travel = contra and last and not c[2] > margin * c[1]
    if by_travel:
        sums += (f"; this heading moves backwards ({off:.0f} deg from the travel, {t[1]:.2f} m in {t[2]:g} "
                 "frames), the other forwards")
    if not by_travel and ((c[2] > margin * c[1] and not contra) or (last and not c[1] > margin * c[2])):
        tr.heading_check.rival = None
        tr.heading_check.gap_rechecked = False
        if not c[2] > margin * c[1] and not tr.heading_check.rechecked_undecided:
            # kept for want of evidence: the rival may still have been converging; once more later
            tr.heading_check.recheck_at = tr.frames + UNDECIDED_RECHECK_FRAMES
            sums += f"; undecided, re-checked in {UNDECIDED_RECHECK_FRAMES} frames"
        return dataclasses.replace(res, n_evals=n_evals, time_s=time.perf_counter() - ctx.t0,
                                   notes=res.notes + (f"heading check decided: kept the initial heading ({sums})",))
    if not last:
        return dataclasses.replace(res, n_evals=n_evals, time_s=time.perf_counter() - ctx.t0)
    # the rival wins: its track (estimate, predictor, masks, root history) becomes this tracker's; external predictions were made from this tracker's
    # estimates, so they are ignored while the predictor's history still holds any of them
    tr.heading_check.rival = None
    tr.heading_check.gap_rechecked = False
    # views that joined during the check took part in a switch: no re-check for them (a fresh track
    # checked again at once lost its heading to a fresh rival, generated walk seed 6); a check that
    # kept the heading is re-checked on the next frame that sees them
    tr.heading_check.views = max(tr.heading_check.views, res.views_used, other.views_used)
    tr.track = rival.track
    cap = getattr(tr.predictor, "capacity", None)
    tr.heading_check.own_prediction_frames = (int(cap) if cap is not None else cfg.prediction.predictor_order + 1) - 1
    return dataclasses.replace(other, n_evals=n_evals, time_s=time.perf_counter() - ctx.t0, notes=other.notes + (
        f"heading check decided: switched to the other heading ({sums}); the frames before were estimated facing "
        "the wrong way",))
