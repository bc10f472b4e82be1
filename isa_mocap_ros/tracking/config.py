"""The tracker's settings (:class:`TrackerConfig`), its result record (:class:`FrameResult`), its errors
and the module constants its stages share. Pure: no ROS import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from .limbs import LIMBS

__all__ = ["TrackerError", "TrackerConfig", "FrameResult", "DEFAULT_PARAMS", "PREDICTORS", "frame_rng"]

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
