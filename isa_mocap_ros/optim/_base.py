"""Common optimizer protocol: ask/tell, exact evaluation budgets, diagnostics, frozen results.

The shape follows pycma's ``OOOptimizer`` (ask, tell, stop, result) and the particle-system loop of
particles' ``SMC.__next__``: one generation per ``next(opt)``. Every algorithm of this package
(ISA, gall_isa_introduction §13.3; APF/PSAPF/CMA-ES/DE/PSO, yeguas_ea_vs_pf_mocap §4) derives from
:class:`Optimizer` and only implements ``_ask`` / ``_tell``.

Conventions
-----------
* A batch energy is ``energy(X) -> E`` with ``X : (n, d)`` and ``E : (n,)``; it is minimised.
  A wrong shape raises :class:`OptimError`. Non-finite energies (NaN, +/-inf) are replaced by
  ``+inf`` ("worst"), counted in ``n_nonfinite`` and never crash the run: in importance weights
  ``exp(-beta * inf) = 0``, in rankings they come last.
* Every row handed to the energy counts as one evaluation (as scipy counts ``nfev``).
* Budgets: :func:`minimize` never exceeds ``max_evals``. When the remaining budget is smaller than
  a generation, only the first ``remaining`` rows of that (last) generation are evaluated; the
  others are told to the algorithm with energy ``+inf`` and are *not* counted. A budget smaller
  than the *first* generation raises :class:`OptimError` (nothing sensible can be estimated).
* Bounds are enforced by clipping every proposed particle into ``[lo, hi]`` (all algorithms; PSO
  also zeroes the clipped velocity components).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from . import _fast

__all__ = ["OptimError", "Result", "GenerationInfo", "Optimizer", "minimize", "check_energies"]


class OptimError(ValueError):
    """Bad input to an optimizer (shape, value, budget, partition)."""


@dataclass(frozen=True)
class GenerationInfo:
    """Diagnostics of one generation.

    Attributes
    ----------
    n_iter : int
        Generations completed (1 after the first).
    n_evals : int
        Energy evaluations so far.
    best_energy : float
        Lowest energy seen so far.
    mean_energy : float
        Mean of the finite energies of this generation (nan if none).
    spread : float
        Mean over coordinates of the population's standard deviation.
    beta : float
        Annealing exponent used for this generation's weights (nan for EAs).
    ess : float
        Effective sample size ``1 / sum W^2`` of this generation's weights (nan for EAs).
    """

    n_iter: int
    n_evals: int
    best_energy: float
    mean_energy: float
    spread: float
    beta: float = float("nan")
    ess: float = float("nan")


@dataclass(frozen=True)
class Result:
    """Frozen outcome of a run.

    Attributes
    ----------
    x : (d,) ndarray
        The algorithm's estimate (weighted mean for ISA/APF, distribution mean for CMA-ES, best
        for DE/PSO).
    best_x : (d,) ndarray
        Best evaluated particle.
    energy : float
        Energy of ``x`` if ``x`` was evaluated, else ``best_energy``.
    best_energy : float
    n_evals, n_iter : int
    reason : str
        Why the run stopped ("" if it did not).
    population : (n, d) ndarray
        Final particles (for warm starts).
    weights : (n,) ndarray or None
        Normalised weights of ``population`` (particle filters), else None.
    history : tuple of GenerationInfo
    n_nonfinite : int
        Evaluations that returned NaN or inf.
    """

    x: np.ndarray
    best_x: np.ndarray
    energy: float
    best_energy: float
    n_evals: int
    n_iter: int
    reason: str
    population: np.ndarray
    weights: np.ndarray | None
    history: tuple
    n_nonfinite: int = 0


def check_energies(E, n: int) -> tuple[np.ndarray, int]:
    """Validate a batch of energies and make non-finite values ``+inf``.

    Parameters
    ----------
    E : array_like, (n,)
    n : int
        Expected number of rows.

    Returns
    -------
    E : (n,) float ndarray (a copy)
    n_nonfinite : int
    """
    arr = np.array(E, dtype=float, copy=True)
    if arr.shape != (n,):
        raise OptimError(f"energy: expected an array of shape ({n},) for {n} particles, "
                         f"got shape {arr.shape}")
    if math.isfinite(arr.sum()):     # every value finite (cheaper than isfinite + sum)
        return arr, 0
    bad = ~np.isfinite(arr)
    k = int(bad.sum())
    if k:
        arr[bad] = np.inf
    return arr, k


def _as_vector(name: str, value, d: int | None = None) -> np.ndarray:
    arr = np.array(value, dtype=float, copy=True)
    if arr.ndim == 0 and d is not None:
        arr = np.full(d, float(arr))
    if arr.ndim != 1 or (d is not None and arr.shape[0] != d):
        want = f"({d},)" if d is not None else "(d,)"
        raise OptimError(f"{name}: expected shape {want}, got {np.shape(value)}")
    if not np.isfinite(arr).all():
        raise OptimError(f"{name}: expected finite values, got {arr}")
    return arr


def _broadcast(name: str, value, d: int) -> np.ndarray:
    """``value`` broadcast to a fresh ``(d,)`` float array (``np.broadcast_to(...).copy()``)."""
    arr = np.array(value, dtype=float)
    if arr.shape == (d,):
        return arr
    if arr.size == 1 and arr.ndim <= 1:
        return np.full(d, float(arr.reshape(())))
    raise OptimError(f"{name}: expected a float or shape ({d},), got shape {arr.shape}")


class Optimizer:
    """Base class of every optimizer: validation, bounds, counting, iteration.

    Parameters
    ----------
    x0 : (d,) array_like
        Initial mean (clipped into ``bounds``).
    spread : float or (d,) array_like
        Initial standard deviation (``init="normal"``) or half-width (``init="uniform"``) per
        coordinate; must be > 0.
    bounds : (lo, hi) of (d,) arrays, optional
        Box constraints, enforced by clipping.
    rng : numpy.random.Generator
    initial_population : (n, d) array_like, optional
        First generation (replaces the draw around ``x0``); ``n`` must equal the population size.
    rotation_blocks : sequence of (i, j, k)
        Index triples holding rotation vectors (used by ISA/APF for the rotation mean, 13.24).
    init : {"normal", "uniform"}
        Law of the initial draw around ``x0``.
    max_iter : int, optional
        Stop after this many generations.
    """

    name = "optimizer"
    has_weights = False

    def __init__(self, x0, spread, *, bounds=None, rng: np.random.Generator,
                 initial_population=None, rotation_blocks: Sequence[tuple[int, int, int]] = (),
                 init: str = "normal", max_iter: int | None = None):
        if not isinstance(rng, np.random.Generator):
            raise OptimError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
        self.rng = rng
        x0 = _as_vector("x0", x0)
        d = x0.shape[0]
        if d < 1:
            raise OptimError("x0: expected at least one coordinate, got shape (0,)")
        self.d = d
        sp = np.array(spread, dtype=float)
        if sp.ndim > 1 or (sp.ndim == 1 and sp.shape[0] != d):
            raise OptimError(f"spread: expected a float or shape ({d},), got shape {sp.shape}")
        sp = np.full(d, float(sp)) if sp.ndim == 0 else sp
        if not np.isfinite(sp).all() or (sp <= 0).any():
            raise OptimError(f"spread: expected finite values > 0, got {sp}")
        self.spread = sp
        if bounds is None:
            self.lo = np.full(d, -np.inf)
            self.hi = np.full(d, np.inf)
        else:
            try:
                lo, hi = bounds
            except (TypeError, ValueError):
                raise OptimError(f"bounds: expected a pair (lo, hi), got {bounds!r}") from None
            lo, hi = _broadcast("bounds", lo, d), _broadcast("bounds", hi, d)
            if np.isnan(lo).any() or np.isnan(hi).any() or (lo >= hi).any():
                raise OptimError(f"bounds: expected lo < hi everywhere, got lo={lo}, hi={hi}")
            self.lo, self.hi = lo, hi
        self.x0 = self.clip(x0)
        if init not in ("normal", "uniform"):
            raise OptimError(f"init: expected 'normal' or 'uniform', got {init!r}")
        self.init = init
        self.rotation_blocks = self._check_blocks(rotation_blocks, d)
        if initial_population is not None:
            P = np.array(initial_population, dtype=float, copy=True)
            if P.ndim != 2 or P.shape[1] != d or P.shape[0] < 1:
                raise OptimError(f"initial_population: expected shape (n, {d}), got {P.shape}")
            if not np.isfinite(P).all():
                raise OptimError("initial_population: expected finite values")
            initial_population = self.clip(P)
        self._initial_population = initial_population
        if max_iter is not None and int(max_iter) < 1:
            raise OptimError(f"max_iter: expected >= 1, got {max_iter}")
        self.max_iter = None if max_iter is None else int(max_iter)
        # run state
        self.n_evals = 0
        self.n_iter = 0
        self.n_nonfinite = 0
        self.best_x = self.x0.copy()
        self.best_energy = np.inf
        self.history: list[GenerationInfo] = []
        self._energy: Callable | None = None
        self._max_evals: int | None = None
        self._user_stop: str = ""

    # ----------------------------------------------------------------- helpers
    @staticmethod
    def _check_blocks(blocks, d):
        out = []
        seen: set[int] = set()
        for b in blocks:
            t = tuple(int(i) for i in b)
            if len(t) != 3 or any(i < 0 or i >= d for i in t) or len(set(t)) != 3:
                raise OptimError(f"rotation_blocks: expected triples of distinct indices in "
                                 f"[0, {d}), got {tuple(b)}")
            if seen & set(t):
                raise OptimError(f"rotation_blocks: overlapping triple {t}")
            seen |= set(t)
            out.append(t)
        return tuple(out)

    def clip(self, X: np.ndarray) -> np.ndarray:
        """Clip particles ``X : (..., d)`` into the bounds (returns a new array)."""
        return np.clip(X, self.lo, self.hi)

    def _draw_initial(self, n: int) -> np.ndarray:
        """``(n, d)`` initial particles: the given population, or a draw around ``x0``."""
        if self._initial_population is not None:
            P = self._initial_population
            if P.shape[0] != n:
                raise OptimError(f"initial_population: expected {n} rows (the population size "
                                 f"of {self.name}), got {P.shape[0]}")
            return P.copy()
        if self.init == "uniform":
            Z = self.rng.uniform(-1.0, 1.0, size=(n, self.d))
        else:
            Z = self.rng.standard_normal((n, self.d))
        return self.clip(self.x0 + Z * self.spread)

    @property
    def initial_population(self) -> np.ndarray | None:
        """The first generation given to the constructor (clipped to the bounds), or None (drawn around
        ``x0``)."""
        return self._initial_population

    # ----------------------------------------------------------- to implement
    @property
    def generation_size(self) -> int:
        """Rows of the next ``ask()`` (the first generation before any ask)."""
        raise NotImplementedError

    def _ask(self) -> np.ndarray:
        raise NotImplementedError

    def _tell(self, X: np.ndarray, E: np.ndarray) -> None:
        raise NotImplementedError

    def _stop(self) -> dict:
        return {}

    def _estimate(self) -> tuple[np.ndarray, float | None]:
        """(estimate x, its energy if evaluated else None)."""
        return self.best_x.copy(), self.best_energy

    def _population(self) -> tuple[np.ndarray, np.ndarray | None]:
        raise NotImplementedError

    def _on_bind(self, max_evals: int | None) -> None:
        """Hook: an algorithm may size itself from the budget (PSO g_max, APF n_particles)."""

    def _beta_ess(self) -> tuple[float, float]:
        return float("nan"), float("nan")

    # ---------------------------------------------------------------- protocol
    def estimate(self) -> tuple[np.ndarray, float | None]:
        """The current estimate ``x (d,)`` (a copy) and its energy, None when it was not evaluated (the
        weighted mean of the particle methods)."""
        return self._estimate()

    def size_for_budget(self, max_evals: int | None) -> None:
        """Let the algorithm size itself from a budget of ``max_evals`` evaluations (PSO g_max, APF
        n_particles) without binding an energy, as :meth:`bind` does (a driver that splits its budget)."""
        self._on_bind(max_evals)

    def record(self, X: np.ndarray, E: np.ndarray, *, n_counted: int, n_bad: int = 0) -> None:
        """:meth:`tell` for energies already checked (``E (n,)`` finite or +inf, ``n_bad`` of them replaced):
        ``n_counted`` of the ``n`` rows were evaluated (a truncated last generation). ``X`` is kept as given."""
        self._record(X, E, n_counted=n_counted, n_bad=n_bad)

    def ask(self) -> np.ndarray:
        """Next generation to evaluate, ``(n, d)`` (a fresh array)."""
        X = np.array(self._ask(), dtype=float, copy=True)
        return X

    def tell(self, X, energies) -> None:
        """Report the energies ``(n,)`` of the particles ``X (n, d)`` returned by :meth:`ask`."""
        X = np.array(X, dtype=float, copy=True)
        if X.ndim != 2 or X.shape[1] != self.d:
            raise OptimError(f"X: expected shape (n, {self.d}), got {X.shape}")
        E, k = check_energies(energies, X.shape[0])
        self._record(X, E, n_counted=X.shape[0], n_bad=k)

    def _record(self, X, E, *, n_counted: int, n_bad: int) -> None:
        self.n_evals += int(n_counted)
        self.n_nonfinite += int(n_bad)
        i = int(E.argmin())
        if E[i] < self.best_energy:
            self.best_energy = float(E[i])
            self.best_x = X[i].copy()
        self._tell(X, E)
        self.n_iter += 1
        beta, ess = self._beta_ess()
        P, _ = self._population()
        # E[isfinite(E)].mean() and np.mean(np.std(P, axis=0)) (nan if empty), compiled: bit-identical
        mean_energy, spread = _fast.generation_stats(E, np.asarray(P, dtype=float))
        self.history.append(GenerationInfo(
            n_iter=self.n_iter, n_evals=self.n_evals, best_energy=float(self.best_energy),
            mean_energy=float(mean_energy), spread=float(spread), beta=float(beta), ess=float(ess)))

    def stop(self) -> dict:
        """Termination reasons, empty while the run should go on."""
        out = {}
        if self._user_stop:
            out["callback"] = self._user_stop
        if self._max_evals is not None and self.n_evals >= self._max_evals:
            out["max_evals"] = self._max_evals
        if self.max_iter is not None and self.n_iter >= self.max_iter:
            out["max_iter"] = self.max_iter
        out.update(self._stop())
        return out

    def bind(self, energy: Callable, *, max_evals: int | None = None) -> "Optimizer":
        """Attach the energy (and optionally a budget) used by ``next(opt)``; returns self.

        Raises
        ------
        OptimError
            If ``max_evals`` is smaller than the first generation.
        """
        if not callable(energy):
            raise OptimError(f"energy: expected a callable, got {type(energy).__name__}")
        if max_evals is not None:
            if int(max_evals) != max_evals or max_evals < 1:
                raise OptimError(f"max_evals: expected a positive integer, got {max_evals!r}")
            max_evals = int(max_evals)
            self._on_bind(max_evals - self.n_evals)
            need = self.generation_size
            if max_evals - self.n_evals < need:
                raise OptimError(
                    f"max_evals: budget {max_evals} (remaining {max_evals - self.n_evals}) is "
                    f"smaller than one generation of {self.name} ({need} evaluations)")
        else:
            self._on_bind(None)
        self._energy = energy
        self._max_evals = max_evals
        return self

    def _remaining(self) -> int | None:
        if self._max_evals is None:
            return None
        return self._max_evals - self.n_evals

    def __iter__(self):
        return self

    def __next__(self) -> GenerationInfo:
        """Run one generation with the bound energy; StopIteration when :meth:`stop` says so."""
        if self._energy is None:
            raise OptimError("energy: call bind(energy) (or minimize) before iterating")
        if self.stop():
            raise StopIteration
        X = self.ask()
        n = X.shape[0]
        rem = self._remaining()
        k = n if rem is None else max(0, min(n, rem))
        if k == 0:
            raise StopIteration
        E, bad = check_energies(self._energy(X[:k]), k)
        if k < n:       # the truncated last generation: rows beyond the budget get +inf
            E = np.concatenate([E, np.full(n - k, np.inf)])
        self._record(X, E, n_counted=k, n_bad=bad)
        return self.history[-1]

    def result(self) -> Result:
        """Frozen snapshot of the current state."""
        x, ex = self._estimate()
        P, W = self._population()
        stop = self.stop()
        reason = ", ".join(f"{k}={v}" for k, v in stop.items())
        return Result(
            x=np.array(x, dtype=float), best_x=self.best_x.copy(),
            energy=float(self.best_energy if ex is None else ex),
            best_energy=float(self.best_energy), n_evals=self.n_evals, n_iter=self.n_iter,
            reason=reason, population=np.array(P, dtype=float),
            weights=None if W is None else np.array(W, dtype=float),
            history=tuple(self.history), n_nonfinite=self.n_nonfinite)


def minimize(opt: Optimizer, energy: Callable, *, max_evals: int,
             callback: Callable[[GenerationInfo], bool] | None = None) -> Result:
    """Run ``opt`` on ``energy`` until it stops or ``max_evals`` evaluations are spent.

    Parameters
    ----------
    opt : Optimizer
    energy : callable ``(n, d) -> (n,)``
    max_evals : int
        Hard budget, never exceeded: the last generation is truncated to the remaining budget
        (its unevaluated rows get ``+inf`` and are not counted).
    callback : callable ``(GenerationInfo) -> bool``, optional
        Called after each generation; returning True stops the run (reason ``callback``).

    Returns
    -------
    Result

    Raises
    ------
    OptimError
        If ``max_evals`` is smaller than the first generation, or the energy returns a wrong shape.

    Examples
    --------
    >>> import numpy as np
    >>> from isa_mocap_ros.optim import CmaEs, minimize
    >>> opt = CmaEs(np.ones(3), 0.5, rng=np.random.default_rng(1))
    >>> res = minimize(opt, lambda X: (X ** 2).sum(axis=1), max_evals=700)
    >>> res.n_evals <= 700 and res.best_energy < 1e-6
    True
    """
    opt.bind(energy, max_evals=max_evals)
    for info in opt:
        if callback is not None and callback(info):
            opt._user_stop = "True"
            break
    return opt.result()


class ParticleOptimizer(Optimizer):
    """Shared state handling of the particle methods (ISA, APF).

    Subclasses keep ``self._x`` (the weighted estimate), ``self._P``/``self._W`` (the last weighted
    population and its weights, None before the first ``tell``), ``self.beta`` and ``self._ess``.
    """

    def _beta_ess(self):
        return self.beta, self._ess

    def _estimate(self):
        return self._x.copy(), None

    def _population(self):
        if self._P is None:
            P = self._ask()
            return P, np.full(len(P), 1.0 / len(P))
        return self._P, self._W
