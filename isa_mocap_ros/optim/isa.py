"""Interacting simulated annealing (ISA), gall_isa_introduction §13.3, Algorithm 6.

One generation ``t``:

1. weights ``pi_i = exp(-beta_t V(x_i))`` (log-sum-exp normalised), ``beta_t`` from the
   annealing scheme: polynomial (13.19), logarithmic (13.18) or adaptive (target ESS);
2. the estimate: weighted mean ``sum_i W_i x_i``, with rotation-vector triples averaged on SO(3)
   by the fixed-point iteration (13.24);
3. selection by kernel S1 (13.8), S2 (13.9) or S3 (13.10) (:mod:`.resampling`);
4. mutation by the dynamic variance scheme (13.16): Gaussian, diagonal covariance ``Sigma_t``, added
   to the selected particles.

Two readings of (13.16) (``variance=``). The equation as printed, ``"population"`` (default):
``Sigma_kk = c / (n - 1) * sum_i max(x_ik - mu_k, rho)^2`` over the generation's particles ``x_t``
(before selection; ``mu_t`` their plain mean) with the floor ``((x)_rho)_k = max(x_k, rho)`` applied
to the signed deviation, exactly as written. The text around it ("proportional to the sample
covariance after resampling"), ``"selected"``: ``c / (n - 1) * sum_i max(|x~_ik - mu_k|, rho)^2``
over the selected particles ``x~_t``. Measured on the Ackley protocol (docs/optimizers.md, 300 runs
per row): the printed equation reaches the minimum in every run of every row of Tables 13.1-13.2
and keeps small populations searching (S1, n = 10: 93 % vs 42 %, the book: 100 % for n >= 10);
after selection a population of n <= 30 can collapse onto a local minimum in two steps, and S3 with
n = 28 misses it in ~1 % of runs.

What ``c`` multiplies (``c_scale=``). In (13.16) it multiplies the covariance, ``"covariance"``
(default): the mutation's standard deviation is ``sqrt(c)`` times the particles'. The book's Fig. 13.13
plots "the standard deviations ..., which are scaled by c", ``"deviation"``: ``Sigma_t`` is ``c^2``
times the sum, the standard deviation ``c`` times the particles'. The same family of kernels (``c``
with ``"deviation"`` is ``c^2`` with ``"covariance"``, to the bit); it matters only when taking ``c``
from the book. On the Ackley protocol the book's c is the deviation's: there the best ``c`` at its
``b`` lies at 0.6-0.7 (the book: 0.7-0.8, "c in the range 0.5-1.0"), with ``"covariance"`` at 0.3-0.5,
and the noiseless rows of the book's Tables 13.1-13.2 at its b, c, n come within -9..+19 % of its mean steps
over 600 runs each (docs/optimizers.md, "What the book's c multiplies").

Steps 1, 3 and 4 run compiled (:mod:`._fast`; 3 and 4 fused for multinomial replacement) with the
random numbers drawn here, from the optimizer's generator and in the order of the numpy
formulation, which is kept for the other resampling schemes and as the reference; the rotation mean
of step 2 uses the compiled SO(3) maps of :mod:`._fast_so3`. ``test/test_optim_compiled.py``
checks that the runs are bit-identical to the numpy formulation.
"""
from __future__ import annotations

import math

import numpy as np

from . import _fast
from ._base import OptimError, ParticleOptimizer
from ._rotations import rotation_mean
from .resampling import SCHEMES, SELECTION_KERNELS, multinomial
from .schedules import AdaptiveEss, make_schedule

__all__ = ["Isa", "weighted_estimate", "dynamic_variance", "covariance_constant", "VARIANCE_READINGS", "C_SCALES"]

#: Readings of the dynamic variance scheme (13.16); the first is the default (module doc).
VARIANCE_READINGS = ("population", "selected")
#: What the constant ``c`` of (13.16) multiplies; the first is the default (module doc).
C_SCALES = ("covariance", "deviation")


def covariance_constant(c: float, c_scale: str) -> float:
    """The constant (13.16)'s covariance is multiplied with for ``c`` and ``c_scale`` (module doc): ``c``
    on the covariance, ``c^2`` when ``c`` scales the standard deviation."""
    return c if c_scale == "covariance" else c * c


def weighted_estimate(X: np.ndarray, W: np.ndarray, rotation_blocks=()) -> np.ndarray:
    """Weighted mean ``(d,)`` of ``X : (n, d)`` with weights ``W : (n,)``; coordinates in
    ``rotation_blocks`` (index triples) are averaged with :func:`rotation_mean` (13.24)."""
    x = W @ X
    for blk in rotation_blocks:
        idx = list(blk)
        x[idx] = rotation_mean(X[:, idx], W)
    return x


def dynamic_variance(X: np.ndarray, c: float, rho: float, *, one_sided: bool = False) -> np.ndarray:
    """Diagonal of the dynamic-variance covariance (13.16), ``(d,)``, of particles ``X : (n, d)``:
    ``c / (n - 1) * sum_i dev_i^2`` with ``dev = max(x - mu, rho)`` (``one_sided``, as printed) or
    ``max(|x - mu|, rho)``."""
    n = X.shape[0]
    d = X - X.mean(axis=0)
    dev = np.maximum(d if one_sided else np.abs(d), rho)
    return c / max(n - 1, 1) * np.sum(dev * dev, axis=0)


class Isa(ParticleOptimizer):
    """Interacting simulated annealing (Algorithm 6).

    Parameters
    ----------
    x0, spread, bounds, rng, initial_population, rotation_blocks, init, max_iter
        See :class:`Optimizer`.
    n_particles : int
        Particles ``n`` (default 50, as in Table 13.1).
    kernel : {"s1", "s2", "s3"}
        Selection kernel (13.8) / (13.9) / (13.10).
    schedule : {"polynomial", "logarithmic", "adaptive"} or callable ``(t, E) -> beta``
        Annealing scheme (13.19) / (13.18) / target-ESS.
    b : float, optional
        Schedule parameter (polynomial default 0.993, logarithmic default 2).
    target_ess : float
        ESS fraction for the adaptive schedule (default 0.5); the adaptive beta never decreases.
    c : float
        Dynamic-variance constant (13.16), default 0.8.
    c_scale : {"covariance", "deviation"}
        What ``c`` multiplies: the covariance, as (13.16) prints it (default), or the standard
        deviation, as the book's Fig. 13.13 and its Ackley tables take it (``Sigma_t`` gets ``c^2``).
    rho : float
        Floor of the deviations in (13.16), default 1e-4.
    variance : {"population", "selected"}
        Reading of (13.16): the generation's particles with the printed one-sided floor
        (default) or the selected particles with a floor on the deviation's magnitude (module doc).
    resampling : {"multinomial", "residual", "stratified", "systematic"}
        Scheme used for the replaced particles (the paper: multinomial).
    """

    name = "isa"
    has_weights = True

    def __init__(self, x0, spread, *, n_particles: int = 50, kernel: str = "s1",
                 schedule="polynomial", b: float | None = None, target_ess: float = 0.5,
                 c: float = 0.8, c_scale: str = "covariance", rho: float = 1e-4,
                 variance: str = "population", resampling: str = "multinomial", **kw):
        super().__init__(x0, spread, **kw)
        n = int(n_particles) if self._initial_population is None or n_particles != 50 \
            else self._initial_population.shape[0]
        if n < 2:
            raise OptimError(f"n_particles: expected >= 2, got {n_particles}")
        self.n = n
        if kernel not in SELECTION_KERNELS:
            raise OptimError(f"kernel: expected one of {sorted(SELECTION_KERNELS)}, got {kernel!r}")
        self.kernel = kernel
        self._select = SELECTION_KERNELS[kernel]
        if resampling not in SCHEMES:
            raise OptimError(f"resampling: expected one of {sorted(SCHEMES)}, got {resampling!r}")
        self._scheme = SCHEMES[resampling]
        # selection + variance + mutation compiled in one step (multinomial replacement only)
        self._fused = self._scheme is multinomial
        self.schedule = make_schedule(schedule, b=b, target=target_ess)
        self._monotone = isinstance(self.schedule, AdaptiveEss)
        if not (c > 0):
            raise OptimError(f"c: expected > 0, got {c}")
        if not (rho >= 0):
            raise OptimError(f"rho: expected >= 0, got {rho}")
        if c_scale not in C_SCALES:
            raise OptimError(f"c_scale: expected one of {list(C_SCALES)}, got {c_scale!r}")
        self.c, self.c_scale, self.rho = float(c), c_scale, float(rho)
        #: the constant the covariance of (13.16) is multiplied with
        self.c_cov = covariance_constant(self.c, c_scale)
        if variance not in VARIANCE_READINGS:
            raise OptimError(f"variance: expected one of {list(VARIANCE_READINGS)}, got {variance!r}")
        self.variance = variance
        self._X: np.ndarray | None = None   # next particles to evaluate
        self._P: np.ndarray | None = None   # last evaluated particles
        self._W: np.ndarray | None = None   # their normalised weights
        self._x = self.x0.copy()
        self.beta = float("nan")
        self._ess = float("nan")

    @property
    def fused(self) -> bool:
        """Whether selection, variance and mutation run as one compiled step (multinomial resampling)."""
        return self._fused

    @property
    def generation_size(self) -> int:
        return self.n

    def _ask(self):
        if self._X is None:
            self._X = self._draw_initial(self.n)
        return self._X

    def weights(self, E: np.ndarray) -> np.ndarray:
        """Normalised weights ``exp(-beta_t E)`` of this generation (sets ``self.beta`` and the ESS)."""
        E = np.ascontiguousarray(E, dtype=float)
        beta = float(self.schedule(self.n_iter, E))
        if self._monotone and math.isfinite(self.beta):
            beta = max(beta, self.beta)
        self.beta = beta
        W = np.empty(E.size)
        self._ess = float(_fast.annealed_weights(E, beta, W))
        return W

    def _tell(self, X, E):
        W = self.weights(E)                                        # pi_i (13.18/13.19 or target ESS)
        self._P, self._W = X, W
        self._x = weighted_estimate(X, W, self.rotation_blocks)    # estimate, rotations by (13.24)
        if self._fused:
            self._X = self._select_mutate(X, W)
            return
        A = self._select(W, self.rng, scheme=self._scheme)        # selection (13.8-13.10)
        Xs = X[A]
        population = self.variance == "population"
        var = dynamic_variance(X if population else Xs, self.c_cov, self.rho,
                               one_sided=population)               # Sigma_t (13.16), diagonal
        Z = self.rng.standard_normal(Xs.shape)
        self._X = self.clip(Xs + Z * np.sqrt(var))                 # mutation K_t

    def _select_mutate(self, X, W):
        """The three lines above for multinomial replacement, compiled (:func:`._fast.select_mutate`);
        the uniforms of the kept/replaced decision, the sorted uniforms of the replacements and the
        normals of the mutation are drawn in that order, as the numpy path draws them."""
        n = W.size
        keep = np.zeros(n, dtype=bool)
        k = n                                                      # S1 replaces every particle
        if self.kernel != "s1":
            k = _fast.keep_mask(W, self.rng.random(n), self.kernel == "s3", keep)
        v = self.rng.random(k)
        v.sort()
        Z = self.rng.standard_normal(X.shape)
        return _fast.select_mutate(X, W, keep, v, Z, self.c_cov, self.rho,
                                   self.lo, self.hi, self.variance == "population")
