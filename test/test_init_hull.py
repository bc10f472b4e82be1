"""The first frame's mask filter (tracking/init_hull.py): ISA's occluding rectangles, drawn into each view
independently, go; the person, seen by every view, stays; the tracker runs it before its first estimate only."""
import numpy as np
import pytest
from scipy import ndimage

from isa_mocap_ros.tracking import Tracker, TrackerConfig
from isa_mocap_ros.tracking.init_hull import capture_volume, person_masks
from isa_mocap_ros.vision import occluders

from walk_scene import walk_scene


@pytest.fixture(scope="module")
def scene():
    return walk_scene(width=320, height=240, frames=2, duration_s=0.2, seed=0)


def _occluded(masks, seed):
    """Each view's mask with 35 rectangles (ISA §13.4.2: edges 1-40 px, random grey; grey 0 is background)."""
    rng = np.random.default_rng(seed)
    return [np.where(occluders(m, 35, rng=rng) > 0, 255, 0).astype(np.uint8) for m in masks]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_occluders_away_from_the_person_go_and_the_person_stays(scene, seed):
    model, cams, poses, masks = scene
    person = [m > 0 for m in masks[0]]
    noisy = _occluded(masks[0], seed)
    out, note = person_masks(noisy, cams)
    assert note and note.startswith("first-frame hull: the person's blob")
    for v, (o, p, n) in enumerate(zip(out, person, noisy)):
        assert o.dtype == np.uint8 and o.shape == p.shape
        assert not np.any((o > 0) & ~(n > 0)), f"view {v}: foreground was added"
        kept = (o > 0)[p].mean()
        assert kept > 0.99, f"view {v}: only {kept:.3f} of the person kept"
        far = (n > 0) & ~ndimage.binary_dilation(p, iterations=25)
        if far.sum() > 200:
            removed = 1.0 - (o > 0)[far].mean()
            assert removed > 0.85, f"view {v}: only {removed:.2f} of the occluders beyond 25 px removed"


def test_clean_masks_come_back_unchanged_and_too_few_views_are_left_alone(scene):
    model, cams, poses, masks = scene
    out, note = person_masks(masks[1], cams)
    for o, m in zip(out, masks[1]):
        np.testing.assert_array_equal(o, m)
    assert note is None
    one = [masks[1][0], None, None, None]
    out, note = person_masks(one, cams)
    assert note is None and out[0] is one[0] and out[1:] == [None, None, None]


def test_the_capture_volume_holds_the_rig_s_middle(scene):
    _, cams, poses, _ = scene
    lo, hi = capture_volume(cams)
    assert np.all(lo[:2] < poses[0][:2]) and np.all(poses[0][:2] < hi[:2])
    assert lo[2] < 0 < 2.0 < hi[2]


def test_the_tracker_filters_the_first_frame_only_and_only_when_asked(scene):
    model, cams, poses, masks = scene
    noisy = [_occluded(masks[k], 10 + k) for k in range(2)]
    on = Tracker(model, cams, TrackerConfig.from_flat(evals=300, seed=0, first_frame_hull=True, init_confirm_frames=0))
    r0 = on.step(noisy[0], 0)
    assert any(n.startswith("first-frame hull: the person's blob") and "removed: view" in n for n in r0.notes)
    r1 = on.step(noisy[1], 1)
    assert not any(n.startswith("first-frame hull") for n in r1.notes)
    off = Tracker(model, cams, TrackerConfig.from_flat(evals=300, seed=0, first_frame_hull=False, init_confirm_frames=0))
    assert not any(n.startswith("first-frame hull") for n in off.step(noisy[0], 0).notes)


def test_the_compiled_carve_counts_as_its_numpy_reference(scene):
    """init_hull._carve (one compiled pass per view) against _carve_reference: the same seen / denied counts per
    cube, on occluded masks, with a strongly distorted camera whose far-off cubes project to non-finite pixels,
    and with the bags' calibrated cameras' Fortran-ordered rotations."""
    import dataclasses

    from isa_mocap_ros.tracking import init_hull as H
    from isa_mocap_ros.vision.camera import project_batch

    model, cams, poses, masks = scene
    cams = list(cams)
    cams[1] = dataclasses.replace(cams[1], dist=np.array([-0.6, 0.4, 0.01, -0.01, 0.2]))
    cams[2] = dataclasses.replace(cams[2], R=np.asfortranarray(cams[2].R))
    noisy = _occluded(masks[0], 3)
    lo, hi = capture_volume(cams)
    n = np.ceil((hi - lo) / 0.08).astype(int)
    G = np.stack(np.meshgrid(*[lo[i] + 0.08 * (np.arange(n[i]) + 0.5) for i in range(3)], indexing="ij"),
                 axis=-1).reshape(-1, 3)
    UV = project_batch(cams, G[None])[:, 0]
    UV[1, ::97] = np.nan                             # cubes far off a distorted view's field have no pixel
    for v, cam in enumerate(cams):
        F = noisy[v] > 0
        got = [np.zeros(len(G), np.int16) for _ in range(2)]
        ref = [np.zeros(len(G), np.int16) for _ in range(2)]
        H._carve(G, UV[v], np.ascontiguousarray(cam.R[2]), float(cam.t[2]), cam.width, cam.height, F, *got)
        H._carve_reference(G, UV[v], cam, F, *ref)
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])
        assert ref[0].sum() > 1000 and 0 < ref[1].sum() < ref[0].sum()


def test_the_compiled_discs_are_opencvs_filled_circles_pixel_for_pixel():
    """init_hull._discs (the first-frame hull's discs, compiled) against cv2.circle(..., -1) one by one: the same
    pixels for discs inside, across the edges and wholly outside images of odd and even sizes, radius 0 included."""
    from isa_mocap_ros.tracking import init_hull as H

    rng = np.random.default_rng(7)
    for _ in range(200):
        h, w = (int(v) for v in rng.integers(3, 90, 2))
        n = int(rng.integers(1, 40))
        uv = np.stack([rng.integers(-30, w + 30, n), rng.integers(-30, h + 30, n)], axis=1).astype(np.int64)
        r = rng.integers(0, 35, n).astype(np.int64)
        got, ref = np.zeros((h, w), np.uint8), np.zeros((h, w), np.uint8)
        H._discs(got, uv, r)
        H._discs_reference(ref, uv, r)
        np.testing.assert_array_equal(got, ref)


def test_the_cached_grid_and_the_cropped_labels_change_no_mask(scene):
    """The first pass's grid and pixels kept between calls (init_hull._grid) and the blobs labelled within the kept
    cubes' box give the masks and note of a fresh call with the whole volume labelled, call after call."""
    from scipy import ndimage

    from isa_mocap_ros.tracking import init_hull as H

    model, cams, poses, masks = scene
    noisy = _occluded(masks[0], 5)
    H._GRIDS.clear()
    first = H.person_masks(noisy, cams)
    again = H.person_masks(noisy, cams)           # from the cache
    for a, b in zip(first[0], again[0]):
        np.testing.assert_array_equal(a, b)
    assert first[1] == again[1] and first[1] is not None
    # the cropped labelling against scipy's on the whole grid
    F = {v: np.asarray(m) > 0 for v, m in enumerate(noisy)}
    lo, hi = capture_volume(cams)
    G, n, sizes, labels = H._blobs(F, cams, lo, hi, 0.08, 3, misses=0, cache=True)
    keep = labels > 0
    whole, _ = ndimage.label(keep.reshape(n), structure=np.ones((3, 3, 3), bool))
    np.testing.assert_array_equal(labels, whole.ravel())
    np.testing.assert_array_equal(sizes, np.bincount(whole.ravel())[1:])
    assert sizes.size >= 1
