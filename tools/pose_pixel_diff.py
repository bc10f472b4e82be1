"""Where does one tracked run's pose gain over another's on the same frames? (issue 33, the flexed-leg bias)

    .venv/bin/python tools/pose_pixel_diff.py BAG SHAPE RUN_A RUN_B

``SHAPE`` the runs' body shape (``truth`` or a shape YAML), ``RUN_A`` / ``RUN_B`` two ``isa-mocap track --out``
directories (e.g. a free run and ``tools/oracle_track.py --oracle``'s). For every frame both estimated, it renders
both poses' capsules (``render_mask``) in every view against the bag's segmented foreground (one background model
per view, as ``track``) and counts the pixels where the renders differ: foreground covered by A only / by B only,
background covered by B only / by A only (the first and third favour A in Eq. 4's two terms), in total and per body
region covering them (pelvis, trunk, thighs, shins and feet, arms, head and neck). A diagnostic, not part of the
tracker.
"""
import sys
from pathlib import Path
import numpy as np
from isa_mocap_ros.cli.track_io import read_sequence
from isa_mocap_ros.cli.run_report import read_estimates
from isa_mocap_ros.body import make_model, load_shape, capsule_endpoints
from isa_mocap_ros.vision.render import render_mask
from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig
if len(sys.argv) != 5:
    raise SystemExit(__doc__)
bag, shape, fr_run, or_run = sys.argv[1:5]
seq = read_sequence(bag, want_images=True, want_masks=False)
model = seq.truth_model if shape == "truth" else make_model(39, shape=load_shape(shape))
learn = seq.empty_frames or 10
segs = [BackgroundSegmenter(SegmentationConfig(learn_frames=learn)) for _ in seq.cameras]
fgs = {}
for fr in seq.frames:
    masks = [s.apply(img) for s, img in zip(segs, fr.images)]
    if fr.index >= learn:
        fgs[fr.stamp_ns] = [m > 0 for m in masks]
cn = list(model.capsule_names); R = np.asarray(model.capsule_radii, float)
groups = {"pelvis": ["pelvis"], "trunk": ["abdomen", "torso", "chest", "shoulders"], "thighs": ["left_thigh", "right_thigh"],
          "shins+feet": ["left_shin", "right_shin", "left_foot", "right_foot"], "arms": [c for c in cn if "arm" in c or "hand" in c],
          "head+neck": ["head", "neck"]}
gi = {g: [cn.index(c) for c in cs if c in cn] for g, cs in groups.items()}
A = read_estimates(Path(fr_run) / "estimates", model)["poses"]; B = read_estimates(Path(or_run) / "estimates", model)["poses"]
ks = sorted(set(A) & set(B) & set(fgs))[1:]
cnt = {g: np.zeros(4, int) for g in groups}   # fg by A only, fg by B only, bg by B only, bg by A only
tot = np.zeros(4, int)
for k in ks:
    EA, EB = capsule_endpoints(model, np.stack([A[k], B[k]]))
    for cam, F in zip(seq.cameras, fgs[k]):
        MA = render_mask(cam, EA, R) > 0; MB = render_mask(cam, EB, R) > 0
        GA = {g: render_mask(cam, EA[ix], R[ix]) > 0 for g, ix in gi.items()}
        GB = {g: render_mask(cam, EB[ix], R[ix]) > 0 for g, ix in gi.items()}
        sets = [F & MA & ~MB, F & MB & ~MA, ~F & MB & ~MA, ~F & MA & ~MB]
        who = [GA, GB, GB, GA]
        for j, (S, G) in enumerate(zip(sets, who)):
            tot[j] += S.sum()
            for g in groups:
                cnt[g][j] += (S & G[g]).sum()
print(f"{len(ks)} frames x {len(seq.cameras)} views; px: [fg covered by A only, fg covered by B only, bg covered by B only, bg covered by A only]")
print("total", tot.tolist(), "net A gain (fg) ", int(tot[0] - tot[1]), " (bg)", int(tot[2] - tot[3]))
for g in groups:
    print(f"  {g:11s}", cnt[g].tolist())
