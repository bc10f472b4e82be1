"""The tracker's settings (:class:`TrackerConfig`), its errors and the module constants its stages share; its
result record (:class:`FrameResult`, tracking/result.py) is re-exported here. Pure: no ROS import.
"""
from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from isa_mocap_ros.config_checks import check_bool, check_choice, check_number

from .limbs import LIMBS
from .result import FrameResult

__all__ = ["TrackerError", "TrackerConfig", "SearchConfig", "PredictionConfig", "ObjectiveConfig", "KeypointConfig",
           "FirstFrameConfig", "HeadingConfig", "StageConfig", "MaskConfig", "LEAVES", "FrameResult", "DEFAULT_PARAMS",
           "PREDICTORS", "frame_rng", "field_docs", "whole_generations", "partition_coords"]

PREDICTORS = ("ar", "constant_pose", "constant_velocity")
#: Initial standard deviation of the joint angles around the prediction, rad.
JOINT_SPREAD_RAD = 0.05
#: Initial standard deviation of the root position around the prediction, m.
ROOT_TRANSLATION_SPREAD_M = 0.015
#: Half-width of the search box of each root rotation-vector component, rad.
ROOT_ROTATION_RADIUS_RAD = 0.5
#: Initial standard deviation of each root rotation-vector component, rad.
ROOT_ROTATION_SPREAD_RAD = 0.025
#: Damping ``g`` of the own prediction ``x_k + g (p − x_k)`` of the root's 6 DOF.
ROOT_VELOCITY_GAIN = 0.7
#: Factor on the initial spreads on the automatically initialized frame (it starts from a standing pose).
INIT_SPREAD_SCALE = 2.0

#: Share of a view's foreground the mask gate may remove before ``FrameResult.notes`` says so.
GATE_NOTE_SHARE = 0.25
#: Frames after a heading check that kept the winner for want of evidence (the sums within
#: ``init_confirm_margin``) until the heading is re-checked once (``TrackerConfig.heading.init_confirm_frames``).
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

#: Optimizer parameters used unless ``optimizer_params`` sets them (tuned on the silhouette energy,
#: ``docs/decisions/001-hierarchy-order.md``); the library defaults apply to anything not listed.
DEFAULT_PARAMS: Mapping[str, Mapping[str, Any]] = MappingProxyType({
    "isa": MappingProxyType({"n_particles": 100, "kernel": "s2", "schedule": "adaptive", "target_ess": 0.3,
                             "c": 0.5, "variance": "selected"}),
    "h-isa": MappingProxyType({"n_particles": 30, "kernel": "s2", "schedule": "adaptive", "target_ess": 0.3,
                               "c": 0.5, "variance": "selected"}),
})


class TrackerError(ValueError):
    """Bad tracker configuration or argument (names the argument, the expected and the received value)."""


def whole_generations(evals: int, generation: int) -> int:
    """``evals`` rounded down to whole generations (unchanged below one generation: the optimizer's error
    names it). The tracker's searches never end on a truncated generation, whose few rows would make a
    weighted-mean estimate (ISA, APF) that of a few random particles
    (``docs/decisions/002-whole-generations.md``)."""
    return evals // generation * generation if evals >= generation else evals


def frame_rng(seed: int, frame_index: int, *extra: int) -> np.random.Generator:
    """The generator of one frame: ``default_rng([seed, frame_index, *extra])``."""
    return np.random.default_rng([int(seed), int(frame_index), *map(int, extra)])


def _number(name: str, value, *, lo: float | None = None, strict: bool = False, integer: bool = False,
            hi: float | None = None, hi_open: bool = False) -> None:
    check_number(name, value, lo=lo, lo_open=strict, hi=hi, hi_open=hi_open, integer=integer, error=TrackerError)


def _bool(name: str, value) -> None:
    check_bool(name, value, error=TrackerError)


def _partition_names(name: str, value, example: str, *, empty: bool) -> tuple:
    """``value`` as a tuple of distinct partition names (a sequence of strings, not a string; ``empty``:
    whether none is allowed), else :class:`TrackerError` naming the setting."""
    if isinstance(value, str) or not isinstance(value, Sequence) or not all(isinstance(v, str) for v in value) \
            or len(set(value)) != len(value) or not (empty or value):
        raise TrackerError(f"{name}: expected distinct partition names (e.g. {example}), received {value!r}")
    return tuple(value)


def partition_coords(model, names) -> np.ndarray:
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
class SearchConfig:
    """The optimizer and its search box around the prediction.

    Attributes
    ----------
    optimizer : str
        Registry name (``h-isa`` default: ISA over the §3.3 hierarchy; flat ISA drifts off at 1500 evaluations).
    evals : int
        Energy evaluations per frame, every stage included (EA-vs-PF: 500 / 1500 / 3000; default 1500).
    optimizer_params : mapping
        Keyword arguments of the optimizer over :data:`DEFAULT_PARAMS` (default none).
    partition_order : tuple of str
        Order of a hierarchical optimizer's partitions (arms before the torso; every partition of the model named).
    search_radius_rad : float
        Half-width of every joint angle's search box around the prediction, rad (EA-vs-PF: 0.5).
    root_translation_radius_m : float
        Half-width of the root position's search box, m (0.25).
    spread_velocity_gain : float
        Joint ``j`` starts with spread ``sqrt(JOINT_SPREAD_RAD² + (k |p_j − x_j|)²)``: wider where the prediction moves (1.5; 0 = off).
    seed : int
        Seed of every per-frame stream ``default_rng([seed, frame, ...])`` (0).
    coarse_fraction : float
        Share of each partition's generations of the compiled h-isa main search evaluated on the energy's coarse
        level (energy "fast": two views, about half the cost; "raster": every second pixel row; docs/energy.md);
        0 = off (default).
    """

    optimizer: str = "h-isa"
    evals: int = 1500
    optimizer_params: Mapping[str, Any] = field(default_factory=dict)
    partition_order: tuple = ("root", "left_arm", "right_arm", "torso", "left_leg", "right_leg")
    search_radius_rad: float = 0.5
    root_translation_radius_m: float = 0.25
    spread_velocity_gain: float = 1.5
    seed: int = 0
    coarse_fraction: float = 0.0

    def __post_init__(self) -> None:
        from isa_mocap_ros.optim import OPTIMIZERS

        check_choice("optimizer", self.optimizer, OPTIMIZERS, error=TrackerError)
        _number("evals", self.evals, lo=1, integer=True)
        if not isinstance(self.optimizer_params, Mapping):
            raise TrackerError(f"optimizer_params: expected a mapping, received {type(self.optimizer_params).__name__}")
        bad = [k for k in self.optimizer_params if k in ("bounds", "rng", "rotation_blocks", "partitions", "x0",
                                                         "spread")]
        if bad:
            raise TrackerError(f"optimizer_params: expected algorithm parameters only, received {bad} "
                               "(set by the tracker)")
        object.__setattr__(self, "optimizer_params", MappingProxyType(dict(self.optimizer_params)))
        object.__setattr__(self, "partition_order", _partition_names(
            "partition_order", self.partition_order, "root, left_arm, right_arm, torso, left_leg, right_leg",
            empty=False))
        for name in ("search_radius_rad", "root_translation_radius_m"):
            _number(name, getattr(self, name), lo=0.0, strict=True)
        _number("spread_velocity_gain", self.spread_velocity_gain, lo=0.0)
        _number("seed", self.seed, lo=0, integer=True)
        _number("coarse_fraction", self.coarse_fraction, lo=0.0, hi=0.99)

    def params(self) -> dict:
        """Optimizer keyword arguments: :data:`DEFAULT_PARAMS` of the optimizer, then ``optimizer_params``."""
        out = dict(DEFAULT_PARAMS.get(self.optimizer, {}))
        out.update(self.optimizer_params)
        return out


@dataclass(frozen=True)
class PredictionConfig:
    """The tracker's own prediction of the next pose (when no external one is given).

    Attributes
    ----------
    predictor : {"ar", "constant_pose", "constant_velocity"}
        The tracker's own predictor (``ar``: ISA 13.28).
    predictor_order : int
        AR order (1).
    joint_velocity_gain : float
        Damping ``g`` of the own prediction ``x_k + g (p − x_k)`` of the joints (0.5; 1 = undamped, 0 = constant pose; the root's: :data:`ROOT_VELOCITY_GAIN`).
    max_frames_ahead : float
        The own prediction looks at most this many periods ahead; beyond, the root follows the foreground (5).
    """

    predictor: str = "ar"
    predictor_order: int = 1
    joint_velocity_gain: float = 0.5
    max_frames_ahead: float = 5.0

    def __post_init__(self) -> None:
        check_choice("predictor", self.predictor, PREDICTORS, error=TrackerError)
        _number("predictor_order", self.predictor_order, lo=1, integer=True)
        _number("joint_velocity_gain", self.joint_velocity_gain, lo=0.0)
        _number("max_frames_ahead", self.max_frames_ahead, lo=1.0)


@dataclass(frozen=True)
class ObjectiveConfig:
    """The energy the searches minimise: silhouette term (EA-vs-PF Eq. 4-5) and Parzen prior (13.33).

    Attributes
    ----------
    energy : {"raster", "fast", "exact"}
        Silhouette energy: the scanline count on the pixel grid (default; decision 017), the compiled sampled kernel, or
        the exact rendering reference.
    downsample : int
        Mask downsampling of the fast energy, row stride of the scanline count (1 = none).
    n_model_points : int
        Fast energy's sample size: model-template points per view (640).
    n_mask_points : int
        Fast energy's sample size: foreground pixels per view (384).
    silhouette_core_px : float
        Term 2 of Eq. 4 counts a foreground pixel by min(1, d / this), d its distance to the background, px: clothes and soft tissue at the silhouette's rim ask less to be covered (0 = Eq. 4 as printed).
    view_weights : bool
        Eq. 5's mean over views weighted by the share of the predicted body each view sees (True).
    prior_eta : float
        Weight η of the Parzen prior ``−η ln p(x)`` (13.33); 0 = off (default).
    prior_file : str
        ``.npz`` of :meth:`ParzenPrior.save`, used when no ``prior=`` object is given ("" = none).
    temporal_weight : float
        Weight of the temporal term on tracked frames: the temporal_joints held near their predicted positions (0 = off).
        :mod:`~isa_mocap_ros.energy.temporal`, the keypoint term's loss scale; off by default, measured in
        docs/history/issue34_real_recording.md.
    temporal_joints : str
        Comma-separated model joints of the temporal term.
    """

    energy: str = "raster"
    downsample: int = 1
    n_model_points: int = 640
    n_mask_points: int = 384
    silhouette_core_px: float = 0.0
    view_weights: bool = True
    prior_eta: float = 0.0
    prior_file: str = ""
    temporal_weight: float = 0.0
    temporal_joints: str = "left_ankle,right_ankle"

    def __post_init__(self) -> None:
        check_choice("energy", self.energy, ("fast", "exact", "raster"), error=TrackerError)
        _number("downsample", self.downsample, lo=1, integer=True)
        _number("n_model_points", self.n_model_points, lo=1, integer=True)
        _number("n_mask_points", self.n_mask_points, lo=0, integer=True)
        _number("silhouette_core_px", self.silhouette_core_px, lo=0.0)
        _bool("view_weights", self.view_weights)
        _number("prior_eta", self.prior_eta, lo=0.0)
        if not isinstance(self.prior_file, (str, Path)):
            raise TrackerError(f"prior_file: expected a path ('' = none), received {self.prior_file!r}")
        _number("temporal_weight", self.temporal_weight, lo=0.0)
        if not isinstance(self.temporal_joints, str) or not [j for j in self.temporal_joints.split(",") if j.strip()]:
            raise TrackerError(f"temporal_joints: expected comma-separated joint names, received "
                               f"{self.temporal_joints!r}")


@dataclass(frozen=True)
class KeypointConfig:
    """The 2-D keypoint term added on frames given keypoints (docs/keypoints.md).

    Attributes
    ----------
    keypoint_weight : float
        Weight of the keypoint term (:class:`~isa_mocap_ros.energy.KeypointEnergy`, 13.30-13.31) on frames given keypoints (0 = off; docs/keypoints.md).
    keypoint_sigma_m : float
        Scale of the keypoint term's Geman-McClure loss, m (> 0; 0.1).
    """

    keypoint_weight: float = 0.0
    keypoint_sigma_m: float = 0.1

    def __post_init__(self) -> None:
        _number("keypoint_weight", self.keypoint_weight, lo=0.0)
        _number("keypoint_sigma_m", self.keypoint_sigma_m, lo=0.0, strict=True)


@dataclass(frozen=True)
class FirstFrameConfig:
    """The automatic initialization of the first frame (tracking/first_frame.py, docs/decisions/).

    Attributes
    ----------
    init_yaw_steps : int
        Headings of the automatic initialization's grid (24).
    init_refine_evals : int
        Evaluations of each of the initialization's four root refinements (400; 0 = none).
    init_keep : int
        Heading-candidate runs kept after the first partition on the first frame, the heading check's rival second
        (2; 0 = all run to the end).
    init_polish : bool
        The first frame's winner is searched once more from itself with every stage (True).
    """

    init_yaw_steps: int = 24
    init_refine_evals: int = 400
    init_keep: int = 2
    init_polish: bool = True

    def __post_init__(self) -> None:
        _number("init_yaw_steps", self.init_yaw_steps, lo=4, integer=True)
        _number("init_refine_evals", self.init_refine_evals, lo=0, integer=True)
        _number("init_keep", self.init_keep, lo=0, integer=True)
        _bool("init_polish", self.init_polish)


@dataclass(frozen=True)
class HeadingConfig:
    """The heading check: a rival heading tracked beside the track for a few frames (tracking/heading.py).

    Attributes
    ----------
    init_confirm_frames : int
        Frames a rival heading is tracked beside the track in a heading check, re-checks included (3; 0 = no check).
    init_confirm_ratio : float
        A rival is checked when its energy is within this factor of the track's (>= 1; 1.25).
    init_confirm_margin : float
        Factor (>= 1) by which one hypothesis' energy sum must be lower to decide the check (1.1).
    heading_travel_cue : bool
        A track moving backwards (:data:`TRAVEL_FRAMES`) starts a re-check and decides a close one (True).
    """

    init_confirm_frames: int = 3
    init_confirm_ratio: float = 1.25
    init_confirm_margin: float = 1.1
    heading_travel_cue: bool = True

    def __post_init__(self) -> None:
        _number("init_confirm_frames", self.init_confirm_frames, lo=0, integer=True)
        _number("init_confirm_ratio", self.init_confirm_ratio, lo=1.0)
        _number("init_confirm_margin", self.init_confirm_margin, lo=1.0)
        _bool("heading_travel_cue", self.heading_travel_cue)


@dataclass(frozen=True)
class StageConfig:
    """The stages after the main search: pelvis, torso, limb proposals, contour fit (tracking/stages.py).

    Attributes
    ----------
    pelvis_fraction : float
        Budget share of the pelvis stage: root re-fitted with the thighs re-aimed about the knees (0.15; 0 = off).
    torso_fraction : float
        Budget share of the torso stage (hierarchical optimizers): spine and neck with the upper arms re-aimed (0.13; 0 = off).
    leg_untwist : bool
        The untwist stage after the limb stage: each thigh's twist about its axis halved or undone, the ankle turned back (True; False = off; tracking/chain_moves.py, decision 019).
    leg_untwist_tolerance : float
        The untwist stage takes a proposal whose energy is below the pose's times 1 + this (0.01; 0.0: strictly lower).
    leg_untwist_margin : float
        ... or below the pose's energy plus this, in energy units: a fixed price, like the prior's, that the clutter of
        occluders and noise does not inflate (0.0: none; the two add).
    limb_proposals : int
        Twist-and-hinge proposals per limb of the limb stage, within a tenth of the budget (16; 0 = off).
    limb_proposal_limbs : tuple of str
        Limbs of the limb stage (all four).
    limb_hinge_limbs : tuple of str
        Limbs whose proposals redraw the hinge only, unless folded (the legs).
    limb_extrapolations : tuple of float
        Factors ``k`` of the extrapolated proposals ``x + k (x − x_prev)`` per limb ((1, 2, 3); () or [0.0] = none).
    limb_fold_deg : float
        A limb bent beyond this (deg) in the prediction gets twist-and-hinge proposals (130; 0 or >= 180 = never).
    limb_hinge_window_deg : float
        Hinge-only proposals are drawn within this many degrees of the pose's hinge (90; 0 or >= 180 = whole range).
    contour_iterations : int
        Levenberg-Marquardt steps of the contour stage (ISA 13.30-13.31), each charged D + 1 evaluations (3; 0 = off).
    contour_extra_iterations : int
        Further contour steps on ``contour_extra_partitions`` alone, each charged k + 1 (3; 0 = none).
    contour_extra_partitions : tuple of str
        Partitions of those steps (the legs).
    contour_points : int
        Model contour points per view and contour iteration (200).
    contour_max_px : float
        Contour pairs farther apart than this are dropped, px (2.0).
    """

    pelvis_fraction: float = 0.15
    torso_fraction: float = 0.13
    leg_untwist: bool = True
    leg_untwist_tolerance: float = 0.01
    leg_untwist_margin: float = 0.0
    limb_proposals: int = 16
    limb_proposal_limbs: tuple = ("left_arm", "right_arm", "left_leg", "right_leg")
    limb_hinge_limbs: tuple = ("left_leg", "right_leg")
    limb_extrapolations: tuple = (1.0, 2.0, 3.0)
    limb_fold_deg: float = 130.0
    limb_hinge_window_deg: float = 90.0
    contour_iterations: int = 3
    contour_extra_iterations: int = 3
    contour_extra_partitions: tuple = ("left_leg", "right_leg")
    contour_points: int = 200
    contour_max_px: float = 2.0

    def __post_init__(self) -> None:
        for name in ("pelvis_fraction", "torso_fraction"):
            _number(name, getattr(self, name), lo=0.0)
            if getattr(self, name) >= 1.0:
                raise TrackerError(f"{name}: expected a share in [0, 1), received {getattr(self, name)!r}")
        if self.pelvis_fraction + self.torso_fraction >= 1.0:
            raise TrackerError(f"pelvis_fraction + torso_fraction: expected below 1 (the main search needs a share), "
                               f"received {self.pelvis_fraction!r} + {self.torso_fraction!r}")
        _bool("leg_untwist", self.leg_untwist)
        _number("leg_untwist_tolerance", self.leg_untwist_tolerance, lo=0.0)
        _number("leg_untwist_margin", self.leg_untwist_margin, lo=0.0)
        _number("limb_proposals", self.limb_proposals, lo=0, integer=True)
        for name in ("limb_proposal_limbs", "limb_hinge_limbs"):
            object.__setattr__(self, name, _limb_names(name, getattr(self, name)))
        ext = self.limb_extrapolations
        if isinstance(ext, (str, bytes)) or not isinstance(ext, Sequence) or not all(
                isinstance(k, (int, float, np.integer, np.floating)) and not isinstance(k, bool)
                and np.isfinite(k) and k >= 0 for k in ext):
            raise TrackerError(f"limb_extrapolations: expected a sequence of positive factors ([0.0] = none), "
                               f"received {ext!r}")
        object.__setattr__(self, "limb_extrapolations", tuple(float(k) for k in ext if k > 0))
        _number("limb_fold_deg", self.limb_fold_deg, lo=0.0)
        _number("limb_hinge_window_deg", self.limb_hinge_window_deg, lo=0.0)
        _number("contour_iterations", self.contour_iterations, lo=0, integer=True)
        _number("contour_extra_iterations", self.contour_extra_iterations, lo=0, integer=True)
        object.__setattr__(self, "contour_extra_partitions", _partition_names(
            "contour_extra_partitions", self.contour_extra_partitions, "left_leg, right_leg", empty=True))
        _number("contour_points", self.contour_points, lo=1, integer=True)
        _number("contour_max_px", self.contour_max_px, lo=0.0, strict=True)


@dataclass(frozen=True)
class MaskConfig:
    """What the tracker filters out of the masks before the energy sees them (tracking/frame_masks.py).

    Attributes
    ----------
    gate_margin_px : int
        Mask gate: foreground components farther than this from the predicted silhouette are dropped, px (10; 0 = off).
    hull_filter : bool
        Visual-hull filter: foreground the other views do not confirm, beyond the predicted silhouette, is dropped (True).
    hull_dilate_px : int
        Dilation of the confirming views' foreground, px (2).
    hull_keep_px : int
        Foreground within this many px of the predicted silhouette is kept unconfirmed (3).
    hull_pad_m : float
        Growth of the predicted joints' box in which the hull filter looks, m (0.35).
    first_frame_hull : bool
        Before the first estimate, keep only the foreground of the visual hull's largest blob (tracking/init_hull.py;
        with ``hull_filter``): occluders no other view confirms do not reach the initialization (True).
    """

    gate_margin_px: int = 10
    hull_filter: bool = True
    hull_dilate_px: int = 2
    hull_keep_px: int = 3
    hull_pad_m: float = 0.35
    first_frame_hull: bool = True

    def __post_init__(self) -> None:
        _number("gate_margin_px", self.gate_margin_px, lo=0, integer=True)
        _bool("hull_filter", self.hull_filter)
        _number("hull_dilate_px", self.hull_dilate_px, lo=0, integer=True)
        _number("hull_keep_px", self.hull_keep_px, lo=0, integer=True)
        _number("hull_pad_m", self.hull_pad_m, lo=0.0, strict=True)
        _bool("first_frame_hull", self.first_frame_hull)


@dataclass(frozen=True)
class TrackerConfig:
    """Fixed settings of a :class:`Tracker`, in groups: one frozen dataclass per concern, one line per
    setting (unit, default, why). The measurements behind the defaults: ``docs/decisions/`` and
    ``docs/history/tracker_config.md``.

    The settings' names (the *leaves*) are unique across the groups: they are the estimator node's ROS
    parameter names and ``config/pipeline.yaml``'s keys. :meth:`from_flat` builds a config from leaf names
    (``TrackerConfig.from_flat(evals=600, seed=1)``), :meth:`replace` changes some, :meth:`flat` lists all.

    Attributes
    ----------
    search : SearchConfig
        The optimizer, its budget and search box.
    prediction : PredictionConfig
        The tracker's own prediction.
    objective : ObjectiveConfig
        The silhouette energy and the prior.
    keypoints : KeypointConfig
        The 2-D keypoint term.
    first_frame : FirstFrameConfig
        The automatic initialization.
    heading : HeadingConfig
        The heading check.
    stages : StageConfig
        The pelvis, torso, limb and contour stages.
    masks : MaskConfig
        The mask gate and the visual-hull filter.
    """

    search: SearchConfig = field(default_factory=SearchConfig)
    prediction: PredictionConfig = field(default_factory=PredictionConfig)
    objective: ObjectiveConfig = field(default_factory=ObjectiveConfig)
    keypoints: KeypointConfig = field(default_factory=KeypointConfig)
    first_frame: FirstFrameConfig = field(default_factory=FirstFrameConfig)
    heading: HeadingConfig = field(default_factory=HeadingConfig)
    stages: StageConfig = field(default_factory=StageConfig)
    masks: MaskConfig = field(default_factory=MaskConfig)

    def __post_init__(self) -> None:
        for f in fields(self):
            if not isinstance(getattr(self, f.name), _GROUPS[f.name]):
                raise TrackerError(f"{f.name}: expected a {_GROUPS[f.name].__name__}, "
                                   f"received {type(getattr(self, f.name)).__name__}")

    @classmethod
    def from_flat(cls, **settings) -> "TrackerConfig":
        """The config with the leaf settings ``settings`` (e.g. ``evals=600``), the others at their defaults;
        :class:`TrackerError` naming an unknown setting."""
        return cls().replace(**settings)

    def replace(self, **settings) -> "TrackerConfig":
        """A copy with the leaf settings ``settings`` changed (each group checks its own)."""
        groups: dict[str, dict[str, Any]] = {}
        for name, value in settings.items():
            if name not in LEAVES:
                raise TrackerError(f"{name}: not a tracker setting (expected one of {', '.join(LEAVES)})")
            groups.setdefault(LEAVES[name], {})[name] = value
        return dataclasses.replace(self, **{g: dataclasses.replace(getattr(self, g), **kw)
                                            for g, kw in groups.items()})

    def flat(self) -> dict[str, Any]:
        """Every leaf setting by name, in group order (the estimator's parameters)."""
        return {name: getattr(getattr(self, group), name) for name, group in LEAVES.items()}


#: The groups of :class:`TrackerConfig`: field name → its dataclass.
_GROUPS: Mapping[str, type] = MappingProxyType({
    "search": SearchConfig, "prediction": PredictionConfig, "objective": ObjectiveConfig,
    "keypoints": KeypointConfig, "first_frame": FirstFrameConfig, "heading": HeadingConfig,
    "stages": StageConfig, "masks": MaskConfig})


def _leaves(groups: Mapping[str, type]) -> Mapping[str, str]:
    out: dict[str, str] = {}
    for group, cls in groups.items():
        for f in fields(cls):
            if f.name in out:
                raise TrackerError(f"TrackerConfig: setting {f.name!r} in both {out[f.name]} and {group} "
                                   "(leaf names are parameter names and must be unique)")
            out[f.name] = group
    return MappingProxyType(out)


#: Every leaf setting of :class:`TrackerConfig` → the group holding it, in group order.
LEAVES: Mapping[str, str] = _leaves(_GROUPS)


def field_docs(cls=None) -> dict[str, str]:
    """The one-line description of every setting of the config dataclass ``cls`` (default
    :class:`TrackerConfig`: the leaves of all its groups), read from its docstring's Attributes section
    (``name : type`` then one indented line); :class:`TrackerError` naming the field when one has none."""
    if cls is None or cls is TrackerConfig:
        out: dict[str, str] = {}
        for group in _GROUPS.values():
            out.update(field_docs(group))
        return out
    lines = inspect.cleandoc(cls.__doc__ or "").splitlines()
    docs: dict[str, str] = {}
    for head, text in zip(lines, lines[1:]):
        if " : " in head and not head[0].isspace() and text.startswith(" "):
            docs[head.split(" : ")[0]] = text.strip()
    names = [f.name for f in fields(cls)]
    missing = [n for n in names if n not in docs]
    if missing:
        raise TrackerError(f"{cls.__name__}: no one-line description in its docstring for {missing}")
    return {n: docs[n] for n in names}
