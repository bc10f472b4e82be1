"""The per-frame tracker: prediction → optimizer on the energy → estimate (+ diagnostics).

Sources: yeguas_ea_vs_pf_mocap §3 (energy Eq. 4-5 over the V views, §3.3 hierarchy, search radius
0.5 rad around the prediction for every joint, budgets in evaluations per frame), gall_isa_introduction
§13.4.2 (prediction 13.28, prior 13.32-13.33: total energy ``E = E_data − η ln p(x)``).

One call of :meth:`Tracker.step` per frame set:

1. **Masks.** Views whose mask is missing (None), of the wrong size for its camera, or empty are
   skipped (a note says which and why). No usable view: the frame *falls back* to the last
   estimate (``fell_back=True``, no evaluation, the predictor is not updated, so a gap does not
   teach it a zero velocity). With ``gate_margin_px`` > 0 and an estimate, the prediction (step 2)
   comes first and each usable mask keeps only the foreground components touching the predicted
   silhouette grown by that margin (:mod:`.gate`; a view left empty is skipped).
2. **Prediction.** An external prediction (``prediction=``, e.g. from the prediction node) if it is
   finite and of length D, else the tracker's own predictor (``"ar"``: 13.28 of order
   ``predictor_order``; ``"constant_pose"``; ``"constant_velocity"``). A non-finite prediction is
   replaced by the last estimate (note). It is then clipped into the model's limits.
3. **Search box.** ``bounds = prediction ± radius``, clipped to the model limits, with radius
   ``search_radius_rad`` for every joint angle (EA-vs-PF §5: 0.5 rad),
   ``root_translation_radius_m`` for the root position and ``root_rotation_radius_rad`` for each
   rotation-vector component. The optimizer starts around the prediction with standard deviation
   ``joint_spread_rad`` (joints), ``root_translation_spread_m``, ``root_rotation_spread_rad``.
4. **Optimizer.** :func:`~isa_mocap_ros.optim.make_optimizer` by name with ``optimizer_params``
   (defaults per optimizer in :data:`DEFAULT_PARAMS`), hierarchical ones (``h-*``, ``psapf``) over
   ``model.partitions`` in the order ``partition_order`` (default root, left arm, right arm, torso,
   left leg, right leg: the arms before the torso, unlike §3.3's root, torso, limbs);
   at most ``evals_per_frame`` evaluations (:func:`~isa_mocap_ros.optim.minimize`), of which
   the stages below take their shares: the **pelvis stage** (:meth:`Tracker.refit_pelvis`)
   re-fits the root with the limbs below it kept in place (:mod:`.reaim`), the **torso stage**
   (:meth:`Tracker.refit_torso`) re-fits the spine and neck with the upper arms swung about the
   elbows, the **limb stage** (:meth:`Tracker.propose_limbs`) tries twist-and-hinge proposals for
   the arms (and a folded leg), knee proposals for the legs and, for every limb, its angles carried
   further along their motion, and keeps any that lowers the energy, then the optional
   **refinement stage** (:meth:`Tracker.refine`, hierarchical algorithms, off by default) searches
   the torso and both arms together with the algorithm's flat form. None runs on the automatically
   initialized frame. Every search runs **whole generations** (a hierarchical one splits its share
   into whole generations per partition, ``whole_generations``): fewer than one generation of a
   search's share stays unspent rather than end on a truncated generation of a few rows, whose
   weighted mean (ISA, APF) is that of a few random particles (``docs/tracking.md``, "Whole
   generations").
5. **Estimate.** ``estimate="optimizer"``: the algorithm's own estimate (ISA/APF weighted mean,
   CMA-ES mean, DE/PSO best); ``"best"``: the best evaluated particle. Then the predictor is updated.

**Gaps.** ``step(..., frames_elapsed=g)`` says ``g`` frame periods passed since the previous call's
frame (default 1; the estimator node counts them from the stamps when it could not keep up, and
``isa-mocap track --stride`` tracks every g-th frame). The tracker's own prediction then looks
``g`` periods ahead (summed over frames that fell back), and the predictor learns the motion per
period (:mod:`.predict`, "Gaps"); an external prediction is taken as made for this frame. With
consecutive frames nothing changes, bit for bit.

**Random streams.** Frame ``k`` (``frame_index``; the estimator node passes the stamp in ns, any
non-negative integer works) draws everything from ``numpy.random.default_rng([seed, k])``
(a ``SeedSequence`` of the pair), so a frame's result depends only on the seed, the frame key,
its masks and the tracker's state (predictor history), never on timing: same seed and inputs ⇒
identical estimates. The first frame's automatic initialization uses
``default_rng([seed, k, 1])``.

**First frame.** :meth:`Tracker.initialize` with ``pose=`` (given) or ``masks=`` (automatic,
:mod:`.init`); if neither was called, the first ``step`` with usable masks initializes itself
automatically and then tracks from that pose.
"""
from __future__ import annotations

import collections
import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from isa_mocap_ros.geometry import nearest_rotvec

from . import _fast_search
from .contour import ContourFit, ContourFitInfo
from .gate import gate_masks, predicted_silhouettes, visible_shares
from .hull import hull_filter, pose_box
from .init import InitError, initial_pose, root_from_masks
from .limbs import LIMBS, LimbMove
from .pelvis import PelvisMove
from .reaim import ReaimMove
from .predict import (ArPredictor, ConstantPosePredictor, ConstantVelocityPredictor, PredictionError, frame_periods,
                      frames_kwargs)

__all__ = ["TrackerError", "TrackerConfig", "FrameResult", "Tracker", "make_tracker", "DEFAULT_PARAMS",
           "PREDICTORS", "frame_rng"]

PREDICTORS = ("ar", "constant_pose", "constant_velocity")
#: Factor on the root's search spreads in the pelvis stage (:meth:`Tracker.refit_pelvis`), per
#: ``TrackerConfig.pelvis_move`` (each the measured best for its move, ``docs/tracking.md``).
PELVIS_SPREAD_SCALE = MappingProxyType({"reaim": 1.0, "world": 2.0})
#: Moves of the pelvis stage (``TrackerConfig.pelvis_move``).
PELVIS_MOVES = ("reaim", "world")
#: Generations the refinement stage's share must hold (:meth:`Tracker.refine`): with fewer, its estimate is
#: the weighted mean of a few random draws, and the budget it takes from the main search costs more than it
#: gives (measured: 7-frame walks at 160x120, 600 evaluations, 2 generations: 19.6 -> 28.7 mm).
REFINE_MIN_GENERATIONS = 4
#: Share of a view's foreground the mask gate may remove before ``FrameResult.notes`` says so.
GATE_NOTE_SHARE = 0.25
#: Smallest budget of a heading-check hypothesis (``TrackerConfig.init_confirm_share``) unless the frame
#: budget is smaller: the comparison paper's smallest budget, the least the tracker is measured at.
CONFIRM_MIN_EVALS = 500

#: Frames after a heading check that kept the winner for want of evidence (the sums within
#: ``init_confirm_margin``) until the heading is re-checked once (``TrackerConfig.init_confirm_frames``).
UNDECIDED_RECHECK_FRAMES = 10

#: The heading check's **travel cue**: people walk and run forwards. Over the last ``TRAVEL_FRAMES`` frame
#: periods, a root that moved at least ``TRAVEL_MIN_M_PER_FRAME`` per period (0.9 m/s at 30 fps) in a direction
#: more than ``TRAVEL_BACKWARDS_DEG`` from the estimate's heading starts a heading re-check (once per
#: ``TRAVEL_RECHECK_FRAMES`` frames), and in a check where this heading moves backwards and the other forwards
#: (within ``180 - TRAVEL_BACKWARDS_DEG``) this heading is kept only on a clearly lower energy sum
#: (``init_confirm_margin``) over all the check's frames, else the check switches. With two
#: views a figure seen from the front and from the back casts nearly the same silhouettes (generated jog,
#: seed 7: energy sums 0.2829 vs 0.2813 over the check), and the motion tells them apart.
TRAVEL_FRAMES = 3
TRAVEL_MIN_M_PER_FRAME = 0.03
TRAVEL_BACKWARDS_DEG = 135.0
TRAVEL_RECHECK_FRAMES = 15

#: The contour stage's fit replaces the pose unless its energy is more than this share above the pose's: the
#: fast energy's samples make a strict "lower" reject good fits (CMU walk seeds 0-7 10.30 mm / 2.69° knee
#: strictly lower, 10.00 / 2.60° at 0.1, 9.93 / 2.49° always kept), and always keeping follows noise and
#: occluders (robustness knee RMSE, 3 sequences: 50 % noise 11.3° always, 7.1° strict, 7.0° at 0.1).
CONTOUR_KEEP_TOLERANCE = 0.1

#: Fewest proposals per limb of the limb stage: when fewer fit in a tenth of the budget, the stage is skipped.
MIN_LIMB_PROPOSALS = 4
ESTIMATES = ("optimizer", "best")

#: Optimizer parameters used unless ``optimizer_params`` sets them (tuned on the silhouette energy,
#: see ``docs/tracking.md``); the library defaults apply to anything not listed.
DEFAULT_PARAMS: Mapping[str, Mapping[str, Any]] = MappingProxyType({
    "isa": MappingProxyType({"n_particles": 100, "kernel": "s2", "schedule": "adaptive", "target_ess": 0.3,
                             "c": 0.5, "variance": "selected"}),
    "h-isa": MappingProxyType({"n_particles": 30, "kernel": "s2", "schedule": "adaptive", "target_ess": 0.3,
                               "c": 0.5, "variance": "selected"}),
})


class TrackerError(ValueError):
    """Bad tracker configuration or argument (names the argument, the expected and the received value)."""


def _whole_generations(evals: int, generation: int) -> int:
    """``evals`` rounded down to whole generations (unchanged below one generation: the optimizer's error
    names it). The tracker's searches never end on a truncated generation, whose few rows would make a
    weighted-mean estimate (ISA, APF) that of a few random particles (``docs/tracking.md``, "Whole
    generations")."""
    return evals // generation * generation if evals >= generation else evals


def frame_rng(seed: int, frame_index: int, *extra: int) -> np.random.Generator:
    """The generator of one frame: ``default_rng([seed, frame_index, *extra])``."""
    return np.random.default_rng([int(seed), int(frame_index), *map(int, extra)])


def _check_number(name: str, value, *, lo: float | None = None, strict: bool = False, integer: bool = False):
    ok_type = (int, np.integer) if integer else (int, float, np.integer, np.floating)
    if isinstance(value, bool) or not isinstance(value, ok_type) or not math.isfinite(value) \
            or (lo is not None and (value <= lo if strict else value < lo)):
        kind = "an integer" if integer else "a finite number"
        bound = "" if lo is None else f" {'>' if strict else '>='} {lo}"
        raise TrackerError(f"{name}: expected {kind}{bound}, received {value!r}")


def _partition_names(name: str, value, example: str, *, empty: bool) -> tuple:
    """``value`` as a tuple of distinct partition names (a sequence of strings, not a string; ``empty``:
    whether none is allowed), else :class:`TrackerError` naming the setting."""
    if isinstance(value, str) or not isinstance(value, Sequence) or not all(isinstance(v, str) for v in value) \
            or len(set(value)) != len(value) or not (empty or value):
        raise TrackerError(f"{name}: expected distinct partition names (e.g. {example}), received {value!r}")
    return tuple(value)


def _partition_coords(model, names) -> np.ndarray:
    """Sorted coordinate indices of the partitions ``names`` the model has (the others ignored)."""
    return np.array(sorted(int(i) for k in names if k in model.partitions for i in model.partitions[k]),
                    dtype=np.int64)


def _limb_names(name: str, value) -> tuple:
    """``value`` as a tuple of distinct names among :data:`~.limbs.LIMBS`, else :class:`TrackerError`."""
    if isinstance(value, str) or not isinstance(value, Sequence) or any(v not in LIMBS for v in value) \
            or len(set(value)) != len(value):
        raise TrackerError(f"{name}: expected distinct names among {', '.join(LIMBS)}, received {value!r}")
    return tuple(value)


@dataclass(frozen=True)
class TrackerConfig:
    """Fixed settings of a :class:`Tracker` (see the module docstring and ``docs/tracking.md``).

    Attributes
    ----------
    optimizer : str
        Registry name (``isa``, ``apf``, ``psapf``, ``cmaes``, ``de``, ``pso``, ``h-isa``, ...).
        Default ``h-isa`` (ISA over the §3.3 hierarchy): plain ISA drifts off within a few frames
        at 1500 evaluations in 39 DOF (measured, ``docs/tracking.md``).
    evals_per_frame : int
        Energy evaluations per frame (EA-vs-PF: 500 / 1500 / 3000).
    optimizer_params : mapping
        Keyword arguments of the optimizer, over :data:`DEFAULT_PARAMS`.
    search_radius_rad : float
        Half-width of the search box of every joint angle around the prediction (EA-vs-PF: 0.5).
    joint_spread_rad : float
        Initial standard deviation of the joint angles around the prediction.
    spread_velocity_gain : float
        Joint angles that the prediction moves get wider initial spreads: joint ``j`` starts with
        ``sqrt(joint_spread_rad² + (k |p_j − x_j|)²)``, ``p`` the (damped) prediction and ``x`` the
        last estimate, ``k`` this gain; 0 keeps ``joint_spread_rad`` for every joint. The damped
        prediction covers only part of a fast swing, and a fixed small spread left the estimate
        trailing it (CMU walk, 8 seeds: mean joint error 31.7 → 25.7 mm, ``docs/tracking.md``).
        Not on the automatically initialized frame.
    root_translation_radius_m, root_translation_spread_m : float
        Search half-width and initial standard deviation of the root position, metres.
    root_rotation_radius_rad, root_rotation_spread_rad : float
        The same for each root rotation-vector component, radians.
    predictor : {"ar", "constant_pose", "constant_velocity"}
    predictor_order : int
        AR order (13.28).
    root_velocity_gain, joint_velocity_gain : float
        The tracker's own prediction is ``x_k + g (p − x_k)`` with the predictor's ``p`` and the
        last estimate ``x_k``: ``g = 1`` the predictor as it is, ``g = 0`` the last estimate
        (constant pose), between: a damped extrapolation. The root's 6 DOF use the first gain,
        the joint angles the second (see ``docs/tracking.md`` for the measured choice).
    prior_eta : float
        Weight η of the Parzen prior (13.33); 0 disables it.
    prior_file : str or None
        ``.npz`` written by :meth:`ParzenPrior.save` (used when no ``prior=`` object is given).
    energy_method : {"fast", "exact"}
    downsample : int
        Mask downsampling of the fast energy (1: none; measured more accurate at the same cost).
    n_model_points, n_mask_points : int
        Sample sizes of the fast energy (``SilhouetteEnergy``): model-template points and
        foreground pixels per view. The library defaults (160 / 96) leave the energy's minimum
        ≈ 20 mm from the true pose on the CMU walk; 640 / 384 halve the tracking error at about
        1.5× the cost (``docs/tracking.md``).
    estimate : {"optimizer", "best"}
    include_prediction : bool
        Make the prediction the first particle of the first generation (not for hierarchical
        optimizers, whose partitions start from the current estimate anyway).
    seed : int
    init_yaw_steps : int
        Headings of the automatic initialization's grid.
    init_refine_evals : int
        Evaluations of each of the initialization's four root refinements (0: none).
    init_spread_scale : float
        Factor on the initial spreads on the automatically initialized frame (its start is a
        standing pose, far from the tracked one's accuracy).
    init_keep : int
        The automatically initialized frame runs the frame's search from each of the
        initialization's (up to four) heading candidates; once every run has spent its first
        partition's share (hierarchical optimizers; a sixth of the budget for the others), only the
        ``init_keep`` runs with the lowest energy so far go on, and the lowest final energy wins.
        The runs kept end exactly as unpruned runs would (own random streams), so the result only
        changes when the pruned runs held the winner. 0 (or >= the candidates) runs every candidate
        to the end. Default 3: 6430 instead of 7696 evaluations on bags/demo's first frame (109
        instead of 124 ms offline; the network drops the sets that arrive meanwhile); on 120 first
        frames of five motions the unpruned winner was pruned once (3 mm apart), with 2 kept 7
        times; bags/demo and the CMU walk, seeds 0-7, unchanged bit for bit
        (``docs/tracking.md``, "A cheaper initialization").
    init_polish : bool
        On the automatically initialized frame, the winner of the heading candidates' searches (which
        run without stages) is searched once more as a tracked frame, from itself, with every stage (one
        more frame budget; stream ``[seed, k, 6]``), and replaces it when its energy is lower; a rival of
        the heading check (below) is polished alike (``[seed, k, 7]``), and the heading whose polished
        energy is lower becomes the winner. The first frame of a walk stands mid-stride, and from a
        standing pose without stages its knees stayed 20-38° off (CMU walk, every seed: 1.9° of the
        sequence's knee RMSE from that frame alone). CMU walk, 16 seeds: knee RMSE 2.60 → 1.78° (with
        ``contour_extra_iterations``); bags/demo seed 0, whose first frame faced backwards for three frames
        (max 289 mm), and the generated box seed 6, backwards throughout (224 mm), now start the right way
        (8.9 mm, 37.3 mm). Default True (``docs/tracking.md``, "The knee target").
    init_confirm_frames : int
        **Heading check** after the automatic initialization. A standing silhouette looks nearly
        the same from the front and from the back, so on the initialized frame the energies of
        opposite headings can differ by less than the energy's noise (bags/demo, seed 6: the
        winner faced backwards, 2 % below the right heading, and the whole run was lost). When the
        best run whose final heading differs from the winner's by more than 90° has an energy
        within ``init_confirm_ratio`` of the winner's, it is kept as a *rival* and tracked beside
        the winner (its own predictor, the same frame streams; each hypothesis with
        ``init_confirm_share`` of the frame budget) for up to this many
        frames: once the person moves, the wrong heading fits markedly worse (knees do not bend
        forwards). The energy sums decide: the winner is kept as soon as the rival's sum exceeds its
        own by the factor ``init_confirm_margin``; the rival wins only if, over all the frames, the
        winner's sum exceeds the rival's by that factor; otherwise the winner stays (the check acts
        on clear evidence only: at low resolution and budget both headings can fit alike, and one
        frame's sums misled on 3 of 120 first frames of generated motions). When the rival wins, the tracker takes over its state
        and that frame's result is the rival's (a note says so; the frames before it stay as
        estimated), and for as many frames as its predictor looks back it ignores external
        predictions (made from the estimates before the switch). Frames of the check report both
        hypotheses' evaluations and time. The check compares consecutive frames only: a frame that
        comes after a gap (``step``'s ``frames_elapsed`` > 1, as in real time when the sets that
        arrived during the initialization were dropped) ends it and keeps the winner, because
        after a gap both hypotheses are still catching up and their energies decided wrongly
        (measured). **Heading re-check**: on a later frame where more views use the person's
        foreground than when the heading was checked (the person walks into a camera's view), one
        search from a standing pose heading the other way runs on that frame (the initialization's
        four standing variants, pruned as ``init_keep`` says; about four frame budgets) and, when
        its estimate is within ``init_confirm_ratio`` of the frame's energy, is checked beside the
        track for up to this many frames as above. The same re-check runs once
        :data:`UNDECIDED_RECHECK_FRAMES` frames after a check that kept the winner for want of evidence
        (sums within the margin). Not after an initialization from a given pose.
        The generated walk starts seen by two cameras, which cannot tell front from back: 4 of 8
        seeds faced backwards to the end (163.8 mm); with the re-check, when the other two cameras
        see the person (frame 14-16), all 8 turn (34.0 mm; the frames before stay wrong); generated
        box 110.0 → 89.3 mm, jog 84.1 → 51.9 mm (8 seeds).
        0 turns both off (``docs/tracking.md``, "Checking the heading", "The heading re-check").
    init_confirm_share : float
        Share of the frame budget each hypothesis of the heading check gets, in (0, 1]; never below
        ``CONFIRM_MIN_EVALS`` (500, the comparison paper's smallest budget) or the frame budget if
        that is smaller. Default 1.0: each hypothesis is tracked as the frame would be. 0.5 makes a
        frame of the check cost one frame's budget (in real time 1-3 fewer sets dropped after the
        initialization on bags/demo) but decides worse when the person moves fast: on 120 first
        frames started mid-motion (CMU walk and the generated walk, jog, wave, box) it switched to
        the right heading 7 times instead of 12, lost runs 19 instead of 14 (``docs/tracking.md``,
        "Checking the heading").
    init_confirm_ratio : float
        How close (>= 1, a factor on the winner's energy) the rival's energy on the initialized
        frame must be for the heading check to run. Default 1.25.
    init_confirm_margin : float
        Factor (>= 1) by which a hypothesis' energy sum must be below the other's to decide the
        heading check. Default 1.1.
    heading_travel_cue : bool
        The heading check's **travel cue** (:data:`TRAVEL_FRAMES`): people walk and run forwards, so a track
        whose root travelled at least 0.09 m over the last 3 frames (0.9 m/s at 30 fps) in a direction more
        than 135° from its heading starts a heading re-check (at most every 15 frames), and a check where this
        heading moves backwards and the other forwards runs to its last frame and keeps this heading only if
        its energy sum is lower by ``init_confirm_margin``. With two views a person seen from the front and
        from the back casts nearly the same silhouettes (generated jog, 16 seeds: 4 tracked backwards for
        45-48 frames, 130-341 mm; with the cue 0, and 81.1 → 46.0 mm; generated walk 36.2 → 20.1 mm). Also
        after an initialization from a given pose (a track that flips later is turned back). Default True;
        False for a person who walks backwards on purpose.
    pelvis_fraction : float
        Share of the frame budget spent, after the main search, on the **pelvis stage**: the
        configured algorithm's flat form re-fits the 6 root DOF with the limbs below the root kept in
        place (``pelvis_move``). It undoes the slow drift of the weakly observed pelvis orientation
        that the spine and hips otherwise compensate (CMU walk, 4 seeds: mean joint error 34-64 mm →
        29-31 mm with the world move, ``docs/tracking.md``). 0 disables it; skipped (with a note)
        when its share is below one generation of the algorithm, and on the automatically
        initialized frame.
    pelvis_move : {"reaim", "world"}
        The pelvis stage's move. ``"reaim"`` (default, :mod:`.reaim`): the thighs swing about the
        knees and the lower spine about the chest, so a new pelvis moves the hip joint centres with
        the knees, shanks, chest, arms and head kept in the world — the hip centres set the knee
        angle, and they were the worst-estimated joints (CMU walk: 29 mm). ``"world"``
        (:mod:`.pelvis`, the stage before session 13): the root's children keep their world
        rotations, so the legs move with the hips. Measured with the torso stage and whole
        generations, 8 seeds (``docs/tracking.md``, "Re-aimed moves"): see the docs for the figures.
    torso_fraction : float
        Share of the frame budget spent, after the pelvis stage, on the **torso stage**
        (:meth:`Tracker.refit_torso`): the flat form searches the torso partition (spine, neck) with
        the upper arms swung about the elbows (:mod:`.reaim`), everything else held; the result
        replaces the pose when it lowers the energy. The hierarchy fits the torso with the arms held
        at their angles, so a torso move there drags the arms along; this one leaves the elbows and
        hands where they are. Hierarchical algorithms only (``h-*``, ``psapf``): a flat search moves torso
        and arms together already, and the stage's share cost the reference peers most (28 DOF, 1500,
        comparison design, 3 seeds: scipy-DE wave 16.0 → 19.9 mm, CMU walk 33.6 → 41.2; pycma 22.6 →
        32.8 / 51.7 → 65.2; our CMA-ES unchanged, PSO mixed). 0 disables it; skipped (with a note) when
        its share is below one generation + 2; not for models without a ``torso`` partition, nor on the
        automatically initialized frame. Default 0.13 since session 15 (0.25 before; with the session-14
        limb stage the main search gains more from the evaluations: CMU walk 16 seeds 16.74 → 15.75 mm,
        knee 5.80 → 4.86°; 0.07-0.25 measured, ``docs/tracking.md``, "The torso stage's share").
    limb_proposals : int
        Twist-and-hinge proposals per limb and frame of the **limb stage** (:mod:`.limbs`), after
        the pelvis stage: each limb's base joint turned about its upper bone and its hinge redrawn
        over its whole range, the rest of the pose held; the best proposal replaces the limb when
        it lowers the energy. It re-opens an arm the search left folded (forearm on the upper arm,
        twist 140-180° off) — a trap the ±0.5 rad search box cannot leave (CMU walk, 8 seeds: mean
        joint error 35.2 → 31.7 mm, the folded right arm gone; ``docs/tracking.md``). Takes
        ``(limb_proposals + len(limb_extrapolations)) × limbs + 2`` evaluations of the budget; when
        that is more than a tenth of the budget, each limb gets as many drawn proposals as fit in the
        tenth beside the extrapolated ones (500 evaluations, four limbs: 9), and the stage is skipped
        (with a note) when fewer than :data:`MIN_LIMB_PROPOSALS` fit. 0 disables it; not on the
        automatically initialized frame.
    limb_proposal_limbs : tuple of str
        Limbs of the limb stage, among ``left_arm``, ``right_arm``, ``left_leg``, ``right_leg``
        (limbs the model does not have are ignored). Default all four (the arms only before
        session 14).
    limb_hinge_limbs : tuple of str
        Limbs of the limb stage whose proposals redraw the hinge only, the base joint kept (no twist),
        unless the prediction folds the limb beyond ``limb_fold_deg``. Default both legs: the CMU
        walk's kick straightens and re-bends a knee by 25-30° per frame, beyond the search box, and
        the estimate trailed it by a frame or stayed folded (right knee 31° RMSE over frames 25-50,
        seed 0); with knee proposals on every frame the knee RMSE went 7.4 → 6.2° over 16 seeds
        (mean joint error 17.3 → 16.9 mm); twist-and-hinge proposals for the legs lost a right leg after
        the kick in 1 of 16 seeds (``docs/tracking.md``, "Knee proposals").
    limb_extrapolations : tuple of float
        **Extrapolated proposals** of the limb stage: per limb, the pose with the limb's angles (base
        joint and hinge) carried further along their motion since the last frame, ``x + k (x − x_prev)``
        for each factor ``k`` (:meth:`.limbs.LimbMove.extrapolate`), in the same batch as the other
        proposals (``len × limbs`` more evaluations of the stage's share). The search trails a limb that
        speeds up (a kick, a punch), and the motion it did find points the way. Default (1, 2, 3):
        CMU walk 16 seeds 17.01 → 16.74 mm (knee 6.23 → 5.80°); 8 seeds, bags/demo 13.29 → 12.86, generated
        wave 13.18 → 12.77 (``docs/tracking.md``, "Extrapolated proposals").
        () turns them off; not on a frame without a previous estimate.
    limb_fold_deg : float
        A limb folded in the prediction (hinge bent by more than this many degrees, absolute) gets
        twist-and-hinge proposals on that frame, and a limb not in ``limb_proposal_limbs`` joins the
        stage (while each limb keeps ``limb_proposals`` within the tenth). Default 130: a fast
        stride's prediction overshoots the knee to its 155° limit and the leg stayed folded there with
        the hip twisted for the rest of the sequence (CMU walk: 3 of 16 seeds); with the proposals
        for a folded knee, 0 of 16. A walk bends the knee to about 70°, a run to about 130°.
        0 (or >= 180): never.
    limb_hinge_window_deg : float
        The hinge-only proposals of the limb stage (``limb_hinge_limbs``, the knees) are drawn
        uniformly within this many degrees of the pose's hinge (and its limits) instead of over the
        whole range. Default 90 (session 18): under 70 % pixel noise a knee proposal over the whole
        range found a folded knee (140-155°, truth 5°) that the noisy masks scored lower on the
        generated walk's third frame in 8 of 8 seeds (knee RMSE 10.1°); with a 90° window 4.1°
        (45°: 5.4, 60°: 3.8; clean walks unchanged; 8 seeds, ``docs/tracking.md``, "Noise: the
        field vote and the knee proposals' window"). 0 (or >= 180): the whole range.
    partition_order : tuple of str
        Order in which a hierarchical algorithm (``h-*``, ``psapf``) searches ``model.partitions``
        (names the model does not have are ignored; every partition the model has must be named).
        Default root, left arm, right arm, torso, left leg, right leg. EA-vs-PF §3.3 goes root, torso,
        then the limbs, down the kinematic tree; but the torso stage then fits the spine and neck with
        the arms held at their prediction, and an arm the prediction left behind drags them after it
        (a generated wave: the raised arm lagged 20-70° behind for 30 frames and the neck bent 40-70°
        forward after it, every part compensating the others). The arms move more than the torso in most
        motions, so fitting them first on the predicted torso, then the torso with the arms found,
        measured better on every sequence at 1500 evaluations (8 / 8 / 4 / 4 seeds, segmented images:
        CMU walk 24.6 → 23.2 mm, bags/demo 19.7 → 17.9, generated wave 29.2 → 21.0, box 104 → 94; not
        on a 7-frame occluded walk at 600: 33.8 → 37.1; ``docs/tracking.md``, "The partition order").
        ``("root", "torso", "left_arm", "right_arm", "left_leg", "right_leg")`` is the paper's.
    refine_fraction : float
        Share of the frame budget spent, after the limb stage, on the **refinement stage**
        (:meth:`Tracker.refine`): for a hierarchical algorithm (``h-isa``, ``h-cmaes``, ``h-de``,
        ``h-pso``, ``psapf``), its flat form searches the coordinates of the partitions
        ``refine_partitions`` together, around the pose so far (the pose itself in the first
        generation; the frame's search box and initial spreads without the motion term), everything
        else held; its estimate replaces the pose when it lowers the energy. The §3.3 hierarchy
        fits the torso with the arms held at their prediction, then each arm on that torso: a
        waving arm drags the spine after it, and no partition alone can undo that shared error;
        searched together they can (wave 46 → 29 mm, CMU walk 25.7 → 24.6 mm, ``docs/tracking.md``,
        "The refinement stage"). 0 disables it; not for flat algorithms (their search is holistic
        already); skipped (with a note) when its share is below :data:`REFINE_MIN_GENERATIONS` (4)
        generations of the algorithm + 2 (h-isa: 1220 evaluations per frame at 0.1), and on the
        automatically initialized frame. Default 0 (0.1 before session 13): the torso stage does its
        job at the same budget with the arms kept in place (``docs/tracking.md``, "Re-aimed moves").
    refine_partitions : tuple of str
        Names of ``model.partitions`` searched together by the refinement stage (default the upper
        body: ``torso``, ``left_arm``, ``right_arm``; partitions the model does not have are
        ignored, none left: no stage).
    contour_iterations : int
        Iterations of the **contour stage** (:mod:`.contour`, :meth:`Tracker.fit_contours`), the last
        stage of a frame: Levenberg-Marquardt steps on the Plücker-line contour correspondences of ISA
        13.30-13.31 (model contour points of the current pose matched to the closest mask contour
        points, re-matched every iteration), the result kept unless its energy is more than
        :data:`CONTOUR_KEEP_TOLERANCE` (10 %) above the pose's. The population's weighted
        mean trails a fast knee and leaves a shared error of pelvis, torso and limbs that no partition
        alone can undo; the local fit removes most of it (CMU walk, 16 seeds: 15.74 → 10.09 mm, knee
        4.86 → 2.60°; ``docs/tracking.md``, "The contour stage"). Each iteration is charged
        ``D + 1`` evaluations of the frame budget (what the Jacobian costs by finite differences of the
        correspondence energy; the stage itself evaluates the silhouette energy only for the poses before and
        after it, + 2),
        taken from the main search. 0 disables it; skipped (with a note) when its share is above a
        quarter of the budget, and on the automatically initialized frame. Default 3.
    contour_extra_iterations : int
        Further steps of the contour stage on the coordinates of ``contour_extra_partitions`` alone, from
        the contour points of the pose the first steps fitted (rendered once), each charged ``k + 1``
        evaluations for the ``k`` coordinates (default 3; 0 = none). The knees trail a fast swing; more
        steps on every coordinate drag the arms (an arm before the body has no contour of its own).
    contour_extra_partitions : tuple of str
        Partitions of those steps (default the legs; partitions the model does not have are ignored).
    contour_points : int
        Model contour points per view and iteration of the contour stage (default 200).
    contour_max_px : float
        The contour stage drops pairs whose image contour point lies farther than this many pixels from
        the model's (default 2; 5 in session 16: a farther match is more often another limb's edge, noise
        or an occluder's edge; at 2 px the stage aligns what is nearly aligned and leaves the rest to the
        search: CMU walk 8 seeds 9.75 → 8.56 mm, wave 9.06 → 6.26, bags/demo 9.13 → 6.19; from the true
        first pose, CMU walk with 35 occluders knee RMSE 10.7 → 2.98°; ``docs/tracking.md``, "Tighter
        contour pairs").
    gate_margin_px : int
        **Mask gate** (:mod:`.gate`): once the tracker has an estimate, each usable mask keeps only
        the foreground components touching the predicted pose's silhouette grown by this many
        pixels (whole components: a limb beyond the margin but connected to the body stays); far
        blobs (occluders segmented as foreground) no longer pull the model towards them. 0 = off;
        not on the automatically initialized frame. A view that lost more than
        :data:`GATE_NOTE_SHARE` of its foreground gets a note; a view left empty is skipped as an
        empty view. Default 10 (at 320×240; robustness bench, 3 seeds, 35 occluders: CMU walk
        121 → 48 mm and knee RMSE 64 → 10°, generated walk 74 → 38 mm; clean walks unchanged bit
        for bit; ``docs/tracking.md``, "Occluders and the gate").
    hull_filter : bool
        **Visual-hull filter** (:mod:`.hull`), after the gate, once the tracker has an estimate:
        each view keeps the foreground pixels whose viewing ray has a point, inside the predicted
        pose's box (joints grown by ``hull_pad_m``), that the other views' foreground (dilated by
        ``hull_dilate_px``) confirms, all but ``hull_misses`` of them, and every foreground pixel
        inside the predicted silhouette grown by ``hull_keep_px``. What one view alone reports
        beyond where the person is expected — an occluder glued to the person there, which the gate
        keeps whole — goes. Needs two views or more (else nothing changes). Default on (robustness
        bench, 8 seeds, knee RMSE: 35 occluders CMU walk 5.03 → 3.23°, generated walk 2.95 → 3.00°
        and 16.3 → 13.8 mm; 70 % noise CMU walk 2.71 → 2.66°, generated walk 4.13 → 4.38°; clean
        walks unchanged; ``docs/tracking.md``, "The CMU walk's occluder failures analysed, and the
        visual-hull filter").
    hull_misses : int
        Views that may fail to confirm a point (default 0; 1 let the occluders back: CMU walk 5.9°).
    hull_dilate_px : int
        Dilation of the confirming views' foreground, pixels (default 2).
    hull_keep_px : int
        Foreground inside the predicted silhouette grown by this many pixels is kept unconfirmed
        (default 3): there the person is expected, and a hole in another view's mask (pixel noise, a
        limb at that view's border) must not cut it — without it the generated walk at 70 % noise
        lost a seed (8.5°).
    hull_pad_m : float
        Growth of the predicted joints' bounding box, metres (default 0.35: the limbs' radii and a
        fast limb's motion in one frame).
    view_weights : bool
        **Views counted by what they see**: once the tracker has an estimate, Eq. 5's mean over the
        views becomes ``sum_v w_v f_v / sum_v w_v`` with ``w_v`` the share of the predicted pose's
        silhouette inside view ``v``'s image (:func:`.gate.visible_shares`; 1 for a view that sees
        the whole body, so nothing changes while every view does). A view that sees a person
        entering or leaving it at its border — a few per cent of the body — no longer counts as
        much as one that sees all of it: its Eq. 4 compares only the visible sliver, normalised by
        that sliver's area, and a pose that fits the sliver at the legs' expense won. Default on
        (``make bench`` robustness, 8 seeds, generated walk, knee RMSE: clean 1.77 → 1.50°, 70 % noise
        3.71 → 3.38°, 35 occluders 2.95 → 2.09°, with the energy's template cut at the image border;
        the CMU walk, seen whole by every view, unchanged bit for bit; ``docs/tracking.md``, "Views at
        the image border").
    max_frames_ahead : float
        After frames the tracker did not see (``step``'s ``frames_elapsed`` > 1, or frames that
        fell back), its own prediction looks that many periods ahead, but at most this many
        (>= 1; default 5, 1/6 s at 30 fps): past that, extrapolating the last motion says little,
        so the predicted root position is moved instead by how far the foreground's triangulated
        centroid moved since the last estimate's frame (:meth:`Tracker._recentre`). The same
        happens after any gap while the predictor holds a single estimate (no motion known yet:
        real time after the automatic initialization; ``docs/tracking.md``). The predictor
        still learns the motion per period from the true gap.
    """

    optimizer: str = "h-isa"
    evals_per_frame: int = 1500
    optimizer_params: Mapping[str, Any] = field(default_factory=dict)
    search_radius_rad: float = 0.5
    joint_spread_rad: float = 0.05
    spread_velocity_gain: float = 1.5
    root_translation_radius_m: float = 0.25
    root_translation_spread_m: float = 0.015
    root_rotation_radius_rad: float = 0.5
    root_rotation_spread_rad: float = 0.025
    predictor: str = "ar"
    predictor_order: int = 1
    root_velocity_gain: float = 0.7
    joint_velocity_gain: float = 0.5
    prior_eta: float = 0.0
    prior_file: str | None = None
    energy_method: str = "fast"
    downsample: int = 1
    n_model_points: int = 640
    n_mask_points: int = 384
    estimate: str = "optimizer"
    include_prediction: bool = True
    seed: int = 0
    init_yaw_steps: int = 24
    init_refine_evals: int = 400
    init_spread_scale: float = 2.0
    init_keep: int = 3
    init_polish: bool = True
    init_confirm_frames: int = 3
    init_confirm_share: float = 1.0
    init_confirm_ratio: float = 1.25
    init_confirm_margin: float = 1.1
    heading_travel_cue: bool = True
    pelvis_fraction: float = 0.15
    pelvis_move: str = "reaim"
    torso_fraction: float = 0.13
    limb_proposals: int = 16
    limb_proposal_limbs: tuple = ("left_arm", "right_arm", "left_leg", "right_leg")
    limb_hinge_limbs: tuple = ("left_leg", "right_leg")
    limb_extrapolations: tuple = (1.0, 2.0, 3.0)
    limb_fold_deg: float = 130.0
    limb_hinge_window_deg: float = 90.0
    partition_order: tuple = ("root", "left_arm", "right_arm", "torso", "left_leg", "right_leg")
    refine_fraction: float = 0.0
    refine_partitions: tuple = ("torso", "left_arm", "right_arm")
    contour_iterations: int = 3
    contour_extra_iterations: int = 3
    contour_extra_partitions: tuple = ("left_leg", "right_leg")
    contour_points: int = 200
    contour_max_px: float = 2.0
    gate_margin_px: int = 10
    hull_filter: bool = True
    hull_misses: int = 0
    hull_dilate_px: int = 2
    hull_keep_px: int = 3
    hull_pad_m: float = 0.35
    view_weights: bool = True
    max_frames_ahead: float = 5.0

    def __post_init__(self) -> None:
        from isa_mocap_ros.optim import OPTIMIZERS

        if self.optimizer not in OPTIMIZERS:
            raise TrackerError(f"optimizer: expected one of {', '.join(OPTIMIZERS)}, received {self.optimizer!r}")
        _check_number("evals_per_frame", self.evals_per_frame, lo=1, integer=True)
        if not isinstance(self.optimizer_params, Mapping):
            raise TrackerError(f"optimizer_params: expected a mapping, received {type(self.optimizer_params).__name__}")
        bad = [k for k in self.optimizer_params if k in ("bounds", "rng", "rotation_blocks", "partitions", "x0",
                                                         "spread")]
        if bad:
            raise TrackerError(f"optimizer_params: expected algorithm parameters only, received {bad} "
                               "(set by the tracker)")
        object.__setattr__(self, "optimizer_params", MappingProxyType(dict(self.optimizer_params)))
        for name in ("search_radius_rad", "joint_spread_rad", "root_translation_radius_m", "root_translation_spread_m",
                     "root_rotation_radius_rad", "root_rotation_spread_rad"):
            _check_number(name, getattr(self, name), lo=0.0, strict=True)
        _check_number("spread_velocity_gain", self.spread_velocity_gain, lo=0.0)
        if self.predictor not in PREDICTORS:
            raise TrackerError(f"predictor: expected one of {', '.join(PREDICTORS)}, received {self.predictor!r}")
        _check_number("predictor_order", self.predictor_order, lo=1, integer=True)
        _check_number("max_frames_ahead", self.max_frames_ahead, lo=1.0)
        for name in ("root_velocity_gain", "joint_velocity_gain"):
            _check_number(name, getattr(self, name), lo=0.0)
        _check_number("prior_eta", self.prior_eta, lo=0.0)
        if self.prior_file is not None and not isinstance(self.prior_file, (str, Path)):
            raise TrackerError(f"prior_file: expected a path or None, received {self.prior_file!r}")
        if self.energy_method not in ("fast", "exact"):
            raise TrackerError(f"energy_method: expected 'fast' or 'exact', received {self.energy_method!r}")
        _check_number("downsample", self.downsample, lo=1, integer=True)
        _check_number("n_model_points", self.n_model_points, lo=1, integer=True)
        _check_number("n_mask_points", self.n_mask_points, lo=0, integer=True)
        if self.estimate not in ESTIMATES:
            raise TrackerError(f"estimate: expected one of {', '.join(ESTIMATES)}, received {self.estimate!r}")
        if not isinstance(self.include_prediction, bool):
            raise TrackerError(f"include_prediction: expected a bool, received {self.include_prediction!r}")
        _check_number("seed", self.seed, lo=0, integer=True)
        _check_number("init_yaw_steps", self.init_yaw_steps, lo=4, integer=True)
        _check_number("init_refine_evals", self.init_refine_evals, lo=0, integer=True)
        _check_number("init_spread_scale", self.init_spread_scale, lo=0.0, strict=True)
        _check_number("init_keep", self.init_keep, lo=0, integer=True)
        _check_number("init_confirm_frames", self.init_confirm_frames, lo=0, integer=True)
        _check_number("init_confirm_share", self.init_confirm_share, lo=0.0, strict=True)
        if self.init_confirm_share > 1.0:
            raise TrackerError(f"init_confirm_share: expected a share in (0, 1], received {self.init_confirm_share!r}")
        _check_number("init_confirm_ratio", self.init_confirm_ratio, lo=1.0)
        _check_number("init_confirm_margin", self.init_confirm_margin, lo=1.0)
        if not isinstance(self.heading_travel_cue, bool):
            raise TrackerError(f"heading_travel_cue: expected a bool, received {self.heading_travel_cue!r}")
        _check_number("pelvis_fraction", self.pelvis_fraction, lo=0.0)
        if self.pelvis_fraction >= 1.0:
            raise TrackerError(f"pelvis_fraction: expected a share in [0, 1), received {self.pelvis_fraction!r}")
        if self.pelvis_move not in PELVIS_MOVES:
            raise TrackerError(f"pelvis_move: expected one of {', '.join(PELVIS_MOVES)}, received {self.pelvis_move!r}")
        _check_number("torso_fraction", self.torso_fraction, lo=0.0)
        if self.torso_fraction >= 1.0:
            raise TrackerError(f"torso_fraction: expected a share in [0, 1), received {self.torso_fraction!r}")
        _check_number("limb_proposals", self.limb_proposals, lo=0, integer=True)
        for name in ("limb_proposal_limbs", "limb_hinge_limbs"):
            object.__setattr__(self, name, _limb_names(name, getattr(self, name)))
        ext = self.limb_extrapolations
        if isinstance(ext, (str, bytes)) or not isinstance(ext, Sequence) or not all(
                isinstance(k, (int, float, np.integer, np.floating)) and not isinstance(k, bool)
                and np.isfinite(k) and k > 0 for k in ext):
            raise TrackerError(f"limb_extrapolations: expected a sequence of positive factors, received {ext!r}")
        object.__setattr__(self, "limb_extrapolations", tuple(float(k) for k in ext))
        _check_number("limb_fold_deg", self.limb_fold_deg, lo=0.0)
        _check_number("limb_hinge_window_deg", self.limb_hinge_window_deg, lo=0.0)
        object.__setattr__(self, "partition_order", _partition_names(
            "partition_order", self.partition_order, "root, left_arm, right_arm, torso, left_leg, right_leg",
            empty=False))
        _check_number("refine_fraction", self.refine_fraction, lo=0.0)
        if self.refine_fraction >= 1.0:
            raise TrackerError(f"refine_fraction: expected a share in [0, 1), received {self.refine_fraction!r}")
        object.__setattr__(self, "refine_partitions", _partition_names(
            "refine_partitions", self.refine_partitions, "torso, left_arm, right_arm", empty=True))
        _check_number("contour_iterations", self.contour_iterations, lo=0, integer=True)
        _check_number("contour_extra_iterations", self.contour_extra_iterations, lo=0, integer=True)
        object.__setattr__(self, "contour_extra_partitions", _partition_names(
            "contour_extra_partitions", self.contour_extra_partitions, "left_leg, right_leg", empty=True))
        if not isinstance(self.init_polish, (bool, np.bool_)):
            raise TrackerError(f"init_polish: expected true or false, received {self.init_polish!r}")
        _check_number("contour_points", self.contour_points, lo=1, integer=True)
        _check_number("contour_max_px", self.contour_max_px, lo=0.0, strict=True)
        if self.pelvis_fraction + self.torso_fraction + self.refine_fraction >= 1.0:
            raise TrackerError(f"pelvis_fraction + torso_fraction + refine_fraction: expected below 1 (the main "
                               f"search needs a share), received {self.pelvis_fraction!r} + "
                               f"{self.torso_fraction!r} + {self.refine_fraction!r}")
        _check_number("gate_margin_px", self.gate_margin_px, lo=0, integer=True)
        if not isinstance(self.hull_filter, (bool, np.bool_)):
            raise TrackerError(f"hull_filter: expected a bool, received {self.hull_filter!r}")
        _check_number("hull_misses", self.hull_misses, lo=0, integer=True)
        _check_number("hull_dilate_px", self.hull_dilate_px, lo=0, integer=True)
        _check_number("hull_keep_px", self.hull_keep_px, lo=0, integer=True)
        _check_number("hull_pad_m", self.hull_pad_m, lo=0.0, strict=True)
        if not isinstance(self.view_weights, (bool, np.bool_)):
            raise TrackerError(f"view_weights: expected a bool, received {self.view_weights!r}")

    def params(self) -> dict:
        """Optimizer keyword arguments: :data:`DEFAULT_PARAMS` of the optimizer, then ``optimizer_params``."""
        out = dict(DEFAULT_PARAMS.get(self.optimizer, {}))
        out.update(self.optimizer_params)
        return out


@dataclass(frozen=True, eq=False)
class FrameResult:
    """What one :meth:`Tracker.step` produced.

    Attributes
    ----------
    x : (D,) ndarray or None
        The estimate (None only when the tracker has never had an estimate: no usable masks yet).
    energy : float
        Energy of the estimate as the optimizer reports it (nan when no optimization ran).
    n_evals : int
        Evaluations this frame (initialization included).
    spread : float
        Final population spread (mean over coordinates of the standard deviation), nan if none.
    time_s : float
        Wall time of the call.
    views_used : int
        Views whose mask entered the energy.
    notes : tuple of str
        Everything skipped or replaced, and why (``"view 2: empty mask; skipped"``, ...); with the
        mask gate (``gate_margin_px``) also each view that lost more than :data:`GATE_NOTE_SHARE`
        of its foreground (``"view 1: the gate removed 812 of 2440 foreground pixels (33 %)"``).
    fell_back : bool
        True when no optimization ran and ``x`` is the last estimate.
    prediction : (D,) ndarray or None
        The prediction the search was centred on.
    initialized : bool
        True on the frame that ran the automatic initialization.
    """

    x: np.ndarray | None
    energy: float
    n_evals: int
    spread: float
    time_s: float
    views_used: int
    notes: tuple = ()
    fell_back: bool = False
    prediction: np.ndarray | None = None
    initialized: bool = False


@dataclass(frozen=True)
class FrameBudget:
    """What one hypothesis may spend on a frame: ``evals`` evaluations (``evals_per_frame``, or a heading
    check's :meth:`Tracker.confirm_evals`) and whether the contour stage runs (``step(contour_stage=)``).
    Every stage sizes its share from it; the configuration is never changed mid-step."""

    evals: int
    contour: bool = True


def _make_predictor(config: TrackerConfig):
    if config.predictor == "ar":
        return ArPredictor(order=config.predictor_order)
    if config.predictor == "constant_pose":
        return ConstantPosePredictor()
    return ConstantVelocityPredictor()


class Tracker:
    """Per-frame pose tracker (see the module docstring).

    Parameters
    ----------
    model : BodyModel
    cameras : sequence of Camera
        One per view, in view order.
    config : TrackerConfig
    prior : ParzenPrior, optional
        Used when ``config.prior_eta > 0`` (else ``config.prior_file`` is loaded).
    energy : object, optional
        Data term with ``set_masks(masks)`` and ``__call__(X (n, D)) -> (n,)``; default
        :class:`~isa_mocap_ros.energy.silhouette.SilhouetteEnergy` with the config's method and
        downsampling.
    predictor : object, optional
        With ``update(x)``, ``predict()``, ``reset()`` (e.g. :class:`.published.PublishedPredictor`
        to reproduce the node network's numbers); default from ``config.predictor``.

    Examples
    --------
    >>> tracker = Tracker(model, rig.cameras, TrackerConfig(seed=1))      # doctest: +SKIP
    >>> tracker.initialize(masks=first_masks)                              # doctest: +SKIP
    >>> for k, masks in enumerate(frames):                                 # doctest: +SKIP
    ...     r = tracker.step(masks, k); print(r.x[:3], r.energy, r.notes)
    """

    def __init__(self, model, cameras: Sequence, config: TrackerConfig = TrackerConfig(), *, prior=None,
                 energy=None, predictor=None):
        if not isinstance(config, TrackerConfig):
            raise TrackerError(f"config: expected a TrackerConfig, received {type(config).__name__}")
        cams = list(cameras)
        if not cams:
            raise TrackerError("cameras: expected at least one camera, received none")
        for i, c in enumerate(cams):
            if not all(hasattr(c, a) for a in ("width", "height", "ray", "project")):
                raise TrackerError(f"cameras[{i}]: expected a Camera, received {type(c).__name__}")
        self.model = model
        self.cameras = cams
        self.config = config
        self.prior = None
        if config.prior_eta > 0:
            if prior is None and config.prior_file:
                from isa_mocap_ros.energy.prior import ParzenPrior

                prior = ParzenPrior.load(config.prior_file)
            if prior is None:
                raise TrackerError("prior: expected a ParzenPrior (prior= or config.prior_file) when prior_eta > 0, "
                                   "received none")
            if getattr(prior, "n_dof", model.dof) != model.dof:
                raise TrackerError(f"prior: expected a prior over {model.dof}-DOF poses, received one over "
                                   f"{prior.n_dof}")
            self.prior = prior
        own_energy = energy is None
        from isa_mocap_ros.energy.silhouette import SilhouetteEnergy
        if energy is None:

            energy = SilhouetteEnergy(model, cams, None, method=config.energy_method, downsample=config.downsample,
                                      n_model_points=config.n_model_points, n_mask_points=config.n_mask_points,
                                      rng=np.random.default_rng([config.seed, 2**32 - 1]))
        if not (callable(energy) and hasattr(energy, "set_masks")):
            raise TrackerError(f"energy: expected an object with set_masks() and __call__, received "
                               f"{type(energy).__name__}")
        self.energy = energy
        # the automatic initialization's grid scores rough standing poses: with the fine sample
        # sizes it picked a heading 180 deg off on bags/demo, with the library's coarse ones not
        self._init_energy = None
        if own_energy and config.energy_method == "fast":
            self._init_energy = SilhouetteEnergy(model, cams, None, method="fast", downsample=config.downsample,
                                                 rng=np.random.default_rng([config.seed, 2**32 - 2]))
        self.predictor = _make_predictor(config) if predictor is None else predictor
        self._last: np.ndarray | None = None
        self._elapsed = 0.0        # frame periods since the last estimate (step's frames_elapsed, summed)
        self._masks_last: list | None = None   # usable masks of the last estimate's frame (re-centring)
        self._masks_now: list | None = None    # usable masks of the frame being tracked
        self._pelvis = PelvisMove(model) if "root" in model.partitions else None
        self._pelvis_reaim = ReaimMove(model, [0]) if "root" in model.partitions else None
        # the torso stage's move: the joints of the torso partition (e.g. spine and neck), the arms re-aimed
        torso_joints = sorted({int(model.dof_joint[d]) for d in model.partitions.get("torso", ())})
        self._torso = ReaimMove(model, torso_joints) if torso_joints else None
        self._flat_generations: dict[int, int] = {}     # _flat_generation's cache
        self._limbs = LimbMove(model)
        self._contour = ContourFit(model, self.cameras, n_points=config.contour_points,
                                   max_px=config.contour_max_px)
        self._refine_coords = _partition_coords(model, config.refine_partitions)
        self._contour_extra_coords = _partition_coords(model, config.contour_extra_partitions)
        missing = [k for k in model.partitions if k not in config.partition_order]
        if missing:
            raise TrackerError(f"partition_order: expected every partition of model {model.name} "
                               f"({', '.join(model.partitions)}), missing {', '.join(missing)}")
        self._partitions = [np.asarray(model.partitions[k]) for k in config.partition_order if k in model.partitions]
        self.frames = 0
        self._contour_now = True               # step(contour_stage=...) of the frame being tracked
        # the heading check after an automatic initialization (config.init_confirm_frames)
        self._rival_start: tuple[np.ndarray, float, float] | None = None   # (pose, energy, winner's energy)
        self._rival: Tracker | None = None
        self._confirm = [0, 0.0, 0.0]      # frames compared, energy sums: this tracker, the rival
        self._heading_views = 0            # views the heading was checked with (re-checked when more see the person)
        self._recheck_at: int | None = None   # self.frames at which an undecided check is re-checked
        self._rechecked_undecided = False
        self._own_prediction_frames = 0    # frames left that ignore external predictions (after a switch)
        # (frame periods since the start, root x, y) of the last estimates: the travel cue (TRAVEL_FRAMES)
        self._roots: collections.deque = collections.deque(maxlen=TRAVEL_FRAMES + 1)
        self._clock = 0.0
        self._travel_recheck_after = 0     # self.frames from which the travel cue may start a re-check
        # h-isa on the fast energy runs compiled per partition (tracking/_fast_search.py, the same
        # numbers as the optimizer protocol); False: always through the protocol (tests compare both)
        self._compiled_search = True

    # ------------------------------------------------------------------ state
    @property
    def initialized(self) -> bool:
        """True once an estimate exists (given, automatic or tracked)."""
        return self._last is not None

    @property
    def last_estimate(self) -> np.ndarray | None:
        return None if self._last is None else self._last.copy()

    @property
    def checking_heading(self) -> bool:
        """True while the heading check after the automatic initialization runs (``init_confirm_frames``):
        it decides on consecutive frames only, so a caller that drops frames (the estimator node in
        real time) should hand it the frames that follow in sequence meanwhile."""
        return self._rival is not None

    def heading_recheck_pending(self, masks: Sequence) -> bool:
        """True when stepping ``masks`` next may start a heading re-check (more views with foreground
        than the heading was checked with, an undecided check's re-check due, or estimates that travel
        backwards): a caller that drops frames (the estimator node in real time) should hand the tracker
        the frames that follow in sequence, as for :attr:`checking_heading`, or the check ends at the
        first gap."""
        if self.config.init_confirm_frames <= 0 or self._last is None or self._rival is not None:
            return False
        if self._recheck_at is not None and self.frames + 1 >= self._recheck_at:
            return True
        if self._travel_recheck_due() is not None:
            return True
        if self._heading_views >= len(self.cameras):      # every view counted: no need to look at the masks
            return False
        usable, _ = self._check_masks(masks)
        return sum(m is not None for m in usable) > self._heading_views

    def reset(self) -> None:
        """Forget the estimates (the next step initializes again)."""
        self._last = None
        self._elapsed = 0.0
        self._masks_last = None
        self.predictor.reset()
        self._rival_start = self._rival = None
        self._own_prediction_frames = 0
        self._heading_views = 0
        self._recheck_at = None
        self._rechecked_undecided = False
        self._roots.clear()
        self._travel_recheck_after = 0

    @property
    def _has_heading(self) -> bool:
        """Whether the model's root turns by a 3-DOF rotation vector (a heading to check)."""
        return 3 in {len(b) for b in self.model.rotation_blocks}

    def _prior_active(self) -> bool:
        return self.prior is not None and self.config.prior_eta > 0

    def total_energy(self, X) -> np.ndarray:
        """Data term plus the prior ``−η ln p`` (13.33) of poses ``(n, D)`` under the current masks."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        E = np.asarray(self.energy(X), dtype=float)
        if self.prior is not None and self.config.prior_eta > 0:
            E = E + self.prior.energy(X, eta=self.config.prior_eta)
        return E

    def restricted_energy(self, x_base, coords):
        """:meth:`total_energy` for poses equal to ``x_base`` outside ``coords``, the same values: the
        data term's ``restrict`` (``SilhouetteEnergy.restrict``) plus the prior on the full poses; None
        when the data term has no ``restrict``. ``Hierarchical`` asks for it per partition."""
        restrict = getattr(self.energy, "restrict", None)
        data = restrict(x_base, coords) if callable(restrict) else None
        if data is None:
            return None

        def total(X):
            X = np.atleast_2d(np.asarray(X, dtype=float))
            E = np.asarray(data(X), dtype=float)
            if self.prior is not None and self.config.prior_eta > 0:
                E = E + self.prior.energy(X, eta=self.config.prior_eta)
            return E
        return total

    # ------------------------------------------------------------------ masks
    def _check_masks(self, masks) -> tuple[list, list[str]]:
        """Per view a usable mask or None, and notes on what was skipped."""
        V = len(self.cameras)
        notes: list[str] = []
        if masks is None:
            return [None] * V, ["masks: none given"]
        try:
            masks = list(masks)
        except TypeError:
            return [None] * V, [f"masks: expected a sequence of {V} masks, received {type(masks).__name__}"]
        if len(masks) != V:
            notes.append(f"masks: expected {V} views, received {len(masks)}"
                         + ("; missing views skipped" if len(masks) < V else "; extra views ignored"))
            masks = (masks + [None] * V)[:V]
        out: list = []
        for v, (cam, m) in enumerate(zip(self.cameras, masks)):
            if m is None:
                notes.append(f"view {v}: no mask; skipped")
                out.append(None)
                continue
            try:
                a = np.asarray(m)
            except Exception as exc:  # noqa: BLE001 - anything unreadable is skipped, with its reason
                notes.append(f"view {v}: unreadable mask ({type(exc).__name__}); skipped")
                out.append(None)
                continue
            if a.ndim != 2 or a.shape != (cam.height, cam.width):
                notes.append(f"view {v}: mask shape {a.shape}, expected ({cam.height}, {cam.width}); skipped")
                out.append(None)
                continue
            if a.dtype != np.uint8:
                if not np.issubdtype(a.dtype, np.number) and a.dtype != bool:
                    notes.append(f"view {v}: mask dtype {a.dtype}, expected numbers; skipped")
                    out.append(None)
                    continue
                a = np.where(np.nan_to_num(a.astype(float)) > 0, 255, 0).astype(np.uint8)
            if not a.any():
                notes.append(f"view {v}: empty mask (nobody in view); skipped")
                out.append(None)
                continue
            out.append(a)
        return out, notes

    def _set_masks(self, masks: list, notes: list[str], frame_index: int | None, weights=None) -> int:
        """Give the usable masks to the energy (with the view weights, if any, and if the energy takes
        them); returns the number of views it uses (0: none)."""
        if not any(m is not None for m in masks):
            return 0
        if frame_index is not None and isinstance(getattr(self.energy, "rng", None), np.random.Generator):
            # the energy samples foreground pixels at set_masks: draw them from this frame's stream
            self.energy.rng = frame_rng(self.config.seed, frame_index, 2)
        from isa_mocap_ros.energy.silhouette import SilhouetteEnergy, _mask_problem

        try:
            if weights is not None and isinstance(self.energy, SilhouetteEnergy):
                if not any(w > 0 and _mask_problem(m, c) is None for w, m, c in zip(weights, masks, self.cameras)):
                    weights = None             # no usable view sees the predicted body: count them alike
                self.energy.set_masks(masks, weights)
            else:
                self.energy.set_masks(masks)
        except ValueError as exc:          # EnergyError and friends: nothing usable after all
            notes.append(f"energy: masks rejected ({exc})")
            return 0
        for s in getattr(self.energy, "skipped_views", None) or ():
            notes.append(f"energy skipped view {s[0]}: {s[1]}" if isinstance(s, tuple) and len(s) == 2
                         else f"energy skipped view {s}")
        used = getattr(self.energy, "n_views_used", None)
        return int(used) if used is not None else sum(m is not None for m in masks)

    # ------------------------------------------------------------------ initialization
    def initialize(self, masks: Sequence | None = None, pose=None, *, frame_index: int = 0):
        """Set the first estimate: ``pose`` if given, else automatically from ``masks``.

        Parameters
        ----------
        masks : sequence of (H, W) array_like or None, optional
        pose : (D,) array_like, optional
        frame_index : int
            Frame key of the initialization's random stream.

        Returns
        -------
        InitResult or None
            The automatic initialization's result (None for a given pose).

        Raises
        ------
        TrackerError
            Neither argument, a pose of the wrong length or not finite, or no usable foreground.
        """
        self.reset()
        if pose is not None:
            try:
                x = np.asarray(self.model.validate_pose(pose, name="pose"), dtype=float)
            except ValueError as exc:
                raise TrackerError(str(exc)) from None
            if x.ndim != 1:
                raise TrackerError(f"pose: expected shape ({self.model.dof},), received {x.shape}")
            x = np.clip(x, self.model.lower, self.model.upper)
            self._masks_now = None          # no frame: nothing to re-centre from later
            self._accept(x)
            self._heading_views = len(self.cameras)     # a given pose's heading is not re-checked
            return None
        if masks is None:
            raise TrackerError("initialize: expected masks= or pose=, received neither")
        usable, notes = self._check_masks(masks)
        self._masks_now = usable
        if self._set_masks(usable, notes, frame_index) == 0:
            raise TrackerError(f"masks: expected foreground in at least one view, received none ({'; '.join(notes)})")
        cfg = self.config
        try:
            res = initial_pose(self.model, self.cameras, usable, self._init_energy_fn(usable, frame_index),
                               rng=frame_rng(cfg.seed, frame_index, 1), n_yaw=cfg.init_yaw_steps,
                               refine_evals=cfg.init_refine_evals)
        except InitError as exc:
            raise TrackerError(f"masks: automatic initialization failed: {exc}") from None
        self._accept(res.x)
        self._heading_views = res.views_used
        return res

    def _init_energy_fn(self, usable: list, frame_index: int):
        """The energy the automatic initialization scores its grid with (see ``__init__``)."""
        if self._init_energy is None:
            return self.total_energy
        self._init_energy.rng = frame_rng(self.config.seed, frame_index, 4)
        try:
            self._init_energy.set_masks(usable)
        except ValueError:
            return self.total_energy

        def fn(X):
            X = np.atleast_2d(np.asarray(X, dtype=float))
            E = np.asarray(self._init_energy(X), dtype=float)
            if self.prior is not None and self.config.prior_eta > 0:
                E = E + self.prior.energy(X, eta=self.config.prior_eta)
            return E
        return fn

    def _accept(self, x: np.ndarray) -> None:
        self._last = np.array(x, dtype=float)
        self.predictor.update(self._last, **frames_kwargs(self._elapsed or 1))
        self._clock += self._elapsed or 1
        self._roots.append((self._clock, float(self._last[0]), float(self._last[1])))
        self._elapsed = 0.0
        self._masks_last = self._masks_now
        self._masks_now = None

    # ------------------------------------------------------------------ one frame
    def _prediction(self, external, notes: list[str]) -> np.ndarray:
        """The (damped) prediction: ``external`` (e.g. the prediction node's) or the tracker's own.

        Both are damped the same way towards the last estimate (``root/joint_velocity_gain``), so the
        node network (prediction from the prediction node) and ``isa-mocap track`` (own predictor,
        same conversions) give identical numbers.
        """
        D = self.model.dof
        p = None
        if external is not None and self._own_prediction_frames > 0:
            notes.append("prediction: the external one follows the estimates from before the heading check's "
                         "switch; using the tracker's own")
            external = None
        if external is not None:
            try:
                p = np.asarray(external, dtype=float)
            except (TypeError, ValueError):
                p = None
            if p is None or p.shape != (D,):
                notes.append(f"prediction: expected shape ({D},), received "
                             f"{None if p is None else p.shape}; using the tracker's own")
                p = None
            elif not np.all(np.isfinite(p)):
                notes.append("prediction: non-finite values; using the tracker's own")
                p = None
        if p is None:
            try:
                ahead = min(self._elapsed or 1, self.config.max_frames_ahead)
                p = np.asarray(self.predictor.predict(**frames_kwargs(ahead)), dtype=float)
            except ValueError as exc:      # PredictionError: empty history (cannot happen once initialized)
                notes.append(f"prediction: {exc}; using the last estimate")
                return self._last.copy()
            if p.shape != (D,) or not np.all(np.isfinite(p)):
                notes.append("prediction: non-finite values; using the last estimate")
                return self._last.copy()
        cfg = self.config
        for blk in self.model.rotation_blocks:
            # a prediction that went through a JointState (roll/pitch/yaw) has |r| <= pi: near a
            # half turn it can lie on the other side of pi from the last estimate (demo, frame 127:
            # 174° vs -179° gave -72° after damping, and the track was lost)
            idx = list(blk)
            p = p.copy() if p is external else p
            p[idx] = nearest_rotvec(p[idx], self._last[idx])
        gain = np.full(D, cfg.joint_velocity_gain)
        gain[:6] = cfg.root_velocity_gain
        out = self._last + gain * (p - self._last)        # damped extrapolation
        if self._elapsed > cfg.max_frames_ahead or (self._elapsed > 1 and self._motion_unknown()):
            self._recentre(out, notes)
        return out

    def _motion_unknown(self) -> bool:
        """True when the predictor holds a single estimate (no motion to extrapolate: the frame after
        the first, e.g. in real time after the sets that came during the initialization were dropped)."""
        n = getattr(self.predictor, "n_estimates", None)
        return n is not None and int(n) < 2

    def _recentre(self, pred: np.ndarray, notes: list[str]) -> None:
        """After more frames than ``max_frames_ahead`` unseen — or after any gap when the predictor holds
        a single estimate (the first estimate's frame: no motion to extrapolate) — move the predicted
        root position (x, y) by how far the foreground moved: the triangulated mask centroid
        (:func:`.init.root_from_masks`) of this frame minus that of the last estimate's frame.
        Extrapolating the last motion over such a gap says little (in real time the automatic
        initialization alone takes 4-10 frame periods, and a person walking moves 0.2-0.5 m
        meanwhile), the foreground says where the body is."""
        if self._masks_last is None or self._masks_now is None:
            return
        try:
            c_last = root_from_masks(self.model, self.cameras, self._masks_last)[0]
            c_now = root_from_masks(self.model, self.cameras, self._masks_now)[0]
        except InitError:
            return
        pred[:2] = self._last[:2] + (c_now[:2] - c_last[:2])
        notes.append(f"prediction: {self._elapsed:g} frame periods since the last estimate; root moved with the "
                     f"foreground by {1e3 * float(np.hypot(*(c_now[:2] - c_last[:2]))):.0f} mm")

    def search_box(self, center) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bounds ``(lo, hi)`` and initial spreads ``(D,)`` around a (clipped) prediction."""
        cfg, m = self.config, self.model
        radius = np.full(m.dof, cfg.search_radius_rad)
        radius[:3] = cfg.root_translation_radius_m
        radius[3:6] = cfg.root_rotation_radius_rad
        spread = np.full(m.dof, cfg.joint_spread_rad)
        spread[:3] = cfg.root_translation_spread_m
        spread[3:6] = cfg.root_rotation_spread_rad
        c = np.clip(np.asarray(center, dtype=float), m.lower, m.upper)
        lo = np.maximum(c - radius, m.lower)
        hi = np.minimum(c + radius, m.upper)
        tight = hi - lo < 1e-9                 # a prediction on a limit: keep a sliver of room
        lo[tight] = np.maximum(m.lower[tight], hi[tight] - 1e-6)
        hi[tight] = lo[tight] + 1e-6
        return lo, hi, spread

    def _search(self, pred: np.ndarray, rng: np.random.Generator, budget: FrameBudget, spread_scale: float = 1.0,
                notes=None, stages: bool = True):
        """The frame's optimizer around ``pred`` (not yet run), its share of the budget, the stages
        ``(pelvis share or None, limb stage's limbs, refinement share or None)`` and the search box
        ``(lo, hi, spread, spread without the motion term)`` (see :meth:`_optimize`)."""
        from isa_mocap_ros.optim import inner_optimizer, make_optimizer

        cfg = self.config
        lo, hi, spread = self.search_box(pred)
        base = spread * spread_scale
        spread = base.copy()              # the motion term widens the main search's spreads only
        if stages and cfg.spread_velocity_gain > 0 and self._last is not None:
            moved = cfg.spread_velocity_gain * np.abs(pred[6:] - self._last[6:])
            spread[6:] = np.sqrt(spread[6:] ** 2 + moved ** 2)
        x0 = np.clip(pred, lo, hi)
        params = cfg.params()
        if inner_optimizer(cfg.optimizer) is not None:
            params.setdefault("partitions", self._partitions)
            # whole generations (not on the automatically initialized frame, whose runs from the heading
            # candidates keep the proportional split their pruning and heading choice were measured with)
            params.setdefault("whole_generations", stages)
        elif cfg.include_prediction and "initial_population" not in params:
            # first generation: the prediction itself plus draws around it (so the estimate
            # can never be worse than the prediction by the energy's own measure)
            n = make_optimizer(cfg.optimizer, x0, spread, rng=np.random.default_rng(0), bounds=(lo, hi),
                               **params).generation_size
            P = np.clip(x0 + rng.standard_normal((n, x0.size)) * spread, lo, hi)
            P[0] = x0
            params["initial_population"] = P
        opt = make_optimizer(cfg.optimizer, x0, spread, rng=rng, bounds=(lo, hi),
                             rotation_blocks=self.model.rotation_blocks, **params)
        share = self._pelvis_share(notes, budget) if stages else None
        torso = self._torso_share(notes, budget) if stages else None
        limbs = self._limb_stage(notes, x0, budget) if stages else ([], [], 0)
        refine = self._refine_share(notes, budget) if stages else None
        contour = self._contour_share(notes, budget) if stages else None
        budget = budget.evals - (share or 0) - (torso or 0) - self._limb_share(len(limbs[0]), limbs[2]) \
            - (refine or 0) - (contour or 0)
        if torso is not None:
            # the torso stage never starves the main search: two generations per partition stay
            need = 2 * (sum(self._flat_generation(len(p)) for p in self._partitions)
                        if inner_optimizer(cfg.optimizer) is not None else opt.generation_size)
            if budget < need:
                if notes is not None:
                    notes.append(f"torso stage skipped: with its share ({torso} evaluations) the main search would "
                                 f"keep {budget}, fewer than two generations per partition ({need})")
                budget += torso
                torso = None
        if inner_optimizer(cfg.optimizer) is None:
            budget = _whole_generations(budget, opt.generation_size)     # (hierarchical: its split does this)
        return opt, budget, (share, torso, limbs, refine, contour), (lo, hi, spread, base)

    def _optimize(self, pred: np.ndarray, rng: np.random.Generator, budget: FrameBudget, spread_scale: float = 1.0,
                  notes=None, stages: bool = True):
        """One optimizer run of the frame budget around ``pred`` (raises the optimizer's errors), then
        the pelvis stage (``config.pelvis_fraction`` of the budget), the torso stage
        (``config.torso_fraction``), the limb stage (``config.limb_proposals``) and the refinement
        stage (``config.refine_fraction``), each also given what the searches before it left unspent
        (they run whole generations; the limb stage takes the rest as more proposals, so a frame
        leaves fewer evaluations unspent than it has limbs in the stage);
        ``spread_scale`` multiplies the initial spreads (the first frame starts from a rough pose);
        skipped stages are noted in ``notes``. The heading candidates' searches of the automatically
        initialized frame have no stage (``stages=False``): from a rough standing pose the pelvis stage
        turned the pelvis against the legs (bags/demo: 270-340 mm on the first frames, measured); its
        polish (``config.init_polish``) then searches the winner with every stage."""
        from isa_mocap_ros.optim import minimize

        opt, budget, stage_shares, (lo, hi, spread, base) = self._search(pred, rng, budget, spread_scale, notes,
                                                                         stages)
        share, torso, limbs, refine, contour = stage_shares
        if self._compiled_search and _fast_search.supported(opt, self.energy, self._prior_active()):
            res = _fast_search.run_hisa(opt, self.energy, budget)      # the same numbers, compiled per partition
        else:
            res = minimize(opt, _TotalEnergy(self), max_evals=budget)
        # what a search leaves unspent (less than a generation: whole generations) goes to the next stage
        spare = budget - res.n_evals
        if share is not None:
            x, e, n = self.refit_pelvis(res.x, evals=share + spare, rng=rng, bounds=(lo, hi), spread=spread)
            spare += share - n
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
        if torso is not None:
            x, e, n, _ = self.refit_torso(res.x, evals=torso + spare, rng=rng,
                                          energy=res.energy if share is not None else None, bounds=(lo, hi),
                                          spread=spread)
            spare += torso - n
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
        limbs, hinge, n_limb = limbs
        if limbs:
            extra = 0 if refine is not None else spare // len(limbs)       # more proposals with the rest
            x, e, n, _ = self.propose_limbs(res.x, n=n_limb + extra, rng=rng, limbs=limbs, hinge_only=hinge,
                                            last=self._last)
            spare -= extra * len(limbs)
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
        if refine is not None:
            exact = share is not None or torso is not None or bool(limbs)   # else res.energy may be a particle's
            x, e, n, _ = self.refine(res.x, evals=refine + spare, rng=rng, energy=res.energy if exact else None,
                                     bounds=(lo, hi), spread=base)
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
        if contour is not None:
            x, e, n, info = self.fit_contours(res.x)
            if info.stopped and notes is not None:
                notes.append(f"contour stage: stopped after {info.iterations} iterations ({info.stopped})")
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
        return res

    def _initial_runs(self, starts: list, frame_index: int, notes: list[str], budget: FrameBudget,
                      stream: tuple = ()) -> tuple[list, int]:
        """The automatically initialized frame's search from every start (heading candidate), pruned
        to ``config.init_keep`` runs at the checkpoint (see :class:`TrackerConfig`): the list of
        ``(start index, result, start)`` of the runs that ended, and the evaluations of all runs.
        Raises the optimizer's errors."""
        cfg = self.config
        runs = []
        for j, pred in enumerate(starts):
            if stream:          # the heading re-check's runs: their own streams
                rng = frame_rng(cfg.seed, frame_index, *stream, j)
            else:
                rng = frame_rng(cfg.seed, frame_index) if j == 0 else frame_rng(cfg.seed, frame_index, 3, j)
            opt, evals, _, _ = self._search(pred, rng, budget, cfg.init_spread_scale, notes if j == 0 else None,
                                            stages=False)
            if self._compiled_search and _fast_search.supported(opt, self.energy, self._prior_active()):
                # compiled h-isa, paused after its first partition (the same numbers as below)
                runs.append((j, _fast_search.HisaRun(opt, self.energy, evals), pred, None))
                continue
            # bind + iterate + result() is minimize(), split at the checkpoint: the end of the first
            # partition (hierarchical optimizers, whose shares bind() sets) or a sixth of the budget
            opt.bind(_TotalEnergy(self), max_evals=evals)
            shares = getattr(opt, "shares", None)
            runs.append((j, opt, pred, shares[0] if shares else evals // 6))
        n_pruned = 0
        if 0 < cfg.init_keep < len(runs):
            for _, opt, _, checkpoint in runs:
                if checkpoint is None:
                    opt.advance(1)
                    continue
                for _ in opt:
                    if opt.n_evals >= checkpoint:
                        break
            ranked = sorted(runs, key=lambda r: r[1].best_energy)      # stable: ties keep the start order
            n_pruned = sum(r[1].n_evals for r in ranked[cfg.init_keep:])
            runs = sorted(ranked[:cfg.init_keep], key=lambda r: r[0])
        out = []
        for j, opt, pred, checkpoint in runs:
            if checkpoint is None:
                out.append((j, opt.advance().result(), pred))
                continue
            for _ in opt:
                pass
            out.append((j, opt.result(), pred))
        return out, n_pruned + sum(res.n_evals for _, res, _ in out)

    def _limb_share(self, n_limbs: int, n: int | None = None) -> int:
        """Evaluations of the limb stage for ``n_limbs`` limbs with ``n`` drawn proposals each (default
        ``limb_proposals``): the drawn and the extrapolated proposals, the starting pose and the final
        pose."""
        n = self.config.limb_proposals if n is None else n
        return (n + len(self.config.limb_extrapolations)) * n_limbs + 2 if n_limbs else 0

    def _limb_proposals(self, n_limbs: int, budget: FrameBudget) -> int:
        """Proposals per limb for ``n_limbs`` limbs: ``limb_proposals``, or as many as fit in a tenth
        of the frame budget."""
        if not n_limbs:
            return 0
        cfg = self.config
        return max(0, min(cfg.limb_proposals,
                          (budget.evals // 10 - 2) // n_limbs - len(cfg.limb_extrapolations)))

    def _limb_stage(self, notes, pred, budget: FrameBudget) -> tuple[list[str], list[str], int]:
        """The limb stage this frame: ``(limbs, those with hinge proposals only, proposals per limb)``,
        no limb when off, none in the model, or fewer than :data:`MIN_LIMB_PROPOSALS` fit in a tenth of
        the budget. The limbs are ``limb_proposal_limbs``, then any other limb whose hinge is folded in
        ``pred`` (``limb_fold_deg``, while each keeps ``limb_proposals`` within the tenth); a folded
        limb gets twist-and-hinge proposals even if it is in ``limb_hinge_limbs``."""
        cfg = self.config
        have = {limb.name for limb in self._limbs.limbs}
        limbs = [name for name in cfg.limb_proposal_limbs if name in have]
        if cfg.limb_proposals <= 0:
            return [], [], 0
        if limbs and self._limb_proposals(len(limbs), budget) < min(MIN_LIMB_PROPOSALS, cfg.limb_proposals):
            if notes is not None:
                notes.append(f"limb stage skipped: fewer than {min(MIN_LIMB_PROPOSALS, cfg.limb_proposals)} "
                             f"proposals per limb fit in a tenth of the frame budget ({budget.evals}; "
                             f"{len(limbs)} limbs)")
            return [], [], 0
        folded = set()
        if pred is not None and 0 < cfg.limb_fold_deg < 180:
            fold = np.deg2rad(cfg.limb_fold_deg)
            for limb in self._limbs.limbs:
                if abs(float(pred[limb.hinge_dof])) <= fold:
                    continue
                if limb.name in limbs:
                    folded.add(limb.name)
                elif 10 * self._limb_share(len(limbs) + 1) <= budget.evals:   # joins while it fits
                    limbs.append(limb.name)
                    folded.add(limb.name)
                    if notes is not None:
                        notes.append(f"limb stage: {limb.name} folded in the prediction "
                                     f"({np.rad2deg(float(pred[limb.hinge_dof])):.0f} deg), proposals for it too")
        hinge = [name for name in limbs if name in cfg.limb_hinge_limbs and name not in folded]
        return limbs, hinge, self._limb_proposals(len(limbs), budget)

    def _flat_algorithm(self) -> tuple[str, dict]:
        """The configured algorithm's flat form (``h-isa`` → ``isa``, ``psapf`` → ``apf``) and its parameters."""
        from isa_mocap_ros.optim import inner_optimizer

        cfg = self.config
        name = inner_optimizer(cfg.optimizer) or cfg.optimizer
        params = {k: v for k, v in cfg.params().items()
                  if k not in ("partitions", "optimizer", "initial_population", "evals_per_partition",
                               "whole_generations")}
        return name, params

    def _flat_generation(self, d: int) -> int:
        """Rows of a generation of the configured algorithm's flat form on ``d`` coordinates (the
        pelvis and refinement stages' searches; it depends on the algorithm, its parameters and ``d``
        only, so it is computed once per ``d``)."""
        from isa_mocap_ros.optim import make_optimizer

        if d not in self._flat_generations:
            name, params = self._flat_algorithm()
            self._flat_generations[d] = make_optimizer(name, np.zeros(d), np.ones(d), rng=np.random.default_rng(0),
                                                       **params).generation_size
        return self._flat_generations[d]

    def _pelvis_share(self, notes, budget: FrameBudget) -> int | None:
        """Evaluations of the pelvis stage, or None (off, no root children, or below one generation + 1)."""
        cfg = self.config
        if cfg.pelvis_fraction <= 0 or self._pelvis is None:
            return None
        if not (self._pelvis_reaim.ops if cfg.pelvis_move == "reaim" else self._pelvis.children):
            return None
        share = int(budget.evals * cfg.pelvis_fraction)
        n = self._flat_generation(6)
        if share - 1 < n:       # one evaluation is kept for the final pose
            if notes is not None:
                notes.append(f"pelvis stage skipped: its share ({share} evaluations) is below one generation "
                             f"of {self._flat_algorithm()[0]} ({n}) + 1")
            return None
        return share

    def _torso_share(self, notes, budget: FrameBudget) -> int | None:
        """Evaluations of the torso stage, or None (off, a flat algorithm, no torso partition, or below one
        generation + 2)."""
        from isa_mocap_ros.optim import inner_optimizer

        cfg = self.config
        if cfg.torso_fraction <= 0 or self._torso is None or inner_optimizer(cfg.optimizer) is None:
            return None
        share = int(budget.evals * cfg.torso_fraction)
        n = self._flat_generation(self._torso.coords.size)
        if share - 2 < n:       # the start's and the result's energies
            if notes is not None:
                notes.append(f"torso stage skipped: its share ({share} evaluations) is below one generation "
                             f"of {self._flat_algorithm()[0]} ({n}) + 2")
            return None
        return share

    def _refine_share(self, notes, budget: FrameBudget) -> int | None:
        """Evaluations of the refinement stage, or None (off, a flat algorithm, no partition of
        ``refine_partitions`` in the model, or below ``REFINE_MIN_GENERATIONS`` generations + 2)."""
        from isa_mocap_ros.optim import inner_optimizer

        cfg = self.config
        if cfg.refine_fraction <= 0 or inner_optimizer(cfg.optimizer) is None or not self._refine_coords.size:
            return None
        share = int(budget.evals * cfg.refine_fraction)
        n = self._flat_generation(self._refine_coords.size)
        if share < REFINE_MIN_GENERATIONS * n + 2:    # + the start's and the result's energies
            if notes is not None:
                notes.append(f"refinement stage skipped: its share ({share} evaluations) is below "
                             f"{REFINE_MIN_GENERATIONS} generations of {self._flat_algorithm()[0]} "
                             f"({REFINE_MIN_GENERATIONS} x {n}) + 2")
            return None
        return share

    def _contour_extra(self) -> int:
        """The contour stage's extra iterations on ``contour_extra_partitions`` (0 without such partitions)."""
        return self.config.contour_extra_iterations if self._contour_extra_coords.size else 0

    def _contour_share(self, notes, budget: FrameBudget) -> int | None:
        """Evaluations charged for the contour stage (``contour_iterations`` × (D + 1), plus
        ``contour_extra_iterations`` × (k + 1) for the k coordinates of ``contour_extra_partitions``,
        + 2 for the energies of the pose before and after), or None (off, or above a quarter of the
        frame budget, or no contour stage this frame)."""
        cfg = self.config
        if cfg.contour_iterations <= 0 or not budget.contour:
            return None
        share = cfg.contour_iterations * (self.model.dof + 1) \
            + self._contour_extra() * (self._contour_extra_coords.size + 1) + 2
        if 4 * share > budget.evals:
            if notes is not None:
                notes.append(f"contour stage skipped: its share ({share} evaluations) is above a quarter of the "
                             f"frame budget ({budget.evals})")
            return None
        return share

    def fit_contours(self, x, *, iterations: int | None = None, extra_iterations: int | None = None):
        """The contour stage on pose ``x`` under the current masks (:class:`~.contour.ContourFit`):
        ``config.contour_iterations`` (or ``iterations``) steps over all coordinates, then
        ``config.contour_extra_iterations`` (or ``extra_iterations``) over the coordinates of
        ``config.contour_extra_partitions`` alone, from that pose's contour points (rendered again);
        returns ``(pose, its energy, evaluations charged, ContourFitInfo)`` (the info of both fits
        together). The fitted pose replaces ``x`` unless its silhouette energy is more than
        :data:`CONTOUR_KEEP_TOLERANCE` above ``x``'s (both evaluated in one batch: a mask contour bent by an
        occluder or noise can pull the fit away); the evaluations charged are ``(D + 1)`` per iteration
        taken over all coordinates, ``(k + 1)`` per iteration over ``k`` of them, + 2."""
        if self._masks_now is None:
            raise TrackerError("fit_contours: no masks yet (call step first)")
        iterations = self.config.contour_iterations if iterations is None else iterations
        extra = self._contour_extra() if extra_iterations is None else extra_iterations
        x = np.asarray(x, dtype=np.float64)
        self._contour.set_masks(self._masks_now)
        y, info = self._contour.fit(x, iterations=iterations)
        n = info.iterations * (self.model.dof + 1) + 2
        if extra and self._contour_extra_coords.size and not info.stopped:
            y, more = self._contour.fit(y, iterations=extra, coords=self._contour_extra_coords,
                                        render_each=False)
            n += more.iterations * (self._contour_extra_coords.size + 1)
            info = ContourFitInfo(info.iterations + more.iterations, info.correspondences + more.correspondences,
                                  info.rms_px + more.rms_px, more.stopped)
        e_x, e_y = (float(v) for v in self.total_energy(np.stack([x, y])))
        return (y, e_y, n, info) if e_y < e_x + CONTOUR_KEEP_TOLERANCE * abs(e_x) else (x, e_x, n, info)

    def refine(self, x, *, evals: int, rng: np.random.Generator, energy: float | None = None, bounds=None,
               spread=None) -> tuple[np.ndarray, float, int, bool]:
        """The refinement stage on pose ``x`` under the current masks: the configured hierarchical
        algorithm's flat form (``h-isa`` → ``isa`` with the same parameters, ``psapf`` → ``apf``) over
        the coordinates of ``config.refine_partitions`` as one block, the rest of ``x`` held, its first
        generation ``x`` and draws around it; its estimate replaces those coordinates when it lowers
        the energy.

        ``energy`` is ``x``'s energy if known (else one evaluation computes it); the search gets whole
        generations of the rest of ``evals`` but one, which gives the final pose's energy, so the stage
        spends at most ``evals`` (less by under a generation). ``bounds``/``spread`` default to
        :meth:`search_box` around ``x``. Returns ``(pose, its energy, evaluations, replaced)``.
        """
        from isa_mocap_ros.optim import inner_optimizer, make_optimizer, minimize

        cfg, m, c = self.config, self.model, self._refine_coords
        if inner_optimizer(cfg.optimizer) is None:
            raise TrackerError(f"refine: the optimizer {cfg.optimizer!r} is not hierarchical")
        if not c.size:
            raise TrackerError(f"refine: none of refine_partitions {list(cfg.refine_partitions)} is a partition of "
                               f"model {m.name} ({', '.join(m.partitions)})")
        x = np.clip(np.asarray(x, dtype=float), m.lower, m.upper)
        if bounds is None or spread is None:
            box = self.search_box(x)
            bounds = box[:2] if bounds is None else bounds
            spread = box[2] if spread is None else spread
        spread = np.asarray(spread, dtype=float)
        used = 0
        if energy is None:
            energy, used = float(self.total_energy(x[None, :])[0]), 1
        # x is a particle of the first generation (a limb proposal may lie outside the frame's box)
        lo, hi = np.minimum(bounds[0], x), np.maximum(bounds[1], x)
        name, params = self._flat_algorithm()
        data = self.restricted_energy(x, c) or self.total_energy
        blocks = tuple(tuple(int(np.searchsorted(c, i)) for i in b) for b in m.rotation_blocks if set(b) <= set(c))

        def energy_of(Xc):            # poses equal to x outside c
            X = np.repeat(x[None, :], len(Xc), axis=0)
            X[:, c] = Xc
            return data(X)
        # first generation: the pose so far and draws around it (as the main search of a flat algorithm)
        n = self._flat_generation(c.size)
        P = np.clip(x[c] + rng.standard_normal((n, c.size)) * spread[c], lo[c], hi[c])
        P[0] = x[c]
        opt = make_optimizer(name, x[c], spread[c], rng=rng, bounds=(lo[c], hi[c]), initial_population=P,
                             rotation_blocks=blocks, **params)
        r = minimize(opt, energy_of, max_evals=_whole_generations(int(evals) - used - 1, n))
        y = x.copy()
        y[c] = np.clip(r.x, m.lower[c], m.upper[c])
        ey = float(self.total_energy(y[None, :])[0])
        used += r.n_evals + 1
        if ey < energy:
            return y, ey, used, True
        return x, float(energy), used, False

    def refit_pelvis(self, x, *, evals: int, rng: np.random.Generator, optimizer: str | None = None,
                     params: Mapping | None = None, bounds=None, spread=None) -> tuple[np.ndarray, float, int]:
        """Re-fit the 6 root DOF of pose ``x`` under the current masks with the limbs below the root
        kept in place: ``config.pelvis_move`` ``"reaim"`` (:class:`~.reaim.ReaimMove`: thighs swung
        about the knees, the lower spine about the chest) or ``"world"`` (:class:`~.pelvis.PelvisMove`:
        the root's child joints keep their world rotations); returns ``(pose, its energy, evaluations)``.

        Whole generations of ``evals - 1`` evaluations go to the search (``optimizer``: a flat algorithm
        name, default the configured one's flat form, with ``params``), one to the final pose's energy;
        the count spent is returned. ``bounds`` and
        ``spread`` default to :meth:`search_box` around ``x``; the spreads are scaled by
        ``PELVIS_SPREAD_SCALE[config.pelvis_move]``.
        """
        from isa_mocap_ros.optim import make_optimizer, minimize

        m = self.model
        if self._pelvis is None:
            raise TrackerError(f"refit_pelvis: model {m.name} has no root partition")
        x = np.asarray(x, dtype=float)
        lo, hi = bounds if bounds is not None else self.search_box(x)[:2]
        spread = self.search_box(x)[2] if spread is None else np.asarray(spread, dtype=float)
        if optimizer is None:
            optimizer, params = self._flat_algorithm()
        x1 = np.clip(x, lo, hi)
        kind = self.config.pelvis_move
        move = (self._pelvis_reaim if kind == "reaim" else self._pelvis).around(x1)

        def energy(roots):
            return self.total_energy(np.clip(move(roots), m.lower, m.upper))

        opt = make_optimizer(optimizer, x1[:6], spread[:6] * PELVIS_SPREAD_SCALE[kind], rng=rng,
                             bounds=(lo[:6], hi[:6]), rotation_blocks=((3, 4, 5),), **dict(params or {}))
        evals_search = _whole_generations(int(evals) - 1, opt.generation_size)
        if self._compiled_search and _fast_search.supported_flat(opt):
            r = _fast_search.run_isa(opt, energy, evals_search)     # the same numbers, generations compiled
        else:
            r = minimize(opt, energy, max_evals=evals_search)
        out = np.clip(move(r.x)[0], m.lower, m.upper)
        return out, float(self.total_energy(out[None, :])[0]), r.n_evals + 1

    def refit_torso(self, x, *, evals: int, rng: np.random.Generator, energy: float | None = None, bounds=None,
                    spread=None) -> tuple[np.ndarray, float, int, bool]:
        """The torso stage on pose ``x`` under the current masks: the configured algorithm's flat form
        searches the torso partition's DOFs with the arms re-aimed (:class:`~.reaim.ReaimMove`: each
        upper arm swung about its elbow, the forearm keeping its direction), everything else held; the
        result replaces ``x`` when it lowers the energy.

        ``energy`` is ``x``'s energy if known (else one evaluation computes it); the search gets whole
        generations of the rest of ``evals`` but one, which gives the result's energy, so the stage
        spends at most ``evals`` (less by under a generation). ``bounds``/``spread`` default to
        :meth:`search_box` around ``x`` (the bounds are widened to hold ``x``). Returns ``(pose, its
        energy, evaluations, replaced)``.
        """
        from isa_mocap_ros.optim import make_optimizer, minimize

        m = self.model
        if self._torso is None:
            raise TrackerError(f"refit_torso: model {m.name} has no torso partition")
        x = np.clip(np.asarray(x, dtype=float), m.lower, m.upper)
        if bounds is None or spread is None:
            box = self.search_box(x)
            bounds = box[:2] if bounds is None else bounds
            spread = box[2] if spread is None else spread
        c = self._torso.coords
        spread = np.asarray(spread, dtype=float)[c]
        lo, hi = np.minimum(bounds[0][c], x[c]), np.maximum(bounds[1][c], x[c])
        used = 0
        if energy is None:
            energy, used = float(self.total_energy(x[None, :])[0]), 1
        move = self._torso.around(x)
        # the poses differ from x in the torso and the re-aimed joints only: the restricted energy (same values)
        changed = np.union1d(c, [d for j in self._torso.ops for d in m.joint_dofs[j]])
        data = self.restricted_energy(x, changed) or self.total_energy

        def energy_of(C):
            return data(np.clip(move(C), m.lower, m.upper))

        name, params = self._flat_algorithm()
        opt = make_optimizer(name, x[c], spread, rng=rng, bounds=(lo, hi), **params)
        evals_search = _whole_generations(int(evals) - used - 1, opt.generation_size)
        if self._compiled_search and _fast_search.supported_flat(opt):
            r = _fast_search.run_isa(opt, energy_of, evals_search)
        else:
            r = minimize(opt, energy_of, max_evals=evals_search)
        y = np.clip(move(r.x[None, :])[0], m.lower, m.upper)
        ey = float(self.total_energy(y[None, :])[0])
        used += r.n_evals + 1
        if ey < energy:
            return y, ey, used, True
        return x, float(energy), used, False

    def propose_limbs(self, x, *, n: int, rng: np.random.Generator, limbs: Sequence[str] | None = None,
                      hinge_only: Sequence[str] = (), last=None) -> tuple[np.ndarray, float, int, list[str]]:
        """The limb stage on pose ``x`` under the current masks (:class:`~.limbs.LimbMove`): ``n``
        twist-and-hinge proposals per limb (hinge proposals only for the limbs in ``hinge_only``) and,
        given the previous frame's pose ``last``, the ``config.limb_extrapolations`` proposals,
        evaluated in one batch with ``x`` itself; each limb whose best proposal has a lower energy than
        ``x`` takes that proposal's angles.

        Returns ``(pose, its energy, evaluations, limbs replaced)``; evaluations are always
        ``(n + extrapolations) × limbs + 2``: the batch, then the returned pose once more (its energy is
        not among the batch's when two limbs changed), so the stage spends exactly its share.
        """
        m = self.model
        names = [limb.name for limb in self._limbs.limbs] if limbs is None else list(limbs)
        chosen = [self._limbs.limb(name) for name in names]
        x = np.clip(np.asarray(x, dtype=float), m.lower, m.upper)
        if int(n) < 1 or not chosen:
            return x, float(self.total_energy(x[None, :])[0]), 1, []
        n = int(n)
        factors = self.config.limb_extrapolations if last is not None else ()
        w = self.config.limb_hinge_window_deg
        window = np.deg2rad(w) if 0 < w < 180 else None
        batches = [self._limbs.draw(x, limb, n, rng, twist=limb.name not in hinge_only, window=window)
                   for limb in chosen]
        if factors:
            batches = [np.vstack([P, self._limbs.extrapolate(x, last, limb, factors)])
                       for limb, P in zip(chosen, batches)]
        E = self.total_energy(np.vstack([x[None, :]] + batches))
        out, changed = x.copy(), []
        size = n + len(factors)
        for k, (limb, P) in enumerate(zip(chosen, batches)):
            Ek = E[1 + k * size: 1 + (k + 1) * size]
            i = int(np.argmin(Ek))
            if Ek[i] < E[0]:
                out[limb.dofs] = P[i, limb.dofs]
                changed.append(limb.name)
        return out, float(self.total_energy(out[None, :])[0]), size * len(chosen) + 2, changed

    def _gate(self, usable: list, pred: np.ndarray, notes: list[str]) -> list:
        """The usable masks gated around ``pred`` (:func:`.gate.gate_masks`); views left empty become None."""
        g = gate_masks(usable, self.cameras, self.model, pred, self.config.gate_margin_px)
        return _noted(g, notes, "the gate", lambda total: f"all {total} foreground pixels farther than "
                      f"{self.config.gate_margin_px} px from the predicted silhouette")

    def _hull(self, usable: list, pred: np.ndarray, notes: list[str]) -> list:
        """The usable masks through the visual-hull filter (:func:`.hull.hull_filter`) in the box of
        ``pred``, keeping ``pred``'s silhouette grown by ``hull_keep_px``; views left empty become None."""
        cfg = self.config
        if sum(m is not None for m in usable) < 2:
            return usable
        idx = [v for v, m in enumerate(usable) if m is not None]
        keep: list = [None] * len(usable)
        for v, s in zip(idx, predicted_silhouettes(self.model, [self.cameras[v] for v in idx], pred,
                                                   margin_px=cfg.hull_keep_px)):
            keep[v] = s
        g = hull_filter(usable, self.cameras, pose_box(self.model, pred, cfg.hull_pad_m),
                        dilate_px=cfg.hull_dilate_px, misses=cfg.hull_misses, keep=keep)
        return _noted(g, notes, "the hull filter", lambda total: "no foreground pixel confirmed by the other views")

    def _final_pose(self, res) -> tuple[np.ndarray, float]:
        """The estimate of an optimizer result (``config.estimate``) in the model's limits, rotation
        vectors shortened (|r| <= pi), and its energy."""
        if self.config.estimate == "best" or not np.all(np.isfinite(res.x)):
            x, energy = res.best_x, res.best_energy
        else:
            x, energy = res.x, res.energy
        x = np.clip(np.array(x, dtype=float), self.model.lower, self.model.upper)
        for blk in self.model.rotation_blocks:      # |r| <= pi: turning on and on never meets the limits
            idx = list(blk)
            x[idx] = nearest_rotvec(x[idx], np.zeros(3))
        return x, float(energy)

    def _polish(self, x: np.ndarray, energy: float, frame_index: int, stream: int, notes, budget: FrameBudget):
        """``config.init_polish``'s search of the initialized frame's pose ``x`` (energy ``energy``) as a tracked
        frame, every stage, stream ``[seed, frame, stream]``: ``(result or None if the optimizer refused, the
        lower-energy pose of the two, its energy)``; a refusal is noted in ``notes`` (when given)."""
        try:
            res = self._optimize(x, frame_rng(self.config.seed, frame_index, stream), budget, notes=notes)
        except ValueError as exc:
            if notes is not None:
                notes.append(f"initialization polish failed: {exc}")
            return None, x, energy
        xp, ep = self._final_pose(res)
        return (res, xp, ep) if ep < energy else (res, x, energy)

    def _pick_rival(self, runs: list, winner, x: np.ndarray, energy: float):
        """The heading check's rival among the initialized frame's runs (``config.init_confirm_frames``):
        the lowest-energy run heading more than 90° away from the winner's estimate ``x``, if its
        energy is within ``config.init_confirm_ratio`` of ``energy``; else None."""
        from .init import _wrap, _yaw_of

        if not self._has_heading or not np.isfinite(energy):
            return None
        yaw = _yaw_of(x[3:6])
        best = None
        for _, res, _ in runs:
            if res is winner:
                continue
            xr, er = self._final_pose(res)
            if abs(float(_wrap(_yaw_of(xr[3:6]) - yaw))) > np.pi / 2 and np.isfinite(er) \
                    and (best is None or er < best[1]):
                best = (xr, er)
        if best is None or best[1] > self.config.init_confirm_ratio * max(energy, 0.0):
            return None
        return best[0], best[1], energy

    def _start_rival(self, frame_index: int) -> None:
        """A second tracker (same model, cameras, configuration and energy; a fresh predictor of this
        one's kind) at the rival's pose of the initialized frame."""
        import copy

        xr, _, _ = self._rival_start
        self._rival_start = None
        predictor = copy.deepcopy(self.predictor, memo={id(self.model): self.model})
        predictor.reset()
        rival = Tracker(self.model, self.cameras, dataclasses.replace(self.config, init_confirm_frames=0),
                        prior=self.prior, energy=self.energy, predictor=predictor)
        rival.initialize(pose=xr, frame_index=frame_index)
        rival._elapsed = self._elapsed
        rival._masks_last = self._masks_last
        self._rival = rival
        self._confirm = [0, 0.0, 0.0]

    def step(self, masks: Sequence, frame_index: int, *, prediction=None, frames_elapsed: float = 1,
             contour_stage: bool = True) -> FrameResult:
        """Track one frame (see the module docstring). Never raises on bad masks or predictions.

        Parameters
        ----------
        masks : sequence of (H, W) array_like or None
            One per camera (nonzero = foreground).
        frame_index : int
            Non-negative frame key (index or stamp) of the per-frame random stream.
        prediction : (D,) array_like, optional
            External prediction; default the tracker's predictor.
        frames_elapsed : float
            Frame periods since the previous call's frame (> 0; default 1). See "Gaps" above.
        contour_stage : bool
            False: this frame without the contour stage (its share goes to the main search, as with
            ``contour_iterations=0``): what the estimator node does in real time with a frame set that
            waited too long (its ``catch_up_ms``; the stage is the costliest in time per evaluation).

        Returns
        -------
        FrameResult
        """
        t0 = time.perf_counter()
        rival = self._rival
        # a frame of the heading check (consecutive frames only, see below) shares the budget
        evals = self.confirm_evals() if rival is not None and frames_elapsed == 1 else self.config.evals_per_frame
        self._contour_now = bool(contour_stage)
        res = self._step(masks, frame_index, FrameBudget(evals, self._contour_now), prediction=prediction,
                         frames_elapsed=frames_elapsed)
        if self._own_prediction_frames > 0:
            self._own_prediction_frames -= 1
        if res.initialized:
            self._rival = None
            self._heading_views = res.views_used
            if self._rival_start is not None:
                e_rival, e_win = self._rival_start[1], self._rival_start[2]
                self._start_rival(frame_index)
                return dataclasses.replace(res, notes=res.notes + (
                    f"heading check started: a run heading the other way ended {e_rival:.4g} (winner {e_win:.4g}); both "
                    f"tracked for up to {self.config.init_confirm_frames} frames",))
            return res
        if rival is None:
            return self._recheck_heading(res, frame_index, frames_elapsed, t0)
        if rival is not self._rival:
            return res
        if frames_elapsed != 1:
            # after a gap both hypotheses are still catching up and their energies say little (real
            # time, the sets that arrived during the initialization dropped: wrong switches measured)
            self._rival = None
            return dataclasses.replace(res, notes=res.notes + (
                f"heading check ended: no decision ({frames_elapsed:g} frame periods since the last frame; "
                "it compares consecutive frames only); kept this heading",))
        return self._confirm_heading(res, masks, frame_index, frames_elapsed, t0)

    def travel(self, min_periods: float = 0.0) -> tuple[float, float, float] | None:
        """The travel cue (:data:`TRAVEL_FRAMES`): ``(direction in radians, distance in m, frame periods)`` of the
        root's horizontal travel over the last estimates, or None when they span fewer than ``min_periods``
        periods (or none), the root moved less than :data:`TRAVEL_MIN_M_PER_FRAME` per period, or the model
        has no 3-DOF root rotation."""
        if len(self._roots) < 2 or not self._has_heading:
            return None
        (ta, xa, ya), (tb, xb, yb) = self._roots[0], self._roots[-1]
        span, dist = tb - ta, math.hypot(xb - xa, yb - ya)
        if span <= 0 or span < min_periods or dist < TRAVEL_MIN_M_PER_FRAME * span:
            return None
        return math.atan2(yb - ya, xb - xa), dist, span

    @staticmethod
    def _off_travel(direction: float, x) -> float:
        """Degrees between pose ``x``'s heading and a travel ``direction`` (radians)."""
        from .init import _wrap, _yaw_of

        return math.degrees(abs(float(_wrap(direction - _yaw_of(np.asarray(x, dtype=float)[3:6])))))

    def _travel_recheck_due(self) -> tuple[float, float, float] | None:
        """The travel cue's trigger of a re-check: ``(degrees off the heading, m, periods)`` of :meth:`travel`
        over :data:`TRAVEL_FRAMES` periods when it points backwards (beyond :data:`TRAVEL_BACKWARDS_DEG`) and no
        re-check ran in the last :data:`TRAVEL_RECHECK_FRAMES` frames; else None."""
        if not self.config.heading_travel_cue or self.frames < self._travel_recheck_after or self._last is None:
            return None
        t = self.travel(TRAVEL_FRAMES)
        if t is None:
            return None
        off = self._off_travel(t[0], self._last)
        return (off, t[1], t[2]) if off > TRAVEL_BACKWARDS_DEG else None

    def _recheck_heading(self, res: FrameResult, frame_index: int, frames_elapsed: float, t0: float) -> FrameResult:
        """The heading re-check (``TrackerConfig.init_confirm_frames``): on a tracked frame where more
        views use the person's foreground than when the heading was last checked (or an undecided
        check's re-check is due, or the travel cue finds the track moving backwards,
        ``TrackerConfig.heading_travel_cue``), the frame's search from each standing variant heading the
        other way (at the estimate's root position, the automatic initialization's spreads, pruned as
        :meth:`_initial_runs` does); when the lowest-energy run's estimate heads more than 90° away and
        its energy is within ``init_confirm_ratio`` of this frame's, it becomes the rival of a heading
        check as after the initialization."""
        from .init import _wrap, _yaw_of, standing_poses

        cfg = self.config
        due = self._recheck_at is not None and self.frames >= self._recheck_at
        if cfg.init_confirm_frames <= 0 or res.fell_back or res.initialized or frames_elapsed != 1 \
                or not np.isfinite(res.energy) or not self._has_heading:
            return res
        more_views = res.views_used > self._heading_views
        travel = None if due or more_views else self._travel_recheck_due()
        if not (due or more_views or travel):
            return res
        if due:
            self._recheck_at, self._rechecked_undecided = None, True
        self._travel_recheck_after = self.frames + TRAVEL_RECHECK_FRAMES
        before, self._heading_views = self._heading_views, max(self._heading_views, res.views_used)
        x = np.asarray(res.x, dtype=float)
        yaw = _yaw_of(x[3:6])
        starts, _ = standing_poses(self.model, x[:3], [yaw + np.pi])
        if travel:
            head = (f"heading re-check: the person moves backwards ({travel[1]:.2f} m in {travel[2]:g} frames, "
                    f"{travel[0]:.0f} deg from the heading)")
        elif not more_views:
            head = "heading re-check: the last check was undecided"
        else:
            head = f"heading re-check: {res.views_used} views see the person ({before} when the heading was checked)"
        try:
            runs, n = self._initial_runs(list(starts), frame_index, None, FrameBudget(cfg.evals_per_frame), stream=(5,))
        except ValueError as exc:
            return dataclasses.replace(res, time_s=time.perf_counter() - t0,
                                       notes=res.notes + (f"{head}; its search failed ({exc}); kept this heading",))
        xr, er = min((self._final_pose(r) for _, r, _ in runs), key=lambda t: t[1])
        turned = abs(float(_wrap(_yaw_of(xr[3:6]) - yaw))) > np.pi / 2
        if turned and np.isfinite(er) and er <= cfg.init_confirm_ratio * max(res.energy, 0.0):
            self._rival_start = (xr, er, res.energy)
            self._start_rival(frame_index)
            note = (f"{head}: a run heading the other way ended {er:.4g} (estimate {res.energy:.4g}); both tracked for "
                    f"up to {cfg.init_confirm_frames} frames")
        else:
            note = (f"{head}: a run heading the other way ended {er:.4g}"
                    f"{'' if turned else ' turned back'} (estimate {res.energy:.4g}); kept this heading")
        return dataclasses.replace(res, n_evals=res.n_evals + n, time_s=time.perf_counter() - t0,
                                   notes=res.notes + (note,))

    def confirm_evals(self) -> int:
        """Evaluations of each hypothesis on a frame of the heading check (``config.init_confirm_share``
        of the frame budget, at least ``min(CONFIRM_MIN_EVALS, evals_per_frame)``)."""
        cfg = self.config
        return max(int(cfg.evals_per_frame * cfg.init_confirm_share), min(CONFIRM_MIN_EVALS, cfg.evals_per_frame))

    def _confirm_heading(self, res: FrameResult, masks, frame_index: int, frames_elapsed: float,
                         t0: float) -> FrameResult:
        """One frame of the heading check: step the rival on the same masks, add both energies, decide
        (see ``TrackerConfig.init_confirm_frames``); the frame's result (the rival's when it wins)."""
        cfg = self.config
        rival = self._rival
        other = rival._step(masks, frame_index, FrameBudget(self.confirm_evals(), self._contour_now), prediction=None,
                            frames_elapsed=frames_elapsed)
        n_evals = res.n_evals + other.n_evals
        if res.fell_back and other.fell_back:       # nothing to compare this frame
            return dataclasses.replace(res, n_evals=n_evals, time_s=time.perf_counter() - t0)
        if res.fell_back != other.fell_back or not (np.isfinite(res.energy) and np.isfinite(other.energy)):
            self._rival = None
            return dataclasses.replace(res, n_evals=n_evals, time_s=time.perf_counter() - t0, notes=res.notes + (
                "heading check ended: no decision (only one hypothesis could be tracked); kept this one",))
        c = self._confirm
        c[0] += 1
        c[1] += res.energy
        c[2] += other.energy
        margin = cfg.init_confirm_margin
        sums = f"energy sums over {c[0]} frame(s) {c[1]:.4g} vs {c[2]:.4g} for the other heading"
        # keeping may be decided early, switching only on all the frames: a wrong keep leaves the
        # track as it would be without the check, a wrong switch loses a good one (and one frame's
        # sums misled on 3 of 120 first frames of generated motions, docs/tracking.md)
        last = c[0] >= cfg.init_confirm_frames
        # the travel cue (TRAVEL_FRAMES): when this heading moves backwards and the other forwards, the check
        # runs to its last frame and keeps this heading only if the energies clearly prefer it
        t = self.travel() if cfg.heading_travel_cue else None
        off = self._off_travel(t[0], res.x) if t is not None else None
        contra = off is not None and off > TRAVEL_BACKWARDS_DEG \
            and self._off_travel(t[0], other.x) < 180.0 - TRAVEL_BACKWARDS_DEG
        by_travel = contra and last and not c[2] > margin * c[1]
        if by_travel:
            sums += (f"; this heading moves backwards ({off:.0f} deg from the travel, {t[1]:.2f} m in {t[2]:g} "
                     "frames), the other forwards")
        if not by_travel and ((c[2] > margin * c[1] and not contra) or (last and not c[1] > margin * c[2])):
            self._rival = None
            if not c[2] > margin * c[1] and not self._rechecked_undecided:
                # kept for want of evidence: the rival may still have been converging; once more later
                self._recheck_at = self.frames + UNDECIDED_RECHECK_FRAMES
                sums += f"; undecided, re-checked in {UNDECIDED_RECHECK_FRAMES} frames"
            return dataclasses.replace(res, n_evals=n_evals, time_s=time.perf_counter() - t0,
                                       notes=res.notes + (f"heading check decided: kept the initial heading ({sums})",))
        if not last:
            return dataclasses.replace(res, n_evals=n_evals, time_s=time.perf_counter() - t0)
        # the rival wins: take over its state; external predictions were made from this tracker's
        # estimates, so they are ignored while the predictor's history still holds any of them
        self._rival = None
        # views that joined during the check took part in a switch: no re-check for them (a fresh track
        # checked again at once lost its heading to a fresh rival, generated walk seed 6); a check that
        # kept the heading is re-checked on the next frame that sees them
        self._heading_views = max(self._heading_views, res.views_used, other.views_used)
        self._last, self._elapsed = rival._last, rival._elapsed
        self._masks_last, self._masks_now = rival._masks_last, rival._masks_now
        self._roots, self._clock = rival._roots, rival._clock
        self.predictor = rival.predictor
        cap = getattr(self.predictor, "capacity", None)
        self._own_prediction_frames = (int(cap) if cap is not None else cfg.predictor_order + 1) - 1
        return dataclasses.replace(other, n_evals=n_evals, time_s=time.perf_counter() - t0, notes=other.notes + (
            f"heading check decided: switched to the other heading ({sums}); the frames before were estimated facing "
            "the wrong way",))

    def _step(self, masks: Sequence, frame_index: int, budget: FrameBudget, *, prediction=None,
              frames_elapsed: float = 1) -> FrameResult:
        """:meth:`step` for one hypothesis (without the heading check's rival)."""
        t0 = time.perf_counter()
        if isinstance(frame_index, bool) or not isinstance(frame_index, (int, np.integer)) or frame_index < 0:
            raise TrackerError(f"frame_index: expected an integer >= 0, received {frame_index!r}")
        try:
            self._elapsed += frame_periods("frames_elapsed", frames_elapsed)
        except PredictionError as exc:
            raise TrackerError(str(exc)) from None
        cfg = self.config
        usable, notes = self._check_masks(masks)
        self._masks_now = usable
        gated_pred = None
        if (cfg.gate_margin_px > 0 or cfg.hull_filter) and self._last is not None \
                and any(m is not None for m in usable):
            gated_pred = self._prediction(prediction, notes)
            if cfg.gate_margin_px > 0:
                # the mask gate (config.gate_margin_px): foreground far from the predicted silhouette is dropped
                usable = self._gate(usable, gated_pred, notes)
            if cfg.hull_filter:
                # the visual-hull filter (config.hull_filter): foreground the other views do not confirm
                usable = self._hull(usable, gated_pred, notes)
        weights = None
        if cfg.view_weights and self._last is not None and any(m is not None for m in usable):
            if gated_pred is None:
                gated_pred = self._prediction(prediction, notes)
            # Eq. 5's view weights (config.view_weights): the share of the predicted body each view sees
            weights = visible_shares(self.model, self.cameras, gated_pred)
        views = self._set_masks(usable, notes, frame_index, weights)
        if views == 0:
            notes.append("no usable view: falling back to the last estimate" if self._last is not None
                         else "no usable view and no estimate yet: nothing to track")
            return FrameResult(x=self.last_estimate, energy=float("nan"), n_evals=0, spread=float("nan"),
                               time_s=time.perf_counter() - t0, views_used=0, notes=tuple(notes), fell_back=True)
        n_evals = 0
        initialized = False
        if self._last is None:
            try:
                res0 = initial_pose(self.model, self.cameras, usable, self._init_energy_fn(usable, frame_index),
                                    rng=frame_rng(cfg.seed, frame_index, 1), n_yaw=cfg.init_yaw_steps,
                                    refine_evals=cfg.init_refine_evals)
            except InitError as exc:
                notes.append(f"automatic initialization failed: {exc}")
                return FrameResult(x=None, energy=float("nan"), n_evals=0, spread=float("nan"),
                                   time_s=time.perf_counter() - t0, views_used=views, notes=tuple(notes),
                                   fell_back=True)
            n_evals += res0.n_evals
            initialized = True
            starts = [c[0] for c in res0.candidates] or [res0.x]
        else:
            starts = [gated_pred if gated_pred is not None else self._prediction(prediction, notes)]
        # the first frame optimizes from every initialization candidate (pruned to config.init_keep
        # runs part-way) and keeps the lowest energy
        try:
            if initialized:
                runs, n = self._initial_runs(starts, frame_index, notes, budget)
            else:
                res = self._optimize(starts[0], frame_rng(cfg.seed, frame_index), budget, notes=notes)
                runs, n = [(0, res, starts[0])], res.n_evals
        except ValueError as exc:
            # a configuration the optimizer rejects (budget below one generation, bad parameter):
            # report it on every frame instead of crashing the caller
            notes.append(f"optimizer failed: {exc}; falling back to the last estimate")
            return FrameResult(x=self.last_estimate, energy=float("nan"), n_evals=n_evals, spread=float("nan"),
                               time_s=time.perf_counter() - t0, views_used=views, notes=tuple(notes),
                               fell_back=True, prediction=starts[0], initialized=initialized)
        best = None
        for _, res, pred in runs:
            e = res.best_energy if cfg.estimate == "best" else res.energy
            if best is None or e < best[0]:
                best = (e, res, pred)
        n_evals += n
        _, res, pred = best
        if initialized:
            notes.append(f"initialized automatically ({len(starts)} heading candidates, {len(runs)} searched to the "
                         f"end, grid best yaw {np.rad2deg(res0.yaw):.0f} deg {res0.variant}, {n_evals} evaluations)")
        x, energy = self._final_pose(res)
        if initialized and cfg.init_confirm_frames > 0:
            self._rival_start = self._pick_rival(runs, res, x, energy)
        if initialized and cfg.init_polish:
            # config.init_polish: the winner searched once more as a tracked frame (all stages), from itself
            res2, x2, e2 = self._polish(x, energy, frame_index, 6, notes, budget)
            if res2 is not None:
                n_evals += res2.n_evals
                if e2 < energy:
                    x, energy, res = x2, e2, res2
            if self._rival_start is not None:
                # the heading check's rival polished alike: the heading that fits better after it wins (the
                # check still tracks both)
                res_r, xr, er = self._polish(*self._rival_start[:2], frame_index, 7, None, budget)
                if res_r is not None:
                    n_evals += res_r.n_evals
                if er < energy:
                    notes.append(f"initialization polish: the heading check's rival fits better ({er:.4g} against "
                                 f"{energy:.4g}) and leads")
                    self._rival_start = (x, energy, er)
                    x, energy = xr, er
                    res = res_r if res_r is not None else res
                else:
                    self._rival_start = (xr, er, energy)
        if res.n_nonfinite:
            notes.append(f"energy: {res.n_nonfinite} non-finite evaluations")
        spread_out = res.history[-1].spread if res.history else float("nan")
        self._masks_now = usable         # after the gate: the person's foreground, for a later re-centring
        self._accept(x)
        self.frames += 1
        return FrameResult(x=x, energy=float(energy), n_evals=int(n_evals), spread=float(spread_out),
                           time_s=time.perf_counter() - t0, views_used=views, notes=tuple(notes), fell_back=False,
                           prediction=pred, initialized=initialized)


def _noted(g, notes: list[str], what: str, why_empty: Callable[[int], str]) -> list:
    """The masks of a mask filter's :class:`.gate.GateResult` ``g`` for the energy: a view it emptied
    becomes None (note: ``why_empty(total)``), one it cut by more than :data:`GATE_NOTE_SHARE` gets a note.
    (The views given to the filters are never empty: :meth:`Tracker._check_masks` skips empty ones.)"""
    out = []
    for v, (m, lost, total) in enumerate(zip(g.masks, g.lost_px, g.total_px)):
        if m is not None and lost >= total:
            notes.append(f"view {v}: empty mask after {what} ({why_empty(total)}); skipped")
            m = None
        elif m is not None and lost > GATE_NOTE_SHARE * total:
            notes.append(f"view {v}: {what} removed {lost} of {total} foreground pixels ({100 * lost / total:.0f} %)")
        out.append(m)
    return out


class _TotalEnergy:
    """``tracker.total_energy`` with ``restrict`` (:meth:`Tracker.restricted_energy`), which
    ``Hierarchical`` asks for when a partition starts."""

    def __init__(self, tracker: Tracker) -> None:
        self.tracker = tracker

    def __call__(self, X) -> np.ndarray:
        return self.tracker.total_energy(X)

    def restrict(self, x_base, coords):
        return self.tracker.restricted_energy(x_base, coords)


def make_tracker(model, cameras: Sequence, *, optimizer: str = "h-isa", evals: int = 1500,
                 params: Mapping | None = None, seed: int = 0, energy: str = "fast", downsample: int = 1,
                 search_radius_rad: float = 0.5, predictor: str = "ar", predictor_order: int = 1,
                 prior_eta: float = 0.0, prior_file: str | None = None, energy_fn: Callable | None = None,
                 **config) -> Tracker:
    """A :class:`Tracker` from flat settings (the estimator node's parameters).

    ``optimizer, evals, params, seed, energy, downsample, search_radius_rad, predictor,
    predictor_order, prior_eta, prior_file`` map onto :class:`TrackerConfig` fields (``prior_file``
    ``""`` = none); further ``config`` keywords are passed to it as they are. ``energy_fn``: a data
    term object (see :class:`Tracker`).
    """
    cfg = TrackerConfig(optimizer=optimizer, evals_per_frame=evals, optimizer_params=dict(params or {}), seed=seed,
                        energy_method=energy, downsample=downsample, search_radius_rad=search_radius_rad,
                        predictor=predictor, predictor_order=predictor_order, prior_eta=prior_eta,
                        prior_file=prior_file or None, **config)
    return Tracker(model, cameras, cfg, energy=energy_fn)
