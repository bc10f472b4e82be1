"""A flat ISA whose every generation is one compiled call, the energy included: the tracker's pelvis and torso stages.

The stages (``tracking/stages.py``) search a few coordinates ``C`` of a pose whose other joints are re-aimed to
them (:class:`~isa_mocap_ros.tracking.reaim.ReaimMove`) and score ``objective(clip(move(C), lower, upper))``: the
silhouette energy (full, or restricted to the coordinates the move changes) plus the weighted keypoint term.
:func:`~.compiled_search.run_isa` runs that with the energy as a Python callable, so each of a stage's ~7
generations paid a dozen Python calls around the compiled pieces (the move, the clip, the energy's checks and
kernel launch, the keypoint term, the energies' check, the generator handed to numba). :func:`run_isa_moved`
runs the same algorithm with one compiled call per stage: the same compiled helpers (:func:`~.compiled_search._start`,
:func:`~.compiled_search._tell`, the move's :func:`~isa_mocap_ros.body.reaim_kernel.rebuild`, the energy kernels
through :func:`~.compiled_search._kernel`), the same draws from the same generator, in the same order, so the
result is :func:`~.compiled_search.run_isa`'s bit for bit (``test/test_compiled_stage.py``).
"""
from __future__ import annotations

import numba
import numpy as np

from isa_mocap_ros.body import reaim_kernel as _reaim
from isa_mocap_ros.energy import keypoint_kernel as _kp
from isa_mocap_ros.numba_cache import register_dependent_cache
from isa_mocap_ros.optim import _fast, compiled_search
from isa_mocap_ros.optim._base import GenerationInfo, OptimError, Result
from isa_mocap_ros.optim.compiled_search import _KERNELS, _kernel, _start, _tell, supported_flat

__all__ = ["run_isa_moved", "supported_moved"]

register_dependent_cache(__file__, (compiled_search, _reaim))


@numba.njit(cache=True)
def _moved_isa(x0, spread, lo, hi, n, max_evals, rng, target, kernel, c, rho, population, block, coords, lower,
               upper, move, threads, kargs, kp, hist):  # pragma: no cover - compiled
    """:func:`~.compiled_search.run_isa` of ``E(C) = kernel(clip(rebuild(C), lower, upper)) + kp.scale *
    keypoints``: ``move`` = ``(x, Rb, Pb, parents, offsets, ptr, dofs, axes, op, target)``
    (:meth:`~isa_mocap_ros.tracking.reaim.ReaimMove.kernel_args`; ``C`` goes into the columns ``coords`` of ``x``);
    ``kargs`` the kernel's arguments between the poses and ``n_chunks``. Writes each generation's ``(evaluations,
    best energy, mean finite energy, spread, beta, ESS)`` into ``hist``. Returns (estimate, best energy, best
    particle, last evaluated particles, their weights, evaluations, non-finite, generations); generations -1 when
    the kernel flagged a row with a negative energy (a restricted kernel's row off its base pose)."""
    xb = move[0]
    D = xb.size
    X = _start(x0, spread, lo, hi, n, rng)
    used = 0
    bad = 0
    g = 0
    best = np.inf
    best_x = x0.copy()
    beta = np.nan
    x = x0.copy()
    W = np.full(n, 1.0 / n)
    P = X
    while used < max_evals:
        kk = min(n, max_evals - used)
        F = np.empty((kk, D))
        for i in range(kk):                               # ReaimMove.around's poses
            F[i, :] = xb
            for q in range(coords.size):
                F[i, coords[q]] = X[i, q]
        _reaim.rebuild(F, *move)
        ok = np.ones(kk, np.bool_)
        n_ok = 0
        for i in range(kk):                               # np.clip(..., lower, upper); a non-finite row: +inf
            for q in range(D):
                F[i, q] = min(max(F[i, q], lower[q]), upper[q])
                if not np.isfinite(F[i, q]):
                    ok[i] = False
            n_ok += ok[i]
        out = np.full(kk, np.inf)
        if n_ok == kk:
            _kernel(F, kargs, max(1, min(kk, threads)), out)
        elif n_ok > 0:
            Fg = np.empty((n_ok, D))
            j = 0
            for i in range(kk):
                if ok[i]:
                    Fg[j] = F[i]
                    j += 1
            og = np.empty(n_ok)
            _kernel(Fg, kargs, max(1, min(n_ok, threads)), og)
            j = 0
            for i in range(kk):
                if ok[i]:
                    out[i] = og[j]
                    j += 1
        for i in range(kk):
            if out[i] < 0.0:
                return x, best, best_x, X, W, used, bad, -1
        if kp.scale > 0.0:
            ek = np.empty(kk)
            _kp.keypoint_batch(F, kp.parents, kp.offsets, kp.ptr, kp.dofs, kp.axes, kp.joints, kp.dirs, kp.moms,
                               kp.weights, kp.sigma, ek)
            for i in range(kk):
                out[i] = out[i] + kp.scale * (ek[i] if ok[i] else np.inf)
        E = np.full(n, np.inf)
        for i in range(kk):                               # check_energies: non-finite to +inf, counted
            if np.isfinite(out[i]):
                E[i] = out[i]
            else:
                bad += 1
        used += kk
        i = np.argmin(E)
        if E[i] < best:
            best = E[i]
            best_x = X[i].copy()
        Xn, x, beta, W, ess = _tell(X, E, rng, beta, target, kernel, c, rho, lo, hi, population, block)
        mean_energy, spread_g = _fast.generation_stats(E, X)
        hist[g, 0] = used
        hist[g, 1] = best
        hist[g, 2] = mean_energy
        hist[g, 3] = spread_g
        hist[g, 4] = beta
        hist[g, 5] = ess
        g += 1
        P = X
        X = Xn
    return x, best, best_x, P, W, used, bad, g


def supported_moved(opt, energy) -> bool:
    """True when :func:`run_isa_moved` covers ``opt`` on the data energy ``energy`` (a scanline or sampled
    :class:`~isa_mocap_ros.energy.silhouette.SilhouetteEnergy` with masks; a flat ISA as
    :func:`~.compiled_search.supported_flat` takes); the caller checks that no prior is added."""
    from isa_mocap_ros.energy.silhouette import SilhouetteEnergy

    return (type(energy) is SilhouetteEnergy and energy.method != "exact" and energy.has_masks
            and supported_flat(opt))


def run_isa_moved(opt, energy, max_evals: int, *, move: tuple, coords, limits, restricted=None, keypoints=None):
    """``run_isa(opt, lambda C: objective(clip(move(C), *limits)), max_evals)`` in one compiled call, or None when
    this path does not cover it (then run that through :func:`~.compiled_search.run_isa`).

    ``opt``: an unbound flat :class:`~isa_mocap_ros.optim.Isa` (:func:`~.compiled_search.supported_flat`) over the
    move's coordinates; ``energy``: the :class:`~isa_mocap_ros.energy.silhouette.SilhouetteEnergy` of the objective
    (the scanline or sampled kernel; no prior); ``restricted``: the energy restricted to the coordinates the move
    changes (:meth:`~isa_mocap_ros.energy.silhouette.SilhouetteEnergy.restrict` of the move's base pose; None: the
    full energy); ``move``, ``coords``: :meth:`~isa_mocap_ros.tracking.reaim.ReaimMove.kernel_args` and
    :attr:`~isa_mocap_ros.tracking.reaim.ReaimMove.coords`; ``limits``: ``(lower, upper)`` of the poses;
    ``keypoints``: ``(KeypointEnergy, weight)`` or None. Evaluations count in ``energy.n_evals`` (and the keypoint
    term's) as the Python path counts them."""
    if not supported_moved(opt, energy):
        return None
    n, max_evals = opt.n, int(max_evals)
    if max_evals < n:
        raise OptimError(f"max_evals: budget {max_evals} (remaining {max_evals}) is smaller than one generation "
                         f"of isa ({n} evaluations)")
    rest = restricted if restricted is not None and not restricted.full else None
    kargs = rest.kernel_args() if rest is not None else energy.kernel_args()
    term = keypoints[0] if keypoints is not None else None
    kp = term.kernel_term(keypoints[1]) if term is not None else _kp.no_keypoints(energy.kin_tables)
    block = opt.rotation_blocks[0][0] if opt.rotation_blocks else -1
    lower, upper = (np.ascontiguousarray(a, dtype=np.float64) for a in limits)
    hist = np.empty((-(-max_evals // n), 6))
    x, best, best_x, P, W, used, bad, g = _moved_isa(
        opt.x0, opt.spread, opt.lo, opt.hi, n, max_evals, opt.rng, float(opt.schedule.target), _KERNELS[opt.kernel],
        opt.c_cov, opt.rho, opt.variance == "population", block, np.ascontiguousarray(coords, dtype=np.int64),
        lower, upper, move, energy.threads, kargs, kp, hist)
    energy.n_evals += used
    if term is not None:
        term.n_evals += used
    if g < 0:
        raise rest.violation(P, np.arange(len(P)))
    history = tuple(GenerationInfo(n_iter=i + 1, n_evals=int(hist[i, 0]), best_energy=float(hist[i, 1]),
                                   mean_energy=float(hist[i, 2]), spread=float(hist[i, 3]), beta=float(hist[i, 4]),
                                   ess=float(hist[i, 5])) for i in range(g))
    return Result(x=np.array(x, dtype=float), best_x=best_x.copy(), energy=float(best), best_energy=float(best),
                  n_evals=used, n_iter=g, reason=f"max_evals={max_evals}", population=np.array(P, dtype=float),
                  weights=np.array(W, dtype=float), history=history, n_nonfinite=bad)
