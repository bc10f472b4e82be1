"""The contour stage fits the masks the energy scores: the gated, hull-filtered ones (not the raw masks
with the occluders the gate removed)."""
import numpy as np

from isa_mocap_ros.tracking import Tracker, TrackerConfig

from walk_scene import walk_scene


def test_contour_stage_sees_the_filtered_masks():
    model, cams, walk, masks = walk_scene(width=160, height=120, frames=3, duration_s=0.2, seed=0)
    occluded = []
    for m in masks[1]:
        m = np.array(m, copy=True)
        m[:12, :12] = 255                   # a blob far from the person: the mask gate removes it
        occluded.append(m)
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=0, init_confirm_frames=0))
    tr.initialize(pose=walk[0])
    seen = []
    fit = tr.contour_fit.set_masks

    def record(ms):
        seen.append([None if m is None else np.array(m, copy=True) for m in ms])
        return fit(ms)

    tr.contour_fit.set_masks = record
    r = tr.step(occluded, 1)
    assert not r.fell_back and seen, "the contour stage did not run"
    for v, m in enumerate(seen[-1]):
        assert m is not None and m.any()
        assert not m[:12, :12].any(), f"view {v}: the contour stage was given the blob the gate removed"
        assert m.sum() <= np.asarray(occluded[v]).sum()
