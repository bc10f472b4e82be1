"""CMA-ES with the default strategy parameters of yeguas_ea_vs_pf_mocap Table 2 (§4.2.1, Fig. 4;
Hansen's (mu/mu_w, lambda)-CMA-ES).

Sampling Eq. (9) ``x_k = m + sigma B D z_k``; recombination Eq. (10); cumulation for step size
Eq. (11) and the step-size update Eq. (12); covariance path Eq. (13) with the Heaviside stall
``h_sigma``; rank-one + rank-mu covariance update Eq. (14) with ``mu_cov`` and ``c_cov`` of Table 2.
Candidates outside the bounds are clipped and the clipped points are used in the update.
The estimate is the distribution mean ``m``.
"""
from __future__ import annotations

import numpy as np

from ._base import OptimError, Optimizer

__all__ = ["CmaEs", "CmaEsParameters"]


class CmaEsParameters:
    """Table 2 defaults for dimension ``D`` (any can be overridden by keyword)."""

    def __init__(self, D: int, *, popsize: int | None = None, mu: int | None = None,
                 c_sigma=None, d_sigma=None, c_c=None, mu_cov=None, c_cov=None):
        self.lam = int(popsize) if popsize is not None else 4 + int(np.floor(3 * np.log(D)))
        if self.lam < 2:
            raise OptimError(f"popsize: expected >= 2, got {self.lam}")
        self.mu = int(mu) if mu is not None else self.lam // 2
        if not (1 <= self.mu <= self.lam):
            raise OptimError(f"mu: expected 1 <= mu <= popsize={self.lam}, got {self.mu}")
        w = np.log(self.mu + 1) - np.log(np.arange(1, self.mu + 1))
        self.weights = w / w.sum()
        self.mu_eff = 1.0 / np.sum(self.weights ** 2)
        me = self.mu_eff
        self.c_sigma = c_sigma if c_sigma is not None else (me + 2) / (D + me + 3)
        self.d_sigma = d_sigma if d_sigma is not None else \
            1 + 2 * max(0.0, np.sqrt((me - 1) / (D + 1)) - 1) + self.c_sigma
        self.c_c = c_c if c_c is not None else 4.0 / (D + 4)
        self.mu_cov = mu_cov if mu_cov is not None else me
        mc = self.mu_cov
        self.c_cov = c_cov if c_cov is not None else \
            (1 / mc) * 2 / (D + np.sqrt(2)) ** 2 + (1 - 1 / mc) * min(1.0, (2 * me - 1) / ((D + 2) ** 2 + me))
        self.chi_n = np.sqrt(D) * (1 - 1 / (4 * D) + 1 / (21 * D * D))  # E||N(0, I)||


class CmaEs(Optimizer):
    """CMA-ES (Table 2 defaults; ``spread`` is sigma0 -- a vector spread scales C0's diagonal).

    Parameters
    ----------
    x0, spread, bounds, rng, initial_population, rotation_blocks, init, max_iter
        See :class:`Optimizer` (``initial_population`` is used as the first generation).
    popsize : int, optional
        lambda (default ``4 + floor(3 ln D)``).
    tol_sigma : float
        Stop when ``sigma * sqrt(max diag C) < tol_sigma`` (default 1e-12).
    **strategy
        Overrides of :class:`CmaEsParameters` (mu, c_sigma, d_sigma, c_c, mu_cov, c_cov).
    """

    name = "cmaes"

    def __init__(self, x0, spread, *, popsize: int | None = None, tol_sigma: float = 1e-12,
                 mu=None, c_sigma=None, d_sigma=None, c_c=None, mu_cov=None, c_cov=None, **kw):
        super().__init__(x0, spread, **kw)
        if popsize is None and self._initial_population is not None:
            popsize = self._initial_population.shape[0]
        self.par = CmaEsParameters(self.d, popsize=popsize, mu=mu, c_sigma=c_sigma,
                                   d_sigma=d_sigma, c_c=c_c, mu_cov=mu_cov, c_cov=c_cov)
        s = self.spread
        self.sigma = float(s.max())
        self.m = self.x0.copy()
        self.C = np.diag((s / self.sigma) ** 2)
        self.B = np.diag(np.ones(self.d))
        self.Dd = s / self.sigma
        self.p_sigma = np.zeros(self.d)
        self.p_c = np.zeros(self.d)
        self.tol_sigma = float(tol_sigma)
        self._X = None
        self._last_X = None

    @property
    def generation_size(self):
        return self.par.lam

    def _ask(self):
        if self._X is None:
            if self.n_iter == 0 and self._initial_population is not None:
                self._X = self._draw_initial(self.par.lam)
            else:
                Z = self.rng.standard_normal((self.par.lam, self.d))
                Y = (Z * self.Dd) @ self.B.T                       # y = B D z ~ N(0, C)
                self._X = self.clip(self.m + self.sigma * Y)       # Eq. (9)
        return self._X

    def _tell(self, X, E):
        p = self.par
        order = np.argsort(E, kind="stable")
        Xmu = X[order[: p.mu]]
        m_old = self.m
        self.m = p.weights @ Xmu                                    # Eq. (10)
        y_w = (self.m - m_old) / self.sigma
        Cinvsqrt_y = self.B @ ((self.B.T @ y_w) / self.Dd)
        cs = p.c_sigma
        self.p_sigma = (1 - cs) * self.p_sigma + np.sqrt(cs * (2 - cs) * p.mu_eff) * Cinvsqrt_y  # (11)
        g = self.n_iter + 1
        ps_norm = np.linalg.norm(self.p_sigma)
        h_sigma = ps_norm / np.sqrt(1 - (1 - cs) ** (2 * g)) < (1.4 + 2 / (self.d + 1)) * p.chi_n
        cc = p.c_c
        self.p_c = (1 - cc) * self.p_c + h_sigma * np.sqrt(cc * (2 - cc) * p.mu_eff) * y_w   # (13)
        Y = (Xmu - m_old) / self.sigma
        rank_mu = (Y.T * p.weights) @ Y
        c1 = p.c_cov / p.mu_cov
        cmu = p.c_cov - c1
        # C = (1 - c_cov) C + c_cov/mu_cov p_c p_c^T + (c_cov - c_cov/mu_cov) sum w_i y_i y_i^T  (14)
        self.C = (1 - p.c_cov) * self.C + c1 * (np.outer(self.p_c, self.p_c)
                                                + (1 - h_sigma) * cc * (2 - cc) * self.C) + cmu * rank_mu
        self.sigma *= np.exp((cs / p.d_sigma) * (ps_norm / p.chi_n - 1))              # (12)
        self.C = (self.C + self.C.T) / 2
        evals, self.B = np.linalg.eigh(self.C)
        self.Dd = np.sqrt(np.maximum(evals, 1e-300))
        self._last_X = X
        self._X = None

    def _stop(self):
        out = {}
        if self.sigma * self.Dd.max() < self.tol_sigma:
            out["tol_sigma"] = self.tol_sigma
        if self.Dd.max() > 1e7 * self.Dd.min():
            out["condition"] = float((self.Dd.max() / self.Dd.min()) ** 2)
        if not np.isfinite(self.sigma) or self.sigma <= 0:
            out["sigma"] = self.sigma
        return out

    def _estimate(self):
        return self.m.copy(), None

    def _population(self):
        return (self._last_X if self._last_X is not None else self._ask()), None
