"""A degraded bag's masks against its clean twin's (issue 33: what 70 % noise and 35 occluders do to the masks).

    .venv/bin/python tools/mask_errors.py CLEAN_BAG DEGRADED_BAG [DEGRADED_BAG ...] [--frames 30] [--png OUT --frame K]

The bench's conditions render the same motion of the same body into the same cameras and then degrade the images
(``bench robustness``'s renderer), so the clean bag's segmented masks are the reference silhouettes of the degraded
bag's frames. Both bags are segmented as ``isa-mocap track`` and ``calibrate`` do (one background model per view,
learning from the bag's empty frames); the degraded masks are scored raw and cut to the visual hull's person blob
(:func:`isa_mocap_ros.tracking.init_hull.person_masks`, what the calibration's shape fit and the first frame see).
Per bag, over the first ``--frames`` frames after the learning and all views: the foreground the degraded masks
miss and the foreground they add, both as shares of the reference's, and how much of each lies within 1.5 px of
the reference's outline (a rim that moves, rather than a limb lost or a blob added). ``--png`` draws frame
``--frame``'s four views: white kept truth, red truth the hull-cut mask misses, green added and kept by the cut,
grey added and removed by the cut. A diagnostic, not part of the tracker.
"""
from __future__ import annotations

import argparse

import cv2
import numpy as np

from isa_mocap_ros.cli.shape_options import calibration_frames
from isa_mocap_ros.cli.track_io import read_sequence
from isa_mocap_ros.tracking.init_hull import person_masks


def segmented(bag: str, n: int):
    """The bag's cameras and the masks of its first ``n`` frames after the learning (as ``calibrate`` reads them)."""
    seq = read_sequence(bag, want_images=True, want_masks=False)
    learn = seq.empty_frames or 10
    return seq.cameras, [m for _, m in calibration_frames(seq, use_masks=False, learn=learn, first=learn, n=n)]


def scores(reference: list, degraded: list, cameras) -> dict:
    """Shares (of the reference foreground) missed and added, raw and hull-cut, and the rim shares."""
    acc = np.zeros(6)
    rim = np.zeros(4)
    for ref, deg in zip(reference, degraded):
        kept, _ = person_masks(deg, cameras)
        for t, m, k in zip(ref, deg, kept):
            T, M = t > 0, m > 0
            K = np.zeros_like(T) if k is None else k > 0
            out = cv2.distanceTransform((~T).astype(np.uint8), cv2.DIST_L2, 3)   # distance outside the truth
            inside = cv2.distanceTransform(T.astype(np.uint8), cv2.DIST_L2, 3)
            acc += [T.sum(), (T & ~M).sum(), (M & ~T).sum(), (T & ~K).sum(), (K & ~T).sum(), 1]
            rim += [(inside[T & ~K] <= 1.5).sum(), (T & ~K).sum(), (out[K & ~T] <= 1.5).sum(), (K & ~T).sum()]
    t = acc[0]
    return {"reference_px_per_view": t / acc[5], "raw_missed": acc[1] / t, "raw_added": acc[2] / t,
            "hull_missed": acc[3] / t, "hull_added": acc[4] / t,
            "hull_missed_on_rim": rim[0] / max(rim[1], 1), "hull_added_on_rim": rim[2] / max(rim[3], 1)}


def draw(reference, degraded, cameras, path: str) -> None:
    kept, _ = person_masks(degraded, cameras)
    tiles = []
    for t, m, k in zip(reference, degraded, kept):
        T, M = t > 0, m > 0
        K = np.zeros_like(T) if k is None else k > 0
        img = np.zeros(T.shape + (3,), np.uint8)
        img[M & ~K & ~T] = (80, 80, 80)
        img[T & K] = (255, 255, 255)
        img[T & ~K] = (0, 0, 255)
        img[K & ~T] = (0, 255, 0)
        tiles.append(img)
    h = len(tiles) // 2 * 2
    grid = np.vstack([np.hstack(tiles[i:i + 2]) for i in range(0, h, 2)]) if h else tiles[0]
    cv2.imwrite(path, grid)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("clean")
    p.add_argument("degraded", nargs="+")
    p.add_argument("--frames", type=int, default=30)
    p.add_argument("--png", default=None)
    p.add_argument("--frame", type=int, default=12)
    a = p.parse_args(argv)
    cameras, ref = segmented(a.clean, a.frames)
    for bag in a.degraded:
        _, deg = segmented(bag, a.frames)
        s = scores(ref, deg, cameras)
        print(f"{bag}: reference {s['reference_px_per_view']:.0f} px per view; raw masks miss {100 * s['raw_missed']:.1f} % "
              f"add {100 * s['raw_added']:.1f} %; hull-cut miss {100 * s['hull_missed']:.1f} % "
              f"({100 * s['hull_missed_on_rim']:.0f} % of it on the rim) add {100 * s['hull_added']:.1f} % "
              f"({100 * s['hull_added_on_rim']:.0f} % on the rim)")
        if a.png:
            draw(ref[a.frame], deg[a.frame], cameras, a.png if len(a.degraded) == 1 else f"{a.png}.{len(deg)}.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
