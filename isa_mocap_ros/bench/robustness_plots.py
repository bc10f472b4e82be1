"""Figures of ``isa-mocap bench robustness`` for the results page: knee angles per condition (as ISA
Fig. 13.15) and knee RMSE per condition beside the paper's values."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from isa_mocap_ros.bench.robustness import condition


def plot(res: dict, path: Path) -> Path:
    """Knee angles against the ground truth per condition (as ISA Fig. 13.15), first sequence, first seed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seq = res["design"]["sequences"][0]["name"]
    seed0 = (res["design"].get("seeds") or [res["design"]["seed"]])[0]
    runs = [r for r in res["runs"] if r["sequence"] == seq and r.get("seed", seed0) == seed0]
    fig, ax = plt.subplots(len(runs), 2, figsize=(10, 2.1 * len(runs) + 0.6), sharex=True, squeeze=False)
    for i, r in enumerate(runs):
        ke, kt = np.array(r["knee_est_deg"]), np.array(r["knee_truth_deg"])
        for j, side in enumerate(("left", "right")):
            a = ax[i, j]
            a.plot(r["t_s"], kt[:, j], "k-", lw=2, label="ground truth")
            a.plot(r["t_s"], ke[:, j], "r--", lw=1.3, label="estimate")
            a.set_title(f"{condition(r['condition'])[1]}: {side} knee (knee RMSE {r['knee_rmse_deg']:.2f}°)", fontsize=8)
            a.set_ylabel("deg", fontsize=8)
            if i == 0 and j == 0:
                a.legend(fontsize=7, loc="upper right")
    for a in ax[-1]:
        a.set_xlabel("time (s)")
    fig.suptitle(f"robustness: {seq}, {res['design']['optimizer']} {res['design']['evals']} evals/frame, seed {seed0}")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return Path(path)


def plot_bars(res: dict, path: Path) -> Path:
    """Knee RMSE per condition and sequence beside the paper's values."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    conds = res["conditions"]
    seqs = [s["name"] for s in res["design"]["sequences"]]
    w = 0.8 / (len(seqs) + 1)
    x = np.arange(len(conds))
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.bar(x - 0.4 + w / 2, [c["paper_knee_rmse_deg"] for c in conds], w, color="0.6", label="ISA paper")
    for i, sname in enumerate(seqs):
        cells = [c["per_sequence"].get(sname, {}) for c in conds]
        mean = np.array([v.get("knee_rmse_deg", np.nan) for v in cells])
        lo = np.array([v.get("knee_rmse_deg_min", m) for v, m in zip(cells, mean)])
        hi = np.array([v.get("knee_rmse_deg_max", m) for v, m in zip(cells, mean)])
        ax.bar(x - 0.4 + w * (i + 1.5), mean, w, yerr=np.vstack([mean - lo, hi - mean]), capsize=2, label=sname)
    ax.set_xticks(x, [c["label"] for c in conds], fontsize=8)
    ax.set_ylabel("knee-angle RMSE (deg)")
    ax.set_title("robustness (ISA §13.4.2): knee RMSE per condition (mean, min-max over seeds)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return Path(path)
