"""Reference optimizers as peers of our own: pycma's CMA-ES and scipy's differential evolution.

Both are :class:`~isa_mocap_ros.optim.Optimizer` subclasses, so the tracker runs them exactly like
ours (:func:`~isa_mocap_ros.optim.minimize` with the frame's budget, bounds = the tracker's search
box, the same energy and prior), and every row handed to the energy is one counted evaluation:

* :class:`PycmaEs` (``"pycma"``): :class:`cma.CMAEvolutionStrategy` through its ask/tell
  interface. ``sigma0 = 1`` with ``CMA_stds = spread`` (per-coordinate initial standard
  deviations), ``bounds`` passed to pycma (its default ``BoundTransform``), the library's default
  population size ``4 + ⌊3 ln d⌋`` unless ``popsize`` is given; the normal draws come from the given
  ``numpy.random.Generator`` (pycma's ``randn`` option), so pycma never touches numpy's global
  random state. The estimate is pycma's distribution mean (``xfavorite``), as our
  :class:`~isa_mocap_ros.optim.CmaEs` returns its mean. pycma starts from ``x0`` and ``spread``;
  an ``initial_population`` (the tracker's prediction plus draws) is accepted and ignored, since
  pycma samples its own first generation.
* :class:`ScipyDe` (``"scipy-de"``): :func:`scipy.optimize.differential_evolution`, vectorised
  (one energy call per generation, ``updating="deferred"``), ``polish=False``, ``tol = atol = 0``,
  strategy ``best1bin`` with scipy's default dithered ``mutation=(0.5, 1)`` and
  ``recombination=0.7``, ``rng`` = the given Generator, and an explicit first population of
  ``popsize`` rows (``initial_population`` if given, else ``x0`` plus normal draws with standard
  deviation ``spread``, clipped into the bounds; scipy's own default, ``15 d`` Latin-hypercube rows,
  would not fit a 500-evaluation budget at 39 DOF). scipy has no ask/tell, so the whole run happens
  in the first ``next()``: the wrapped energy evaluates at most the remaining budget (rows past it
  get ``+inf`` without being evaluated or counted) and scipy's callback stops it when the budget is
  spent. Bounds are required by scipy; without ``bounds`` the box ``x0 ± 5·spread`` is used.

:func:`register_peers` adds both names to :data:`isa_mocap_ros.optim.OPTIMIZERS`, after which
``make_optimizer("pycma", ...)``, ``TrackerConfig.from_flat(optimizer="scipy-de")`` and
``make_tracker(..., optimizer="pycma")`` work. Nothing registers them on import: the CLI, the estimator
node and the comparison call :func:`register_peers` (``optim`` never imports ``eval``).
"""
from __future__ import annotations


import numpy as np

from isa_mocap_ros.optim import OPTIMIZERS, OptimError, Optimizer, check_energies

__all__ = ["PycmaEs", "ScipyDe", "PEERS", "register_peers"]


class PycmaEs(Optimizer):
    """pycma's CMA-ES as an :class:`Optimizer` (see the module docstring).

    Parameters
    ----------
    x0, spread, bounds, rng, initial_population, rotation_blocks, init, max_iter
        As :class:`~isa_mocap_ros.optim.Optimizer` (``initial_population`` and ``rotation_blocks``
        are ignored).
    popsize : int, optional
        λ (default pycma's ``4 + ⌊3 ln d⌋``).
    options : mapping, optional
        Further pycma options (not ``bounds``, ``CMA_stds``, ``randn``, ``seed``, ``popsize``).
    """

    name = "pycma"

    def __init__(self, x0, spread, *, popsize: int | None = None, options=None, **kw):
        import cma

        kw.pop("initial_population", None)
        super().__init__(x0, spread, **kw)
        opts = {"CMA_stds": self.spread.tolist(), "verbose": -9, "verb_log": 0, "verb_disp": 0,
                "seed": float("nan"), "randn": lambda lam, n: self.rng.standard_normal((lam, n)),
                "tolfun": 0, "tolx": 0, "tolfunhist": 0, "tolstagnation": 10**9, "tolflatfitness": 10**9,
                "maxfevals": float("inf"), "maxiter": float("inf")}
        if np.all(np.isfinite(self.lo)) or np.all(np.isfinite(self.hi)):
            opts["bounds"] = [np.where(np.isfinite(self.lo), self.lo, None).tolist(),
                              np.where(np.isfinite(self.hi), self.hi, None).tolist()]
        if popsize is not None:
            if int(popsize) != popsize or popsize < 2:
                raise OptimError(f"popsize: expected an integer >= 2, got {popsize!r}")
            opts["popsize"] = int(popsize)
        for k, v in dict(options or {}).items():
            if k in ("bounds", "CMA_stds", "randn", "seed", "popsize"):
                raise OptimError(f"options: {k!r} is set by PycmaEs, got it in options")
            opts[k] = v
        self.es = cma.CMAEvolutionStrategy(self.x0.tolist(), 1.0, opts)
        self._X: np.ndarray | None = None
        self._last_X: np.ndarray | None = None

    @property
    def generation_size(self) -> int:
        return int(self.es.popsize)

    def _ask(self) -> np.ndarray:
        if self._X is None:
            self._X = np.asarray(self.es.ask(), dtype=float)
        return self.clip(self._X)

    def _tell(self, X, E) -> None:
        Xa = self._X if self._X is not None else X
        self._X = None
        self._last_X = X
        if np.isinf(E).all():
            return
        fin = np.isfinite(E)
        if not fin.all():          # truncated generation or non-finite energies: worst finite + margin
            worst = E[fin].max()
            E = np.where(fin, E, worst + 1.0 + abs(worst))
        self.es.tell(list(Xa), E.tolist())

    def _estimate(self):
        return self.clip(np.asarray(self.es.mean, dtype=float)), None

    def _population(self):
        return (self._last_X if self._last_X is not None else self.x0[None, :]), None

    def _stop(self) -> dict:
        s = {k: v for k, v in self.es.stop().items() if k not in ("maxfevals", "maxiter")}
        return {f"pycma_{k}": v for k, v in s.items()}


class ScipyDe(Optimizer):
    """scipy's ``differential_evolution`` as an :class:`Optimizer` (see the module docstring).

    Parameters
    ----------
    x0, spread, bounds, rng, initial_population, rotation_blocks, init, max_iter
        As :class:`~isa_mocap_ros.optim.Optimizer` (``rotation_blocks`` ignored).
    popsize : int
        Rows of the population (total, not scipy's per-dimension multiplier; default 20, >= 5).
    strategy, mutation, recombination
        Passed to scipy.
    """

    name = "scipy-de"

    def __init__(self, x0, spread, *, popsize: int = 20, strategy: str = "best1bin", mutation=(0.5, 1.0),
                 recombination: float = 0.7, **kw):
        P0 = kw.get("initial_population")
        if P0 is not None:
            popsize = int(np.shape(P0)[0])
        if int(popsize) != popsize or popsize < 5:
            raise OptimError(f"popsize: expected an integer >= 5 (scipy's minimum), got {popsize!r}")
        self.popsize = int(popsize)
        super().__init__(x0, spread, **kw)
        if not (np.all(np.isfinite(self.lo)) and np.all(np.isfinite(self.hi))):
            lo = np.where(np.isfinite(self.lo), self.lo, self.x0 - 5 * self.spread)
            hi = np.where(np.isfinite(self.hi), self.hi, self.x0 + 5 * self.spread)
            self.lo, self.hi = lo, hi
        self.strategy, self.mutation, self.recombination = strategy, mutation, float(recombination)
        self._done = False
        self._message = ""
        self._last_X: np.ndarray | None = None

    @property
    def generation_size(self) -> int:
        return self.popsize

    def _tell(self, X, E) -> None:
        self._last_X = X

    def _population(self):
        return (self._last_X if self._last_X is not None else self.x0[None, :]), None

    def _stop(self) -> dict:
        return {"scipy": self._message} if self._done else {}

    def __next__(self):
        from scipy.optimize import differential_evolution

        if self._energy is None:
            raise OptimError("energy: call bind(energy) (or minimize) before iterating")
        if self._done or self.stop():
            raise StopIteration
        energy = self._energy

        def fn(Xt):
            X = np.atleast_2d(np.asarray(Xt, dtype=float).T)
            n = X.shape[0]
            rem = self._remaining()
            k = n if rem is None else max(0, min(n, rem))
            E = np.full(n, np.inf)
            if k > 0:
                Ek, bad = check_energies(energy(X[:k]), k)
                E[:k] = Ek
                self._record(X, E, n_counted=k, n_bad=bad)
            return E

        def callback(intermediate_result=None):
            rem = self._remaining()
            return (rem is not None and rem <= 0) or (self.max_iter is not None and self.n_iter >= self.max_iter)

        init = self._draw_initial(self.popsize)
        if self._initial_population is None:
            init[0] = self.x0
        # scipy rejects an initial population outside the bounds only by clipping; ours is clipped
        res = differential_evolution(fn, list(zip(self.lo, self.hi)), strategy=self.strategy, maxiter=10**9,
                                     popsize=1, init=init, mutation=self.mutation, recombination=self.recombination,
                                     tol=0.0, atol=0.0, polish=False, updating="deferred", vectorized=True,
                                     rng=self.rng, callback=callback)
        self._done = True
        self._message = str(res.message)
        if not self.history:
            raise StopIteration
        return self.history[-1]


PEERS = {"pycma": PycmaEs, "scipy-de": ScipyDe}


def register_peers() -> None:
    """Add ``"pycma"`` and ``"scipy-de"`` to :data:`isa_mocap_ros.optim.OPTIMIZERS` (idempotent)."""
    for k, v in PEERS.items():
        OPTIMIZERS.setdefault(k, v)

