"""The knee's silhouette-energy landscape at the ground truth of a mesh bag (issue 33, the swing knee).

    .venv/bin/python tools/knee_landscape.py BAG [--frames 40] [--min-flexion-deg 40] [--json OUT]

Question it answers: does Eq. 4 itself prefer a straighter capsule knee than the mesh's, or does the
tracker's estimate sit elsewhere? It takes the bag's ground-truth model (the mesh skeleton's bone lengths,
radii the default shape's scaled by stature) and ground-truth poses, segments the bag's images as ``isa-mocap
track`` does (one background model per view, learning from the bag's empty frames), and then

1. scans each knee whose true 3-D flexion (mesh joint centres) exceeds ``--min-flexion-deg`` over ±20° of the
   true knee DOF in 2.5° steps, the rest of the pose at the truth, with Eq. 4's two terms counted exactly
   (``render_mask``): the argmin's offset from the truth (+ = more bent) per term and for their sum;
2. fits the leg capsules' radii to the truth poses of every 2nd frame (one factor per capsule end: thigh at the
   hip and at the knee, shin at the knee and at the ankle, the foot; left/right alike; coordinate search on the
   summed energy), the "tapered capsule fitted to the mesh at each end" of the issue's lever 1;
3. scans again with the fitted radii.

Prints one line per scan; ``--json`` keeps every curve. A diagnostic, not part of the tracker (the bag needs
ground truth: ``isa-mocap synth ... --subject S``).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from isa_mocap_ros.body import capsule_endpoints
from isa_mocap_ros.cli.track_io import read_sequence
from isa_mocap_ros.eval.metrics import knee_flexion_from_points
from isa_mocap_ros.vision.render import render_mask
from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

OFFSETS_DEG = np.arange(-20.0, 20.1, 2.5)
#: leg radius groups fitted in step 2: (capsule, end) pairs, both sides alike
LEG_GROUPS = {"thigh_hip": (("thigh", 0),), "thigh_knee": (("thigh", 1),), "shin_knee": (("shin", 0),),
              "shin_ankle": (("shin", 1),), "foot": (("foot", 0), ("foot", 1))}


def load_frames(bag: Path, n_frames: int):
    """(ground-truth model, cameras, [(frame index, true pose, foreground masks, true flexion deg (2,))])."""
    seq = read_sequence(bag, want_images=True, want_masks=False)
    if seq.truth_model is None or not seq.truth_marker_names:
        raise SystemExit(f"{bag}: expected a bag with a ground-truth model and markers (isa-mocap synth)")
    learn = seq.empty_frames or 10
    segs = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn)) for _ in seq.cameras]
    names = list(seq.truth_marker_names)
    frames = []
    for fr in seq.frames:
        masks = [s.apply(img) for s, img in zip(segs, fr.images)]
        if fr.index < learn or fr.truth is None or fr.truth_markers is None:
            continue
        if len(frames) >= n_frames:
            break
        tm = np.asarray(fr.truth_markers)
        flex = [float(np.degrees(knee_flexion_from_points(*(tm[names.index(f"{side}_{j}")]
                                                              for j in ("hip", "knee", "ankle")))))
                for side in ("left", "right")]
        frames.append((fr.index, np.asarray(fr.truth, float), [m > 0 for m in masks], flex))
    return seq.truth_model, seq.cameras, frames


def eq4_terms(model, cameras, X, radii, fg):
    """Eq. 4's two terms (model off the foreground / foreground missed, each halved), mean over views, of poses
    ``X (n, D)`` with capsule ``radii (C, 2)`` against boolean masks ``fg``."""
    E = capsule_endpoints(model, X)
    t1, t2 = np.zeros(len(X)), np.zeros(len(X))
    for cam, F in zip(cameras, fg):
        n_fg = max(1, int(F.sum()))
        for j in range(len(X)):
            M = render_mask(cam, E[j], radii) > 0
            t1[j] += 0.5 * np.count_nonzero(M & ~F) / max(1, int(M.sum()))
            t2[j] += 0.5 * np.count_nonzero(F & ~M) / n_fg
    return t1 / len(fg), t2 / len(fg)


def scan(model, cameras, frames, radii, min_flexion_deg: float) -> list[dict]:
    knees = [list(model.dof_names).index(n) for n in ("left_knee_y", "right_knee_y")]
    off = np.radians(OFFSETS_DEG)
    rows = []
    for k, x, fg, flex in frames:
        for side, d in enumerate(knees):
            if flex[side] < min_flexion_deg:
                continue
            X = np.repeat(x[None], len(off), 0)
            X[:, d] = x[d] + off
            t1, t2 = eq4_terms(model, cameras, X, radii, fg)
            rows.append({"frame": k, "side": side, "true_flexion_deg": flex[side],
                         "argmin_term1_deg": float(OFFSETS_DEG[np.argmin(t1)]),
                         "argmin_term2_deg": float(OFFSETS_DEG[np.argmin(t2)]),
                         "argmin_deg": float(OFFSETS_DEG[np.argmin(t1 + t2)]), "energy": (t1 + t2).tolist()})
    return rows


def fit_leg_radii(model, cameras, frames):
    """Per-end factors of the leg radii minimising the summed Eq. 5 at the truth poses of every 2nd frame."""
    names = list(model.capsule_names)
    R0 = np.array(model.capsule_radii, float)
    use = frames[::2]

    def radii(f):
        R = R0.copy()
        for g, ends in LEG_GROUPS.items():
            for cap, end in ends:
                for side in ("left", "right"):
                    R[names.index(f"{side}_{cap}"), end] = R0[names.index(f"{side}_{cap}"), end] * f[g]
        return R

    def total(f):
        R = radii(f)
        return float(np.mean([sum(eq4_terms(model, cameras, x[None], R, fg))[0] for _, x, fg, _ in use]))

    f = dict.fromkeys(LEG_GROUPS, 1.0)
    best = start = total(f)
    for step in (0.2, 0.1, 0.05):
        for g in LEG_GROUPS:
            for s in (-step, step, -2 * step, 2 * step):
                t = {**f, g: max(0.3, f[g] + s)}
                e = total(t)
                if e < best - 1e-6:
                    best, f = e, t
    return f, radii(f), start, best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bag", type=Path)
    p.add_argument("--frames", type=int, default=40, help="frames after the empty ones (default 40)")
    p.add_argument("--min-flexion-deg", type=float, default=40.0, help="knees scanned: true flexion above (40)")
    p.add_argument("--json", type=Path, default=None, help="write every scan's curves here")
    a = p.parse_args(argv)
    model, cameras, frames = load_frames(a.bag, a.frames)

    def report(label, rows):
        m = {k: float(np.mean([r[k] for r in rows])) for k in ("true_flexion_deg", "argmin_term1_deg",
                                                                "argmin_term2_deg", "argmin_deg")}
        print(f"{label}: {len(rows)} knees above {a.min_flexion_deg:g} deg (true flexion {m['true_flexion_deg']:.1f}); "
              f"energy argmin from the truth (+ = more bent): term 1 {m['argmin_term1_deg']:+.1f}, term 2 "
              f"{m['argmin_term2_deg']:+.1f}, sum {m['argmin_deg']:+.1f} deg (median "
              f"{np.median([r['argmin_deg'] for r in rows]):+.1f})", flush=True)

    out = {"bag": str(a.bag), "frames": len(frames), "offsets_deg": OFFSETS_DEG.tolist()}
    out["scan_truth_model"] = rows = scan(model, cameras, frames, np.array(model.capsule_radii, float),
                                          a.min_flexion_deg)
    report("ground-truth model's radii", rows)
    f, R, e0, e1 = fit_leg_radii(model, cameras, frames)
    print(f"leg radii fitted at the truth: factors {({g: round(v, 2) for g, v in f.items()})}, mean Eq. 5 "
          f"{e0:.4f} -> {e1:.4f}", flush=True)
    out["fit"] = {"factors": f, "energy_before": e0, "energy_after": e1}
    out["scan_fitted_radii"] = rows = scan(model, cameras, frames, R, a.min_flexion_deg)
    report("fitted leg radii", rows)
    if a.json:
        a.json.write_text(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
