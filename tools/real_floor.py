#!/usr/bin/env python3
"""How close can our rigid body model come to the peer's points at all? A diagnostic of the real recording (issue 34).

    python tools/real_floor.py BAG TRACK_DIR [TRACK_DIR ...]

``BAG`` is the imported demo (``bench real``'s ``demo_bag_320``, docs/real_cameras.md section 3), each ``TRACK_DIR`` an
``isa-mocap track --out`` directory (``estimates`` with the latched ``/mocap/model``: the shape it tracked with). Per
track it prints, scored as ``bench real`` scores (each joint's mean offset removed in the reference hips' axes):

- the tracked estimate;
- the same model posed to the peer's own points in every frame (bounded least squares on the 14 scored joints,
  started at the tracked pose; the peer's points are the target here, so this is a bound, never a score): what a
  rigid model of that shape could reach if the images were read perfectly. The IK is local (from the tracked pose)
  and minimises the raw distance, not the offset-removed one, so the true floor is lower still.

and once, the peer's own distances that a rigid body keeps constant (shoulder width, hip width, hips to neck) per
third of the recording, mean ± standard deviation over the frames.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def peer_distances(names: list[str], T: np.ndarray, parts: int = 3) -> dict:
    """The peer's shoulder width, hip width and mid-hip to neck distance (mm) per span: ``{name: [(mean, std)...]}``."""
    def g(n):
        return T[:, names.index(n)]
    d = {"shoulder width": np.linalg.norm(g("left_shoulder") - g("right_shoulder"), axis=1),
         "hip width": np.linalg.norm(g("left_hip") - g("right_hip"), axis=1),
         "mid-hip to neck": np.linalg.norm(g("neck") - 0.5 * (g("left_hip") + g("right_hip")), axis=1)}
    spans = np.array_split(np.arange(len(T)), parts)
    return {k: [(float(np.nanmean(v[s]) * 1e3), float(np.nanstd(v[s]) * 1e3)) for s in spans] for k, v in d.items()}


def ik_to_peer(model, X: np.ndarray, Pt: np.ndarray, shared: list[str]) -> np.ndarray:
    """Per frame, the pose of ``model`` nearest (least squares) to the peer's points ``Pt`` (F, J, 3) of the joints
    ``shared``, within the model's limits, started at ``X`` (F, D)."""
    from scipy.optimize import least_squares

    from isa_mocap_ros.eval.metrics import marker_positions

    lo, hi = np.asarray(model.lower, float), np.asarray(model.upper, float)
    out = X.copy()
    for f in range(len(X)):
        ok = np.isfinite(Pt[f]).all(axis=1)

        def residual(x, f=f, ok=ok):
            return (marker_positions(model, x[None], joints=shared)[0][ok] - Pt[f][ok]).ravel()

        def jacobian(x, f=f, ok=ok, h=1e-6):
            # forward differences, all D steps in one batch of the kinematics
            Xh = x[None] + h * np.eye(len(x))
            P0 = marker_positions(model, x[None], joints=shared)[0][ok].ravel()
            return ((marker_positions(model, Xh, joints=shared)[:, ok].reshape(len(x), -1) - P0) / h).T

        out[f] = least_squares(residual, np.clip(X[f], lo + 1e-9, hi - 1e-9), jac=jacobian, bounds=(lo, hi),
                               x_scale=0.1, max_nfev=400).x
    return out


def _score(model, X, Pt, shared, parts: int = 3) -> tuple[float, float, list[float], dict]:
    from isa_mocap_ros.eval.metrics import body_frames, marker_positions, offset_removed_errors_mm

    P = marker_positions(model, X, joints=shared)
    with np.errstate(invalid="ignore"):
        raw = float(np.nanmean(np.linalg.norm(P - Pt, axis=-1)) * 1e3)
        err, _ = offset_removed_errors_mm(P, Pt, body_frames(Pt, shared.index("left_hip"), shared.index("right_hip")))
        thirds = [float(np.nanmean(err[s])) for s in np.array_split(np.arange(len(P)), parts)]
        per = {n: float(np.nanmean(err[:, m])) for m, n in enumerate(shared)}
        return raw, float(np.nanmean(np.nanmean(err, axis=1))), thirds, per


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bag", type=Path)
    p.add_argument("tracks", type=Path, nargs="+")
    a = p.parse_args(argv)
    from isa_mocap_ros.cli.run_report import published_model, read_estimates
    from isa_mocap_ros.cli.track_io import read_sequence

    seq = read_sequence(a.bag, want_images=True, want_masks=False)
    names = list(seq.truth_marker_names)
    truth = {f.stamp_ns: f.truth_markers for f in seq.frames if f.truth_markers is not None}
    if not truth:
        print(f"real_floor: {a.bag}: expected reference markers (/mocap/ground_truth/markers), found none", file=sys.stderr)
        return 2
    T = np.array([truth[s] for s in sorted(truth)])
    for k, v in peer_distances(names, T).items():
        print(f"peer {k} (mm, per third): " + " / ".join(f"{m:.0f} ± {s:.0f}" for m, s in v))
    for tr in a.tracks:
        model = published_model(tr / "estimates")
        if model is None:
            print(f"real_floor: {tr / 'estimates'}: expected the latched /mocap/model, found none", file=sys.stderr)
            return 2
        poses = read_estimates(tr / "estimates", model)["poses"]
        stamps = sorted(s for s in poses if s in truth)
        X = np.array([poses[s] for s in stamps])
        shared = [model.joint_names[j] for j in model.markers if model.joint_names[j] in names]
        Pt = np.array([truth[s] for s in stamps])[:, [names.index(n) for n in shared]]
        for label, XX in (("tracked", X), ("posed to the peer's points (a bound)", ik_to_peer(model, X, Pt, shared))):
            raw, rem, thirds, per = _score(model, XX, Pt, shared)
            print(f"{tr.name}, {label}: raw {raw:.1f} mm, offsets removed {rem:.1f} mm (thirds "
                  + " / ".join(f"{t:.1f}" for t in thirds) + "); per joint " + ", ".join(
                      f"{n.replace('_', ' ')} {v:.0f}" for n, v in per.items()), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
