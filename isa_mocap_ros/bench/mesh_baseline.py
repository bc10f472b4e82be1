"""Mesh bodies vs capsules: reduced robustness and comparison runs on both bodies (issue 32's baseline).

``isa-mocap bench mesh_baseline [--frames N] [--seeds 0,1] [--compare-frames N] [--jobs N] [--out DIR]
[--json FILE]``.

The same reduced designs run twice, once on skinned human meshes (``--body mesh``, the average man,
scored by the mesh skeleton's joint centres, knees in 3-D) and once on capsule renders of the
tracking model (``--body capsules``, the control, scored against the ground-truth poses):

* robustness (:mod:`.robustness`): the default sequences (CMU walk from 1 s if present, generated
  walk, jog), cut to ``--frames`` (default 30) frames, the four conditions, tracker seeds
  ``--seeds`` (default 0,1), h-isa 1500, initialized from the ground truth, the shape calibrated once per
  bag from its images (robustness's default);
* comparison (:mod:`isa_mocap_ros.eval.compare`): the default design's sequences, algorithms
  h-isa, isa, cmaes and pycma at 39 DOF and 1500 evaluations, seed 0, the first
  ``--compare-frames`` (default 10) frames, the shape calibrated once per sequence from its images (the
  comparison's default since session 25; the calibration reads the sequence's first 30 frames).

Results go to ``--json`` (default ``docs/results/mesh_baseline.json``), which ``bench all``
renders into ``docs/RESULTS.md`` ("Mesh bodies vs capsules").
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from isa_mocap_ros.bench._common import comma_list, write_result

BODIES = ("mesh", "capsules")
COMPARE_ALGORITHMS = ("h-isa", "isa", "cmaes", "pycma")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--frames", type=int, default=30, metavar="N", help="robustness frames per sequence (default 30)")
    p.add_argument("--seeds", default="0,1", metavar="A,B", help="robustness tracker seeds (default 0,1)")
    p.add_argument("--compare-frames", type=int, default=10, metavar="N", help="comparison frames tracked (default 10)")
    p.add_argument("--jobs", type=int, default=2, metavar="N", help="worker processes (default 2)")
    p.add_argument("--out", default=None, metavar="DIR", help="work directory (default: a temporary one)")
    p.add_argument("--json", default="docs/results/mesh_baseline.json", metavar="FILE", help="where to write the results")


def collect(*, frames: int = 30, seeds=(0, 1), compare_frames: int = 10, jobs: int = 2, out: Path,
            quick: bool = False) -> dict:
    """Both bodies through the reduced designs (``quick``: the benches' own ``--quick`` designs, a smoke test)."""
    from isa_mocap_ros.bench import robustness as br
    from isa_mocap_ros.bench.compare import run_design
    from isa_mocap_ros.eval.compare import make_design, summarize

    t0 = time.perf_counter()
    res: dict = {"robustness": {}, "compare": {}}
    for body in BODIES:
        d = br.make_design("quick", body=body) if quick else \
            br.make_design("default", seeds=tuple(seeds), body=body, frames=frames)
        res["robustness"][body] = br.collect(d, cache=out / "cache" / "robustness", out=out / f"robustness_{body}",
                                             jobs=jobs)
        cd = make_design("quick" if quick else "default", body=body)
        if not quick:
            cd = replace(cd, algorithms=COMPARE_ALGORITHMS, models=(39,), budgets=(1500,), seeds=(0,),
                         frames=compare_frames)
        recs = run_design(cd, out / f"compare_{body}", jobs=jobs, progress=False)
        s = summarize(recs)
        s["design"] = cd.to_dict()
        s["records"] = [{k: r[k] for k in ("algorithm", "sequence", "mpjpe_mm", "knee_rmse_deg", "max_frame_error_mm",
                                           "frames")} for r in recs]
        res["compare"][body] = s
    res["settings"] = {"frames": frames, "seeds": list(seeds), "compare_frames": compare_frames,
                       "compare_algorithms": list(COMPARE_ALGORITHMS), "quick": quick}
    res["seconds"] = round(time.perf_counter() - t0, 1)
    return res


def render_markdown(res: dict) -> str:
    """Side-by-side tables (mesh | capsules) of :func:`collect`'s output."""
    st = res["settings"]
    if st.get("quick"):
        desc = ("> **Smoke run** (the robustness and comparison benches' `--quick` designs, on both bodies): the "
                "numbers say nothing about the tracker.")
    else:
        desc = ("Reduced runs (`isa-mocap bench mesh_baseline`, module docstring): robustness on the default sequences "
                f"cut to {st['frames']} frames, tracker seeds {', '.join(map(str, st['seeds']))}; comparison of "
                f"{', '.join(st['compare_algorithms'])} at 39 DOF / 1500 evaluations, seed 0, first "
                f"{st['compare_frames']} frames. Mesh: a skinned human (the average man) scored by its skeleton's "
                "joint centres (knee angles in 3-D); capsules: the tracking model itself (the control). Today's "
                "tracker on meshes: the baseline part 2 starts from.")
    L = [desc, "",
         "| condition | sequence | mesh knee RMSE | mesh mean joint error | capsules knee RMSE | "
         "capsules mean joint error |", "|---|---|---|---|---|---|"]
    rob = res["robustness"]
    for cm in rob["mesh"]["conditions"]:
        cc = next((c for c in rob["capsules"]["conditions"] if c["condition"] == cm["condition"]), None)
        for seq, v in cm["per_sequence"].items():
            w = (cc or {}).get("per_sequence", {}).get(seq)
            L.append(f"| {cm['label']} | {seq} | {v['knee_rmse_deg']:.2f}° | {v['mpjpe_mm']:.1f} mm | "
                     + (f"{w['knee_rmse_deg']:.2f}° | {w['mpjpe_mm']:.1f} mm |" if w else "– | – |"))
        L.append(f"| {cm['label']} | **mean** | **{cm['knee_rmse_deg']:.2f}°** | **{cm['mpjpe_mm']:.1f} mm** | "
                 + (f"**{cc['knee_rmse_deg']:.2f}°** | **{cc['mpjpe_mm']:.1f} mm** |" if cc else "– | – |"))
    L += ["", "| algorithm | sequence | mesh mean joint error | mesh knee RMSE | capsules mean joint error | "
              "capsules knee RMSE |", "|---|---|---|---|---|---|"]
    cap = {(r["algorithm"], r["sequence"]): r for r in res["compare"]["capsules"]["records"]}
    for r in sorted(res["compare"]["mesh"]["records"], key=lambda r: (r["algorithm"], r["sequence"])):
        c = cap.get((r["algorithm"], r["sequence"]))
        L.append(f"| {r['algorithm']} | {r['sequence']} | {r['mpjpe_mm']:.1f} mm | {r['knee_rmse_deg']:.2f}° | "
                 + (f"{c['mpjpe_mm']:.1f} mm | {c['knee_rmse_deg']:.2f}° |" if c else "– | – |"))
    L += ["", f"Wall time {res['seconds'] / 60:.1f} min (2-core machine shared with other work: no speed claims)."]
    return "\n".join(L)


def run(args: argparse.Namespace) -> int:
    seeds = tuple(int(x) for x in comma_list(args.seeds))
    if args.frames < 2 or args.compare_frames < 2 or not seeds or args.jobs < 1:
        print("isa-mocap bench mesh_baseline: error: expected --frames, --compare-frames >= 2, seeds, --jobs >= 1",
              file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="isa_mocap_mesh_baseline_"))
    res = collect(frames=args.frames, seeds=seeds, compare_frames=args.compare_frames, jobs=args.jobs, out=out)
    res["command"] = "isa-mocap bench mesh_baseline " + " ".join(sys.argv[3:])
    return write_result("mesh_baseline", res, args.json, render_markdown(res))
