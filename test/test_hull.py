"""The visual-hull filter (tracking/hull.py) and the tracker's ``hull_filter``: what one view alone
reports goes, the person stays, the numba kernel equals the numpy reference, bad input."""
import numpy as np
import pytest

from isa_mocap_ros.tracking import Tracker, TrackerConfig, TrackerError
from isa_mocap_ros.tracking.gate import GateError
from isa_mocap_ros.tracking.hull import hull_filter, hull_filter_numpy, pose_box
from isa_mocap_ros.vision import Camera

from walk_scene import walk_scene


@pytest.fixture(scope="module")
def scene():
    return walk_scene(width=160, height=120, frames=3, duration_s=0.3, seed=0)


def _attached_rect(mask: np.ndarray, h: int = 20, w: int = 16) -> np.ndarray:
    """A ``h × w`` block of foreground glued to the right side of the person's silhouette, at its middle
    height (what the gate keeps: it touches the person). Returns the block's pixels that are new."""
    rows, cols = np.nonzero(mask)
    r = int(np.median(rows))
    c = int(cols[rows == r].max()) + 1
    block = np.zeros_like(mask)
    block[r - h // 2:r - h // 2 + h, c:c + w] = 255
    return (block > 0) & (mask == 0)


def test_the_person_stays_and_a_one_view_occluder_goes(scene):
    model, cams, poses, masks = scene
    x, m = poses[1], [a.copy() for a in masks[1]]
    added = _attached_rect(m[0])
    m[0][added] = 255
    g = hull_filter(m, cams, pose_box(model, x, 0.35))
    person = [a > 0 for a in masks[1]]
    for v, out in enumerate(g.masks):
        assert out.dtype == np.uint8 and set(np.unique(out)) <= {0, 255}
        kept = (out > 0)[person[v]].mean()
        assert kept > 0.98, f"view {v}: only {kept:.3f} of the person kept"
    removed = 1.0 - (g.masks[0] > 0)[added].mean()
    assert removed > 0.8, f"only {removed:.2f} of the occluder removed"
    assert g.lost_px[0] >= 0.8 * added.sum()
    np.testing.assert_array_equal(g.total_px, [np.count_nonzero(a) for a in m])


def test_numba_kernel_equals_the_numpy_reference(scene):
    model, cams, poses, masks = scene
    m = [a.copy() for a in masks[2]]
    m[1][_attached_rect(m[1])] = 255
    m[3][5:20, 5:30] = 255                     # a far blob too
    m[2][m[2].shape[0] // 2, :] = 0            # and a hole across one view
    box = pose_box(model, poses[2], 0.35)
    keep = [None, m[1] > 0, None, np.ones_like(m[3])]
    for kw in (dict(), dict(misses=1), dict(dilate_px=0, step_m=0.05), dict(keep=keep)):
        a = hull_filter(m, cams, box, **kw)
        b = hull_filter_numpy(m, cams, box, **kw)
        for u, w in zip(a.masks, b.masks):
            np.testing.assert_array_equal(u, w)
        np.testing.assert_array_equal(a.lost_px, b.lost_px)


def test_a_hole_in_one_view_costs_nothing_with_one_miss_allowed(scene):
    model, cams, poses, masks = scene
    m = [a.copy() for a in masks[0]]
    m[1][:] = 0
    m[1][: m[1].shape[0] // 2] = masks[0][1][: m[1].shape[0] // 2]      # view 1 lost the person's lower half
    box = pose_box(model, poses[0], 0.35)
    strict = hull_filter(m, cams, box)
    lenient = hull_filter(m, cams, box, misses=1)
    legs0 = np.zeros_like(m[0], bool)
    rows = np.nonzero(m[0])[0]
    legs0[int(np.percentile(rows, 75)):] = True
    legs0 &= m[0] > 0
    assert (strict.masks[0] > 0)[legs0].mean() < 0.5           # view 1 cannot confirm the legs
    assert (lenient.masks[0] > 0)[legs0].mean() > 0.98


def test_keep_protects_the_expected_silhouette(scene):
    """A hole in view 1 cuts view 0's legs; pixels inside ``keep`` (e.g. the predicted silhouette)
    stay anyway, and the occluder outside it still goes."""
    from isa_mocap_ros.tracking.gate import predicted_silhouettes

    model, cams, poses, masks = scene
    m = [a.copy() for a in masks[0]]
    m[1][m[1].shape[0] // 2:] = 0                                  # view 1 lost the lower half
    added = _attached_rect(m[0])
    m[0][added] = 255
    box = pose_box(model, poses[0], 0.35)
    sil = predicted_silhouettes(model, cams, poses[0], margin_px=1)
    plain = hull_filter(m, cams, box)
    kept = hull_filter(m, cams, box, keep=sil)
    person0 = masks[0][0] > 0
    assert (plain.masks[0] > 0)[person0].mean() < 0.8
    assert (kept.masks[0] > 0)[person0].mean() > 0.99
    outside = added & (sil[0] == 0)
    assert outside.sum() > 100 and (kept.masks[0] > 0)[outside].mean() < 0.3
    with pytest.raises(GateError, match=r"keep: expected 4 masks or None \(one per camera\), received 2"):
        hull_filter(m, cams, box, keep=sil[:2])
    with pytest.raises(GateError, match=r"keep\[1\]: expected shape \(120, 160\), received \(3, 3\)"):
        hull_filter(m, cams, box, keep=[None, np.zeros((3, 3)), None, None])


def test_none_views_pass_and_fewer_than_two_views_change_nothing(scene):
    model, cams, poses, masks = scene
    box = pose_box(model, poses[0], 0.35)
    m = [masks[0][0], None, masks[0][2], None]
    g = hull_filter(m, cams, box)
    assert g.masks[1] is None and g.masks[3] is None and g.lost_px[1] == 0
    one = hull_filter([masks[0][0], None, None, None], cams, box)
    np.testing.assert_array_equal(one.masks[0], masks[0][0])
    assert one.lost_px.tolist() == [0, 0, 0, 0]


def test_a_box_away_from_the_person_empties_the_masks(scene):
    model, cams, poses, masks = scene
    lo, hi = pose_box(model, poses[0], 0.1)
    g = hull_filter(masks[0], cams, (lo + 5.0, hi + 5.0))
    assert all(np.count_nonzero(a) == 0 for a in g.masks)
    np.testing.assert_array_equal(g.lost_px, g.total_px)


def test_lens_distortion_keeps_the_person():
    from isa_mocap_ros.body import capsule_endpoints
    from isa_mocap_ros.vision import render_mask

    model, cams, poses, _ = walk_scene(width=160, height=120, frames=1, duration_s=0.3, seed=0)
    dist = [Camera(c.name, c.width, c.height, c.K, np.array([-0.5, 0.1, 0.0, 0.0, 0.0]), c.R, c.t)
            for c in cams]
    x = poses[0]
    m = [render_mask(c, capsule_endpoints(model, x)[0], model.capsule_radii) for c in dist]
    g = hull_filter(m, dist, pose_box(model, x, 0.35))
    for v, (a, b) in enumerate(zip(m, g.masks)):
        assert (b > 0)[a > 0].mean() > 0.98, f"view {v}"
    # ignoring the distortion loses part of the person: the test can fail
    pin = [Camera(c.name, c.width, c.height, c.K, np.zeros(5), c.R, c.t) for c in cams]
    wrong = hull_filter(m, pin, pose_box(model, x, 0.35))
    assert min((b > 0)[a > 0].mean() for a, b in zip(m, wrong.masks)) < 0.98


@pytest.mark.parametrize("kw, match", [
    (dict(dilate_px=-1), "dilate_px: expected an integer >= 0"),
    (dict(misses=1.5), "misses: expected an integer >= 0"),
    (dict(step_m=0.0), "step_m: expected a finite number > 0"),
    (dict(step_m=float("nan")), "step_m: expected a finite number > 0"),
])
def test_bad_arguments_are_named(scene, kw, match):
    model, cams, poses, masks = scene
    with pytest.raises(GateError, match=match):
        hull_filter(masks[0], cams, pose_box(model, poses[0], 0.3), **kw)


def test_bad_masks_and_box_are_named(scene):
    model, cams, poses, masks = scene
    box = pose_box(model, poses[0], 0.3)
    with pytest.raises(GateError, match=r"masks: expected 4 \(one per camera\), received 3"):
        hull_filter(masks[0][:3], cams, box)
    with pytest.raises(GateError, match=r"masks\[2\]: expected shape \(120, 160\), received \(10, 10\)"):
        hull_filter([masks[0][0], masks[0][1], np.zeros((10, 10)), masks[0][3]], cams, box)
    with pytest.raises(GateError, match="box: expected lo <= hi"):
        hull_filter(masks[0], cams, (box[1], box[0]))
    with pytest.raises(GateError, match="box: expected two finite 3-vectors"):
        hull_filter(masks[0], cams, (np.zeros(2), np.ones(3)))


def test_tracker_config_checks_the_hull_settings():
    with pytest.raises(TrackerError, match="hull_dilate_px"):
        TrackerConfig.from_flat(hull_dilate_px=-1)
    with pytest.raises(TrackerError, match="hull_keep_px"):
        TrackerConfig.from_flat(hull_keep_px=-1)
    with pytest.raises(TrackerError, match="hull_pad_m"):
        TrackerConfig.from_flat(hull_pad_m=0.0)
    with pytest.raises(TrackerError, match="hull_filter"):
        TrackerConfig.from_flat(hull_filter="yes")


def test_tracker_hands_the_energy_the_filtered_masks(scene):
    """With an estimate, the tracker gates and filters: the occluder glued to the person in one view
    (which the gate keeps) mostly never reaches the energy (what is left lies next to the person,
    where the other views cannot tell); ``hull_filter=False`` lets it all through."""
    model, cams, poses, masks = scene
    m = [a.copy() for a in masks[1]]
    added = _attached_rect(m[0])
    m[0][added] = 255
    seen = {}
    for on in (True, False):
        tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, hull_filter=on, hull_keep_px=0,
                                                contour_iterations=0, contour_extra_iterations=0, limb_proposals=0))
        tr.initialize(pose=poses[0])
        res = tr.step(m, 1)
        assert not res.fell_back
        seen[on] = tr.track.masks_last[0] > 0
    assert seen[True][added].mean() < 0.35
    assert seen[False][added].mean() == 1.0


def test_tracker_with_occluder_blobs_tracks_better_with_the_filter_alone():
    """test_gate's scene (35 rectangles, edges 1-20 px, drawn into the masks of a 7-frame walk at
    160×120; 600 evaluations, contour stage off) with the gate off: the filter alone removes the
    blobs, near the person or far (mean joint error, seeds 0-2, measured: 34.0 / 41.5 / 34.2 mm without,
    20.1 / 17.2 / 31.8 mm with). On the sampled energy ('fast'): the scanline count (the default since decision 017)
    suffers little from these blobs here (seeds 0-4 without the filter 12.0 / 15.1 / 60.5 / 11.5 / 17.1 mm, with it
    15.4 / 13.3 / 13.5 / 15.8 / 14.7: it helps the mean, not every seed)."""
    from isa_mocap_ros.body import capsule_endpoints, make_model
    from isa_mocap_ros.body.motion import generate_motion
    from isa_mocap_ros.eval import frame_errors_mm, marker_positions
    from isa_mocap_ros.vision import default_rig, render_mask
    from isa_mocap_ros.vision.distort import occluders

    n = 8
    model = make_model(39)
    cams = default_rig(width=160, height=120).cameras
    walk = generate_motion("walk", model, duration_s=0.4, fps=30, rng=np.random.default_rng(0))[:n]
    rng = np.random.default_rng(0)
    masks = [[occluders(render_mask(c, capsule_endpoints(model, x)[0], model.capsule_radii), 35, rng=rng,
                        max_size=20) for c in cams] for x in walk]
    err = np.zeros((3, 2))
    for seed in range(3):
        for j, on in enumerate((False, True)):
            tr = Tracker(model, cams, TrackerConfig.from_flat(evals=600, seed=seed, gate_margin_px=0,
                                                    contour_iterations=0, hull_filter=on, energy="fast"))
            tr.initialize(pose=walk[0])
            out = [tr.step(masks[k], k) for k in range(1, n)]
            assert all(r.views_used == 4 and not r.fell_back for r in out)
            if on:
                assert any("the hull filter removed" in note for r in out for note in r.notes)
            err[seed, j] = frame_errors_mm(marker_positions(model, np.array([r.x for r in out])),
                                           marker_positions(model, walk[1:])).mean()
    assert np.all(err[:, 1] < err[:, 0]) and err[:, 1].mean() < 0.75 * err[:, 0].mean() and err[:, 1].mean() < 40.0, err
