"""Unseen motions on mesh bodies (issue 33): real motion capture of several kinds, everything automatic.

``isa-mocap bench mesh_motions [--quick] [--motions punch,kick,...] [--subjects average_man,random]
[--seeds 0,1,2] [--frames N] [--jobs N] [--cache DIR] [--out DIR] [--json FILE]``.

``bench mesh`` scores one generated walk. Here each subject (``isa-mocap synth --subject``; ``random`` draws a
different body per clip, from the bag seed 1 + the clip's place in :data:`CLIPS`) performs CMU clips of other kinds
(``../shared/data/mocap/cmu/``, its README: punches, a dribble and shot, a kick, waving, a jog, forward jumps), carried
onto the subject's own skeleton by ``synth`` (:func:`isa_mocap_ros.synth.make_clip`), 2 s from a start past each
clip's T-pose, rendered clean in the default 4-view rig (:mod:`.robustness`'s renderer and cache). Tracking and
scoring are ``bench mesh``'s: the shape calibrated once per bag from its images, the automatic initialization,
h-isa 1500, ``track``'s defaults, once per tracker seed; every frame against the mesh skeleton's joint centres,
mapped by the shipped rig map (:mod:`isa_mocap_ros.eval.joint_map`).

The clips are not the tracker's tuning set: it was tuned on generated walks. Two CMU clips are left out of
:data:`CLIPS` on purpose (07_05 slow walk, 03_01 uneven terrain: session 28's held-out bags, and 09_12, 06_10):
``synth`` them by hand to check a change on motions nothing was chosen on.

Results go to ``--json`` (default ``docs/results/mesh_motions.json``), rendered by ``bench all``. ``--quick``: the
jog, one subject, 6 frames of 160x120, 300 evaluations, a 2-round calibration (a smoke test). Skips clips whose
file is absent (with a note).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from isa_mocap_ros.bench import robustness as br
from isa_mocap_ros.bench._common import collect_and_write, comma_list
from isa_mocap_ros.cli.keypoint_options import default_keypoint_weight
from isa_mocap_ros.eval.compare import SequenceSpec

#: clip key -> (file under shared/data/mocap/cmu, metres per BVH unit or None = detect, start s, label)
CLIPS = {
    "punch": ("02_05_punch_strike.bvh", 0.056444, 2.0, "punch / strike (02_05)"),
    "dribble_shoot": ("06_15_basketball_dribble_shoot.bvh", 0.056444, 1.0, "dribble, shoot (06_15)"),
    "kick": ("10_02_soccer_kick.bvh", None, 1.5, "soccer kick (10_02)"),
    "wave": ("13_26_direct_traffic_wave.bvh", 0.056444, 3.0, "direct traffic, wave (13_26)"),
    "jog": ("16_36_run_jog.bvh", None, 0.0, "run / jog (16_36, 1.6 s)"),
    "jumps": ("01_01_forward_jumps_turn.bvh", 0.056444, 1.0, "forward jumps (01_01)"),
}
MOTIONS = tuple(CLIPS)
SUBJECTS = ("average_man", "random")
SEEDS = (0, 1, 2)
#: frames per run (2 s at 30 fps; a clip shorter than that gives what it has)
FRAMES = 60
_MEANS = ("mpjpe_mm", "mapped_mpjpe_mm", "offset_removed_mpjpe_mm", "mapped_knee_rmse_deg", "knee_rmse_deg")


def cmu_dir() -> Path:
    """``shared/data/mocap/cmu`` beside the checkout (or under ``$ISA_MOCAP_SHARED``)."""
    from isa_mocap_ros.resources import shared_data_dir

    return shared_data_dir() / "mocap" / "cmu"


def make_design(kind: str = "default", *, motions=None, subjects=None, seeds=None, frames: int | None = None,
                tracker=(), root: Path | None = None) -> br.RobustDesign:
    """``"default"`` (:data:`MOTIONS` x :data:`SUBJECTS` x :data:`SEEDS`, 60 frames) or ``"quick"`` (the jog, one
    subject, 6 small frames); clips whose file is not under ``root`` (default :func:`cmu_dir`) are left out with a
    note."""
    root = Path(root) if root is not None else cmu_dir()
    motions = tuple(motions or (("jog",) if kind == "quick" else MOTIONS))
    subjects = tuple(subjects or (SUBJECTS[:1] if kind == "quick" else SUBJECTS))
    bad = [m for m in motions if m not in CLIPS]
    if bad or not motions:
        raise ValueError(f"motions: expected some of {', '.join(CLIPS)}, received {list(motions)}")
    bad = [s for s in subjects if s not in ("slim_woman", "average_man", "heavy_man", "random")]
    if bad or not subjects:
        raise ValueError(f"subjects: expected some of slim_woman, average_man, heavy_man, random, received {bad}")
    if kind not in ("quick", "default"):
        raise ValueError(f"kind: expected 'quick' or 'default', received {kind!r}")
    quick = kind == "quick"
    n = 6 if quick else int(frames or FRAMES)
    if n < 2:
        raise ValueError(f"frames: expected an integer >= 2, received {frames!r}")
    size = {"width": 160, "height": 120} if quick else {}
    seqs, notes = [], []
    for m in motions:
        f, scale, start, _label = CLIPS[m]
        if not (root / f).is_file():
            notes.append(f"{m} skipped: {root / f} not found")
            continue
        for s in subjects:
            seqs.append(SequenceSpec(f"{m}-{s}", str(root / f), start_s=start, duration_s=n / 30.0,
                                     **{**br.SEQUENCE_DEFAULTS, **size}, subject=s, bvh_scale=scale,
                                     seed=1 + MOTIONS.index(m) if s == "random" else 0))
    if not seqs:
        raise ValueError(f"no clip found under {root} (expected the shared CMU clips: {', '.join(CLIPS[m][0] for m in motions)})")
    seeds = tuple(seeds or ((0,) if quick else SEEDS))
    tracker = tuple((str(k), v) for k, v in tracker)
    return br.RobustDesign("mesh motions quick" if quick else "mesh motions", tuple(seqs), ("clean",), "h-isa",
                           300 if quick else 1500, seeds[0], "auto", tuple(notes), seeds=seeds, shape="auto",
                           calib=br.QUICK_CALIB if quick else (), tracker=tracker)


def summarize(runs: list[dict], calibrations: list[dict]) -> dict:
    """Per sequence (clip x subject) the means over the seeds; per clip and overall the means over sequences."""
    bone = {c["bag"]: c.get("bone_error_mm") for c in calibrations}
    per: dict = {}
    for name in dict.fromkeys(r["sequence"] for r in runs):
        q = [r for r in runs if r["sequence"] == name]
        per[name] = {"runs": len(q), "motion": name.split("-", 1)[0], "subject": name.split("-", 1)[1],
                     **{k: float(np.mean([r.get(k, np.nan) for r in q])) for k in _MEANS},
                     "mapped_range_mm": [float(min(r["mapped_mpjpe_mm"] for r in q)),
                                         float(max(r["mapped_mpjpe_mm"] for r in q))],
                     "mapped_max_frame_error_mm": float(max(r["mapped_max_frame_error_mm"] for r in q)),
                     "backwards_runs": int(sum(r["backwards_share"] > 0.5 for r in q)),
                     "bone_error_mm": bone.get(q[0].get("bag"))}
    motions = {}
    for m in dict.fromkeys(v["motion"] for v in per.values()):
        vs = [v for v in per.values() if v["motion"] == m]
        motions[m] = {k: float(np.mean([v[k] for v in vs])) for k in _MEANS}
        motions[m]["mapped_max_frame_error_mm"] = float(max(v["mapped_max_frame_error_mm"] for v in vs))
    mean = {k: float(np.mean([v[k] for v in per.values()])) for k in _MEANS}
    return {"per_sequence": per, "per_motion": motions, "mean": mean}


def collect(design: br.RobustDesign, *, cache: Path, out: Path, jobs: int = 2, progress: bool = True) -> dict:
    res = br.collect(design, cache=cache, out=out, progress=progress, jobs=jobs)
    cal = res.get("calibrations", [])
    names = {br.bag_name(s, "clean"): s.name for s in design.sequences}
    for r in res["runs"]:
        r["bag"] = next(b for b, n in names.items() if n == r["sequence"])
    return {"design": res["design"], "runs": res["runs"], "calibrations": cal, **summarize(res["runs"], cal),
            "seconds": res["seconds"], "jobs": res["jobs"]}


def _f(v, f="{:.1f}") -> str:
    return "–" if v is None or not np.isfinite(v) else f.format(v)


def render_markdown(res: dict) -> str:
    d = res["design"]
    seeds = d.get("seeds") or [d["seed"]]
    seq = d["sequences"][0]
    L = []
    if d["name"].endswith("quick"):
        L += ["> **Smoke run** (`isa-mocap bench mesh_motions --quick`): the numbers say nothing about the tracker.", ""]
    elif (len(d["sequences"]) != len(MOTIONS) * len(SUBJECTS) or tuple(seeds) != SEEDS
          or round(seq["duration_s"] * seq["fps"]) != FRAMES):
        L += [f"> **Reduced run** (`{res.get('command', 'isa-mocap bench mesh_motions')}`): fewer clips, subjects, seeds "
              f"or frames than the design ({len(MOTIONS)} clips x {len(SUBJECTS)} subjects x seeds "
              f"{', '.join(map(str, SEEDS))}, {FRAMES} frames).", ""]
    L += [f"CMU clips of several kinds on mesh subjects (the BVH's motion on the subject's own skeleton; `random`: "
          f"a different random body per clip), {round(seq['duration_s'] * seq['fps'])} frames from each clip's start, "
          f"clean, 4 views {seq['width']}x{seq['height']}; shape calibrated from the images, automatic "
          f"initialization, {d['optimizer']} {d['evals']} evaluations, tracker seeds {', '.join(map(str, seeds))}; "
          "scored like `bench mesh` (mapped: the shipped rig map). The tracker was tuned on generated walks "
          "(`bench mesh`: clean 25.8 mm mapped, knee 4.5°).", ""]
    L += [f"> {n}" for n in d.get("notes") or ()]
    L += ["| clip | subject | mean joint error: mapped (seed range) | raw | offset removed | knee RMSE (mapped) | "
          "worst frame (mapped) | runs backwards | calibrated bone error |", "|---|---|---|---|---|---|---|---|---|"]
    for name, v in res["per_sequence"].items():
        L.append(f"| {v['motion']} | {v['subject']} | {v['mapped_mpjpe_mm']:.1f} mm ({v['mapped_range_mm'][0]:.1f}-"
                 f"{v['mapped_range_mm'][1]:.1f}) | {v['mpjpe_mm']:.1f} mm | {v['offset_removed_mpjpe_mm']:.1f} mm | "
                 f"{_f(v['mapped_knee_rmse_deg'], '{:.2f}')}° | {v['mapped_max_frame_error_mm']:.1f} mm | "
                 f"{v['backwards_runs']} of {v['runs']} | {_f(v.get('bone_error_mm'))} mm |")
    L += ["", "| clip | mapped | knee RMSE | worst frame |", "|---|---|---|---|"]
    for m, v in res["per_motion"].items():
        L.append(f"| {CLIPS[m][3]} | {v['mapped_mpjpe_mm']:.1f} mm | {v['mapped_knee_rmse_deg']:.2f}° | "
                 f"{v['mapped_max_frame_error_mm']:.1f} mm |")
    m = res["mean"]
    L.append(f"| **all** | **{m['mapped_mpjpe_mm']:.1f} mm** | **{m['mapped_knee_rmse_deg']:.2f}°** | |")
    L += ["", f"Wall time {res['seconds'] / 60:.1f} min with {res['jobs']} worker(s) (no speed claims)."]
    return "\n".join(L)


def for_all(quick: bool, ctx: dict) -> dict:
    """``bench all``'s run: the default (or quick) design, bags cached with the robustness bench's; ``{"skipped":
    why}`` where the shared CMU clips are absent (a checkout without ``../shared``)."""
    root = cmu_dir()
    if not any((root / CLIPS[m][0]).is_file() for m in MOTIONS):
        return {"skipped": f"the shared CMU clips are not under {root} (set ISA_MOCAP_SHARED)"}
    design = make_design("quick" if quick else "default", tracker=(("keypoint_weight", default_keypoint_weight()[0]),))
    return collect(design, cache=ctx["out"] / "cache" / "robustness", out=ctx["out"] / "mesh_motions",
                   jobs=ctx["jobs"], progress=ctx["progress"])


def section(res: dict) -> str:
    """``bench all``'s section of the results page."""
    if "skipped" in res:
        return f"Not run: {res['skipped']}.\n"
    return ("`isa-mocap bench mesh_motions` (module docstring; docs/history/issue33_generalisation.md).\n\n"
            + render_markdown(res) + "\n")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="smoke test: the jog, one subject, 6 small frames, seed 0")
    p.add_argument("--motions", default=None, metavar="A,B", help=f"clips (default {','.join(MOTIONS)})")
    p.add_argument("--subjects", default=None, metavar="A,B", help=f"mesh subjects (default {','.join(SUBJECTS)})")
    p.add_argument("--seeds", default=None, metavar="A,B", help="tracker seeds (default 0,1,2)")
    p.add_argument("--frames", type=int, default=None, metavar="N", help=f"frames per run (default {FRAMES})")
    p.add_argument("--jobs", type=int, default=2, metavar="N", help="worker processes (default 2)")
    p.add_argument("--cache", default=None, metavar="DIR", help="rendered bags (default OUT/cache)")
    p.add_argument("--out", default=None, metavar="DIR", help="work directory (default: a temporary one)")
    p.add_argument("--json", default="docs/results/mesh_motions.json", metavar="FILE",
                   help="where to write the results")


def run(args: argparse.Namespace) -> int:
    try:
        seeds = None if args.seeds is None else tuple(int(x) for x in comma_list(args.seeds))
        w, note = default_keypoint_weight()        # the main job's default (cli.keypoint_options)
        if note:
            print(f"isa-mocap bench mesh_motions: {note}", file=sys.stderr)
        design = make_design("quick" if args.quick else "default", motions=comma_list(args.motions),
                             subjects=comma_list(args.subjects), seeds=seeds, frames=args.frames,
                             tracker=(("keypoint_weight", w),))
        if args.jobs < 1:
            raise ValueError(f"--jobs: expected an integer >= 1, received {args.jobs}")
    except ValueError as exc:
        print(f"isa-mocap bench mesh_motions: error: {exc}", file=sys.stderr)
        return 2
    return collect_and_write("mesh_motions", collect, design, args, render_markdown)
