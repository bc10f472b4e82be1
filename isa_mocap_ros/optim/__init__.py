"""isa_mocap_ros.optim -- population optimizers on batch energies ``energy(X: (n, d)) -> (n,)``.

Algorithms (all minimise, all share the ask/tell/iterator protocol of :class:`Optimizer` and the
:func:`minimize` driver with an exact evaluation budget):

* :class:`Isa` -- interacting simulated annealing, gall_isa_introduction §13.3 (Alg. 6,
  Eq. 13.8-13.10, 13.16, 13.18-13.19, 13.24);
* :class:`AnnealedParticleFilter` / :func:`PartitionedApf` -- yeguas_ea_vs_pf_mocap §4.1.1-4.1.2
  (Eq. 6-8);
* :class:`CmaEs` (§4.2.1, Table 2), :class:`DifferentialEvolution` (§4.2.2, Fig. 5),
  :class:`Pso` (§4.2.3, Eq. 17-19);
* :class:`Hierarchical` -- any of them over ordered partitions (§3.3).

:func:`make_optimizer` builds one by name: "isa", "apf", "psapf", "cmaes", "de", "pso",
"h-isa", "h-apf", "h-cmaes", "h-de", "h-pso" (the ``h-`` ones and "psapf" need ``partitions``).
"""
from __future__ import annotations

from ._base import GenerationInfo, OptimError, Optimizer, Result, check_energies, minimize
from ._rotations import rotation_mean
from .apf import AnnealedParticleFilter, PartitionedApf
from .cmaes import CmaEs, CmaEsParameters
from .de import DifferentialEvolution
from .hierarchical import Hierarchical, check_partitions, split_budget
from .isa import Isa, dynamic_variance, weighted_estimate
from .pso import Pso
from .resampling import (SELECTION_KERNELS, ess, multinomial, normalise_log, residual,
                         select_s1, select_s2, select_s3, stratified, systematic)
from .schedules import AdaptiveEss, Logarithmic, Polynomial, beta_for_ess, make_schedule

OPTIMIZERS = {
    "isa": Isa,
    "apf": AnnealedParticleFilter,
    "cmaes": CmaEs,
    "de": DifferentialEvolution,
    "pso": Pso,
    "psapf": None,
    "h-isa": None, "h-apf": None, "h-cmaes": None, "h-de": None, "h-pso": None,
}


def inner_optimizer(name: str) -> str | None:
    """The flat algorithm a hierarchical registry name runs per partition ("h-isa" -> "isa",
    "psapf" -> "apf"); None for a flat name."""
    if name == "psapf":
        return "apf"
    return name[2:] if name.startswith("h-") else None


def make_optimizer(name: str, x0, spread, *, rng, **params) -> Optimizer:
    """An optimizer by registry name.

    Parameters
    ----------
    name : str
        One of ``OPTIMIZERS``; "psapf" and "h-<name>" build :class:`Hierarchical` and need
        ``partitions=`` in ``params``.
    x0 : (d,) array_like
    spread : float or (d,)
    rng : numpy.random.Generator
    **params
        Keyword arguments of the class (bounds, n_particles, popsize, ...).

    Examples
    --------
    >>> import numpy as np
    >>> opt = make_optimizer("h-cmaes", np.zeros(4), 0.5, rng=np.random.default_rng(1),
    ...                      partitions=[[0, 1], [2, 3]])
    >>> minimize(opt, lambda X: ((X - 1) ** 2).sum(axis=1), max_evals=800).best_energy < 1e-6
    True
    """
    if name not in OPTIMIZERS:
        raise OptimError(f"name: expected one of {', '.join(OPTIMIZERS)}, got {name!r}")
    inner = inner_optimizer(name)
    if inner is not None:
        if "partitions" not in params:
            raise OptimError(f"partitions: optimizer {name!r} needs partitions=[index arrays]")
        return Hierarchical(x0, spread, optimizer=inner, rng=rng, **params)
    return OPTIMIZERS[name](x0, spread, rng=rng, **params)


__all__ = [
    "OptimError", "Result", "GenerationInfo", "Optimizer", "minimize", "check_energies",
    "Isa", "AnnealedParticleFilter", "PartitionedApf", "CmaEs", "CmaEsParameters",
    "DifferentialEvolution", "Pso", "Hierarchical", "check_partitions", "split_budget",
    "make_optimizer", "inner_optimizer", "OPTIMIZERS",
    "multinomial", "systematic", "residual", "stratified", "normalise_log", "ess",
    "select_s1", "select_s2", "select_s3", "SELECTION_KERNELS",
    "Polynomial", "Logarithmic", "AdaptiveEss", "beta_for_ess", "make_schedule",
    "rotation_mean", "weighted_estimate", "dynamic_variance",
]
