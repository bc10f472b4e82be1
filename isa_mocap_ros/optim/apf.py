"""Annealed particle filter (APF) and its partitioned version (PSAPF).

yeguas_ea_vs_pf_mocap §4.1.1 (after Deutscher & Reid): ``L`` layers per run; in layer ``l`` the
weights are ``pi_i ~ exp(-beta_l E(x_i))`` with ``beta_l`` solved so that the particle survival
rate ``delta = 1 / (N sum pi_i^2)`` (Eq. 7) is closest to its target 0.5 (Eq. 8, bisection in
:func:`.schedules.beta_for_ess`); the particles are resampled (multinomial, ISA kernel S1, 13.8)
and diffused with Gaussian noise ``B_l = alpha^l * noise_scale * Cov(particles)`` -- the
population covariance of Eq. (6) (full matrix, ``1/N`` normalisation, plus a tiny ridge for
positive definiteness) -- where ``alpha`` is the per-layer decay of the noise (default 0.5 after
Deutscher & Reid's annealing rate; ``alpha = 1`` keeps pure Eq. 6). The estimate is the weighted
mean of the last layer (rotation triples by ISA 13.24).

PSAPF (§4.1.2) runs one APF per partition of the coordinates in order (Bandouch et al.):
:class:`PartitionedApf` is :class:`~.hierarchical.Hierarchical` with APF inside.
"""
from __future__ import annotations

import numpy as np

from ._base import OptimError, ParticleOptimizer
from .isa import weighted_estimate
from .resampling import SCHEMES, ess, normalise_log
from .schedules import beta_for_ess

__all__ = ["AnnealedParticleFilter", "PartitionedApf"]


class AnnealedParticleFilter(ParticleOptimizer):
    """APF with ``n_layers`` annealing layers (stops after the last one).

    Parameters
    ----------
    x0, spread, bounds, rng, initial_population, rotation_blocks, init, max_iter
        See :class:`Optimizer`.
    n_particles : int, optional
        Particles per layer. Default: ``max_evals // n_layers`` when bound to a budget, else 100.
    n_layers : int
        ``L`` (default 10, Table 3).
    survival : float
        Target survival rate ``delta`` of Eq. (7)-(8) (default 0.5).
    noise_scale : float
        Proportionality factor of Eq. (6) (default 1).
    alpha : float
        Per-layer decay of the noise covariance, ``alpha**l`` (default 0.5).
    resampling : str
        Resampling scheme name (default multinomial).
    """

    name = "apf"
    has_weights = True

    def __init__(self, x0, spread, *, n_particles: int | None = None, n_layers: int = 10,
                 survival: float = 0.5, noise_scale: float = 1.0, alpha: float = 0.5,
                 resampling: str = "multinomial", **kw):
        super().__init__(x0, spread, **kw)
        if int(n_layers) < 1:
            raise OptimError(f"n_layers: expected >= 1, got {n_layers}")
        self.n_layers = int(n_layers)
        self._auto_n = n_particles is None
        if n_particles is None:
            n_particles = (self._initial_population.shape[0]
                           if self._initial_population is not None else 100)
        if int(n_particles) < 2:
            raise OptimError(f"n_particles: expected >= 2, got {n_particles}")
        self.n = int(n_particles)
        if not (0 < survival <= 1):
            raise OptimError(f"survival: expected a rate in (0, 1], got {survival}")
        if not (noise_scale > 0) or not (0 < alpha <= 1):
            raise OptimError(f"noise_scale/alpha: expected noise_scale > 0 and alpha in (0, 1], "
                             f"got {noise_scale}, {alpha}")
        if resampling not in SCHEMES:
            raise OptimError(f"resampling: expected one of {sorted(SCHEMES)}, got {resampling!r}")
        self._scheme = SCHEMES[resampling]
        self.survival, self.noise_scale, self.alpha = float(survival), float(noise_scale), float(alpha)
        self._X = self._P = self._W = None
        self._x = self.x0.copy()
        self.beta = float("nan")
        self._ess = float("nan")

    def _on_bind(self, max_evals):
        if self._auto_n and max_evals is not None and self.n_iter == 0 and \
                self._initial_population is None:
            n = max_evals // self.n_layers
            if n < 2:
                raise OptimError(f"max_evals: APF with n_layers={self.n_layers} needs at least "
                                 f"{2 * self.n_layers} evaluations (2 particles per layer), "
                                 f"got {max_evals}")
            self.n = n

    @property
    def generation_size(self):
        return self.n

    def _ask(self):
        if self._X is None:
            self._X = self._draw_initial(self.n)
        return self._X

    def _tell(self, X, E):
        l = self.n_iter                                  # layer index (0-based)
        beta = beta_for_ess(E, self.survival)            # Eq. (7)-(8)
        self.beta = beta
        fin = np.isfinite(E)
        E0 = E[fin].min() if fin.any() else 0.0
        W = normalise_log(np.where(fin, -beta * (E - E0), -np.inf))
        self._P, self._W, self._ess = X, W, ess(W)
        self._x = weighted_estimate(X, W, self.rotation_blocks)
        Xs = X[self._scheme(W, self.rng, self.n)]
        mu = Xs.mean(axis=0)
        D = Xs - mu
        B = (D.T @ D) / len(Xs)                          # Eq. (6), 1/N normalisation
        B = self.noise_scale * self.alpha ** l * B
        ridge = 1e-12 * (np.trace(B) / self.d + 1e-300)
        try:
            Lc = np.linalg.cholesky(B + ridge * np.eye(self.d))
        except np.linalg.LinAlgError:
            Lc = np.diag(np.sqrt(np.maximum(np.diag(B), 0)))
        self._X = self.clip(Xs + self.rng.standard_normal(Xs.shape) @ Lc.T)

    def _stop(self):
        return {"n_layers": self.n_layers} if self.n_iter >= self.n_layers else {}


def PartitionedApf(x0, spread, *, partitions, rng, **params):
    """PSAPF (§4.1.2): an APF per partition, in order. See :class:`~.hierarchical.Hierarchical`."""
    from .hierarchical import Hierarchical
    return Hierarchical(x0, spread, partitions=partitions, optimizer="apf", rng=rng, **params)
