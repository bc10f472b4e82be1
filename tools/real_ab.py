#!/usr/bin/env python3
"""A/B runs of the real recording (issue 34): ``isa-mocap track`` per arm and seed, scored as ``bench real`` scores.

    python tools/real_ab.py BAG OUT --arm NAME='--shape auto' [--arm NAME2='...'] --seeds 0,1,2,3,4,5
    python tools/real_ab.py BAG OUT --report [--arms A,B]

``BAG`` is ``bench real``'s imported demo (``demo_bag_320``, docs/real_cameras.md section 3). Each run goes through
:func:`isa_mocap_ros.bench.real._track` (the bench's own tracking and scoring: offsets removed, per joint and third,
the filtered like-for-like figure) and is kept as ``OUT/NAME_sS.json`` beside the track in ``OUT/NAME_sS/``; a run
whose JSON exists is not repeated, so the arms are interleaved seed by seed (A B A B ...) and a stopped run resumes.
An argument ``{shape_of:ARM}`` in an arm is replaced by ``OUT/ARM_sS/body.yaml`` (the shape that arm calibrated with
the same seed: ``track --shape auto`` calibrates with the tracking seed, and a track with that file is the same
track bit for bit), so a change of the tracker need not calibrate again; ``{seed}`` by the seed.

``--report`` prints per arm the mean offset-removed error per seed, per joint and third (mean over the seeds), and
per 10-frame block, from the JSON files.
"""
from __future__ import annotations

import argparse
import ast
import importlib
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np


def _joint_frame_errors(collect: dict) -> dict:
    """Per scored joint, the error of every scored frame with the offsets removed as the score removes them (mm)."""
    from isa_mocap_ros.bench import real

    scored = real._scored_markers(collect)
    if scored is None:
        return {}
    frames, names, shared, Pe = scored
    Pt = np.array([collect["truth_markers"][k] for k in frames])[:, [names.index(n) for n in shared]]
    err = real._offset_removed_mm(Pe, Pt, shared)
    return {n: [round(float(x), 2) for x in err[:, m]] for m, n in enumerate(shared)}


def _run(bag: Path, out: Path, name: str, extra: str, seed: int, evals: int) -> dict:
    from isa_mocap_ros.bench import real

    stash: dict = {}
    thirds = real.joint_thirds

    def joint_thirds(collect, parts=3):          # the bench's own scoring, and the per-frame errors kept
        stash["joint_frame_errors_mm"] = _joint_frame_errors(collect)
        return thirds(collect, parts)

    words = shlex.split(extra.replace("{seed}", str(seed)))
    sets = [w[len("{set:"):-1] for w in words if w.startswith("{set:")]
    args = [str(out / f"{a[len('{shape_of:'):-1]}_s{seed}" / "body.yaml") if a.startswith("{shape_of:") else a
            for a in words if not a.startswith("{set:")]
    saved = []
    for item in sets:
        target, value = item.split("=", 1)
        module, attr = target.rsplit(".", 1)
        mod = importlib.import_module(module)
        saved.append((mod, attr, getattr(mod, attr)))
        setattr(mod, attr, ast.literal_eval(value))
    t0 = time.process_time()
    real.joint_thirds = joint_thirds
    try:
        r = real._track(bag, out / f"{name}_s{seed}", args + ["--seed", str(seed), "--evals", str(evals)])
    finally:
        real.joint_thirds = thirds
        for mod, attr, value in reversed(saved):
            setattr(mod, attr, value)
    r.update(stash)
    r["cpu_seconds"] = round(time.process_time() - t0, 1)
    r["seed"], r["arm"], r["args"] = seed, name, args + [f"{{set:{x}}}" for x in sets]
    return r


def _blocks(frame_errors, n: int = 10) -> list[float]:
    e = np.asarray(frame_errors, float)
    return [float(np.nanmean(e[i:i + n])) for i in range(0, len(e), n)]


def report(out: Path, arms: list[str] | None, target_mm: float = 40.0) -> None:
    runs: dict[str, list[dict]] = {}
    for f in sorted(out.glob("*_s*.json")):
        r = json.loads(f.read_text())
        runs.setdefault(r["arm"], []).append(r)
    for arm in arms or sorted(runs):
        rs = sorted(runs.get(arm, []), key=lambda r: r["seed"])
        if not rs:
            continue
        rem = [r["offset_removed_mpjpe_mm"] for r in rs]
        print(f"== {arm} ({' '.join(rs[0]['args'])}): seeds {[r['seed'] for r in rs]}")
        print("  offsets removed per seed: " + " / ".join(f"{x:.2f}" for x in rem) + f"  mean {np.mean(rem):.2f}"
              f"  raw {np.mean([r['mpjpe_mm'] for r in rs]):.1f}  knee {np.mean([r['knee_rmse_deg'] for r in rs]):.1f}"
              f"  backwards {sum(r['frames_facing_backwards'] or 0 for r in rs)}"
              f"  filtered {np.mean([r['filtered_offset_removed_mpjpe_mm'] or np.nan for r in rs]):.1f}"
              f"  cpu {np.mean([r.get('cpu_seconds', np.nan) for r in rs]):.0f} s")
        th = {n: np.mean([r["joint_thirds_mm"][n] for r in rs], axis=0) for n in rs[0]["joint_thirds_mm"]}
        cols = np.array(list(th.values()))
        print("  per joint, thirds (mean over seeds):")
        for n, v in th.items():
            print(f"    {n:15s} " + " ".join(f"{x:6.1f}" for x in v) + f"   all {np.mean(v):6.1f}")
        print(f"    {'mean':15s} " + " ".join(f"{x:6.1f}" for x in np.nanmean(cols, axis=0)))
        fe = [r.get("joint_frame_errors_mm") for r in rs if r.get("joint_frame_errors_mm")]
        if fe:
            per_frame = np.mean([np.nanmean(np.array(list(f.values())), axis=0) for f in fe], axis=0)
            print(f"  10-frame blocks ({len(fe)} seeds): " + " ".join(f"{x:.0f}" for x in _blocks(per_frame)))
            x = excess({n: np.mean([f[n] for f in fe], axis=0) for n in fe[0]}, target_mm)
            print(f"  mean over the target {target_mm:g} mm: {x['mean_over_mm']:+.2f}; frames above it "
                  f"{x['frames_above']} of {x['frames']}, which carry {x['carried_mm']:.2f} mm of the mean; per joint "
                  "(its share of the mean's excess, mm): " + ", ".join(f"{n} {v:+.2f}" for n, v in x["per_joint_mm"].items()))


def excess(joint_frame_errors: dict, target_mm: float = 40.0) -> dict:
    """Where a track's mean error exceeds ``target_mm``: ``joint_frame_errors`` maps each scored joint to its errors
    ``(F,)`` (mm, NaN where the reference has no point). Returns ``mean_over_mm`` (the mean minus the target),
    ``frames`` and ``frames_above`` (frames whose mean over the joints is above the target), ``carried_mm`` (the
    excess of those frames, averaged over all frames) and ``per_joint_mm``: each joint's share of ``mean_over_mm``
    ((its mean − target) / J; the shares sum to ``mean_over_mm`` when no point is missing)."""
    names = list(joint_frame_errors)
    E = np.array([np.asarray(joint_frame_errors[n], float) for n in names])          # (J, F)
    over = np.nanmean(E, axis=0) - target_mm
    return {"mean_over_mm": float(np.nanmean(over)), "frames": int(over.size), "frames_above": int(np.sum(over > 0)),
            "carried_mm": float(np.nansum(np.clip(over, 0.0, None)) / over.size),
            "per_joint_mm": {n: float((np.nanmean(E[m]) - target_mm) / len(names)) for m, n in enumerate(names)}}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("bag", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--arm", action="append", default=[], metavar="NAME=ARGS")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--evals", type=int, default=1500)
    p.add_argument("--report", action="store_true")
    p.add_argument("--arms", default=None, help="--report: these arms, in this order")
    a = p.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    if a.report:
        report(a.out, a.arms.split(",") if a.arms else None)
        return 0
    arms = [s.split("=", 1) for s in a.arm]
    for seed in (int(s) for s in a.seeds.split(",")):
        for name, extra in arms:
            f = a.out / f"{name}_s{seed}.json"
            if f.is_file():
                continue
            print(f"real_ab: {name} seed {seed} ...", file=sys.stderr, flush=True)
            r = _run(a.bag, a.out, name, extra, seed, a.evals)
            f.write_text(json.dumps(r))
            print(f"real_ab: {name} seed {seed}: {r['offset_removed_mpjpe_mm']:.2f} mm offsets removed "
                  f"({r['cpu_seconds']:.0f} CPU s)", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
