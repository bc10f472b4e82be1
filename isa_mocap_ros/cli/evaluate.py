"""``isa-mocap evaluate RESULT``: accuracy tables and plots of a tracked sequence against its ground truth.

``RESULT`` is a directory written by ``isa-mocap track`` or ``isa-mocap run`` (its ``summary.json``
names the bag with the ground truth, its ``estimates`` holds ``/mocap/joint_states``), or an
estimates bag together with ``--truth BAG``. Estimates are matched to the ground truth by stamp.

Printed and written to ``OUT/evaluation.json`` (``OUT`` = ``--out``, default the result directory):

* per sequence: frames, mean joint error (EA-vs-PF Eq. 20, mm, over the markers both models
  share), median / max frame error, knee-angle RMSE (ISA §13.4.2);
* per joint: mean error of every marker (mm) and the RMSE of every joint-angle DOF (degrees), knees
  first;
* per frame: Eq. 20 error (a decimated table is printed; all frames are in the JSON).

Plots (PNG, like the ISA paper's Fig. 13.11/13.14): ``knees_and_error.png`` (left/right knee
flexion against the ground truth, per-frame error), and ``energy_and_error.png`` when the result
carries energies: per-frame energies in ``summary.json`` (``frame_energies``) or the estimator's
``energy`` values on ``/diagnostics`` in the recording (``isa-mocap run``; sampled at the
diagnostics rate, placed at the stamp of the latest estimate).

Body shape of the tracking model: the ground-truth subject's (as ``isa-mocap track`` does by
default) for a track result, the default shape for a run result (as the estimator node);
``--shape`` overrides. Exit codes: 0 done, 2 bad input.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="accuracy tables and plots of a track/run result against the ground truth",
                       description="Evaluate RESULT (a track/run output directory, or an estimates bag with --truth) "
                                   "against the ground truth: per-sequence, per-joint and per-frame errors, plots.")
    p.add_argument("result", metavar="RESULT", help="track/run output directory, or an estimates bag (with --truth)")
    p.add_argument("--truth", default=None, metavar="BAG", help="ground-truth bag (default: summary.json's bag)")
    p.add_argument("--out", default=None, metavar="DIR", help="where to write evaluation.json and the plots "
                                                            "(default: the result directory)")
    p.add_argument("--model", type=int, choices=(18, 28, 39), default=None,
                   help="tracking model DOF (default: summary.json's model_dof, else the estimates' joint names)")
    p.add_argument("--shape", choices=("auto", "truth", "default"), default="auto",
                   help="body shape of the tracking model (default auto: truth for track results, default for run)")
    p.add_argument("--rows", type=int, default=15, metavar="N", help="per-frame rows to print (default 15)")
    p.add_argument("--no-plots", action="store_true", help="write no PNG")
    p.add_argument("--json", action="store_true", help="print evaluation.json instead of the tables")
    p.set_defaults(func=run)


def _fail(msg: str) -> int:
    print(f"isa-mocap evaluate: error: {msg}", file=sys.stderr)
    return 2


def _resolve(args) -> tuple[Path, Path, dict, Path]:
    res = Path(args.result)
    if not res.exists():
        raise ValueError(f"RESULT: expected a track/run directory or an estimates bag, received {args.result!r} "
                         "(no such path)")
    summary: dict = {}
    if res.is_dir() and (res / "summary.json").is_file():
        summary = json.loads((res / "summary.json").read_text())
        est = res / "estimates"
        out_default = res
    else:
        est = res
        out_default = res.parent if res.is_file() or (res / "metadata.yaml").exists() else res
    if not est.exists():
        raise ValueError(f"RESULT: expected {est} (the estimates bag) to exist, received none")
    truth = args.truth or summary.get("bag")
    if not truth:
        raise ValueError("--truth: expected a ground-truth bag (RESULT has no summary.json naming one), received none")
    if not Path(truth).exists():
        raise ValueError(f"--truth: expected a rosbag2 directory or .mcap file, received {truth!r} (no such path)")
    return est, Path(truth), summary, Path(args.out) if args.out else out_default


def _diag_energies(path: Path) -> list[tuple[int, float]]:
    """``(log_time_ns, energy)`` of the estimator's /diagnostics status in a recording."""
    import msg_adapters as ma

    from isa_mocap_ros.bag import BagReader

    out = []
    with BagReader(path) as bag:
        if "/diagnostics" not in bag.topics:
            return out
        for m in bag.messages(["/diagnostics"]):
            msg = ma.from_cdr(m.data, m.type)
            for st in msg.status:
                if st.name.endswith("estimator"):
                    kv = {x.key: x.value for x in st.values}
                    try:
                        e = float(kv.get("energy", "nan"))
                    except ValueError:
                        continue
                    if np.isfinite(e) and int(float(kv.get("frames", "0") or 0)) > 0:
                        out.append((m.log_time_ns, e))
    return out


def evaluate(args) -> dict:
    """Do the work of ``isa-mocap evaluate`` (raises ValueError on bad input); return the evaluation."""
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.cli.run_report import read_estimates
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.eval import joint_errors_mm, marker_positions, per_joint_angle_rmse_deg, shared_markers
    from isa_mocap_ros.eval.report import accuracy, plot_sequence

    est_path, truth_path, summary, out = _resolve(args)
    from isa_mocap_ros.bag import BagReader

    with BagReader(truth_path) as probe:        # frames are built from images or masks: read the cheaper
        has_masks = any(x.startswith("/mocap/cam") and x.endswith("/mask") for x in probe.topics)
    seq = read_sequence(truth_path, want_images=not has_masks, want_masks=has_masks)
    if not (seq.has_truth and seq.truth_model is not None) and not seq.has_marker_truth:
        raise ValueError(f"--truth: expected ground truth (/mocap/ground_truth/*) in {truth_path}, received none")
    tm = seq.truth_model
    from isa_mocap_ros.cli.run_report import published_model

    published = published_model(est_path)
    if published is not None and args.model is None and args.shape == "auto":
        model, shape = published, "published by the tracker (/mocap/model)"
    else:
        dof = args.model or summary.get("model_dof") or (tm.dof if tm is not None else 39)
        shape = args.shape
        if shape == "auto":
            shape = "truth" if (("masks" in summary or not summary) and tm is not None) else "default"
        if shape == "truth" and tm is None:
            raise ValueError("--shape truth: expected a ground-truth model in the bag, received none")
        model = make_model(int(dof), shape=dict(tm.shape)) if shape == "truth" else make_model(int(dof))
    rec = read_estimates(est_path, model)
    poses = rec["poses"]
    from isa_mocap_ros.eval.report import plot_marker_score, score

    acc = score(model, seq, poses)
    if acc is None:
        n_truth = sum(1 for f in seq.frames if f.truth is not None or f.truth_markers is not None)
        raise ValueError(f"RESULT: expected estimates at ground-truth stamps, received {len(poses)} estimates and "
                         f"{n_truth} ground-truth frames with no stamp in common")
    stamps = acc.pop("stamps")
    P = np.array([poses[s] for s in stamps])
    t = (np.array(stamps) - stamps[0]) / 1e9
    by_markers = acc["scored_by"] == "markers"
    if by_markers:
        fm = {f.stamp_ns: f.truth_markers for f in seq.frames}
        TM = np.array([fm[s] for s in stamps])
        angles = {}
        n_truth = sum(1 for f in seq.frames if f.truth_markers is not None)
    else:
        truth = {f.stamp_ns: f.truth for f in seq.frames if f.truth is not None}
        T = np.array([truth[s] for s in stamps])
        names = shared_markers(model, tm)
        je = joint_errors_mm(marker_positions(model, P, joints=names), marker_positions(tm, T, joints=names))
        acc["per_marker_mm"] = {n: float(v) for n, v in zip(names, je.mean(axis=0))}
        angles = dict(per_joint_angle_rmse_deg(P, T, model, true_model=tm))
        knees = [k for k in ("left_knee_y", "right_knee_y") if k in angles]
        angles = {**{k: angles[k] for k in knees}, **{k: v for k, v in angles.items() if k not in knees}}
        n_truth = len(truth)
    ev = {"result": str(args.result), "estimates": str(est_path), "truth": str(truth_path),
          "optimizer": summary.get("optimizer"), "evals_per_frame": summary.get("evals_per_frame"),
          "model_dof": model.dof, "shape": shape, "scored_by": acc["scored_by"],
          "sequence": {k: acc[k] for k in ("frames", "mpjpe_mm", "median_frame_error_mm", "max_frame_error_mm",
                                           "knee_rmse_deg")},
          "worst_frame_stamp_ns": acc["worst_frame_stamp_ns"],
          "estimates_total": len(poses), "frames_without_estimate": n_truth - len(stamps),
          "per_marker_mm": acc["per_marker_mm"],
          "per_dof_rmse_deg": angles,
          "per_frame": [{"stamp_ns": int(s), "t_s": round(float(ti), 4), "error_mm": e}
                        for s, ti, e in zip(stamps, t, acc["frame_errors_mm"])]}
    energies = None
    fe = summary.get("frame_energies")
    fs = summary.get("frame_stamps_ns")
    if isinstance(fe, list) and isinstance(fs, list) and fe and len(fe) == len(fs):
        # `isa-mocap track`: one energy per estimated frame, matched to the evaluated stamps
        by_stamp = {int(s): (np.nan if e is None else float(e)) for s, e in zip(fs, fe)}
        ev_e = np.array([by_stamp.get(s, np.nan) for s in stamps], dtype=float)
        if np.isfinite(ev_e).any():
            energies = ("per frame (summary.json)", t, ev_e)
    elif isinstance(fe, list) and fe and len(fe) == len(stamps):
        energies = ("per frame (summary.json)", t, np.array([np.nan if e is None else e for e in fe], dtype=float))
    if energies is None:
        de = _diag_energies(est_path)
        if de:
            js = sorted(poses)
            lt = np.array([d[0] for d in de], dtype=np.int64)
            # a diagnostics message reports the latest estimate: place it at that estimate's stamp
            # (approximated by the recording's time offset of the first estimate)
            t0 = stamps[0]
            ev_t = (lt - lt[0]) / 1e9 + (js[0] - t0) / 1e9
            energies = ("/diagnostics (estimator, latest frame)", ev_t, np.array([d[1] for d in de]))
    if energies is not None:
        ev["energy"] = {"source": energies[0], "t_s": [round(float(x), 4) for x in energies[1]],
                        "energy": [float(x) if np.isfinite(x) else None for x in energies[2]]}
    out.mkdir(parents=True, exist_ok=True)
    plots = []
    if not args.no_plots:
        title = f"{summary.get('optimizer', '')} {summary.get('evals_per_frame', '')} evals/frame, {model.dof} DOF"
        if by_markers:
            plots.append(str(plot_marker_score(out / "knees_and_error.png", model, P, list(seq.truth_marker_names),
                                               TM, times_s=t, title=title.strip())))
        else:
            plots.append(str(plot_sequence(out / "knees_and_error.png", model, P, tm, T, times_s=t,
                                           title=title.strip())))
        if energies is not None and not by_markers:
            from isa_mocap_ros.eval import knee_errors_deg
            ke = np.abs(knee_errors_deg(P, T, model, true_model=tm))
            plots.append(str(_plot_energy(out / "energy_and_error.png", energies, t,
                                          np.array(acc["frame_errors_mm"]), title, knee_err_deg=ke)))
    ev["plots"] = plots
    (out / "evaluation.json").write_text(json.dumps(ev, indent=2) + "\n")
    ev["out"] = str(out)
    return ev


def _plot_energy(path: Path, energies, t, fe, title: str, *, knee_err_deg=None) -> Path:
    """PNG like the ISA paper's Fig. 13.14: energy of the estimate over time, and the error of the
    estimate over time (absolute left/right knee-angle error, and the Eq. 20 error per frame)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = 3 if knee_err_deg is not None else 2
    fig, ax = plt.subplots(rows, 1, figsize=(9, 2.6 * rows + 0.5), sharex=True)
    ax[0].plot(energies[1], energies[2], "g.-")
    ax[0].set_ylabel("energy")
    ax[0].set_title(f"energy of the estimate ({energies[0]})", fontsize=9)
    if knee_err_deg is not None:
        ke = np.asarray(knee_err_deg, dtype=float)
        ax[1].plot(t, ke[:, 0], "r-", label="left knee")
        ax[1].plot(t, ke[:, 1], "b-", label="right knee")
        ax[1].set_ylabel("knee error (deg)")
        ax[1].legend(loc="upper right", fontsize=8)
        ax[1].set_title(f"knee-angle error: RMSE {np.sqrt(np.mean(ke ** 2)):.2f} deg", fontsize=9)
    ax[-1].plot(t, fe, "k-")
    ax[-1].set_ylabel("mean joint error (mm)")
    ax[-1].set_xlabel("time (s)")
    ax[-1].set_title(f"Eq. 20 per frame: mean {fe.mean():.1f} mm", fontsize=9)
    if title.strip():
        fig.suptitle(title.strip())
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return Path(path)


def format_evaluation(ev: dict, rows: int = 15) -> str:
    s = ev["sequence"]
    lines = [f"evaluate: {ev['result']} against {ev['truth']} ({ev['model_dof']} DOF, {ev['shape']} shape"
             + (f", {ev['optimizer']} {ev['evals_per_frame']} evals/frame" if ev.get("optimizer") else "") + ")",
             "", "per sequence:",
             f"  {'frames':28s} {s['frames']} (without estimate: {ev['frames_without_estimate']})",
             f"  {'mean joint error (Eq. 20)':28s} {s['mpjpe_mm']:.1f} mm",
             f"  {'median / max frame error':28s} {s['median_frame_error_mm']:.1f} / {s['max_frame_error_mm']:.1f} mm",
             f"  {'knee-angle RMSE':28s} {s['knee_rmse_deg']:.2f} deg", "", "per joint: mean error (mm)"]
    for n, v in ev["per_marker_mm"].items():
        lines.append(f"  {n:28s} {v:8.1f}")
    lines += ["", "per DOF: joint-angle RMSE (deg), knees first"]
    for n, v in ev["per_dof_rmse_deg"].items():
        lines.append(f"  {n:28s} {v:8.2f}")
    pf = ev["per_frame"]
    pick = sorted(set(np.linspace(0, len(pf) - 1, min(rows, len(pf)), dtype=int).tolist())) if rows > 0 else []
    lines += ["", f"per frame: Eq. 20 error (mm), {len(pick)} of {len(pf)} frames (all in evaluation.json)",
              f"  {'t (s)':>8s} {'error':>8s}"]
    for i in pick:
        lines.append(f"  {pf[i]['t_s']:8.3f} {pf[i]['error_mm']:8.1f}")
    if "energy" in ev:
        e = np.array([np.nan if x is None else x for x in ev["energy"]["energy"]], dtype=float)
        lines += ["", f"energy ({ev['energy']['source']}): {int(np.isfinite(e).sum())} values, "
                      f"mean {np.nanmean(e):.4f}"]
    lines.append("")
    lines.append(f"evaluate: wrote {Path(ev['out']) / 'evaluation.json'}"
                 + "".join(f", {p}" for p in ev["plots"]))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    try:
        ev = evaluate(args)
    except (ValueError, OSError) as exc:
        return _fail(str(exc))
    if args.json:
        print(json.dumps({k: v for k, v in ev.items() if k != "out"}, indent=2))
    else:
        print(format_evaluation(ev, args.rows))
    return 0
