"""Particle swarm optimisation with exponentially decaying inertia.

yeguas_ea_vs_pf_mocap §4.2.3, Fig. 6 (after John et al.): position update Eq. (17)
``x <- x + v``; velocity update Eq. (18)
``v <- omega v + phi1 r1 (p_i - x) + phi2 r2 (b - x)`` (``r1, r2 ~ U[0, 1]`` per component,
``p_i`` the particle's best, ``b`` the swarm's best); inertia Eq. (19)
``omega(c) = omega_max / e^c`` with ``c`` growing by ``Delta c = ln(omega_max / omega_min) / g_max``
per generation (the paper writes ``ln(10 omega_max)``, i.e. ``omega_min = 0.1``).
Velocities are clamped to ``|v_k| <= v_max_k`` (default: the spread); positions are clipped to the
bounds and the clipped velocity components set to 0. ``g_max`` defaults to the number of
generations the bound budget allows. Defaults: N = 10, phi1 = phi2 = 2, omega_max = 2,
omega_min = 0.1 (Table 3). The estimate is the swarm's best.
"""
from __future__ import annotations

import numpy as np

from ._base import OptimError, Optimizer

__all__ = ["Pso"]


class Pso(Optimizer):
    """PSO (Fig. 6, Eq. 17-19).

    Parameters
    ----------
    x0, spread, bounds, rng, initial_population, rotation_blocks, init, max_iter
        See :class:`Optimizer`.
    popsize : int
        N (default 10).
    phi1, phi2 : float
        Cognitive and social factors (2, 2).
    omega_max, omega_min : float
        Inertia range (2, 0.1).
    g_max : int, optional
        Inertia changes until ``omega_min``; default ``max_evals // N - 1`` when bound, else 100.
    v_max : float or (d,), optional
        Velocity clamp (default: ``spread``).
    """

    name = "pso"

    def __init__(self, x0, spread, *, popsize: int = 10, phi1: float = 2.0, phi2: float = 2.0,
                 omega_max: float = 2.0, omega_min: float = 0.1, g_max: int | None = None,
                 v_max=None, **kw):
        super().__init__(x0, spread, **kw)
        if self._initial_population is not None and popsize == 10:
            popsize = self._initial_population.shape[0]
        if int(popsize) < 2:
            raise OptimError(f"popsize: expected >= 2, got {popsize}")
        if not (0 < omega_min <= omega_max):
            raise OptimError(f"omega_min/omega_max: expected 0 < omega_min <= omega_max, "
                             f"got {omega_min}, {omega_max}")
        self.N = int(popsize)
        self.phi1, self.phi2 = float(phi1), float(phi2)
        self.omega_max, self.omega_min = float(omega_max), float(omega_min)
        self._g_max_given = g_max
        self.g_max = int(g_max) if g_max is not None else 100
        if self.g_max < 1:
            raise OptimError(f"g_max: expected >= 1, got {g_max}")
        vm = self.spread if v_max is None else np.broadcast_to(np.asarray(v_max, float), (self.d,))
        if np.any(~(vm > 0)):
            raise OptimError(f"v_max: expected values > 0, got {v_max}")
        self.v_max = np.array(vm, dtype=float)
        self.c = 0.0
        self.omega = self.omega_max
        self.x = self.v = self.p = self.pE = None
        self._X = None

    def _on_bind(self, max_evals):
        if self._g_max_given is None and max_evals is not None:
            self.g_max = max(1, max_evals // self.N - 1)

    @property
    def generation_size(self):
        return self.N

    def _ask(self):
        if self._X is not None:
            return self._X
        if self.x is None:
            self._X = self._draw_initial(self.N)
            self.v = self.rng.uniform(-1, 1, size=(self.N, self.d)) * self.v_max
            return self._X
        r1 = self.rng.random((self.N, self.d))
        r2 = self.rng.random((self.N, self.d))
        b = self.best_x
        v = self.omega * self.v + self.phi1 * r1 * (self.p - self.x) + self.phi2 * r2 * (b - self.x)  # (18)
        v = np.clip(v, -self.v_max, self.v_max)
        x = self.x + v                                                           # (17)
        xc = self.clip(x)
        v[xc != x] = 0.0
        self.v = v
        self._X = xc
        # inertia update (19): omega = omega_max / e^c, c += ln(omega_max/omega_min) / g_max
        self.c = min(self.c + np.log(self.omega_max / self.omega_min) / self.g_max,
                     np.log(self.omega_max / self.omega_min))
        self.omega = self.omega_max * np.exp(-self.c)
        return self._X

    def _tell(self, X, E):
        self.x = X.copy()
        if self.p is None:
            self.p, self.pE = X.copy(), E.copy()
        else:
            better = E < self.pE
            self.p[better], self.pE[better] = X[better], E[better]
        self._X = None

    def _estimate(self):
        return self.best_x.copy(), self.best_energy

    def _population(self):
        return (self.x if self.x is not None else self._ask()), None
