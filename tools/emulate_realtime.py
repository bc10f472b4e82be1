#!/usr/bin/env python3
"""The estimator's real-time schedule over a bag on a virtual clock (:func:`isa_mocap_ros.tracking.realtime`), for A/B
of the start-up and load policies on any machine, contended or not:

    NUMBA_NUM_THREADS=1 python tools/emulate_realtime.py BAG SHAPE.yaml --seeds 0,1,2,3 \\
        --catch-up 0 --catch-up 12 [--catch-up-evals 300] [--load 2] [--cost 0.010,9e-6,0.005,0.060] --out R.json

The bag's masks are segmented as ``isa-mocap track`` does (one background model per view, learnt on the bag's
empty frames; cached beside ``--out``). Set ``k`` arrives at ``k`` frame periods; the tracker (the node's config:
``TrackerConfig`` defaults, the estimator's own prediction through the JointState conversions) steps the set the
node's :class:`~isa_mocap_ros.tracking.realtime.RealTimeSchedule` gives it, for a time a cost model says:
``load × (fixed + per_eval × evaluations + contour if the contour stage ran + init if it initialized)``. The
default cost is fitted to the idle bench (session 27: a tracked set ~28 ms, the initialization ~145 ms); the timing
is deterministic, so every seed and policy sees the same clock and the differences are the policies'. Printed per
run: sets dropped (those after the initialized one within 25 sets: the start-up's), latency p50/p95 of the
estimated sets (virtual: arrival to estimate, without segmentation and transport), mean joint error, the governor's
lowerings. docs/history/issue35_speed.md (session 28) has the figures this made.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

PERIOD = 1 / 30


def segmented_masks(bag: Path, seq, cache: Path) -> list:
    """One mask per view and frame, as ``isa-mocap track`` segments them (cached in ``cache``)."""
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    views = len(seq.cameras)
    if cache.is_file():
        z = np.load(cache)
        return [[z[f"m{k}_{v}"] if f"m{k}_{v}" in z else None for v in range(views)] for k in range(len(seq.frames))]
    learn = seq.empty_frames or next((f.index for f in seq.frames if f.truth_markers is not None), 0) or 10
    segs = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn)) for _ in seq.cameras]
    out = [[None if img is None else seg.apply(img) for seg, img in zip(segs, fr.images)] for fr in seq.frames]
    np.savez_compressed(cache, **{f"m{k}_{v}": m for k, ms in enumerate(out) for v, m in enumerate(ms) if m is not None})
    return out


def cost_model(fixed_s: float, per_eval_s: float, contour_s: float, init_s: float, load: float):
    """A step's seconds from its result and budget (see the module docstring); a set without an estimate 2 ms."""
    def step_s(result, budget) -> float:
        if result.x is None or (result.fell_back and result.n_evals == 0):
            return load * 0.002
        t = fixed_s + per_eval_s * result.n_evals + (contour_s if budget.contour_stage else 0.0)
        return load * (t + (init_s if result.initialized else 0.0))
    return step_s


def governor_trace(schedule) -> list:
    """Per step of ``schedule`` (in order): the governor's account (:attr:`RealTimeSchedule.last_account`: the
    reference energy before the step, the lost count, level and reason after it; None where it did not count the step)
    (a list the schedule's ``after`` appends to)."""
    rows, after = [], schedule.after

    def traced(tracker, result, **kw):
        d = after(tracker, result, **kw)
        rows.append(dict(schedule.last_account or dict(reference=float("nan"), lost=0, level=None, reason="not counted"),
                         resets=schedule.governor.resets))
        return d
    schedule.after = traced
    return rows


def heading_errors(model, seq, scored, steps, stamps) -> list:
    """The heading error (degrees) of the estimates at the ``scored`` stamps (none without marker truth)."""
    from isa_mocap_ros.eval.metrics import score_markers
    from isa_mocap_ros.eval.report import rig_joint_map

    if not scored or not seq.has_marker_truth:
        return [None] * len(scored)
    x_of = {stamps[s["k"]]: s["x"] for s in steps if s["x"] is not None}
    truth = {f.stamp_ns: f.truth_markers for f in seq.frames}
    sc = score_markers(model, np.array([x_of[t] for t in scored]), seq.truth_marker_names,
                       np.array([truth[t] for t in scored]), joint_map=rig_joint_map(seq))
    return [float(h) for h in sc.get("heading_errors_deg", [None] * len(scored))]


def print_trace(steps) -> None:
    """One line per tracked set: frame, gap, budget, energy against the governor's reference, lost count, error."""
    for s in steps:
        ratio = s["energy"] / s["reference"] if s["reference"] == s["reference"] and s["reference"] else float("nan")
        err = "-" if s["error_mm"] is None else f"{s['error_mm']:.0f}"
        head = "-" if s["heading_deg"] is None else f"{s['heading_deg']:.0f}"
        print(f"  k {s['k']:3d} gap {s['gap']:2d} {'I' if s['initialized'] else ' '} evals {s['evals']:5d} "
              f"E {s['energy']:.4f} ref {s['reference']:.4f} ({ratio:.2f}x) lost {s['lost']:2d} level {s['level']} "
              f"err {err} mm heading {head} deg {s['reason']}")


def main(argv=None) -> int:
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.eval.report import score
    from isa_mocap_ros.tracking.config import TrackerConfig
    from isa_mocap_ros.tracking.load import LoadGovernor, LoadSettings, StartupCatchUp
    from isa_mocap_ros.tracking.published import PublishedPredictor
    from isa_mocap_ros.tracking.realtime import RealTimeSchedule, emulate
    from isa_mocap_ros.tracking.recovery import Recovery, RecoverySettings
    from isa_mocap_ros.tracking.tracker import Tracker

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bag")
    p.add_argument("shape", help="body-shape YAML the tracker uses (- = the default shape)")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--catch-up", type=int, action="append", help="startup_catch_up values to run (default 0)")
    p.add_argument("--catch-up-evals", type=int, default=300,
                   help="the catch-up's evaluations per held set (the node's degrade_min_evals; default 300)")
    p.add_argument("--min-evals", type=int, default=300, help="the governor's fewest evaluations (degrade_min_evals)")
    p.add_argument("--catch-up-ms", type=float, default=1000.0, help="startup_catch_up_ms (default 1000)")
    p.add_argument("--catch-up-stale-ms", type=float, default=0.0,
                   help="startup_catch_up_stale_ms: held sets that waited longer are dropped, oldest first (default 0)")
    p.add_argument("--load", type=float, default=1.0, help="step times × this (2: one core busy)")
    p.add_argument("--cost", default="0.010,9e-6,0.005,0.060",
                   help="fixed_s,per_eval_s,contour_s,init_s of the step cost (default: fitted to the idle bench)")
    p.add_argument("--recovery", action="store_true",
                   help="the estimator's recovery (tracking/recovery.py): a second opinion after a drift under load")
    p.add_argument("--recovery-settings", default="",
                   help="RecoverySettings fields, e.g. cooldown=30,adopt_ratio=0.7 (with --recovery)")
    p.add_argument("--trace", action="store_true", help="print every tracked set: energy, the governor's state, error")
    p.add_argument("--out", required=True, help="JSON of every run (its steps included)")
    a = p.parse_args(argv)
    bag, out = Path(a.bag), Path(a.out)
    seq = read_sequence(bag, want_images=True, want_masks=False)
    masks = segmented_masks(bag, seq, out.with_name(bag.name + ".masks.npz"))
    stamps = [int(f.stamp_ns) for f in seq.frames]
    step_s = cost_model(*(float(v) for v in a.cost.split(",")), load=a.load)
    settings = {k: (float(v) if "." in v else int(v)) for k, v in
                (kv.split("=") for kv in a.recovery_settings.split(",") if kv)}
    rows = []
    for catch_up in a.catch_up or [0]:
        for seed in (int(s) for s in a.seeds.split(",")):
            model = make_model(39, shape=None if a.shape == "-" else Path(a.shape))
            cfg = TrackerConfig.from_flat(seed=seed)
            tracker = Tracker(model, seq.cameras, cfg)
            tracker.predictor = PublishedPredictor(model, tracker.predictor)
            schedule = RealTimeSchedule(
                evals=cfg.search.evals, heading_sets=cfg.heading.init_confirm_frames,
                startup=StartupCatchUp(sets=catch_up, evals=a.catch_up_evals, limit_ms=a.catch_up_ms,
                                       stale_ms=a.catch_up_stale_ms),
                governor=LoadGovernor(LoadSettings(evals=cfg.search.evals, period_s=PERIOD,
                                                   min_evals=a.min_evals)),
                recovery=Recovery(RecoverySettings(**settings)) if a.recovery else None)
            governed = governor_trace(schedule)

            def make_tracker():
                t = Tracker(model, seq.cameras, cfg)
                t.predictor = PublishedPredictor(model, t.predictor)
                return t
            done_steps, dropped = emulate(tracker, masks, schedule, period_s=PERIOD, step_s=step_s,
                                          frame_key=lambda k: stamps[k], make_tracker=make_tracker)
            steps = [dict(k=s.k, x=s.result.x, initialized=s.result.initialized, evals=s.result.n_evals,
                          budget=s.budget.evals, contour=s.budget.contour_stage, latency_ms=s.latency_s * 1e3,
                          gap=s.gap, **{**g, "energy": float(s.result.energy)}) for s, g in zip(done_steps, governed)]
            acc = score(model, seq, {stamps[s["k"]]: s["x"] for s in steps if s["x"] is not None}) or {}
            per_stamp = dict(zip(acc.get("stamps", ()), zip(acc.get("frame_errors_mm", ()),
                                                            heading_errors(model, seq, acc.get("stamps", ()), steps,
                                                                           stamps))))
            for s in steps:
                s["error_mm"], s["heading_deg"] = per_stamp.get(stamps[s["k"]], (None, None))
            if a.trace:
                print_trace(steps)
            lat = [s["latency_ms"] for s in steps if s["x"] is not None]
            k_init = next((s["k"] for s in steps if s["initialized"]), None)
            done = {s["k"] for s in steps}
            startup = [] if k_init is None else [k for k in range(k_init, min(k_init + 25, len(masks)))
                                                 if k not in done]
            row = dict(bag=bag.name, catch_up=catch_up, stale_ms=a.catch_up_stale_ms, seed=seed, load=a.load, dropped=dropped,
                       startup_dropped=startup, p50_ms=float(np.percentile(lat, 50)) if lat else None,
                       p95_ms=float(np.percentile(lat, 95)) if lat else None, mpjpe_mm=acc.get("mpjpe_mm"),
                       lowered=schedule.governor.lowered, caught_up=schedule.startup.caught_up,
                       probes=schedule.recovery.probes if schedule.recovery else 0,
                       recoveries=schedule.recovery.adopted if schedule.recovery else 0,
                       probe_log=[dict(p, k=stamps.index(p["frame"])) for p in schedule.probe_log],
                       steps=[{k: v for k, v in s.items() if k != "x"} for s in steps])
            rows.append(row)
            print(f"{bag.name} catch-up {catch_up} (stale {a.catch_up_stale_ms:g} ms) seed {seed} load {a.load:g}: dropped {dropped} (start-up "
                  f"{len(startup)}), latency p50 {row['p50_ms']:.0f} p95 {row['p95_ms']:.0f} ms (virtual), "
                  f"{row['mpjpe_mm']:.1f} mm, budget lowered {row['lowered']}, caught up {row['caught_up']}, "
                  f"probes {row['probes']} (recoveries {row['recoveries']})", flush=True)
            out.write_text(json.dumps(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
