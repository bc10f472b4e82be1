"""tracking/camera_data.py: the per-camera data (the renderer's rays and tile cones, the hull filter's rays) are built
when the tracker gets its cameras, so the start-up's frames (the automatic initialization, the
first hull-filtered frame) build none; the track is bit-identical to one that builds them at first use."""
import importlib

import numpy as np

from isa_mocap_ros.tracking import camera_data, hull
from isa_mocap_ros.tracking import tracker as tracker_module
from isa_mocap_ros.tracking.config import TrackerConfig
from isa_mocap_ros.tracking.tracker import Tracker

from walk_scene import walk_scene

render = importlib.import_module("isa_mocap_ros.vision.render")   # the module (the package exports a function of its name)


def _cached() -> set:
    return {("render", k) for k in render._CACHE} | {("hull", k) for k in hull._RAYS._cache}


def _run(model, cams, masks, cfg, frames: int):
    """Clear the caches, make a tracker, step ``frames`` frames: (the cache entries the steps added, the poses, the
    notes)."""
    render.clear_ray_cache()
    hull._RAYS._cache.clear()
    tracker = Tracker(model, cams, cfg)
    before = _cached()
    results = [tracker.step(masks[k], k) for k in range(frames)]
    return _cached() - before, [r.x.tobytes() for r in results], [r.notes for r in results]


def test_the_start_up_frames_build_no_camera_data_and_track_the_same(monkeypatch):
    model, cams, _, masks = walk_scene(width=160, height=120, frames=3, duration_s=0.2, seed=0)
    cfg = TrackerConfig.from_flat(seed=0)
    assert cfg.masks.hull_filter
    with monkeypatch.context() as m:      # the data built at first use, as before
        m.setattr(tracker_module, "prepare_cameras", lambda cameras, config=None: None)
        built_late, poses_late, notes = _run(model, cams, masks, cfg, 3)
    # the frames of this start-up do need them (else the check below could not fail): the initialized frame
    # (its polish's contour stage) the renderer's, the frames after it the hull filter's
    assert any(n.startswith("initialized automatically") for n in notes[0])
    assert {kind for kind, _ in built_late} == {"render", "hull"}, built_late
    assert len(built_late) == 2 * len(cams)
    built, poses, _ = _run(model, cams, masks, cfg, 3)
    assert built == set()
    assert poses == poses_late


def test_prepare_cameras_builds_what_the_config_uses():
    _, cams, _, _ = walk_scene(width=80, height=60, frames=1, duration_s=0.1, seed=0)
    render.clear_ray_cache()
    hull._RAYS._cache.clear()
    camera_data.prepare_cameras(cams, TrackerConfig.from_flat(hull_filter=False))
    assert len(render._CACHE) == len(cams) and not hull._RAYS._cache
    camera_data.prepare_cameras(cams)
    assert len(hull._RAYS._cache) == len(cams)
    # the same arrays the filter would build at first use
    np.testing.assert_array_equal(hull._RAYS(cams[0]), hull._rays(cams[0]))
    o, dirs, _ = render.pixel_rays(cams[1])
    _, d = cams[1].ray(np.array([5.0]), np.array([7.0]))
    np.testing.assert_allclose(dirs[7 * cams[1].width + 5], d[0], atol=1e-12)
