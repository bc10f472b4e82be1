"""Annealing schedules ``beta_t`` for ISA (gall_isa_introduction §13.3.1) and APF.

* :class:`Polynomial` ``beta_t = (t + 1)^b``, ``b in (0, 1)`` -- Eq. (13.19);
* :class:`Logarithmic` ``beta_t = ln(t + b)``, ``b > 1`` -- Eq. (13.18);
* :class:`AdaptiveEss` picks ``beta`` so that the effective sample size of
  ``W ~ exp(-beta E)`` is a target fraction of ``n``; with target 0.5 this is the APF rule of
  yeguas_ea_vs_pf_mocap Eq. (7)-(8) (survival rate ``delta = 1 / (N sum W^2) = ESS / N``).

A schedule is a callable ``schedule(t, energies) -> beta`` (``t`` = 0 for the first generation).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _fast
from ._base import OptimError

__all__ = ["Polynomial", "Logarithmic", "AdaptiveEss", "beta_for_ess", "make_schedule"]


@dataclass(frozen=True)
class Polynomial:
    """``beta_t = (t + 1)^b`` (13.19)."""

    b: float = 0.993

    def __post_init__(self):
        if not (0.0 < self.b):
            raise OptimError(f"b: polynomial schedule expects b > 0 (paper: b in (0, 1)), "
                             f"got {self.b}")

    def __call__(self, t: int, energies=None) -> float:
        return float((t + 1) ** self.b)


@dataclass(frozen=True)
class Logarithmic:
    """``beta_t = ln(t + b)`` (13.18)."""

    b: float = 2.0

    def __post_init__(self):
        if not (self.b > 1.0):
            raise OptimError(f"b: logarithmic schedule expects b > 1, got {self.b}")

    def __call__(self, t: int, energies=None) -> float:
        return float(np.log(t + self.b))


def beta_for_ess(energies, target: float, *, beta_max: float = 1e12, tol: float = 1e-6) -> float:
    """``beta >= 0`` whose weights ``exp(-beta E)`` have ``ESS / n`` closest to ``target``.

    Solves yeguas Eq. (8) by bisection on ``log10 beta`` (ESS is non-increasing in beta) between
    ``1e-12`` over the median positive energy gap and ``beta_max``; returns the upper end if even it
    keeps the ESS above the target. Non-finite energies get weight 0 (they count in ``n``).
    Returns 0 when fewer than two energies are finite, all finite energies are equal, or the
    non-finite rows already push ``ESS / n`` below the target.

    Parameters
    ----------
    energies : (n,) array_like
    target : float in (0, 1]
    """
    if not (0.0 < target <= 1.0):
        raise OptimError(f"target: expected an ESS fraction in (0, 1], got {target}")
    E = np.ascontiguousarray(energies, dtype=float).ravel()
    # compiled, bit-identical to the numpy formulation (see _fast.adaptive_beta)
    return float(_fast.adaptive_beta(E, float(target), float(beta_max), float(tol)))


@dataclass(frozen=True)
class AdaptiveEss:
    """``beta_t`` chosen so that ``ESS / n = target`` (yeguas Eq. 7-8 for ``target = 0.5``).

    With ``monotone=True`` the schedule never decreases (annealing), i.e.
    ``beta_t = max(beta_{t-1}, beta_for_ess(E_t))``; that memory lives in the optimizer.
    """

    target: float = 0.5
    monotone: bool = False

    def __post_init__(self):
        if not (0.0 < self.target <= 1.0):
            raise OptimError(f"target: expected an ESS fraction in (0, 1], got {self.target}")

    def __call__(self, t: int, energies) -> float:
        return beta_for_ess(energies, self.target)


def make_schedule(schedule, b: float | None = None, target: float | None = None):
    """A schedule from a name ("polynomial", "logarithmic", "adaptive") or a callable."""
    if callable(schedule):
        return schedule
    if schedule == "polynomial":
        return Polynomial(0.993 if b is None else b)
    if schedule == "logarithmic":
        return Logarithmic(2.0 if b is None else b)
    if schedule == "adaptive":
        return AdaptiveEss(0.5 if target is None else target)
    raise OptimError(f"schedule: expected 'polynomial', 'logarithmic', 'adaptive' or a callable, "
                     f"got {schedule!r}")
