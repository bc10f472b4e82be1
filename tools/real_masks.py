#!/usr/bin/env python3
"""Where the real recording's masks and the tracked model disagree, per view, body part and third (issue 34).

    python tools/real_masks.py BAG TRACK_DIR [TRACK_DIR ...] [--every K]

``BAG`` is the imported demo (``bench real``'s ``demo_bag_320``, docs/real_cameras.md section 3), each ``TRACK_DIR`` an
``isa-mocap track --out`` directory (``estimates`` with the latched ``/mocap/model``). The masks are the default
segmentation's, learnt from the bag's background frames as ``track`` learns them (before the tracker's gate and
visual-hull filter). Per view, over every ``K``-th scored frame, it prints (shares, mean over frames and tracks):

- ``added``: mask pixels more than 3 px outside the estimate's silhouette, as a share of the mask, split into
  ``floor`` (below the estimate's lower ankle in the image: the treadmill, shadows, reflections), ``near`` (within
  15 px of the silhouette: limbs wider than the capsules, loose clothes, a limb the estimate misplaces) and ``far``
  (the rest: ghosts in the background model);
- ``missing``: silhouette pixels more than 3 px inside it that the mask lacks, as a share of the silhouette, and the
  share of those that are dark in the image (grey < 60: dark clothes on a dark floor), per body part (capsules
  grouped) and per third of the recording;
- ``peer on mask`` / ``peer in silhouette``: the share of the peer's projected points (the 14 scored joints and its
  feet and head points) on the mask and inside the estimate's silhouette dilated by 3 px.

A diagnostic: the peer's points are used, so nothing here may be tuned on.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

def _part(name: str) -> str:
    """The capsule's body part: trunk, head, left/right arm, left/right leg."""
    if name in ("pelvis", "abdomen", "torso", "chest", "shoulders"):
        return "trunk"
    if name in ("neck", "head"):
        return "head"
    side, _, rest = name.partition("_")
    return f"{side}_{'arm' if rest in ('upper_arm', 'forearm', 'hand') else 'leg'}"


def frame_figures(cam, image, mask, labels, parts, ankles_uv, peer_uv) -> dict:
    """One view's figures for one frame (module docstring)."""
    sil = labels >= 0
    k3 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))
    sil_out = cv2.dilate(sil.astype(np.uint8), k3) > 0
    sil_in = cv2.erode(sil.astype(np.uint8), k3) > 0
    m = mask > 0
    added = m & ~sil_out
    near_zone = cv2.dilate(sil.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (31, 31))) > 0
    rows = np.arange(m.shape[0])[:, None] * np.ones((1, m.shape[1]), bool)
    floor = added & (rows > np.nanmax(ankles_uv[:, 1])) if np.isfinite(ankles_uv).all() else added & False
    near = added & ~floor & near_zone
    far = added & ~floor & ~near_zone
    missing = sil_in & ~m
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    dark = missing & (grey < 60)
    out = {"mask_px": int(m.sum()), "sil_px": int(sil.sum()), "floor": floor.sum(), "near": near.sum(),
           "far": far.sum(), "missing": missing.sum(), "sil_in": sil_in.sum(), "dark_missing": dark.sum()}
    for p in set(parts):
        ids = [i for i, q in enumerate(parts) if q == p]
        inside = sil_in & np.isin(labels, ids)
        out[f"in_{p}"] = int(inside.sum())
        out[f"miss_{p}"] = int((inside & ~m).sum())
    ok = np.isfinite(peer_uv).all(axis=1)
    uv = np.round(peer_uv[ok]).astype(int)
    inb = (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < m.shape[1]) & (uv[:, 1] < m.shape[0])
    uv = uv[inb]
    out["peer_n"] = len(uv)
    out["peer_on_mask"] = int(m[uv[:, 1], uv[:, 0]].sum()) if len(uv) else 0
    out["peer_in_sil"] = int(sil_out[uv[:, 1], uv[:, 0]].sum()) if len(uv) else 0
    return out


def filtered_masks(model, cameras, masks, pred) -> list:
    """``masks`` through the tracker's mask gate and visual-hull filter around ``pred`` (their default settings)."""
    from isa_mocap_ros.tracking.config import MaskConfig
    from isa_mocap_ros.tracking.gate import gate_masks, predicted_silhouettes
    from isa_mocap_ros.tracking.hull import hull_filter, pose_box

    c = MaskConfig()
    g = gate_masks(masks, cameras, model, pred, c.gate_margin_px).masks
    keep = predicted_silhouettes(model, cameras, pred, margin_px=c.hull_keep_px)
    out = hull_filter(g, cameras, pose_box(model, pred, c.hull_pad_m), dilate_px=c.hull_dilate_px, keep=keep).masks
    return [np.zeros_like(m) if o is None else o for m, o in zip(masks, out)]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bag", type=Path)
    p.add_argument("tracks", type=Path, nargs="+")
    p.add_argument("--every", type=int, default=3, help="every K-th scored frame (default 3)")
    p.add_argument("--filtered", action="store_true",
                   help="the masks after the tracker's gate and visual-hull filter (default settings), with the "
                        "previous frame's estimate as the prediction")
    a = p.parse_args(argv)
    from isa_mocap_ros.body import capsule_endpoints
    from isa_mocap_ros.eval.metrics import marker_positions
    from isa_mocap_ros.cli.run_report import published_model, read_estimates
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.vision.render import render_labels
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    seq = read_sequence(a.bag, want_images=True, want_masks=False)
    learn = next((f.index for f in seq.frames if f.truth_markers is not None), 0)
    if learn == 0:
        print(f"real_masks: {a.bag}: expected background frames before the reference markers", file=sys.stderr)
        return 2
    masks = {}
    segs = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn)) for _ in seq.cameras]
    for f in seq.frames:
        ms = [s.apply(img) for s, img in zip(segs, f.images)]
        if f.truth_markers is not None:
            masks[f.stamp_ns] = (f, ms)
    stamps = sorted(masks)
    for tr in a.tracks:
        model = published_model(tr / "estimates")
        poses = read_estimates(tr / "estimates", model)["poses"]
        parts = [_part(n) for n in model.capsule_names]
        rows = {v: [] for v in range(len(seq.cameras))}
        for k, s in enumerate(stamps):
            if k % a.every or s not in poses:
                continue
            f, ms = masks[s]
            x = np.asarray(poses[s])[None]
            if a.filtered:
                if k == 0 or stamps[k - 1] not in poses:
                    continue
                ms = filtered_masks(model, seq.cameras, ms, np.asarray(poses[stamps[k - 1]]))
            E = capsule_endpoints(model, x)[0]
            J = marker_positions(model, x, joints=["left_ankle", "right_ankle"])[0]
            for v, cam in enumerate(seq.cameras):
                labels, _ = render_labels(cam, E, model.capsule_radii)
                ank_uv = cam.project(J)
                peer_uv = cam.project(np.asarray(f.truth_markers, float))
                r = frame_figures(cam, f.images[v], ms[v], labels, parts, np.asarray(ank_uv, float),
                                  np.asarray(peer_uv, float))
                r["third"] = min(2, 3 * k // len(stamps))
                rows[v].append(r)
        print(f"== {tr.name}")
        for v, rs in rows.items():
            def share(num, den, sel=None):
                rr = [r for r in rs if sel is None or r["third"] == sel]
                return np.mean([r[num] / max(r[den], 1) for r in rr]) if rr else float("nan")
            pp = sorted({k[3:] for r in rs for k in r if k.startswith("in_")})
            print(f"view {v}: mask/sil {share('mask_px', 'sil_px'):.2f}; added floor {share('floor', 'mask_px'):.3f} "
                  f"near {share('near', 'mask_px'):.3f} far {share('far', 'mask_px'):.3f}; missing "
                  f"{share('missing', 'sil_in'):.3f} (thirds " + " / ".join(f"{share('missing', 'sil_in', t):.3f}"
                                                                        for t in range(3))
                  + f"), dark {share('dark_missing', 'missing'):.2f}; per part missing "
                  + ", ".join(f"{q} {share('miss_' + q, 'in_' + q):.3f}" for q in pp)
                  + f"; peer on mask {share('peer_on_mask', 'peer_n'):.2f}, in silhouette {share('peer_in_sil', 'peer_n'):.2f}",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
