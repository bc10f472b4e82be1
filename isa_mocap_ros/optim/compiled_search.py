"""H-ISA on the fast silhouette energy with every generation compiled: the tracker's default search.

The tracker's frame search is :class:`~isa_mocap_ros.optim.Hierarchical` over :class:`~isa_mocap_ros.optim.Isa`
(``h-isa``, ~45 generations of 30 particles per frame) on the restricted silhouette energy of each
partition. Through the optimizer protocol each generation is a dozen Python calls around the compiled
pieces (ask, embed, check, kernel, record, weights, estimate, selection, mutation, diagnostics): about
a fifth of a tracked frame's time went there. :func:`run_hisa` runs the same algorithm with one compiled
call per partition: the same compiled helpers (:mod:`isa_mocap_ros.optim._fast`,
:mod:`~isa_mocap_ros.optim._fast_so3`), the same energy kernels, the same random draws from the same
``numpy.random.Generator`` (numba draws from its state exactly as numpy does), in the same order — so
the result is the protocol's, bit for bit (``test/test_compiled_search.py`` checks estimates, best
particles, energies, diagnostics and the generator's state afterwards). What it covers, and the
tracker checks before using it (:func:`supported`): inner ISA with multinomial replacement (kernels
S1/S2/S3, either variance reading) and the adaptive schedule, the fast energy, no prior, no initial
population; anything else runs through the protocol. :func:`run_isa` does the same for a flat ISA
whose energy stays a Python callable (the tracker's pelvis stage): one compiled call per generation
for everything but the energy.
"""
from __future__ import annotations

import numba
import numpy as np
from numba.extending import overload

from isa_mocap_ros.body import kinematics as _kinematics
from isa_mocap_ros.energy import keypoint_kernel as _kp
from isa_mocap_ros.energy import raster_kernel as _rk
from isa_mocap_ros.energy import silhouette_kernel as _k
from isa_mocap_ros.numba_cache import register_dependent_cache
from isa_mocap_ros.optim import _fast, _fast_so3
from isa_mocap_ros.optim._base import GenerationInfo, Result
from isa_mocap_ros.optim.isa import C_SCALES, VARIANCE_READINGS, covariance_constant

__all__ = ["supported", "run_hisa", "HisaRun", "supported_flat", "run_isa", "rotation_mean"]


#: The modules whose compiled functions the functions here call (their hashes, and those of the files they depend on,
#: key this module's numba cache: :func:`isa_mocap_ros.numba_cache.register_dependent_cache`).
DEPENDENCIES = (_k, _rk, _kp, _kinematics, _fast, _fast_so3)


register_dependent_cache(__file__, DEPENDENCIES)

#: Inner ISA parameters this path implements (others: the protocol).
_PARAMS = {"n_particles", "kernel", "schedule", "target_ess", "c", "c_scale", "rho", "variance", "resampling"}
_KERNELS = {"s1": 1, "s2": 2, "s3": 3}


def supported(opt, energy, prior_active: bool) -> bool:
    """True when ``opt`` (an unbound :class:`~isa_mocap_ros.optim.Hierarchical`) and ``energy`` are what
    :func:`run_hisa` implements."""
    from isa_mocap_ros.energy.silhouette import SilhouetteEnergy
    from isa_mocap_ros.optim import Hierarchical

    if prior_active or type(energy) is not SilhouetteEnergy or energy.method == "exact" or not energy.has_masks:
        return False
    if type(opt) is not Hierarchical or getattr(opt, "inner_name", None) != "isa" or opt.n_iter != 0:
        return False
    p = opt.params
    return (set(p) <= _PARAMS and p.get("kernel", "s1") in _KERNELS and p.get("schedule") == "adaptive"
            and p.get("resampling", "multinomial") == "multinomial" and opt.initial_population is None
            and opt.init == "normal" and opt.max_iter is None
            and p.get("variance", VARIANCE_READINGS[0]) in VARIANCE_READINGS
            and p.get("c_scale", C_SCALES[0]) in C_SCALES)


@numba.njit(cache=True)
def rotation_mean(r, weights, n_iter, tol):  # pragma: no cover - compiled
    """:func:`isa_mocap_ros.optim._rotations.rotation_mean` (13.24, then the representative nearest to
    the start, ``geometry.nearest_rotvec``) of rotation vectors ``r (n, 3)``, compiled."""
    w = weights / _fast.pairwise_sum(weights)
    Ri = _fast_so3.exp_many(r)
    start = r[np.argmax(w)].copy()
    mean = start.copy()
    for _ in range(n_iter):
        delta = _fast_so3.relative_logs(mean, Ri)
        step = np.dot(w, delta)
        mean = _fast_so3.compose(mean, step)
        if np.dot(step, step) < tol:
            break
    theta = np.sqrt(np.dot(mean, mean))
    if theta < 1e-12:
        return mean
    axis = mean / theta
    m = np.round((np.dot(axis, start) - theta) / (2.0 * np.pi))
    if m == 0:
        return mean
    return axis * (theta + 2.0 * np.pi * m)


@numba.njit(cache=True)
def _tell(XF, E, rng, beta_prev, target, kernel, c, rho, lo, hi, population, block):  # pragma: no cover
    """``Isa._tell`` (weights by the adaptive schedule, never decreasing; the weighted estimate with the
    rotation mean of the local triple at ``block`` (< 0: none); fused selection and mutation) for
    particles ``XF (n, d)`` (F order, as the hierarchy hands them over; C order for a flat run) with
    energies ``E``. Returns (next particles, estimate, beta, weights, ESS)."""
    beta = _fast.adaptive_beta(E, target, 1e12, 1e-6)
    if np.isfinite(beta_prev):
        beta = max(beta, beta_prev)
    n = E.size
    W = np.empty(n)
    ess = _fast.annealed_weights(E, beta, W)
    x = np.dot(W, XF)
    if block >= 0:
        x[block:block + 3] = rotation_mean(np.ascontiguousarray(XF[:, block:block + 3]), W, 20, 1e-12)
    keep = np.zeros(n, np.bool_)
    k = n
    if kernel != 1:
        k = _fast.keep_mask(W, rng.random(n), kernel == 3, keep)
    v = rng.random(k)
    v.sort()
    Z = rng.standard_normal((n, XF.shape[1]))
    return _fast.select_mutate(XF, W, keep, v, Z, c, rho, lo, hi, population), x, beta, W, ess


@numba.njit(cache=True)
def _start(x0, spread, lo, hi, n, rng):  # pragma: no cover - compiled
    """``Optimizer._draw_initial``: ``clip(x0 + Z * spread)``, ``Z`` standard normal ``(n, d)``."""
    Z = rng.standard_normal((n, x0.size))
    X = np.empty((n, x0.size))
    for i in range(n):
        for q in range(x0.size):
            X[i, q] = min(max(x0[q] + Z[i, q] * spread[q], lo[q]), hi[q])
    return X


@numba.njit(cache=True)
def _record(E, kk, X, best, best_x, stats, g, n_evals):  # pragma: no cover - compiled
    """After a generation's kernel call on the full particles ``X``: non-finite energies to +inf
    (counted), the truncated rows +inf, the best particle, the hierarchy's diagnostics row ``stats[g]``
    (n_evals, best energy, mean finite energy, spread of the full particles). Returns the number of
    non-finite energies."""
    bad = 0
    for i in range(kk):
        if not np.isfinite(E[i]):
            E[i] = np.inf
            bad += 1
    for i in range(kk, E.size):
        E[i] = np.inf
    i = np.argmin(E)
    if E[i] < best[0]:
        best[0] = E[i]
        best_x[:] = X[i]
    mean_energy, spread = _fast.generation_stats(E, X)
    stats[g, 0] = n_evals
    stats[g, 1] = best[0]
    stats[g, 2] = mean_energy
    stats[g, 3] = spread
    return bad


@numba.njit(cache=True)
def _embed(xbase, idx, Xs):  # pragma: no cover - compiled
    """The full particles: ``xbase`` in every row, ``Xs`` in the columns ``idx``."""
    n = Xs.shape[0]
    X = np.empty((n, xbase.size))
    for i in range(n):
        X[i, :] = xbase
        for q in range(idx.size):
            X[i, idx[q]] = Xs[i, q]
    return X


def _kernel(X, kargs, n_chunks, out):  # pragma: no cover - compiled only (see the overload below)
    """``silhouette_batch`` or ``silhouette_restricted`` of ``X`` with their arguments ``kargs`` (between
    the poses and ``n_chunks``), or the scanline kernels ``raster_batch`` / ``raster_restricted``, told apart by
    the number of arguments when numba compiles the caller."""
    raise NotImplementedError("compiled_search._kernel is for compiled code only")


_N_BATCH = _k.silhouette_batch.py_func.__code__.co_argcount - 3          # without X, n_chunks, out
_N_RESTRICTED = _k.silhouette_restricted.py_func.__code__.co_argcount - 3
_N_RASTER = _rk.raster_batch.py_func.__code__.co_argcount - 3
_N_RASTER_RESTRICTED = _rk.raster_restricted.py_func.__code__.co_argcount - 3
assert len({_N_BATCH, _N_RESTRICTED, _N_RASTER, _N_RASTER_RESTRICTED}) == 4


@overload(_kernel)
def _kernel_overload(X, kargs, n_chunks, out):
    # chosen from the argument tuple's type at compile time: the kernels are called by name (a kernel
    # passed as an argument would key numba's cache on the dispatcher object, i.e. compile again in
    # every process), and one partition loop serves both
    if len(kargs) == _N_RESTRICTED:
        def restricted(X, kargs, n_chunks, out):
            _k.silhouette_restricted(X, *kargs, n_chunks, out)
        return restricted
    if len(kargs) == _N_BATCH:
        def batch(X, kargs, n_chunks, out):
            _k.silhouette_batch(X, *kargs, n_chunks, out)
        return batch
    if len(kargs) == _N_RASTER_RESTRICTED:
        def raster_restricted(X, kargs, n_chunks, out):
            _rk.raster_restricted(X, *kargs, n_chunks, out)
        return raster_restricted
    if len(kargs) == _N_RASTER:
        def raster(X, kargs, n_chunks, out):
            _rk.raster_batch(X, *kargs, n_chunks, out)
        return raster
    return None


@numba.njit(cache=True)
def _partition(xbase, idx, x0, spread, lo, hi, share, n, rng, target, kernel, c, rho, population, block,
               best, best_x, stats, g0, n_evals0, threads, kargs, kp, kargs_c, kargs_c2, n_coarse):  # pragma: no cover
    """One partition of the hierarchy, evaluated with the full kernel or the restricted one (``kargs``:
    its arguments between the poses and ``n_chunks``, :func:`_kernel`), plus ``kp.scale`` times the keypoint
    term ``kp`` (:class:`~isa_mocap_ros.energy.keypoint_kernel.KeypointTerm`; scale 0: none) as the tracker's
    objective adds it (``E + w * keypoints(X)``). The first ``n_coarse`` generations are evaluated with ``kargs_c``
    and ``kargs_c2`` in turn instead (the coarse level: the sampled kernel's two pairs of views, the scanline kernel's
    every second row, :meth:`~isa_mocap_ros.energy.silhouette.SilhouetteEnergy.coarse_kernel_args`; the same kernel
    kind) and leave the
    best particle alone. Returns (estimate, generations,
    evaluations, non-finite, last full particles); -1 generations if the kernel flagged a row with a
    negative energy (the restricted kernel's mark of a row off its base pose: never, by construction)."""
    Xs = _start(x0, spread, lo, hi, n, rng)
    used = 0
    g = g0
    bad = 0
    beta = np.nan
    x = x0.copy()
    X = _embed(xbase, idx, Xs)
    while used < share:
        kk = min(n, share - used)
        X = _embed(xbase, idx, Xs)
        E = np.empty(n)
        out = np.empty(kk)
        Xk = X if kk == n else X[:kk].copy()
        coarse = g - g0 < n_coarse
        if coarse and (g - g0) % 2 == 1:
            _kernel(Xk, kargs_c2, max(1, min(kk, threads)), out)
        elif coarse:
            _kernel(Xk, kargs_c, max(1, min(kk, threads)), out)
        else:
            _kernel(Xk, kargs, max(1, min(kk, threads)), out)   # a chunk per thread (energy._fast)
        for i in range(kk):
            if out[i] < 0.0:
                return x, -1, used, bad, X
        if kp.scale > 0.0:
            ek = np.empty(kk)
            _kp.keypoint_batch(Xk, kp.parents, kp.offsets, kp.ptr, kp.dofs, kp.axes, kp.joints, kp.dirs, kp.moms,
                               kp.weights, kp.sigma, ek)
            for i in range(kk):
                out[i] = out[i] + kp.scale * ek[i]
        E[:kk] = out
        used += kk
        if coarse:      # a coarse energy is not compared with the full ones
            bad += _record(E, kk, X, np.full(1, np.inf), X[0].copy(), stats, g, n_evals0 + used)
        else:
            bad += _record(E, kk, X, best, best_x, stats, g, n_evals0 + used)
        Xs, x, beta, _, _ = _tell(np.asfortranarray(Xs), E, rng, beta, target, kernel, c, rho, lo, hi, population,
                                  block)
        g += 1
    return x, g - g0, used, bad, X


class HisaRun:
    """``opt.bind(energy, max_evals=...)`` then generations, compiled per partition: :meth:`advance` runs
    partitions up to an index (the tracker's first frame pauses its candidate runs after the first
    partition), :meth:`result` is ``opt.result()`` once every partition ran. The same draws from
    ``opt.rng`` as the protocol. Counts the evaluations in ``energy.n_evals`` as the protocol does."""

    def __init__(self, opt, energy, max_evals: int, keypoints=None, coarse_fraction: float = 0.0) -> None:
        from isa_mocap_ros.optim import split_budget
        from isa_mocap_ros.optim._base import OptimError

        p = opt.params
        self.n = n = int(p.get("n_particles", 50))
        self.kernel = _KERNELS[p.get("kernel", "s1")]
        self.target = float(p.get("target_ess", 0.5))
        self.c = float(p.get("c", 0.8))
        self.rho = float(p.get("rho", 1e-4))
        self.population = p.get("variance", "population") == "population"
        if n < 2 or not (0.0 < self.target <= 1.0) or not self.c > 0 or not self.rho >= 0:
            raise OptimError(f"h-isa parameters out of range: n_particles={n}, target_ess={self.target}, "
                             f"c={self.c}, rho={self.rho}")
        self.c = covariance_constant(self.c, p.get("c_scale", C_SCALES[0]))     # Isa.c_cov
        self.opt, self.energy, self.max_evals = opt, energy, int(max_evals)
        if not 0.0 <= coarse_fraction < 1.0:
            raise OptimError(f"coarse_fraction: expected a fraction in [0, 1), received {coarse_fraction!r}")
        self.coarse_fraction = float(coarse_fraction)
        self.keypoint_term = keypoints[0] if keypoints is not None else None
        self.kp = (self.keypoint_term.kernel_term(keypoints[1]) if keypoints is not None
                   else _kp.no_keypoints(energy.kin_tables))
        self.parts = opt.partitions
        self.shares = split_budget(self.max_evals, [len(q) for q in self.parts],
                                   [self.n] * len(self.parts) if opt.whole_generations else None)
        if min(self.shares) < n:
            k = int(np.argmin(self.shares))
            raise OptimError(f"max_evals: partition {k} ({len(self.parts[k])} coordinates) gets {self.shares[k]} "
                             f"evaluations, fewer than one generation of isa ({n})")
        self.blocks = []
        for q in self.parts:
            local = {int(i): j for j, i in enumerate(q.tolist())}
            own = [blk for blk in opt.rotation_blocks if set(blk) <= set(local)]
            if len(own) > 1 or (own and [local[i] for i in own[0]] != list(range(local[own[0][0]],
                                                                                 local[own[0][0]] + 3))):
                raise OptimError("rotation_blocks: the compiled h-isa takes at most one consecutive triple per "
                                 "partition")
            self.blocks.append(local[own[0][0]] if own else -1)
        self.xbase = opt.x0.copy()
        self.best = np.array([np.inf])
        self.best_x = opt.x0.copy()
        self.stats = np.empty((sum(-(-s // n) for s in self.shares), 4))
        self.k = self.g = self.n_evals = self.bad = 0
        self.X = None

    @property
    def best_energy(self) -> float:
        return float(self.best[0])

    def advance(self, to: int | None = None) -> "HisaRun":
        """Run the partitions up to (not including) ``to`` (default: all)."""
        energy, opt = self.energy, self.opt
        stop = len(self.parts) if to is None else min(int(to), len(self.parts))
        while self.k < stop:
            k = self.k
            idx = np.ascontiguousarray(self.parts[k], dtype=np.int64)
            lo, hi = np.ascontiguousarray(opt.lo[idx]), np.ascontiguousarray(opt.hi[idx])
            x0 = np.clip(self.xbase[idx], lo, hi)
            rest = energy.restrict(self.xbase.copy(), idx.copy())
            args = (self.xbase, idx, x0, np.ascontiguousarray(opt.spread[idx]), lo, hi, self.shares[k], self.n,
                    opt.rng, self.target, self.kernel, self.c, self.rho, self.population, self.blocks[k], self.best,
                    self.best_x, self.stats, self.g, self.n_evals, energy.threads)
            kargs = energy.kernel_args() if rest.full else rest.kernel_args()
            n_coarse = int(self.coarse_fraction * (-(-self.shares[k] // self.n)))
            kc = [kargs if n_coarse <= i else (energy.coarse_kernel_args(i == 1) if rest.full
                                               else rest.coarse_kernel_args(i == 1)) for i in (0, 1)]
            x, gens, used, nb, self.X = _partition(*args, kargs, self.kp, kc[0], kc[1], n_coarse)
            if gens < 0:
                raise rest.violation(self.X, np.flatnonzero(np.any(self.X != rest.x_base, axis=1)))
            energy.n_evals += used
            if self.keypoint_term is not None:
                self.keypoint_term.n_evals += used
            self.xbase[idx] = x
            self.g += gens
            self.n_evals += used
            self.bad += nb
            self.k += 1
        return self

    def result(self) -> Result:
        s = self.stats
        history = tuple(GenerationInfo(n_iter=i + 1, n_evals=int(s[i, 0]), best_energy=float(s[i, 1]),
                                       mean_energy=float(s[i, 2]), spread=float(s[i, 3])) for i in range(self.g))
        e = float(self.best[0])
        return Result(x=self.xbase.copy(), best_x=self.best_x.copy(), energy=e, best_energy=e, n_evals=self.n_evals,
                      n_iter=self.g, reason=f"max_evals={self.max_evals}, partitions={len(self.parts)}",
                      population=np.array(self.X, dtype=float), weights=None, history=history,
                      n_nonfinite=self.bad)


def search(opt, energy, max_evals: int, *, extra_terms: bool = False, keypoints=None, paused: bool = False,
           coarse_fraction: float = 0.0):
    """The entry point: ``minimize(opt, energy, max_evals=max_evals)`` compiled, or None when this path does
    not cover ``opt`` and ``energy`` (then run it through the optimizer protocol, :func:`~.minimize`).

    An unbound :class:`~isa_mocap_ros.optim.Hierarchical` over ISA on the fast
    :class:`~isa_mocap_ros.energy.silhouette.SilhouetteEnergy` (:func:`supported`; ``extra_terms``: the
    energy is not the whole objective, a prior is added in Python, so not covered) runs
    compiled per partition, with ``keypoints = (KeypointEnergy, weight)`` adding ``weight`` times that term
    (compiled too, :mod:`~isa_mocap_ros.energy.keypoint_kernel`); with ``paused`` it is returned as a :class:`HisaRun` stopped before its first
    partition (``advance()``, ``result()``: the first frame's pruned runs); ``coarse_fraction`` of each partition's
    generations (rounded down) are evaluated on the energy's coarse level first (sampled: two views, the two pairs in
    turn; scanline: every second pixel row,
    :meth:`~isa_mocap_ros.energy.silhouette.SilhouetteEnergy.coarse_kernel_args`; 0: none, the protocol's numbers). A flat
    :class:`~isa_mocap_ros.optim.Isa` (:func:`supported_flat`) on any batch energy runs with compiled
    generations (:func:`run_isa`). The numbers are the protocol's, bit for bit."""
    from isa_mocap_ros.optim import Hierarchical

    if type(opt) is Hierarchical:
        if not supported(opt, energy, extra_terms):
            return None
        run = HisaRun(opt, energy, max_evals, keypoints, coarse_fraction)
        return run if paused else run.advance().result()
    if paused or extra_terms or keypoints is not None or not supported_flat(opt):
        return None
    return run_isa(opt, energy, max_evals)


def run_hisa(opt, energy, max_evals: int) -> Result:
    """``minimize(opt, energy, max_evals=max_evals)`` for what :func:`supported` accepts (:class:`HisaRun`)."""
    return HisaRun(opt, energy, max_evals).advance().result()


def supported_flat(opt) -> bool:
    """True when ``opt`` (an unbound :class:`~isa_mocap_ros.optim.Isa`) is what :func:`run_isa` implements."""
    from isa_mocap_ros.optim import Isa
    from isa_mocap_ros.optim.schedules import AdaptiveEss

    blocks = opt.rotation_blocks if isinstance(opt, Isa) else ()
    return (type(opt) is Isa and opt.n_iter == 0 and opt.fused and isinstance(opt.schedule, AdaptiveEss)
            and opt.kernel in _KERNELS and opt.initial_population is None and opt.init == "normal"
            and opt.max_iter is None and len(blocks) <= 1
            and all(list(b) == list(range(b[0], b[0] + 3)) for b in blocks))


def run_isa(opt, energy, max_evals: int) -> Result:
    """``minimize(opt, energy, max_evals=max_evals)`` for a flat ISA that :func:`supported_flat` accepts:
    ``energy`` (any batch energy) is called from Python once per generation, everything else of a
    generation (weights, estimate, selection, mutation) in one compiled call (:func:`_tell`). The
    same :class:`~isa_mocap_ros.optim.Result` (history included) and draws from ``opt.rng``."""
    from isa_mocap_ros.optim._base import OptimError, check_energies

    n, max_evals = opt.n, int(max_evals)
    if max_evals < n:
        raise OptimError(f"max_evals: budget {max_evals} (remaining {max_evals}) is smaller than one generation "
                         f"of isa ({n} evaluations)")
    kernel = _KERNELS[opt.kernel]
    target = float(opt.schedule.target)
    block = opt.rotation_blocks[0][0] if opt.rotation_blocks else -1
    population = opt.variance == "population"
    X = _start(opt.x0, opt.spread, opt.lo, opt.hi, n, opt.rng)
    used = bad = 0
    best, best_x = np.inf, opt.x0.copy()
    beta = np.nan
    x = W = P = None
    history = []
    while used < max_evals:
        kk = min(n, max_evals - used)
        E, nb = check_energies(energy(X[:kk]), kk)
        if kk < n:
            E = np.concatenate([E, np.full(n - kk, np.inf)])
        used += kk
        bad += nb
        i = int(E.argmin())
        if E[i] < best:
            best, best_x = float(E[i]), X[i].copy()
        Xn, x, beta, W, ess = _tell(X, E, opt.rng, beta, target, kernel, opt.c_cov, opt.rho, opt.lo, opt.hi,
                                    population, block)
        mean_energy, spread = _fast.generation_stats(E, X)
        history.append(GenerationInfo(n_iter=len(history) + 1, n_evals=used, best_energy=float(best),
                                      mean_energy=float(mean_energy), spread=float(spread), beta=float(beta),
                                      ess=float(ess)))
        P, X = X, Xn
    return Result(x=np.array(x, dtype=float), best_x=best_x.copy(), energy=float(best), best_energy=float(best),
                  n_evals=used, n_iter=len(history), reason=f"max_evals={max_evals}",
                  population=np.array(P, dtype=float), weights=np.array(W, dtype=float), history=tuple(history),
                  n_nonfinite=bad)
