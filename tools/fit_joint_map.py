#!/usr/bin/env python3
"""Fit a model → rig joint map (``isa_mocap_ros.eval.joint_map``) on TRAINING track results; score others with it.

    python tools/fit_joint_map.py --out config/joint_maps/makehuman_cmu_mb.yaml --train DIR [DIR ...] \\
        [--check DIR ...] [--scaled] [--rig NAME]

Each DIR is an ``isa-mocap track BAG --out DIR`` result on a bag with named ground-truth joint centres (a mesh
bag of ``isa-mocap synth --body mesh``); the tracking model is the one the estimates were published with
(``/mocap/model``), else ``summary.json``'s ``--shape`` file. The map is fitted on the ``--train`` results only;
the ``--check`` results (other subjects and motions) are scored with it: raw, mapped and offset-removed mean
joint error, knee RMSE and worst frame. Left and right are fitted as one (mirrored). Written with the list of
results it was fitted on (``source.fitted_on``). docs/decisions/012-joint-definitions.md says how the shipped
map was made.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def load_result(d: Path):
    """(model, poses (F, D), names, truth (F, M, 3)) of one track result, matched by stamp."""
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.body.model import load_shape
    from isa_mocap_ros.cli.run_report import published_model, read_estimates
    from isa_mocap_ros.cli.track_io import read_sequence

    summary = json.loads((d / "summary.json").read_text())
    est = d / "estimates"
    model = published_model(est)
    if model is None:
        shape = summary.get("shape")
        if not shape or not Path(str(shape)).is_file():
            raise ValueError(f"{d}: no /mocap/model in the estimates and no --shape file in summary.json ({shape!r})")
        model = make_model(int(summary.get("model_dof", 39)), shape=load_shape(shape))
    seq = read_sequence(summary["bag"], want_images=True, want_masks=False)   # frames come from the images
    if not seq.has_marker_truth:
        raise ValueError(f"{d}: the bag {summary['bag']} has no named ground-truth joint centres")
    poses = read_estimates(est, model)["poses"]
    by = {f.stamp_ns: f.truth_markers for f in seq.frames if f.truth_markers is not None}
    stamps = sorted(s for s in poses if s in by)
    if not stamps:
        raise ValueError(f"{d}: no estimate at a ground-truth stamp")
    return model, np.array([poses[s] for s in stamps]), list(seq.truth_marker_names), np.array([by[s] for s in stamps])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="map YAML to write")
    p.add_argument("--train", nargs="+", required=True, metavar="DIR", help="track results to fit on")
    p.add_argument("--check", nargs="*", default=[], metavar="DIR", help="track results to score with the map")
    p.add_argument("--scaled", action="store_true", help="offsets in parent-segment lengths (default metres)")
    p.add_argument("--rig", default="MakeHuman cmu_mb", help="rig name kept in the file")
    p.add_argument("--note", default="", help="free text kept in the file's source")
    a = p.parse_args(argv)
    from isa_mocap_ros.eval import score_markers
    from isa_mocap_ros.eval.joint_map import fit_joint_map, save_joint_map

    try:
        train = [load_result(Path(d)) for d in a.train]
        check = [load_result(Path(d)) for d in a.check]
    except (ValueError, OSError) as exc:
        print(f"fit_joint_map: error: {exc}", file=sys.stderr)
        return 2
    source = {"fitted_on": [Path(d).name for d in a.train], "frames": int(sum(len(r[1]) for r in train))}
    if a.note:
        source["note"] = a.note
    jm = fit_joint_map(train, scaled=a.scaled, rig=a.rig, source=source)
    save_joint_map(jm, a.out)
    print(f"fit_joint_map: wrote {a.out} (fitted on {len(train)} results, {source['frames']} frames)")
    rows = [("train", d, r) for d, r in zip(a.train, train)] + [("check", d, r) for d, r in zip(a.check, check)]
    print(f"{'set':5s} {'result':40s} {'raw':>6s} {'mapped':>6s} {'offrem':>6s} | {'knee':>5s} {'mapped':>6s} "
          f"{'offrem':>6s} | {'worst':>6s} {'mapped':>6s}")
    for kind, d, r in rows:
        s = score_markers(*r, joint_map=jm)
        print(f"{kind:5s} {Path(d).name:40s} {s['mpjpe_mm']:6.1f} {s['mapped_mpjpe_mm']:6.1f} "
              f"{s['offset_removed_mpjpe_mm']:6.1f} | {s['knee_rmse_deg']:5.2f} {s['mapped_knee_rmse_deg']:6.2f} "
              f"{s['offset_removed_knee_rmse_deg']:6.2f} | {s['max_frame_error_mm']:6.1f} "
              f"{s['mapped_max_frame_error_mm']:6.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
