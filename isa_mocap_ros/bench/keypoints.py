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
* ``synth``: capsule renders of the tracking model (flat-shaded, ``isa_mocap_ros.synth``; the
  default 4-camera rig at ``--width`` x ``--height``), generated motions and the CMU walk if present;
  the reference is the exact joint centres projected; the crop is the square around the exact mask.

Reported per kind and per landmark: median and mean pixel error, the error relative to the crop side
(%), and the fraction of left/right swaps (frames where the detected hips+knees+ankles fit the
reference better with left and right exchanged).

A third kind, ``track``, tracks capsule renders (``isa-mocap synth`` with exact masks, 4 views at
320x240, 10 empty frames, ``--track-s`` seconds of each motion, bag seeds ``--seeds``) with
``isa-mocap track``'s code and the automatic initialization, three ways: without the keypoint term, with
it on the initialized frame only, and on that frame and every ``--every``-th frame (weight
``--weight``). Scored per run: mean joint error (Eq. 20), frames tracked facing backwards (estimate's
heading more than 90 degrees from the truth's), leg swaps (frames whose left/right knee and ankle fit
the truth better exchanged), and the detection time per frame set that had keypoints.

A fourth kind, ``init``, isolates the heading decision: every ``--init-every``-th frame of each motion
and seed is rendered (320x240, 4 views) and handed to a fresh tracker as its first frame (the automatic
initialization and the heading candidates' runs), without and with keypoints detected on those images;
scored by the heading error of the result.
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

from isa_mocap_ros.resources import cmu_walk_bvh, shared_data_dir
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
    p.add_argument("--kinds", default="real,synth", help="comma-separated: real, synth, track, init (default real,synth)")
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
    p.add_argument("--every", type=int, default=5, help="track kind: every K-th frame (default 5)")
    p.add_argument("--init-every", type=int, default=15, help="init kind: every K-th frame is a first frame")
    p.add_argument("--configs", default="off,init,every", help="track kind: which of off, init, every to run")
    p.add_argument("--cache", default="out/bench_keypoints", help="track kind: bags and tracking output folder")
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


def _heading(x: np.ndarray) -> float:
    from isa_mocap_ros.geometry import exp_so3
    f = exp_so3(np.asarray(x[3:6], float)) @ [1.0, 0.0, 0.0]
    return float(np.arctan2(f[1], f[0]))


def _track_one(bag: Path, out: Path, *, weight: float, every: int) -> dict:
    from isa_mocap_ros.cli.track import track_bag
    from isa_mocap_ros.eval import marker_positions, shared_markers

    ns = argparse.Namespace(
        bag=str(bag), out=str(out), optimizer="h-isa", evals=1500, params=None, model=None, seed=0, frames=None,
        start=0, use_masks=True, learn_frames=None, shape="truth", init="auto", predictor=None, prior=None,
        prior_eta=0.0, energy="fast", overwrite=True, no_progress=True, keypoint_weight=weight, keypoint_every=every)
    got: dict = {}
    s = track_bag(ns, collect=got)
    model, tm = got["model"], got["truth_model"]
    idx = [k for k in sorted(got["estimates"]) if k in got["truth"]]
    P = np.array([got["estimates"][k] for k in idx])
    T = np.array([got["truth"][k] for k in idx])
    back = sum(abs(np.angle(np.exp(1j * (_heading(p) - _heading(t))))) > np.pi / 2 for p, t in zip(P, T))
    legs = [f"{side}_{j}" for side in ("left", "right") for j in ("knee", "ankle")]
    names = [n for n in shared_markers(model, tm) if n in legs]
    Pe, Pt = marker_positions(model, P, joints=names), marker_positions(tm, T, joints=names)
    swap_idx = [names.index(n.replace("left", "RIGHT").replace("right", "left").replace("RIGHT", "right"))
                for n in names]
    straight = np.linalg.norm(Pe - Pt, axis=2).sum(axis=1)
    swapped = np.linalg.norm(Pe[:, swap_idx] - Pt, axis=2).sum(axis=1)
    return dict(mpjpe_mm=float(s["mpjpe_mm"]), frames=len(idx), backwards=int(back),
                leg_swaps=int(np.sum(swapped < straight)), keypoint_frames=s["keypoint_frames"],
                keypoint_ms_per_frame_set=s["keypoint_ms_per_frame_set"], fps=float(s["fps"]))


def bench_track(args) -> dict:
    from isa_mocap_ros.cli.synth import write_bag

    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    bvh = cmu_walk_bvh()
    motions = [m.strip() for m in args.motions.split(",") if m.strip()]
    seeds = [int(v) for v in args.seeds.split(",") if v.strip()]
    configs = {"off": (0.0, 0), "init": (args.weight, 0), f"every {args.every}": (args.weight, args.every)}
    wanted = [c.strip() for c in getattr(args, "configs", "off,init,every").split(",") if c.strip()]
    configs = {k: v for k, v in configs.items() if k.split()[0] in wanted}
    if args.weight != 1.0:
        configs = {(f"{k} w{args.weight:g}" if v[0] > 0 else k): v for k, v in configs.items()}
    out: dict = {}
    for motion in motions:
        src = str(bvh) if motion == "cmu" else motion
        if motion == "cmu" and not bvh.is_file():
            print(f"bench keypoints: {bvh} not found; skipping cmu", file=sys.stderr)
            continue
        given = Path(motion)
        for seed in ([0] if (given / "metadata.yaml").is_file() else seeds):
            bag = given if (given / "metadata.yaml").is_file() else cache / f"{motion}_s{seed}"
            if not (bag / "metadata.yaml").is_file():
                write_bag(argparse.Namespace(
                    motion=src, out=str(bag), views=None, width=None, height=None, fps=30.0, model=39,
                    start_s=1.0 if motion == "cmu" else 0.0, duration_s=args.track_s, empty_frames=10, noise=0.0,
                    occluders=0, rig=None, seed=seed, bvh_scale=None, masks=True, compression="zstd", chunk_mb=32.0,
                    overwrite=True, no_progress=True))
            for name, (w, k) in configs.items():
                r = _track_one(bag, cache / f"{given.name}_s{seed}_{name.replace(' ', '_')}", weight=w, every=k)
                out.setdefault(name, {})[f"{motion} s{seed}"] = r
                print(f"  {motion} seed {seed} {name:8s} mpjpe {r['mpjpe_mm']:7.1f} mm  backwards {r['backwards']:3d}"
                      f"/{r['frames']}  leg swaps {r['leg_swaps']:3d}  keypoint frames {r['keypoint_frames']:3d}"
                      f"  {r['keypoint_ms_per_frame_set'] or 0:6.1f} ms/set", file=sys.stderr, flush=True)
    return out


def bench_init(args) -> dict:
    """The heading decision of the automatic initialization, with and without keypoints: every
    ``--init-every``-th frame of each motion and bag seed is a first frame (a fresh tracker's first
    ``step``: grid, refinement, the heading candidates' runs); keypoints detected on the rendered
    images, cropped around the exact masks."""
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.synth import SceneRenderer, make_clip
    from isa_mocap_ros.tracking import Tracker, TrackerConfig
    from isa_mocap_ros.vision import default_rig

    det = PoseLandmarker()
    rig = default_rig()
    motions = [m.strip() for m in args.motions.split(",") if m.strip() and not Path(m.strip()).is_dir()]
    seeds = [int(v) for v in args.seeds.split(",") if v.strip()]
    rows = []
    for motion in motions:
        src = cmu_walk_bvh() if motion == "cmu" else motion
        if motion == "cmu" and not Path(src).is_file():
            continue
        for seed in seeds:
            clip = make_clip(src, dof=39, fps=30.0, duration_s=args.track_s, seed=seed,
                             start_s=1.0 if motion == "cmu" else 0.0)
            model = make_model(39, shape=dict(clip.model.shape))
            renderer = SceneRenderer(clip.model, rig, seed=seed)
            for f in range(0, clip.n_frames, args.init_every):
                images, masks = renderer.render(clip.poses[f], f)
                kp = []
                for img, m in zip(images, masks):
                    box = box_from_mask(m)
                    kp.append(None if box is None else (lambda lm: (lm.uv, lm.confidence))(det.detect(img, box)))
                truth = _heading(clip.poses[f])
                row = {"motion": motion, "seed": seed, "frame": f}
                for name, w in (("off", 0.0), ("keypoints", args.weight)):
                    tr = Tracker(model, rig.cameras, TrackerConfig.from_flat(seed=seed, keypoint_weight=w))
                    r = tr.step(masks, f, keypoints=kp if w > 0 else None)
                    row[name] = float(np.rad2deg(abs(np.angle(np.exp(1j * (_heading(r.x) - truth))))))
                rows.append(row)
                print(f"  init {motion} seed {seed} frame {f:3d}: heading error off {row['off']:6.1f} deg, "
                      f"keypoints {row['keypoints']:6.1f} deg", file=sys.stderr, flush=True)
    return {"rows": rows, "weight": args.weight}


def _print_init(res: dict) -> None:
    rows = res["rows"]
    print(f"\n== init (heading of the automatically initialized frame; weight {res['weight']:g}) ==")
    for name in ("off", "keypoints"):
        e = np.array([r[name] for r in rows])
        print(f"{name:10s} frames {len(e):3d}  facing backwards (> 90 deg) {int(np.sum(e > 90)):3d}  "
              f"off by > 45 deg {int(np.sum(e > 45)):3d}  median {np.median(e):5.1f} deg")


def _print_track(res: dict) -> None:
    print("\n== track (capsule renders, automatic initialization) ==")
    print(f"{'config':14s} {'runs':>4s} {'mpjpe mm':>9s} {'runs backwards':>14s} {'backwards frames':>16s} "
          f"{'leg swaps':>9s} {'ms/set (kp frames)':>18s}")
    for name, runs in res.items():
        r = list(runs.values())
        ms = [x["keypoint_ms_per_frame_set"] for x in r if x["keypoint_ms_per_frame_set"]]
        print(f"{name:14s} {len(r):4d} {np.mean([x['mpjpe_mm'] for x in r]):9.1f} "
              f"{sum(x['backwards'] > 0 for x in r):14d} {sum(x['backwards'] for x in r):16d} "
              f"{sum(x['leg_swaps'] for x in r):9d} {np.mean(ms) if ms else 0:18.1f}")


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
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    bad = [k for k in kinds if k not in ("real", "synth", "track", "init")]
    if bad or args.step < 1:
        print(f"isa-mocap bench keypoints: error: --kinds {bad} / --step {args.step}: expected real, synth and "
              "a step >= 1", file=sys.stderr)
        return 2
    results: dict = {}
    if "track" in kinds:
        results["track"] = bench_track(args)
    if "init" in kinds:
        results["init"] = bench_init(args)
    det = PoseLandmarker() if {"real", "synth"} & set(kinds) else None
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
    if args.json:
        print(json.dumps(results, indent=1))
    else:
        for kind, res in results.items():
            {"track": _print_track, "init": _print_init}.get(kind, lambda r: _print(kind, r))(res)
    return 0
