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

from isa_mocap_ros.vision.landmarks import LANDMARK_NAMES, PoseLandmarker, box_from_mask, box_from_points, upright_angle

_REAL = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real" / "pose2sim_demo"
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
    p.add_argument("--kinds", default="real,synth", help="comma-separated: real, synth (default both)")
    p.add_argument("--step", type=int, default=5, help="every STEP-th frame (default 5)")
    p.add_argument("--data", default=str(_REAL), help="the Pose2Sim demo folder")
    p.add_argument("--width", type=int, default=640, help="synthetic image width (default 640)")
    p.add_argument("--height", type=int, default=480, help="synthetic image height (default 480)")
    p.add_argument("--synth-s", type=float, default=4.0, help="seconds of each synthetic motion (default 4)")
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
    bvh = _REAL.parents[1] / "mocap" / "cmu_131_01_walk.bvh"
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
    bad = [k for k in kinds if k not in ("real", "synth")]
    if bad or args.step < 1:
        print(f"isa-mocap bench keypoints: error: --kinds {bad} / --step {args.step}: expected real, synth and "
              "a step >= 1", file=sys.stderr)
        return 2
    det = PoseLandmarker()
    results: dict = {}
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
            _print(kind, res)
    return 0
