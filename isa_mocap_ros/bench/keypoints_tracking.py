"""Keypoint benchmark, the kinds that track (``isa-mocap bench keypoints --kinds track,init,peer``).

The ``track`` kind tracks capsule renders (``isa-mocap synth`` with exact masks, 4 views at
320x240, 10 empty frames, ``--track-s`` seconds of each motion, bag seeds ``--seeds``) with
``isa-mocap track``'s code and the automatic initialization (tracker seed = bag seed), three ways: without the keypoint term, with
it on the initialized frame only, and on that frame and every ``--every``-th frame (weight
``--weight``). Scored per run: mean joint error (Eq. 20), frames tracked facing backwards (estimate's
heading more than 90 degrees from the truth's), leg swaps (frames whose left/right knee and ankle fit
the truth better exchanged), and the detection time per frame set that had keypoints.

The ``peer`` kind tracks an imported real recording with reference markers (``--peer-bag``, made by
``isa-mocap import ... --reference FILE.trc``) without and with the term (``isa-mocap track``'s defaults:
automatic shape and initialization, segmented images; a run folder in ``--cache`` that holds a
``summary.json`` is scored as it is) and scores the estimates against the peer's 3-D keypoints *here* (the
project's scorer for the reference topic is issue 34's): per frame, the mean distance of our 12 limb joint
centres (shoulders, elbows, wrists, hips, knees, ankles) from the peer's keypoints of the same names
(:data:`_TRC_TO_JOINT`; a peer's keypoints are not joint centres, so the figure has a floor), the frames facing
backwards (our left-to-right hip direction more than 90 degrees, in the ground plane, from the peer's) and the
leg swaps (our left knee and ankle closer to the peer's right ones, summed over both legs).

The ``init`` kind isolates the heading decision: every ``--init-every``-th frame of each motion
and seed is rendered (320x240, 4 views) and handed to a fresh tracker as its first frame (the automatic
initialization and the heading candidates' runs), without and with keypoints detected on those images;
scored by the heading error of the result.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from isa_mocap_ros.bench._common import comma_list
from isa_mocap_ros.resources import cmu_walk_bvh
from isa_mocap_ros.vision.landmarks import PoseLandmarker, box_from_mask

# Pose2Sim TRC keypoint -> our joint (the peer kind)
_TRC_TO_JOINT = {"RShoulder": "right_shoulder", "LShoulder": "left_shoulder", "RElbow": "right_elbow",
                 "LElbow": "left_elbow", "RWrist": "right_wrist", "LWrist": "left_wrist", "RHip": "right_hip",
                 "LHip": "left_hip", "RKnee": "right_knee", "LKnee": "left_knee", "RAnkle": "right_ankle",
                 "LAnkle": "left_ankle"}


def peer_scores(bag: Path, run_dir: Path) -> dict:
    """Our estimates in ``run_dir/estimates`` against the peer's keypoints in ``bag`` (the peer kind)."""
    from isa_mocap_ros.body import joint_positions
    from isa_mocap_ros.cli.run_report import published_model, read_estimates

    import yaml

    import msg_adapters as ma
    from isa_mocap_ros.bag import BagReader

    # the import's reference (isa-mocap import --reference): names in the latched YAML, points per frame
    marker_names: list[str] = []
    markers: dict[int, np.ndarray] = {}
    with BagReader(bag) as r:
        for m in r.messages(["/mocap/ground_truth/reference", "/mocap/ground_truth/markers"]):
            msg = ma.from_cdr(m.data, m.type)
            if m.topic.endswith("/reference"):
                marker_names = list(yaml.safe_load(msg.data)["marker_names"])
            else:
                markers[ma.stamp_to_ns(msg.header)] = np.array([(p.position.x, p.position.y, p.position.z)
                                                                for p in msg.poses])
    model = published_model(run_dir / "estimates")
    est = read_estimates(run_dir / "estimates", model)["poses"]
    names = [n for n in _TRC_TO_JOINT if n in marker_names]
    mi = [marker_names.index(n) for n in names]
    ji = [model.joint_names.index(_TRC_TO_JOINT[n]) for n in names]
    err, back, swaps = [], 0, 0
    for stamp in sorted(markers):
        if stamp not in est:
            continue
        P = joint_positions(model, np.asarray(est[stamp])[None])[0][ji]
        R = markers[stamp][mi]
        ok = np.all(np.isfinite(R), axis=1)
        err.append(float(np.linalg.norm(P[ok] - R[ok], axis=1).mean() * 1e3))
        k = {n: i for i, n in enumerate(names)}
        hp, hr = P[k["LHip"]] - P[k["RHip"]], R[k["LHip"]] - R[k["RHip"]]
        back += bool(hp[:2] @ hr[:2] < 0)
        straight = sum(np.linalg.norm(P[k[s + j]] - R[k[s + j]]) for s in "LR" for j in ("Knee", "Ankle"))
        crossed = sum(np.linalg.norm(P[k[s + j]] - R[k[o + j]]) for s, o in ("LR", "RL") for j in ("Knee", "Ankle"))
        swaps += bool(crossed < straight)
    e = np.array(err)
    return dict(frames=len(e), mean_mm=float(e.mean()), median_mm=float(np.median(e)), max_mm=float(e.max()),
                backwards=back, leg_swaps=swaps, markers=names)


def bench_peer(args) -> dict:
    from isa_mocap_ros.cli.track import track_bag

    if not args.peer_bag:
        raise SystemExit("isa-mocap bench keypoints: --kinds peer needs --peer-bag BAG (isa-mocap import ... --reference)")
    bag = Path(args.peer_bag)
    out = {}
    for name, w in (("off", 0.0), (f"every {args.every}", args.weight)):
        run_dir = Path(args.cache) / f"{bag.name}_{name.replace(' ', '_')}"
        if not (run_dir / "summary.json").is_file():
            track_bag(argparse.Namespace(
                bag=str(bag), out=str(run_dir), optimizer="h-isa", evals=1500, params=None, model=None, seed=0,
                frames=None, start=0, use_masks=False, learn_frames=None, shape="auto", init="auto", predictor=None,
                prior=None, prior_eta=0.0, energy=None, overwrite=True, no_progress=True, keypoint_weight=w,
                keypoint_every=args.every, calib_frames=None, calib_rounds=None, calib_evals=None))
        out[name] = peer_scores(bag, run_dir)
        print(f"  peer {bag.name} {name}: {out[name]}", file=sys.stderr, flush=True)
    return out


def _heading(x: np.ndarray) -> float:
    from isa_mocap_ros.geometry import exp_so3
    f = exp_so3(np.asarray(x[3:6], float)) @ [1.0, 0.0, 0.0]
    return float(np.arctan2(f[1], f[0]))


def _track_one(bag: Path, out: Path, *, weight: float, every: int, shape: str = "truth", seed: int = 0) -> dict:
    """``isa-mocap track`` of one bag (h-isa 1500, exact masks, automatic initialization) and its scores:
    mean joint error (Eq. 20), frames facing backwards (torso heading more than 90 degrees from the truth's;
    the run is *backwards* when most frames are), leg-swap frames (the estimated left knee and ankle lie
    closer to the true right ones than to the true left ones, summed over both legs)."""
    from isa_mocap_ros.cli.track import track_bag
    from isa_mocap_ros.eval import marker_positions, shared_markers

    ns = argparse.Namespace(
        bag=str(bag), out=str(out), optimizer="h-isa", evals=1500, params=None, model=None, seed=seed, frames=None,
        start=0, use_masks=True, learn_frames=None, shape=shape, init="auto", predictor=None, prior=None,
        prior_eta=0.0, energy=None, overwrite=True, no_progress=True, keypoint_weight=weight, keypoint_every=every,
        calib_frames=None, calib_rounds=None, calib_evals=None)
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
                backwards_run=bool(back > len(idx) / 2), leg_swaps=int(np.sum(swapped < straight)),
                keypoint_frames=s["keypoint_frames"], keypoint_detections=s.get("keypoint_detections", 0),
                keypoint_ms_per_frame_set=s["keypoint_ms_per_frame_set"], fps=float(s["fps"]))


def bench_track(args) -> dict:
    from isa_mocap_ros.cli.synth import write_bag

    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    bvh = cmu_walk_bvh()
    motions = list(comma_list(args.motions))
    seeds = [int(v) for v in comma_list(args.seeds)]
    configs = {"off": (0.0, 0), "start": (args.weight, 0), f"every {args.every}": (args.weight, args.every)}
    wanted = comma_list(getattr(args, "configs", "off,start,every"))
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
        mname = given.stem if motion.endswith(".bvh") else motion      # a BVH file's name labels its runs
        body = getattr(args, "body", "capsules")
        subjects = (list(comma_list(args.subjects)) if body == "mesh"
                    and not (given / "metadata.yaml").is_file() else [None])
        for subject, seed in [(su, se) for su in subjects
                              for se in ([0] if (given / "metadata.yaml").is_file() else seeds)]:
            label = mname + (f" {subject}" if subject else "")
            bag = given if (given / "metadata.yaml").is_file() else \
                cache / (f"{mname}_s{seed}" + (f"_mesh_{subject}" if subject else "_capsules"))
            if not (bag / "metadata.yaml").is_file():
                write_bag(argparse.Namespace(
                    motion=src, out=str(bag), views=None, width=None, height=None, fps=30.0, model=39,
                    start_s=1.0 if motion == "cmu" or motion.endswith(".bvh") else 0.0, duration_s=args.track_s, empty_frames=10, noise=0.0,
                    occluders=0, rig=None, seed=seed, bvh_scale=args.bvh_scale if motion.endswith(".bvh") else None, masks=True,
                    compression="zstd", chunk_mb=32.0, overwrite=True, no_progress=True, body=body, subject=subject or "average_man", skirt=False))
            for name, (w, k) in configs.items():
                r = _track_one(bag, cache / f"{bag.name}_{name.replace(' ', '_')}", weight=w, every=k,
                               shape=getattr(args, "shape", "truth"), seed=seed)
                out.setdefault(name, {})[f"{label} s{seed}"] = r
                print(f"  {label} seed {seed} {name:8s} mpjpe {r['mpjpe_mm']:7.1f} mm  backwards {r['backwards']:3d}"
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
    motions = [m for m in comma_list(args.motions) if not Path(m).is_dir()]
    seeds = [int(v) for v in comma_list(args.seeds)]
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


def print_init(res: dict) -> None:
    rows = res["rows"]
    print(f"\n== init (heading of the automatically initialized frame; weight {res['weight']:g}) ==")
    for name in ("off", "keypoints"):
        e = np.array([r[name] for r in rows])
        print(f"{name:10s} frames {len(e):3d}  facing backwards (> 90 deg) {int(np.sum(e > 90)):3d}  "
              f"off by > 45 deg {int(np.sum(e > 45)):3d}  median {np.median(e):5.1f} deg")


def print_track(res: dict) -> None:
    print("\n== track (automatic initialization) ==")
    print(f"{'config':14s} {'runs':>4s} {'mpjpe mm':>9s} {'backwards runs':>14s} {'runs w/ bw frames':>17s} "
          f"{'backwards frames':>16s} {'leg swaps':>9s} {'ms/set (kp frames)':>18s}")
    for name, runs in res.items():
        r = list(runs.values())
        ms = [x["keypoint_ms_per_frame_set"] for x in r if x["keypoint_ms_per_frame_set"]]
        print(f"{name:14s} {len(r):4d} {np.mean([x['mpjpe_mm'] for x in r]):9.1f} "
              f"{sum(x.get('backwards_run', False) for x in r):14d} {sum(x['backwards'] > 0 for x in r):17d} "
              f"{sum(x['backwards'] for x in r):16d} {sum(x['leg_swaps'] for x in r):9d} {np.mean(ms) if ms else 0:18.1f}")
    print("per run: " + "; ".join(f"{name} {seq}: {x['mpjpe_mm']:.1f} mm, bw {x['backwards']}/{x['frames']}, "
                                  f"swaps {x['leg_swaps']}" for name, runs in res.items() for seq, x in runs.items()))
