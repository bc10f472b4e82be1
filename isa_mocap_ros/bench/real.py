"""The real recording (issue 34): the Pose2Sim demo imported, tracked offline and through the network.

``isa-mocap bench real [--quick] [--configs A,B] [--lockstep CONFIG] [--out DIR] [--json FILE]``:

1. imports ``../shared/data/real/pose2sim_demo`` as ``docs/real_cameras.md`` section 3 does (4 views at
   320x565, the calibration scene shots as background images, Pose2Sim's raw TRC as the reference), cached in
   ``DIR/demo_bag``;
2. tracks every frame offline (``isa-mocap track``, h-isa 1500, seed 0, automatic initialization) per
   configuration (:data:`CONFIGS`: the default shape, the default shape with the keypoint term, the shape
   calibrated from the first frames, without and with the keypoint term); scored against Pose2Sim's keypoints mapped to our joints: mean error
   raw and with each joint's mean offset removed, the worst frame, the knee angle, frames facing backwards,
   per joint;
3. the same through the node network (``isa-mocap run --lockstep``; ``--lockstep CONFIG``, default the calibrated
   shape when it is tracked, else the first configuration) and how many frames differ from the offline run of
   that configuration (the lockstep replay must not depend on machine load).

``--quick``: the first 8 frames at 160 px, 300 evaluations. Without ``../shared`` nothing runs and the
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
from isa_mocap_ros.bench._common import write_result

__all__ = ["CONFIGS", "collect", "render_markdown", "add_arguments", "run"]

#: configuration name -> (label, extra ``isa-mocap track`` / ``run`` arguments)
CONFIGS = {
    "default": ("default shape", ["--shape", "default"]),
    "keypoints": ("default shape + keypoint term (weight 1, the default rate: every 8th frame)",
                  ["--shape", "default", "--keypoint-weight", "1"]),
    "auto": ("shape calibrated from the first 30 frames", ["--shape", "auto"]),
    "auto_keypoints": ("calibrated shape + keypoint term (weight 1, every 8th frame)",
                       ["--shape", "auto", "--keypoint-weight", "1"]),
}
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


def _track(bag: Path, out: Path, extra: list[str]) -> dict:
    from isa_mocap_ros.cli.main import build_parser
    from isa_mocap_ros.cli.track import track_bag

    args = build_parser().parse_args(["track", str(bag), "--out", str(out), "--overwrite", "--no-progress", *extra])
    t0 = time.perf_counter()
    s = track_bag(args)
    r = {k: s.get(k) for k in _KEEP}
    r["wall_seconds"] = round(time.perf_counter() - t0, 1)
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


def collect(*, quick: bool, out: Path, configs=tuple(CONFIGS), lockstep: str | None = "default_choice") -> dict:
    """The section's measurements (module docstring)."""
    if not (demo_dir() / "calibration" / "Calib_scene_checkerboard.toml").is_file():
        return {"skipped": f"the Pose2Sim demo is not at {demo_dir()} (set ISA_MOCAP_SHARED)"}
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    width, frames = (160, 8) if quick else (320, None)
    bag = out / (f"demo_bag_{width}" + ("" if frames is None else f"_{frames}"))
    if not (bag / "metadata.yaml").is_file():
        import_demo(bag, width=width, frames=frames)
    common = ["--seed", "0", "--evals", "300" if quick else "1500"]
    res: dict = {"quick": bool(quick), "width": width, "evals": int(common[-1]), "seed": 0, "runs": {}}
    for name in configs:
        label, extra = CONFIGS[name]
        print(f"bench real: track {name} ...", file=sys.stderr, flush=True)
        res["runs"][name] = {"label": label, "command": "isa-mocap track BAG " + " ".join(extra + common),
                             **_track(bag, out / f"track_{name}", extra + common)}
    if lockstep:
        name = lockstep if lockstep != "default_choice" else ("auto" if "auto" in configs else configs[0])
        print(f"bench real: run --lockstep {name} ...", file=sys.stderr, flush=True)
        r = _lockstep(bag, out / f"run_{name}", CONFIGS[name][1] + common)
        if "frame_errors_mm" in r and name in res["runs"]:
            a, b = np.asarray(r["frame_errors_mm"]), np.asarray(res["runs"][name]["frame_errors_mm"])
            r["frames_differing_from_track"] = int(np.sum(a != b)) if a.shape == b.shape else None
        res["lockstep"] = {"config": name, "command": "isa-mocap run BAG --lockstep " + " ".join(CONFIGS[name][1] + common),
                           **r}
    return res


def _f(v, fmt: str = "{:.1f}") -> str:
    return fmt.format(v) if v is not None and np.isfinite(v) else "-"


def render_markdown(d: dict) -> str:
    if "skipped" in d:
        return f"Not run: {d['skipped']}.\n"
    L = ["`isa-mocap bench real` (`isa_mocap_ros/bench/real.py`; the recording, its import and the scoring: "
         "[real_cameras.md](real_cameras.md)). The Pose2Sim demo (4 real cameras, 100 frames at 60 fps) imported at "
         f"{d['width']} px wide, h-isa {d['evals']} evaluations per frame, seed {d['seed']}, automatic initialization, "
         "every frame tracked offline (`isa-mocap track`); scored against Pose2Sim's own keypoints (raw TRC) mapped "
         "to our joints — a peer's estimate, not ground truth; its keypoints are not joint centres, so the error with "
         "each joint's mean offset removed is the measure (target ≤ 40 mm)."
         + (" **Quick run (8 frames, 160 px): a smoke test, not the figures.**" if d.get("quick") else ""), "",
         "| run | frames tracked | mean error raw (mm) | offsets removed (mm) | worst frame, offsets removed (mm) "
         "| knee RMSE (°) | frames facing backwards |", "|---|---|---|---|---|---|---|"]
    for r in d["runs"].values():
        L.append(f"| {r['label']} | {r['frames_tracked']} | {_f(r['mpjpe_mm'])} | **{_f(r['offset_removed_mpjpe_mm'])}** "
                 f"| {_f(r['offset_removed_max_frame_error_mm'])} | {_f(r['knee_rmse_deg'])} "
                 f"| {r['frames_facing_backwards']} (heading within {_f(r['max_heading_error_deg'], '{:.0f}')}°) |")
    first = next(iter(d["runs"].values()), None)
    if first and first.get("per_marker_mm"):
        L += ["", f"Per joint ({first['label']}; raw / offsets removed, mm): " + ", ".join(
            f"{n.replace('_', ' ')} {first['per_marker_mm'][n]:.0f}/{first['offset_removed_per_marker_mm'][n]:.0f}"
            for n in first["per_marker_mm"]) + "."]
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
    p.add_argument("--configs", default=",".join(CONFIGS), metavar="A,B",
                   help=f"configurations to track (of {', '.join(CONFIGS)}; default all)")
    p.add_argument("--lockstep", default=None, metavar="CONFIG",
                   help="also run the network in lockstep with this configuration (default: auto, the calibrated shape, "
                        "when it is among --configs, else the first; 'none' = no network run)")
    p.add_argument("--out", default=None, metavar="DIR", help="work directory: the bag, tracks (default: a temporary one)")
    p.add_argument("--json", default="docs/results/real.json", metavar="FILE", help="where to write the results")


def run(args: argparse.Namespace) -> int:
    configs = tuple(c.strip() for c in args.configs.split(",") if c.strip())
    bad = [c for c in configs if c not in CONFIGS]
    lockstep = None if args.lockstep == "none" else (args.lockstep or "default_choice")
    if bad or not configs or (lockstep not in (None, "default_choice") and lockstep not in CONFIGS):
        print(f"isa-mocap bench real: error: --configs / --lockstep: expected names of {', '.join(CONFIGS)}, received "
              f"{args.configs!r} / {args.lockstep!r}", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="isa_mocap_real_"))
    res = collect(quick=args.quick, out=out, configs=configs, lockstep=lockstep)
    res["command"] = "isa-mocap bench real " + " ".join(sys.argv[3:])
    return write_result("real", res, args.json, render_markdown(res))
