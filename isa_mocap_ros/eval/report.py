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
    return _error_panel_and_save(fig, ax[2], times_s, fe, "Eq. 20 per frame", title, path)


def score(model, seq, poses_by_stamp: dict) -> dict | None:
    """Accuracy of estimates (stamp -> pose of ``model``) against a sequence's ground truth.

    By name against the ground-truth joint centres (:func:`.metrics.score_markers`, no
    ground-truth model needed) when the sequence has named markers and either no ground-truth
    joint states or a mesh body (whose joint centres are the mesh skeleton's, not a model's);
    otherwise against the ground-truth poses through the ground-truth model (:func:`accuracy`).
    None without ground truth at an estimated stamp.

    Returns
    -------
    dict
        :func:`accuracy`'s keys plus ``scored_by`` (``"markers"`` or ``"joint_states"``),
        ``stamps`` (the scored stamps) and ``worst_frame_stamp_ns``.
    """
    from .metrics import score_markers

    use_markers = seq.has_marker_truth and (not seq.has_truth or seq.body_kind == "mesh")
    if use_markers:
        stamps = [f.stamp_ns for f in seq.frames if f.truth_markers is not None and f.stamp_ns in poses_by_stamp]
        if not stamps:
            return None
        by = {f.stamp_ns: f.truth_markers for f in seq.frames}
        P = np.array([poses_by_stamp[s] for s in stamps])
        sc = score_markers(model, P, seq.truth_marker_names, np.array([by[s] for s in stamps]),
                           joint_map=rig_joint_map(seq))
        out = {k: sc[k] for k in ("frames", "mpjpe_mm", "max_frame_error_mm", "median_frame_error_mm",
                                  "knee_rmse_deg", "markers")}
        out["frame_errors_mm"] = [round(float(e), 2) for e in sc["frame_errors_mm"]]
        out["per_marker_mm"] = sc["per_marker_mm"]
        # the same with each joint's mean offset removed (a reference whose points are not joint centres)
        for k in ("offset_removed_mpjpe_mm", "offset_removed_max_frame_error_mm", "offset_removed_per_marker_mm",
                  "per_marker_offset_mm", "backwards_share", "frames_facing_backwards",
                  "offset_removed_knee_rmse_deg", "joint_map", "mapped_mpjpe_mm", "mapped_median_frame_error_mm",
                  "mapped_max_frame_error_mm", "mapped_per_marker_mm", "mapped_knee_rmse_deg"):
            if k in sc:
                out[k] = sc[k]
        out.update(scored_by="markers", stamps=stamps, worst_frame_stamp_ns=int(stamps[sc["worst_frame"]]),
                   worst_frame_index=int(sc["worst_frame"]),
                   offset_removed_worst_frame_index=int(sc["offset_removed_worst_frame"]))
        if "heading_errors_deg" in sc:
            out["max_heading_error_deg"] = float(np.nanmax(sc["heading_errors_deg"]))
        if sc["knee_errors_deg"] is not None:
            ke = np.asarray(sc["knee_errors_deg"], float)
            out["knee_mean_abs_error_deg"] = float(np.nanmean(np.abs(ke)))
        return out
    if not seq.has_truth:
        return None
    stamps = [f.stamp_ns for f in seq.frames if f.truth is not None and f.stamp_ns in poses_by_stamp]
    if not stamps:
        return None
    by = {f.stamp_ns: f.truth for f in seq.frames}
    out = accuracy(model, np.array([poses_by_stamp[s] for s in stamps]), seq.truth_model,
                   np.array([by[s] for s in stamps]))
    out.update(scored_by="joint_states", stamps=stamps,
               worst_frame_stamp_ns=int(stamps[int(np.argmax(out["frame_errors_mm"]))]))
    return out


def rig_joint_map(seq):
    """The shipped joint map of the sequence's reference rig (the mesh bodies' MakeHuman ``cmu_mb`` rig), else None
    (a rig without a fitted map is scored raw and offset-removed only)."""
    from .joint_map import mesh_rig_map

    body = seq.truth_info.get("body") if isinstance(seq.truth_info, dict) else None
    if seq.body_kind == "mesh" and isinstance(body, dict) and "cmu_mb" in str(body.get("assets", "")):
        return mesh_rig_map()
    return None


def marker_score_lines(acc: dict) -> list[str]:
    """The per-joint table of a marker score (:func:`score` with ``scored_by == "markers"``) as text
    lines: per joint the mean error raw, with the joint's mean offset removed, and the offset."""
    pm, pr, off = acc.get("per_marker_mm"), acc.get("offset_removed_per_marker_mm"), acc.get("per_marker_offset_mm")
    if not pm or not pr:
        return []
    off = {n: float(np.linalg.norm(v)) for n, v in off.items()}
    mm = acc.get("mapped_per_marker_mm") or {}
    w = max(len(n) for n in pm)
    lines = [f"  {'joint':<{w}}  {'raw (mm)':>9}" + (f"  {'mapped (mm)':>11}" if mm else "")
             + f"  {'offset removed (mm)':>19}  {'mean offset (mm)':>16}"]
    for n in pm:
        lines.append(f"  {n:<{w}}  {pm[n]:9.1f}" + (f"  {mm.get(n, float('nan')):11.1f}" if mm else "")
                     + f"  {pr[n]:19.1f}  {off[n]:16.1f}")
    return lines


def plot_marker_score(path: Path, model, poses: np.ndarray, truth_names, truth_markers: np.ndarray, *,
                      times_s: np.ndarray, title: str = "") -> Path:
    """PNG: knee flexion measured in 3-D (estimate vs ground-truth joint centres) and the per-frame
    joint error over time (:func:`.metrics.score_markers`)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .metrics import knee_flexion_from_points, score_markers

    sc = score_markers(model, poses, truth_names, truth_markers)
    names = list(truth_names)
    Pe = marker_positions(model, poses, joints=[n for n in names if n in model.joint_names])
    en = [n for n in names if n in model.joint_names]
    fig, ax = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for i, side in enumerate(("left", "right")):
        js = [f"{side}_{j}" for j in ("hip", "knee", "ankle")]
        if all(j in names for j in js) and all(j in en for j in js):
            kt = np.degrees(knee_flexion_from_points(*(truth_markers[:, names.index(j)] for j in js)))
            ke = np.degrees(knee_flexion_from_points(*(Pe[:, en.index(j)] for j in js)))
            ax[i].plot(times_s, kt, "k-", lw=2, label="ground truth (3-D)")
            ax[i].plot(times_s, ke, "r--", lw=1.5, label="estimate")
            ax[i].legend(loc="upper right", fontsize=8)
        ax[i].set_ylabel(f"{side} knee (deg)")
    return _error_panel_and_save(fig, ax[2], times_s, sc["frame_errors_mm"], "Eq. 20 per frame (by marker name)",
                                 title, path)


def _error_panel_and_save(fig, ax, times_s, fe, what: str, title: str | None, path) -> Path:
    """The per-frame error panel of the knee plots, then the figure saved to ``path`` and closed."""
    import matplotlib.pyplot as plt

    ax.plot(times_s, fe, "b-")
    ax.set_ylabel("mean joint error (mm)")
    ax.set_xlabel("time (s)")
    ax.set_title(f"{what}: mean {fe.mean():.1f} mm, max {fe.max():.1f} mm", fontsize=9)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
