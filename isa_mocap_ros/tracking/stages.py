"""The frame's stage searches after the main search (``docs/tracking.md``): the pelvis stage
(:func:`refit_pelvis`), the torso stage (:func:`refit_torso`), the limb stage (:func:`propose_limbs`)
and the contour stage (:func:`fit_contours`). Each takes the tracker (its model, moves, energy), the frame
(:class:`~.frame_context.FrameContext`: its masks and objective) and a pose, and returns the pose it found with
its energy and the evaluations it spent.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from isa_mocap_ros.optim import compiled_search, compiled_stage

from . import plan
from .contour import ContourFitInfo
from .config import CONTOUR_KEEP_TOLERANCE, TrackerError, whole_generations


def fit_contours(tr, ctx, x, *, iterations: int | None = None, extra_iterations: int | None = None,
                 energy: float | None = None):
    """The contour stage on pose ``x`` under the frame's masks ``ctx.masks`` (:class:`~.contour.ContourFit`):
    ``config.stages.contour_iterations`` (or ``iterations``) steps over all coordinates, then
    ``config.stages.contour_extra_iterations`` (or ``extra_iterations``) over the coordinates of
    ``config.stages.contour_extra_partitions`` alone, from that pose's contour points (rendered again);
    returns ``(pose, its energy, evaluations charged, ContourFitInfo)`` (the info of both fits
    together). The fitted pose replaces ``x`` unless its silhouette energy is more than
    :data:`CONTOUR_KEEP_TOLERANCE` above ``x``'s (both evaluated in one batch: a mask contour bent by an
    occluder or noise can pull the fit away); the evaluations charged are ``(D + 1)`` per iteration
    taken over all coordinates, ``(k + 1)`` per iteration over ``k`` of them, + 2. ``energy``: ``x``'s energy under
    ``ctx.objective`` if known to the bit (a stage's returned energy), so only the fit's is evaluated (not with a
    prior, whose batch of both poses may round otherwise)."""
    if ctx.masks is None:
        raise TrackerError("fit_contours: no masks yet (call step first)")
    iterations = tr.config.stages.contour_iterations if iterations is None else iterations
    extra = plan.contour_extra(tr) if extra_iterations is None else extra_iterations
    x = np.asarray(x, dtype=np.float64)
    tr.contour_fit.set_masks(ctx.masks)
    y, info = tr.contour_fit.fit(x, iterations=iterations)
    n = info.iterations * (tr.model.dof + 1) + 2
    if extra and tr.contour_extra_coords.size and not info.stopped:
        y, more = tr.contour_fit.fit(y, iterations=extra, coords=tr.contour_extra_coords,
                                    render_each=False)
        n += more.iterations * (tr.contour_extra_coords.size + 1)
        info = ContourFitInfo(info.iterations + more.iterations, info.correspondences + more.correspondences,
                              info.rms_px + more.rms_px, more.stopped)
    if energy is None or ctx.objective.prior_active:
        e_x, e_y = (float(v) for v in ctx.objective(np.stack([x, y])))
    else:
        e_x, e_y = float(energy), float(ctx.objective(y[None, :])[0])
    return (y, e_y, n, info) if e_y < e_x + CONTOUR_KEEP_TOLERANCE * abs(e_x) else (x, e_x, n, info)


def refit_pelvis(tr, ctx, x, *, evals: int, rng: np.random.Generator, optimizer: str | None = None,
                 params: Mapping | None = None, bounds=None, spread=None) -> tuple[np.ndarray, float, int]:
    """Re-fit the 6 root DOF of pose ``x`` on the frame's objective ``ctx.objective`` with the limbs below the root
    kept in place (:class:`~.reaim.ReaimMove`: the thighs swung about the knees, the lower spine about
    the chest); returns ``(pose, its energy, evaluations)``.

    Whole generations of ``evals - 1`` evaluations go to the search (``optimizer``: a flat algorithm
    name, default the configured one's flat form, with ``params``), one to the final pose's energy;
    the count spent is returned. ``bounds`` and
    ``spread`` default to :meth:`search_box` around ``x``.
    """
    from isa_mocap_ros.optim import make_optimizer, minimize

    m = tr.model
    if tr.pelvis_reaim is None:
        raise TrackerError(f"refit_pelvis: model {m.name} has no root partition")
    x = np.asarray(x, dtype=float)
    lo, hi = bounds if bounds is not None else tr.search_box(x)[:2]
    spread = tr.search_box(x)[2] if spread is None else np.asarray(spread, dtype=float)
    if optimizer is None:
        optimizer, params = plan.flat_algorithm(tr)
    x1 = np.clip(x, lo, hi)
    move = tr.pelvis_reaim.around(x1)

    def energy(roots):
        return ctx.objective(np.clip(move(roots), m.lower, m.upper))

    opt = make_optimizer(optimizer, x1[:6], np.array(spread[:6]), rng=rng,
                         bounds=(lo[:6], hi[:6]), rotation_blocks=((3, 4, 5),), **dict(params or {}))
    evals_search = whole_generations(int(evals) - 1, opt.generation_size)
    r = _moved_search(tr, ctx, opt, evals_search, tr.pelvis_reaim, x1) if tr.use_compiled_search else None
    if r is None and tr.use_compiled_search:
        r = compiled_search.search(opt, energy, evals_search)
    if r is None:                                 # not covered by the compiled path (the same numbers)
        r = minimize(opt, energy, max_evals=evals_search)
    out = np.clip(move(r.x)[0], m.lower, m.upper)
    return out, float(ctx.objective(out[None, :])[0]), r.n_evals + 1


def refit_torso(tr, ctx, x, *, evals: int, rng: np.random.Generator, energy: float | None = None, bounds=None,
                spread=None) -> tuple[np.ndarray, float, int, bool]:
    """The torso stage on pose ``x`` on the frame's objective ``ctx.objective``: the configured algorithm's flat form
    searches the torso partition's DOFs with the arms re-aimed (:class:`~.reaim.ReaimMove`: each
    upper arm swung about its elbow, the forearm keeping its direction), everything else held; the
    result replaces ``x`` when it lowers the energy.

    ``energy`` is ``x``'s energy if known (else one evaluation computes it); the search gets whole
    generations of the rest of ``evals`` but one, which gives the result's energy, so the stage
    spends at most ``evals`` (less by under a generation). ``bounds``/``spread`` default to
    :meth:`search_box` around ``x`` (the bounds are widened to hold ``x``). Returns ``(pose, its
    energy, evaluations, replaced)``.
    """
    from isa_mocap_ros.optim import make_optimizer, minimize

    m = tr.model
    if tr.torso_reaim is None:
        raise TrackerError(f"refit_torso: model {m.name} has no torso partition")
    x = np.clip(np.asarray(x, dtype=float), m.lower, m.upper)
    if bounds is None or spread is None:
        box = tr.search_box(x)
        bounds = box[:2] if bounds is None else bounds
        spread = box[2] if spread is None else spread
    c = tr.torso_reaim.coords
    spread = np.asarray(spread, dtype=float)[c]
    lo, hi = np.minimum(bounds[0][c], x[c]), np.maximum(bounds[1][c], x[c])
    used = 0
    if energy is None:
        energy, used = float(ctx.objective(x[None, :])[0]), 1
    move = tr.torso_reaim.around(x)
    # the poses differ from x in the torso and the re-aimed joints only: the restricted energy (same values)
    changed = np.union1d(c, [d for j in tr.torso_reaim.ops for d in m.joint_dofs[j]])
    name, params = plan.flat_algorithm(tr)
    opt = make_optimizer(name, x[c], spread, rng=rng, bounds=(lo, hi), **params)
    evals_search = whole_generations(int(evals) - used - 1, opt.generation_size)
    r = _moved_search(tr, ctx, opt, evals_search, tr.torso_reaim, x, changed) if tr.use_compiled_search else None
    if r is None:
        data = ctx.objective.restrict(x, changed) or ctx.objective

        def energy_of(C):
            return data(np.clip(move(C), m.lower, m.upper))

        r = compiled_search.search(opt, energy_of, evals_search) if tr.use_compiled_search else None
        if r is None:
            r = minimize(opt, energy_of, max_evals=evals_search)
    y = np.clip(move(r.x[None, :])[0], m.lower, m.upper)
    ey = float(ctx.objective(y[None, :])[0])
    used += r.n_evals + 1
    if ey < energy:
        return y, ey, used, True
    return x, float(energy), used, False


def _moved_search(tr, ctx, opt, evals: int, reaim, x, changed=None):
    """The pelvis or torso stage's search of ``ctx.objective(clip(reaim.around(x)(C)))`` in one compiled call
    (:func:`~isa_mocap_ros.optim.compiled_stage.run_isa_moved`, the same numbers as the Python energy through
    :func:`~isa_mocap_ros.optim.compiled_search.search`), on the data energy restricted to ``changed`` when given;
    None when that path does not cover it (a prior, another data energy or optimizer)."""
    if ctx.objective.extra_terms or not compiled_stage.supported_moved(opt, tr.energy):
        return None
    rest = tr.energy.restrict(x, changed) if changed is not None else None
    return compiled_stage.run_isa_moved(opt, tr.energy, evals, move=reaim.kernel_args(x), coords=reaim.coords,
                                        limits=(tr.model.lower, tr.model.upper), restricted=rest,
                                        keypoints=ctx.objective.weighted_keypoints)


def propose_limbs(tr, ctx, x, *, n: int, rng: np.random.Generator, limbs: Sequence[str] | None = None,
                  hinge_only: Sequence[str] = (), last=None) -> tuple[np.ndarray, float, int, list[str]]:
    """The limb stage on pose ``x`` on the frame's objective ``ctx.objective`` (:class:`~.limbs.LimbMove`): ``n``
    twist-and-hinge proposals per limb (hinge proposals only for the limbs in ``hinge_only``) and,
    given the previous frame's pose ``last``, the ``config.stages.limb_extrapolations`` proposals,
    evaluated in one batch with ``x`` itself; each limb whose best proposal has a lower energy than
    ``x`` takes that proposal's angles.

    Returns ``(pose, its energy, evaluations, limbs replaced)``; evaluations are always
    ``(n + extrapolations) × limbs + 2``: the batch, then the returned pose once more (its energy is
    not among the batch's when two limbs changed), so the stage spends exactly its share. The batch's data
    term is evaluated limb by limb on the energy restricted to that limb (:func:`_limb_batch_energies`: the
    same values as one call of ``ctx.objective``).
    """
    m = tr.model
    names = [limb.name for limb in tr.limb_move.limbs] if limbs is None else list(limbs)
    chosen = [tr.limb_move.limb(name) for name in names]
    x = np.clip(np.asarray(x, dtype=float), m.lower, m.upper)
    if int(n) < 1 or not chosen:
        return x, float(ctx.objective(x[None, :])[0]), 1, []
    n = int(n)
    factors = tr.config.stages.limb_extrapolations if last is not None else ()
    w = tr.config.stages.limb_hinge_window_deg
    window = np.deg2rad(w) if 0 < w < 180 else None
    batches = [tr.limb_move.draw(x, limb, n, rng, twist=limb.name not in hinge_only, window=window)
               for limb in chosen]
    if factors:
        batches = [np.vstack([P, tr.limb_move.extrapolate(x, last, limb, factors)])
                   for limb, P in zip(chosen, batches)]
    E = _limb_batch_energies(ctx, x, chosen, batches)
    out, changed = x.copy(), []
    size = n + len(factors)
    energy, row = float(E[0]), None
    for k, (limb, P) in enumerate(zip(chosen, batches)):
        Ek = E[1 + k * size: 1 + (k + 1) * size]
        i = int(np.argmin(Ek))
        if Ek[i] < E[0]:
            out[limb.dofs] = P[i, limb.dofs]
            changed.append(limb.name)
            energy, row = float(Ek[i]), P[i]
    # the returned pose's energy: the batch's row of that very pose when at most one limb changed (the same
    # bits: each row is scored alone; not with a prior, whose batch sums may round otherwise), else evaluated
    if len(changed) > 1 or ctx.objective.prior_active or (row is not None and not np.array_equal(row, out)):
        energy = float(ctx.objective(out[None, :])[0])
    return out, energy, size * len(chosen) + 2, changed


def _limb_batch_energies(ctx, x, chosen, batches) -> np.ndarray:
    """``ctx.objective`` of the limb stage's batch ``[x, *batches]`` (``batches[k]``: poses equal to ``x`` outside
    limb ``chosen[k]``'s DOFs), the same values: the data term of each limb's rows from the data energy restricted
    to that limb's DOFs (:meth:`~isa_mocap_ros.energy.SilhouetteEnergy.restrict`: the same bits as the full energy,
    a few capsules rasterized per pose instead of all), the prior and keypoint terms on the whole batch as
    ``ctx.objective`` adds them. A data energy without ``restrict`` is called on the whole batch."""
    X = np.vstack([x[None, :]] + batches)
    obj = ctx.objective
    restrict = getattr(obj.tracker.energy, "restrict", None)
    if not callable(restrict):
        return obj(X)
    data = [restrict(x, limb.dofs)(np.vstack([x[None, :], P]) if k == 0 else P)
            for k, (limb, P) in enumerate(zip(chosen, batches))]
    return obj.add_terms(X, np.concatenate(data))
