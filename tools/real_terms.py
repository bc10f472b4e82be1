#!/usr/bin/env python3
"""Which term of the energy prefers our pose to the peer's, by term and view? (issue 34)

    .venv/bin/python tools/real_terms.py BAG --out DIR [--offsets SUMMARY] [isa-mocap track options...]
    .venv/bin/python tools/real_terms.py --report DIR [DIR ...]

``BAG`` is the imported demo (``bench real``'s ``demo_bag_320``, docs/real_cameras.md section 3). The first form runs
``isa-mocap track`` in this process (the same code and options, so the same estimates) and after every step poses the
tracking model to the peer's points moved by each joint's mean offset of this track (``summary.json``'s
``per_marker_offset_mm``, or of the track ``--offsets SUMMARY`` names: the pose the offset-removed score calls exact)
by ``real_floor.ik_to_peer`` from the estimate (the "peer pose"), and evaluates, under the frame's own filtered masks
(kept during the track, scored after it), each view's silhouette term alone (Eq. 4 of that view, the tracker's energy kernel) and
the frame's keypoint term per view (as screened, times its weight; only on the frames the schedule detects on) for:

- ``est``: the estimate; ``peer``: the peer pose;
- ``est+peer_<part>``: the estimate with one part's coordinates fitted so that its joints reach the peer's (moved)
  points, the rest held (``left_arm``: the shoulder's, elbow's and wrist's angles to the peer's elbow and wrist;
  ``right_arm``; ``left_leg``: the hip's, knee's and ankle's angles to the peer's knee and ankle; ``right_leg``;
  ``pelvis``: the root, the lower spine and both hips to the peer's hips, with our neck, shoulders, knees and ankles
  held where they are), so a part's preference is read with the rest of the body where the energy put it.

The frame's total is ``Σ_v w_v E_v / Σ_v w_v`` (Eq. 5 with the tracker's view weights) plus the keypoint term; the
per-view rows are each view's ``E_v`` unweighted, so the share a view has of a difference is ``w_v ΔE_v / Σ w``.
Writes ``DIR/term_energies.json``; ``--report`` prints per third and variant the mean difference to ``est`` per view
(silhouette) and per view (keypoints, over the frames that have them), and the share of frames in which the variant
is higher (the energy prefers ours). A diagnostic that uses the peer's points: nothing here may be tuned on.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from real_floor import ik_to_peer  # noqa: E402
from track_hooks import pop_option, reference_markers, track_args, track_patched  # noqa: E402

#: part: (DOF-name prefixes fitted, joints moved to the peer's points, joints held where the estimate has them)
PARTS = {"left_arm": (("left_shoulder", "left_elbow", "left_wrist"), ("left_elbow", "left_wrist"), ()),
         "right_arm": (("right_shoulder", "right_elbow", "right_wrist"), ("right_elbow", "right_wrist"), ()),
         "left_leg": (("left_hip", "left_knee", "left_ankle"), ("left_knee", "left_ankle"), ()),
         "right_leg": (("right_hip", "right_knee", "right_ankle"), ("right_knee", "right_ankle"), ()),
         "pelvis": (("root", "spine_lower", "left_hip", "right_hip"), ("left_hip", "right_hip"),
                    ("neck", "left_shoulder", "right_shoulder", "left_knee", "right_knee", "left_ankle",
                     "right_ankle"))}


def part_coords(model) -> dict[str, np.ndarray]:
    """Pose coordinates each part's fit moves (``PARTS`` by DOF-name prefix)."""
    out = {p: np.array([i for i, n in enumerate(model.dof_names) if n.startswith(pre)], dtype=np.int64)
           for p, (pre, _, _) in PARTS.items()}
    return {p: c for p, c in out.items() if len(c)}


def fit_part(model, x: np.ndarray, coords: np.ndarray, targets: dict) -> np.ndarray:
    """``x`` with only ``coords`` moved (bounded least squares, the model's limits) so that the joints of
    ``targets`` (name -> (3,) point) come nearest to their points."""
    from scipy.optimize import least_squares

    from isa_mocap_ros.eval.metrics import marker_positions

    names = list(targets)
    T = np.array([targets[n] for n in names])
    lo, hi = np.asarray(model.lower, float)[coords], np.asarray(model.upper, float)[coords]

    def pose(z):
        y = x.copy()
        y[coords] = z
        return y

    def residual(z):
        return (marker_positions(model, pose(z)[None], joints=names)[0] - T).ravel()

    z = least_squares(residual, np.clip(x[coords], lo + 1e-9, hi - 1e-9), bounds=(lo, hi), x_scale=0.1,
                      max_nfev=200).x
    return pose(z)


def variants(model, x_est: np.ndarray, x_peer: np.ndarray, peer_points: dict,
             parts: dict) -> tuple[list[str], np.ndarray]:
    """The poses scored per frame: the estimate, the peer pose, and per part the estimate with that part's
    coordinates fitted to the peer's points of its joints (the rest held where the estimate has it)."""
    from isa_mocap_ros.eval.metrics import marker_positions

    names, rows = ["est", "peer"], [x_est, x_peer]
    for p, c in parts.items():
        _, moved, held = PARTS[p]
        if not all(j in peer_points for j in moved):
            continue
        targets = {j: peer_points[j] for j in moved}
        if held:
            P = marker_positions(model, x_est[None], joints=list(held))[0]
            targets.update({j: P[i] for i, j in enumerate(held)})
        names.append(f"est+peer_{p}")
        rows.append(fit_part(model, x_est, c, targets))
    return names, np.array(rows)


def keypoints_per_view(term, X: np.ndarray, n_views: int) -> np.ndarray:
    """``(n, V)``: the keypoint term's ``Σ w ρ(err²)`` split by the view of each correspondence (unscaled)."""
    from isa_mocap_ros.energy.keypoints import geman_mcclure

    d = term.distances(X)
    rho = term.weights[None] * geman_mcclure(d * d, term.sigma_m)
    return np.stack([rho[:, term.views == v].sum(axis=1) for v in range(n_views)], axis=1)


def _moved_truth(truth: dict, names: list[str], summary: Path) -> dict:
    from isa_mocap_ros.eval.metrics import body_frames

    offsets = json.loads(summary.read_text())["per_marker_offset_mm"]
    ks = sorted(truth)
    T = np.array([truth[k] for k in ks])
    B = body_frames(T, names.index("left_hip"), names.index("right_hip"))
    off = np.array([offsets.get(n, [0.0, 0.0, 0.0]) for n in names]) / 1e3
    T = T + np.einsum("fij,mj->fmi", B, off)
    return {k: T[i] for i, k in enumerate(ks)}


def record(argv: list[str]) -> int:
    from isa_mocap_ros.energy.silhouette import SilhouetteEnergy
    from isa_mocap_ros.tracking import keypoint_screen
    from isa_mocap_ros.tracking import tracker as tracker_module

    argv = list(argv)
    summary = pop_option(argv, "--offsets")
    summary = Path(summary) if summary is not None else None
    _, args, bag, out = track_args(argv, "--no-such-flag", __doc__)
    out = Path(out)
    names, truth = reference_markers(bag)
    per_tracker: list[list[dict]] = []
    last_masks: dict = {}
    last_term: list = [None]
    step, set_masks, screen = tracker_module.Tracker.step, SilhouetteEnergy.set_masks, keypoint_screen.screen
    trackers: list = []

    def recording_set_masks(self, masks, weights=None):
        last_masks[id(self)] = (masks, weights)
        return set_masks(self, masks, weights)

    def recording_screen(term, masks):
        kept = screen(term, masks)
        last_term[0] = kept[0]
        return kept

    def recording_step(self, masks, frame_index, **kw):
        last_term[0] = None
        r = step(self, masks, frame_index, **kw)
        if r.x is not None and int(frame_index) in truth and id(self.energy) in last_masks:
            if self not in trackers:        # a calibration tracks the first frames first: the longest run is kept
                trackers.append(self)
                per_tracker.append([])
            per_tracker[trackers.index(self)].append({"stamp": int(frame_index), "x": np.asarray(r.x, float).copy(),
                           "masks": last_masks[id(self.energy)], "term": last_term[0]})
        return r

    rc = track_patched(args, [(tracker_module.Tracker, "step", recording_step),
                              (SilhouetteEnergy, "set_masks", recording_set_masks),
                              (keypoint_screen, "screen", recording_screen)])
    if rc or not per_tracker:
        return rc or 1
    k = int(np.argmax([len(p) for p in per_tracker]))
    frames, tr = per_tracker[k], trackers[k]
    # the peer's points moved by each joint's mean offset (this track's, unless --offsets names another's): the pose
    # the offset-removed score calls exact
    truth = _moved_truth(truth, names, summary or out / "summary.json")
    model, obj = tr.model, tr.config.objective
    f = SilhouetteEnergy(model, tr.energy.cameras, None, method=obj.energy, downsample=obj.downsample,
                         n_model_points=obj.n_model_points, n_mask_points=obj.n_mask_points,
                         core_px=obj.silhouette_core_px, rng=np.random.default_rng(0))
    V = len(tr.energy.cameras)
    shared = [model.joint_names[j] for j in model.markers if model.joint_names[j] in names]
    parts = part_coords(model)
    rows: list[dict] = []
    for fr in frames:
        t = truth[fr["stamp"]]
        x_est = fr["x"]
        x_peer = ik_to_peer(model, x_est[None], t[[names.index(n) for n in shared]][None], shared)[0]
        peer_points = {n: t[names.index(n)] for n in shared if np.all(np.isfinite(t[names.index(n)]))}
        vnames, X = variants(model, x_est, x_peer, peer_points, parts)
        fmasks, weights = fr["masks"]
        w = np.ones(V) if weights is None else np.asarray(weights, float)
        sil = np.full((len(X), V), np.nan)
        for v in range(V):
            one = np.zeros(V)
            one[v] = 1.0
            try:
                set_masks(f, fmasks, one)
            except Exception:       # noqa: BLE001 - a view the frame did not use (no mask, empty)
                continue
            sil[:, v] = f(X)
        w_used = np.where(np.isfinite(sil[0]), w, 0.0)
        total = (np.nan_to_num(sil) * w_used).sum(axis=1) / w_used.sum()
        row = {"stamp": fr["stamp"], "variants": vnames, "weights": w_used.tolist(), "silhouette": sil.tolist(),
               "silhouette_total": total.tolist()}
        term = fr["term"]
        if term is not None and term.n_correspondences:
            row["keypoints"] = (tr.config.keypoints.keypoint_weight * keypoints_per_view(term, X, V)).tolist()
        rows.append(row)
    (out / "term_energies.json").write_text(json.dumps({"offsets": str(summary or out / "summary.json"),
                                                        "per_frame": rows}))
    report([out])
    return 0


def report(dirs: list[Path]) -> int:
    for d in dirs:
        rows = json.loads((Path(d) / "term_energies.json").read_text())["per_frame"]
        vn = rows[0]["variants"]
        thirds = np.array_split(np.arange(len(rows)), 3)
        S = np.array([r["silhouette"] for r in rows])                 # (F, n_variants, V)
        T = np.array([r["silhouette_total"] for r in rows])           # (F, n_variants)
        W = np.array([r["weights"] for r in rows])                    # (F, V)
        V = S.shape[2]
        print(f"== {d} ({len(rows)} frames); differences to est (positive: the energy prefers est); silhouette "
              "per view unweighted, then the view's weighted share of the total (w_v dE_v / sum w)")
        for k, name in enumerate(vn[1:], start=1):
            print(f"-- {name}")
            for i, s in enumerate(thirds):
                dS = S[s, k] - S[s, 0]
                share = W[s] * np.nan_to_num(dS) / W[s].sum(axis=1, keepdims=True)
                dT = T[s, k] - T[s, 0]
                line = (f"  third {i + 1}: silhouette total {dT.mean():+.4f} (higher in {np.mean(dT > 0):.0%}); "
                        + "; ".join(f"view {v} {np.nanmean(dS[:, v]):+.4f} (share {share[:, v].mean():+.4f}, "
                                    f"higher {np.mean(dS[:, v] > 0):.0%})" for v in range(V)))
                kf = [j for j in s if "keypoints" in rows[j]]
                if kf:
                    K = np.array([rows[j]["keypoints"] for j in kf])   # (f, n_variants, V)
                    dK = K[:, k] - K[:, 0]
                    dtot = dK.sum(axis=1) + (T[kf, k] - T[kf, 0])
                    line += (f"\n    keypoints ({len(kf)} frames): total {dK.sum(axis=1).mean():+.4f}; "
                             + "; ".join(f"view {v} {dK[:, v].mean():+.4f}" for v in range(V))
                             + f"; silhouettes + keypoints on those frames {dtot.mean():+.4f} "
                             f"(higher in {np.mean(dtot > 0):.0%})")
                print(line)
    return 0


def main(argv: list[str]) -> int:
    if argv[:1] == ["--report"]:
        return report([Path(a) for a in argv[1:]])
    return record(argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
