"""The real recording (issue 34): the Pose2Sim demo imported, tracked offline and through the network.

``isa-mocap bench real [--quick] [--configs A,B] [--lockstep CONFIG] [--out DIR] [--json FILE]``:

1. imports ``../shared/data/real/pose2sim_demo`` as ``docs/real_cameras.md`` section 3 does (4 views at
   320x565, the calibration scene shots as background images, the person found in each frame by the
   landmark model for the background, Pose2Sim's raw TRC as the reference), cached in ``DIR/demo_bag``; the
   masks the default segmentation learns from it are measured against the peer's stick figure per view
   (:mod:`isa_mocap_ros.eval.mask_quality`);
2. tracks every frame offline (``isa-mocap track``, h-isa 1500, automatic initialization) per configuration
   (:data:`CONFIGS`; default: the shape calibrated from the first frames with the keypoint term, ``track``'s own
   defaults and so the headline row, and the default shape with it) and per seed (``--seeds``, default 0,1,2: the track is chaotic across seeds, so one seed says
   little); scored against Pose2Sim's keypoints mapped to our joints: mean error raw and with each joint's mean
   offset removed (mean, min and max over the seeds), the worst frame, the knee angle, frames facing backwards,
   per joint, and per joint in each third of the recording (mean over the seeds: where and when the error is);
   the same runs re-scored with the peer's surface points (head top, nose, heels, toes) defined on the mesh bodies
   (:func:`definition_scores`, :mod:`isa_mocap_ros.eval.keypoint_map`: a diagnostic) and smoothed offline as the peer
   smooths its points (``track --smooth-hz 6``, scored apart);
3. the same through the node network (``isa-mocap run --lockstep``; ``--lockstep CONFIG``, default the calibrated
   shape when it is tracked, else the first configuration) and how many frames differ from the offline run of
   that configuration (the lockstep replay must not depend on machine load).

``--quick``: the first 8 frames at 160 px, 300 evaluations, seed 0. Without ``../shared`` nothing runs and the
section says so. The recording is third-party data (BSD-3, perfanalytics): neither the bag nor overlays
are written anywhere but ``DIR``.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from isa_mocap_ros.bench._common import comma_list, write_result

__all__ = ["CONFIGS", "DEFAULT_CONFIGS", "collect", "mask_figures", "render_markdown", "add_arguments", "run"]

#: configuration name -> (label, extra ``isa-mocap track`` / ``run`` arguments)
CONFIGS = {
    "default": ("default shape", ["--shape", "default"]),
    "keypoints": ("default shape + keypoint term (weight 1, the default rate: every 8th frame)",
                  ["--shape", "default", "--keypoint-weight", "1"]),
    "auto": ("shape calibrated from the first 30 frames", ["--shape", "auto"]),
    "auto_keypoints": ("calibrated shape + keypoint term (weight 1, every 8th frame): track's defaults",
                       ["--shape", "auto", "--keypoint-weight", "1"]),
}
#: configurations tracked when ``--configs`` is not given; the first is the headline row (the per-joint tables)
DEFAULT_CONFIGS = ("auto_keypoints", "keypoints")
_KEEP = ("frames", "frames_tracked", "frames_fell_back", "mpjpe_mm", "offset_removed_mpjpe_mm", "max_frame_error_mm",
         "offset_removed_max_frame_error_mm", "knee_rmse_deg", "offset_removed_knee_rmse_deg", "frames_facing_backwards",
         "max_heading_error_deg", "per_marker_mm", "offset_removed_per_marker_mm", "fps", "frame_errors_mm")


def demo_dir() -> Path:
    from isa_mocap_ros.resources import shared_data_dir

    return shared_data_dir() / "real" / "pose2sim_demo"


def import_demo(bag: Path, *, width: int, frames: int | None) -> None:
    """``isa-mocap import`` of the demo into ``bag`` (docs/real_cameras.md section 3)."""
    from isa_mocap_ros.cli.main import build_parser

    D = demo_dir()
    argv = ["import", str(bag), *[str(D / "balancing" / f"cam0{i}.mp4") for i in range(1, 5)],
            "--calibration", str(D / "calibration" / "Calib_scene_checkerboard.toml"),
            "--background", str(D / "calibration" / "extrinsics"),
            "--reference", str(D / "reference" / "balancing_pose2sim.trc"), "--width", str(width), "--no-progress",
            "--overwrite"]          # a bag left unfinished (no metadata.yaml) is made again
    argv += ["--frames", str(frames)] if frames else []
    args = build_parser().parse_args(argv)
    with contextlib.redirect_stdout(io.StringIO()):
        if args.func(args) != 0:
            raise RuntimeError(f"isa-mocap {' '.join(argv)} failed")


def _scored_markers(collect: dict):
    """``(frames, names, shared, Pe)`` of :func:`isa_mocap_ros.cli.track.track_bag`'s ``collect``: the scored frames
    (estimated, with reference markers), the reference's marker names, the marker joints both define, and our
    estimates' positions of those ``(F, J, 3)``; None without frames or without both hips (the body frame's axes)."""
    from isa_mocap_ros.eval.metrics import marker_positions

    model, names = collect["model"], list(collect["truth_marker_names"])
    frames = sorted(k for k in collect["estimates"] if k in collect["truth_markers"])
    shared = [model.joint_names[j] for j in model.markers if model.joint_names[j] in names]
    if not frames or "left_hip" not in shared or "right_hip" not in shared:
        return None
    return frames, names, shared, marker_positions(model, np.array([collect["estimates"][k] for k in frames]),
                                                   joints=shared)


def _offset_removed_mm(Pe: np.ndarray, Pt: np.ndarray, shared: list[str]) -> np.ndarray:
    """``(F, J)`` errors with each joint's mean offset removed in the reference's body frames, as the score does."""
    from isa_mocap_ros.eval.metrics import body_frames, offset_removed_errors_mm

    err, _ = offset_removed_errors_mm(Pe, Pt, body_frames(Pt, shared.index("left_hip"), shared.index("right_hip")))
    return err


def joint_thirds(collect: dict, parts: int = 3) -> dict:
    """Per marker joint, the error with each joint's mean offset removed (as the score removes it) averaged over
    each of ``parts`` equal spans of the scored frames, mm: ``{joint: [first, ..., last]}``; ``collect`` is
    :func:`isa_mocap_ros.cli.track.track_bag`'s."""
    scored = _scored_markers(collect)
    if scored is None:
        return {}
    frames, names, shared, Pe = scored
    Pt = np.array([collect["truth_markers"][k] for k in frames])[:, [names.index(n) for n in shared]]
    err = _offset_removed_mm(Pe, Pt, shared)
    spans = np.array_split(np.arange(len(frames)), parts)
    with np.errstate(invalid="ignore"):
        return {n: [float(np.nanmean(err[i, m])) for i in spans] for m, n in enumerate(shared)}


#: the score's point definitions compared by :func:`definition_scores`: name -> label
DEFINITIONS = {
    "joints": "our joints (the score)",
    "head_top": "the peer's Head as the mesh bodies' head top (eval/keypoint_map), the rest our joints",
    "mesh": "Head as the mesh head top, every other joint as the mesh rig's joint (decision 012's map)",
}


def definition_scores(collect: dict) -> dict | None:
    """The scored frames against the peer with its points defined on the mesh bodies instead of our joints (issue
    34: nothing fitted on this recording): per :data:`DEFINITIONS` the mean error raw and offsets removed (mm) and
    per joint offsets removed; ``extra``: the peer's points our joints do not name (nose, heels, toes) placed by
    :mod:`isa_mocap_ros.eval.keypoint_map`, raw and offsets removed per point."""
    from isa_mocap_ros.eval.joint_map import mapped_markers, mesh_rig_map
    from isa_mocap_ros.eval.keypoint_map import keypoint_positions, mesh_keypoint_points
    from isa_mocap_ros.eval.metrics import body_frames, offset_removed_errors_mm

    scored = _scored_markers(collect)
    if scored is None or "head" not in scored[2]:
        return None
    frames, names, shared, Pe = scored
    model = collect["model"]
    X = np.array([collect["estimates"][k] for k in frames])
    T = np.array([collect["truth_markers"][k] for k in frames])
    Pt = T[:, [names.index(n) for n in shared]]
    pts, rig = mesh_keypoint_points(), mesh_rig_map()
    head = shared.index("head")
    Ph = Pe.copy()
    Ph[:, head] = keypoint_positions(pts, model, X, ["Head"], rig_map=rig)[:, 0]
    Pm = mapped_markers(rig, model, X, shared)
    Pm[:, head] = Ph[:, head]
    out: dict = {}
    with np.errstate(invalid="ignore"):
        for key, P in (("joints", Pe), ("head_top", Ph), ("mesh", Pm)):
            rem = _offset_removed_mm(P, Pt, shared)
            out[key] = {"raw_mm": float(np.nanmean(np.nanmean(1e3 * np.linalg.norm(P - Pt, axis=-1), axis=1))),
                        "offset_removed_mm": float(np.nanmean(np.nanmean(rem, axis=1))),
                        "per_joint_offset_removed_mm": {n: float(np.nanmean(rem[:, m])) for m, n in enumerate(shared)}}
        extra = [n for n in names if n in pts.points and n != "Head"]
        if extra:
            Pk = keypoint_positions(pts, model, X, extra, rig_map=rig)
            Tk = T[:, [names.index(n) for n in extra]]
            rem, _ = offset_removed_errors_mm(Pk, Tk, body_frames(Pt, shared.index("left_hip"),
                                                                  shared.index("right_hip")))
            raw = 1e3 * np.linalg.norm(Pk - Tk, axis=-1)
            out["extra"] = {n: [float(np.nanmean(raw[:, m])), float(np.nanmean(rem[:, m]))]
                            for m, n in enumerate(extra)}
    return out


#: Pose2Sim's own filter of its triangulated points (the demo's Config.toml ``[filtering.butterworth]``): order,
#: cut-off (Hz); zero phase (filtered forward and backward)
PEER_FILTER = (4, 6.0)


def filtered_score(collect: dict, fps: float, reference: Path) -> float | None:
    """Like for like with the peer's final output: our joint centres filtered as Pose2Sim filters its points
    (:data:`PEER_FILTER`) against its filtered file ``reference`` (TRC, rows = the scored frames in order), offsets
    removed as the score removes them; mean mm. An offline figure (a zero-phase filter needs the whole recording)."""
    from isa_mocap_ros.eval.trc import TRC_TO_WORLD, read_trc
    from isa_mocap_ros.tracking.smooth import zero_phase_lowpass

    scored = _scored_markers(collect)
    trc = read_trc(reference)
    if scored is None or len(scored[0]) != len(trc.points) or len(scored[0]) < 16:
        return None
    frames, names, shared, Pe = scored
    order, cut_hz = PEER_FILTER
    Pt = trc.in_world(TRC_TO_WORLD)[:, [names.index(n) for n in shared]]
    err = _offset_removed_mm(zero_phase_lowpass(Pe, fps, cut_hz, order=order), Pt, shared)
    return float(np.nanmean(np.nanmean(err, axis=1)))


def _track(bag: Path, out: Path, extra: list[str]) -> dict:
    from isa_mocap_ros.cli.main import build_parser
    from isa_mocap_ros.cli.track import track_bag

    args = build_parser().parse_args(["track", str(bag), "--out", str(out), "--overwrite", "--no-progress",
                                      "--smooth-hz", f"{PEER_FILTER[1]:g}", *extra])
    t0 = time.perf_counter()
    collect: dict = {}
    s = track_bag(args, collect=collect)
    r = {k: s.get(k) for k in _KEEP}
    r["wall_seconds"] = round(time.perf_counter() - t0, 1)
    r["joint_thirds_mm"] = joint_thirds(collect)
    r["definitions"] = definition_scores(collect)
    sm = s.get("smoothed") or {}
    r["smoothed_mpjpe_mm"], r["smoothed_offset_removed_mpjpe_mm"] = sm.get("mpjpe_mm"), sm.get("offset_removed_mpjpe_mm")
    ref = demo_dir() / "reference" / "balancing_pose2sim_butterworth.trc"
    stamps = sorted(collect["stamps"].values())
    fps = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / 1e9) if len(stamps) > 1 else 0.0
    r["filtered_offset_removed_mpjpe_mm"] = filtered_score(collect, round(fps, 3), ref) if ref.is_file() else None
    return r


def _lockstep(bag: Path, out: Path, extra: list[str]) -> dict:
    from isa_mocap_ros.cli import run as run_cli

    p = argparse.ArgumentParser()
    run_cli.add_run_arguments(p)
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        rc = run_cli.run(p.parse_args([str(bag), "--out", str(out), "--quiet", "--lockstep", *extra]))
    if rc != 0 or not (out / "summary.json").is_file():
        return {"error": f"isa-mocap run exited with {rc}; see {out / 'nodes.log'}"}
    s = json.loads((out / "summary.json").read_text())
    log = (out / "nodes.log").read_text(errors="replace")
    r = {k: s.get(k) for k in _KEEP if k in s}
    r.update(frames_estimated=s.get("frames_estimated"), dropped_frames=s.get("dropped_frames"),
             no_prediction_lines=log.count("no prediction for frame"), wall_seconds=round(time.perf_counter() - t0, 1))
    return r


def mask_figures(bag: Path) -> list[dict]:
    """Per view, the default segmentation's masks (learnt from the bag's background frames) against the
    reference's stick figure, averaged over the frames (:func:`isa_mocap_ros.eval.mask_quality.mask_quality`), and the
    share beyond the person in each third of the recording (``beyond_thirds``)."""
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.eval.mask_quality import mask_quality, mean_quality
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    seq = read_sequence(bag, want_images=True, want_masks=False)
    learn = [f for f in seq.frames if f.truth_markers is None]
    scored = [f for f in seq.frames if f.truth_markers is not None]
    out = []
    for v, cam in enumerate(seq.cameras):
        seg = BackgroundSegmenter(SegmentationConfig(learn_frames=max(len(learn), 1)))
        for f in learn:
            seg.apply(f.images[v])
        per = [mask_quality(cam, f.truth_markers, seq.truth_marker_names, seg.apply(f.images[v])) for f in scored]
        q = mean_quality(per)
        thirds = [round(mean_quality([per[i] for i in span]).beyond, 3)
                  for span in np.array_split(np.arange(len(per)), 3)]
        out.append({"view": v, "beyond": round(q.beyond, 3), "core_missed": round(q.core_missed, 3),
                    "keypoints_on": round(q.keypoints_on, 3), "beyond_thirds": thirds})
    return out


def _mean_thirds(runs: list[dict]) -> dict:
    """:func:`joint_thirds` of several seeds averaged."""
    names = [n for n in (runs[0] if runs else {}) if all(n in r for r in runs)]
    return {n: [float(np.mean(v)) for v in zip(*(r[n] for r in runs))] for n in names}


def _spread(runs: list[dict], key: str) -> dict:
    v = np.array([r.get(key) if r.get(key) is not None else np.nan for r in runs], float)
    return {"mean": float(np.nanmean(v)), "min": float(np.nanmin(v)), "max": float(np.nanmax(v))} if np.isfinite(v).any() \
        else {"mean": None, "min": None, "max": None}


def _definitions_over_seeds(per_seed: list[dict]) -> dict | None:
    """:func:`definition_scores` of several seeds: per definition the spread of raw and offset-removed means and the
    per-joint means; per extra point the mean raw / offset-removed error over the seeds."""
    runs = [r["definitions"] for r in per_seed if r.get("definitions")]
    if not runs:
        return None
    out = {}
    for key in DEFINITIONS:
        out[key] = {"raw": _spread([r[key] for r in runs], "raw_mm"),
                    "offset_removed": _spread([r[key] for r in runs], "offset_removed_mm"),
                    "per_seed_offset_removed": [r[key]["offset_removed_mm"] for r in runs],
                    "per_joint_offset_removed_mm": {n: float(np.mean([r[key]["per_joint_offset_removed_mm"][n]
                                                                      for r in runs]))
                                                    for n in runs[0][key]["per_joint_offset_removed_mm"]}}
    if all("extra" in r for r in runs):
        out["extra"] = {n: [float(np.mean([r["extra"][n][i] for r in runs])) for i in (0, 1)] for n in runs[0]["extra"]}
    return out


def collect(*, quick: bool, out: Path, configs=DEFAULT_CONFIGS, lockstep: str | None = "default_choice",
            seeds=(0, 1, 2)) -> dict:
    """The section's measurements (module docstring)."""
    if not (demo_dir() / "calibration" / "Calib_scene_checkerboard.toml").is_file():
        return {"skipped": f"the Pose2Sim demo is not at {demo_dir()} (set ISA_MOCAP_SHARED)"}
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    width, frames = (160, 8) if quick else (320, None)
    bag = out / (f"demo_bag_{width}" + ("" if frames is None else f"_{frames}"))
    if not (bag / "metadata.yaml").is_file():
        import_demo(bag, width=width, frames=frames)
    seeds = (0,) if quick else tuple(int(x) for x in seeds)
    evals = ["--evals", "300" if quick else "1500"]
    t0 = time.perf_counter()
    res: dict = {"quick": bool(quick), "width": width, "evals": int(evals[-1]), "seeds": list(seeds), "runs": {},
                 "masks": mask_figures(bag)}
    for name in configs:
        label, extra = CONFIGS[name]
        per_seed = []
        for seed in seeds:
            print(f"bench real: track {name} seed {seed} ...", file=sys.stderr, flush=True)
            per_seed.append({"seed": seed, **_track(bag, out / f"track_{name}_s{seed}",
                                                    extra + ["--seed", str(seed)] + evals)})
        first = per_seed[0]
        res["runs"][name] = {"label": label, "command": "isa-mocap track BAG " + " ".join(extra + evals) + " --seed S",
                             **first, "seeds": [{k: r[k] for k in ("seed", "mpjpe_mm", "offset_removed_mpjpe_mm",
                                                                    "knee_rmse_deg", "frames_tracked",
                                                                    "frames_facing_backwards", "wall_seconds")}
                                                for r in per_seed],
                             "offset_removed_over_seeds": _spread(per_seed, "offset_removed_mpjpe_mm"),
                             "raw_over_seeds": _spread(per_seed, "mpjpe_mm"),
                             "knee_over_seeds": _spread(per_seed, "knee_rmse_deg"),
                             "filtered_over_seeds": _spread(per_seed, "filtered_offset_removed_mpjpe_mm"),
                             "smoothed_over_seeds": _spread(per_seed, "smoothed_offset_removed_mpjpe_mm"),
                             "smoothed_raw_over_seeds": _spread(per_seed, "smoothed_mpjpe_mm"),
                             "backwards_over_seeds": int(sum(r["frames_facing_backwards"] or 0 for r in per_seed)),
                             "tracked_over_seeds": int(min(r["frames_tracked"] or 0 for r in per_seed)),
                             "joint_thirds_over_seeds": _mean_thirds([r["joint_thirds_mm"] for r in per_seed]),
                             "definitions_over_seeds": _definitions_over_seeds(per_seed)}
    common = ["--seed", str(seeds[0])] + evals
    if lockstep:
        name = lockstep if lockstep != "default_choice" else next(
            (c for c in ("auto_keypoints", "auto") if c in configs), configs[0])
        print(f"bench real: run --lockstep {name} ...", file=sys.stderr, flush=True)
        net = CONFIGS[name][1] + (["--keypoints"] if "--keypoint-weight" in CONFIGS[name][1] else [])   # the keypoint node
        r = _lockstep(bag, out / f"run_{name}", net + common)
        if "frame_errors_mm" in r and name in res["runs"]:
            a, b = np.asarray(r["frame_errors_mm"]), np.asarray(res["runs"][name]["frame_errors_mm"])
            r["frames_differing_from_track"] = int(np.sum(a != b)) if a.shape == b.shape else None
        res["lockstep"] = {"config": name, "command": "isa-mocap run BAG --lockstep " + " ".join(net + common),
                           **r}
    res["wall_seconds"] = round(time.perf_counter() - t0, 1)
    return res


def _seeds(d: dict) -> list:
    return d.get("seeds") or [d.get("seed", 0)]


def _one(r: dict, key: str) -> dict:
    return {"mean": r.get(key), "min": r.get(key), "max": r.get(key)}


def _f(v, fmt: str = "{:.1f}") -> str:
    return fmt.format(v) if v is not None and np.isfinite(v) else "-"


def render_markdown(d: dict) -> str:
    if "skipped" in d:
        return f"Not run: {d['skipped']}.\n"
    seeds = _seeds(d)
    L = ["`isa-mocap bench real` (`isa_mocap_ros/bench/real.py`; the recording, its import and the scoring: "
         "[real_cameras.md](real_cameras.md)). The Pose2Sim demo (4 real cameras, 100 frames at 60 fps) imported at "
         f"{d['width']} px wide, h-isa {d['evals']} evaluations per frame, seeds {', '.join(map(str, _seeds(d)))}, "
         "automatic initialization, "
         "every frame tracked offline (`isa-mocap track`); scored against Pose2Sim's own keypoints (raw TRC) mapped "
         "to our joints — a peer's estimate, not ground truth; its keypoints are not joint centres, so the error with "
         "each joint's mean offset removed is the measure (target ≤ 40 mm)."
         + (" **Quick run (8 frames, 160 px): a smoke test, not the figures.**" if d.get("quick") else ""), "",
         "| run | frames tracked (fewest of the seeds) | mean error raw (mm), mean [min-max] over the seeds "
         "| offsets removed (mm), mean [min-max] | per seed, offsets removed (mm) | knee RMSE (°), mean "
         "| frames facing backwards (all seeds) |", "|---|---|---|---|---|---|---|"]
    for r in d["runs"].values():
        raw, rem, knee = (r.get(k) or _one(r, k2) for k, k2 in (("raw_over_seeds", "mpjpe_mm"),
                                                                  ("offset_removed_over_seeds", "offset_removed_mpjpe_mm"),
                                                                  ("knee_over_seeds", "knee_rmse_deg")))
        per = ", ".join(f"{_f(x['offset_removed_mpjpe_mm'])}" for x in r.get("seeds", [r]))
        L.append(f"| {r['label']} | {r.get('tracked_over_seeds', r['frames_tracked'])} | {_f(raw['mean'])} "
                 f"[{_f(raw['min'])}-{_f(raw['max'])}] | **{_f(rem['mean'])}** [{_f(rem['min'])}-{_f(rem['max'])}] "
                 f"| {per} | {_f(knee['mean'])} | {r.get('backwards_over_seeds', r['frames_facing_backwards'])} |")
    filt = [(r["label"], r["filtered_over_seeds"]) for r in d["runs"].values()
            if (r.get("filtered_over_seeds") or {}).get("mean") is not None]
    if filt:
        L += ["", "Like for like with the peer's final output (Pose2Sim filters its triangulated points with a zero-phase "
                  f"Butterworth filter, order {PEER_FILTER[0]}, {PEER_FILTER[1]:g} Hz, its Config.toml; here our joint "
                  "centres filtered the same way against its filtered file, offsets removed; an offline figure, not the "
                  "score above): " + "; ".join(f"{lab}: **{_f(f['mean'])}** [{_f(f['min'])}-{_f(f['max'])}] mm"
                                              for lab, f in filt) + "."]
    smo = [(r["label"], r["smoothed_over_seeds"], r.get("smoothed_raw_over_seeds") or {}) for r in d["runs"].values()
           if (r.get("smoothed_over_seeds") or {}).get("mean") is not None]
    if smo:
        L += ["", f"`track --smooth-hz {PEER_FILTER[1]:g}` (an offline option: the finished track's poses low-passed "
                  "by the peer's kind of filter, zero phase; against the raw file, as the score): " + "; ".join(
                      f"{lab}: **{_f(f['mean'])}** [{_f(f['min'])}-{_f(f['max'])}] mm offsets removed, raw "
                      f"{_f(raw.get('mean'))}" for lab, f, raw in smo) + "."]
    first = next(iter(d["runs"].values()), None)
    defs = (first or {}).get("definitions_over_seeds")
    if defs:
        L += ["", f"The peer's points defined on the mesh bodies ({first['label']}; the same runs re-scored; "
                  "`isa_mocap_ros/eval/keypoint_map.py`: the MakeHuman meshes' head top, nose, heels and toes anchored "
                  "on our head and ankle joints, `config/joint_maps/halpe26_mesh_points.yaml`; nothing fitted on this "
                  "recording; a diagnostic, not the score: on mesh bags the mapped head top is farther from the mesh's "
                  "than our head joint, real_cameras.md section 5):", "",
              "| points scored as | raw (mm), mean [min-max] | offsets removed (mm), mean [min-max] | per seed "
              "| head | right ankle |", "|---|---|---|---|---|---|"]
        for key, label in DEFINITIONS.items():
            v = defs[key]
            pj = v["per_joint_offset_removed_mm"]
            L.append(f"| {label} | {_f(v['raw']['mean'])} [{_f(v['raw']['min'])}-{_f(v['raw']['max'])}] "
                     f"| **{_f(v['offset_removed']['mean'])}** [{_f(v['offset_removed']['min'])}-"
                     f"{_f(v['offset_removed']['max'])}] | {', '.join(_f(x) for x in v['per_seed_offset_removed'])} "
                     f"| {_f(pj.get('head'), '{:.0f}')} | {_f(pj.get('right_ankle'), '{:.0f}')} |")
        if defs.get("extra"):
            L += ["", "The peer's points outside the score, placed the same way (raw / offsets removed, mm, mean over "
                      "the seeds): " + ", ".join(f"{n} {a:.0f}/{b:.0f}" for n, (a, b) in defs["extra"].items()) + "."]
    if first and first.get("per_marker_mm"):
        L += ["", f"Per joint ({first['label']}, seed {seeds[0]}; raw / offsets removed, mm): " + ", ".join(
            f"{n.replace('_', ' ')} {first['per_marker_mm'][n]:.0f}/{first['offset_removed_per_marker_mm'][n]:.0f}"
            for n in first["per_marker_mm"]) + "."]
    th = (first or {}).get("joint_thirds_over_seeds")
    if th:
        cols = np.array(list(th.values()))
        L += ["", f"Per joint in each third of the recording ({first['label']}; offsets removed, mm, mean over the seeds "
                  f"{', '.join(map(str, seeds))}):", "", "| joint | first third | second third | last third |",
              "|---|---|---|---|"]
        L += [f"| {n.replace('_', ' ')} | " + " | ".join(f"{x:.0f}" for x in v) + " |" for n, v in th.items()]
        L.append("| **mean** | " + " | ".join(f"**{x:.1f}**" for x in np.nanmean(cols, axis=0)) + " |")
    if d.get("masks"):
        L += ["", "Masks of the default segmentation learnt from the import's background frames, against the peer's "
                  "stick figure (`isa_mocap_ros.eval.mask_quality`; share of the mask farther than 18 px from it / share "
                  "of its 5-px core missed / keypoints on the mask): " + "; ".join(
                      f"cam{m['view']} {m['beyond']:.2f} / {m['core_missed']:.2f} / {m['keypoints_on']:.2f}"
                      for m in d["masks"]) + "."]
        if all("beyond_thirds" in m for m in d["masks"]):
            L[-1] += " Beyond the person in the first / second / last third of the recording: " + "; ".join(
                f"cam{m['view']} " + " / ".join(f"{x:.2f}" for x in m["beyond_thirds"]) for m in d["masks"]) + "."
    if d.get("wall_seconds") is not None:
        L += ["", f"The bench took {d['wall_seconds'] / 60:.1f} min (import, masks, every run)."]
    lk = d.get("lockstep")
    if lk:
        if "error" in lk:
            L += ["", f"Node network (`{lk['command']}`): {lk['error']}."]
        else:
            L += ["", f"Node network (`{lk['command']}`): {lk['frames_estimated']} frames estimated, "
                      f"{lk['dropped_frames']} dropped, {_f(lk['mpjpe_mm'])} mm raw, "
                      f"{_f(lk['offset_removed_mpjpe_mm'])} mm with the offsets removed; "
                      f"**{lk.get('frames_differing_from_track')} frames differ** from the offline run of the same "
                      f"configuration; {lk['no_prediction_lines']} \"no prediction\" lines."]
    return "\n".join(L) + "\n"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="8 frames at 160 px, 300 evaluations (a smoke test)")
    p.add_argument("--configs", default=",".join(DEFAULT_CONFIGS), metavar="A,B",
                   help=f"configurations to track (of {', '.join(CONFIGS)}; default {','.join(DEFAULT_CONFIGS)})")
    p.add_argument("--seeds", default="0,1,2", metavar="S,T",
                   help="seeds tracked per configuration (default 0,1,2; --quick: 0)")
    p.add_argument("--lockstep", default=None, metavar="CONFIG",
                   help="also run the network in lockstep with this configuration, first seed (default: the calibrated "
                        "shape, auto_keypoints or auto, when among --configs, else the first; 'none' = no network run)")
    p.add_argument("--out", default=None, metavar="DIR", help="work directory: the bag, tracks (default: a temporary one)")
    p.add_argument("--json", default="docs/results/real.json", metavar="FILE", help="where to write the results")


def run(args: argparse.Namespace) -> int:
    configs = comma_list(args.configs)
    bad = [c for c in configs if c not in CONFIGS]
    lockstep = None if args.lockstep == "none" else (args.lockstep or "default_choice")
    try:
        seeds = tuple(int(x) for x in comma_list(args.seeds))
    except ValueError:
        seeds = ()
    if not seeds:
        print(f"isa-mocap bench real: error: --seeds: expected integers like 0,1,2, received {args.seeds!r}", file=sys.stderr)
        return 2
    if bad or not configs or (lockstep not in (None, "default_choice") and lockstep not in CONFIGS):
        print(f"isa-mocap bench real: error: --configs / --lockstep: expected names of {', '.join(CONFIGS)}, received "
              f"{args.configs!r} / {args.lockstep!r}", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="isa_mocap_real_"))
    res = collect(quick=args.quick, out=out, configs=configs, lockstep=lockstep, seeds=seeds)
    res["command"] = "isa-mocap bench real " + " ".join(sys.argv[3:])
    res["_seconds"] = res.get("wall_seconds")     # the results page's "Time:" line (bench all sets it the same way)
    return write_result("real", res, args.json, render_markdown(res))
