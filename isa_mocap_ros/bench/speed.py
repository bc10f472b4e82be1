"""Speed side by side: energy evaluations/s, tracker frames/s per budget, the node network on the demo bag.

``isa-mocap bench speed [--quick] [--json] [--frames N] [--no-network]``. Measured in one run, one
after the other on the same machine:

1. **energy**: evaluations per second of the fast silhouette kernel and of the exact raster
   reference (``isa-mocap bench energy``'s code and scene: 39 DOF, 4 views 320×240, batch 1500);
2. **tracker**: frames per second of the offline tracker (``isa-mocap track``'s code,
   :func:`isa_mocap_ros.cli.track.track_bag`) at 500 / 1500 / 3000 evaluations per frame on the
   first ``--frames`` (default 30) frames of ``bags/demo`` after its background frames: h-isa, 39
   DOF, images segmented as ``isa-mocap track`` does, first frame from the ground truth; the rate is
   frames over the summed wall time of the tracker's steps (segmentation and bag reading excluded),
   and the whole call's wall time is reported too (after an unreported warm-up call that loads or
   compiles the compiled kernels);
3. **network**: ``isa-mocap run``'s code (:mod:`isa_mocap_ros.cli.run`: segmentation, prediction and
   estimator nodes and a recorder, each its own process, over DDS on localhost) on ``bags/demo``,
   once in real time (rate 1.0: frames the estimator cannot keep up with are dropped) and once in
   lockstep: frame sets processed per second of replay, the real-time factor (that rate over the
   bag's 30 frames/s), latency p50 / p95 (image received → estimate received, the recorder's clock),
   dropped frame sets, and the mean joint error.

``--quick`` (tests): energy at small sizes, the tracker on 3 frames of ``bags/fixture`` (its exact
masks), no network part (``--network`` adds it on ``bags/fixture`` in lockstep).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BUDGETS = (500, 1500, 3000)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="small sizes, bags/fixture, no network part (tests)")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("--frames", type=int, default=None, help="frames tracked per budget (default 30; --quick 3)")
    p.add_argument("--optimizer", default="h-isa", help="optimizer of the tracker and network parts (default h-isa)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--no-network", action="store_true", help="skip the node network part")
    g.add_argument("--network", action="store_true", help="run the node network part with --quick too")


def energy_speed(quick: bool) -> dict:
    from isa_mocap_ros.bench import energy as bench_energy
    from isa_mocap_ros.bench._common import json_of

    return json_of(bench_energy, ["--quick"] if quick else [])


def tracker_speed(bag: Path, *, frames: int, budgets=BUDGETS, optimizer: str = "h-isa", use_masks: bool = False,
                  work: Path) -> list[dict]:
    """Offline tracker frames/s per budget (``isa-mocap track``'s code)."""
    from isa_mocap_ros.cli.track import track_bag

    def ns(b: int, n: int, name: str) -> argparse.Namespace:
        return argparse.Namespace(
            bag=str(bag), out=str(work / name), optimizer=optimizer, evals=int(b), params=None, model=None,
            seed=0, frames=n, start=0, use_masks=use_masks, learn_frames=None, shape="truth", init="truth",
            predictor=None, prior=None, prior_eta=0.0, energy="fast", overwrite=True, no_progress=True)

    # warm-up (not reported): loads or compiles every numba function the tracker calls
    track_bag(ns(min(budgets), 3, "track_warmup"))
    rows = []
    for b in budgets:
        got: dict = {}
        t0 = time.perf_counter()
        s = track_bag(ns(b, frames + 1, f"track_{b}"), collect=got)
        wall = time.perf_counter() - t0
        steps = np.array(list(got["step_seconds"].values()), dtype=float)
        rows.append({"evals_per_frame": int(b), "frames": int(steps.size),
                     "frames_per_s": float(steps.size / steps.sum()) if steps.sum() > 0 else float("nan"),
                     "ms_per_frame_p50": float(np.median(steps) * 1e3), "ms_per_frame_max": float(steps.max() * 1e3),
                     "evals_per_s": float(b * steps.size / steps.sum()) if steps.sum() > 0 else float("nan"),
                     "wall_seconds": round(wall, 2), "mpjpe_mm": s.get("mpjpe_mm")})
    return rows


def network_speed(bag: Path, *, mode: str, optimizer: str, work: Path) -> dict:
    """``isa-mocap run`` on ``bag`` in real time (rate 1.0) or lockstep; the summary's speed figures."""
    from isa_mocap_ros.cli import run as run_cli

    out = work / f"run_{mode}"
    p = argparse.ArgumentParser()
    run_cli.add_run_arguments(p)
    argv = [str(bag), "--out", str(out), "--quiet", "--overlay-frames", "0", "--optimizer", optimizer]
    argv += ["--lockstep"] if mode == "lockstep" else ["--rate", "1.0"]
    buf = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(buf):
        rc = run_cli.run(p.parse_args(argv))
    wall = time.perf_counter() - t0
    if rc != 0 or not (out / "summary.json").is_file():
        return {"mode": mode, "error": f"isa-mocap run exited with {rc}; see {out / 'nodes.log'}",
                "wall_seconds": round(wall, 1)}
    s = json.loads((out / "summary.json").read_text())
    bag_fps = _bag_fps(bag)
    keep = ("frame_sets_played", "frames_processed", "frames_estimated", "fps", "latency_ms_p50", "latency_ms_p95",
            "dropped_frames", "dropped_while_initializing", "frames_without_contour_stage", "init_ms", "tracker_ms_p50", "tracker_ms_p95", "mpjpe_mm", "knee_rmse_deg", "evals_per_frame", "optimizer")
    r = {"mode": mode, **{k: s.get(k) for k in keep}, "bag_fps": bag_fps, "wall_seconds": round(wall, 1)}
    r["real_time_factor"] = (s["fps"] / bag_fps) if bag_fps and s.get("fps") and np.isfinite(s["fps"]) else None
    return r


def _bag_fps(bag: Path) -> float | None:
    from isa_mocap_ros.bag import BagReader
    import msg_adapters as ma

    with BagReader(bag) as r:
        st = sorted({ma.header_stamp_ns_from_cdr(m.data) for m in r.messages(["/mocap/cam0/image_raw"])})
    if len(st) < 2:
        return None
    return float(1e9 / np.median(np.diff(st)))


def collect(args: argparse.Namespace) -> dict:
    from isa_mocap_ros.resources import resource_dir

    bags = resource_dir("bags")
    frames = args.frames or (3 if args.quick else 30)
    work = Path(tempfile.mkdtemp(prefix="isa_mocap_speed_"))
    t0 = time.perf_counter()
    try:
        res: dict = {"quick": bool(args.quick)}
        print("bench speed: energy ...", file=sys.stderr, flush=True)
        res["energy"] = energy_speed(args.quick)
        tbag = bags / ("fixture" if args.quick else "demo")
        print(f"bench speed: tracker on {tbag.name}, {frames} frames per budget ...", file=sys.stderr, flush=True)
        res["tracker"] = {"bag": tbag.name, "optimizer": args.optimizer, "frames": frames,
                          "rows": tracker_speed(tbag, frames=frames, optimizer=args.optimizer,
                                                use_masks=args.quick, work=work)}
        net = (not args.no_network) and (not args.quick or args.network)
        if net:
            nbag = bags / ("fixture" if args.quick else "demo")
            modes = ("lockstep",) if args.quick else ("real time", "lockstep")
            rows = []
            for m in modes:
                print(f"bench speed: node network on {nbag.name}, {m} ...", file=sys.stderr, flush=True)
                rows.append(network_speed(nbag, mode=m, optimizer=args.optimizer, work=work))
            res["network"] = {"bag": nbag.name, "rows": rows}
        else:
            res["network"] = {"skipped": "--quick" if args.quick else "--no-network", "rows": []}
    finally:
        shutil.rmtree(work, ignore_errors=True)
    res["seconds"] = round(time.perf_counter() - t0, 1)
    return res


def _f(v, fmt="{:.1f}"):
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else fmt.format(v)


def render_markdown(res: dict) -> str:
    from isa_mocap_ros.bench._common import energy_sizes

    e = res["energy"]
    L = ["#### Silhouette energy", "",
         f"{e['dof']} DOF, {e['views']} views, batch {e['batch']} (exact reference measured on {e['exact_batch']} poses"
         f"{energy_sizes(e)}).",
         "", "| energy | evaluations/s |", "|---|---|",
         f"| fast (compiled kernel) | {e['fast_evals_per_s']:.0f} |", f"| exact (raster reference) | {e['exact_evals_per_s']:.0f} |",
         f"| ratio | {e['ratio']:.0f}× |", ""]
    t = res["tracker"]
    L += ["#### Offline tracker", "",
          f"`bags/{t['bag']}`, {t['optimizer']}, {t['frames']} frames per budget after a ground-truth first frame; "
          "frames/s over the tracker's steps (segmentation and bag reading excluded).", "",
          "| evaluations/frame | frames/s | ms/frame (median) | ms/frame (max) | evaluations/s | call wall time (s) |",
          "|---|---|---|---|---|---|"]
    for r in t["rows"]:
        L.append(f"| {r['evals_per_frame']} | {_f(r['frames_per_s'], '{:.2f}')} | {_f(r['ms_per_frame_p50'], '{:.0f}')} | "
                 f"{_f(r['ms_per_frame_max'], '{:.0f}')} | {_f(r['evals_per_s'], '{:.0f}')} | {r['wall_seconds']:.1f} |")
    n = res["network"]
    L += ["", "#### Node network (`isa-mocap run`)", ""]
    if not n["rows"]:
        L.append(f"Skipped ({n.get('skipped')}).")
    else:
        L += [f"`bags/{n['bag']}`, segmentation + prediction + estimator + recorder processes over DDS (localhost).", "",
              "| mode | frame sets played | processed | frames/s | real-time factor | latency p50 (ms) | latency p95 (ms) | dropped | of them while initializing | without the contour stage | initialization (ms) | tracker ms per set p50 / p95 | mean joint error (mm) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in n["rows"]:
            if "error" in r:
                L.append(f"| {r['mode']} | failed: {r['error']} | | | | | | | | | | | |")
                continue
            L.append(f"| {r['mode']} | {r['frame_sets_played']} | {r['frames_processed']} | {_f(r['fps'], '{:.2f}')} | "
                     f"{_f(r['real_time_factor'], '{:.2f}')} | {_f(r['latency_ms_p50'], '{:.0f}')} | "
                     f"{_f(r['latency_ms_p95'], '{:.0f}')} | {r['dropped_frames']} | "
                     f"{_f(r.get('dropped_while_initializing'), '{}')} | "
                     f"{_f(r.get('frames_without_contour_stage'), '{}')} | {_f(r.get('init_ms'), '{:.0f}')} | "
                     f"{_f(r.get('tracker_ms_p50'), '{:.0f}')} / "
                     f"{_f(r.get('tracker_ms_p95'), '{:.0f}')} | {_f(r['mpjpe_mm'])} |")
    return "\n".join(L) + "\n"


def plot(res: dict, path: Path) -> Path:
    """Tracker frames/s against the budget (and the network's rates as horizontal lines)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["tracker"]["rows"]
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.plot([r["evals_per_frame"] for r in rows], [r["frames_per_s"] for r in rows], "bo-", label="offline tracker")
    for r, st in zip(res["network"]["rows"], ("g--", "m:")):
        if r.get("fps"):
            ax.axhline(r["fps"], color=st[0], ls=st[1:], label=f"network, {r['mode']} ({r.get('evals_per_frame')} evals)")
    ax.set_xlabel("evaluations per frame")
    ax.set_ylabel("frames per second")
    ax.set_title(f"tracking speed, {res['tracker']['optimizer']}, bags/{res['tracker']['bag']}", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return Path(path)


def run(args: argparse.Namespace) -> int:
    if args.frames is not None and args.frames < 1:
        print(f"isa-mocap bench speed: error: --frames: expected an integer >= 1, received {args.frames}",
              file=sys.stderr)
        return 2
    res = collect(args)
    if args.json:
        print(json.dumps(res))
    else:
        print(render_markdown(res))
    return 0
