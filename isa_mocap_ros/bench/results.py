"""``isa-mocap bench all``: run every benchmark and regenerate the results page (``docs/RESULTS.md``).

``isa-mocap bench all [--quick] [--results PATH] [--out DIR] [--jobs N] [--only A,B] [--render]``. Runs, in
order, ackley, adapters, render, energy, compare, robustness, speed, mesh_baseline (mesh bodies vs capsules,
reduced), mesh (the headline: mesh subjects, automatic shape and init.), mesh_motions, keypoints (a reduced
``bench keypoints``: the detector's cost per rate, tracking with and without the term, :mod:`.keypoints_summary`)
and real (the Pose2Sim recording offline and in lockstep, :mod:`.real`)
with their default designs (compare and robustness on mesh bodies since issue 32)
(``--quick``: their ``--quick`` variants), then writes

* ``PATH`` (default ``docs/RESULTS.md`` of the source checkout): every bench's tables, the figures,
  the checked qualitative findings of the comparison paper and issue #7's targets (met / not met,
  computed from the measured numbers), with the exact command, date, git commit and machine;
* ``PATH``'s folder ``results/``: the figures (PNG) and each bench's raw results (``<bench>.json``).

Work files (the comparison's resumable ``cells.jsonl``, the robustness bags) go to ``--out``
(default ``out/bench``; with ``--quick`` a temporary directory): ``bench all --resume`` continues an
interrupted comparison from its ``cells.jsonl`` (without it, the previous cells are moved to
``cells.jsonl.prev`` so results of older code never mix with new ones); the robustness bags are
cached there by their parameters. ``--render`` runs nothing and rewrites the page from the saved
results. ``--only`` runs a subset; the page then shows the
other benches' last saved raw results when ``results/<bench>.json`` exists (and says so).
"""
from __future__ import annotations

import argparse
import contextlib
import datetime
import io
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from importlib import import_module
from pathlib import Path

import numpy as np

from isa_mocap_ros.bench._common import comma_list, energy_sizes, json_of

#: Run order of ``bench all``: the timed benches first, on a rested machine. After the 20 minutes of
#: both cores at full load that ackley, compare and robustness take, the node network's real-time run
#: in ``speed`` dropped 24 of 145 frame sets (tracker 31 ms a frame, p50) where the same bench alone
#: a minute later dropped 6 (22.7 ms; session 12, docs/evaluation.md).
ORDER = ("energy", "speed", "adapters", "render", "ackley", "compare", "robustness", "mesh_baseline", "mesh",
         "mesh_motions", "keypoints", "real")
_MOTIONS = "isa_mocap_ros.bench.mesh_motions"      # its runner and section live there (bench all: for_all, section)
_SRC_ROOT = Path(__file__).resolve().parents[2]


def default_results_path() -> Path:
    docs = _SRC_ROOT / "docs"
    return docs / "RESULTS.md" if docs.is_dir() else Path("RESULTS.md")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="every bench's --quick variant (smoke; minutes)")
    p.add_argument("--results", default=None, metavar="PATH",
                   help=f"results page to write (default {default_results_path()}); figures go to PATH's folder/results/")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="work directory (default out/bench; --quick: a temporary directory)")
    p.add_argument("--jobs", type=int, default=2, metavar="N", help="worker processes of the comparison (default 2)")
    p.add_argument("--only", default=None, metavar="A,B", help=f"run only these benches (of {', '.join(ORDER)})")
    p.add_argument("--resume", action="store_true",
                   help="continue the comparison of the last run in --out (its cells.jsonl) instead of starting anew; "
                        "only with unchanged code")
    p.add_argument("--render", action="store_true",
                   help="run nothing: rewrite the page from the saved results (PATH's folder/results/<bench>.json), "
                        "e.g. after one bench was run alone with --json there")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


# ------------------------------------------------------------------ machine and provenance
def machine() -> dict:
    cpu = ""
    try:
        cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), "")
    except OSError:
        pass
    ram = None
    try:
        kb = next(int(ln.split()[1]) for ln in open("/proc/meminfo") if ln.startswith("MemTotal"))
        ram = round(kb / 1024 ** 2, 1)
    except (OSError, StopIteration, ValueError):
        pass
    try:
        avail = len(os.sched_getaffinity(0))
    except AttributeError:
        avail = os.cpu_count()
    return {"host": platform.node(), "cpus": os.cpu_count(), "cpus_available": avail, "cpu_model": cpu or "unknown",
            "ram_gb": ram, "os": f"{platform.system()} {platform.release()}", "python": platform.python_version()}


def git_commit() -> str:
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=_SRC_ROOT, capture_output=True, text=True,
                             timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=_SRC_ROOT,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown (no git)"
    if not sha:
        return "unknown (not a git checkout)"
    return sha + (" with uncommitted changes" if dirty else "")


# ------------------------------------------------------------------ one bench each: data + markdown + figure
def _bench_ackley(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench import ackley as bench_ackley

    runs = 5 if quick else 50
    return {"runs": runs, "rows": bench_ackley.collect(runs, 0, quick=quick, jobs=ctx.get("jobs", 2))}


def _bench_adapters(quick: bool, ctx: dict) -> dict:
    from msg_adapters import bench as bench_adapters

    return {"rows": json_of(bench_adapters, ["--number", "5", "--repeat", "2"] if quick else [])}


def _bench_render(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench import render as bench_render

    return json_of(bench_render, ["--repeats", "3", "--particles", "100"] if quick else [])


def _bench_energy(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench import energy as bench_energy

    return json_of(bench_energy, ["--quick"] if quick else [])


def _bench_compare(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench.compare import collect

    summary, design, seconds = collect("quick" if quick else "default", ctx["out"] / "compare", jobs=ctx["jobs"],
                                       progress=ctx["progress"])
    summary["seconds"] = round(seconds, 1)
    return summary


def _bench_robustness(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench import robustness as br

    # the paper's protocol on renders of the tracking model with its true shape: issue 33's capsule control
    # (mesh bodies under noise and occluders, automatic shape: bench mesh, the headline)
    design = br.make_design("quick" if quick else "default", body="capsules", shape="truth")
    for n in design.notes:
        print(f"bench robustness: {n}", file=sys.stderr)
    return br.collect(design, cache=ctx["out"] / "cache" / "robustness", out=ctx["out"] / "robustness",
                      progress=ctx["progress"])


def _bench_mesh_baseline(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench import mesh_baseline as mb

    return mb.collect(jobs=ctx["jobs"], out=ctx["out"] / "mesh_baseline", quick=quick)


def _bench_mesh(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench import mesh as bm

    return bm.collect(bm.make_design("quick" if quick else "default"), cache=ctx["out"] / "cache" / "robustness",
                      out=ctx["out"] / "mesh", jobs=ctx["jobs"], progress=ctx["progress"])


def _bench_keypoints(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench import keypoints_summary

    return keypoints_summary.collect(quick=quick, out=ctx["out"])


def _bench_real(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench import real

    if quick:      # a smoke test: the default shape offline, no network run
        return real.collect(quick=True, out=ctx["out"] / "real", configs=("default",), lockstep=None)
    return real.collect(quick=False, out=ctx["out"] / "real")


def _bench_speed(quick: bool, ctx: dict) -> dict:
    from isa_mocap_ros.bench import speed as bench_speed

    bp = argparse.ArgumentParser()
    bench_speed.add_arguments(bp)
    return bench_speed.collect(bp.parse_args(["--quick"] if quick else []))


RUNNERS = {"ackley": _bench_ackley, "adapters": _bench_adapters, "render": _bench_render, "energy": _bench_energy,
           "compare": _bench_compare, "robustness": _bench_robustness, "speed": _bench_speed,
           "mesh_baseline": _bench_mesh_baseline, "mesh": _bench_mesh, "keypoints": _bench_keypoints,
           "real": _bench_real, "mesh_motions": lambda quick, ctx: import_module(_MOTIONS).for_all(quick, ctx)}


# ------------------------------------------------------------------ markdown sections
def _f(v, fmt="{:.2f}") -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "-"
    return fmt.format(v)


def md_ackley(d: dict) -> str:
    book = [r for r in d["rows"] if "selection_mean_steps" not in r]
    searched = [r for r in d["rows"] if "selection_mean_steps" in r]
    L = [f"{d['runs']} runs per row (paper: 50), 2-D Ackley on [-4, 4]², ≤ 999 steps; δ = 1e-3 (noisy: σ = 0.5, δ = 1e-2). "
         "Protocol: `isa_mocap_ros/bench/ackley.py`, [docs/optimizers.md](optimizers.md).", "",
         "Readings of the dynamic variance scheme (13.16): its particles, *population* = the equation as printed, "
         "*selected* = the selected particles (the text's \"after resampling\"); what the book's c multiplies, "
         "*deviation* = the standard deviation (Fig. 13.13), *covariance* = the covariance as (13.16) prints it. "
         "The first reading (population, deviation) is the benchmark's.", "",
         "**At the book's parameters** (b, c of Table 13.1, n of Table 13.2):", "",
         "| method | (13.16) | c scales | noise | n | b | c | mean steps | paper | diff | success | mean evaluations |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in book:
        L.append(f"| {r['method']} | {r.get('variance') or '-'} | {r.get('c_scale') or '-'} | {r['noise']:.1f} | {r['n']} | {_f(r['b'], '{:.3f}')} | {_f(r['c'], '{:.1f}')} | "
                 f"{_f(r['mean_steps'])} | {_f(r['paper_mean_steps'])} | {_pct(r['mean_steps'], r['paper_mean_steps'])} | "
                 f"{100 * r['success_rate']:.0f} % | {_f(r['mean_evals'], '{:.0f}')} |")
    if searched:
        r0 = searched[0]
        L += ["", f"**Searched as the book did**: Table 13.1 = the (b, c) with the lowest mean steps at n = 50 over Fig. 13.5's "
              "grid; Table 13.2 = with those b, c, the n with the lowest cost n·t over 4..200 step 2; only cells where every run "
              f"reaches δ. Chosen on {r0['selection_runs']} runs, measured on {r0['held_out_runs']} held-out runs "
              "(the figures below; *chosen* is the biased-low mean the choice was made on).", "",
              "| method | (13.16) | c scales | noise | paper n / b / c | ours n / b / c | chosen | mean steps | paper | diff | "
              "success | n·t | paper n·t |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in searched:
            m = r["mean_steps"]
            L.append(f"| {r['method']} | {r['variance']} | {r.get('c_scale') or '-'} | {r['noise']:.1f} | {r['paper_n']} / {r['paper_b']:.3f} / {r['paper_c']:.1f} | "
                     f"{r['n']} / {r['b']:.3f} / {r['c']:.1f} | {_f(r['selection_mean_steps'])} | {_f(m)} | "
                     f"{_f(r['paper_mean_steps'])} | {_pct(m, r['paper_mean_steps'])} | {100 * r['success_rate']:.1f} % | "
                     f"{_f(None if m is None else r['n'] * m, '{:.0f}')} | {r['paper_n'] * r['paper_mean_steps']:.0f} |")
    return "\n".join(L) + "\n"


def _pct(m, p) -> str:
    return "-" if (m is None or p is None) else f"{100 * (m - p) / p:+.0f} %"


def md_adapters(d: dict) -> str:
    L = ["Microseconds per call, best of the rounds (`isa-mocap bench adapters`).", "", "| conversion | µs |", "|---|---|"]
    for k, v in d["rows"].items():
        L.append(f"| {k} | {v:.2f} |")
    return "\n".join(L) + "\n"


def md_render(d: dict) -> str:
    return "\n".join([
        f"{d['width']}×{d['height']}, {d['capsules']} capsules, {d['views']} views, {d['threads']} numba threads "
        f"(`isa-mocap bench render`).", "", "| operation | ms (median) | ms (min) |", "|---|---|---|",
        f"| render, per view | {d['render_ms_per_view']:.3f} | {d['render_ms_per_view_min']:.3f} |",
        f"| render_mask, per view | {d['render_mask_ms_per_view']:.3f} | {d['render_mask_ms_per_view_min']:.3f} |",
        f"| project_batch ({d['project_batch_points']} points) | {d['project_batch_ms']:.3f} | {d['project_batch_ms_min']:.3f} |",
        f"| first render per camera (ray set-up) | {d['first_render_ms_per_view']:.2f} | |"]) + "\n"


def md_energy(d: dict) -> str:
    return "\n".join([
        f"{d['dof']} DOF, {d['views']} views 320×240, batch {d['batch']} (`isa-mocap bench energy`; the exact reference "
        f"measured on {d['exact_batch']} poses){energy_sizes(d)}.", "", "| energy | evaluations/s |", "|---|---|",
        f"| fast (compiled kernel) | {d['fast_evals_per_s']:.0f} |", f"| exact (raster reference) | {d['exact_evals_per_s']:.0f} |",
        f"| ratio | {d['ratio']:.0f}× |"]) + "\n"


def md_compare(d: dict) -> str:
    from isa_mocap_ros.eval.compare import render_markdown

    ds = d["design"]
    head = [f"Design `{ds['name']}`: algorithms {', '.join(ds['algorithms'])}; models {ds['models']}; budgets "
            f"{ds['budgets']}; {len(ds['seeds'])} seed(s); sequences "
            + ", ".join(f"{s['name']} ({round(s['duration_s'] * s['fps'])} frames at {s['fps']:g} fps, {s['views']} views "
                        f"{s['width']}×{s['height']})" for s in ds["sequences"])
            + f"; {d['records']} runs in {d.get('seconds', 0):.0f} s; frames that fell back: {d['fell_back_frames']}. "
            "Protocol: [docs/evaluation.md](evaluation.md).", ""]
    from isa_mocap_ros.bench.compare import shape_line

    head += [shape_line(d), ""]
    for n in ds.get("notes", []):
        head += [f"- note: {n}", ""]
    return "\n".join(head) + "\n" + render_markdown(d)


def md_findings(d: dict) -> str:
    from isa_mocap_ros.eval.compare import findings

    L = ["Checked on the comparison's cell means (mean over seeds), matched comparisons, Wilcoxon signed-rank test. "
         "*holds*: the claimed side has the lower error in most matched comparisons and p < 0.05; *not significant*: "
         "lower in most, p ≥ 0.05; *does not hold*: not lower in most.", "",
         "| finding (EA-vs-PF paper) | matched | claimed side better | mean error (other / claimed side) | Wilcoxon p | verdict |",
         "|---|---|---|---|---|---|"]
    for r in findings(d):
        if not r["n"]:
            L.append(f"| {r['claim']} | 0 | | | | not tested (no data) |")
            continue
        L.append(f"| {r['claim']} | {r['n']} | {r['better']}/{r['n']} | {r['mean_a_mm']:.1f} / {r['mean_b_mm']:.1f} mm "
                 f"({r['a']} / {r['b']}) | {_f(r['wilcoxon_p'], '{:.3g}')} | **{r['verdict']}** |")
    return "\n".join(L) + "\n"


def md_robustness(d: dict) -> str:
    from isa_mocap_ros.bench.robustness import render_markdown

    return "Protocol: ISA §13.4.2, `isa_mocap_ros/bench/robustness.py` (module docstring).\n\n" + render_markdown(d)


def md_mesh_baseline(d: dict) -> str:
    from isa_mocap_ros.bench.mesh_baseline import render_markdown

    return render_markdown(d)


def md_mesh(d: dict) -> str:
    from isa_mocap_ros.bench.mesh import render_markdown

    return "`isa-mocap bench mesh` (module docstring; limits: docs/shape_calibration.md, docs/tracking.md).\n\n" \
        + render_markdown(d) + "\n"


def md_keypoints(d: dict) -> str:
    from isa_mocap_ros.bench.keypoints_summary import render_markdown

    return render_markdown(d)


def md_real(d: dict) -> str:
    from isa_mocap_ros.bench.real import render_markdown

    return render_markdown(d)


def md_speed(d: dict) -> str:
    from isa_mocap_ros.bench.speed import render_markdown

    return "Measured in one run, one part after the other (`isa-mocap bench speed`).\n\n" + render_markdown(d)


def targets(data: dict) -> list[tuple[str, str, str]]:
    """``(target, measured, status)`` rows of issue #7's targets, from the measured numbers."""
    from isa_mocap_ros.bench.robustness import render_targets
    from isa_mocap_ros.eval.compare import peer_targets

    rows = []
    cmp_ = data.get("compare")
    pts = peer_targets(cmp_) if cmp_ else []
    if pts:
        for t in pts:
            vals = ", ".join(f"{s} {v['ours_mm']:.1f} vs {v['peer_mm']:.1f} mm" for s, v in t["per_sequence"].items())
            rows.append((f"best of ours at 1500 evaluations ({t['model']} DOF: {t['ours']}) beats {t['peer']} on every "
                         "sequence", vals, "met" if t["met"] else "not met"))
    else:
        rows.append(("best of ours at 1500 evaluations beats pycma and scipy-DE on every sequence",
                     "no 1500-evaluation peer runs in this design", "not tested"))
    rob = data.get("robustness")
    if rob:
        for name, vals, met in render_targets(rob):
            rows.append((name, vals, "met" if met else "not met"))
    else:
        rows.append(("clean walk ≤ 25 mm and ≤ 2°; 70 % noise ≤ 3.5°; 35 occluders ≤ 4.0°", "robustness not run",
                     "not tested"))
    return rows


def headlines(data: dict) -> list[str]:
    """One line per bench with its main measured figure (for the page's top and the closing note)."""
    out = []
    me = data.get("mesh")
    if me and me.get("conditions"):
        def one(x):
            if x.get("mapped_mpjpe_mm") is not None and np.isfinite(x["mapped_mpjpe_mm"]):
                return (f"{x['label']} {x['mapped_mpjpe_mm']:.1f} mm mapped ({x['mpjpe_mm']:.1f} raw, "
                        f"{x['offset_removed_mpjpe_mm']:.1f} offset removed), knee {x['mapped_knee_rmse_deg']:.2f}° "
                        f"mapped, {x['backwards_runs']} run(s) backwards")
            return (f"{x['label']} {x['mpjpe_mm']:.1f} mm ({x['offset_removed_mpjpe_mm']:.1f} mm offset removed), knee "
                    f"{x['knee_rmse_deg']:.2f}°, {x['backwards_runs']} run(s) backwards")
        out.append("**mesh subjects, everything automatic** (shape, initialization; bench mesh): "
                   + "; ".join(one(x) for x in me["conditions"]))
    c = data.get("compare")
    if c and c.get("mean_over_sequences_mm"):
        from isa_mocap_ros.eval.compare import PEER_ALGORITHMS, label
        for d in c["models"]:
            b = 1500 if 1500 in c["budgets"] else c["budgets"][-1]
            cand = [(c["mean_over_sequences_mm"][label(a, d, b)], a) for a in c["algorithms"]
                    if label(a, d, b) in c["mean_over_sequences_mm"] and a not in PEER_ALGORITHMS]
            peers = {a: c["mean_over_sequences_mm"][label(a, d, b)] for a in c["algorithms"]
                     if a in PEER_ALGORITHMS and label(a, d, b) in c["mean_over_sequences_mm"]}
            if cand:
                e, a = min(cand)
                out.append(f"comparison, {d} DOF, {b} evaluations: best of ours {a} {e:.1f} mm mean joint error over "
                           f"{len(c['sequences'])} sequence(s)"
                           + "".join(f"; {p} {v:.1f} mm" for p, v in peers.items()))
    r = data.get("robustness")
    if r and r.get("conditions"):
        out.append("robustness, knee RMSE (ours vs the ISA paper): " + "; ".join(
            f"{x['label']} {x['knee_rmse_deg']:.2f}° vs {x['paper_knee_rmse_deg']:.2f}° ({x['mpjpe_mm']:.1f} mm)"
            for x in r["conditions"]))
    sp = data.get("speed")
    if sp:
        e = sp["energy"]
        line = (f"speed: scanline energy (the default) {e['raster_evals_per_s']:.0f} evaluations/s ({e['raster_ratio']:.0f}× "
                f"the exact one); " if e.get("raster_evals_per_s") else "speed: ")
        line += f"fast energy {e['fast_evals_per_s']:.0f} evaluations/s ({e['ratio']:.0f}× the exact one); tracker " \
            + ", ".join(f"{x['frames_per_s']:.2f} frames/s at {x['evals_per_frame']}" for x in sp["tracker"]["rows"])
        for x in sp["network"]["rows"]:
            if "error" not in x and x.get("fps") is not None:
                line += (f"; network {x['mode']} {x['fps']:.2f} frame sets/s, p95 latency {_f(x['latency_ms_p95'], '{:.0f}')} ms, "
                         f"{x.get('dropped_frames')} of {x.get('frame_sets_played')} frame sets dropped")
        pr = sp.get("profile")
        if pr:
            top = sorted((r for r in pr["by_stage"]), key=lambda r: -r["cpu_ms_per_frame"])[:3]
            line += (f"; tracked frame at {pr['evals_per_frame']} evaluations: {pr['cpu_ms_per_frame']:.1f} CPU ms, most in "
                     + ", ".join(f"{r['stage']} {100 * r['share']:.0f} %" for r in top))
        out.append(line)
    a = data.get("ackley")
    if a:
        readings = list(dict.fromkeys((x.get("variance"), x.get("c_scale")) for x in a["rows"] if x["kernel"]))
        for v, cs in readings:
            mine = [x for x in a["rows"] if (x.get("variance"), x.get("c_scale")) == (v, cs)]
            for label, isa in (("at the book's parameters", [x for x in mine if "selection_mean_steps" not in x]),
                               ("searched as the book did", [x for x in mine if "selection_mean_steps" in x])):
                if not isa:
                    continue
                ok = sum(1 for x in isa if x["success_rate"] == 1.0)
                clean = [x for x in isa if not x["noise"] and x["mean_steps"] is not None]
                worst = max((abs(x["mean_steps"] / x["paper_mean_steps"] - 1) for x in clean), default=float("nan"))
                runs = isa[0].get("held_out_runs", a["runs"])
                how = f"*{v}*" + (f", c scaling the *{cs}*" if cs else "")
                out.append(f"Ackley, ISA with (13.16) read as {how}, {label}: {ok} of {len(isa)} rows reach δ in "
                           f"every run ({runs} runs per row); noiseless rows' mean steps within ±{100 * worst:.0f} % "
                           "of the paper")
    return out


SECTIONS = (("mesh", "Headline: mesh subjects, automatic shape and initialization (issue 33)", md_mesh),
            ("ackley", "Ackley function (ISA §13.4.1, Tables 13.1-13.2)", md_ackley),
            ("compare", "Optimizer comparison (EA-vs-PF §5.2-5.4, with pycma and scipy-DE)", md_compare),
            ("robustness", "Robustness: noise and occlusions (ISA §13.4.2)", md_robustness),
            ("mesh_motions", "Unseen motions on mesh subjects (issue 33)", lambda d: import_module(_MOTIONS).section(d)),
            ("mesh_baseline", "Mesh bodies vs capsules (issue 32's baseline)", md_mesh_baseline),
            ("keypoints", "Learned keypoints: cost and tracking with the term (issue 36)", md_keypoints),
            ("real", "The real recording: Pose2Sim demo against the peer's keypoints (issue 34)", md_real),
            ("speed", "Speed: energy, tracker, node network", md_speed),
            ("energy", "Silhouette energy speed", md_energy),
            ("render", "Renderer speed", md_render),
            ("adapters", "Message adapter speed", md_adapters))


def figures(data: dict, fig_dir: Path) -> dict:
    """Write the figures; ``{bench: [relative paths]}``."""
    fig_dir.mkdir(parents=True, exist_ok=True)
    out: dict = {}
    if "compare" in data and data["compare"].get("cells"):
        from isa_mocap_ros.eval.compare import plot_summary
        out["compare"] = [plot_summary(data["compare"], fig_dir / "compare_error_vs_budget.png")]
    if "robustness" in data and data["robustness"].get("runs"):
        from isa_mocap_ros.bench.robustness_plots import plot, plot_bars
        out["robustness"] = [plot_bars(data["robustness"], fig_dir / "robustness_knee_rmse.png"),
                             plot(data["robustness"], fig_dir / "robustness_knees.png")]
    if "speed" in data:
        from isa_mocap_ros.bench.speed import plot
        out["speed"] = [plot(data["speed"], fig_dir / "speed_tracker_fps.png")]
    if "ackley" in data:
        out["ackley"] = [_plot_ackley(data["ackley"], fig_dir / "ackley_steps.png")]
    return out


def _plot_ackley(d: dict, path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    first = next((r.get("variance"), r.get("c_scale")) for r in d["rows"] if r["kernel"] is not None)
    rows = [r for r in d["rows"] if r["paper_mean_steps"] is not None and r["mean_steps"] is not None
            and (r.get("variance"), r.get("c_scale")) == first]
    fig, ax = plt.subplots(figsize=(10, 3.8))
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["paper_mean_steps"] for r in rows], 0.4, label="paper", color="0.6")
    ax.bar(x + 0.2, [r["mean_steps"] for r in rows], 0.4, label="measured", color="tab:blue")
    ax.set_xticks(x, [f"{r['kernel'].upper()} n={r['n']}{' noisy' if r['noise'] else ''}"
                      f"{' (searched)' if 'selection_mean_steps' in r else ''}" for r in rows],
                  rotation=40, ha="right", fontsize=7)
    ax.set_ylabel("mean steps to δ")
    ax.set_title(f"Ackley, ISA ((13.16): {first[0]}, c on the {first[1]}) vs the paper's Tables 13.1-13.2 "
                 "(searched: b, c, n chosen as the book did; held-out runs)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return Path(path)


def render_page(data: dict, *, meta: dict, figs: dict, page: Path, stale: set) -> str:
    m = meta["machine"]
    L = ["# Results", "",
         "Generated by `isa-mocap bench all` (`make bench`); do not edit by hand. Protocols: "
         "[evaluation.md](evaluation.md), [optimizers.md](optimizers.md), [tracking.md](tracking.md).", ""]
    if meta["quick"]:
        L += ["> **Smoke run** (`--quick` variants): tiny designs that check the pipeline end to end. Their numbers say "
              "nothing about the algorithms; `make bench` produces the real page.", ""]
    L += [f"- command: `{meta['command']}`", f"- date: {meta['date']} (wall time {meta['seconds'] / 60:.1f} min)",
          f"- git commit: {meta['commit']}",
          f"- machine: {m['cpus']} CPUs ({m['cpus_available']} available), {m['cpu_model']}, "
          f"{_f(m['ram_gb'], '{:.1f}')} GB RAM, {m['os']}, Python {m['python']} ({m['host']})", ""]
    if stale:
        L += [f"- not re-run this time (last saved results shown): {', '.join(sorted(stale))}", ""]
    heads = headlines(data)
    if heads:
        L += ["## Headline figures", ""] + [f"- {h}" for h in heads] + [""]
    L += ["## Targets (issue #7), from the measured numbers", "", "| target | measured | status |", "|---|---|---|"]
    for name, vals, st in targets(data):
        L.append(f"| {name} | {vals} | **{st}** |")
    L.append("")
    if "compare" in data:
        L += ["## The comparison paper's findings, checked on our data", "", md_findings(data["compare"])]
    for key, title, fn in SECTIONS:
        if key not in data:
            continue
        L += [f"## {title}", "", f"Time: {data[key].get('_seconds', 0):.0f} s." if "_seconds" in data[key] else "", ""]
        for p in figs.get(key, []):
            rel = os.path.relpath(p, page.parent)
            L += [f"![{key}]({rel})", ""]
        L.append(fn(data[key]))
    return "\n".join(L).replace("\n\n\n", "\n\n") + "\n"


def run(args: argparse.Namespace) -> int:
    if args.jobs < 1:
        print(f"isa-mocap bench all: error: --jobs: expected an integer >= 1, received {args.jobs}", file=sys.stderr)
        return 2
    only = ORDER
    if args.only:
        only = comma_list(args.only)
        bad = [x for x in only if x not in ORDER]
        if bad:
            print(f"isa-mocap bench all: error: --only: expected names of {', '.join(ORDER)}, received {bad}",
                  file=sys.stderr)
            return 2
    if getattr(args, "render", False):
        only = ()
    page = Path(args.results) if args.results else default_results_path()
    fig_dir = page.parent / "results"
    tmp = None
    if args.out:
        out = Path(args.out)
    elif args.quick:
        tmp = out = Path(tempfile.mkdtemp(prefix="isa_mocap_bench_all_"))
    else:
        out = Path("out/bench")
    out.mkdir(parents=True, exist_ok=True)
    fig_dir.mkdir(parents=True, exist_ok=True)
    commit = git_commit()          # before anything is written
    jl = out / "compare" / "cells.jsonl"
    if "compare" in only and jl.exists() and not getattr(args, "resume", False):
        # results of older code must not mix with this run's: start the comparison anew
        jl.replace(jl.with_name("cells.jsonl.prev"))
        print(f"bench all: moved the previous comparison cells to {jl.with_name('cells.jsonl.prev')} "
              "(--resume continues them instead)", file=sys.stderr)
    ctx = {"out": out, "jobs": args.jobs, "progress": not args.no_progress}
    data: dict = {}
    stale: set = set()
    t_all = time.perf_counter()
    rc = 0
    try:
        for name in ORDER:
            if name not in only:
                saved = fig_dir / f"{name}.json"
                if saved.is_file():
                    data[name] = json.loads(saved.read_text())
                    stale.add(name)
                continue
            print(f"== bench {name}{' --quick' if args.quick else ''}", file=sys.stderr, flush=True)
            t0 = time.perf_counter()
            try:
                d = RUNNERS[name](args.quick, ctx)
            except KeyboardInterrupt:
                raise
            except Exception as exc:  # a failing bench must not lose the others' results
                print(f"bench all: {name} failed: {type(exc).__name__}: {exc}", file=sys.stderr)
                rc = 1
                continue
            d["_seconds"] = round(time.perf_counter() - t0, 1)
            data[name] = d
            (fig_dir / f"{name}.json").write_text(json.dumps(d) + "\n")
            print(f"== bench {name}: {d['_seconds']:.0f} s", file=sys.stderr, flush=True)
        figs = figures(data, fig_dir)
        cmd = "isa-mocap bench all" + (" --quick" if args.quick else "") + (f" --only {args.only}" if args.only else "") \
            + (f" --jobs {args.jobs}" if args.jobs != 2 else "") + (" --resume" if args.resume else "") \
            + (" --render" if getattr(args, "render", False) else "") + (f" --results {args.results}" if args.results else "")
        meta = {"command": cmd, "quick": bool(args.quick), "machine": machine(), "commit": commit,
                "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
                "seconds": time.perf_counter() - t_all}
        page.write_text(render_page(data, meta=meta, figs=figs, page=page, stale=stale))
        print(f"bench all: wrote {page} and {fig_dir}/ in {meta['seconds'] / 60:.1f} min")
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return rc
