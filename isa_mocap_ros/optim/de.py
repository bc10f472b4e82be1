"""Differential evolution with role differentiation and malleable mating.

yeguas_ea_vs_pf_mocap §4.2.2 and Fig. 5 (after García-Martínez et al.): per generation, for every
receiving vector ``R = x_i`` of the population,

* placing ``P``: uniform from the best ``N_P`` members without ``R``;
* the mating parameters ``(alpha_L, alpha_C)`` of ``P`` are perturbed:
  ``alpha' = reflect_[0,1](alpha + N(0, alpha_sigma^2))``;
* leading ``L`` / correcting ``C``: assortative mating from the best ``N_L`` without ``{R, P}`` /
  the worst ``N_C`` without ``{R, P, L}``: candidates are ranked by distance to ``P`` and the one at
  rank ``floor(alpha' * k)`` of ``k`` is taken (``alpha' = 0``: the nearest, positive assortative;
  ``alpha' = 1``: the farthest, negative assortative);
* donor ``V = P + F (L - C)`` (Eq. 15 with the roles), binomial crossover with ``R`` (Eq. 16),
  the trial carries ``alpha'``; greedy selection between ``R`` and the trial (ties go to the trial).

The exact form of "assortative mating with alpha" is our reading of Fig. 5 (the rank rule above);
the source (García-Martínez et al., Soft Computing 2011) was not available.
Defaults: N = 10, N_P = N_L = N_C = 5, CR = 0.9, F = 0.5 (Table 3). The estimate is the best member.
"""
from __future__ import annotations

import numpy as np

from ._base import OptimError, Optimizer

__all__ = ["DifferentialEvolution"]


def _reflect01(a):
    a = np.mod(a, 2.0)
    return np.where(a > 1.0, 2.0 - a, a)


class DifferentialEvolution(Optimizer):
    """DE with role differentiation and malleable mating (Fig. 5).

    Parameters
    ----------
    x0, spread, bounds, rng, initial_population, rotation_blocks, init, max_iter
        See :class:`Optimizer`.
    popsize : int
        N (default 10).
    n_placing, n_leading, n_correcting : int
        N_P, N_L, N_C (default 5 each).
    CR, F : float
        Crossover rate (0.9) and scale factor (0.5).
    alpha_sigma : float
        Std of the random alteration of the mating parameters (default 0.1).
    """

    name = "de"

    def __init__(self, x0, spread, *, popsize: int = 10, n_placing: int = 5, n_leading: int = 5,
                 n_correcting: int = 5, CR: float = 0.9, F: float = 0.5,
                 alpha_sigma: float = 0.1, **kw):
        super().__init__(x0, spread, **kw)
        if self._initial_population is not None and popsize == 10:
            popsize = self._initial_population.shape[0]
        N = int(popsize)
        if N < 4:
            raise OptimError(f"popsize: expected >= 4 (R, P, L, C distinct), got {popsize}")
        for nm, v in (("n_placing", n_placing), ("n_leading", n_leading),
                      ("n_correcting", n_correcting)):
            if not (2 <= int(v) <= N):
                raise OptimError(f"{nm}: expected 2 <= {nm} <= popsize={N}, got {v}")
        if not (0 <= CR <= 1) or not (F > 0):
            raise OptimError(f"CR/F: expected CR in [0, 1] and F > 0, got CR={CR}, F={F}")
        self.N, self.NP, self.NL, self.NC = N, int(n_placing), int(n_leading), int(n_correcting)
        self.CR, self.F, self.alpha_sigma = float(CR), float(F), float(alpha_sigma)
        self.pop = None          # (N, d)
        self.E = None            # (N,)
        self.alpha = self.rng.uniform(0, 1, size=(N, 2))  # (alpha_L, alpha_C) per member
        self._trial_alpha = None
        self._U = None

    @property
    def generation_size(self):
        return self.N

    def _mate(self, cand, p_vec, a):
        """Assortative mating: candidate at rank floor(a k) by distance to the placing vector."""
        dist = np.linalg.norm(self.pop[cand] - p_vec, axis=1)
        order = cand[np.argsort(dist, kind="stable")]
        return order[min(int(a * len(order)), len(order) - 1)]

    def _ask(self):
        if self._U is not None:
            return self._U
        if self.pop is None:
            self._U = self._draw_initial(self.N)
            return self._U
        N, d, rng = self.N, self.d, self.rng
        rank = np.argsort(self.E, kind="stable")
        best_p, best_l, worst_c = rank[: self.NP], rank[: self.NL], rank[N - self.NC:]
        U = np.empty((N, d))
        A = np.empty((N, 2))
        for i in range(N):
            cp = best_p[best_p != i]
            p = cp[rng.integers(len(cp))]
            a = _reflect01(self.alpha[p] + rng.normal(0, self.alpha_sigma, 2))
            cl = best_l[(best_l != i) & (best_l != p)]
            if len(cl) == 0:
                cl = np.setdiff1d(np.arange(N), [i, p])
            l_ = self._mate(cl, self.pop[p], a[0])
            cc = worst_c[(worst_c != i) & (worst_c != p) & (worst_c != l_)]
            if len(cc) == 0:
                cc = np.setdiff1d(np.arange(N), [i, p, l_])
            c_ = self._mate(cc, self.pop[p], a[1])
            v = self.pop[p] + self.F * (self.pop[l_] - self.pop[c_])     # mutation (15)
            mask = rng.random(d) <= self.CR                               # crossover (16)
            mask[rng.integers(d)] = True
            U[i] = np.where(mask, v, self.pop[i])
            A[i] = a
        self._U = self.clip(U)
        self._trial_alpha = A
        return self._U

    def _tell(self, X, E):
        if self.pop is None:
            self.pop, self.E = X.copy(), E.copy()
        else:
            win = E <= self.E                                             # selection
            self.pop[win], self.E[win] = X[win], E[win]
            self.alpha[win] = self._trial_alpha[win]
        self._U = None

    def _estimate(self):
        return self.best_x.copy(), self.best_energy

    def _population(self):
        return (self.pop if self.pop is not None else self._ask()), None
