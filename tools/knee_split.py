"""Split the knee angle's error of tracked mesh runs into its parts (issue 33, the clean knee).

    .venv/bin/python tools/knee_split.py RUN_DIR [RUN_DIR ...] [--json FILE]

Each RUN_DIR is an ``isa-mocap track`` output (``summary.json`` naming the bag and the shape file, ``estimates``),
e.g. a ``bench mesh --out`` run directory or ``tools/oracle_track.py``'s. Per run, for the knee angle in 3-D
(thigh vs shank, :func:`isa_mocap_ros.eval.metrics.knee_flexion_from_points`) scored three ways (raw joint
centres, **mapped** through the shipped rig map, each joint's mean offset removed), over both knees and every
scored frame (not the initialized first one):

- ``rmse`` and its split ``rmse² = bias² + sd²`` (``bias``: the mean signed error, + = the estimate more bent);
- ``lin``: the error regressed on the true flexion, ``e = a + b·flexion``: ``a`` (deg), ``b`` (deg per deg), and the
  RMSE left after it (``rmse_after_lin``): what a flexion-dependent bias explains;
- ``step_rms``: the frame-to-frame change of the error, rms (white noise of sd σ gives √2 σ; a slowly varying error
  much less);
- ``straight`` / ``swing``: the RMSE and bias on the frames with the true flexion below 20° / above 40°;
- ``thigh`` / ``shin``: the mean signed sagittal pitch error of the segment (estimate − truth, degrees, + = tilted
  further forward at its lower end, i.e. hip flexion for the thigh), raw joint centres and mapped, and the mapped
  one's standard deviation over frames and legs (the sagittal knee angle is the thigh's pitch minus the shin's, so
  the two sd say which segment carries the knee's varying error); ``pelvis_up_mm``: the mean vertical error of the
  pelvis marker (mapped).

And a scoring floor per bag: the bag's ground-truth model (the mesh skeleton's bone lengths) posed at the true
poses, scored raw and mapped like an estimate (``truth_pose``): the knee error a perfect pose would get from the
map alone. A diagnostic: prints one JSON line per run and a table.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from isa_mocap_ros.body import make_model
from isa_mocap_ros.cli.run_report import read_estimates
from isa_mocap_ros.cli.track_io import read_sequence
from isa_mocap_ros.eval import marker_positions
from isa_mocap_ros.eval.joint_map import mapped_markers, mesh_rig_map
from isa_mocap_ros.eval.metrics import body_frames, knee_flexion_from_points, offset_removed_errors_mm

LEGS = [f"{s}_{j}" for s in ("left", "right") for j in ("hip", "knee", "ankle")]
MARKS = ["pelvis", *LEGS]


def knees_deg(P: np.ndarray) -> np.ndarray:
    """(F, 2) knee flexion (left, right) of points ``P (F, 7, 3)`` in :data:`MARKS` order, degrees."""
    return np.degrees(np.stack([knee_flexion_from_points(*(P[:, MARKS.index(f"{s}_{j}")] for j in ("hip", "knee", "ankle")))
                                for s in ("left", "right")], 1))


def sagittal_pitch_deg(P: np.ndarray, B: np.ndarray, a: str, b: str) -> np.ndarray:
    """(F,) pitch of segment a→b in the body's sagittal plane (forward-down angle from straight down), degrees;
    ``B (F, 3, 3)`` body frames (columns lateral, forward, up)."""
    v = P[:, MARKS.index(b)] - P[:, MARKS.index(a)]
    loc = np.einsum("fji,fj->fi", B, v)                 # (lateral, forward, up)
    return np.degrees(np.arctan2(loc[:, 1], -loc[:, 2]))


def stats(e: np.ndarray, flex: np.ndarray) -> dict:
    e, flex = e.ravel(), flex.ravel()
    ok = np.isfinite(e) & np.isfinite(flex)
    e, flex = e[ok], flex[ok]
    A = np.stack([np.ones_like(flex), flex], 1)
    coef, *_ = np.linalg.lstsq(A, e, rcond=None)
    res = e - A @ coef
    st, sw = flex < 20, flex > 40
    return {"rmse": float(np.sqrt(np.mean(e ** 2))), "bias": float(e.mean()), "sd": float(e.std()),
            "lin_a": float(coef[0]), "lin_b": float(coef[1]), "rmse_after_lin": float(np.sqrt(np.mean(res ** 2))),
            "straight_rmse": float(np.sqrt(np.mean(e[st] ** 2))) if st.any() else float("nan"),
            "straight_bias": float(e[st].mean()) if st.any() else float("nan"),
            "swing_rmse": float(np.sqrt(np.mean(e[sw] ** 2))) if sw.any() else float("nan"),
            "swing_bias": float(e[sw].mean()) if sw.any() else float("nan")}


def split_run(run: Path, cache: dict) -> dict:
    s = json.loads((run / "summary.json").read_text())
    bag = s["bag"]
    if bag not in cache:
        seq = read_sequence(bag, want_images=True, want_masks=False)     # the frames come with the images
        cache[bag] = seq
    seq = cache[bag]
    sh = s.get("shape")
    model = (make_model(39, shape=dict(seq.truth_model.shape)) if sh == "truth"
             else make_model(39, shape=Path(sh)) if sh not in (None, "auto", "default")
             else make_model(39, shape=run / "body.yaml") if (run / "body.yaml").is_file() else make_model(39))
    est = read_estimates(run / "estimates", model)["poses"]
    names = list(seq.truth_marker_names)
    tm = {int(f.stamp_ns): np.asarray(f.truth_markers) for f in seq.frames if f.truth_markers is not None}
    tp = {int(f.stamp_ns): np.asarray(f.truth) for f in seq.frames if f.truth is not None}
    ks = sorted(k for k in est if k in tm)[1:]                     # not the initialized first frame
    X = np.stack([est[k] for k in ks])
    T = np.stack([tm[k] for k in ks])[:, [names.index(n) for n in MARKS]]
    jm = mesh_rig_map()
    Pr = marker_positions(model, X, joints=MARKS)
    Pm = mapped_markers(jm, model, X, MARKS)
    B = body_frames(T, MARKS.index("left_hip"), MARKS.index("right_hip"))
    _, off = offset_removed_errors_mm(Pr, T, B)
    Pc = Pr - np.einsum("fij,mj->fmi", B, off / 1e3)
    kt = knees_deg(T)
    out = {"run": str(run), "bag": Path(bag).name, "seed": s.get("seed"), "frames": len(ks),
           "true_flexion_mean": float(kt.mean())}
    for tag, P in (("raw", Pr), ("mapped", Pm), ("offset_removed", Pc)):
        out[tag] = stats(knees_deg(P) - kt, kt)
        e = knees_deg(P) - kt
        out[tag]["step_rms"] = float(np.sqrt(np.mean(np.diff(e, axis=0) ** 2)))
    for seg, (a, b) in (("thigh", ("hip", "knee")), ("shin", ("knee", "ankle"))):
        d = [sagittal_pitch_deg(Pr, B, f"{sd}_{a}", f"{sd}_{b}") - sagittal_pitch_deg(T, B, f"{sd}_{a}", f"{sd}_{b}")
             for sd in ("left", "right")]
        out[f"{seg}_pitch_err"] = float(np.mean(d))
        dm = [sagittal_pitch_deg(Pm, B, f"{sd}_{a}", f"{sd}_{b}") - sagittal_pitch_deg(T, B, f"{sd}_{a}", f"{sd}_{b}")
              for sd in ("left", "right")]
        out[f"{seg}_pitch_err_mapped"] = float(np.mean(dm))
        out[f"{seg}_pitch_sd_mapped"] = float(np.std(np.stack(dm)))
    out["pelvis_up_mm_mapped"] = float(1e3 * np.mean(Pm[:, 0, 2] - T[:, 0, 2]))
    # the scoring floor: the bag's own ground-truth model at the true poses, scored like an estimate
    if seq.truth_model is not None and all(k in tp for k in ks):
        tmod = seq.truth_model
        XT = np.stack([tp[k] for k in ks])
        if XT.shape[1] == tmod.dof:
            out["truth_pose"] = {
                "raw": stats(knees_deg(marker_positions(tmod, XT, joints=MARKS)) - kt, kt),
                "mapped": stats(knees_deg(mapped_markers(jm, tmod, XT, MARKS)) - kt, kt)}
    return out


def main(argv: list[str]) -> int:
    js = None
    if "--json" in argv:
        i = argv.index("--json")
        js = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    if not argv:
        raise SystemExit(__doc__)
    cache: dict = {}
    rows = []
    for r in argv:
        o = split_run(Path(r), cache)
        rows.append(o)
        print(json.dumps(o), flush=True)
    print("| run | mapped rmse / bias / sd | after lin (a, b) | straight / swing rmse (bias) | step rms | raw rmse / bias"
          " | offset-removed rmse / bias | thigh / shin pitch err raw (mapped sd) | truth pose mapped rmse / bias |")
    for o in rows:
        m, r, c = o["mapped"], o["raw"], o["offset_removed"]
        tp = o.get("truth_pose", {}).get("mapped")
        print(f"| {Path(o['run']).name} | {m['rmse']:.2f} / {m['bias']:+.2f} / {m['sd']:.2f} | {m['rmse_after_lin']:.2f} "
              f"({m['lin_a']:+.1f}, {m['lin_b']:+.3f}) | {m['straight_rmse']:.2f} ({m['straight_bias']:+.1f}) / "
              f"{m['swing_rmse']:.2f} ({m['swing_bias']:+.1f}) | {m['step_rms']:.2f} | {r['rmse']:.2f} / {r['bias']:+.2f} | "
              f"{c['rmse']:.2f} / {c['bias']:+.2f} | {o['thigh_pitch_err']:+.1f} / {o['shin_pitch_err']:+.1f} "
              f"({o['thigh_pitch_sd_mapped']:.1f} / {o['shin_pitch_sd_mapped']:.1f}) | "
              + (f"{tp['rmse']:.2f} / {tp['bias']:+.2f} |" if tp else "– |"))
    if js:
        Path(js).write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
