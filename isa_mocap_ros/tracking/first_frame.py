"""The first frame: the automatic initialization (:mod:`.init`), the frame's search from each heading
candidate pruned to ``init_keep`` runs, the polish of the winner (``init_polish``) and the pick of a
heading-check rival (``init_confirm_frames``). The functions take the tracker and the frame
(:class:`~.frame_context.FrameContext`).
"""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from isa_mocap_ros.optim import compiled_search

from . import frame_masks, objective
from .config import INIT_SPREAD_SCALE, TrackerError
from .init import InitError, initial_pose
from .plan import FrameBudget, flat_algorithm

#: Share of the frame's evaluations the first frame's polish (of the winner and of the heading check's rival,
#: ``init_polish``) searches with: at half the budget the initialized frame costs ~45 CPU ms less (bags/demo) and
#: the tracks of 5 sequences x 3 seeds were as accurate (docs/history/issue35_speed.md, session 26)
POLISH_SHARE = 0.5
#: Runs a heading re-check's search (:func:`.heading.recheck_heading`: the standing variants heading the other way)
#: keeps at its checkpoint, at least: ``init_keep``'s count before it became 2 (session 29), with which the re-checks
#: were measured (pruned to 2, a track thrown 2 m off started a heading check on a re-check and was re-initialized
#: 2 sets later, ``test_a_lost_track_is_reinitialized_by_itself``)
RECHECK_KEEP = 3


def initialize(tr, masks: Sequence | None = None, pose=None, *, frame_index: int = 0,
               keypoints: Sequence | None = None):
    """Set the first estimate: ``pose`` if given, else automatically from ``masks``.

    Parameters
    ----------
    masks : sequence of (H, W) array_like or None, optional
    pose : (D,) array_like, optional
    frame_index : int
        Frame key of the initialization's random stream.
    keypoints : sequence of (uv, confidence) or None, optional
        As for :meth:`Tracker.step`: with ``config.keypoints.keypoint_weight > 0`` the grid and refinement also
        score the keypoint term.

    Returns
    -------
    InitResult or None
        The automatic initialization's result (None for a given pose).

    Raises
    ------
    TrackerError
        Neither argument, a pose of the wrong length or not finite, or no usable foreground.
    """
    tr.reset()
    if pose is not None:
        try:
            x = np.asarray(tr.model.validate_pose(pose, name="pose"), dtype=float)
        except ValueError as exc:
            raise TrackerError(str(exc)) from None
        if x.ndim != 1:
            raise TrackerError(f"pose: expected shape ({tr.model.dof},), received {x.shape}")
        x = np.clip(x, tr.model.lower, tr.model.upper)
        tr.track.masks_now = None          # no frame: nothing to re-centre from later
        tr.accept(x)
        tr.heading_check.views = len(tr.cameras)     # a given pose's heading is not re-checked
        return None
    if masks is None:
        raise TrackerError("initialize: expected masks= or pose=, received neither")
    usable, notes = frame_masks.check_masks(tr, masks)
    ctx = tr.frame_context(frame_index, keypoint_term=objective.keypoint_energy(tr, keypoints)[0])
    ctx.notes, ctx.raw_masks = notes, usable
    ctx.masks = tr.track.masks_now = usable
    if frame_masks.set_masks(tr, ctx) == 0:
        raise TrackerError(f"masks: expected foreground in at least one view, received none ({'; '.join(notes)})")
    try:
        res = initial_grid(tr, ctx)
    except InitError as exc:
        raise TrackerError(f"masks: automatic initialization failed: {exc}") from None
    tr.accept(res.x)
    tr.heading_check.views = res.views_used
    return res


def initial_grid(tr, ctx):
    """The automatic initialization (:func:`.init.initial_pose`) on the frame's masks ``ctx.masks``: root from
    the masks' rays, heading × standing-pose grid, root refinements (stream 1); raises :class:`.init.InitError`."""
    cfg = tr.config
    return initial_pose(tr.model, tr.cameras, ctx.masks, init_energy_fn(tr, ctx), rng=ctx.rng(1),
                        n_yaw=cfg.first_frame.init_yaw_steps, refine_evals=cfg.first_frame.init_refine_evals,
                        refine_optimizer=flat_algorithm(tr),
                        refine_search=root_search(tr, ctx) if tr.init_energy is None else None)


def root_search(tr, ctx):
    """The root refinements' search compiled whole (:func:`~isa_mocap_ros.optim.compiled_search.search` of a
    one-partition h-isa over the 6 root coordinates on the frame's energy), or None where that path does not
    cover the frame's objective: ``fn(base (D,), spread (6,), rng, evals) -> Result or None``."""
    from isa_mocap_ros.optim import inner_optimizer, make_optimizer

    if not tr.use_compiled_search or inner_optimizer(tr.config.search.optimizer) != "isa":
        return None
    params = {k: v for k, v in tr.config.search.params().items()
              if k not in ("partitions", "optimizer", "initial_population", "evals_per_partition", "whole_generations")}
    root = np.arange(6)

    def fn(base, spread, rng, evals):
        sp = np.ones(base.size)          # (the coordinates outside the partition are not searched)
        sp[:6] = spread
        lo, hi = tr.model.lower.copy(), tr.model.upper.copy()
        opt = make_optimizer(tr.config.search.optimizer, base, sp, rng=rng, bounds=(lo, hi),
                             rotation_blocks=((3, 4, 5),), partitions=[root], whole_generations=True, **params)
        res = compiled_search.search(opt, tr.energy, evals, extra_terms=ctx.objective.extra_terms,
                                     keypoints=ctx.objective.weighted_keypoints)
        if res is None:
            return None
        return dataclasses.replace(res, x=np.asarray(res.x)[:6], best_x=np.asarray(res.best_x)[:6])
    return fn


def init_energy_fn(tr, ctx):
    """The energy the automatic initialization scores its grid with: the tracker's coarse initialization energy
    (``Tracker.init_energy``, foreground samples from stream 4) on the frame's masks plus the frame's other terms,
    else the frame's objective."""
    if tr.init_energy is None:
        return ctx.objective
    tr.init_energy.rng = ctx.rng(4)
    try:
        tr.init_energy.set_masks(ctx.masks)
    except ValueError:
        return ctx.objective

    def fn(X):
        X = np.atleast_2d(np.asarray(X, dtype=float))
        return ctx.objective.add_terms(X, np.asarray(tr.init_energy(X), dtype=float))
    return fn


def initial_runs(tr, ctx, starts: list, notes: list[str] | None, budget: FrameBudget,
                 stream: tuple = ()) -> tuple[list, int]:
    """The automatically initialized frame's (``ctx``) search from every start (heading candidate), pruned
    to ``config.first_frame.init_keep`` runs at the checkpoint (see :class:`TrackerConfig`; on the first frame the
    lowest-energy run and the lowest heading more than 90° from it first, :func:`rival_second`): the list of
    ``(start index, result, start)`` of the runs that ended, and the evaluations of all runs.
    Raises the optimizer's errors."""
    cfg = tr.config
    runs = []
    for j, pred in enumerate(starts):
        if stream:          # the heading re-check's runs: their own streams
            rng = ctx.rng(*stream, j)
        else:
            rng = ctx.rng() if j == 0 else ctx.rng(3, j)
        opt, evals, _, _ = tr.plan_search(pred, rng, budget, INIT_SPREAD_SCALE, notes if j == 0 else None,
                                          stages=False)
        run = compiled_search.search(opt, tr.energy, evals, extra_terms=ctx.objective.extra_terms,
                                     keypoints=ctx.objective.weighted_keypoints, paused=True) \
            if tr.use_compiled_search else None
        if run is not None:
            # compiled h-isa, bound; the pruning below advances it (the same numbers as the protocol)
            runs.append((j, run, pred, None))
            continue
        # bind + iterate + result() is minimize(), split at the checkpoint: the end of the first
        # partition (hierarchical optimizers, whose shares bind() sets) or a sixth of the budget
        opt.bind(ctx.objective, max_evals=evals)
        shares = getattr(opt, "shares", None)
        runs.append((j, opt, pred, shares[0] if shares else evals // 6))
    n_pruned = 0
    # the heading re-check's runs (``stream``: all heading one way, no rival among them) keep at least
    # RECHECK_KEEP, the count their re-checks were measured with
    keep = cfg.first_frame.init_keep if not stream or not cfg.first_frame.init_keep \
        else max(cfg.first_frame.init_keep, RECHECK_KEEP)
    if 0 < keep < len(runs):
        for _, opt, _, checkpoint in runs:
            if checkpoint is None:
                opt.advance(1)
                continue
            for _ in opt:
                if opt.n_evals >= checkpoint:
                    break
        ranked = sorted(runs, key=lambda r: r[1].best_energy)      # stable: ties keep the start order
        if not stream and tr.has_heading:
            ranked = rival_second(ranked)
        n_pruned = sum(r[1].n_evals for r in ranked[keep:])
        runs = sorted(ranked[:keep], key=lambda r: r[0])
    out = []
    for j, opt, pred, checkpoint in runs:
        if checkpoint is None:
            out.append((j, opt.advance().result(), pred))
            continue
        for _ in opt:
            pass
        out.append((j, opt.result(), pred))
    return out, n_pruned + sum(res.n_evals for _, res, _ in out)


def rival_second(ranked: list) -> list:
    """The runs ``ranked`` (by their best energy at the checkpoint) with the lowest-energy one heading more than 90°
    away from the first (its best pose's heading) moved to second place: pruned to two, the first frame keeps the
    heading check's rival (:func:`pick_rival`) instead of a run heading sideways. With the four heading sectors'
    runs pruned to 2 so, 12 of 18 tracks (bags/demo, the fixture, three mesh walks, the real recording's first 20
    frames; seeds 0-2) were the same as with the 3 lowest, the rest within their spread, none backwards; the initialized
    frame ~6 % cheaper (docs/history/issue35_speed.md, session 29). Pruned to the 2 lowest instead, no heading check
    started on bags/demo and the clean walks."""
    from .init import wrap_angle, yaw_of

    if len(ranked) < 3:
        return ranked
    y0 = yaw_of(np.asarray(ranked[0][1].best_x)[3:6])
    for i, run in enumerate(ranked[1:], 1):
        if abs(float(wrap_angle(yaw_of(np.asarray(run[1].best_x)[3:6]) - y0))) > np.pi / 2:
            return [ranked[0], run] + ranked[1:i] + ranked[i + 1:]
    return ranked


def polish_budget(budget: FrameBudget) -> FrameBudget:
    """The polish's budget: :data:`POLISH_SHARE` of the frame's evaluations, at least 300 (or the frame's when it
    has fewer), the frame's contour stage."""
    return FrameBudget(max(int(budget.evals * POLISH_SHARE), min(budget.evals, 300)), budget.contour)


def polish(tr, ctx, x: np.ndarray, energy: float, stream: int, notes):
    """``config.first_frame.init_polish``'s search of the initialized frame's pose ``x`` (energy ``energy``) as a
    tracked frame, every stage, on :func:`polish_budget`, stream ``[seed, frame, stream]``: ``(result or None if the
    optimizer refused, the lower-energy pose of the two, its energy)``; a refusal is noted in ``notes`` (when given)."""
    try:
        res = tr.optimize(ctx, x, ctx.rng(stream), notes=notes, budget=polish_budget(ctx.budget))
    except ValueError as exc:
        if notes is not None:
            notes.append(f"initialization polish failed: {exc}")
        return None, x, energy
    xp, ep = tr.final_pose(res)
    return (res, xp, ep) if ep < energy else (res, x, energy)


def polish_winner(tr, ctx, x: np.ndarray, energy: float, res):
    """``config.first_frame.init_polish``: the first frame's winner searched once more as a tracked frame (all stages)
    from itself, and the heading check's rival (``heading_check.rival_start``) alike; the heading that
    fits better after it leads (the check still tracks both). Returns ``(x, energy, result, evaluations)``
    of the frame."""
    n_evals = 0
    notes = ctx.notes
    res2, x2, e2 = polish(tr, ctx, x, energy, 6, notes)
    if res2 is not None:
        n_evals += res2.n_evals
        if e2 < energy:
            x, energy, res = x2, e2, res2
    check = tr.heading_check
    if check.rival_start is not None:
        res_r, xr, er = polish(tr, ctx, *check.rival_start[:2], 7, None)
        if res_r is not None:
            n_evals += res_r.n_evals
        if er < energy:
            notes.append(f"initialization polish: the heading check's rival fits better ({er:.4g} against "
                         f"{energy:.4g}) and leads")
            check.rival_start = (x, energy, er)
            x, energy = xr, er
            res = res_r if res_r is not None else res
        else:
            check.rival_start = (xr, er, energy)
    return x, energy, res, n_evals


def pick_rival(tr, runs: list, winner, x: np.ndarray, energy: float):
    """The heading check's rival among the initialized frame's runs (``config.heading.init_confirm_frames``):
    the lowest-energy run heading more than 90° away from the winner's estimate ``x``, if its
    energy is within ``config.heading.init_confirm_ratio`` of ``energy``; else None."""
    from .init import wrap_angle, yaw_of

    if not tr.has_heading or not np.isfinite(energy):
        return None
    yaw = yaw_of(x[3:6])
    best = None
    for _, res, _ in runs:
        if res is winner:
            continue
        xr, er = tr.final_pose(res)
        if abs(float(wrap_angle(yaw_of(xr[3:6]) - yaw))) > np.pi / 2 and np.isfinite(er) \
                and (best is None or er < best[1]):
            best = (xr, er)
    if best is None or best[1] > tr.config.heading.init_confirm_ratio * max(energy, 0.0):
        return None
    return best[0], best[1], energy
