"""Where the mapped knee error of mesh runs sits (issue 33's knee target): per side, bias or scatter, stance or swing.

    .venv/bin/python tools/knee_errors.py [--json FILE] BAG=ESTIMATES [BAG=ESTIMATES ...]

Each pair: a ground-truth mesh bag and a run's ``estimates`` recording of it (``isa-mocap track --out DIR``:
``DIR/estimates``; ``bench mesh --out DIR`` keeps them per run). The estimates are scored as ``bench mesh`` scores
them (``eval.metrics.score_markers`` with the bag's rig joint map, every estimated frame with ground truth) and the
mapped knee errors (estimate's flexion − truth's, degrees, per frame and side) are split into: the mean signed error
(bias: negative = the knee bent too little), its scatter about that mean (RMSE² = bias² + scatter²), the RMSE on the
frames where the true knee is bent less than ``STANCE_DEG`` (stance, the leg nearly straight) or more (swing), and
the share of the squared error on the worst tenth of the frame-sides. Prints one line per run and the means per
bag; ``--json`` writes them. A diagnostic, not part of the tracker.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from isa_mocap_ros.cli.run_report import published_model, read_estimates
from isa_mocap_ros.cli.track_io import read_sequence
from isa_mocap_ros.eval.metrics import knee_flexion_from_points, score_markers
from isa_mocap_ros.eval.report import rig_joint_map

#: true knee flexion (deg) below which a frame counts as stance (the leg nearly straight)
STANCE_DEG = 25.0


def knee_split(bag: str, est: str) -> dict:
    """The split of one run's mapped knee error (see the module's docstring)."""
    seq = read_sequence(bag, want_images=True, want_masks=False)
    model = published_model(Path(est))
    if model is None:
        raise SystemExit(f"knee_errors: {est}: no /mocap/model in the recording (not a track/bench estimates bag)")
    poses = read_estimates(Path(est), model)["poses"]
    stamps = sorted(f.stamp_ns for f in seq.frames if f.truth_markers is not None and f.stamp_ns in poses)
    if not stamps:
        raise SystemExit(f"knee_errors: {est}: no estimate on a frame with ground truth in {bag}")
    by = {f.stamp_ns: f.truth_markers for f in seq.frames}
    names = list(seq.truth_marker_names)
    T = np.array([by[s] for s in stamps])
    sc = score_markers(model, np.array([poses[s] for s in stamps]), names, T, joint_map=rig_joint_map(seq))
    km = np.asarray(sc["mapped_knee_errors_deg"], dtype=float)          # frames x (left, right)
    truth = np.stack([np.rad2deg(knee_flexion_from_points(*(T[:, names.index(f"{s}_{j}")]
                                                            for j in ("hip", "knee", "ankle"))))
                      for s in ("left", "right")], axis=1)
    stance = truth < STANCE_DEG

    def rms(v):
        return float(np.sqrt(np.nanmean(v ** 2))) if v.size else float("nan")

    out = {"bag": Path(bag).name, "estimates": str(est), "frames": int(len(stamps)),
           "rmse_deg": rms(km), "bias_deg": float(np.nanmean(km)),
           "scatter_deg": float(np.nanstd(km)),
           "stance_rmse_deg": rms(km[stance]), "swing_rmse_deg": rms(km[~stance]),
           "stance_bias_deg": float(np.nanmean(km[stance])) if stance.any() else float("nan"),
           "swing_bias_deg": float(np.nanmean(km[~stance])) if (~stance).any() else float("nan"),
           "swing_share": float(np.mean(~stance)),
           # share of the squared error on the worst tenth of the frame-sides
           "worst_tenth_share": float(np.sort((km ** 2).ravel())[::-1][:max(1, km.size // 10)].sum()
                                      / max(np.nansum(km ** 2), 1e-12))}
    for i, s in enumerate(("left", "right")):
        out[f"{s}_rmse_deg"], out[f"{s}_bias_deg"] = rms(km[:, i]), float(np.nanmean(km[:, i]))
    return out


FIELDS = ("rmse_deg", "bias_deg", "scatter_deg", "left_rmse_deg", "right_rmse_deg", "stance_rmse_deg",
          "swing_rmse_deg", "stance_bias_deg", "swing_bias_deg", "worst_tenth_share")


def main(argv: list[str]) -> int:
    js = None
    if len(argv) >= 2 and argv[0] == "--json":
        js, argv = argv[1], argv[2:]
    if not argv or any("=" not in a for a in argv):
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    rows = [knee_split(*a.split("=", 1)) for a in argv]
    for r in rows:
        print(r["bag"][:40], " ".join(f"{k[:-4]} {r[k]:.2f}" for k in FIELDS), r["estimates"])
    means = {}
    for b in sorted({r["bag"] for r in rows}):
        g = [r for r in rows if r["bag"] == b]
        means[b] = {k: float(np.mean([r[k] for r in g])) for k in FIELDS} | {"runs": len(g)}
        print("mean", b[:40], f"({len(g)} runs)", " ".join(f"{k[:-4]} {means[b][k]:.2f}" for k in FIELDS))
    if js:
        with open(js, "w") as f:
            json.dump({"runs": rows, "means": means, "stance_deg": STANCE_DEG}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
