#!/usr/bin/env python3
"""How far the detected landmarks lie from a reference, per view, for each of the detector's crops (issue 34).

    python tools/keypoint_crops.py BAG [--every K]
    python tools/keypoint_crops.py BAG --changed

``--changed`` (any bag with images; no reference needed): on every frame and view, whether the ``"person_checked"``
crop gives other landmarks than the ``"mask"`` crop, and on how many of the frames the keypoint schedule detects on
(``track``'s and the node's: each view's first 4 frames with a person, then every 8th). Where it gives the same on
every scheduled frame, ``track`` and the network give the same estimates with either crop, bit for bit.

``BAG``: an imported recording with reference markers (``bench real``'s ``demo_bag_320``, docs/real_cameras.md
section 3). The masks are the default segmentation's, learnt from the bag's background frames as ``track`` learns
them. On every ``K``-th frame with reference markers, each view is detected on with each crop of
:data:`isa_mocap_ros.vision.keypoint_schedule.CROPS` (the square around every foreground pixel; around the person's
components; those turned to their long axis) and, for comparison, a second pass turned by the first pass's own
hips and shoulders (two model calls, as MediaPipe places its next region). Per view and crop it prints the
median and mean pixel distance of the 12 limb landmarks (confidence >= 0.5, as the keypoint term keeps them) from
the reference's points of the same names projected, the share farther than 15 px, and the frames whose detection
has left and right swapped (the left hip, shoulder and knee nearer the reference's right ones, two of three).

The reference is a peer's estimate with its own point definitions (Pose2Sim's keypoints are not BlazePose's), so
the figures compare the crops with each other; they are not the detector's absolute error. Evaluation only.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bag", type=Path)
    p.add_argument("--every", type=int, default=2, help="every K-th frame with reference markers (default 2)")
    p.add_argument("--changed", action="store_true", help="where 'person_checked' differs from 'mask' (see above)")
    a = p.parse_args(argv)
    if a.changed:
        return changed(a.bag)
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.energy.keypoints import LANDMARK_TO_JOINT
    from isa_mocap_ros.vision.keypoint_schedule import CROPS, crop_box
    from isa_mocap_ros.vision.landmarks import LANDMARK_NAMES, PoseLandmarker, box_from_points, upright_angle
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    seq = read_sequence(a.bag, want_images=True, want_masks=False)
    names = list(seq.truth_marker_names)
    learn = seq.empty_frames or next((f.index for f in seq.frames if f.truth_markers is not None), 0)
    if not learn:
        print(f"keypoint_crops: {a.bag}: expected empty frames or background frames before reference markers", file=sys.stderr)
        return 2
    pairs = [(LANDMARK_NAMES.index(lm), names.index(j)) for lm, j in LANDMARK_TO_JOINT.items() if j in names]
    lm_idx = [i for i, _ in pairs]
    L = {n: LANDMARK_NAMES.index(n) for n in LANDMARK_NAMES}
    det = PoseLandmarker()

    def two_pass(img, mask):
        uv = det.detect(img, crop_box(mask, crop="person")).uv
        turn = upright_angle(0.5 * (uv[L["left_hip"]] + uv[L["right_hip"]]),
                             0.5 * (uv[L["left_shoulder"]] + uv[L["right_shoulder"]]))
        return det.detect(img, box_from_points(uv, angle_rad=turn))

    crops = {c: (lambda img, mask, c=c: det.detect(img, crop_box(mask, crop=c))) for c in CROPS}
    crops["two passes (person, then turned by its hips and shoulders)"] = two_pass
    V = len(seq.cameras)
    err = {c: [[] for _ in range(V)] for c in crops}
    swaps = {c: [0] * V for c in crops}
    segs = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn)) for _ in range(V)]
    n = 0
    for f in seq.frames:
        masks = [s.apply(img) for s, img in zip(segs, f.images)]
        if f.truth_markers is None or (f.index - learn) % a.every:
            continue
        n += 1
        for v, cam in enumerate(seq.cameras):
            ref = cam.project(np.asarray(f.truth_markers, float))
            for c, fn in crops.items():
                lm = fn(f.images[v], masks[v])
                e = np.array([np.linalg.norm(lm.uv[i] - ref[j]) for i, j in pairs])
                err[c][v].append(np.where(lm.confidence[lm_idx] >= 0.5, e, np.nan))
                near_right = [np.linalg.norm(lm.uv[L[f"left_{q}"]] - ref[names.index(f"right_{q}")])
                              < np.linalg.norm(lm.uv[L[f"left_{q}"]] - ref[names.index(f"left_{q}")])
                              for q in ("hip", "shoulder", "knee")]
                swaps[c][v] += int(sum(near_right) >= 2)
    print(f"{n} frames x {V} views; px of the bag's images ({seq.cameras[0].width}x{seq.cameras[0].height})")
    for c in crops:
        E = [np.array(e) for e in err[c]]
        print(f"{c}: median " + " / ".join(f"{np.nanmedian(e):.1f}" for e in E) + ", mean "
              + " / ".join(f"{np.nanmean(e):.1f}" for e in E) + ", > 15 px " + " / ".join(f"{np.nanmean(e > 15):.2f}"
                                                                                 for e in E)
              + f", all views mean {np.nanmean(np.concatenate(E)):.1f}; left-right swapped frames {swaps[c]}")
    return 0


def changed(bag: Path) -> int:
    """``--changed``: the views where ``"person_checked"`` gives other landmarks than ``"mask"``."""
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.vision.keypoint_schedule import DENSE_FRAMES, EVERY_K, KeypointSchedule, detect_in_mask
    from isa_mocap_ros.vision.landmarks import PoseLandmarker
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    seq = read_sequence(bag, want_images=True, want_masks=False)
    learn = seq.empty_frames or next((f.index for f in seq.frames if f.truth_markers is not None), 0)
    det = PoseLandmarker()
    V = len(seq.cameras)
    segs = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn)) for _ in range(V)]
    schedules = [KeypointSchedule(EVERY_K, dense_frames=DENSE_FRAMES) for _ in range(V)]
    views = differ = differ_due = due_n = 0
    where = []
    for f in seq.frames:
        masks = [s.apply(img) for s, img in zip(segs, f.images)]
        if f.index < learn:
            continue
        for v in range(V):
            due = schedules[v].due(bool((masks[v] > 0).any()))
            if not (masks[v] > 0).any():
                continue
            a = detect_in_mask(det, f.images[v], masks[v], crop="mask")        # the default min_score, as track
            b = detect_in_mask(det, f.images[v], masks[v], crop="person_checked")
            views += 1
            due_n += due
            same = (a is None and b is None) or (a is not None and b is not None and np.array_equal(a.uv, b.uv)
                                                 and a.score == b.score and np.array_equal(a.roi, b.roi))
            if not same:
                differ += 1
                differ_due += due
                where.append(f"{f.index}/cam{v}{'*' if due else ''}")
    print(f"{bag.name}: {views} views with a person in the mask, {due_n} of them scheduled; 'person_checked' differs from 'mask' "
          f"in {differ} ({differ_due} scheduled){': ' + ' '.join(where[:40]) if where else ''}"
          f"{' ...' if len(where) > 40 else ''} (frame/view, * = scheduled)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
