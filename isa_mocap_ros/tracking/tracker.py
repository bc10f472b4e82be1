"""The per-frame tracker: prediction → mask filters → optimizer on the energy → stages → estimate.

Sources: yeguas_ea_vs_pf_mocap §3 (energy Eq. 4-5 over the V views, §3.3 hierarchy, search radius
0.5 rad around the prediction, budgets in evaluations per frame), gall_isa_introduction §13.4.2
(prediction 13.28, prior 13.32-13.33: ``E = E_data − η ln p(x)``, contours 13.30-13.31).

:meth:`Tracker.step` tells one frame's story: masks checked (:mod:`.frame_masks`), the prediction
(:mod:`.frame_prediction`), the mask gate and hull filter, the budget plan (:mod:`.plan`), the main
search, the stages (:mod:`.stages`), the estimate; the first frame (:mod:`.first_frame`) and the
heading check (:mod:`.heading`) have their own modules. Frame ``k`` draws everything from
``default_rng([seed, k, ...])``: same seed and inputs ⇒ identical estimates. Bad masks or predictions
are notes in :class:`FrameResult`, never exceptions. Reference: ``docs/tracking.md``.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Callable, Mapping, Sequence

import numpy as np

from isa_mocap_ros.geometry import nearest_rotvec

from isa_mocap_ros.optim import compiled_search

from . import chain_moves, first_frame, frame_masks, frame_prediction, heading, keypoint_screen, objective, plan
from . import stages as frame_stages
from .camera_data import prepare_cameras
from .config import (DEFAULT_PARAMS, JOINT_SPREAD_RAD, ROOT_ROTATION_RADIUS_RAD, ROOT_ROTATION_SPREAD_RAD,
                     ROOT_TRANSLATION_SPREAD_M, PREDICTORS, FrameResult, TrackerConfig, TrackerError,
                     frame_rng, partition_coords, whole_generations)
from .contour import ContourFit
from .frame_context import FrameContext
from .gate import visible_shares
from .init import InitError
from .limbs import LimbMove
from .objective import TotalEnergy
from .plan import FrameBudget
from .predict import (ArPredictor, ConstantPosePredictor, ConstantVelocityPredictor, PredictionError,
                      frame_periods)
from .reaim import ReaimMove
from .state import HeadingCheckState, TrackState

__all__ = ["TrackerError", "TrackerConfig", "FrameResult", "FrameBudget", "FrameContext", "Tracker", "make_tracker",
           "DEFAULT_PARAMS", "PREDICTORS", "frame_rng"]


def _make_predictor(config: TrackerConfig):
    if config.prediction.predictor == "ar":
        return ArPredictor(order=config.prediction.predictor_order)
    if config.prediction.predictor == "constant_pose":
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
        Used when ``config.objective.prior_eta > 0`` (else ``config.objective.prior_file`` is loaded).
    energy : object, optional
        Data term with ``set_masks(masks)`` and ``__call__(X (n, D)) -> (n,)``; default
        :class:`~isa_mocap_ros.energy.silhouette.SilhouetteEnergy` with the config's method and
        downsampling.
    predictor : object, optional
        With ``update(x)``, ``predict()``, ``reset()`` (e.g. :class:`.published.PublishedPredictor`
        to reproduce the node network's numbers); default from ``config.prediction.predictor``.

    Examples
    --------
    >>> tracker = Tracker(model, rig.cameras, TrackerConfig.from_flat(seed=1))      # doctest: +SKIP
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
        if config.objective.prior_eta > 0:
            if prior is None and config.objective.prior_file:
                from isa_mocap_ros.energy.prior import ParzenPrior

                prior = ParzenPrior.load(config.objective.prior_file)
            if prior is None:
                raise TrackerError("prior: expected a ParzenPrior (prior= or config.objective.prior_file) when "
                                   "prior_eta > 0, received none")
            if getattr(prior, "n_dof", model.dof) != model.dof:
                raise TrackerError(f"prior: expected a prior over {model.dof}-DOF poses, received one over "
                                   f"{prior.n_dof}")
            self.prior = prior
        own_energy = energy is None
        from isa_mocap_ros.energy.silhouette import SilhouetteEnergy
        if energy is None:

            obj = config.objective
            energy = SilhouetteEnergy(model, cams, None, method=obj.energy, downsample=obj.downsample,
                                      n_model_points=obj.n_model_points, n_mask_points=obj.n_mask_points,
                                      core_px=obj.silhouette_core_px,
                                      rng=np.random.default_rng([config.search.seed, 2**32 - 1]))
        if not (callable(energy) and hasattr(energy, "set_masks")):
            raise TrackerError(f"energy: expected an object with set_masks() and __call__, received "
                               f"{type(energy).__name__}")
        self.energy = energy
        # the automatic initialization's grid scores rough standing poses: with the fine sample
        # sizes it picked a heading 180 deg off on bags/demo, with the library's coarse ones not
        self.init_energy = None
        if own_energy and config.objective.energy == "fast":
            self.init_energy = SilhouetteEnergy(model, cams, None, method="fast",
                                                downsample=config.objective.downsample,
                                                rng=np.random.default_rng([config.search.seed, 2**32 - 2]))
        # what the frame carries to the next (last estimate, predictor, masks, root history, clock)
        self.track = TrackState(_make_predictor(config) if predictor is None else predictor)
        # the stages' moves (tracking/stages.py): the pelvis stage's (the root, the limbs below it re-aimed), the
        # torso stage's (the joints of the torso partition, e.g. spine and neck, the arms re-aimed), the limb
        # stage's proposals, the contour stage's fit and the coordinates of its extra iterations
        self.pelvis_reaim = ReaimMove(model, [0]) if "root" in model.partitions else None
        torso_joints = sorted({int(model.dof_joint[d]) for d in model.partitions.get("torso", ())})
        self.torso_reaim = ReaimMove(model, torso_joints) if torso_joints else None
        self.limb_move = LimbMove(model)
        self.contour_fit = ContourFit(model, self.cameras, n_points=config.stages.contour_points,
                                      max_px=config.stages.contour_max_px)
        self.contour_extra_coords = partition_coords(model, config.stages.contour_extra_partitions)
        prepare_cameras(self.cameras, config)          # calibration-only data now, not on the start-up's frames
        self.generation_sizes: dict[int, int] = {}     # plan.flat_generation's cache, by coordinate count
        missing = [k for k in model.partitions if k not in config.search.partition_order]
        if missing:
            raise TrackerError(f"partition_order: expected every partition of model {model.name} "
                               f"({', '.join(model.partitions)}), missing {', '.join(missing)}")
        # the hierarchical optimizers' partitions, in config.search.partition_order
        self.partitions = [np.asarray(model.partitions[k]) for k in config.search.partition_order
                           if k in model.partitions]
        self.frames = 0
        # the heading check after an automatic initialization (config.heading.init_confirm_frames)
        self.heading_check = HeadingCheckState()
        # h-isa runs compiled per partition, either energy (optim/compiled_search.py, the same
        # numbers as the optimizer protocol); False: always through the protocol (tests compare both)
        self.use_compiled_search = True

    # ------------------------------------------------------------------ state
    @property
    def predictor(self):
        """The track's own predictor (:attr:`TrackState.predictor`); assignable (e.g. a
        :class:`.published.PublishedPredictor` around it)."""
        return self.track.predictor

    @predictor.setter
    def predictor(self, value) -> None:
        self.track.predictor = value

    @property
    def initialized(self) -> bool:
        """True once an estimate exists (given, automatic or tracked)."""
        return self.track.last is not None

    @property
    def last_estimate(self) -> np.ndarray | None:
        return None if self.track.last is None else self.track.last.copy()

    @property
    def checking_heading(self) -> bool:
        """True while the heading check after the automatic initialization runs (``init_confirm_frames``):
        it decides on consecutive frames only, so a caller that drops frames (the estimator node in
        real time) should hand it the frames that follow in sequence meanwhile."""
        return self.heading_check.rival is not None

    def heading_recheck_pending(self, masks: Sequence) -> bool:
        """See :func:`.heading.heading_recheck_pending`."""
        return heading.heading_recheck_pending(self, masks)


    def reset(self) -> None:
        """Forget the estimates (the next step initializes again)."""
        self.track.forget()
        self.heading_check = HeadingCheckState()

    @property
    def has_heading(self) -> bool:
        """Whether the model's root turns by a 3-DOF rotation vector (a heading to check)."""
        return 3 in {len(b) for b in self.model.rotation_blocks}

    def total_energy(self, X) -> np.ndarray:
        """Data term plus the prior ``−η ln p`` (13.33) of poses ``(n, D)`` under the current masks
        (:class:`.objective.TotalEnergy`; a step's own objective adds its keypoint term)."""
        return TotalEnergy(self)(X)

    def restricted_energy(self, x_base, coords):
        """:meth:`total_energy` for poses equal to ``x_base`` outside ``coords``, the same values (None when the
        data term has no ``restrict``); see :meth:`.objective.TotalEnergy.restrict`."""
        return TotalEnergy(self).restrict(x_base, coords)

    def frame_context(self, frame_index: int = 0, budget: FrameBudget | None = None, *, keypoint_term=None,
                      prediction=None) -> FrameContext:
        """A :class:`FrameContext` for frame ``frame_index``: plan ``budget`` (default the configured
        evaluations with the contour stage), the objective with ``keypoint_term``, the external ``prediction``;
        its masks are the tracker's current ones until the step checks and filters the frame's."""
        return FrameContext(frame_index, self.config.search.seed,
                            budget if budget is not None else FrameBudget(self.config.search.evals),
                            TotalEnergy(self, keypoint_term), external_prediction=prediction,
                            raw_masks=self.track.masks_now, masks=self.track.masks_now, t0=time.perf_counter())

    # ------------------------------------------------------------------ initialization
    def initialize(self, masks: Sequence | None = None, pose=None, *, frame_index: int = 0,
                   keypoints: Sequence | None = None):
        """See :func:`.first_frame.initialize`."""
        return first_frame.initialize(self, masks, pose, frame_index=frame_index, keypoints=keypoints)


    def accept(self, x: np.ndarray) -> None:
        """Take ``x`` as the frame's estimate (:meth:`.state.TrackState.accept`)."""
        self.track.accept(x)

    # ------------------------------------------------------------------ one frame

    def search_box(self, center) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bounds ``(lo, hi)`` and initial spreads ``(D,)`` around a (clipped) prediction."""
        cfg, m = self.config, self.model
        radius = np.full(m.dof, cfg.search.search_radius_rad)
        radius[:3] = cfg.search.root_translation_radius_m
        radius[3:6] = ROOT_ROTATION_RADIUS_RAD
        spread = np.full(m.dof, JOINT_SPREAD_RAD)
        spread[:3] = ROOT_TRANSLATION_SPREAD_M
        spread[3:6] = ROOT_ROTATION_SPREAD_RAD
        c = np.clip(np.asarray(center, dtype=float), m.lower, m.upper)
        lo = np.maximum(c - radius, m.lower)
        hi = np.minimum(c + radius, m.upper)
        tight = hi - lo < 1e-9                 # a prediction on a limit: keep a sliver of room
        lo[tight] = np.maximum(m.lower[tight], hi[tight] - 1e-6)
        hi[tight] = lo[tight] + 1e-6
        return lo, hi, spread

    def plan_search(self, pred: np.ndarray, rng: np.random.Generator, budget: FrameBudget,
                    spread_scale: float = 1.0, notes=None, stages: bool = True):
        """The frame's optimizer around ``pred`` (not yet run), its share of the budget, the stages
        ``(pelvis, torso, limb stage, contour shares; None or empty = skipped)`` and the search box
        ``(lo, hi, spread, spread without the motion term)`` (see :meth:`optimize`)."""
        from isa_mocap_ros.optim import inner_optimizer, make_optimizer

        cfg = self.config
        lo, hi, spread = self.search_box(pred)
        base = spread * spread_scale
        spread = base.copy()              # the motion term widens the main search's spreads only
        if stages and cfg.search.spread_velocity_gain > 0 and self.track.last is not None:
            moved = cfg.search.spread_velocity_gain * np.abs(pred[6:] - self.track.last[6:])
            spread[6:] = np.sqrt(spread[6:] ** 2 + moved ** 2)
        x0 = np.clip(pred, lo, hi)
        params = cfg.search.params()
        if inner_optimizer(cfg.search.optimizer) is not None:
            params.setdefault("partitions", self.partitions)
            # whole generations (not on the automatically initialized frame, whose runs from the heading
            # candidates keep the proportional split their pruning and heading choice were measured with)
            params.setdefault("whole_generations", stages)
        elif "initial_population" not in params:
            # first generation: the prediction itself plus draws around it (so the estimate
            # can never be worse than the prediction by the energy's own measure)
            n = make_optimizer(cfg.search.optimizer, x0, spread, rng=np.random.default_rng(0), bounds=(lo, hi),
                               **params).generation_size
            P = np.clip(x0 + rng.standard_normal((n, x0.size)) * spread, lo, hi)
            P[0] = x0
            params["initial_population"] = P
        opt = make_optimizer(cfg.search.optimizer, x0, spread, rng=rng, bounds=(lo, hi),
                             rotation_blocks=self.model.rotation_blocks, **params)
        share = plan.pelvis_share(self, notes, budget) if stages else None
        torso = plan.torso_share(self, notes, budget) if stages else None
        limbs = plan.limb_stage(self, notes, x0, budget) if stages else ([], [], 0)
        contour = plan.contour_share(self, notes, budget) if stages else None
        budget = budget.evals - (share or 0) - (torso or 0) - plan.limb_share(self, len(limbs[0]), limbs[2]) \
            - (contour or 0) - (chain_moves.untwist_share(self) if stages else 0)
        if torso is not None:
            # the torso stage never starves the main search: two generations per partition stay
            need = 2 * (sum(plan.flat_generation(self, len(p)) for p in self.partitions)
                        if inner_optimizer(cfg.search.optimizer) is not None else opt.generation_size)
            if budget < need:
                if notes is not None:
                    notes.append(f"torso stage skipped: with its share ({torso} evaluations) the main search would "
                                 f"keep {budget}, fewer than two generations per partition ({need})")
                budget += torso
                torso = None
        if inner_optimizer(cfg.search.optimizer) is None:
            budget = whole_generations(budget, opt.generation_size)     # (hierarchical: its split does this)
        return opt, budget, (share, torso, limbs, contour), (lo, hi, spread, base)

    def optimize(self, ctx: FrameContext, pred: np.ndarray, rng: np.random.Generator, *, spread_scale: float = 1.0,
                 notes=None, stages: bool = True, budget: FrameBudget | None = None):
        """One optimizer run of the frame's budget ``ctx.budget`` (or ``budget``: the first frame's polish) on its
        objective around ``pred`` (raises the optimizer's errors), then
        the pelvis stage (``config.stages.pelvis_fraction`` of the budget), the torso stage
        (``config.stages.torso_fraction``), the limb stage (``config.stages.limb_proposals``) and the contour stage
        (``config.stages.contour_iterations``), each also given what the searches before it left unspent
        (they run whole generations; the limb stage takes the rest as more proposals, so a frame
        leaves fewer evaluations unspent than it has limbs in the stage);
        ``spread_scale`` multiplies the initial spreads (the first frame starts from a rough pose);
        skipped stages are noted in ``notes``. The heading candidates' searches of the automatically
        initialized frame have no stage (``stages=False``): from a rough standing pose the pelvis stage
        turned the pelvis against the legs (``docs/decisions/009-first-frame.md``); its
        polish (``config.first_frame.init_polish``) then searches the winner with every stage."""
        from isa_mocap_ros.optim import minimize

        opt, budget, stage_shares, (lo, hi, spread, base) = self.plan_search(
            pred, rng, ctx.budget if budget is None else budget, spread_scale, notes, stages)
        share, torso, limbs, contour = stage_shares
        res = compiled_search.search(opt, self.energy, budget, extra_terms=ctx.objective.extra_terms,
                                     keypoints=ctx.objective.weighted_keypoints,
                                     coarse_fraction=self.config.search.coarse_fraction) \
            if self.use_compiled_search else None
        if res is None:                   # not covered by the compiled path (the same numbers through the protocol)
            res = minimize(opt, ctx.objective, max_evals=budget)
        # what a search leaves unspent (less than a generation: whole generations) goes to the next stage
        spare = budget - res.n_evals
        exact = False           # res.energy is res.x's (a stage's returned energy), not the search's best particle's
        if share is not None:
            x, e, n = frame_stages.refit_pelvis(self, ctx, res.x, evals=share + spare, rng=rng, bounds=(lo, hi),
                                                spread=spread)
            spare += share - n
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
            exact = True
        if torso is not None:
            x, e, n, _ = frame_stages.refit_torso(self, ctx, res.x, evals=torso + spare, rng=rng,
                                                  energy=res.energy if share is not None else None,
                                                  bounds=(lo, hi), spread=spread)
            spare += torso - n
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
            exact = True
        limbs, hinge, n_limb = limbs
        if limbs:
            extra = spare // len(limbs)       # more proposals with the rest
            x, e, n, _ = frame_stages.propose_limbs(self, ctx, res.x, n=n_limb + extra, rng=rng, limbs=limbs,
                                                    hinge_only=hinge, last=self.track.last)
            spare -= extra * len(limbs)
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
            exact = True
        if stages and self.config.stages.leg_untwist:      # chain_moves.py: the thighs' twist halved or undone
            x, e, n, _ = chain_moves.untwist_legs(self, ctx, res.x, energy=res.energy if exact else None,
                                                  tolerance=self.config.stages.leg_untwist_tolerance,
                                                  margin=self.config.stages.leg_untwist_margin)
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
            exact = True
        if contour is not None:
            x, e, n, info = frame_stages.fit_contours(self, ctx, res.x, energy=res.energy if exact else None)
            if info.stopped and notes is not None:
                notes.append(f"contour stage: stopped after {info.iterations} iterations ({info.stopped})")
            res = dataclasses.replace(res, x=x, energy=e, n_evals=res.n_evals + n)
        return res


    def fit_contours(self, x, *, iterations: int | None=None, extra_iterations: int | None=None):
        """:func:`.stages.fit_contours` under the current masks."""
        return frame_stages.fit_contours(self, self.frame_context(), x, iterations=iterations, extra_iterations=extra_iterations)


    def refit_pelvis(self, x, *, evals: int, rng: np.random.Generator, optimizer: str | None=None, params: Mapping | None=None, bounds=None, spread=None) -> tuple[np.ndarray, float, int]:
        """:func:`.stages.refit_pelvis` under the current masks."""
        return frame_stages.refit_pelvis(self, self.frame_context(), x, evals=evals, rng=rng, optimizer=optimizer, params=params, bounds=bounds, spread=spread)


    def refit_torso(self, x, *, evals: int, rng: np.random.Generator, energy: float | None=None, bounds=None, spread=None) -> tuple[np.ndarray, float, int, bool]:
        """:func:`.stages.refit_torso` under the current masks."""
        return frame_stages.refit_torso(self, self.frame_context(), x, evals=evals, rng=rng, energy=energy, bounds=bounds, spread=spread)


    def propose_limbs(self, x, *, n: int, rng: np.random.Generator, limbs: Sequence[str] | None=None, hinge_only: Sequence[str]=(), last=None) -> tuple[np.ndarray, float, int, list[str]]:
        """:func:`.stages.propose_limbs` under the current masks."""
        return frame_stages.propose_limbs(self, self.frame_context(), x, n=n, rng=rng, limbs=limbs, hinge_only=hinge_only, last=last)


    def final_pose(self, res) -> tuple[np.ndarray, float]:
        """The optimizer's estimate (its best particle when the estimate is not finite) in the model's
        limits, rotation vectors shortened (|r| <= pi), and its energy."""
        if not np.all(np.isfinite(res.x)):
            x, energy = res.best_x, res.best_energy
        else:
            x, energy = res.x, res.energy
        x = np.clip(np.array(x, dtype=float), self.model.lower, self.model.upper)
        for blk in self.model.rotation_blocks:      # |r| <= pi: turning on and on never meets the limits
            idx = list(blk)
            x[idx] = nearest_rotvec(x[idx], np.zeros(3))
        return x, float(energy)


    def step(self, masks: Sequence, frame_index: int, *, prediction=None, frames_elapsed: float = 1,
             contour_stage: bool = True, keypoints: Sequence | None = None, evals: int | None = None) -> FrameResult:
        """Track one frame (see the module docstring). Never raises on bad masks, predictions or keypoints.

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
        keypoints : sequence of ``(uv (33, 2), confidence (33,))`` or None
            Per camera BlazePose landmarks; with ``config.keypoints.keypoint_weight > 0`` they add the keypoint term
            to this frame's energy (the heading check's rival's too, so both are scored alike).
        evals : int, optional
            This frame's evaluation budget instead of ``config.search.evals`` (the estimator node's lowered budget
            under load, :mod:`.load`); the stages size their shares from it.

        Returns
        -------
        FrameResult
        """
        if evals is not None and (isinstance(evals, bool) or not isinstance(evals, (int, np.integer)) or evals < 1):
            raise TrackerError(f"evals: expected an integer >= 1 or None, received {evals!r}")
        term, note = objective.keypoint_energy(self, keypoints)
        ctx = self.frame_context(frame_index, FrameBudget(self.config.search.evals if evals is None else int(evals),
                                                             bool(contour_stage)),
                                 keypoint_term=term, prediction=prediction)
        res = self._step_with_heading_check(masks, ctx, frames_elapsed)
        return res if note is None else dataclasses.replace(res, notes=res.notes + (note,))

    def _step_with_heading_check(self, masks: Sequence, ctx: FrameContext, frames_elapsed: float) -> FrameResult:
        """The frame of this hypothesis, then the heading check: start its rival after an automatic
        initialization, re-check the heading, or step the rival beside the track and decide."""
        rival = self.heading_check.rival
        res = self.track_frame(masks, ctx, frames_elapsed=frames_elapsed)
        if self.heading_check.own_prediction_frames > 0:
            self.heading_check.own_prediction_frames -= 1
        if res.initialized:
            self.heading_check.rival = None
            self.heading_check.views = res.views_used
            if self.heading_check.rival_start is not None:
                e_rival, e_win = self.heading_check.rival_start[1], self.heading_check.rival_start[2]
                heading.start_rival(self, ctx.frame_index)
                return dataclasses.replace(res, notes=res.notes + (
                    f"heading check started: a run heading the other way ended {e_rival:.4g} (winner {e_win:.4g}); both "
                    f"tracked for up to {self.config.heading.init_confirm_frames} frames",))
            return res
        if rival is None:
            return heading.recheck_heading(self, ctx, res, frames_elapsed)
        if rival is not self.heading_check.rival:
            return res
        if frames_elapsed != 1:
            # after a gap both hypotheses are still catching up and their energies say little (real
            # time, the sets that arrived during the initialization dropped: wrong switches measured);
            # re-checked once on the next frame that follows its previous one (a real-time caller holds
            # the sets in sequence for it): a re-check started by a wrong heading must not end unheard
            hc = self.heading_check
            hc.rival = None
            again = not hc.gap_rechecked
            if again:
                hc.gap_recheck_at, hc.gap_rechecked = self.frames + 1, True
            return dataclasses.replace(res, notes=res.notes + (
                f"heading check ended: no decision ({frames_elapsed:g} frame periods since the last frame; "
                "it compares consecutive frames only); kept this heading"
                + ("; re-checked on the next frame that follows its previous one" if again else ""),))
        return heading.confirm_heading(self, ctx, res, masks, frames_elapsed)

    def travel(self, min_periods: float = 0.0) -> tuple[float, float, float] | None:
        """See :func:`.heading.travel`."""
        return heading.travel(self, min_periods)

    def track_frame(self, masks: Sequence, ctx: FrameContext, *, frames_elapsed: float = 1) -> FrameResult:
        """The frame ``ctx`` of this hypothesis (:meth:`step` without the heading check's rival): masks checked,
        filtered around the prediction, weighted and given to the energy; the first frame initialized, a tracked
        one searched from the prediction with every stage; the estimate taken."""
        t0 = time.perf_counter()
        frame_index = ctx.frame_index
        if isinstance(frame_index, bool) or not isinstance(frame_index, (int, np.integer)) or frame_index < 0:
            raise TrackerError(f"frame_index: expected an integer >= 0, received {frame_index!r}")
        try:
            self.track.elapsed += frame_periods("frames_elapsed", frames_elapsed)
        except PredictionError as exc:
            raise TrackerError(str(exc)) from None
        cfg, notes = self.config, ctx.notes
        ctx.raw_masks, checked = frame_masks.check_masks(self, masks)
        notes.extend(checked)
        # the mask gate and the visual-hull filter around the prediction (made there when they run)
        frame_masks.filter_masks(self, ctx)
        # the keypoints the views' evidence contradicts go (.keypoint_screen): off the filtered foreground or
        # outside the other views' consensus
        ctx.objective.keypoint_term, note = keypoint_screen.screen(ctx.objective.keypoint_term, ctx.masks)
        if note:
            notes.append(note)
        if cfg.objective.view_weights and self.track.last is not None and any(m is not None for m in ctx.masks):
            # Eq. 5's view weights (config.objective.view_weights): the share of the predicted body each view sees
            ctx.weights = visible_shares(self.model, self.cameras, frame_prediction.prediction(self, ctx),
                                         joints=frame_prediction.prediction_joints(self, ctx))
        views = frame_masks.set_masks(self, ctx)
        if views == 0:
            notes.append("no usable view: falling back to the last estimate" if self.track.last is not None
                         else "no usable view and no estimate yet: nothing to track")
            return FrameResult(x=self.last_estimate, energy=float("nan"), n_evals=0, spread=float("nan"),
                               time_s=time.perf_counter() - t0, views_used=0, notes=tuple(notes), fell_back=True)
        if cfg.objective.temporal_weight > 0 and self.track.last is not None:
            # the temporal term (energy/temporal.py, off by default) around the frame's prediction
            ctx.objective.temporal_term = objective.temporal_term(self, frame_prediction.prediction(self, ctx))
        n_evals = 0
        initialized = False
        if self.track.last is None:
            try:
                res0 = first_frame.initial_grid(self, ctx)
            except InitError as exc:
                notes.append(f"automatic initialization failed: {exc}")
                return FrameResult(x=None, energy=float("nan"), n_evals=0, spread=float("nan"),
                                   time_s=time.perf_counter() - t0, views_used=views, notes=tuple(notes),
                                   fell_back=True)
            n_evals += res0.n_evals
            initialized = True
            starts = [c[0] for c in res0.candidates] or [res0.x]
        else:
            starts = [frame_prediction.prediction(self, ctx)]
            if ctx.after_gap:          # the legs' side unknown: frame_prediction.gap_start
                start, n_side, charged = frame_prediction.gap_start(self, ctx, starts[0])
                starts, n_evals = [start], n_evals + n_side
                ctx.budget = dataclasses.replace(ctx.budget, evals=ctx.budget.evals - charged)   # out of the frame's budget
        # the first frame optimizes from every initialization candidate (pruned to config.first_frame.init_keep
        # runs part-way) and keeps the lowest energy
        try:
            if initialized:
                runs, n = first_frame.initial_runs(self, ctx, starts, notes, ctx.budget)
            else:
                res = self.optimize(ctx, starts[0], ctx.rng(), notes=notes)
                runs, n = [(0, res, starts[0])], res.n_evals
        except ValueError as exc:
            # a configuration the optimizer rejects (budget below one generation, bad parameter):
            # report it on every frame instead of crashing the caller
            notes.append(f"optimizer failed: {exc}; falling back to the last estimate")
            return FrameResult(x=self.last_estimate, energy=float("nan"), n_evals=n_evals, spread=float("nan"),
                               time_s=time.perf_counter() - t0, views_used=views, notes=tuple(notes),
                               fell_back=True, prediction=starts[0], initialized=initialized)
        _, res, pred = min(runs, key=lambda run: run[1].energy)     # the first of the lowest energy
        n_evals += n
        if initialized:
            notes.append(f"initialized automatically ({len(starts)} heading candidates, {len(runs)} searched to the "
                         f"end, grid best yaw {np.rad2deg(res0.yaw):.0f} deg {res0.variant}, {n_evals} evaluations)")
        x, energy = self.final_pose(res)
        if initialized and cfg.heading.init_confirm_frames > 0:
            self.heading_check.rival_start, n = heading.init_rival(self, ctx, runs, res, x, energy, notes)
            n_evals += n
        if initialized and cfg.first_frame.init_polish:
            # config.first_frame.init_polish: the winner (and the heading check's rival) searched once more, from itself
            x, energy, res, n = first_frame.polish_winner(self, ctx, x, energy, res)
            n_evals += n
        if res.n_nonfinite:
            notes.append(f"energy: {res.n_nonfinite} non-finite evaluations")
        spread_out = res.history[-1].spread if res.history else float("nan")
        self.accept(x)
        self.frames += 1
        return FrameResult(x=x, energy=float(energy), n_evals=int(n_evals), spread=float(spread_out),
                           time_s=time.perf_counter() - t0, views_used=views, notes=tuple(notes), fell_back=False,
                           prediction=pred, initialized=initialized)


def make_tracker(model, cameras: Sequence, *, energy_fn: Callable | None = None, **config) -> Tracker:
    """A :class:`Tracker` from flat settings: ``config`` keywords are :class:`TrackerConfig` fields (the
    estimator node's parameters carry the same names); ``energy_fn``: a data term object (see
    :class:`Tracker`)."""
    return Tracker(model, cameras, TrackerConfig.from_flat(**config), energy=energy_fn)
