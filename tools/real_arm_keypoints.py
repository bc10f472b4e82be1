#!/usr/bin/env python3
"""The detector's arm landmarks against the peer's points where the tracked forearm lies over the trunk (issue 34).

    python tools/real_arm_keypoints.py BAG TRACK_DIR [--every K] [--joints a,b,...]

``BAG``: ``bench real``'s imported recording (docs/real_cameras.md section 3); ``TRACK_DIR``: a ``track`` run of it
(its ``estimates`` and ``body.yaml``). On every ``K``-th frame with reference markers, each view is detected on as
``track`` detects (the default segmentation's mask, :func:`~isa_mocap_ros.vision.keypoint_schedule.detect_in_mask`),
and per arm joint (elbows, wrists) the pixel distance to the peer's point of that name is printed: of the
landmark (confidence >= 0.5, as the keypoint term keeps it) and of the tracked estimate's joint projected, split by
whether the previous frame's estimate has a forearm over its trunk in some view
(:func:`~isa_mocap_ros.vision.keypoint_schedule.forearms_over_trunk`, ``track --keypoint-extra-gap``'s want). The
peer's points are not BlazePose's (its own detector and definitions), so this compares the landmark with our
estimate as seen by the peer, not either with the truth. ``--joints``: other landmarks of the same names (default
the elbows and wrists; e.g. the hips, whose line gives the pelvis's heading). Evaluation only.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bag", type=Path)
    p.add_argument("track", type=Path)
    p.add_argument("--every", type=int, default=1)
    p.add_argument("--joints", default="right_elbow,right_wrist,left_elbow,left_wrist")
    a = p.parse_args(argv)
    import msg_adapters as ma
    from isa_mocap_ros.bag import BagReader
    from isa_mocap_ros.body import joint_positions, joint_state_to_pose, make_model
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.vision.keypoint_schedule import ARM_TRUNK_JOINTS, detect_in_mask, forearms_over_trunk
    from isa_mocap_ros.vision.landmarks import LANDMARK_NAMES, PoseLandmarker
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    seq = read_sequence(a.bag, want_images=True, want_masks=False)
    names = list(seq.truth_marker_names)
    model = make_model(39, shape=a.track / "body.yaml")
    est = {}
    with BagReader(a.track / "estimates") as bag:
        for m in bag.messages():
            if m.topic == "/mocap/joint_states":
                msg = ma.from_cdr(m.data, m.type)
                _, q = ma.joint_state_to_arrays(msg, model.dof_names)
                est[ma.stamp_to_ns(msg.header)] = joint_state_to_pose(model, q)
    learn = next((f.index for f in seq.frames if f.truth_markers is not None), 0)
    segs = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn)) for _ in seq.cameras]
    det = PoseLandmarker()
    arm_idx = [model.joint_names.index(n) for n in ARM_TRUNK_JOINTS]
    joints = tuple(a.joints.split(","))
    rows = {(j, over, who): [] for j in joints for over in (False, True) for who in ("landmark", "estimate")}
    prev = None
    n_over = n = 0
    for f in seq.frames:
        masks = [s.apply(img) for s, img in zip(segs, f.images)]
        x = est.get(int(f.stamp_ns))
        if f.truth_markers is None or x is None:
            continue
        over = prev is not None and bool(forearms_over_trunk(
            seq.cameras, joint_positions(model, prev[None])[0, arm_idx]).any())
        prev = x
        if (f.index - learn) % a.every:
            continue
        n += 1
        n_over += over
        J = joint_positions(model, x[None])[0]
        for v, cam in enumerate(seq.cameras):
            lm = detect_in_mask(det, f.images[v], masks[v])
            for j in joints:
                ref = cam.project(np.asarray(f.truth_markers[names.index(j)], float))
                if not np.all(np.isfinite(ref)):
                    continue
                rows[(j, over, "estimate")].append(np.linalg.norm(cam.project(J[model.joint_names.index(j)]) - ref))
                if lm is not None and lm.confidence[LANDMARK_NAMES.index(j)] >= 0.5:
                    rows[(j, over, "landmark")].append(np.linalg.norm(lm.uv[LANDMARK_NAMES.index(j)] - ref))
    print(f"{n} frames ({n_over} with a forearm over the trunk in some view) x {len(seq.cameras)} views; px from the "
          "peer's point, median / mean (n)")
    for j in joints:
        print(f"  {j:12s} " + "   ".join(
            f"{'over' if over else 'free'} {who}: {np.median(r):5.1f} / {np.mean(r):5.1f} ({len(r)})"
            for over in (False, True) for who in ("landmark", "estimate") if (r := rows[(j, over, who)])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
