"""``isa-mocap run [BAG] --out DIR``: the main job — the node network on a bag, recorded and evaluated.

Starts segmentation, prediction and estimator nodes (each its own process, parameters from
``config/pipeline.yaml`` plus the command's options) and a recorder, waits until the estimator is
ready, replays the bag with the player (``--lockstep`` on the estimator's ``estimator/done`` topic for
deterministic runs, or in real time at ``--rate``), then stops everything cleanly, evaluates the
recorded estimates against the bag's ground truth and writes ``DIR/summary.json``, plots and overlay
frames. Uses the caller's ``ROS_DOMAIN_ID`` when set (so you can subscribe to
``/mocap/joint_states`` while it runs), a private one otherwise.
"""
from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from pathlib import Path

import numpy as np

from isa_mocap_ros.bag import BagReader
from isa_mocap_ros.cli.keypoint_options import DEFAULT_KEYPOINT_WEIGHT, default_keypoint_weight
from isa_mocap_ros.launcher import NodeSpec, Supervisor, niceness
from isa_mocap_ros.resources import default_bag, resource_dir
from isa_mocap_ros.rosenv import ros_env

NS = "/mocap"
RECORDED = ["/mocap/joint_states", "/mocap/model", "/mocap/estimator/done", "/mocap/root_pose", "/mocap/prediction/joint_states",
            "/diagnostics", "/mocap/cam*/overlay", "/mocap/cam*/mask", "/mocap/cam0/image_raw", "/mocap/markers",
            "/humans/bodies/*/joint_states", "/humans/bodies/*/urdf", "/mocap/cam*/keypoints"]


def register(sub) -> None:
    p = sub.add_parser("run", help="run the node network on a bag, record and evaluate (the main job)")
    add_run_arguments(p)
    p.set_defaults(func=run)


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bag", nargs="?", default=None, help="bag to process (default: the shipped demo bag)")
    p.add_argument("--out", default="out/run", help="output directory (default out/run)")
    p.add_argument("--optimizer", default=None, help="isa, h-isa, apf, psapf, cmaes, h-cmaes, de, h-de, pso, h-pso")
    p.add_argument("--evals", type=int, default=None, help="energy evaluations per frame")
    p.add_argument("--model", type=int, choices=(18, 28, 39), default=None, help="body model DOF")
    p.add_argument("--seed", type=int, default=None, help="seed of the per-frame random streams")
    p.add_argument("--lockstep", action="store_true",
                   help="deterministic: replay frame k+1 only after the estimate of frame k")
    p.add_argument("--rate", type=float, default=1.0, help="real-time playback rate (default 1.0)")
    p.add_argument("--params", default=None, help="parameter file (default: the package's config/pipeline.yaml)")
    p.add_argument("--learn-frames", type=int, default=None,
                   help="frames the segmentation learns the background from (default: the bag's frames before "
                        "its first ground truth (joint states, else markers), else the parameter file's learn_frames)")
    p.add_argument("--overlay-frames", type=int, default=4,
                   help="overlay frames to save as PNG (drawn after the run from the recording)")
    p.add_argument("--helper-nice", type=int, default=5, choices=range(0, 20), metavar="0..19",
                   help="niceness added to every process but the estimator's (player, segmentation, prediction, "
                        "recorder; default 5, 0 = off): on a small machine the tracker's threads then lose "
                        "less time to the helpers (docs/nodes.md)")
    p.add_argument("--keypoints", action=argparse.BooleanOptionalAction, default=None,
                   help="run the keypoint node (BlazePose landmarks on cam<i>/keypoints, recorded) and track with "
                        "them (the estimator's keypoint_weight; docs/keypoints.md). Default: with --lockstep on when "
                        "the landmark model is installed (make models), else off with a note; in real time off (on "
                        "two cores the node made the estimator drop a third of the frame sets: decision 014); "
                        "--no-keypoints: off")
    p.add_argument("--keypoint-weight", type=float, default=DEFAULT_KEYPOINT_WEIGHT, metavar="W",
                   help=f"with keypoints: weight of the keypoint term (default {DEFAULT_KEYPOINT_WEIGHT:g}; 0 = detect "
                        "and record only)")
    p.add_argument("--keypoint-every", type=int, default=None, metavar="K",
                   help="with keypoints: the keypoint node's every_k_frames (default: the parameter file's, 8)")
    p.add_argument("--shape", default="auto", metavar="auto|default|truth|FILE",
                   help="body shape the estimator tracks with: 'auto' (default) calibrates it from the bag's first "
                        "frames before the replay (as isa-mocap calibrate; written to DIR/body.yaml); 'default' = "
                        "config/body/default.yaml; FILE = a body-shape YAML; 'truth' = the bag's ground-truth "
                        "model's (a diagnostic only)")
    p.add_argument("--single-process", action="store_true",
                   help="run segmentation, prediction and estimator (and keypoints) in one process "
                        "on one executor (isa_mocap_ros.cli.compose) instead of one process each; the recorder "
                        "stays apart. Lockstep results are the same (docs/nodes.md)")
    p.add_argument("--quiet", action="store_true", help="do not echo node output")
    from isa_mocap_ros.cli.shape_options import add_calibration_arguments

    add_calibration_arguments(p)


def _keypoints_on(args: argparse.Namespace) -> bool:
    """Whether the network runs the keypoint node: ``--keypoints`` / ``--no-keypoints``, else (None, the default)
    on when the landmark model is installed (:mod:`isa_mocap_ros.cli.keypoint_options`)."""
    on = getattr(args, "keypoints", False)
    return default_keypoint_weight()[0] > 0 if on is None else bool(on)


def _network(args: argparse.Namespace, params: str, out: Path, n_views: int,
             learn_frames: int | None, body_shape: str | None = None, *,
             frame_period_s: float | None = None) -> list[NodeSpec]:
    # the bag's frame period: the prediction node stamps its prediction for frame k + 1 with t_k + period and
    # the estimator matches it to the frame within half a period; the parameter file's 1/30 s on a 60 fps
    # recording made the lockstep estimator miss the prediction (or take the one made a frame earlier)
    period = [("frame_period_s", repr(float(frame_period_s)))] if frame_period_s else []
    est = [*([("body_shape", body_shape)] if body_shape else []), *period,
           ("views", str(n_views)), ("lockstep", "true" if args.lockstep else "false"), ("wait_for_inputs_s", "60.0"),
           # lockstep: wait for every view (a partial set would make results depend on machine load)
           *([("view_timeout_s", "0.0")] if args.lockstep else [])]
    # No publish_overlay: the overlay PNGs are drawn after the run from the recording (run_report), so
    # the estimator neither subscribes to the images nor draws and publishes 4 overlays per frame set.
    for key, val in (("optimizer", args.optimizer), ("evals", args.evals), ("model_dof", args.model),
                     ("seed", args.seed)):
        if val is not None:
            est.append((key, str(val)))
    seg = [("views", str(n_views))] + ([("learn_frames", str(learn_frames))] if learn_frames else [])
    if args.lockstep or getattr(args, "rate", 1.0) != 1.0:
        # late sets are shed by their stamps' age (nodes/segmentation.py late_set_s): never in lockstep (bit for
        # bit the offline tracker), and not at another rate, where the stamps do not advance at wall speed
        seg.append(("late_set_s", "0.0"))
    if args.lockstep:
        # Deterministic runs must not lose a frame: make the image and mask subscriptions reliable
        # (they are best effort, qos_profile_sensor_data, by default).
        # The camera infos too: the nodes take nothing from a view before a camera_info and an image (mask) of
        # one stamp agree on its camera (isa_mocap_ros.intake), so a lost first camera_info would stall a view.
        seg += [(f"qos_overrides.{NS}/cam{v}/{t}.subscription.reliability", "reliable")
                for v in range(n_views) for t in ("image_raw", "camera_info")]
        est += [(f"qos_overrides.{NS}/cam{v}/{t}.subscription.reliability", "reliable")
                for v in range(n_views) for t in ("mask", "camera_info")]
    common = dict(namespace=NS, params_files=(params,))
    nice = getattr(args, "helper_nice", 0)
    kp = []
    if _keypoints_on(args):
        kp_params = [("views", str(n_views))]
        if getattr(args, "keypoint_every", None) is not None:
            kp_params.append(("every_k_frames", str(args.keypoint_every)))
        est.append(("keypoint_weight", repr(float(getattr(args, "keypoint_weight", DEFAULT_KEYPOINT_WEIGHT)))))
        if args.lockstep:     # the estimator's frame sets: no partial ones in lockstep (isa_mocap_ros.keypoint_intake)
            kp_params += [("view_timeout_s", "0.0")]
            kp_params += [(f"qos_overrides.{NS}/cam{v}/{t}.subscription.reliability", "reliable")
                          for v in range(n_views) for t in ("image_raw", "mask", "camera_info")]
        kp = [NodeSpec(exec="keypoints_node", name="keypoints", params=tuple(kp_params), nice=nice, **common)]
    work = kp + [
        NodeSpec(exec="segmentation_node", name="segmentation", params=tuple(seg), nice=nice, **common),
        NodeSpec(exec="prediction_node", name="prediction", params=tuple(period), nice=nice, **common),
        NodeSpec(exec="estimator_node", name="estimator", params=tuple(est), **common),
    ]
    if getattr(args, "single_process", False):
        # one process at the estimator's priority (no niceness: the helpers' share is the tracker's now)
        work = [NodeSpec(exec="compose", name="mocap_nodes",
                         members=tuple(NodeSpec(**{**s.__dict__, "nice": 0}) for s in work))]
    return work + [
        NodeSpec(exec="recorder_node", name="recorder", namespace=NS, nice=nice,
                 params=(("output", str(out / "estimates")), ("overwrite", "true"),
                         ("topics", "[" + ",".join(f"'{t}'" for t in RECORDED) + "]"))),
    ]


def _inspect(bag: Path) -> tuple[int, int | None, float | None]:
    """Views in the bag, how many frames come before its first ground truth (background only), and its
    frame period in seconds (the median step between view 0's image stamps; None with fewer than 2)."""
    import msg_adapters as ma
    with BagReader(bag) as r:
        n = sum(1 for t in r.topics if t.startswith("/mocap/cam") and t.endswith("/image_raw"))
        if n == 0:
            raise SystemExit(f"isa-mocap run: {bag} has no /mocap/cam<i>/image_raw topics")
        stamps = sorted({ma.header_stamp_ns_from_cdr(m.data) for m in r.messages(["/mocap/cam0/image_raw"])})
        period_s = float(np.median(np.diff(stamps))) / 1e9 if len(stamps) > 1 else None
        gt = "/mocap/ground_truth/joint_states"
        if gt not in r.topics:       # a mesh bag or an imported real recording may have markers only
            gt = "/mocap/ground_truth/markers"
        if gt not in r.topics:
            return n, None, period_s
        first_truth = next((ma.header_stamp_ns_from_cdr(m.data) for m in r.messages([gt])), None)
    learn = (sum(1 for s in stamps if s < first_truth) or None) if first_truth is not None else None
    return n, learn, period_s


def _body_shape(args: argparse.Namespace, bag: Path, out: Path, learn: int | None) -> str | None:
    """The estimator's ``body_shape`` file for ``--shape`` (None = its default shape): ``auto`` calibrates
    the shape from the bag's first frames (the images, segmented as the segmentation node does) into
    ``DIR/body.yaml`` before the replay; ``truth`` writes the bag's ground-truth shape (diagnostic)."""
    shape = getattr(args, "shape", "auto") or "auto"
    if shape == "default":
        return None
    if shape not in ("auto", "truth"):
        from isa_mocap_ros.body import BodyError, load_shape
        try:
            load_shape(shape)
        except BodyError as exc:
            raise ValueError(f"--shape: expected auto, default, truth or a body-shape YAML file ({exc})") from None
        return str(Path(shape).resolve())
    from isa_mocap_ros.body import save_shape
    from isa_mocap_ros.cli.track_io import read_sequence

    seq = read_sequence(bag, want_images=True, want_masks=False)
    path = out / "body.yaml"
    if shape == "truth":
        if seq.truth_model is None:
            raise ValueError("--shape truth: expected a ground-truth model in the bag, received none")
        save_shape(dict(seq.truth_model.shape), path)
        return str(path.resolve())
    from isa_mocap_ros.cli.shape_options import calibrate_sequence, save_calibrated_shape
    from isa_mocap_ros.tracking.shape_calibration import ShapeCalibrationError

    n_learn = learn or 10
    calib = argparse.Namespace(seed=args.seed or 0, **{k: getattr(args, k, None)
                                                        for k in ("calib_frames", "calib_rounds", "calib_evals",
                                                                  "calib_restarts", "calib_combine", "calib_judge",
                                                                  "calib_energy", "calib_radius_prior")})
    try:
        res, report = calibrate_sequence(seq, calib, dof=args.model or 39, use_masks=False, learn=n_learn,
                                         first=n_learn, progress=lambda line: print(f"run: {line}", flush=True))
    except ShapeCalibrationError as exc:
        raise ValueError(f"--shape auto: {exc}; pass --shape default or a body-shape FILE") from None
    save_calibrated_shape(res, bag.name, path)
    (out / "shape_calibration.json").write_text(json.dumps(report, indent=2) + "\n")
    print(f"run: calibrated body shape -> {path}", flush=True)
    return str(path.resolve())


def _tail(path: Path, n: int = 25) -> None:
    try:
        lines = path.read_text(errors="replace").splitlines()[-n:]
    except OSError:
        return
    print("\n".join(lines), file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    bag = Path(args.bag) if args.bag else default_bag()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    params = args.params or str(resource_dir("config") / "pipeline.yaml")
    n_views, empty, period_s = _inspect(bag)
    learn = args.learn_frames if args.learn_frames is not None else empty
    env = ros_env(keep_caller_domain=True)
    log = open(out / "nodes.log", "w")
    ready = threading.Event()
    lines_lock = threading.Lock()

    def on_line(line: str) -> None:
        with lines_lock:
            log.write(line + "\n")
            log.flush()
        if "estimator: ready" in line:
            ready.set()
        if not args.quiet and ("[launch]" in line or "WARN" in line or "ERROR" in line or "estimator:" in line):
            print(line, flush=True)

    if getattr(args, "keypoints", None) is None and not args.lockstep:
        # real time: off by default (decision 014: bags/demo, idle 2 cores, 51 of 145 sets dropped with the
        # keypoint node against 5 without); --keypoints turns it on where cores are to spare
        args.keypoints = False
    if getattr(args, "keypoints", None) is None:
        weight, note = default_keypoint_weight()
        args.keypoints = weight > 0
        if note:
            print(f"run: {note}", file=sys.stderr, flush=True)
    try:
        body_shape = _body_shape(args, bag, out, learn)
    except ValueError as exc:
        print(f"isa-mocap run: error: {exc}", file=sys.stderr)
        return 2
    specs = _network(args, params, out, n_views, learn, body_shape, frame_period_s=period_s)
    sup = Supervisor(specs, env=env, out=on_line)
    runner = threading.Thread(target=sup.run, daemon=True)
    print(f"run: {bag} ({n_views} views) -> {out}; ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}", flush=True)
    runner.start()
    t_start = time.monotonic()
    try:
        if not ready.wait(300):
            print(f"run: the estimator did not become ready within 300 s; see {out / 'nodes.log'}", file=sys.stderr)
            _tail(out / "nodes.log")
            return 1
        play = [sys.executable, "-m", "isa_mocap_ros.cli.main", "play", str(bag), "--json",
                "--topics", "/mocap/cam*/image_raw", "/mocap/cam*/camera_info", "/mocap/cam*/extrinsics",
                # the readers may still be finishing discovery when the writers see them matched: settle
                "--wait-for-subscribers", "30", "--delay", "3.0"]
        if args.lockstep:
            play += ["--lockstep", f"{NS}/estimator/done", "--lockstep-type", "std_msgs/msg/Header",
                     "--lockstep-timeout", "30"]
        else:
            play += ["--rate", str(args.rate)]
        import subprocess
        res = subprocess.run(play, env=env, capture_output=True, text=True,
                             preexec_fn=niceness(getattr(args, "helper_nice", 0)))
        on_line(f"[player] {res.stdout.strip()} {res.stderr.strip()}")
        if res.returncode != 0:
            print(f"run: replay failed:\n{res.stderr}", file=sys.stderr)
            _tail(out / "nodes.log")
            return 1
        summary_play = json.loads(res.stdout.strip().splitlines()[-1])
        time.sleep(2.0)  # let the last estimates reach the recorder
    finally:
        sup.stop()
        runner.join(60)
        log.close()
    from isa_mocap_ros.cli.run_report import write_report
    return write_report(bag, out, args=args, play_summary=summary_play,
                        wall_seconds=time.monotonic() - t_start)
