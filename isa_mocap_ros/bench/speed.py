"""Speed side by side: energy evaluations/s, tracker frames/s per budget, the node network on the demo bag.

``isa-mocap bench speed [--quick] [--json] [--frames N] [--no-network]``. Measured in one run, one
after the other on the same machine:

1. **energy**: evaluations per second of the fast silhouette kernel and of the exact raster
   reference (``isa-mocap bench energy``'s code and scene: 39 DOF, 4 views 320×240, batch 1500), and the
   effective rate of the tracker's h-isa search on that energy (generations of 30, mostly the restricted
   kernel: what the tracker gets, not the kernel's best case);
2. **tracker**: frames per second of the offline tracker (``isa-mocap track``'s code,
   :func:`isa_mocap_ros.cli.track.track_bag`) at 500 / 1500 / 3000 evaluations per frame on the
   first ``--frames`` (default 30) frames of ``bags/demo`` after its background frames: h-isa, 39
   DOF, images segmented as ``isa-mocap track`` does, first frame from the ground truth; the rate is
   frames over the summed wall time of the tracker's steps (segmentation and bag reading excluded),
   and the whole call's wall time is reported too (after an unreported warm-up call that loads or
   compiles the compiled kernels);
   The steps' CPU time (``time.process_time``, every thread of the process) is reported beside the
   wall time: it is what a before/after comparison on a shared machine can trust;
3. **profile**: where a tracked frame's CPU time goes (:func:`frame_profile`), 1500 evaluations, the
   same frames: the step's CPU time unprofiled, then under ``cProfile`` with a CPU clock by stage
   (:data:`PROFILE_STAGES`: prediction, mask checks / gate / hull, view weights, the masks to the
   energy, the main search, the pelvis, torso, limb and contour stages, the rest as bookkeeping) and
   the top functions by own CPU time;
4. **network**: ``isa-mocap run``'s code (:mod:`isa_mocap_ros.cli.run`: segmentation, prediction and
   estimator nodes and a recorder, each its own process, over DDS on localhost) on ``bags/demo``,
   six times (:data:`NETWORK_MODES`): in real time (rate 1.0: frames the estimator cannot keep up
   with are dropped), the same with the estimator's start-up catch-up (``startup_catch_up: 3``), the
   same with segmentation, prediction and estimator in one process
   (``--single-process``), in real time with a CPU-bound process beside it (one core busy,
   :func:`busy_core`; again with the catch-up), and in lockstep: frame sets processed per second of replay, the real-time
   factor (that rate over the bag's 30 frames/s), latency p50 / p95 (image received → estimate
   received, the recorder's clock), dropped frame sets (start-up included), and the mean joint error,
   also as the difference to the lockstep run's. The first run calibrates the body shape
   (``isa-mocap run --shape auto``, before its replay); the others track with that shape file.

``--quick`` (tests): energy at small sizes, the tracker and the profile on 3 frames of ``bags/fixture``
(its exact masks), no network part (``--network`` adds it on ``bags/fixture`` in lockstep).
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


#: working resolutions (``work_scale``) of the segmentation part: the default first, then a reduced one
SEGMENTATION_SCALES = (1.0, 0.5)


def segmentation_speed(bag: Path, *, scales=SEGMENTATION_SCALES, rounds: int = 3) -> dict:
    """CPU time of the segmentation per frame set and per view, per working resolution, and the masks'
    agreement with the default's.

    The segmentation node's core (:class:`~isa_mocap_ros.vision.segmentation.BackgroundSegmenter`, one
    per view, ``pipeline.yaml``'s defaults but ``work_scale``, learning from the bag's empty frames) on
    every frame set of ``bag``; the scales interleaved in ``rounds`` rounds in this process (after an
    unreported warm-up round), CPU time of the calling thread (``time.thread_time``) per set after the
    learning frames: the median over sets, then the median over rounds. IoU: the masks pooled over
    sets and views against the first scale's (intersection / union of the foreground pixels).
    """
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    seq = read_sequence(bag, want_images=True, want_masks=False)
    frames = [f for f in seq.frames if all(i is not None for i in f.images)]
    learn = seq.empty_frames or 10
    V = len(frames[0].images)

    def one(scale: float):
        segs = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn, work_scale=scale)) for _ in range(V)]
        cpu, masks = [], []
        for f in frames:
            t0 = time.thread_time()
            m = [segs[v].apply(f.images[v]) for v in range(V)]
            cpu.append(time.thread_time() - t0)
            masks.append(m)
        return float(np.median(cpu[learn:])), masks[learn:]

    for sc in scales:
        one(sc)
    cpu = {sc: [] for sc in scales}
    masks = {}
    for _ in range(rounds):
        for sc in scales:
            t, masks[sc] = one(sc)
            cpu[sc].append(t)
    ref = masks[scales[0]]
    rows = []
    for sc in scales:
        inter = sum(int(np.count_nonzero((a > 0) & (b > 0))) for fa, fb in zip(masks[sc], ref) for a, b in zip(fa, fb))
        union = sum(int(np.count_nonzero((a > 0) | (b > 0))) for fa, fb in zip(masks[sc], ref) for a, b in zip(fa, fb))
        ms = 1e3 * float(np.median(cpu[sc]))
        rows.append({"work_scale": sc, "cpu_ms_per_set": ms, "cpu_ms_per_view": ms / V,
                     "cpu_ms_per_set_rounds": [1e3 * t for t in cpu[sc]],
                     "iou_vs_default": inter / union if union else None})
    h, w = frames[0].images[0].shape[:2]
    return {"bag": bag.name, "views": V, "image": f"{w}x{h}", "sets": len(frames) - learn, "learn_frames": learn,
            "rounds": rounds, "rows": rows}


def tracker_speed(bag: Path, *, frames: int, budgets=BUDGETS, optimizer: str = "h-isa", use_masks: bool = False,
                  work: Path) -> list[dict]:
    """Offline tracker frames/s per budget (``isa-mocap track``'s code)."""
    from isa_mocap_ros.cli.track import track_bag

    def ns(b: int, n: int, name: str) -> argparse.Namespace:
        return argparse.Namespace(
            bag=str(bag), out=str(work / name), optimizer=optimizer, evals=int(b), params=None, model=None,
            seed=0, frames=n, start=0, use_masks=use_masks, learn_frames=None, shape="truth", init="truth",
            predictor=None, prior=None, prior_eta=0.0, energy=None, overwrite=True, no_progress=True)

    # warm-up (not reported): loads or compiles every numba function the tracker calls. At the largest budget:
    # a small one skips the torso and contour stages (their share of the budget), whose kernels then loaded
    # from numba's cache in the first measured frame at 1500 (~0.25 s: the "one slow frame" of each run)
    track_bag(ns(max(budgets), 3, "track_warmup"))
    rows = []
    for b in budgets:
        got: dict = {}
        t0 = time.perf_counter()
        s = track_bag(ns(b, frames + 1, f"track_{b}"), collect=got)
        wall = time.perf_counter() - t0
        steps = np.array(list(got["step_seconds"].values()), dtype=float)
        cpu = np.array(list(got["step_cpu_seconds"].values()), dtype=float)
        rows.append({"evals_per_frame": int(b), "frames": int(steps.size),
                     "cpu_ms_per_frame": float(cpu.mean() * 1e3),
                     "frames_per_cpu_s": float(cpu.size / cpu.sum()) if cpu.sum() > 0 else float("nan"),
                     "frames_per_s": float(steps.size / steps.sum()) if steps.sum() > 0 else float("nan"),
                     "ms_per_frame_p50": float(np.median(steps) * 1e3), "ms_per_frame_max": float(steps.max() * 1e3),
                     "evals_per_s": float(b * steps.size / steps.sum()) if steps.sum() > 0 else float("nan"),
                     "wall_seconds": round(wall, 2), "mpjpe_mm": s.get("mpjpe_mm")})
    return rows


#: The tracked frame's stages for the profile: a label, then the functions whose CPU time (cumulative,
#: as ``(file, function, caller or None)``; a caller restricts to the calls from that function) it sums.
#: What the tracker's step spends outside them is "bookkeeping" (the step's own Python, notes, clipping,
#: the final pose). A stage nested in another (a re-run frame of the heading check) counts in its own row.
PROFILE_STAGES = (
    ("prediction", (("frame_prediction.py", "predict", None),)),
    ("masks: checks, gate, hull filter", (("frame_masks.py", "check_masks", None), ("frame_masks.py", "gate", None),
                                          ("frame_masks.py", "hull", None))),
    ("view weights", (("gate.py", "visible_shares", None),)),
    ("masks to the energy (foreground sample)", (("frame_masks.py", "set_masks", None),)),
    ("main search: set-up (box, optimizer, plan)", (("tracker.py", "plan_search", "optimize"),)),
    ("main search", (("compiled_search.py", "search", "optimize"), ("_base.py", "minimize", "optimize"))),
    ("pelvis stage", (("stages.py", "refit_pelvis", None),)),
    ("torso stage", (("stages.py", "refit_torso", None),)),
    ("limb stage", (("stages.py", "propose_limbs", None),)),
    ("contour stage", (("stages.py", "fit_contours", None),)),
)
#: The profiled root: the tracker's step (everything it calls).
PROFILE_ROOT = ("tracker.py", "step")


def _pkey_match(key, file: str, func: str) -> bool:
    return key[2] == func and key[0].replace("\\", "/").endswith("/" + file)


def profile_stages(stats) -> tuple[float, list[tuple[str, float, int]]]:
    """``(CPU seconds of the tracker's steps, [(stage, CPU seconds, calls)])`` from ``pstats.Stats``
    ``stats`` of a profile enabled around :meth:`Tracker.step` only (:data:`PROFILE_STAGES`), with a last
    row "bookkeeping" for the rest of the step."""
    raw = stats.stats
    root = [k for k in raw if _pkey_match(k, *PROFILE_ROOT)]
    total = sum(raw[k][3] for k in root)
    rows = []
    for label, funcs in PROFILE_STAGES:
        t, n = 0.0, 0
        for file, func, caller in funcs:
            for k, (cc, nc, tt, ct, callers) in raw.items():
                if not _pkey_match(k, file, func):
                    continue
                if caller is None:
                    t += ct
                    n += nc
                else:
                    for ck, (ccc, cnc, ctt, cct) in callers.items():
                        if ck[2] == caller:
                            t += cct
                            n += cnc
        rows.append((label, t, n))
    rows.append(("bookkeeping (the rest of the step)", max(0.0, total - sum(r[1] for r in rows)), 0))
    return total, rows


def frame_profile(bag: Path, *, frames: int, evals: int = 1500, optimizer: str = "h-isa", use_masks: bool = False,
                  work: Path, top: int = 15) -> dict:
    """CPU-time profile of the tracker's steps on ``frames`` frames of ``bag`` (``isa-mocap track``'s code,
    as :func:`tracker_speed`): per frame, by stage (:data:`PROFILE_STAGES`) and by function (the ``top``
    functions by own CPU time). Two runs: one unprofiled (the CPU time per step as it is) and one under
    ``cProfile`` with a CPU-time clock (``time.process_time``: every thread of the process, so the numba
    kernels' worker threads count; other processes' load does not), whose per-call overhead inflates the
    Python-heavy parts: its stage rows are shares of the profiled step."""
    import cProfile
    import pstats

    from isa_mocap_ros.cli.track import track_bag

    def ns(name: str, n: int) -> argparse.Namespace:
        return argparse.Namespace(
            bag=str(bag), out=str(work / name), optimizer=optimizer, evals=int(evals), params=None, model=None,
            seed=0, frames=n, start=0, use_masks=use_masks, learn_frames=None, shape="truth", init="truth",
            predictor=None, prior=None, prior_eta=0.0, energy=None, overwrite=True, no_progress=True)

    track_bag(ns("profile_warmup", 3))          # loads or compiles every numba function the steps call
    plain: dict = {}
    track_bag(ns("profile_plain", frames + 1), collect=plain)
    cpu = np.array(list(plain["step_cpu_seconds"].values()), dtype=float)
    prof = cProfile.Profile(time.process_time)
    got: dict = {"profiler": prof}
    track_bag(ns("profile", frames + 1), collect=got)
    n = len(got["step_cpu_seconds"])
    st = pstats.Stats(prof)
    total, stage_rows = profile_stages(st)
    funcs = sorted(st.stats.items(), key=lambda kv: -kv[1][2])[:top]
    by_call = [{"function": f"{Path(k[0]).name}:{k[1]}({k[2]})" if k[0] != "~" else k[2],
                "calls_per_frame": round(v[1] / max(n, 1), 1), "own_ms_per_frame": v[2] / max(n, 1) * 1e3,
                "cumulative_ms_per_frame": v[3] / max(n, 1) * 1e3} for k, v in funcs]
    return {"bag": bag.name, "optimizer": optimizer, "evals_per_frame": int(evals), "frames": int(n),
            "cpu_ms_per_frame": float(cpu.mean() * 1e3) if cpu.size else float("nan"),
            "cpu_ms_per_frame_p50": float(np.median(cpu) * 1e3) if cpu.size else float("nan"),
            "profiled_cpu_ms_per_frame": total / max(n, 1) * 1e3,
            "by_stage": [{"stage": label, "cpu_ms_per_frame": t / max(n, 1) * 1e3,
                          "share": t / total if total > 0 else float("nan"),
                          "calls_per_frame": round(c / max(n, 1), 2)} for label, t, c in stage_rows],
            "by_call": by_call}


#: The network part's runs: (label, lockstep, one core busy (a CPU-bound process beside it), single process:
#: ``isa-mocap run --single-process``, estimator parameters changed from ``config/pipeline.yaml``'s). The
#: second run is the first with the start-up catch-up (off by default) of the heading check's 3 held sets
#: (``startup_catch_up: 3``: the sets it holds are tracked after the check instead of dropped, and no more sets wait
#: out the initialization than today, so few sets are late; 12 gave 2 dropped but p95 74-120 ms, sessions 28-29), and
#: the one-core-busy run is repeated with it: its A/B in one bench (docs/history/issue35_speed.md, session 30).
NETWORK_MODES = (("real time", False, False, False, {}),
                 ("real time, start-up catch-up 3", False, False, False, {"startup_catch_up": 3}),
                 ("real time, single process", False, False, True, {}),
                 ("real time, one core busy", False, True, False, {}),
                 ("real time, one core busy, start-up catch-up 3", False, True, False, {"startup_catch_up": 3}),
                 ("lockstep", True, False, False, {}))


@contextlib.contextmanager
def busy_core(on: bool = True):
    """A CPU-bound process (one core kept busy: a Python busy loop at normal priority) while the block
    runs; stopped (by its own pid) after it."""
    import subprocess

    if not on:
        yield None
        return
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        yield proc
    finally:
        proc.kill()
        proc.wait(10)


def network_speed(bag: Path, *, mode: str, optimizer: str, work: Path, lockstep: bool | None = None,
                  busy: bool = False, shape: str = "auto", single: bool = False, estimator: dict | None = None) -> dict:
    """``isa-mocap run`` on ``bag`` in real time (rate 1.0) or lockstep (``lockstep``, default: ``mode ==
    "lockstep"``), with a CPU-bound process beside it when ``busy`` (:func:`busy_core`), tracking with
    body shape ``shape`` (``isa-mocap run --shape``; the calibration runs before the replay); the
    summary's speed figures and ``body_shape``, the shape file the run tracked with."""
    from isa_mocap_ros.cli import run as run_cli

    lockstep = (mode == "lockstep") if lockstep is None else lockstep
    out = work / ("run_" + "".join(ch if ch.isalnum() else "_" for ch in mode))
    p = argparse.ArgumentParser()
    run_cli.add_run_arguments(p)
    argv = [str(bag), "--out", str(out), "--quiet", "--overlay-frames", "0", "--optimizer", optimizer,
            "--shape", shape]
    argv += ["--lockstep"] if lockstep else ["--rate", "1.0"]
    argv += ["--no-keypoints"]     # every row alike: real time's default (decision 014), so lockstep compares
    argv += ["--single-process"] if single else []
    trace = None if lockstep else work / ("trace_" + out.name + ".jsonl")
    estimator = {**(estimator or {}), **({"trace_file": str(trace)} if trace is not None else {})}
    if estimator:
        argv += ["--params", str(_params_with(estimator, work / ("params_" + out.name + ".yaml")))]
    buf = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(buf), busy_core(busy):
        rc = run_cli.run(p.parse_args(argv))
    wall = time.perf_counter() - t0
    if rc != 0 or not (out / "summary.json").is_file():
        return {"mode": mode, "error": f"isa-mocap run exited with {rc}; see {out / 'nodes.log'}",
                "wall_seconds": round(wall, 1)}
    s = json.loads((out / "summary.json").read_text())
    bag_fps = _bag_fps(bag)
    keep = ("frame_sets_played", "frames_processed", "frames_estimated", "fps", "latency_ms_p50", "latency_ms_p95",
            "latency_mask_ms_p95", "latency_estimator_ms_p95",
            "dropped_frames", "dropped_by_estimator", "sets_bunched", "dropped_at_bunched_arrivals", "dropped_while_initializing", "startup_sets_caught_up", "frames_without_contour_stage", "budget_lowered", "track_resets", "init_ms", "init_cpu_ms", "tracker_ms_p50", "tracker_ms_p95", "mpjpe_mm", "knee_rmse_deg", "evals_per_frame", "optimizer")
    r = {"mode": mode, "busy_core": bool(busy), "single_process": bool(single),
         "body_shape": str(out / "body.yaml") if (out / "body.yaml").is_file() else (None if shape == "auto" else shape), **{k: s.get(k) for k in keep}, "bag_fps": bag_fps,
         "wall_seconds": round(wall, 1)}
    r["real_time_factor"] = (s["fps"] / bag_fps) if bag_fps and s.get("fps") and np.isfinite(s["fps"]) else None
    if trace is not None:
        r["budget_levels"] = budget_levels(trace)
    return r


def budget_levels(trace: Path) -> list[int] | None:
    """Sets the governor accounted for at each budget level (index 0 = the full budget), from the estimator's
    ``trace_file`` (one JSON line per tracked set; the start-up's sets carry no level); None without a trace."""
    if not trace.is_file():
        return None
    levels = [json.loads(line).get("level") for line in trace.read_text().splitlines() if line.strip()]
    levels = [lv for lv in levels if isinstance(lv, int)]
    from isa_mocap_ros.tracking.load import LEVELS

    return [levels.count(k) for k in range(len(LEVELS))]


def _params_with(estimator: dict, path: Path) -> Path:
    """``config/pipeline.yaml`` with the estimator's parameters ``estimator`` (name -> value) changed,
    written to ``path`` (each parameter's line rewritten in place: the file's comments and layout kept)."""
    import re

    from isa_mocap_ros.resources import resource_dir

    text = (resource_dir("config") / "pipeline.yaml").read_text()
    head, sep, rest = text.partition("/mocap/estimator:")
    for name, value in estimator.items():
        v = str(value).lower() if isinstance(value, bool) else str(value)
        rest, n = re.subn(rf"^(\s+{re.escape(name)}:)\s*[^\s#]+", rf"\g<1> {v}", rest, count=1, flags=re.M)
        if not n:
            raise ValueError(f"config/pipeline.yaml: no estimator parameter {name!r} to change")
    path.write_text(head + sep + rest)
    return path


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
        print(f"bench speed: segmentation on {tbag.name} ...", file=sys.stderr, flush=True)
        res["segmentation"] = segmentation_speed(tbag, rounds=1 if args.quick else 3)
        print(f"bench speed: tracker on {tbag.name}, {frames} frames per budget ...", file=sys.stderr, flush=True)
        res["tracker"] = {"bag": tbag.name, "optimizer": args.optimizer, "frames": frames,
                          "rows": tracker_speed(tbag, frames=frames, optimizer=args.optimizer,
                                                use_masks=args.quick, work=work)}
        print(f"bench speed: CPU profile of the tracked frame on {tbag.name}, {frames} frames ...", file=sys.stderr,
              flush=True)
        res["profile"] = frame_profile(tbag, frames=frames, optimizer=args.optimizer, use_masks=args.quick,
                                       work=work)
        net = (not args.no_network) and (not args.quick or args.network)
        if net:
            nbag = bags / ("fixture" if args.quick else "demo")
            modes = [m for m in NETWORK_MODES if m[1]] if args.quick else list(NETWORK_MODES)
            rows = []
            shape = "auto"          # calibrated by the first run; the others track with the same shape file
            for label, lockstep, busy, single, estimator in modes:
                print(f"bench speed: node network on {nbag.name}, {label} ...", file=sys.stderr, flush=True)
                try:
                    r = network_speed(nbag, mode=label, optimizer=args.optimizer, work=work, lockstep=lockstep,
                                      busy=busy, shape=shape, single=single, estimator=estimator)
                except Exception as exc:  # noqa: BLE001 - one failed run is a row saying so, not a lost bench
                    r = {"mode": label, "busy_core": busy, "error": f"{type(exc).__name__}: {exc}"}
                if shape == "auto" and r.get("body_shape"):
                    shape = str(shutil.copy(r["body_shape"], work / "body.yaml"))
                rows.append(r)
            ref = next((r for r in rows if r["mode"] == "lockstep" and "error" not in r), None)
            for r in rows:
                if ref is not None and "error" not in r and r.get("mpjpe_mm") is not None \
                        and ref.get("mpjpe_mm") is not None:
                    r["mpjpe_vs_lockstep_mm"] = r["mpjpe_mm"] - ref["mpjpe_mm"]
                if "error" not in r and r.get("frame_sets_played"):
                    r["dropped_share"] = (r["dropped_frames"] or 0) / r["frame_sets_played"]
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
         f"| fast (compiled kernel) | {e['fast_evals_per_s']:.0f} |",
         *([f"| fast, per CPU second (every thread) | {e['fast_evals_per_cpu_s']:.0f} |"]
           if e.get("fast_evals_per_cpu_s") else []),
         f"| exact (raster reference) | {e['exact_evals_per_s']:.0f} |",
         f"| ratio | {e['ratio']:.0f}× |",
         *([f"| the tracker's h-isa search ({e['search_evals']} evaluations in generations of "
            f"{e['search_generation']}, {e['search_restricted_share']:.0%} on the restricted kernel) | "
            f"{e['search_evals_per_s']:.0f} |",
            f"| the search, per CPU second | {_f(e.get('search_evals_per_cpu_s'), '{:.0f}')} |",
            *([f"| the search with half of its generations on two views (`--coarse-fraction 0.5`), per CPU second | "
               f"{_f(e.get('search_coarse_evals_per_cpu_s'), '{:.0f}')} |"] if e.get("search_coarse_evals_per_cpu_s")
              else []),
            f"| ratio, the search to the exact | {e['search_ratio']:.0f}× |"] if e.get("search_evals_per_s") else []),
         *([f"| scanline count (`method='raster'`, the tracker's default: decision 017), every pixel row / every second row | "
            f"{e['raster_evals_per_s']:.0f} / {e['raster2_evals_per_s']:.0f} |",
            f"| its ratio to the exact; mean \\|f − exact\\| (fast kernel: {e['fast_mean_abs_diff']:.4f}) | "
            f"{e['raster_ratio']:.0f}× / {e['raster2_ratio']:.0f}×; {e['raster_mean_abs_diff']:.4f} / "
            f"{e['raster2_mean_abs_diff']:.4f} |",
            f"| the tracker's search on the scanline energy (`isa-mocap track --energy raster`), per CPU second | "
            f"{_f(e.get('search_raster_evals_per_cpu_s'), '{:.0f}')} |"] if e.get("raster_evals_per_s") else []),
         ""]
    if res.get("segmentation"):
        L += render_segmentation(res["segmentation"])
    t = res["tracker"]
    L += ["#### Offline tracker", "",
          f"`bags/{t['bag']}`, {t['optimizer']}, {t['frames']} frames per budget after a ground-truth first frame; "
          "frames/s over the tracker's steps (segmentation and bag reading excluded); CPU ms/frame: the steps' "
          "CPU time, every thread of the process (two busy threads count twice).", "",
          "| evaluations/frame | frames/s | ms/frame (median) | ms/frame (max) | CPU ms/frame (mean) | evaluations/s "
          "| call wall time (s) |",
          "|---|---|---|---|---|---|---|"]
    for r in t["rows"]:
        L.append(f"| {r['evals_per_frame']} | {_f(r['frames_per_s'], '{:.2f}')} | {_f(r['ms_per_frame_p50'], '{:.0f}')} | "
                 f"{_f(r['ms_per_frame_max'], '{:.0f}')} | {_f(r.get('cpu_ms_per_frame'), '{:.1f}')} | "
                 f"{_f(r['evals_per_s'], '{:.0f}')} | {r['wall_seconds']:.1f} |")
    if res.get("profile"):
        L += ["", *render_profile(res["profile"])]
    n = res["network"]
    L += ["", "#### Node network (`isa-mocap run`)", ""]
    if not n["rows"]:
        L.append(f"Skipped ({n.get('skipped')}).")
    else:
        L += [f"`bags/{n['bag']}`, segmentation + prediction + estimator + recorder processes over DDS (localhost; single process: the first three in one process, `--single-process`); "
              "one core busy: a CPU-bound process (a Python busy loop) runs beside the network for the whole run. "
              "Dropped: frame sets played and not processed, start-up included (the share in brackets); by the estimator: "
              "those its queue replaced while the tracker was busy (the rest were lost before it: best-effort image and "
              "mask subscriptions, the synchronizer), of them those that came less than half a period after the set "
              "before (the inputs bunched: segmentation or transport late, not the tracker); budget lowered: the governor's steps down (docs/nodes.md); latency: "
              "image received → joint_states received (the recorder's clock), and its parts' p95: image → the set's last "
              "mask received (segmentation, transport), that mask → joint_states (the estimator's wait, step, publishing); vs lockstep: mean joint error "
              "minus the lockstep run's (same body shape, calibrated once by the first run). Every row without the "
              "keypoint node (`--no-keypoints`: real time's default, decision 014).", ""]
        L += network_table(n["rows"])
    return "\n".join(L) + "\n"


def network_table(rows: list[dict]) -> list[str]:
    """The network part's table (markdown lines): one row per run, a failed run as a row saying so."""
    L = ["| mode | frame sets played | processed | frames/s | real-time factor | latency p50 (ms) | latency p95 (ms) | of it p95: image → masks / masks → estimate | dropped | of them while initializing | of them by the estimator (its queue) / at bunched arrivals | caught up after start-up | without the contour stage | budget lowered (times) | sets per budget level 0/1/2/… | initialization wall / CPU (ms) | tracker ms per set p50 / p95 | mean joint error (mm) | vs lockstep (mm) |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            L.append(f"| {r['mode']} | failed: {r['error']} | | | | | | | | | | | | | | | | | |")
            continue
        share = f" ({100 * r['dropped_share']:.0f} %)" if r.get("dropped_share") is not None else ""
        L.append(f"| {r['mode']} | {r['frame_sets_played']} | {r['frames_processed']} | {_f(r['fps'], '{:.2f}')} | "
                 f"{_f(r['real_time_factor'], '{:.2f}')} | {_f(r['latency_ms_p50'], '{:.0f}')} | "
                 f"{_f(r['latency_ms_p95'], '{:.0f}')} | {_f(r.get('latency_mask_ms_p95'), '{:.0f}')} / "
                 f"{_f(r.get('latency_estimator_ms_p95'), '{:.0f}')} | {r['dropped_frames']}{share} | "
                 f"{_f(r.get('dropped_while_initializing'), '{}')} | {_f(r.get('dropped_by_estimator'), '{}')} / "
                 f"{_f(r.get('dropped_at_bunched_arrivals'), '{}')} | "
                 f"{_f(r.get('startup_sets_caught_up'), '{}')} | "
                 f"{_f(r.get('frames_without_contour_stage'), '{}')} | {_f(r.get('budget_lowered'), '{}')} | "
                 f"{'/'.join(map(str, r['budget_levels'])) if r.get('budget_levels') else '–'} | "
                 f"{_f(r.get('init_ms'), '{:.0f}')} / {_f(r.get('init_cpu_ms'), '{:.0f}')} | "
                 f"{_f(r.get('tracker_ms_p50'), '{:.0f}')} / "
                 f"{_f(r.get('tracker_ms_p95'), '{:.0f}')} | {_f(r['mpjpe_mm'])} | "
                 f"{_f(r.get('mpjpe_vs_lockstep_mm'), '{:+.1f}')} |")
    return L


def render_segmentation(sg: dict) -> list[str]:
    """The markdown lines of :func:`segmentation_speed`'s result."""
    L = ["#### Segmentation", "",
         f"`bags/{sg['bag']}`, {sg['views']} views {sg['image']}, {sg['sets']} frame sets after {sg['learn_frames']} "
         f"learning frames; the segmentation node's core per view (`work_scale` 1 = the default); CPU time of the "
         f"calling thread, median over sets, median of {sg['rounds']} interleaved rounds; IoU: the masks against the "
         "default's, pooled.", "",
         "| work_scale | CPU ms per set | CPU ms per view | IoU vs default |", "|---|---|---|---|"]
    for r in sg["rows"]:
        L.append(f"| {r['work_scale']:g} | {r['cpu_ms_per_set']:.2f} | {r['cpu_ms_per_view']:.2f} | "
                 f"{_f(r['iou_vs_default'], '{:.3f}')} |")
    return L + [""]


def render_profile(pr: dict) -> list[str]:
    """The markdown lines of :func:`frame_profile`'s result."""
    L = ["#### Where a tracked frame's CPU time goes", "",
         f"`bags/{pr['bag']}`, {pr['optimizer']}, {pr['evals_per_frame']} evaluations/frame, {pr['frames']} frames "
         f"after a ground-truth first frame. CPU time of the tracker's step (every thread of the process): "
         f"{_f(pr['cpu_ms_per_frame'], '{:.1f}')} ms per frame unprofiled (median "
         f"{_f(pr['cpu_ms_per_frame_p50'], '{:.1f}')}), {_f(pr['profiled_cpu_ms_per_frame'], '{:.1f}')} ms under "
         "`cProfile` with a CPU clock (its per-call overhead inflates the Python-heavy rows).", "",
         "| stage | CPU ms/frame (profiled) | share | calls/frame |", "|---|---|---|---|"]
    for r in pr["by_stage"]:
        L.append(f"| {r['stage']} | {_f(r['cpu_ms_per_frame'], '{:.2f}')} | {_f(100 * r['share'], '{:.1f}')} % | "
                 f"{_f(r['calls_per_frame'] or None, '{:g}')} |")
    L += ["", "Top functions by own CPU time (profiled):", "",
          "| function | calls/frame | own CPU ms/frame | cumulative CPU ms/frame |", "|---|---|---|---|"]
    for r in pr["by_call"]:
        L.append(f"| `{r['function']}` | {r['calls_per_frame']:g} | {r['own_ms_per_frame']:.2f} | "
                 f"{r['cumulative_ms_per_frame']:.2f} |")
    return L


def plot(res: dict, path: Path) -> Path:
    """Tracker frames/s against the budget (and the network's rates as horizontal lines)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["tracker"]["rows"]
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.plot([r["evals_per_frame"] for r in rows], [r["frames_per_s"] for r in rows], "bo-", label="offline tracker")
    for r, st in zip(res["network"]["rows"], ("g--", "y--", "c-", "r-.", "m:")):
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
