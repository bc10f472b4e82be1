"""2-D keypoint detector accuracy: BlazePose landmarks against projected reference points, per sequence kind.

Two kinds of sequence (docs/keypoints.md):

* ``real``: the Pose2Sim demo (``../shared/data/real/pose2sim_demo``): ``balancing/cam0*.mp4``
  decoded with OpenCV, every ``--step``-th frame. The reference is the peer's 3-D keypoints
  (``reference/balancing_pose2sim.trc``, y-up, mapped to the calibration's z-up world as
  ``(X, Y, Z)_world = (Z, X, Y)_trc``) projected with ``calibration/Calib_scene_checkerboard.toml``
  (Rodrigues, metres, world to camera; intrinsics scaled to the 1080-wide letterboxed videos). The
  crop is the square around those projected points (``box_from_points``); so the box is generous and
  the error includes the peer's own error and its keypoint definitions (not anatomical joint centres).
  Two crops: upright, and turned so the reference's hip-to-shoulder direction points up
  (``upright_angle``, as a predicted pose would give).
* ``mesh``: skinned-mesh renders (the three subjects, generated walk, jog, wave; flat-shaded triangles, not
  real images), against the mesh skeleton's joint centres projected; crop around the exact mask;
* ``synth``: capsule renders of the tracking model (flat-shaded, ``isa_mocap_ros.synth``; the
  default 4-camera rig at ``--width`` x ``--height``), generated motions and the CMU walk if present;
  the reference is the exact joint centres projected; the crop is the square around the exact mask.

Reported per kind and per landmark: median and mean pixel error, the error relative to the crop side
(%), and the fraction of left/right swaps (frames where the detected hips+knees+ankles fit the
reference better with left and right exchanged).

A fifth kind, ``cost``, measures the detector's CPU time on a bag (``--cost-bag``, default the shipped
mesh demo): per detection (crop + model, ``time.thread_time``: the CPU time of the calling thread, so
other processes on a loaded machine inflate it much less than wall time; cache and SMT sharing still
do), on the frames the keypoint node's schedule picks (the dense start, then every ``--every``-th frame
with a person of each view, exact crop from the recorded mask or the segmented image), and from those the
average CPU time per frame set at that rate.

The tracking kinds (``track``, ``init``, ``peer``) are in :mod:`isa_mocap_ros.bench.keypoints_tracking`.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib
from pathlib import Path

import cv2
import numpy as np

from isa_mocap_ros.bench._common import comma_list
from isa_mocap_ros.bench.keypoints_tracking import (bench_init, bench_peer, bench_track, print_init,
                                                   print_track)
from isa_mocap_ros.resources import cmu_walk_bvh, shared_data_dir
from isa_mocap_ros.vision.keypoint_schedule import EVERY_K
from isa_mocap_ros.vision.landmarks import LANDMARK_NAMES, PoseLandmarker, box_from_mask, box_from_points, upright_angle

_REAL = shared_data_dir() / "real" / "pose2sim_demo"
# Pose2Sim TRC keypoint -> BlazePose landmark
_TRC_TO_LM = {"RShoulder": "right_shoulder", "LShoulder": "left_shoulder", "RElbow": "right_elbow",
              "LElbow": "left_elbow", "RWrist": "right_wrist", "LWrist": "left_wrist", "RHip": "right_hip",
              "LHip": "left_hip", "RKnee": "right_knee", "LKnee": "left_knee", "RAnkle": "right_ankle",
              "LAnkle": "left_ankle", "RHeel": "right_heel", "LHeel": "left_heel", "Nose": "nose"}
# model joint -> BlazePose landmark (synthetic ground truth)
_JOINT_TO_LM = {"left_shoulder": "left_shoulder", "right_shoulder": "right_shoulder", "left_elbow": "left_elbow",
                "right_elbow": "right_elbow", "left_wrist": "left_wrist", "right_wrist": "right_wrist",
                "left_hip": "left_hip", "right_hip": "right_hip", "left_knee": "left_knee",
                "right_knee": "right_knee", "left_ankle": "left_ankle", "right_ankle": "right_ankle"}
_LEGS = ("hip", "knee", "ankle")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--kinds", default="real,synth", help="comma-separated: real, synth, mesh, track, init, cost, peer (default real,synth)")
    p.add_argument("--step", type=int, default=5, help="every STEP-th frame (default 5)")
    p.add_argument("--data", default=str(_REAL), help="the Pose2Sim demo folder")
    p.add_argument("--width", type=int, default=640, help="synthetic image width (default 640)")
    p.add_argument("--height", type=int, default=480, help="synthetic image height (default 480)")
    p.add_argument("--synth-s", type=float, default=4.0, help="seconds of each synthetic motion (default 4)")
    p.add_argument("--motions", default="walk,jog,walk_turns,wave,box,cmu",
                   help="track kind: generated motions, 'cmu' (the CMU walk BVH, if present) and/or bag folders "
                        "with masks and ground truth (e.g. bags/demo; tracked once, not per seed)")
    p.add_argument("--seeds", default="0,1,2", help="track kind: bag seeds (default 0,1,2)")
    p.add_argument("--track-s", type=float, default=3.0, help="track kind: seconds of each motion (default 3)")
    p.add_argument("--weight", type=float, default=1.0, help="track kind: keypoint weight (default 1)")
    p.add_argument("--every", type=int, default=EVERY_K, help="track, cost, peer kinds: after the dense start, every "
                   f"K-th frame with a person (default {EVERY_K}, the keypoint node's)")
    p.add_argument("--body", choices=("capsules", "mesh"), default="capsules",
                   help="track kind: render the generated motions as capsules (the control, default) or meshes")
    p.add_argument("--subjects", default="slim_woman,average_man,heavy_man",
                   help="track kind with --body mesh: mesh subjects (default all three)")
    p.add_argument("--shape", default="truth", choices=("truth", "auto", "default"),
                   help="track kind: the tracker's body shape (default truth: the bag's ground-truth model's)")
    p.add_argument("--init-every", type=int, default=15, help="init kind: every K-th frame is a first frame")
    p.add_argument("--configs", default="off,start,every", help="track kind: which of off, start (the dense start "
                   "only), every to run")
    p.add_argument("--cache", default="out/bench_keypoints", help="track kind: bags and tracking output folder")
    p.add_argument("--bvh-scale", type=float, default=None, help="track kind: metres per unit of BVH files given "
                   "in --motions (the CMU clips of data/mocap/cmu: 0.056444)")
    p.add_argument("--peer-bag", default=None, help="peer kind: an imported real recording with reference markers")
    p.add_argument("--cost-bag", default=None, help="cost kind: bag to time the detector on (default: the shipped "
                   "demo bag)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")


# ------------------------------------------------------------------ minimal Pose2Sim readers
def read_pose2sim_toml(path: Path) -> list[dict]:
    """Cameras of a Pose2Sim/anipose TOML: ``[{name, size, K, dist, rvec, tvec}]`` (world to camera, metres)."""
    data = tomllib.loads(Path(path).read_text())
    cams = []
    for name, c in data.items():
        if name == "metadata":
            continue
        cams.append(dict(name=name, size=tuple(int(v) for v in c["size"]), K=np.array(c["matrix"], float),
                         dist=np.array(c["distortions"], float), rvec=np.array(c["rotation"], float),
                         tvec=np.array(c["translation"], float)))
    return cams


def read_trc(path: Path) -> tuple[list[str], np.ndarray]:
    """Marker names and ``(frames, markers, 3)`` positions of a TRC file (its own axes and units)."""
    lines = Path(path).read_text().splitlines()
    names = [n for n in lines[3].split("\t")[2:] if n.strip()]
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    P = np.array([[float(v) for v in r[2:2 + 3 * len(names)]] for r in rows])
    return names, P.reshape(len(rows), len(names), 3)


def _video_K(cam: dict, width: int, height: int) -> np.ndarray:
    """Intrinsics for a video of ``width`` x ``height``: the native sensor image scaled to the width and
    letterboxed vertically (the 1080-wide files of the demo)."""
    K = cam["K"].copy()
    w0, h0 = cam["size"]
    if width != w0:
        s = width / w0
        K[:2] *= s
        K[1, 2] += (height - h0 * s) / 2.0
    return K


# ------------------------------------------------------------------ scoring
def _swapped(det: np.ndarray, ref: np.ndarray, names: list[str]) -> bool:
    """Do detected legs fit the reference better with left and right exchanged?"""
    straight = swap = 0.0
    for part in _LEGS:
        li, ri = names.index(f"left_{part}"), names.index(f"right_{part}")
        straight += np.linalg.norm(det[li] - ref[li]) + np.linalg.norm(det[ri] - ref[ri])
        swap += np.linalg.norm(det[li] - ref[ri]) + np.linalg.norm(det[ri] - ref[li])
    return bool(swap < straight)


class _Tally:
    def __init__(self, names: list[str]):
        self.names = names
        self.err: list[np.ndarray] = []
        self.rel: list[np.ndarray] = []
        self.swaps = 0
        self.n = 0
        self.scores: list[float] = []
        self.ms: list[float] = []

    def add(self, det, ref, side: float, score: float, ms: float) -> None:
        e = np.linalg.norm(det - ref, axis=1)
        self.err.append(e)
        self.rel.append(100.0 * e / side)
        self.swaps += _swapped(det, ref, self.names)
        self.n += 1
        self.scores.append(score)
        self.ms.append(ms)

    def summary(self) -> dict:
        E, R = np.array(self.err), np.array(self.rel)
        return dict(views=self.n, left_right_swaps=self.swaps, median_score=float(np.median(self.scores)),
                    median_px=float(np.median(E)), mean_px=float(E.mean()), median_pct_of_box=float(np.median(R)),
                    ms_per_view_median=float(np.median(self.ms)),
                    per_landmark={n: dict(median_px=float(np.median(E[:, i])), mean_px=float(E[:, i].mean()),
                                          median_pct=float(np.median(R[:, i])))
                                  for i, n in enumerate(self.names)})


def _detect(det: PoseLandmarker, img, box, *, bgr: bool):
    t0 = time.perf_counter()
    lm = det.detect(img, box, bgr=bgr)
    return lm, (time.perf_counter() - t0) * 1e3


def bench_real(det: PoseLandmarker, root: Path, step: int, *, aligned: bool) -> dict:
    cams = read_pose2sim_toml(root / "calibration" / "Calib_scene_checkerboard.toml")
    trc_names, P = read_trc(root / "reference" / "balancing_pose2sim.trc")
    W = P[:, :, [2, 0, 1]]                                        # TRC y-up -> world z-up
    names = [_TRC_TO_LM[n] for n in trc_names if n in _TRC_TO_LM]
    ti = [trc_names.index(n) for n in trc_names if n in _TRC_TO_LM]
    li = [LANDMARK_NAMES.index(n) for n in names]
    out = {}
    for v, cam in enumerate(cams):
        video = root / "balancing" / f"cam0{v + 1}.mp4"
        cap = cv2.VideoCapture(str(video))
        tally = _Tally(names)
        k = 0
        while True:
            ok, img = cap.read()
            if not ok or k >= len(W):
                break
            if k % step == 0:
                K = _video_K(cam, img.shape[1], img.shape[0])
                ref = cv2.projectPoints(W[k], cam["rvec"], cam["tvec"], K, cam["dist"])[0].reshape(-1, 2)
                angle = 0.0
                if aligned:
                    hips = ref[[trc_names.index("RHip"), trc_names.index("LHip")]].mean(axis=0)
                    sh = ref[[trc_names.index("RShoulder"), trc_names.index("LShoulder")]].mean(axis=0)
                    angle = upright_angle(hips, sh)
                box = box_from_points(ref, angle_rad=angle)
                lm, ms = _detect(det, img, box, bgr=True)
                tally.add(lm.uv[li], ref[ti], box[2], lm.score, ms)
            k += 1
        cap.release()
        out[f"cam0{v + 1}"] = tally.summary()
    return out


def bench_synth_mesh(det: PoseLandmarker, width: int, height: int, step: int, seconds: float,
                     subjects: list[str]) -> dict:
    """The detector on skinned-mesh renders (flat-shaded triangles, ``MeshSceneRenderer``; the default 4-camera
    rig): per subject and motion, against the mesh skeleton's joint centres projected; crop around the exact
    mask."""
    from isa_mocap_ros.body.mesh import MESH_MARKERS
    from isa_mocap_ros.synth import MeshSceneRenderer, make_clip
    from isa_mocap_ros.vision import default_rig

    rig = default_rig(width=width, height=height)
    names = list(_JOINT_TO_LM.values())
    li = [LANDMARK_NAMES.index(n) for n in names]
    mi = [MESH_MARKERS.index(j) for j in _JOINT_TO_LM]
    out = {}
    for subject in subjects:
        for motion in ("walk", "jog", "wave"):
            clip = make_clip(motion, dof=39, fps=30.0, duration_s=seconds, seed=0, body="mesh", subject=subject)
            renderer = MeshSceneRenderer(clip, rig, seed=0)
            tally = _Tally(names)
            for f in range(0, clip.n_frames, step):
                images, masks = renderer.render(f, f)
                J = renderer.posed(f)[1]
                for cam, img, mask in zip(rig.cameras, images, masks):
                    box = box_from_mask(mask)
                    if box is None:
                        continue
                    lm, ms = _detect(det, img, box, bgr=False)
                    tally.add(lm.uv[li], cam.project(J[mi]), box[2], lm.score, ms)
            out[f"mesh {subject} {motion}"] = tally.summary()
    return out


def bench_synth(det: PoseLandmarker, width: int, height: int, step: int, seconds: float) -> dict:
    from isa_mocap_ros.body import joint_positions
    from isa_mocap_ros.synth import SceneRenderer, make_clip
    from isa_mocap_ros.vision import default_rig

    rig = default_rig(width=width, height=height)
    motions: list[tuple[str, str | Path]] = [(m, m) for m in ("walk", "jog", "wave", "box")]
    bvh = cmu_walk_bvh()
    if bvh.is_file():
        motions.append(("cmu_131_01_walk", bvh))
    names = list(_JOINT_TO_LM.values())
    li = [LANDMARK_NAMES.index(n) for n in names]
    out = {}
    for label, motion in motions:
        clip = make_clip(motion, dof=39, fps=30.0, duration_s=seconds, seed=0)
        model = clip.model
        ji = [model.joint_names.index(j) for j in _JOINT_TO_LM]
        renderer = SceneRenderer(model, rig, seed=0)
        J = joint_positions(model, clip.poses)
        tally = _Tally(names)
        for f in range(0, clip.n_frames, step):
            images, masks = renderer.render(clip.poses[f], f)
            for cam, img, mask in zip(rig.cameras, images, masks):
                box = box_from_mask(mask)
                if box is None:
                    continue
                ref = cam.project(J[f, ji])
                lm, ms = _detect(det, img, box, bgr=False)
                tally.add(lm.uv[li], ref, box[2], lm.score, ms)
        out[label] = tally.summary()
    return out


#: Rates the cost kind reports beside ``--every`` (after the dense start, every K-th frame with a person)
COST_RATES = (4, 6, 8, 10)


def bench_cost(args) -> dict:
    """CPU time of the detector per detection and per frame set at the keypoint node's rate (module docstring).

    One pass: every frame with a person of each view that the schedule of ``--every`` or of a rate in
    :data:`COST_RATES` picks is detected on once and timed; a rate's CPU per frame set is the sum over the
    frames its schedule picks, divided by the frame sets (so the rates share their timings).
    ``args.frames`` (optional): only the first frame sets after the background learning."""
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.resources import default_bag
    from isa_mocap_ros.vision.keypoint_schedule import DENSE_FRAMES, KeypointSchedule, detect_in_mask
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    bag = Path(args.cost_bag) if args.cost_bag else default_bag()
    seq = read_sequence(bag, want_images=True, want_masks=True)
    det = PoseLandmarker()
    learn = seq.empty_frames or 10
    segs = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn)) for _ in seq.cameras]
    rates = sorted(set(COST_RATES) | {int(args.every)})
    schedules = {k: [KeypointSchedule(k, dense_frames=DENSE_FRAMES) for _ in seq.cameras] for k in rates}
    picked: dict[int, list[float]] = {k: [] for k in rates}
    cpu_ms, wall_ms, invoke_ms = [], [], []
    sets = 0
    limit = getattr(args, "frames", None)
    for fr in seq.frames:
        recorded = bool(fr.masks) and all(m is not None for m in fr.masks)
        masks = list(fr.masks) if recorded else [seg.apply(img) for seg, img in zip(segs, fr.images)]
        if fr.index < learn and not recorded:
            continue
        if limit is not None and sets >= limit:
            break
        sets += 1
        for v, (img, m) in enumerate(zip(fr.images, masks)):
            person = bool(np.any(m))
            due = [k for k in rates if schedules[k][v].due(person)]
            if not due:
                continue
            c0, w0 = time.thread_time(), time.perf_counter()
            detect_in_mask(det, img, m)
            cpu_ms.append((time.thread_time() - c0) * 1e3)
            wall_ms.append((time.perf_counter() - w0) * 1e3)
            for k in due:
                picked[k].append(cpu_ms[-1])
    # the model alone (no crop), on one fixed input, 50 times
    x = np.zeros((256, 256, 3), np.float32)
    for _ in range(50):
        c0 = time.thread_time()
        det.run_model(x)
        invoke_ms.append((time.thread_time() - c0) * 1e3)
    c = np.array(picked[int(args.every)])
    per_rate = {str(k): dict(detections=len(picked[k]), detections_per_set=len(picked[k]) / max(sets, 1),
                             cpu_ms_per_frame_set=float(np.sum(picked[k]) / max(sets, 1))) for k in rates}
    return dict(bag=str(bag), frame_sets=sets, detections=len(c), every_k=args.every, dense_frames=DENSE_FRAMES,
                detections_per_set=len(c) / max(sets, 1), cpu_ms_per_detection_mean=float(c.mean()),
                cpu_ms_per_detection_median=float(np.median(c)), wall_ms_per_detection_median=float(np.median(wall_ms)),
                cpu_ms_per_invoke_median=float(np.median(invoke_ms)),
                cpu_ms_per_frame_set=float(c.sum() / max(sets, 1)), rates=per_rate,
                cpu_ms_per_detection_all_median=float(np.median(cpu_ms)))


def _print_cost(res: dict) -> None:
    print("\n== cost (detector CPU time, time.thread_time) ==")
    print(f"{res['bag']}: {res['frame_sets']} frame sets, {res['detections']} detections at the schedule (dense "
          f"{res['dense_frames']}, then every {res['every_k']}): {res['detections_per_set']:.2f} per set; "
          f"CPU per detection {res['cpu_ms_per_detection_median']:.1f} ms median / {res['cpu_ms_per_detection_mean']:.1f} "
          f"mean (wall {res['wall_ms_per_detection_median']:.1f} median), model invoke alone "
          f"{res['cpu_ms_per_invoke_median']:.1f} ms; CPU per frame set {res['cpu_ms_per_frame_set']:.1f} ms on average")
    for k, r in res.get("rates", {}).items():
        print(f"  every {k:>2s}: {r['detections']:4d} detections, {r['detections_per_set']:.2f} per set, "
              f"{r['cpu_ms_per_frame_set']:.1f} ms CPU per frame set")


def _print(kind: str, res: dict) -> None:
    print(f"\n== {kind} ==")
    print(f"{'sequence':18s} {'views':>5s} {'score':>6s} {'med px':>7s} {'mean px':>8s} {'med %box':>8s} "
          f"{'L/R swaps':>9s} {'ms/view':>7s}")
    for seq, s in res.items():
        print(f"{seq:18s} {s['views']:5d} {s['median_score']:6.3f} {s['median_px']:7.1f} {s['mean_px']:8.1f} "
              f"{s['median_pct_of_box']:8.2f} {s['left_right_swaps']:9d} {s['ms_per_view_median']:7.1f}")
    first = next(iter(res.values()))["per_landmark"]
    print("per landmark, median px per sequence:")
    print(f"{'landmark':16s} " + " ".join(f"{s[:10]:>10s}" for s in res))
    for n in first:
        print(f"{n:16s} " + " ".join(f"{res[s]['per_landmark'][n]['median_px']:10.1f}" for s in res))


def run(args: argparse.Namespace) -> int:
    kinds = list(comma_list(args.kinds))
    bad = [k for k in kinds if k not in ("real", "synth", "mesh", "track", "init", "cost", "peer")]
    if bad or args.step < 1:
        print(f"isa-mocap bench keypoints: error: --kinds {bad} / --step {args.step}: expected real, synth and "
              "a step >= 1", file=sys.stderr)
        return 2
    results: dict = {}
    if "track" in kinds:
        results["track"] = bench_track(args)
    if "init" in kinds:
        results["init"] = bench_init(args)
    if "cost" in kinds:
        results["cost"] = bench_cost(args)
    if "peer" in kinds:
        results["peer"] = bench_peer(args)
    det = PoseLandmarker() if {"real", "synth", "mesh"} & set(kinds) else None
    if "real" in kinds:
        root = Path(args.data)
        if not (root / "balancing").is_dir():
            print(f"isa-mocap bench keypoints: {root}/balancing not found; skipping the real recording",
                  file=sys.stderr)
        else:
            results["real upright crop"] = bench_real(det, root, args.step, aligned=False)
            results["real aligned crop"] = bench_real(det, root, args.step, aligned=True)
    if "synth" in kinds:
        results["synth"] = bench_synth(det, args.width, args.height, args.step, args.synth_s)
    if "mesh" in kinds:
        results["mesh renders"] = bench_synth_mesh(det, args.width, args.height, args.step, args.synth_s,
                                                   list(comma_list(args.subjects)))
    if args.json:
        print(json.dumps(results, indent=1))
    else:
        for kind, res in results.items():
            {"track": print_track, "init": print_init, "cost": _print_cost,
             "peer": lambda r: print("\n== peer ==\n" + "\n".join(f"{k}: {v}" for k, v in r.items()))}.get(
                kind, lambda r: _print(kind, r))(res)
    return 0
