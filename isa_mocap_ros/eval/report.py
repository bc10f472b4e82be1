"""Accuracy summary and plots of a tracked sequence against its ground truth.

Pure (numpy + matplotlib's Agg backend): mean joint error per frame and sequence (EA-vs-PF Eq. 20)
over the markers both models share, knee-angle RMSE (ISA §13.4.2), and figures like the ISA paper's
Fig. 13.11/13.14 (knee angles against ground truth over time; per-frame error).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .metrics import (frame_errors_mm, knee_errors_deg, knee_rmse_deg, marker_positions, max_frame_error_mm,
                      mpjpe_mm, shared_markers)


def accuracy(model, poses: np.ndarray, truth_model, truth_poses: np.ndarray) -> dict:
    """Accuracy of estimates ``poses (F, D)`` against ``truth_poses (F, D')`` (same frames, in order)."""
    names = shared_markers(model, truth_model)
    Pe = marker_positions(model, poses, joints=names)
    Pt = marker_positions(truth_model, truth_poses, joints=names)
    fe = frame_errors_mm(Pe, Pt)
    return {"frames": int(len(poses)), "mpjpe_mm": mpjpe_mm(Pe, Pt), "max_frame_error_mm": max_frame_error_mm(Pe, Pt),
            "median_frame_error_mm": float(np.median(fe)),
            "knee_rmse_deg": knee_rmse_deg(poses, truth_poses, model, true_model=truth_model),
            "markers": list(names), "frame_errors_mm": [round(float(e), 2) for e in fe]}


def plot_sequence(path: Path, model, poses: np.ndarray, truth_model, truth_poses: np.ndarray, *,
                  times_s: np.ndarray, title: str = "") -> Path:
    """PNG: left/right knee flexion (estimate vs truth) and the per-frame joint error over time."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kt = np.degrees(truth_poses[:, truth_model.knee_dofs])
    ke = np.degrees(poses[:, model.knee_dofs])
    names = shared_markers(model, truth_model)
    fe = frame_errors_mm(marker_positions(model, poses, joints=names),
                         marker_positions(truth_model, truth_poses, joints=names))
    err = knee_errors_deg(poses, truth_poses, model, true_model=truth_model)
    fig, ax = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for i, side in enumerate(("left", "right")):
        ax[i].plot(times_s, kt[:, i], "k-", lw=2, label="ground truth")
        ax[i].plot(times_s, ke[:, i], "r--", lw=1.5, label="estimate")
        ax[i].set_ylabel(f"{side} knee (deg)")
        ax[i].legend(loc="upper right", fontsize=8)
        ax[i].set_title(f"{side} knee flexion, RMSE {np.sqrt(np.mean(np.square(err[:, i]))):.2f} deg", fontsize=9)
    ax[2].plot(times_s, fe, "b-")
    ax[2].set_ylabel("mean joint error (mm)")
    ax[2].set_xlabel("time (s)")
    ax[2].set_title(f"Eq. 20 per frame: mean {fe.mean():.1f} mm, max {fe.max():.1f} mm", fontsize=9)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
