"""Trace the untwist stage frame by frame on a ground-truth bag (issue 33: which frames take an untwist, at what cost).

    .venv/bin/python tools/untwist_trace.py [--null] BAG --out DIR [isa-mocap track options, e.g. --leg-untwist 0.01]

Runs ``isa-mocap track`` in this process (the same code and options) with ``chain_moves.untwist_legs`` wrapped: on
every call it records the frame, the stage's CPU time (``time.process_time``; each step's too), the step
objective's energy of the pose before and after the stage (two more evaluations, outside the tracker's count: the
results are unchanged, the energy has no random draws), the legs changed and their hip twists before and after. At
the end it adds each frame's raw joint error (the model's joint centres against the bag's markers of the same names,
the first frame left out) and writes
``DIR/untwist_trace.json``; it prints the frames with the largest errors and what the stage did on and before them.
``--null``: the stage runs and is charged as usual but every leg keeps its pose (the control for what
taking the evaluations from the main search alone changes: a different random path, not the untwist's choices).
A diagnostic, not part of the tracker (the bag needs ground truth: ``isa-mocap synth``).
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from isa_mocap_ros.body import joint_positions
from isa_mocap_ros.cli.run_report import read_estimates
from isa_mocap_ros.cli.track_io import read_sequence
from isa_mocap_ros.tracking import chain_moves
from isa_mocap_ros.tracking import tracker as tracker_module

sys.path.insert(0, str(Path(__file__).parent))
from track_hooks import track_args, track_patched  # noqa: E402


def main(argv: list[str]) -> int:
    null, argv, bag, out = track_args(argv, "--null", __doc__)
    seq = read_sequence(bag, want_images=True, want_masks=False)
    records: list[dict] = []
    frame = [None]
    step, untwist = tracker_module.Tracker.step, chain_moves.untwist_legs

    models: list = []
    step_cpu_ms: list[float] = []

    def recording_step(self, masks, frame_index, **kw):
        frame[0] = int(frame_index)
        if not models:
            models.append(self.model)
        t0 = time.process_time()
        r = step(self, masks, frame_index, **kw)
        step_cpu_ms.append(1e3 * (time.process_time() - t0))       # includes the stage, not the trace's 2 evaluations
        return r

    def recording_untwist(tr, ctx, x, **kw):
        t0 = time.process_time()
        r = untwist(tr, ctx, x, **kw)
        cpu_ms = 1e3 * (time.process_time() - t0)
        if null:                          # same evaluations charged, the pose (and its energy) kept
            x0 = np.clip(np.asarray(x, dtype=float), tr.model.lower, tr.model.upper)
            e0 = kw.get("energy")
            r = (x0, float(ctx.objective(x0[None, :])[0]) if e0 is None else float(e0), r[2], [])
        names = list(tr.model.dof_names)
        e = np.asarray(ctx.objective(np.stack([np.clip(x, tr.model.lower, tr.model.upper), r[0]])), dtype=float)
        hz = [names.index(f"{s}_hip_z") for s in ("left", "right")]
        records.append({"frame": frame[0], "cpu_ms": round(cpu_ms, 3), "energy_before": float(e[0]), "energy_after": float(e[1]),
                        "rise": float(e[1] / e[0] - 1.0), "legs": list(r[3]),
                        "hip_z_before_deg": np.round(np.degrees(np.asarray(x)[hz]), 2).tolist(),
                        "hip_z_after_deg": np.round(np.degrees(r[0][hz]), 2).tolist()})
        return r

    rc = track_patched(argv, [(tracker_module.Tracker, "step", recording_step),
                              (chain_moves, "untwist_legs", recording_untwist)])
    with open(Path(out) / "untwist_trace.json", "w") as f:       # kept if the scoring below fails
        json.dump({"per_frame": records}, f)
    if rc:
        return rc
    model = models[0]
    est = read_estimates(Path(out) / "estimates", model)["poses"]
    names, jn = list(seq.truth_marker_names), list(model.joint_names)
    common = [n for n in jn if n in names]
    tm = {int(f.stamp_ns): np.asarray(f.truth_markers) for f in seq.frames if f.truth_markers is not None}
    ks = sorted(k for k in est if k in tm)[1:]          # not the first (initialized) frame
    J = joint_positions(model, np.stack([est[k] for k in ks]), backend="numpy")[:, [jn.index(n) for n in common]]
    T = np.stack([tm[k] for k in ks])[:, [names.index(n) for n in common]]
    err = dict(zip(ks, (1000.0 * np.linalg.norm(J - T, axis=-1).mean(1)).tolist()))
    for r in records:
        r["raw_error_mm"] = round(err.get(r["frame"], float("nan")), 1)
    taken = [r for r in records if r["legs"]]
    rises = np.array([r["rise"] for r in taken]) if taken else np.zeros(1)
    res = {"frames": len(records), "untwists_taken": len(taken), "legs_taken": sum(len(r["legs"]) for r in taken),
           "mean_energy": float(np.mean([r["energy_before"] for r in records])) if records else None,
           "mean_rise_taken": float(rises.mean()), "max_rise_taken": float(rises.max()),
           "mean_raw_error_mm": float(np.mean(list(err.values()))), "max_raw_error_mm": float(max(err.values())),
           "stage_cpu_ms_per_frame": float(np.mean([r["cpu_ms"] for r in records])) if records else None,
           "step_cpu_ms_per_frame": float(np.median(step_cpu_ms[1:])) if len(step_cpu_ms) > 1 else None}
    print(json.dumps(res))
    order = [r["frame"] for r in records]
    for r in sorted(records, key=lambda r: -r["raw_error_mm"] if r["raw_error_mm"] == r["raw_error_mm"] else 0)[:3]:
        i = order.index(r["frame"])
        for q in records[max(0, i - 4):i + 1]:
            print(json.dumps(q))
        print("--")
    with open(Path(out) / "untwist_trace.json", "w") as f:
        json.dump({**res, "per_frame": records}, f)
    return 0

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
