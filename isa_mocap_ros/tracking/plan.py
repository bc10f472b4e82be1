"""The frame's budget plan: how many evaluations each stage of a frame gets.

:class:`FrameBudget` is what one hypothesis may spend on a frame (the frame budget, or a heading check's
share; with or without the contour stage); the functions below size each stage's share from it (the
pelvis, torso, limb and contour stages, ``docs/tracking.md``) and note a skipped stage.
They read the tracker's configuration and moves, never change them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import MIN_LIMB_PROPOSALS


@dataclass(frozen=True)
class FrameBudget:
    """What one hypothesis may spend on a frame: ``evals`` evaluations (``TrackerConfig.search.evals``, or a heading
    hypothesis of a heading check alike) and whether the contour stage runs (``step(contour_stage=)``).
    Every stage sizes its share from it; the configuration is never changed mid-step."""

    evals: int
    contour: bool = True


def limb_share(tr, n_limbs: int, n: int | None = None) -> int:
    """Evaluations of the limb stage for ``n_limbs`` limbs with ``n`` drawn proposals each (default
    ``limb_proposals``): the drawn and the extrapolated proposals, the starting pose and the final
    pose."""
    n = tr.config.stages.limb_proposals if n is None else n
    return (n + len(tr.config.stages.limb_extrapolations)) * n_limbs + 2 if n_limbs else 0


def limb_proposals(tr, n_limbs: int, budget: FrameBudget) -> int:
    """Proposals per limb for ``n_limbs`` limbs: ``limb_proposals``, or as many as fit in a tenth
    of the frame budget."""
    if not n_limbs:
        return 0
    cfg = tr.config
    return max(0, min(cfg.stages.limb_proposals,
                      (budget.evals // 10 - 2) // n_limbs - len(cfg.stages.limb_extrapolations)))


def limb_stage(tr, notes, pred, budget: FrameBudget) -> tuple[list[str], list[str], int]:
    """The limb stage this frame: ``(limbs, those with hinge proposals only, proposals per limb)``,
    no limb when off, none in the model, or fewer than :data:`MIN_LIMB_PROPOSALS` fit in a tenth of
    the budget. The limbs are ``limb_proposal_limbs``, then any other limb whose hinge is folded in
    ``pred`` (``limb_fold_deg``, while each keeps ``limb_proposals`` within the tenth); a folded
    limb gets twist-and-hinge proposals even if it is in ``limb_hinge_limbs``."""
    cfg = tr.config
    have = {limb.name for limb in tr.limb_move.limbs}
    limbs = [name for name in cfg.stages.limb_proposal_limbs if name in have]
    if cfg.stages.limb_proposals <= 0:
        return [], [], 0
    if limbs and limb_proposals(tr, len(limbs), budget) < min(MIN_LIMB_PROPOSALS, cfg.stages.limb_proposals):
        if notes is not None:
            notes.append(f"limb stage skipped: fewer than {min(MIN_LIMB_PROPOSALS, cfg.stages.limb_proposals)} "
                         f"proposals per limb fit in a tenth of the frame budget ({budget.evals}; "
                         f"{len(limbs)} limbs)")
        return [], [], 0
    folded = set()
    if pred is not None and 0 < cfg.stages.limb_fold_deg < 180:
        fold = np.deg2rad(cfg.stages.limb_fold_deg)
        for limb in tr.limb_move.limbs:
            if abs(float(pred[limb.hinge_dof])) <= fold:
                continue
            if limb.name in limbs:
                folded.add(limb.name)
            elif 10 * limb_share(tr, len(limbs) + 1) <= budget.evals:   # joins while it fits
                limbs.append(limb.name)
                folded.add(limb.name)
                if notes is not None:
                    notes.append(f"limb stage: {limb.name} folded in the prediction "
                                 f"({np.rad2deg(float(pred[limb.hinge_dof])):.0f} deg), proposals for it too")
    hinge = [name for name in limbs if name in cfg.stages.limb_hinge_limbs and name not in folded]
    return limbs, hinge, limb_proposals(tr, len(limbs), budget)


def flat_algorithm(tr) -> tuple[str, dict]:
    """The configured algorithm's flat form (``h-isa`` → ``isa``, ``psapf`` → ``apf``) and its parameters."""
    from isa_mocap_ros.optim import inner_optimizer

    cfg = tr.config
    name = inner_optimizer(cfg.search.optimizer) or cfg.search.optimizer
    params = {k: v for k, v in cfg.search.params().items()
              if k not in ("partitions", "optimizer", "initial_population", "evals_per_partition",
                           "whole_generations")}
    return name, params


def flat_generation(tr, d: int) -> int:
    """Rows of a generation of the configured algorithm's flat form on ``d`` coordinates (the
    pelvis and torso stages' searches; it depends on the algorithm, its parameters and ``d``
    only, so it is computed once per ``d``)."""
    from isa_mocap_ros.optim import make_optimizer

    if d not in tr.generation_sizes:
        name, params = flat_algorithm(tr)
        tr.generation_sizes[d] = make_optimizer(name, np.zeros(d), np.ones(d), rng=np.random.default_rng(0),
                                                   **params).generation_size
    return tr.generation_sizes[d]


def pelvis_share(tr, notes, budget: FrameBudget) -> int | None:
    """Evaluations of the pelvis stage, or None (off, no root children, or below one generation + 1)."""
    cfg = tr.config
    if cfg.stages.pelvis_fraction <= 0 or tr.pelvis_reaim is None or not tr.pelvis_reaim.ops:
        return None
    share = int(budget.evals * cfg.stages.pelvis_fraction)
    n = flat_generation(tr, 6)
    if share - 1 < n:       # one evaluation is kept for the final pose
        if notes is not None:
            notes.append(f"pelvis stage skipped: its share ({share} evaluations) is below one generation "
                         f"of {flat_algorithm(tr)[0]} ({n}) + 1")
        return None
    return share


def torso_share(tr, notes, budget: FrameBudget) -> int | None:
    """Evaluations of the torso stage, or None (off, a flat algorithm, no torso partition, or below one
    generation + 2)."""
    from isa_mocap_ros.optim import inner_optimizer

    cfg = tr.config
    if cfg.stages.torso_fraction <= 0 or tr.torso_reaim is None or inner_optimizer(cfg.search.optimizer) is None:
        return None
    share = int(budget.evals * cfg.stages.torso_fraction)
    n = flat_generation(tr, tr.torso_reaim.coords.size)
    if share - 2 < n:       # the start's and the result's energies
        if notes is not None:
            notes.append(f"torso stage skipped: its share ({share} evaluations) is below one generation "
                         f"of {flat_algorithm(tr)[0]} ({n}) + 2")
        return None
    return share


def contour_extra(tr) -> int:
    """The contour stage's extra iterations on ``contour_extra_partitions`` (0 without such partitions)."""
    return tr.config.stages.contour_extra_iterations if tr.contour_extra_coords.size else 0


def contour_share(tr, notes, budget: FrameBudget) -> int | None:
    """Evaluations charged for the contour stage (``contour_iterations`` × (D + 1), plus
    ``contour_extra_iterations`` × (k + 1) for the k coordinates of ``contour_extra_partitions``,
    + 2 for the energies of the pose before and after), or None (off, or above a quarter of the
    frame budget, or no contour stage this frame)."""
    cfg = tr.config
    if cfg.stages.contour_iterations <= 0 or not budget.contour:
        return None
    share = cfg.stages.contour_iterations * (tr.model.dof + 1) \
        + contour_extra(tr) * (tr.contour_extra_coords.size + 1) + 2
    if 4 * share > budget.evals:
        if notes is not None:
            notes.append(f"contour stage skipped: its share ({share} evaluations) is above a quarter of the "
                         f"frame budget ({budget.evals})")
        return None
    return share
