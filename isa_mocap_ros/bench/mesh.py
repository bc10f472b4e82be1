"""The mesh headline bench (issue 33 item 3): skinned human meshes, automatic initialization and shape.

``isa-mocap bench mesh [--quick] [--seeds 0,...,7] [--calib-seeds 0,1,2] [--frames N] [--conditions clean,noise70,occluders35]
[--subjects slim_woman,average_man,heavy_man] [--jobs N] [--cache DIR] [--out DIR] [--json FILE]``.

What a user meets: a person who is not the tracking model. Each subject (MakeHuman/MPFB2 meshes of
``isa-mocap synth --subject``: a slim woman 1.60 m, an average man 1.78 m, a heavy man 1.88 m) walks (the
generated walk, bag seed 0) in the default 4-view rig; the bags are rendered once per condition (clean, 70 %
pixel noise, 35 occluding rectangles; :mod:`.robustness`'s renderer and cache) and tracked by ``isa-mocap
track``'s code with **everything automatic**: the shape calibrated from the first frames' silhouettes
(``--shape auto``), the automatic initialization, h-isa at 1500 evaluations per frame, the keypoint term as
``track``'s default (on when the landmark model is installed: decision 014), all other settings the tracker's
defaults; once per tracker seed (default 0-7). The shape is calibrated once per bag and calibration seed
(``--calib-seeds``, default 0, 1, 2: ``isa-mocap calibrate``'s code, kept beside the bag in the cache under a key
of the calibration's options, seed and code, :func:`.robustness.calibrate_bag`), and tracker seed i tracks with
the file of calibration seed i mod 3, as a user who calibrates once and tracks with ``--shape FILE``: one
calibration is a lottery (the tracked mean of one bag moves by up to 30 mm across calibration seeds,
``docs/shape_calibration.md``), so the headline averages over three and shows each one's mean. Every frame is
scored against the mesh skeleton's joint centres by name (no ground-truth model): mean joint error (Eq. 20),
worst frame, knee angle in 3-D, the share of frames tracked facing backwards (hip axis more than 90° off);
each raw (the model's joint centres), **mapped** (the headline: the estimate's virtual markers of the shipped
rig map ``config/joint_maps/makehuman_cmu_mb.yaml``, fitted once on other subjects and motions,
:mod:`isa_mocap_ros.eval.joint_map`) and with each joint's mean offset in the body removed (a lower bound; the
mesh rig and the capsule model define some joints at different places: ``docs/decisions/012-joint-definitions.md``).

Targets (issue 33; on the per-subject means over the seeds, mapped figures): clean mean joint error ≤ 30 mm,
knee RMSE ≤ 3°, no frame above 100 mm in any run, no run tracked facing backwards (a run counts as backwards
when more than half of its frames are); 70 % noise and 35 occluders: knee RMSE ≤ 5°.

Results go to ``--json`` (default ``docs/results/mesh.json``), which ``bench all`` renders as the headline
of ``docs/RESULTS.md``. ``--quick``: one subject, 6 frames of 160x120, 300 evaluations, a 2-round
calibration on 4 frames, seed 0 (a smoke test: the numbers say nothing).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from isa_mocap_ros.eval.compare import SequenceSpec

from . import robustness as br
from isa_mocap_ros.bench._common import collect_and_write, comma_list
from isa_mocap_ros.cli.keypoint_options import default_keypoint_weight

SUBJECTS = ("slim_woman", "average_man", "heavy_man")
CONDITIONS = ("clean", "noise70", "occluders35")
#: frames tracked per run (2 s at 30 fps: the calibration's 30-frame window and as many again)
FRAMES = 60
#: shape calibration seeds: each bag calibrated once per seed, tracker seed i tracking with calibration i % 3 (one
#: calibration is a lottery that moves a bag's tracked mean by up to 30 mm: docs/shape_calibration.md)
CALIB_SEEDS = (0, 1, 2)
#: (condition, what, limit, label) on every subject's mean over the seeds
#: (the mapped figures: the estimate's virtual markers of the shipped rig map, decision 012)
TARGETS = (("clean", "mapped_mpjpe_mm", 30.0, "clean: mean joint error ≤ 30 mm (mapped)"),
           ("clean", "mapped_knee_rmse_deg", 3.0, "clean: knee RMSE ≤ 3° (mapped)"),
           ("clean", "mapped_max_frame_error_mm", 100.0, "clean: no frame > 100 mm (mapped, worst run)"),
           ("clean", "backwards_runs", 0.0, "clean: no run tracked facing backwards"),
           ("noise70", "mapped_knee_rmse_deg", 5.0, "70 % pixel noise: knee RMSE ≤ 5° (mapped)"),
           ("occluders35", "mapped_knee_rmse_deg", 5.0, "35 occluders: knee RMSE ≤ 5° (mapped)"))
#: per-run figures averaged over the seeds
_MEANS = ("mpjpe_mm", "mapped_mpjpe_mm", "offset_removed_mpjpe_mm", "knee_rmse_deg", "mapped_knee_rmse_deg",
          "offset_removed_knee_rmse_deg")


def make_design(kind: str = "default", *, seeds=None, frames: int | None = None, subjects=None,
                conditions=None, tracker=(), calib_seeds=None, calib=()) -> br.RobustDesign:
    """``"default"`` (3 subjects x 3 conditions x seeds 0-7, 60 frames, calibration seeds 0-2) or ``"quick"`` (the
    smoke test, one calibration); ``tracker``: ``track`` options beyond the defaults, (name, value) pairs (e.g.
    ``("keypoint_weight", 1.0)``); ``calib_seeds``: the shape calibration seeds (tracker seed i tracks with the
    calibration of ``calib_seeds[i % n]``); ``calib``: calibration options beyond the defaults, (name, value) pairs of
    ``track``'s ``--calib-*`` (e.g. ``("calib_radius_prior", 0.05)``)."""
    calib = tuple((str(k), v) for k, v in calib)
    tracker = tuple((str(k), v) for k, v in tracker)
    subjects = tuple(subjects or (SUBJECTS[1:2] if kind == "quick" else SUBJECTS))
    conditions = tuple(conditions or (("clean",) if kind == "quick" else CONDITIONS))
    bad = [s for s in subjects if s not in ("slim_woman", "average_man", "heavy_man", "random")]
    if bad or not subjects:
        raise ValueError(f"subjects: expected some of slim_woman, average_man, heavy_man, random, received {bad}")
    known = [c[0] for c in br.CONDITIONS]
    if not conditions or any(c not in known for c in conditions):
        raise ValueError(f"conditions: expected some of {', '.join(known)}, received {list(conditions)}")
    if kind == "quick":
        seqs = tuple(SequenceSpec(s, "walk", duration_s=6 / 30, **{**br.SEQUENCE_DEFAULTS, "width": 160, "height": 120},
                                  subject=s) for s in subjects)
        seeds = tuple(seeds or (0,))
        return br.RobustDesign("mesh quick", seqs, conditions, "h-isa", 300, seeds[0], "auto", seeds=seeds,
                               shape="auto", calib=br.QUICK_CALIB + calib, tracker=tracker,
                               calib_seeds=_calib_seeds(calib_seeds or (seeds[0],)))
    if kind != "default":
        raise ValueError(f"kind: expected 'quick' or 'default', received {kind!r}")
    n = int(frames or FRAMES)
    if n < 2:
        raise ValueError(f"frames: expected an integer >= 2, received {frames!r}")
    seqs = tuple(SequenceSpec(s, "walk", duration_s=n / 30.0, **br.SEQUENCE_DEFAULTS, subject=s) for s in subjects)
    seeds = tuple(seeds or br.DEFAULT_SEEDS)
    return br.RobustDesign("mesh", seqs, conditions, "h-isa", 1500, seeds[0], "auto", seeds=seeds, shape="auto",
                           tracker=tracker, calib_seeds=_calib_seeds(calib_seeds or CALIB_SEEDS), calib=calib)


def _calib_seeds(v) -> tuple:
    out = tuple(int(x) for x in v)
    if not out or len(set(out)) != len(out):
        raise ValueError(f"calibration seeds: expected distinct integers, received {list(v)}")
    return out


def summarize(runs: list[dict]) -> dict:
    """Per condition and subject: means over the seeds (and the worst run's frame); per condition the mean
    over the subjects; the targets."""
    out: dict = {"conditions": []}
    for cond in dict.fromkeys(r["condition"] for r in runs):
        rs = [r for r in runs if r["condition"] == cond]
        per: dict = {}
        for subj in dict.fromkeys(r["sequence"] for r in rs):
            q = [r for r in rs if r["sequence"] == subj]
            per[subj] = {"runs": len(q), **{k: float(np.mean([r.get(k, np.nan) for r in q])) for k in _MEANS},
                         "max_frame_error_mm": float(max(r["max_frame_error_mm"] for r in q)),
                         "mapped_max_frame_error_mm": float(max(r.get("mapped_max_frame_error_mm", np.nan) for r in q)),
                         "mpjpe_range_mm": [float(min(r["mpjpe_mm"] for r in q)), float(max(r["mpjpe_mm"] for r in q))],
                         "backwards_runs": int(sum(r["backwards_share"] > 0.5 for r in q)),
                         **_by_calibration(q)}
        mean = {k: float(np.mean([v[k] for v in per.values()])) for k in _MEANS}
        mean["max_frame_error_mm"] = float(max(v["max_frame_error_mm"] for v in per.values()))
        mean["mapped_max_frame_error_mm"] = float(max(v["mapped_max_frame_error_mm"] for v in per.values()))
        mean["backwards_runs"] = int(sum(v["backwards_runs"] for v in per.values()))
        out["conditions"].append({"condition": cond, "label": br.condition(cond)[1], "per_subject": per, **mean})
    tg = []
    for cond, what, limit, label in TARGETS:
        c = next((x for x in out["conditions"] if x["condition"] == cond), None)
        if c is None:
            tg.append({"target": label, "measured": None, "met": None})
            continue
        vals = {s: v[what] for s, v in c["per_subject"].items()}
        tg.append({"target": label, "measured": vals, "met": all(v <= limit for v in vals.values())})
    out["targets"] = tg
    return out


def _by_calibration(runs: list[dict]) -> dict:
    """The runs' mapped means per calibration seed (``calib_seed``) and their range: the calibration's lottery."""
    ks = sorted({r["calib_seed"] for r in runs if r.get("calib_seed") is not None})
    if len(ks) < 2:
        return {}
    per = {str(k): {w: float(np.mean([r.get(w, np.nan) for r in runs if r.get("calib_seed") == k]))
                    for w in ("mapped_mpjpe_mm", "mapped_knee_rmse_deg")} for k in ks}
    mm = [v["mapped_mpjpe_mm"] for v in per.values()]
    return {"per_calibration": per, "calibration_range_mm": [float(min(mm)), float(max(mm))]}


def collect(design: br.RobustDesign, *, cache: Path, out: Path, jobs: int = 2, progress: bool = True) -> dict:
    res = br.collect(design, cache=cache, out=out, progress=progress, jobs=jobs)
    return {"design": res["design"], "runs": res["runs"], "calibrations": res.get("calibrations", []),
            **summarize(res["runs"]), "seconds": res["seconds"], "jobs": res["jobs"]}


def _fmt(v, f="{:.1f}") -> str:
    return "–" if v is None or not np.isfinite(v) else f.format(v)


def render_markdown(res: dict) -> str:
    """Tables of :func:`collect`'s output: per condition and subject, then the targets."""
    d = res["design"]
    seeds = d.get("seeds") or [d["seed"]]
    cseeds = list(d.get("calib_seeds") or [seeds[0]])
    L = []
    if d["name"] == "mesh quick":
        L += ["> **Smoke run** (`isa-mocap bench mesh --quick`): the numbers say nothing about the tracker.", ""]
    seq = d["sequences"][0]
    full = (list(seeds) == list(br.DEFAULT_SEEDS) and list(d["conditions"]) == list(CONDITIONS) and cseeds == list(CALIB_SEEDS)
            and round(seq["duration_s"] * seq["fps"]) == FRAMES and len(d["sequences"]) == len(SUBJECTS))
    if d["name"] != "mesh quick" and not full:
        L += [f"> **Reduced run** (`{res.get('command', 'isa-mocap bench mesh')}`): fewer seeds, conditions or frames "
              f"than the design ({len(SUBJECTS)} subjects x {len(CONDITIONS)} conditions x 8 seeds, {len(CALIB_SEEDS)} "
              f"calibrations per bag, {FRAMES} frames); "
              "`make bench` runs it in full.", ""]
    L += [f"Skinned human meshes (MakeHuman/MPFB2), generated walk, {round(seq['duration_s'] * seq['fps'])} frames, "
          f"4 views {seq['width']}x{seq['height']}; shape calibrated from the images, automatic initialization, "
          f"{d['optimizer']} {d['evals']} evaluations per frame, tracker seeds {', '.join(map(str, seeds))}"
          + (f" (each bag calibrated with seeds {', '.join(map(str, cseeds))}, used by the tracker seeds in turn)"
             if len(cseeds) > 1 else "")
          + "".join(f", {k} {v}" for k, v in d.get("tracker") or ()) + "; every "
          "frame scored against the mesh skeleton's joint centres. *Mapped* (the headline): the estimate's virtual "
          "markers of the shipped rig map, `config/joint_maps/makehuman_cmu_mb.yaml`, fitted once on other subjects and "
          "motions (the two skeletons define some joints at different places; decision 012). *Offset removed*: each "
          "joint's mean offset in the body removed per run (a lower bound: it also removes a run's constant bias).", "",
          "| condition | subject | mean joint error: mapped | raw | offset removed | knee RMSE: mapped | raw | "
          "offset removed | worst frame, mapped / raw (worst run) | runs backwards | mapped mm per calibration seed |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    f1, f2 = "{:.1f}", "{:.2f}"
    for c in res["conditions"]:
        for s, v in c["per_subject"].items():
            L.append(f"| {c['label']} | {s} | {_fmt(v.get('mapped_mpjpe_mm'), f1)} mm | {v['mpjpe_mm']:.1f} mm "
                     f"({v['mpjpe_range_mm'][0]:.1f}-{v['mpjpe_range_mm'][1]:.1f}) | {v['offset_removed_mpjpe_mm']:.1f} mm | "
                     f"{_fmt(v.get('mapped_knee_rmse_deg'), f2)}° | {v['knee_rmse_deg']:.2f}° | "
                     f"{_fmt(v.get('offset_removed_knee_rmse_deg'), f2)}° | "
                     f"{_fmt(v.get('mapped_max_frame_error_mm'), f1)} / {v['max_frame_error_mm']:.1f} mm | "
                     f"{v['backwards_runs']} of {v['runs']} | {_per_calibration(v)} |")
        L.append(f"| {c['label']} | **mean** | **{_fmt(c.get('mapped_mpjpe_mm'), f1)} mm** | {c['mpjpe_mm']:.1f} mm | "
                 f"{c['offset_removed_mpjpe_mm']:.1f} mm | **{_fmt(c.get('mapped_knee_rmse_deg'), f2)}°** | "
                 f"{c['knee_rmse_deg']:.2f}° | {_fmt(c.get('offset_removed_knee_rmse_deg'), f2)}° | "
                 f"{_fmt(c.get('mapped_max_frame_error_mm'), f1)} / {c['max_frame_error_mm']:.1f} mm | "
                 f"{c['backwards_runs']} | |")
    L += ["", "| target (issue 33) | measured (per subject) | status |", "|---|---|---|"]
    for t in res["targets"]:
        m = "not run" if t["measured"] is None else ", ".join(f"{s} {_fmt(v, '{:.2f}')}" for s, v in t["measured"].items())
        L.append(f"| {t['target']} | {m} | {'not tested' if t['met'] is None else ('met' if t['met'] else 'not met')} |")
    cal = res.get("calibrations") or []
    if cal:
        secs = [c["seconds"] for c in cal if c.get("seconds") is not None]
        L += ["", "Body shape calibrated once per bag" + (" and calibration seed" if len(cseeds) > 1 else "")
              + " (`isa-mocap calibrate`, calibration seed"
              + (f"s {', '.join(map(str, cseeds))}" if len(cseeds) > 1 else f" {cseeds[0]}")
              + f", {_calibration_settings(d)}; "
              + ("every tracker seed tracks with it" if len(cseeds) == 1 else "each tracker seed with one of them")
              + (f"; {np.mean(secs):.0f} s wall per bag, {max(secs):.0f} s at most" if secs else "")
              + "); mean bone-length error against the mesh skeleton's joint centres (12 bones; the 8 limb bones, "
              "whose joints both skeletons define alike):", "",
              "| bag | calibrated | default shape | limbs calibrated | limbs default shape |", "|---|---|---|---|---|"]
        L += [f"| {c['bag']}" + (f" (seed {c.get('calib_seed')})" if len(cseeds) > 1 else "")
              + f" | {_fmt(c['bone_error_mm'])} mm | {_fmt(c['bone_error_default_shape_mm'])} mm | "
              f"{_fmt(c.get('limb_bone_error_mm'))} mm | {_fmt(c.get('limb_bone_error_default_shape_mm'))} mm |"
              for c in cal]
        v = [c["bone_error_mm"] for c in cal if c.get("bone_error_mm") is not None]
        if v:
            L += ["", f"Bone-length error over the {len(v)} calibrations: mean {np.mean(v):.1f} mm, worst {max(v):.1f} mm."]
    L += ["", f"Wall time {res['seconds'] / 60:.1f} min with {res['jobs']} worker(s) (no speed claims)."]
    return "\n".join(L)


def _per_calibration(v: dict) -> str:
    per = v.get("per_calibration") or {}
    return " / ".join(f"{x['mapped_mpjpe_mm']:.1f}" for x in per.values()) if per else "–"


def _calibration_settings(design: dict) -> str:
    """The calibration's settings as the bench ran it: ``isa-mocap calibrate``'s defaults and the design's options."""
    from isa_mocap_ros.cli.shape_options import calibration_config

    cfg = calibration_config(argparse.Namespace(**dict(design.get("calib") or ())), 0)
    return (f"shape-fit energy {cfg.energy}, {cfg.restarts} restart{'s' if cfg.restarts > 1 else ''}"
            + (f" combined by the {cfg.combine}" if cfg.restarts > 1 else "")
            + f", {cfg.rounds} rounds x {cfg.shape_evals} evaluations on {cfg.n_frames} of {cfg.window_frames} frames"
            + (f", radius prior {cfg.radius_prior:g}" if cfg.radius_prior else ""))


def _untwist_tolerance(text: str):
    """``--leg-untwist``'s value: a tolerance >= 0 or ``off``."""
    from isa_mocap_ros.tracking.chain_moves import parse_untwist_tolerance

    try:
        return parse_untwist_tolerance(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="smoke test: one subject, 6 small frames, seed 0")
    p.add_argument("--seeds", default=None, metavar="A,B", help="tracker seeds (default 0-7)")
    p.add_argument("--calib-seeds", default=None, metavar="A,B",
                   help="shape calibration seeds, each bag calibrated once per seed; tracker seed i tracks with the "
                        "calibration of the (i mod n)-th (default 0,1,2; --quick: the first tracker seed)")
    p.add_argument("--frames", type=int, default=None, metavar="N", help=f"frames per run (default {FRAMES})")
    p.add_argument("--subjects", default=None, metavar="A,B", help=f"mesh subjects (default {','.join(SUBJECTS)})")
    p.add_argument("--conditions", default=None, metavar="A,B", help=f"conditions (default {','.join(CONDITIONS)})")
    p.add_argument("--calib-radius-prior", type=float, default=None, metavar="W",
                   help="the shape calibration's radius prior (isa-mocap calibrate's --calib-radius-prior; default: "
                        "calibrate's, off); the calibrations are cached under their own name")
    p.add_argument("--keypoint-weight", type=float, default=None, metavar="W",
                   help="weight of the learned-keypoint term (docs/keypoints.md; 0 = off; default: track's, 1 when "
                        "the landmark model is installed)")
    p.add_argument("--keypoint-every", type=int, default=None, metavar="K",
                   help="keypoints on the first frames and every K-th frame after (default: track's, 8)")
    p.add_argument("--silhouette-core-px", type=float, default=None, metavar="PX",
                   help="the tracker's silhouette_core_px (docs/energy.md; default the tracker's)")
    p.add_argument("--leg-untwist", type=_untwist_tolerance, default=None, metavar="TOL|off",
                   help="the tracker's untwist stage with this tolerance, or off (docs/tracking.md; default the "
                        "tracker's, on at 0.01: decision 019)")
    p.add_argument("--leg-untwist-margin", type=float, default=None, metavar="M",
                   help="the tracker's untwist stage also with this absolute energy margin (docs/tracking.md; default 0)")
    p.add_argument("--pelvis-fraction", type=float, default=None, metavar="F",
                   help="the tracker's pelvis stage share (default the tracker's)")
    p.add_argument("--jobs", type=int, default=2, metavar="N", help="worker processes (default 2)")
    p.add_argument("--cache", default=None, metavar="DIR", help="rendered bags (default OUT/cache)")
    p.add_argument("--out", default=None, metavar="DIR", help="work directory (default: a temporary one)")
    p.add_argument("--json", default="docs/results/mesh.json", metavar="FILE", help="where to write the results")


def run(args: argparse.Namespace) -> int:
    try:
        seeds = None if args.seeds is None else tuple(int(x) for x in comma_list(args.seeds))
        if getattr(args, "keypoint_weight", None) is None:     # the main job's default (cli.keypoint_options)
            args.keypoint_weight, note = default_keypoint_weight()
            if note:
                print(f"isa-mocap bench mesh: {note}", file=sys.stderr)
        tracker = tuple((k, getattr(args, k)) for k in ("keypoint_weight", "keypoint_every", "silhouette_core_px",
                                                        "pelvis_fraction", "leg_untwist", "leg_untwist_margin")
                        if getattr(args, k, None) is not None)
        cseeds = None if getattr(args, "calib_seeds", None) is None else tuple(int(x) for x in comma_list(args.calib_seeds))
        design = make_design("quick" if args.quick else "default", seeds=seeds, frames=args.frames,
                             subjects=comma_list(args.subjects), conditions=comma_list(args.conditions), tracker=tracker,
                             calib_seeds=cseeds,
                             calib=tuple((k, getattr(args, k)) for k in ("calib_radius_prior",)
                                         if getattr(args, k, None) is not None))
        if args.jobs < 1:
            raise ValueError(f"--jobs: expected an integer >= 1, received {args.jobs}")
    except ValueError as exc:
        print(f"isa-mocap bench mesh: error: {exc}", file=sys.stderr)
        return 2
    return collect_and_write("mesh", collect, design, args, render_markdown)
