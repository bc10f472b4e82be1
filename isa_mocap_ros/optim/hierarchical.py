"""Hierarchical driver: one optimizer per ordered partition of the coordinates.

yeguas_ea_vs_pf_mocap §3.3 (the six-step hierarchy: root, torso+head, then each limb) and §5
(H-CMAES, H-DE, H-PSO run "sequentially in each part of the 6-step hierarchy"); PSAPF (§4.1.2) is
the same driver with APF inside. H-ISA (ISA inside) is new.

Rules
-----
* ``partitions`` is an ordered list of non-empty, pairwise disjoint index arrays within
  ``[0, d)``. They need not cover every coordinate: uncovered coordinates stay at ``x0``.
* While partition ``k`` is optimised, every other coordinate is held at the current estimate
  (partitions before ``k`` at their optimised values, later ones at ``x0``); the inner optimizer
  starts at the current estimate's sub-vector with the sub-spread.
* Budget split: partition ``k`` gets ``floor(B * d_k / sum_j d_j)`` evaluations (proportional to its
  dimension); the remainder of the integer division goes to the first partition. Each share must
  hold at least one generation of its inner optimizer, else :class:`OptimError`. Without a bound
  budget, ``evals_per_partition`` (int or list) must be given.
* A partition ends when its share is spent or its inner optimizer stops; its estimate (the inner
  ``result().x``) is then written into the full estimate. Rotation triples must lie inside one
  partition.
* Restricted energies: when the bound energy (``bind``/``minimize``) has a ``restrict`` method,
  ``energy.restrict(x, coords)`` is called once when a partition starts evaluating, with ``x`` the
  current estimate and ``coords`` the partition's indices, and that partition's generations are
  evaluated with what it returns (a batch energy valid for poses equal to ``x`` outside ``coords``,
  as every generation of the partition is; ``None``: the energy itself). The energy must give the
  same values either way (e.g. :meth:`SilhouetteEnergy.restrict
  <isa_mocap_ros.energy.silhouette.SilhouetteEnergy.restrict>`, the same bits); evaluation counts
  and budgets do not change. Without ``restrict`` the energy is called as it is.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ._base import OptimError, Optimizer

__all__ = ["Hierarchical", "check_partitions", "split_budget"]


def check_partitions(partitions, d: int) -> list[np.ndarray]:
    """Validate ordered partitions: non-empty, integer, in ``[0, d)``, pairwise disjoint."""
    if partitions is None or len(partitions) == 0:
        raise OptimError("partitions: expected a non-empty list of index arrays, got none")
    out, seen = [], {}
    for k, p in enumerate(partitions):
        a = np.asarray(p)
        if a.ndim != 1 or a.size == 0:
            raise OptimError(f"partitions[{k}]: expected a non-empty 1-D index array, got {p!r}")
        if not np.issubdtype(a.dtype, np.integer):
            raise OptimError(f"partitions[{k}]: expected integer indices, got dtype {a.dtype}")
        idx = a.tolist()
        if min(idx) < 0 or max(idx) >= d:
            raise OptimError(f"partitions[{k}]: indices must lie in [0, {d}), got {idx}")
        if len(set(idx)) != len(idx):
            raise OptimError(f"partitions[{k}]: repeated index in {idx}")
        for i in idx:
            if i in seen:
                raise OptimError(f"partitions: index {i} is in partitions[{seen[i]}] and "
                                 f"partitions[{k}] (partitions must be disjoint)")
            seen[i] = k
        out.append(a.astype(int))
    return out


def split_budget(max_evals: int, dims: Sequence[int], generations: Sequence[int] | None = None) -> list[int]:
    """Shares ``floor(B d_k / sum d)``, remainder to the first partition.

    With ``generations`` (the inner optimizers' generation sizes ``g_k``), shares are whole
    generations: each ``floor(B d_k / sum d)`` rounded down to a multiple of ``g_k``; then the
    remaining evaluations are handed out one generation at a time, first to partitions left without
    one (in order), then to all partitions in order (cycling) while one still fits; fewer than the
    smallest fitting generation stay unspent, so the shares may sum to less than ``B``."""
    tot = sum(dims)
    shares = [max_evals * dk // tot for dk in dims]
    if generations is None:
        shares[0] += max_evals - sum(shares)
        return shares
    shares = [s // g * g for s, g in zip(shares, generations)]
    left = max_evals - sum(shares)
    for k, g in enumerate(generations):
        if shares[k] == 0 and g <= left:
            shares[k] += g
            left -= g
    while any(g <= left for g in generations):
        for k, g in enumerate(generations):
            if g <= left:
                shares[k] += g
                left -= g
    return shares


class Hierarchical(Optimizer):
    """Run an inner optimizer sequentially over ordered partitions (H-ISA, PSAPF, H-CMAES, ...).

    Parameters
    ----------
    x0, spread, bounds, rng, initial_population, rotation_blocks
        See :class:`Optimizer`. ``initial_population`` columns of a partition are handed to its
        inner optimizer.
    partitions : list of index arrays
        Ordered partitions (see module rules).
    optimizer : str or callable
        Inner optimizer: a :func:`make_optimizer` name, or a factory
        ``f(x0_sub, spread_sub, *, rng, bounds, initial_population, rotation_blocks, **params)``.
    evals_per_partition : int or list of int, optional
        Shares when no budget is bound (``minimize`` binds one and overrides this).
    whole_generations : bool
        Split a bound budget into whole generations of the inner optimizers (:func:`split_budget`
        with their generation sizes), leaving fewer than one generation unspent, instead of ending
        partitions on a truncated generation. A truncated last generation of a few rows makes the
        partition's estimate that of a few random particles for the weighted-mean estimators (ISA,
        APF; ``docs/decisions/002-whole-generations.md``). Default False.
    **params
        Passed to every inner optimizer.
    """

    name = "hierarchical"

    def __init__(self, x0, spread, *, partitions, optimizer="cmaes",
                 evals_per_partition=None, whole_generations=False, rng, bounds=None, initial_population=None,
                 rotation_blocks=(), init="normal", max_iter=None, **params):
        super().__init__(x0, spread, rng=rng, bounds=bounds, initial_population=initial_population,
                         rotation_blocks=rotation_blocks, init=init, max_iter=max_iter)
        self.partitions = check_partitions(partitions, self.d)
        # column selectors: a slice for a run of consecutive indices (a view, ~10x cheaper than
        # fancy indexing per generation), else the index array
        self._columns = [slice(int(p[0]), int(p[-1]) + 1) if p.tolist() == list(range(p[0], p[-1] + 1))
                         else p for p in self.partitions]
        self._blocks = []
        for blk in self.rotation_blocks:
            owner = [k for k, p in enumerate(self.partitions) if set(blk) <= set(p.tolist())]
            touched = [k for k, p in enumerate(self.partitions) if set(blk) & set(p.tolist())]
            if touched and not owner:
                raise OptimError(f"rotation_blocks: triple {blk} is split across partitions "
                                 f"{touched}")
            self._blocks.append((owner[0] if owner else None, blk))
        if isinstance(optimizer, str):
            from . import OPTIMIZERS, inner_optimizer, make_optimizer
            if optimizer not in OPTIMIZERS or inner_optimizer(optimizer) is not None:
                raise OptimError(f"optimizer: expected a flat optimizer name "
                                 f"({', '.join(k for k in OPTIMIZERS if inner_optimizer(k) is None)}), "
                                 f"got {optimizer!r}")
            name = optimizer

            def factory(x, s, **kw):
                return make_optimizer(name, x, s, **kw)
            self._factory: Callable = factory
            self.inner_name = optimizer
        elif callable(optimizer):
            self._factory = optimizer
            self.inner_name = getattr(optimizer, "__name__", "custom")
        else:
            raise OptimError(f"optimizer: expected a name or a factory, got {optimizer!r}")
        self.params = params
        self.whole_generations = bool(whole_generations)
        self._x = self.x0.copy()
        self.k = 0                      # current partition
        self._inner: Optimizer | None = None
        self._inner_used = 0
        self.shares: list[int] | None = None
        if evals_per_partition is not None:
            self.shares = self._check_shares(evals_per_partition)
        self._last_pop = None
        self._probes: list[Optimizer | None] | None = None   # inner optimizers built by bind()
        self.partition_log: list[tuple[int, int]] = []   # (partition, evaluations spent)
        self._full_energy: Callable | None = None
        self._stage_energy: tuple[int, Callable] | None = None   # (partition, its restricted energy)

    def _check_shares(self, eps):
        if np.ndim(eps) == 0:
            eps = [int(eps)] * len(self.partitions)
        eps = [int(e) for e in eps]
        if len(eps) != len(self.partitions) or min(eps) < 1:
            raise OptimError(f"evals_per_partition: expected {len(self.partitions)} positive "
                             f"integers, got {eps}")
        return eps

    # ------------------------------------------------------------ inner setup
    def _make_inner(self, k: int, share: int | None) -> Optimizer:
        idx = self.partitions[k]
        local = {int(i): j for j, i in enumerate(idx.tolist())}
        blocks = tuple(tuple(local[i] for i in blk) for owner, blk in self._blocks if owner == k)
        P = None
        if self._initial_population is not None:
            P = self._initial_population[:, idx]
        opt = self._factory(self._x[idx], self.spread[idx], rng=self.rng,
                            bounds=(self.lo[idx], self.hi[idx]), initial_population=P,
                            rotation_blocks=blocks, **self.params)
        if share is not None:
            opt.size_for_budget(share)
            if share < opt.generation_size:
                raise OptimError(
                    f"max_evals: partition {k} ({len(idx)} coordinates) gets {share} evaluations, "
                    f"fewer than one generation of {opt.name} ({opt.generation_size})")
        return opt

    def _on_bind(self, max_evals):
        if self.n_iter != 0:
            return
        if max_evals is not None:
            gens = None
            if self.whole_generations:
                # generation sizes of the inner optimizers, built without drawing from the run's stream
                state = self.rng.bit_generator.state
                gens = [self._make_inner(k, None).generation_size for k in range(len(self.partitions))]
                self.rng.bit_generator.state = state
            self.shares = split_budget(max_evals, [len(p) for p in self.partitions], gens)
            if min(self.shares) < 1:
                raise OptimError(f"max_evals: budget {max_evals} gives an empty share to a "
                                 f"partition (shares {self.shares})")
            # validate every share now, so a too-small budget fails before any evaluation. A probe is
            # the inner optimizer its partition will run if building the probes drew no random
            # numbers (ISA, APF, CMA-ES): a partition's sub-vector of the estimate, its start, does
            # not change before it runs, so a later build would give the same optimizer. Otherwise
            # (DE draws at construction) later partitions are built again when they start.
            state = self.rng.bit_generator.state
            self._probes = [self._make_inner(k, self.shares[k]) for k in range(len(self.partitions))]
            if self.rng.bit_generator.state != state:
                self._probes[1:] = [None] * (len(self.partitions) - 1)
            self._inner = self._probes[0]
            self._inner_used = 0

    def bind(self, energy: Callable, *, max_evals: int | None = None) -> "Hierarchical":
        """:meth:`Optimizer.bind`; an energy with a ``restrict`` method is restricted to each partition
        when it starts (see the module rules)."""
        super().bind(energy, max_evals=max_evals)
        self._full_energy = energy
        self._stage_energy = None
        if callable(getattr(energy, "restrict", None)):
            self._energy = self._partition_energy
        return self

    def _partition_energy(self, X):
        """The bound energy, restricted to the current partition (built when it first evaluates: the
        estimate outside the partition does not change while it runs)."""
        if self._stage_energy is None or self._stage_energy[0] != self.k:
            fn = self._full_energy.restrict(self._x.copy(), self.partitions[self.k].copy())
            self._stage_energy = (self.k, self._full_energy if fn is None else fn)
        return self._stage_energy[1](X)

    @property
    def generation_size(self):
        return self._current().generation_size

    def _current(self) -> Optimizer:
        if self._inner is None:
            probe = self._probes[self.k] if self._probes is not None else None
            self._inner = probe if probe is not None else \
                self._make_inner(self.k, None if self.shares is None else self.shares[self.k])
        return self._inner

    def _share(self) -> int | None:
        return None if self.shares is None else self.shares[self.k]

    def _advance_if_done(self):
        inner = self._current()
        share = self._share()
        while (share is not None and self._inner_used >= share) or inner.stop():
            self._finish_partition()
            if self.k >= len(self.partitions):
                return False
            inner = self._current()
            share = self._share()
        return True

    def _finish_partition(self):
        inner = self._inner
        idx = self.partitions[self.k]
        if inner is not None and inner.n_iter > 0:
            self._x[idx] = inner.estimate()[0]
        self.partition_log.append((self.k, self._inner_used))
        self.k += 1
        self._inner = None
        self._inner_used = 0

    # --------------------------------------------------------------- protocol
    def _ask(self):
        if self.shares is None:
            raise OptimError("evals_per_partition: no budget to split; pass max_evals to "
                             "minimize/bind or evals_per_partition= to Hierarchical")
        if not self._advance_if_done():
            raise OptimError("ask: every partition is finished")
        Xs = self._current().ask()
        X = np.empty((len(Xs), self.d))
        X[:] = self._x
        X[:, self._columns[self.k]] = Xs
        return X

    def ask(self) -> np.ndarray:
        """Next generation to evaluate, ``(n, d)``: the current estimate with the partition's columns
        replaced by the inner optimizer's particles (a fresh array)."""
        return self._ask()

    def _remaining(self):
        rem = super()._remaining()
        share = self._share()
        if share is None:
            return rem
        part = share - self._inner_used
        return part if rem is None else min(rem, part)

    def _record(self, X, E, *, n_counted, n_bad):
        self._counted = n_counted
        super()._record(X, E, n_counted=n_counted, n_bad=n_bad)

    def _tell(self, X, E):
        inner = self._current()
        n = getattr(self, "_counted", len(X))
        # F order, as X[:, index_array] gives: the inner weighted mean (BLAS) keeps its bits
        inner.record(X[:, self._columns[self.k]].copy(order="F"), E, n_counted=n, n_bad=0)
        self._inner_used += n
        self._counted = len(X)
        self._last_pop = X

    def _stop(self):
        if self.k >= len(self.partitions):
            return {"partitions": len(self.partitions)}
        share = self._share()
        last = self.k == len(self.partitions) - 1
        if last and ((share is not None and self._inner_used >= share)
                     or (self._inner is not None and self._inner.stop())):
            return {"partitions": len(self.partitions)}
        return {}

    def _estimate(self):
        x = self._x.copy()
        if self._inner is not None and self._inner.n_iter > 0 and self.k < len(self.partitions):
            x[self.partitions[self.k]] = self._inner.estimate()[0]
        return x, None

    def _population(self):
        if self._last_pop is None:
            return np.repeat(self._x[None, :], 1, axis=0), None
        return self._last_pop, None

    @property
    def current_partition(self) -> int:
        """Index of the partition being optimised (``len(partitions)`` when done)."""
        return self.k
