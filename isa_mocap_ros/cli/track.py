"""``isa-mocap track BAG --out DIR``: track a recorded multi-view bag offline (no ROS runtime).

Reads the bag with :class:`isa_mocap_ros.bag.BagReader`, converts the messages with
``msg_adapters`` into a :class:`isa_mocap_ros.sequence.Sequence`, takes the recorded masks
(``/mocap/cam<i>/mask``, with ``--use-masks``) or segments the images with the segmentation node's
code (:class:`~isa_mocap_ros.vision.segmentation.BackgroundSegmenter`, one per view, learning the
background from the empty frames at the start), runs :class:`~isa_mocap_ros.tracking.Tracker` once
per frame, and writes

* ``DIR/estimates``: rosbag2 MCAP with ``/mocap/joint_states`` (``sensor_msgs/JointState``, the
  tracking model's ``dof_names``, root as x, y, z, roll, pitch, yaw as the estimator node publishes
  it), stamped with the frame stamp;
* ``DIR/summary.json``: settings, speed and, with ground truth in the bag, the accuracy
  (``mpjpe_mm``, ``knee_rmse_deg``, ``max_frame_error_mm``, ``frames``).

Ground-truth joints: forward kinematics of the ground-truth pose with the ground-truth model (from
the bag's ``/mocap/ground_truth/model``) and of the estimate with the tracking model, over the
marker joints both models share (by name). Exit codes: 0 done, 2 bad input, 130 interrupted.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from isa_mocap_ros.cli.track_io import TOPIC, JointStateBag, read_sequence, reference_coverage, refine_by_model, write_overlay_media
from isa_mocap_ros.cli.keypoint_options import DEFAULT_KEYPOINT_WEIGHT, default_keypoint_weight
from isa_mocap_ros.vision.keypoint_schedule import EVERY_K


#: The tracker settings ``track`` takes as valued options: (flag, type, default, metavar, help); a default of None
#: leaves the tracker's own.
_TRACKER_OPTIONS = (
    ("--silhouette-core-px", float, None, "PX",
     "silhouette energy: a foreground pixel d px from the background counts min(1, d/PX) in the term of foreground "
     "the model misses (the rim of clothes and soft tissue asks less to be covered; <= 1: Eq. 4 as printed; "
     "default: the tracker's default)"),
    ("--gate-margin-px", int, None, "PX",
     "mask gate: keep only foreground components within PX pixels of the predicted silhouette (0 = off; default: "
     "the tracker's default)"),
    ("--init-confirm-frames", int, None, "N",
     "heading check after the automatic initialization: frames an opposite-heading rival is tracked beside the "
     "winner (0 = off; default: the tracker's default)"),
    ("--partition-order", str, None, "NAMES",
     "comma-separated order of the hierarchy's partitions (default: the tracker's, root,left_arm,right_arm,torso,"
     "left_leg,right_leg; the paper's: root,torso,left_arm,right_arm,left_leg,right_leg)"),
    ("--coarse-fraction", float, None, "F",
     "share of each partition's generations of the main search evaluated on the energy's coarse level (--energy "
     "fast: two views; raster: every second pixel row; docs/energy.md); 0 = off (default: the tracker's default)"),
    ("--leg-untwist", "untwist", None, "TOL|off",
     "the untwist stage (docs/tracking.md, decision 019): each thigh's twist halved or undone, the ankle turned back, "
     "taken when its energy is below the pose's times 1 + TOL (0: strictly lower; off: the stage off; default: the "
     "tracker's, on at 0.01)"),
    ("--leg-untwist-margin", float, None, "M",
     "the untwist stage (on with it) also takes a proposal whose energy is below the pose's times 1 + TOL plus M "
     "(energy units; with --leg-untwist 0: the margin alone; default: the tracker's, 0)"),
    ("--pelvis-fraction", float, None, "F",
     "budget share of the pelvis stage (0 = off; default: the tracker's default)"),
    ("--keypoint-weight", float, None, "W",
     "weight of the learned-keypoint term (BlazePose landmarks on the images, cropped around the mask; "
     f"docs/keypoints.md); 0 = off; default {DEFAULT_KEYPOINT_WEIGHT:g} when the landmark model is installed "
     "(make models), else off with a note"),
    ("--keypoint-every", int, EVERY_K, "K",
     "with --keypoint-weight: after the dense start, detect keypoints on every K-th frame with a person of each "
     f"view (0 = the dense start only; default {EVERY_K}, the keypoint node's every_k_frames)"),
    ("--keypoint-dense", int, None, "N",
     "with --keypoint-weight: detect on each view's first N frames with a person (the initialization and its "
     "heading check; default 4, the keypoint node's dense_frames)"),
    ("--keypoint-extra-gap", int, 0, "G",
     "with --keypoint-weight: also detect on every view of a frame where a forearm of the previous estimate lies "
     "over its trunk in some view, at most every G-th frame (an option, issue 34; 0 = off, the default)"),
    ("--temporal-weight", float, None, "W",
     "weight of the temporal term: chosen joints held near their predicted positions, robustly (an option, "
     "issue 34, energy/temporal.py; 0 = off, the default)"),
    ("--temporal-joints", str, None, "A,B",
     "the temporal term's model joints (default: the tracker's, left_ankle,right_ankle)"),
)


def _untwist_tolerance(text: str):
    """``--leg-untwist``'s value: a tolerance >= 0 or ``off`` (imported here: the tracker loads only to run)."""
    from isa_mocap_ros.tracking.chain_moves import parse_untwist_tolerance

    try:
        return parse_untwist_tolerance(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def register(sub) -> None:
    p = sub.add_parser("track", help="track a multi-view bag offline and report the accuracy",
                       description="Track the person in BAG (masks or images of /mocap/cam<i>/...) frame by frame; "
                                   "write DIR/estimates (MCAP) and DIR/summary.json.")
    p.add_argument("bag", metavar="BAG", help="rosbag2 directory or .mcap file")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--optimizer", default="h-isa", help="optimizer name (default h-isa; isa, apf, psapf, cmaes, de, pso, h-isa, "
                                                     "h-apf, h-cmaes, h-de, h-pso)")
    p.add_argument("--evals", type=int, default=1500, help="energy evaluations per frame (default 1500)")
    p.add_argument("--params", default=None, metavar="JSON", help="optimizer parameters as a JSON object")
    p.add_argument("--model", type=int, choices=(18, 28, 39), default=None,
                   help="tracking model DOF (default: the bag's ground-truth model's, else 39)")
    p.add_argument("--seed", type=int, default=0, help="seed of the per-frame random streams (default 0)")
    p.add_argument("--frames", type=int, default=None, metavar="N", help="track at most N frames")
    p.add_argument("--stride", type=int, default=1, metavar="K",
                   help="track every K-th frame only, as a network that keeps up with 1/K of the frame rate "
                        "(the prediction looks K periods ahead; every frame is still segmented; default 1)")
    p.add_argument("--start", type=int, default=0, metavar="K",
                   help="first frame to track (frame index in the bag, empty frames included; default: the "
                        "first frame after the background learning)")
    p.add_argument("--use-masks", action="store_true", help="use /mocap/cam<i>/mask when the bag has it")
    p.add_argument("--learn-frames", type=int, default=None, metavar="K",
                   help="frames the segmenter learns the background from (default: the bag's empty frames, "
                        "else the frames before its first reference marker, else 10)")
    p.add_argument("--shape", default="auto", metavar="auto|default|truth|FILE",
                   help="body shape of the tracking model: 'auto' (default) calibrates it from the silhouettes of "
                        "the first frames (isa-mocap calibrate); 'default' = config/body/default.yaml; FILE = a "
                        "body-shape YAML (e.g. written by isa-mocap calibrate); 'truth' = the bag's ground-truth "
                        "model's (a diagnostic only)")
    p.add_argument("--init", choices=("auto", "truth"), default="auto",
                   help="first pose: automatic from the masks (default) or the ground truth")
    p.add_argument("--predictor", choices=("ar", "constant_pose", "constant_velocity"), default=None)
    p.add_argument("--prior", default=None, metavar="NPZ", help="Parzen prior file (with --prior-eta)")
    p.add_argument("--prior-eta", type=float, default=0.0, help="prior weight (0 = off)")
    p.add_argument("--energy", choices=("raster", "fast", "exact"), default=None,
                   help="silhouette energy method (default: the tracker's, raster: Eq. 4 counted on the pixel grid; "
                        "fast: the sampled kernel; exact: the rendered reference; docs/energy.md)")
    for flag, kind, default, metavar, text in _TRACKER_OPTIONS:
        p.add_argument(flag, type=_untwist_tolerance if kind == "untwist" else kind, default=default, metavar=metavar,
                       help=text)
    p.add_argument("--no-hull", action="store_true",
                   help="visual-hull filter off (on by default: foreground pixels the other views do not confirm, "
                        "beyond the predicted silhouette, are dropped)")
    p.add_argument("--no-view-weights", action="store_true",
                   help="count every view alike in the silhouette energy (Eq. 5 as printed; by default a view counts "
                        "by the share of the predicted body inside its image)")
    p.add_argument("--refine-masks", action="store_true",
                   help="model-guided mask refinement: a graph cut (GrabCut) per view seeded by the previous "
                        "estimate's silhouette (ISA eq. 13.29's shape prior; isa_mocap_ros.vision.refine), for "
                        "parts the background subtraction misses (dark clothes on a dark floor)")
    p.add_argument("--field-memory", type=float, default=None, metavar="W",
                   help="segmentation under pixel noise (robust mode's field vote): weight of the earlier frames' "
                        "person evidence in a pixel's, 0 <= W < 1 (default: the segmentation's, 0 = off; "
                        "docs/history/issue33_noise_s30.md)")
    p.add_argument("--overlays", default=None, metavar="DIR",
                   help="also draw the estimate on every view: DIR/strip.png (a few frames, all views) and "
                        "DIR/overlay.mp4 (every tracked frame, all views side by side)")
    p.add_argument("--smooth-hz", type=float, default=0.0, metavar="HZ",
                   help="also smooth the finished track offline: a zero-phase Butterworth low-pass (order 4, forward "
                        "and backward, the filter Pose2Sim applies to its points; 6 Hz its demo's) on the poses, "
                        "written to DIR/estimates_smoothed and scored apart ('smoothed' in summary.json); the "
                        "per-frame estimates and their score are unchanged (0 = off, the default)")
    p.add_argument("--overwrite", action="store_true", help="replace DIR/estimates if it exists")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    from isa_mocap_ros.cli.shape_options import add_calibration_arguments

    add_calibration_arguments(p)
    p.set_defaults(func=run)


def _fail(msg: str) -> int:
    print(f"isa-mocap track: error: {msg}", file=sys.stderr)
    return 2


def _table(rows: list[tuple[str, str]]) -> str:
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{w}}  {v}" for k, v in rows)


def track_bag(args, *, collect: dict | None = None) -> dict:
    """Do the work of ``isa-mocap track`` (raises ValueError subclasses on bad input); return the summary.

    ``collect``, when given, receives the arrays behind the summary (for benchmarks that score
    differently): ``model``, ``truth_model``, ``estimates`` / ``truth`` / ``energies`` (dicts frame
    index -> pose / energy), ``init_frame`` (the index initialized from the ground truth with
    ``--init truth``, else None), ``stamps`` (frame index -> stamp in ns) and ``step_seconds`` (frame
    index -> wall time of the tracker's step, segmentation excluded), ``step_cpu_seconds`` (the same steps'
    CPU time, every thread of the process). A ``collect["profiler"]`` given in (a ``cProfile.Profile``)
    is enabled around the tracker's steps only.
    """
    from tqdm import tqdm

    from isa_mocap_ros.bag import BagReader
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.tracking import Tracker, TrackerConfig
    from isa_mocap_ros.tracking.published import PublishedPredictor
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    smooth_hz = float(getattr(args, "smooth_hz", 0.0) or 0.0)
    if not np.isfinite(smooth_hz) or smooth_hz < 0:
        raise ValueError(f"--smooth-hz: expected a cut-off in Hz >= 0 (0 = off), received {smooth_hz}")
    if args.evals < 1:
        raise ValueError(f"--evals: expected an integer >= 1, received {args.evals}")
    if args.frames is not None and args.frames < 1:
        raise ValueError(f"--frames: expected an integer >= 1, received {args.frames}")
    if args.start < 0:
        raise ValueError(f"--start: expected an integer >= 0, received {args.start}")
    stride = getattr(args, "stride", 1)
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1:
        raise ValueError(f"--stride: expected an integer >= 1, received {stride}")
    params = {}
    if args.params:
        try:
            params = json.loads(args.params)
        except json.JSONDecodeError as exc:
            raise ValueError(f"--params: expected a JSON object, received {args.params!r} ({exc})") from None
        if not isinstance(params, dict):
            raise ValueError(f"--params: expected a JSON object, received {args.params!r}")
    bag_path = Path(args.bag)
    if not bag_path.exists():
        raise ValueError(f"BAG: expected a rosbag2 directory or .mcap file, received {args.bag!r} (no such path)")
    with BagReader(bag_path) as probe:
        has_mask_topics = any(t.endswith("/mask") and t.startswith(f"{TOPIC}/cam") for t in probe.topics)
    use_masks = bool(args.use_masks and has_mask_topics)
    # a caller's namespace without the option tracks without keypoints; the command line's default (None) is
    # the main job's: on when the landmark model is installed (cli.keypoint_options)
    kp_weight = getattr(args, "keypoint_weight", 0.0)
    kp_note = None
    if kp_weight is None:
        kp_weight, kp_note = default_keypoint_weight()
        if kp_note:
            print(f"track: {kp_note}", file=sys.stderr)
    kp_weight = float(kp_weight)
    kp_every = int(getattr(args, "keypoint_every", EVERY_K))
    from isa_mocap_ros.vision.keypoint_schedule import (ARM_TRUNK_JOINTS, DENSE_FRAMES, KeypointSchedule,
                                                        detect_in_mask, forearms_over_trunk)
    kp_dense = getattr(args, "keypoint_dense", None)
    kp_dense = DENSE_FRAMES if kp_dense is None else int(kp_dense)
    if not np.isfinite(kp_weight) or kp_weight < 0 or kp_every < 0 or kp_dense < 0:
        raise ValueError(f"--keypoint-weight / --keypoint-every / --keypoint-dense: expected numbers >= 0, received "
                         f"{kp_weight}, {kp_every}, {kp_dense}")
    detector = None
    if kp_weight > 0:
        from isa_mocap_ros.vision.landmark_model import ModelUnavailable
        from isa_mocap_ros.vision.landmarks import PoseLandmarker
        try:
            detector = PoseLandmarker()
        except ModelUnavailable as exc:
            raise ValueError(f"--keypoint-weight: {exc}") from None
    seq = read_sequence(bag_path, want_images=not use_masks or detector is not None, want_masks=use_masks)
    if not seq.frames:
        raise ValueError(f"BAG: expected frames with images{' or masks' if use_masks else ''}, received none")
    dof = args.model or (seq.truth_model.dof if seq.truth_model is not None else 39)
    shape_arg = getattr(args, "shape", "auto")
    if shape_arg == "truth":
        if seq.truth_model is None:
            raise ValueError("--shape truth: expected a ground-truth model in the bag, received none")
        # diagnostic only: the subject's true shape, as the papers' subject-specific models
        model = make_model(dof, shape=dict(seq.truth_model.shape))
    elif shape_arg in ("default", "auto"):
        model = make_model(dof)          # auto: replaced by the calibrated shape below
    else:
        from isa_mocap_ros.body import BodyError
        try:
            model = make_model(dof, shape=Path(shape_arg))
        except BodyError as exc:
            raise ValueError(f"--shape: expected auto, default, truth or a body-shape YAML file ({exc})") from None
    notes = list(seq.notes) + ([kp_note] if kp_note else [])
    if args.use_masks and not has_mask_topics:
        notes.append("--use-masks: the bag has no mask topics; segmenting the images")

    # masks per frame: recorded, or segmented with one background model per view
    learn = 0
    segmenters = None
    if not use_masks:
        # default: the bag's empty frames, else (an imported recording) the frames before its first
        # reference marker, as `isa-mocap run` counts them, else 10
        before_markers = next((f.index for f in seq.frames if f.truth_markers is not None), 0)
        learn = args.learn_frames if args.learn_frames is not None else (seq.empty_frames or before_markers or 10)
        if learn < 1:
            raise ValueError(f"--learn-frames: expected an integer >= 1, received {learn}")
        memory = {} if getattr(args, "field_memory", None) is None else {"field_memory": args.field_memory}
        segmenters = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn, **memory)) for _ in seq.cameras]
    first = max(args.start, learn if not use_masks else 0)
    if args.init == "truth":
        with_truth = [f.index for f in seq.frames if f.truth is not None and f.index >= first]
        if not with_truth:
            raise ValueError("--init truth: expected ground truth in the bag, received none")
        first = with_truth[0]
    stop = len(seq.frames) if args.frames is None else min(len(seq.frames), first + args.frames)
    if first >= len(seq.frames):
        raise ValueError(f"--start: expected a frame before the bag's end ({len(seq.frames)} frames, background "
                         f"learning takes {learn}), received {args.start}")

    prior = None
    if args.prior_eta > 0:
        if not args.prior:
            raise ValueError("--prior-eta: expected --prior NPZ as well, received none")
        from isa_mocap_ros.energy.prior import ParzenPrior
        prior = ParzenPrior.load(args.prior)
    cfg_kw = dict(optimizer=args.optimizer, evals=args.evals, optimizer_params=params, seed=args.seed,
                  prior_eta=args.prior_eta, keypoint_weight=kp_weight)
    if getattr(args, "energy", None) is not None:
        cfg_kw["energy"] = args.energy
    if args.predictor:
        cfg_kw["predictor"] = args.predictor
    if getattr(args, "silhouette_core_px", None) is not None:
        cfg_kw["silhouette_core_px"] = args.silhouette_core_px
    if getattr(args, "gate_margin_px", None) is not None:
        cfg_kw["gate_margin_px"] = args.gate_margin_px
    if getattr(args, "no_hull", False):
        cfg_kw["hull_filter"] = False
    if getattr(args, "temporal_weight", None) is not None:
        cfg_kw["temporal_weight"] = args.temporal_weight
    if getattr(args, "temporal_joints", None) is not None:
        cfg_kw["temporal_joints"] = args.temporal_joints
    if getattr(args, "no_view_weights", False):
        cfg_kw["view_weights"] = False
    if getattr(args, "init_confirm_frames", None) is not None:
        cfg_kw["init_confirm_frames"] = args.init_confirm_frames
    if getattr(args, "pelvis_fraction", None) is not None:
        cfg_kw["pelvis_fraction"] = args.pelvis_fraction
    if getattr(args, "leg_untwist", None) == "off":
        cfg_kw["leg_untwist"] = False
    elif getattr(args, "leg_untwist", None) is not None:
        cfg_kw.update(leg_untwist=True, leg_untwist_tolerance=args.leg_untwist)
    if getattr(args, "leg_untwist_margin", None) is not None:
        cfg_kw.update(leg_untwist=True, leg_untwist_margin=args.leg_untwist_margin)
    if getattr(args, "coarse_fraction", None) is not None:
        cfg_kw["coarse_fraction"] = args.coarse_fraction
    if getattr(args, "partition_order", None) is not None:
        cfg_kw["partition_order"] = tuple(v.strip() for v in args.partition_order.split(",") if v.strip())
    cfg = TrackerConfig.from_flat(**cfg_kw)
    calibration = None
    if shape_arg == "auto":
        from isa_mocap_ros.cli.shape_options import calibrate_sequence, save_calibrated_shape
        from isa_mocap_ros.tracking.shape_calibration import ShapeCalibrationError

        try:
            res, calibration = calibrate_sequence(
                seq, args, dof=dof, use_masks=use_masks, learn=learn, first=first,
                tracker_config=cfg.replace(prior_eta=0.0, keypoint_weight=0.0, temporal_weight=0.0),
                progress=None if args.no_progress else (lambda line: print(line, file=sys.stderr, flush=True)))
        except ShapeCalibrationError as exc:
            raise ValueError(f"--shape auto: {exc}; pass --shape default or a body-shape FILE") from None
        # tracked with the shape read back from DIR/body.yaml (written exactly), as `run` and `calibrate` give it
        save_calibrated_shape(res, bag_path.name, Path(args.out) / "body.yaml")
        model = make_model(dof, shape=Path(args.out) / "body.yaml")
    tracker = Tracker(model, seq.cameras, cfg, prior=prior)
    # as the node network: the prediction travels as JointState (roll/pitch/yaw root) and the
    # frame key is the stamp in ns, so `isa-mocap track` reproduces the estimator node's numbers
    tracker.predictor = PublishedPredictor(model, tracker.predictor)

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    est_path = out / "estimates"
    if est_path.exists() and not args.overwrite:
        raise FileExistsError(f"--out: {est_path} exists; pass --overwrite to replace it")
    show = not args.no_progress
    refine = bool(getattr(args, "refine_masks", False))
    if refine and not seq.frames[first].has_images:
        raise ValueError("--refine-masks: expected images in the bag (the graph cut needs colours), received "
                         "masks only")
    overlay_dir = getattr(args, "overlays", None)
    overlay_store: list | None = [] if overlay_dir else None
    refine_seconds: list[float] = []
    coverage: list[float] = []          # share of the reference points inside the masks, per frame
    estimates: dict[int, np.ndarray] = {}
    energies: dict[int, float] = {}
    step_seconds: dict[int, float] = {}
    step_cpu: dict[int, float] = {}         # CPU time of the step (this process, every thread)
    profiler = None if collect is None else collect.get("profiler")
    init_frame = None
    results = []
    n_fell_back = 0
    t_track = 0.0
    kp_seconds: list[float] = []        # detection time per frame set with keypoints

    kp_gap = int(getattr(args, "keypoint_extra_gap", 0) or 0)
    schedules = [KeypointSchedule(kp_every, dense_frames=kp_dense, extra_gap=kp_gap) for _ in seq.cameras]
    kp_views = [0]                      # detections run
    if kp_gap > 0 and not set(ARM_TRUNK_JOINTS) <= set(model.joint_names):
        raise ValueError(f"--keypoint-extra-gap: expected a model with arms, received {model.dof} DOF")
    arm_idx = [model.joint_names.index(n) for n in ARM_TRUNK_JOINTS] if kp_gap > 0 else []

    def arm_over_trunk() -> bool:
        """--keypoint-extra-gap's want: a forearm of the previous estimate over its trunk in some view."""
        if kp_gap <= 0 or tracker.last_estimate is None:
            return False
        from isa_mocap_ros.body import joint_positions
        P = joint_positions(model, tracker.last_estimate[None])[0, arm_idx]
        return bool(forearms_over_trunk(seq.cameras, P).any())

    def keypoints_of(fr, masks):
        """The keypoint node's output for this frame (the same schedule and detection, through its message:
        Point32 is float32), so a lockstep run of the network with keypoints gives these estimates."""
        import msg_adapters as ma
        t0 = time.perf_counter()
        out, looked = [], False
        wanted = arm_over_trunk()
        for v, (img, m) in enumerate(zip(fr.images, masks)):
            if img is None or m is None or not schedules[v].due(bool(np.any(m)), wanted=wanted):
                out.append(None)
                continue
            looked = True
            kp_views[0] += 1
            lm = detect_in_mask(detector, img, m)       # bag images are rgb8 (camera node, synth)
            if lm is None:
                out.append(None)
                continue
            wire = ma.to_cdr(ma.keypoints_to_polygon(lm.uv, lm.confidence))     # float32 on the wire
            out.append(ma.polygon_to_keypoints(ma.from_cdr(wire, "geometry_msgs/msg/PolygonStamped")))
        if looked:
            kp_seconds.append(time.perf_counter() - t0)
        return out if any(o is not None for o in out) else None
    t_model = int(seq.frames[0].stamp_ns) if seq.frames else 0
    with JointStateBag(est_path, model, role="isa-mocap track", overwrite=args.overwrite,
                       model_stamp_ns=t_model) as bag:
        bar = tqdm(total=stop - first, unit="frame", desc="track", file=sys.stderr, disable=not show)
        for fr in seq.frames[:stop]:
            if use_masks:
                masks = list(fr.masks)
            else:
                masks = [None if img is None else seg.apply(img) for seg, img in zip(segmenters, fr.images)]
            if fr.index < first:
                continue
            if refine and tracker.initialized and fr.index % stride == first % stride:
                t0 = time.perf_counter()
                masks = refine_by_model(model, seq.cameras, tracker.last_estimate, fr.images, masks)
                refine_seconds.append(time.perf_counter() - t0)
            if fr.truth_markers is not None and seq.truth_marker_names:
                coverage.append(reference_coverage(seq.cameras, fr.truth_markers, masks))
            if (fr.index - first) % stride:
                bar.update(1)
                continue
            t0 = time.perf_counter()
            if args.init == "truth" and not tracker.initialized:
                if fr.truth is None or seq.truth_model is None or seq.truth_model.dof != model.dof:
                    raise ValueError("--init truth: expected ground truth of the tracking model's DOF at the first "
                                     f"frame ({fr.index}), received none")
                tracker.initialize(pose=fr.truth)
                init_frame = fr.index
                r = None
                x = tracker.last_estimate
            else:
                kp = keypoints_of(fr, masks) if detector is not None else None
                c0 = time.process_time()
                if profiler is not None:
                    profiler.enable()
                r = tracker.step(masks, int(fr.stamp_ns), frames_elapsed=stride, keypoints=kp)
                if profiler is not None:
                    profiler.disable()
                step_cpu[fr.index] = time.process_time() - c0
                x = r.x
            dt = time.perf_counter() - t0
            t_track += dt
            if r is not None:
                step_seconds[fr.index] = dt
                results.append(r)
                n_fell_back += int(r.fell_back)
            if x is not None and overlay_store is not None:
                overlay_store.append((fr.index, fr.images, masks, x))
            if x is not None:
                estimates[fr.index] = x
                if r is not None:
                    energies[fr.index] = float(r.energy)
                bag.write(fr.stamp_ns, x)
            if r is not None and show:
                bar.set_postfix(E=f"{r.energy:.3f}", views=r.views_used)
            bar.update(1)
        bar.close()

    n_tracked = len(range(first, stop, stride))
    stamp_of = {f.index: int(f.stamp_ns) for f in seq.frames[first:stop:stride]}
    if collect is not None:
        collect.update(model=model, truth_model=seq.truth_model, estimates=dict(estimates), energies=dict(energies),
                       truth={f.index: f.truth for f in seq.frames[first:stop:stride] if f.truth is not None},
                       init_frame=init_frame, stamps=stamp_of, step_seconds=dict(step_seconds),
                       step_cpu_seconds=dict(step_cpu),
                       truth_markers={f.index: f.truth_markers for f in seq.frames[first:stop:stride]
                                      if f.truth_markers is not None},
                       truth_marker_names=tuple(seq.truth_marker_names), body=seq.body_kind)
    summary: dict = {"bag": str(bag_path), "out": str(out), "optimizer": args.optimizer, "evals_per_frame": args.evals,
                     "stride": stride, "shape": shape_arg,
                     "optimizer_params": cfg.search.params(), "model_dof": model.dof, "seed": args.seed,
                     "gate_margin_px": cfg.masks.gate_margin_px, "hull_filter": cfg.masks.hull_filter,
                     "silhouette_core_px": cfg.objective.silhouette_core_px,
                     "view_weights": cfg.objective.view_weights,
                     "init_confirm_frames": cfg.heading.init_confirm_frames,
                     "partition_order": list(cfg.search.partition_order),
                     "coarse_fraction": cfg.search.coarse_fraction,
                     "keypoint_weight": kp_weight, "keypoint_every": kp_every, "keypoint_dense": kp_dense,
                     "keypoint_extra_gap": kp_gap, "keypoint_extra_detections": sum(s.extra for s in schedules),
                     "keypoint_frames": len(kp_seconds), "keypoint_detections": kp_views[0],
                     "keypoint_ms_per_frame_set": float(np.mean(kp_seconds) * 1e3) if kp_seconds else None,
                     "masks": "recorded" if use_masks else f"segmented (learned from {learn} frames)",
                     "frames_tracked": n_tracked, "frames_estimated": len(estimates), "frames_fell_back": n_fell_back,
                     "fps": n_tracked / t_track if t_track > 0 else float("nan"),
                     "mean_energy": float(np.mean(fin)) if (fin := [r.energy for r in results if np.isfinite(r.energy)])
                     else float("nan"),
                     # per estimated frame, in order: its stamp and the energy of the estimate (null for a
                     # frame initialized from the ground truth); `isa-mocap evaluate` plots them
                     "frame_stamps_ns": [stamp_of[k] for k in sorted(estimates)],
                     "frame_energies": [None if k not in energies or not np.isfinite(energies[k])
                                        else round(energies[k], 6) for k in sorted(estimates)],
                     "notes": notes + sorted({n for r in results for n in r.notes
                                              if not n.startswith("initialized")})[:20]}
    if overlay_store:
        summary["overlays"] = write_overlay_media(Path(overlay_dir), model, seq, overlay_store)
    summary["refine_masks"] = refine
    summary["field_memory"] = segmenters[0].config.field_memory if segmenters else None
    if refine_seconds:
        summary["refine_ms_per_frame_set"] = float(np.mean(refine_seconds) * 1e3)
    if coverage:
        # mask quality without exact masks: the share of the reference's points (all of them, in view)
        # that the masks the tracker used cover
        summary["mask_reference_coverage"] = float(np.nanmean(coverage))
    if calibration is not None:
        summary["shape_calibration"] = calibration
    inits = [n for r in results for n in r.notes if n.startswith("initialized")]
    if inits:
        summary["init"] = inits[0]
    from isa_mocap_ros.eval.report import score

    by_stamp = {int(seq.frames[k].stamp_ns): estimates[k] for k in estimates}
    acc = score(model, seq, by_stamp)
    if acc is not None:
        acc.pop("stamps")
        summary.update(acc)
    else:
        summary["frames"] = len(estimates)
    if smooth_hz > 0 and estimates:
        from isa_mocap_ros.cli.track_io import smooth_track, write_joint_states

        smoothed = smooth_track(model, stamp_of, estimates, smooth_hz)
        if collect is not None:
            collect["estimates_smoothed"] = smoothed
        write_joint_states(out / "estimates_smoothed", model, {stamp_of[k]: x for k, x in smoothed.items()},
                           overwrite=args.overwrite)
        sm = score(model, seq, {int(seq.frames[k].stamp_ns): smoothed[k] for k in smoothed})
        summary["smoothed"] = {"cutoff_hz": smooth_hz, "order": 4, **({k: sm[k] for k in (
            "mpjpe_mm", "offset_removed_mpjpe_mm", "knee_rmse_deg", "max_frame_error_mm", "per_marker_mm",
            "offset_removed_per_marker_mm") if k in sm} if sm is not None else {})}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def run(args: argparse.Namespace) -> int:
    try:
        s = track_bag(args)
    except (ValueError, FileExistsError) as exc:
        return _fail(str(exc))
    rows = [("bag", s["bag"]), ("optimizer", f"{s['optimizer']}, {s['evals_per_frame']} evaluations/frame"),
            ("model", f"{s['model_dof']} DOF"), ("masks", s["masks"]),
            ("frames", f"{s['frames_tracked']} tracked, {s['frames_fell_back']} fell back"),
            ("keypoints", f"weight {s['keypoint_weight']:g}, every {s['keypoint_every']} frames after the first "
                          f"{s['keypoint_dense']}" if s["keypoint_weight"] > 0 else "off"),
            ("speed", f"{s['fps']:.2f} frames/s")]
    if "mpjpe_mm" in s:
        rows += [("mean joint error (Eq. 20)", f"{s['mpjpe_mm']:.1f} mm over {s['frames']} frames "
                                               f"(by {s['scored_by'].replace('_', ' ')})")]
        if "mapped_mpjpe_mm" in s:
            rows.append((f"mapped to the rig ({s.get('joint_map', '')} joint map)",
                         f"{s['mapped_mpjpe_mm']:.1f} mm (max frame {s['mapped_max_frame_error_mm']:.1f} mm, knee "
                         f"{s['mapped_knee_rmse_deg']:.2f} deg)"))
        if "offset_removed_mpjpe_mm" in s:
            rows.append(("each joint's mean offset removed", f"{s['offset_removed_mpjpe_mm']:.1f} mm "
                                                            f"(max frame {s['offset_removed_max_frame_error_mm']:.1f} mm"
                                                            + (f", knee {s['offset_removed_knee_rmse_deg']:.2f} deg)"
                                                               if "offset_removed_knee_rmse_deg" in s else ")")))
        rows.append(("max frame error", f"{s['max_frame_error_mm']:.1f} mm"
                     + (f" (frame {s['worst_frame_index']} of the scored)" if "worst_frame_index" in s else "")))
        rows.append(("knee-angle RMSE", f"{s['knee_rmse_deg']:.2f} deg"))
        sm = s.get("smoothed") or {}
        if "mpjpe_mm" in sm:
            rows.append((f"smoothed offline ({sm['cutoff_hz']:g} Hz, zero phase)",
                         f"{sm['mpjpe_mm']:.1f} mm" + (f", offsets removed {sm['offset_removed_mpjpe_mm']:.1f} mm"
                                                       if "offset_removed_mpjpe_mm" in sm else "")
                         + f", knee {sm['knee_rmse_deg']:.2f} deg"))
        if s.get("frames_facing_backwards") is not None:
            rows.append(("frames facing backwards", f"{s['frames_facing_backwards']} (heading error max "
                                                    f"{s['max_heading_error_deg']:.0f} deg)"))
    else:
        rows.append(("accuracy", "no ground truth in the bag"))
    print("track: accuracy\n" + _table(rows))
    if s.get("scored_by") == "markers":
        from isa_mocap_ros.eval.report import marker_score_lines

        print("\n".join(marker_score_lines(s)))
    print(f"track: wrote {Path(s['out']) / 'estimates'} and {Path(s['out']) / 'summary.json'}")
    if "overlays" in s:
        print(f"track: overlays {s['overlays']['strip']} (frames {s['overlays']['strip_frames']}) and "
              f"{s['overlays']['video']} ({s['overlays']['video_frames']} frames at {s['overlays']['video_fps']} fps)")
    return 0
