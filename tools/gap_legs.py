#!/usr/bin/env python3
"""The gap after a fresh start, without a clock: does the track come back with the legs swapped?

    NUMBA_NUM_THREADS=1 python tools/gap_legs.py BAG --out R.json [--shape default|truth|FILE.yaml]
        [--gaps 0,10,15,20,25] [--seeds 0,1,2] [--set energy=fast --set init_polish=false ...] [--after 20]

What real time does to a fresh start (docs/history/issue35_speed.md, session 33 (lead)): the tracker initializes on the
first set with the person and runs its heading check on the sets held in sequence after it; the sets that arrived
meanwhile are dropped, so the next set it tracks comes ``N`` frame periods later. Here, per seed and gap ``N``: the
first sets with the person are stepped in sequence until the initialization and its heading check are over (as the
held sets give them), then ``N`` sets are skipped, then the next ``--after`` sets are stepped in sequence at the full
budget (``frames_elapsed`` = the gap for the first). The masks are segmented as ``isa-mocap track`` does
(``tools/emulate_realtime.segmented_masks``; cached beside ``--out``).

The legs' side (the lead's legs.py test): over the sets after the gap, the mean distance of the estimated knees and
ankles to the truth's, and to the truth's with the legs exchanged; ``swapped`` when the second is the smaller.
Printed per run: the heading check's decision, the first set after the gap, both distances, the mean joint error of the
sets after the gap. ``--side-gap 0``: the side check off (``better_side`` only: the code before it), for A/B.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

LEGS = ("left_knee", "left_ankle", "right_knee", "right_ankle")
SWAP = ("right_knee", "right_ankle", "left_knee", "left_ankle")


def truth_joints(seq, model):
    """Per frame index: ``(names, (J, 3) positions)`` of the ground truth (named markers, else the truth model's
    joints), None where the frame has none."""
    from isa_mocap_ros.body import joint_positions

    out = {}
    for k, f in enumerate(seq.frames):
        if getattr(f, "truth_markers", None) is not None and seq.truth_marker_names:
            out[k] = (list(seq.truth_marker_names), np.asarray(f.truth_markers, float))
        elif f.truth is not None and seq.truth_model is not None:
            tm = seq.truth_model
            out[k] = (list(tm.joint_names), joint_positions(tm, np.asarray(f.truth, float)[None])[0])
    return out


def leg_distances(model, x, truth):
    """Mean distance (m) of the estimate's knees and ankles to the truth's, and to the truth's legs exchanged; and
    the mean distance of the joints both name."""
    from isa_mocap_ros.body import joint_positions

    names, T = truth
    J = joint_positions(model, np.asarray(x, float)[None])[0]
    mine = list(model.joint_names)
    P = np.array([J[mine.index(n)] for n in LEGS])
    same = np.linalg.norm(P - np.array([T[names.index(n)] for n in LEGS]), axis=1).mean()
    swap = np.linalg.norm(P - np.array([T[names.index(n)] for n in SWAP]), axis=1).mean()
    shared = [n for n in (mine[j] for j in model.markers) if n in names]
    err = np.linalg.norm(np.array([J[mine.index(n)] for n in shared]) - np.array([T[names.index(n)] for n in shared]),
                         axis=1)
    return float(same), float(swap), float(np.nanmean(err))


def run_one(model, seq, masks, stamps, cfg, gap: int, after: int, truth) -> dict:
    """One fresh start, gap and track on (see the module docstring)."""
    from isa_mocap_ros.tracking.published import PublishedPredictor
    from isa_mocap_ros.tracking.tracker import Tracker

    tr = Tracker(model, seq.cameras, cfg)
    tr.predictor = PublishedPredictor(model, tr.predictor)
    k, notes, k_init = 0, [], None
    while k < len(masks):                   # the initialization and the heading check, in sequence
        r = tr.step(masks[k], stamps[k])
        notes += [n for n in r.notes if n.startswith("heading check")]
        if r.initialized:
            k_init = k
        k += 1
        if k_init is not None and not tr.checking_heading:
            break
    k_start = k + gap                       # the first set after the gap
    rows = []
    for j, kk in enumerate(range(k_start, min(k_start + after, len(masks)))):
        r = tr.step(masks[kk], stamps[kk], frames_elapsed=gap + 1 if j == 0 else 1)
        if kk in truth and r.x is not None:
            rows.append(leg_distances(model, r.x, truth[kk]))
        notes += [n for n in r.notes if "after the gap" in n or "side check" in n]
    d = np.array(rows) if rows else np.full((1, 3), np.nan)
    same, swap = 1e3 * d[:, 0].mean(), 1e3 * d[:, 1].mean()
    return dict(gap=gap, k_init=k_init, k_start=k_start, legs_mm=same, legs_exchanged_mm=swap,
                swapped=bool(swap < same), error_mm=1e3 * float(d[:, 2].mean()),
                per_frame_legs_mm=[round(1e3 * v, 1) for v in d[:, 0]], notes=notes)


def main(argv=None) -> int:
    from emulate_realtime import segmented_masks

    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.tracking.config import TrackerConfig

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bag")
    p.add_argument("--out", required=True)
    p.add_argument("--shape", default="default", help="default | truth (the bag's model) | a body-shape YAML")
    p.add_argument("--gaps", default="0,10,15,20,25")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--after", type=int, default=20, help="sets tracked in sequence after the gap (default 20)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="TrackerConfig.from_flat settings, e.g. energy=fast, init_polish=false")
    p.add_argument("--side-gap", type=int, default=None,
                   help="frame_prediction.SIDE_CHECK_GAP for this run (0 = the side check off: better_side only)")
    p.add_argument("--side-share", type=float, default=None, help="frame_prediction.SIDE_CHECK_SHARE for this run")
    a = p.parse_args(argv)
    from isa_mocap_ros.tracking import frame_prediction
    if a.side_gap is not None:
        frame_prediction.SIDE_CHECK_GAP = a.side_gap
    if a.side_share is not None:
        frame_prediction.SIDE_CHECK_SHARE = a.side_share
    bag, out = Path(a.bag), Path(a.out)
    seq = read_sequence(bag, want_images=True, want_masks=False)
    masks = segmented_masks(bag, seq, out.with_name(bag.name + ".masks.npz"))
    stamps = [int(f.stamp_ns) for f in seq.frames]
    if a.shape == "truth":
        model = seq.truth_model
    else:
        model = make_model(39, shape=None if a.shape == "default" else Path(a.shape))
    truth = truth_joints(seq, model)
    flat = {}
    for kv in a.set:
        key, v = kv.split("=", 1)
        flat[key] = {"true": True, "false": False}.get(v.lower(), v)
        if isinstance(flat[key], str):
            try:
                flat[key] = float(v) if "." in v or "e" in v else int(v)
            except ValueError:
                pass
    rows = []
    for seed in (int(s) for s in a.seeds.split(",")):
        cfg = TrackerConfig.from_flat(seed=seed, **flat)
        for gap in (int(g) for g in a.gaps.split(",")):
            row = dict(bag=bag.name, seed=seed, **run_one(model, seq, masks, stamps, cfg, gap, a.after, truth))
            rows.append(row)
            dec = next((n for n in row["notes"] if n.startswith("heading check decided")), "no check")
            print(f"{bag.name[:40]} seed {seed} gap {gap:2d}: init {row['k_init']} next {row['k_start']} "
                  f"legs {row['legs_mm']:.0f} / exchanged {row['legs_exchanged_mm']:.0f} mm "
                  f"{'SWAPPED' if row['swapped'] else 'ok'}; {row['error_mm']:.0f} mm; {dec[:60]}", flush=True)
            out.write_text(json.dumps(rows))
    n = sum(r["swapped"] for r in rows)
    print(f"swapped {n} of {len(rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
