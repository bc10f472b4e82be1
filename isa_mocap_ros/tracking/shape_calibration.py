"""Body shape calibrated from the silhouettes of the first frames (no ground-truth shape needed).

The papers track with a subject-specific model measured beforehand (EA-vs-PF §3.1, ISA §13.4.2); a
user of this package has only the images. :func:`calibrate_shape` estimates the segment lengths and
capsule radii (left/right symmetric) from the foreground masks of a few frames by alternating, with
the project's own silhouette energy (EA-vs-PF Eq. 4-5), tracker and CMA-ES (§4.2.1):

1. **poses with the shape fixed**: round 0 tracks the first ``window_frames`` frames with the
   :class:`~.tracker.Tracker` from its automatic initialization, starting from ``base_shape`` (the
   default ~1.75 m body); later rounds re-fit each calibration frame with one tracker step from the
   previous round's pose (the prediction) under the new shape;
2. **the shape with the joint angles fixed**: CMA-ES over :data:`SHAPE_PARAMS` (log factors on the
   base shape) and a change of each frame's root height (a taller body stands higher), minimising the
   mean silhouette energy over the ``n_frames`` calibration frames (plus a weak pull of the log
   factors towards 0, which only decides directions the images leave flat).

The calibration frames' masks are first cut to the largest blob of each frame's visual hull (what the
tracker does to its first frame, :mod:`.init_hull`): an occluder drawn into one image or pixel noise
that no other view confirms does not enter the shape fit (``masks="raw"`` keeps them as given).

The shape is a few numbers, not free lengths: an overall scale, length factors of thigh, shin,
upper arm, forearm, trunk and neck/head, hip and shoulder widths, and radius factors of trunk, arms
and legs; both sides share them.

:func:`bone_lengths` and :func:`marker_bone_lengths` measure the same bones (distances between named
joint centres: thigh = hip-knee, shin = knee-ankle, upper arm = shoulder-elbow, forearm =
elbow-wrist, hip and shoulder widths, pelvis-neck, neck-head) on a model (rest pose) and on
ground-truth markers (median over frames), so a calibrated model is compared like with like with a
mesh skeleton's joint centres. See ``docs/shape_calibration.md``.
"""
from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from .shape_judge import tracked_energy

__all__ = ["SHAPE_PARAMS", "BONES", "LIMB_BONES", "ShapeCalibrationConfig", "ShapeCalibrationResult", "ShapeCalibrationError",
           "shape_from_params", "bone_lengths", "marker_bone_lengths", "bone_errors", "prior", "calibrate_shape"]

#: shape parameters: (name, lower, upper) bounds of the factor on the base shape
SHAPE_PARAMS: tuple[tuple[str, float, float], ...] = (
    ("scale", 0.8, 1.2),             # every offset and radius (stature)
    ("thigh", 0.7, 1.35),            # hip -> knee, on top of the scale
    ("shin", 0.7, 1.35),             # knee -> ankle
    ("upper_arm", 0.7, 1.35),        # shoulder -> elbow
    ("forearm", 0.7, 1.35),          # elbow -> wrist -> hand (a straight arm shows only their sum)
    ("trunk", 0.6, 1.35),            # pelvis -> lower spine -> upper spine -> neck, shoulder height
    ("neck_head", 0.6, 1.4),         # neck -> head centre -> head top
    ("hip_width", 0.7, 1.4),         # pelvis -> hip lateral offset
    ("shoulder_width", 0.7, 1.35),   # chest -> shoulder lateral offset
    ("r_trunk", 0.6, 1.7),           # radii of pelvis, abdomen, torso, chest
    ("r_arms", 0.6, 1.7),            # radii of upper arms, forearms, hands
    ("r_legs", 0.6, 1.7),            # radii of thighs, shins, feet
)
_LENGTH_OF = {"knee": "thigh", "ankle": "shin", "elbow": "upper_arm", "wrist": "forearm", "hand": "forearm",
              "spine_lower": "trunk", "spine_upper": "trunk", "neck": "trunk", "head": "neck_head",
              "head_top": "neck_head"}
_R_TRUNK = ("pelvis", "abdomen", "torso", "chest")
_R_ARMS = ("upper_arm", "forearm", "hand")
_R_LEGS = ("thigh", "shin", "foot")

#: bones compared with the truth: (name, joint a, joint b); left/right pairs both listed
BONES: tuple[tuple[str, str, str], ...] = tuple(
    [(f"{s}_{b}", f"{s}_{a}", f"{s}_{c}") for s in ("left", "right")
     for b, a, c in (("thigh", "hip", "knee"), ("shin", "knee", "ankle"),
                     ("upper_arm", "shoulder", "elbow"), ("forearm", "elbow", "wrist"))]
    + [("hip_width", "left_hip", "right_hip"), ("shoulder_width", "left_shoulder", "right_shoulder"),
       ("pelvis_neck", "pelvis", "neck"), ("neck_head", "neck", "head")])


class ShapeCalibrationError(ValueError):
    """The calibration cannot run (no usable frames, no automatic initialization, bad settings)."""


@dataclass(frozen=True)
class ShapeCalibrationConfig:
    """Settings of :func:`calibrate_shape` (one line per setting: unit and why)."""

    window_frames: int = 30         # first frames tracked in round 0 (1 s at 30 fps: varied leg poses)
    n_frames: int = 6               # calibration frames, spread evenly over the window
    rounds: int = 4                 # pose/shape alternations (the poses improve with the shape)
    pose_steps: int = 3             # tracker steps per calibration frame in each later round's pose fit
    shape_evals: int = 1500         # CMA-ES evaluations (shapes x all calibration frames) per round
    n_model_points: int = 600       # silhouette sample sizes of the shape fit (finer than tracking's:
    n_mask_points: int = 600        # the fit compares shapes that differ by a few pixels)
    translation_m: float = 0.15     # bound of each frame's root height change in the shape fit
    angle_rad: float = 0.3          # bound of each frame's change of the coupled joint angles in the shape fit
    coupled_dofs: tuple = ()        # joint angles also free in the shape fit (e.g. the abductions left/right_hip_x,
                                    # left/right_shoulder_x: truer bones on capsule renders, but on 6-frame mesh
                                    # calibrations 24 more dimensions leave the silhouette fit unconverged; off)
    retrack: bool = True            # later rounds re-track the whole window with the new shape first
    regularization: float = 2e-3    # weight of sum(log factor^2): decides only flat directions
    arm_split_prior: float = 0.05   # weight of (log upper_arm - log forearm)^2: a straight arm shows only the sum
    radius_prior: float = 0.0       # weight of sum((log r - log radius_centre)^2) over r_trunk/r_arms/r_legs: degraded
                                    # masks fatten the calibrated limbs (session 28: a lead on noisy bags, off)
    radius_centre: float = 1.15     # the radius factors' level on clean mesh bags (bench mesh's calibrations 1.08-1.25)
    energy: str = "raster"          # the shape fit's silhouette energy: "raster" (Eq. 4 counted on the pixel grid, no
                                    # sample) or "fast" (sampled: session 26's fit)
    restarts: int = 3               # whole calibrations from other seeds (x cost each), combined as `combine` says:
                                    # one calibration is a lottery of round 0's poses (docs/shape_calibration.md)
    combine: str = "lowest"         # restarts: "lowest" judged energy kept (measured better), or "median" of each factor
    judge: str = "fit"              # restarts judged by "fit" (each one's own shape-fit energy) or "track" (the mean
    judge_frames: int = 60          # tracker energy of the first judge_frames frames tracked with its shape: shape_judge)
    masks: str = "hull"             # the calibration frames' masks: "hull" = cut to the visual hull's person blob
                                    # (tracking/init_hull.py: occluders and noise no other view confirms go), "raw"
    seed: int = 0                   # all random streams derive from it

    def __post_init__(self):
        for name in ("window_frames", "n_frames", "rounds", "pose_steps", "shape_evals", "n_model_points", "n_mask_points",
                     "restarts", "judge_frames"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ShapeCalibrationError(f"{name}: expected an integer >= 1, received {v!r}")
        if not (np.isfinite(self.translation_m) and self.translation_m > 0):
            raise ShapeCalibrationError(f"translation_m: expected a number > 0, received {self.translation_m!r}")
        if self.masks not in ("hull", "raw"):
            raise ShapeCalibrationError(f"masks: expected 'hull' or 'raw', received {self.masks!r}")
        if self.energy not in ("raster", "fast"):
            raise ShapeCalibrationError(f"energy: expected 'raster' or 'fast', received {self.energy!r}")
        if self.judge not in ("fit", "track"):
            raise ShapeCalibrationError(f"judge: expected 'fit' or 'track', received {self.judge!r}")
        if self.combine not in ("lowest", "median"):
            raise ShapeCalibrationError(f"combine: expected 'lowest' or 'median', received {self.combine!r}")
        if not (np.isfinite(self.radius_centre) and self.radius_centre > 0):
            raise ShapeCalibrationError(f"radius_centre: expected a number > 0, received {self.radius_centre!r}")
        for name in ("regularization", "arm_split_prior", "radius_prior"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ShapeCalibrationError(f"{name}: expected a number >= 0, received {v!r}")


@dataclass(frozen=True)
class ShapeCalibrationResult:
    """What :func:`calibrate_shape` found.

    ``shape`` (a body-shape mapping, :func:`~isa_mocap_ros.body.save_shape` writes it), ``params``
    (factor per :data:`SHAPE_PARAMS` name), ``frame_keys`` (the calibration frames), ``poses``
    ((K, D) their poses under the calibrated shape), ``energy_default`` / ``energy`` (mean silhouette
    energy of the calibration frames with the base shape after round 0, and at the end), ``rounds``
    (per round: params and energy), ``notes``.
    """

    shape: dict
    params: dict
    frame_keys: tuple
    poses: np.ndarray
    energy_default: float
    energy: float
    rounds: tuple = ()
    notes: tuple = field(default=())


def shape_from_params(base: Mapping, factors: Mapping[str, float] | Sequence[float], *, name: str = "calibrated") -> dict:
    """The body shape ``base`` scaled by the factors of :data:`SHAPE_PARAMS` (a mapping by name or a
    sequence in that order; missing names = 1). Left/right symmetric: every right-side entry is the
    mirror of the left one."""
    from isa_mocap_ros.body.model import complete_shape

    if not isinstance(factors, Mapping):
        f = np.asarray(factors, dtype=float)
        if f.shape != (len(SHAPE_PARAMS),):
            raise ShapeCalibrationError(f"factors: expected {len(SHAPE_PARAMS)} numbers, received shape {f.shape}")
        factors = {n: float(v) for (n, _, _), v in zip(SHAPE_PARAMS, f)}
    unknown = set(factors) - {n for n, _, _ in SHAPE_PARAMS}
    if unknown:
        raise ShapeCalibrationError(f"factors: unknown names {sorted(unknown)} (expected "
                                    f"{', '.join(n for n, _, _ in SHAPE_PARAMS)})")
    g = {n: float(factors.get(n, 1.0)) for n, _, _ in SHAPE_PARAMS}
    if not all(np.isfinite(v) and v > 0 for v in g.values()):
        raise ShapeCalibrationError(f"factors: expected positive finite numbers, received {g}")
    shp = complete_shape(copy.deepcopy(dict(base)), source="base shape")
    offsets, radii = {}, {}
    for j, o in shp["offsets"].items():
        if j.startswith("right_"):
            continue
        o = np.array(o, dtype=float) * g["scale"]
        part = j[5:] if j.startswith("left_") else j
        if part in _LENGTH_OF:
            o *= g[_LENGTH_OF[part]]
        elif part == "hip":
            o[1] *= g["hip_width"]
        elif part == "shoulder":
            o[1] *= g["shoulder_width"]
            o[2] *= g["trunk"]
        offsets[j] = o
    for c, r in shp["radii"].items():
        if c.startswith("right_"):
            continue
        part = c[5:] if c.startswith("left_") else c
        k = g["scale"]
        if part in _R_TRUNK:
            k *= g["r_trunk"]
        elif part in _R_ARMS:
            k *= g["r_arms"]
        elif part in _R_LEGS:
            k *= g["r_legs"]
        radii[c] = np.array(r, dtype=float) * k
    return complete_shape({"name": name, "offsets": offsets, "radii": radii,
                           "axis_offsets": shp["axis_offsets"]}, source=name)


def bone_lengths(model) -> dict[str, float]:
    """Lengths (metres) of :data:`BONES` on ``model`` in its rest pose (those whose joints it has)."""
    from isa_mocap_ros.body import joint_positions

    P = joint_positions(model, model.rest_pose()[None, :])[0]
    idx = {n: i for i, n in enumerate(model.joint_names)}
    return {b: float(np.linalg.norm(P[idx[a]] - P[idx[c]])) for b, a, c in BONES if a in idx and c in idx}


def marker_bone_lengths(names: Sequence[str], markers) -> dict[str, float]:
    """Lengths (metres) of :data:`BONES` from named joint centres ``markers (F, M, 3)``: per bone the
    median over the frames of the distance between its two markers (a mesh skeleton's joint
    centres move slightly against each other as the skin is posed; the median is robust to that)."""
    T = np.asarray(markers, dtype=float)
    if T.ndim != 3 or T.shape[1] != len(names) or T.shape[2] != 3:
        raise ShapeCalibrationError(f"markers: expected shape (F, {len(names)}, 3), received {T.shape}")
    idx = {n: i for i, n in enumerate(names)}
    out = {}
    for b, a, c in BONES:
        if a in idx and c in idx:
            d = np.linalg.norm(T[:, idx[a]] - T[:, idx[c]], axis=1)
            d = d[np.isfinite(d)]
            if d.size:
                out[b] = float(np.median(d))
    return out


#: the bones whose two joints the capsule model and a mesh skeleton define alike (hip, knee, ankle, shoulder,
#: elbow, wrist centres); the trunk's (hip and shoulder widths, pelvis-neck, neck-head) join points the two
#: skeletons place differently (docs/decisions/012-joint-definitions.md)
LIMB_BONES: tuple[str, ...] = tuple(b for b, _, _ in BONES[:8])


def bone_errors(estimated: Mapping[str, float], truth: Mapping[str, float]) -> dict:
    """Per-bone absolute error (mm) over the bones both have, their mean (``mean_mm``) and the mean over the
    :data:`LIMB_BONES` among them (``limbs_mean_mm``: the like-with-like figure against a mesh skeleton)."""
    common = [b for b, _, _ in BONES if b in estimated and b in truth]
    per = {b: round(1e3 * abs(estimated[b] - truth[b]), 1) for b in common}
    limbs = [per[b] for b in LIMB_BONES if b in per]
    return {"per_bone_mm": per, "mean_mm": float(np.mean(list(per.values()))) if per else float("nan"),
            "limbs_mean_mm": float(np.mean(limbs)) if limbs else float("nan")}


class _ShapeEnergy:
    """Mean silhouette energy over the calibration frames of a batch of shape vectors ``Z (n, P+3K)``:
    log factors (``P``) and changes of the pose coordinates ``coords`` (root height, the coupled joint
    angles) of each frame, on the poses ``X (K, D)`` otherwise fixed. ``masks`` are the frames' masks as
    :func:`_prepared_masks` prepared them once (what does not depend on the candidate shape)."""

    def __init__(self, dof, base, cameras, masks, X, cfg: ShapeCalibrationConfig, rng_seed, coords=(2,)):
        self.dof, self.base, self.cameras, self.masks = dof, base, cameras, masks
        self.X = np.asarray(X, dtype=float)
        self.coords = np.asarray(coords, dtype=int)
        self.cfg = cfg
        self.seed = rng_seed
        self.n_evals = 0
        self._route = _RasterRoute(dof, base, cameras, masks, cfg) if cfg.energy == "raster" else None

    def params(self, z) -> np.ndarray:
        return np.exp(np.asarray(z[:len(SHAPE_PARAMS)], dtype=float))

    def model(self, z):
        from isa_mocap_ros.body import make_model

        return make_model(self.dof, shape=shape_from_params(self.base, self.params(z)))

    def poses(self, z) -> np.ndarray:
        P = len(SHAPE_PARAMS)
        X = self.X.copy()
        X[:, self.coords] += np.asarray(z[P:], dtype=float).reshape(len(X), len(self.coords))
        return X

    def frame_energy(self, model, k: int, x) -> float:
        """Silhouette energy of pose ``x`` of model ``model`` on calibration frame ``k``."""
        f = _energy(model, self.cameras, self.cfg, self.seed)
        f.set_masks(self.masks[k])
        return float(f(np.asarray(x, dtype=float)[None, :])[0])

    def one(self, z) -> float:
        X = self.poses(z)
        if self._route is not None:
            return self._route(self.params(z), X) + prior(self.cfg, z[:len(SHAPE_PARAMS)])
        # the same generator seed for every shape
        f = _energy(self.model(z), self.cameras, self.cfg, self.seed)
        e = 0.0
        for k, masks in enumerate(self.masks):
            f.set_masks(masks)
            e += float(f(X[k][None, :])[0])
        return e / len(self.masks) + prior(self.cfg, z[:len(SHAPE_PARAMS)])

    def __call__(self, Z) -> np.ndarray:
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        self.n_evals += len(Z)
        return np.array([self.one(z) if np.all(np.isfinite(z)) else np.inf for z in Z])


class _RasterRoute:
    """The raster shape fit's energy without a model or an energy object per candidate shape: the calibration
    frames' kernel inputs are set once (an energy of the base model per frame), and a candidate's offsets and radii
    are the base model's times the factors each entry scales (``offsets(f) = offsets0 * prod_p f_p^E_p``, ``E`` read
    off :func:`shape_from_params` once, factor by factor); the same kernel as ``SilhouetteEnergy(method='raster')``."""

    def __init__(self, dof, base, cameras, masks, cfg):
        from isa_mocap_ros.body import make_model
        from isa_mocap_ros.energy.silhouette import kinematic_tables
        from isa_mocap_ros.energy.silhouette_kernel import Body

        m0 = make_model(dof, shape=shape_from_params(base, {}))
        o0, r0 = np.asarray(m0.offsets, dtype=float), np.asarray(m0.capsule_radii, dtype=float)
        eo, er = [], []
        for n, _, _ in SHAPE_PARAMS:
            m = make_model(dof, shape=shape_from_params(base, {n: 2.0}))
            eo.append(np.round(np.log2(np.divide(m.offsets, o0, out=np.ones_like(o0), where=o0 != 0))))
            er.append(np.round(np.log2(np.divide(m.capsule_radii, r0, out=np.ones_like(r0), where=r0 != 0))))
        self.o0, self.r0, self.eo, self.er = o0, r0, np.array(eo), np.array(er)
        parents, _, ptr, dofs, axes = kinematic_tables(m0)
        self.body = lambda o, r: Body(parents, np.ascontiguousarray(o), ptr, dofs, axes,
                                      np.ascontiguousarray(m0.capsules, dtype=np.int64), np.ascontiguousarray(r))
        self.frames = []
        for pre in masks:
            f = _energy(m0, cameras, cfg, 0)
            f.set_masks(pre)
            self.frames.append(f.kernel_args()[1:])

    def __call__(self, factors, X) -> float:
        from isa_mocap_ros.energy.raster_kernel import raster_batch_serial

        lf = np.log(np.asarray(factors, dtype=float))
        body = self.body(self.o0 * np.exp(np.tensordot(lf, self.eo, 1)), self.r0 * np.exp(np.tensordot(lf, self.er, 1)))
        out = np.empty(1)
        e = 0.0
        for k, (views, raster) in enumerate(self.frames):
            raster_batch_serial(np.ascontiguousarray(X[k:k + 1], dtype=np.float64), body, views, raster, 1, out)
            e += float(out[0])
        return e / len(self.frames)


_UA, _FA = (next(i for i, (n, _, _) in enumerate(SHAPE_PARAMS) if n == m) for m in ("upper_arm", "forearm"))
_RADII = [i for i, (n, _, _) in enumerate(SHAPE_PARAMS) if n.startswith("r_")]


def prior(cfg: ShapeCalibrationConfig, logf) -> float:
    """The shape fit's prior on the log factors ``logf``: a weak pull of all towards 0 (the base shape) and one
    on the split of the arm between upper arm and forearm (which the silhouette of a straight arm cannot tell); with
    ``radius_prior`` > 0 one pulling the radius factors towards ``radius_centre``."""
    logf = np.asarray(logf, dtype=float)
    e = cfg.regularization * float(logf @ logf) + cfg.arm_split_prior * float(logf[_UA] - logf[_FA]) ** 2
    if cfg.radius_prior > 0:
        e += cfg.radius_prior * float(np.sum((logf[_RADII] - np.log(cfg.radius_centre)) ** 2))
    return e


def _energy(model, cameras, cfg: ShapeCalibrationConfig, seed):
    """The shape fit's silhouette energy of ``model`` (no masks set)."""
    from isa_mocap_ros.energy import SilhouetteEnergy

    method = cfg.energy
    return SilhouetteEnergy(model, cameras, None, method=method,
                            n_model_points=cfg.n_model_points if method == "fast" else 8,
                            n_mask_points=cfg.n_mask_points, rng=np.random.default_rng(seed))


def _prepared_masks(dof, cameras, masks, cfg: ShapeCalibrationConfig) -> list:
    """Each calibration frame's masks prepared once for the shape fit's energies (the foreground pixels and,
    with lens distortion, their undistorted area: the same for every candidate shape)."""
    from isa_mocap_ros.body import make_model

    f = _energy(make_model(dof), cameras, cfg, 0)
    return [f.prepare_masks(m) for m in masks]


def _hull_masks(masks_per_frame, cameras) -> tuple[list, str | None]:
    """Each frame's masks cut to the largest blob of its visual hull (:func:`.init_hull.person_masks`, what the
    tracker does to its first frame): foreground one view alone reports (an occluder drawn into one image, pixel
    noise) does not enter the shape fit. A view left empty becomes None. Returns the masks and a note on the share
    of foreground removed (None when nothing was)."""
    from .init_hull import person_masks

    out, cut, total = [], 0, 0
    for masks in masks_per_frame:
        kept, _ = person_masks(masks, cameras)
        for m, k in zip(masks, kept):
            if m is not None:
                n = int(np.count_nonzero(m))
                total += n
                cut += n - int(np.count_nonzero(k))
        out.append([None if k is None or not np.any(k) else k for k in kept])
    if not cut:
        return out, None
    return out, (f"calibration masks: the visual hull's person blob kept; {cut} of {total} foreground pixels "
                 f"({100 * cut / max(total, 1):.1f} %) removed over {len(out)} frames")


def _calibration_masks(masks_per_frame, cameras, config: ShapeCalibrationConfig) -> tuple[list, str | None]:
    """The calibration frames' masks as ``config.masks`` says (``hull``: :func:`_hull_masks`; ``raw``: as given)
    and the cut's note (or None)."""
    if config.masks == "hull":
        return _hull_masks(masks_per_frame, cameras)
    return list(masks_per_frame), None


def _tracker(model, cameras, tracker_config):
    from .tracker import Tracker

    return Tracker(model, cameras, tracker_config)


def calibrate_shape(dof: int, cameras: Sequence, frames: Sequence[tuple[int, Sequence]], *, tracker_config=None,
                    config: ShapeCalibrationConfig = ShapeCalibrationConfig(), base_shape=None,
                    progress=None) -> ShapeCalibrationResult:
    """Estimate the subject's body shape from the masks of the first frames.

    Parameters
    ----------
    dof : {18, 28, 39}
        Tracking model.
    cameras : sequence of Camera
    frames : sequence of (frame key, masks) or (frame key, masks, keypoints)
        Consecutive frames from the first the person is in view, masks one per camera (None for a
        missing view); the first ``config.window_frames`` are used. ``keypoints`` (per camera ``(uv (33, 2),
        confidence (33,))`` or None, as :meth:`.tracker.Tracker.step` takes them) enter the pose fits when
        ``tracker_config`` weighs the keypoint term.
    tracker_config : TrackerConfig, optional
        Settings of the pose fits (default ``TrackerConfig.from_flat(seed=config.seed)``).
    config : ShapeCalibrationConfig
    base_shape : mapping or path, optional
        Start and reference of the factors (default ``config/body/default.yaml``).
    progress : callable(str), optional
        Called with one line per round.

    Raises
    ------
    ShapeCalibrationError
        No frames, or the tracker cannot initialize from the first frame's masks.
    """
    from isa_mocap_ros.body import default_shape, load_shape

    from .tracker import TrackerConfig

    if not isinstance(config, ShapeCalibrationConfig):
        raise ShapeCalibrationError(f"config: expected a ShapeCalibrationConfig, received {type(config).__name__}")
    judge_frames = [(f[0], f[1], f[2] if len(f) > 2 else None) for f in list(frames)[:config.judge_frames]]
    frames = [(f[0], f[1], f[2] if len(f) > 2 else None) for f in list(frames)[:config.window_frames]]
    if not frames:
        raise ShapeCalibrationError("frames: expected at least one frame with masks, received none")
    base = default_shape() if base_shape is None else (
        load_shape(base_shape) if not isinstance(base_shape, Mapping) else dict(base_shape))
    tcfg = tracker_config if tracker_config is not None else TrackerConfig.from_flat(seed=config.seed)
    say = progress or (lambda s: None)
    if config.restarts == 1:
        return _calibrate_once(dof, cameras, frames, tcfg, config, base, say)
    # restarts: the whole calibration from other tracker (and shape fit) seeds; each result judged by the same
    # energy (one sample seed for all) on its calibration frames' masks as its fits used them (config.masks)
    out = []
    for r in range(config.restarts):
        seed = config.seed + 7919 * r
        cfg_r = dataclasses.replace(config, seed=seed, restarts=1)
        say(f"shape calibration restart {r + 1}/{config.restarts} (seed {seed})")
        res = _calibrate_once(dof, cameras, frames, tcfg.replace(seed=tcfg.search.seed + 7919 * r), cfg_r, base, say)
        out.append((_judged(dof, cameras, frames, base, config, res, res.params) if config.judge == "fit" else
                    tracked_energy(dof, cameras, judge_frames, res.shape, tcfg), r, res))
    listed = ", ".join(f"{t[0]:.4f}" for t in out)
    e, r, best = min(out, key=lambda t: t[0])
    if config.combine == "lowest":
        return dataclasses.replace(best, notes=best.notes + (f"restart {r + 1} of {config.restarts} kept ({config.judge} "
                                                             f"judge; judged energies {listed})",))
    # the median of each factor over the restarts (their poses: those of the restart that fits it best)
    logs = np.array([[np.log(t[2].params[n]) for n, _, _ in SHAPE_PARAMS] for t in out])
    factors = {n: float(v) for (n, _, _), v in zip(SHAPE_PARAMS, np.exp(np.median(logs, axis=0)))}
    e, r, best = min(((_judged(dof, cameras, frames, base, config, t[2], factors), t[1], t[2]) for t in out),
                     key=lambda t: t[0])
    note = (f"median factors of {config.restarts} restarts (judged energies {listed}; the median {e:.4f} on "
            f"restart {r + 1}'s poses)")
    return dataclasses.replace(best, shape=shape_from_params(base, factors), params=factors, energy=e,
                               notes=best.notes + (note,))


def _judged(dof, cameras, frames, base, config, res, params) -> float:
    """The energy (one sample seed for every restart) of the shape ``params`` with restart ``res``'s calibration
    frames and poses, on those frames' masks as its fits used them (``config.masks``)."""
    masks_of = {int(k): m for k, m, _ in frames}
    cal, _ = _calibration_masks([masks_of[k] for k in res.frame_keys], cameras, config)
    judge = _ShapeEnergy(dof, base, cameras, _prepared_masks(dof, cameras, cal, config), res.poses, config,
                         [config.seed, 33, 2])
    z = np.concatenate([np.log([params[n] for n, _, _ in SHAPE_PARAMS]), np.zeros(len(res.poses))])
    return float(judge(z[None, :])[0])


def _calibrate_once(dof, cameras, frames, tcfg, config, base, say) -> ShapeCalibrationResult:
    """One calibration (:func:`calibrate_shape` without restarts) from tracker settings ``tcfg``."""
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.optim import CmaEs, minimize

    from .tracker import TrackerError, frame_rng

    notes: list[str] = []

    # round 0 poses: track the window with the base shape from the automatic initialization
    model = make_model(dof, shape=shape_from_params(base, {}))
    tr = _tracker(model, cameras, tcfg)
    poses: dict[int, np.ndarray] = {}
    energies: dict[int, float] = {}
    for key, masks, kp in frames:
        r = tr.step(masks, int(key), keypoints=kp)
        if r.x is not None and np.isfinite(r.energy):
            poses[int(key)], energies[int(key)] = np.asarray(r.x, dtype=float), float(r.energy)
    if not poses:
        raise ShapeCalibrationError("frames: the tracker found no person in the calibration frames (no usable "
                                    "foreground); start the calibration where the person is in view")
    keys = sorted(poses)
    pick = np.unique(np.round(np.linspace(0, len(keys) - 1, min(config.n_frames, len(keys)))).astype(int))
    cal_keys = [keys[i] for i in pick]
    masks_of = {int(k): m for k, m, _ in frames}
    kps_of = {int(k): kp for k, _, kp in frames}
    # the pose fits' (the tracker filters them further) and the shape fit's: what one view alone reports stays out
    cal_raw, note = _calibration_masks([masks_of[k] for k in cal_keys], cameras, config)
    if note:
        notes.append(note)
    cal_masks = _prepared_masks(dof, cameras, cal_raw, config)     # the shape fit's energies'
    X = np.array([poses[k] for k in cal_keys])
    P = len(SHAPE_PARAMS)
    m0 = make_model(dof)
    coupled = [m0.dof_names.index(n) for n in config.coupled_dofs if n in m0.dof_names]
    coords = [2] + coupled                       # root height, then the coupled joint angles
    step = np.array([config.translation_m] + [config.angle_rad] * len(coupled))
    n_pose = len(X) * len(coords)
    lo = np.concatenate([np.log([b for _, b, _ in SHAPE_PARAMS]), -np.tile(step, len(X))])
    hi = np.concatenate([np.log([b for _, _, b in SHAPE_PARAMS]), np.tile(step, len(X))])
    spread = np.concatenate([0.25 * (hi[:P] - lo[:P]), 0.3 * np.tile(step, len(X))])
    logf = np.zeros(P)
    history = []
    best = None
    e_default = None
    energy_seed = [config.seed, 33, 1]
    for rnd in range(config.rounds):
        if rnd > 0:
            model = make_model(dof, shape=shape_from_params(base, np.exp(logf)))
            if config.retrack:
                # poses with the shape fixed, 1: the window tracked again from the automatic initialization
                # (a calibration frame keeps its last pose when that fits the new shape better)
                tr = _tracker(model, cameras, tcfg)
                judge = _ShapeEnergy(dof, base, cameras, cal_masks, X, config, energy_seed).frame_energy
                for key, masks, kp in frames:
                    r = tr.step(masks, int(key), keypoints=kp)
                    if int(key) in cal_keys and r.x is not None and np.all(np.isfinite(r.x)):
                        i = cal_keys.index(int(key))
                        if judge(model, i, r.x) < judge(model, i, X[i]):
                            X[i] = r.x
            # 2: tracker steps on each calibration frame from its last pose
            tr = _tracker(model, cameras, tcfg)
            for i, (k, masks) in enumerate(zip(cal_keys, cal_raw)):
                try:
                    tr.initialize(pose=X[i])
                except TrackerError as exc:
                    raise ShapeCalibrationError(f"pose fit of frame {k}: {exc}") from None
                for j in range(config.pose_steps):
                    # the frame key picks the random stream: one per (frame, round, step)
                    r = tr.step(masks, int(k) + 7919 * (rnd * config.pose_steps + j + 1), prediction=X[i],
                                keypoints=kps_of[k])
                    if r.x is not None and np.all(np.isfinite(r.x)):
                        X[i] = r.x
        fe = _ShapeEnergy(dof, base, cameras, cal_masks, X, config, energy_seed, coords)
        z0 = np.concatenate([logf, np.zeros(n_pose)])
        e0 = float(fe(z0[None, :])[0])
        if e_default is None:
            e_default = float(fe(np.zeros_like(z0)[None, :])[0])
        opt = CmaEs(z0, spread * (0.6 ** rnd), bounds=(lo, hi), rng=frame_rng(config.seed, rnd, 33))
        res = minimize(opt, fe, max_evals=config.shape_evals)
        if res.energy < e0:
            z = np.clip(res.x, lo, hi)
            logf = z[:P]
            X = np.clip(fe.poses(z), m0.lower, m0.upper)
        else:
            notes.append(f"round {rnd}: the shape fit found nothing better than {e0:.4f}")
        e_now = float(min(res.energy, e0))
        if best is None or e_now < best[0]:
            best = (e_now, logf.copy(), X.copy())
        history.append({"round": rnd, "energy": round(e_now, 5),
                        "params": {n: round(float(v), 4) for (n, _, _), v in zip(SHAPE_PARAMS, np.exp(logf))}})
        say(f"shape calibration round {rnd + 1}/{config.rounds}: energy {e0:.4f} -> {e_now:.4f}, "
            + ", ".join(f"{n} {v:.3f}" for n, v in history[-1]["params"].items()))
    # the round with the lowest energy (a re-tracked window can come back worse)
    e_final, logf, X = best
    factors = {n: float(v) for (n, _, _), v in zip(SHAPE_PARAMS, np.exp(logf))}
    shape = shape_from_params(base, factors)
    at_bound = [n for (n, lo_, hi_), v in zip(SHAPE_PARAMS, np.exp(logf)) if v <= lo_ * 1.005 or v >= hi_ / 1.005]
    if at_bound:
        notes.append(f"factors at their bounds: {', '.join(at_bound)}")
    return ShapeCalibrationResult(shape=shape, params=factors, frame_keys=tuple(cal_keys), poses=X,
                                  energy_default=float(e_default), energy=float(e_final), rounds=tuple(history),
                                  notes=tuple(notes))
