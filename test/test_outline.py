"""Capsule outlines by scanlines (vision/outline.py): against an independent point-in-hull test, the compiled
projection against the camera's own, the exact silhouette, bad input."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.vision import VisionError, capsule_contains, look_at, render_mask
from isa_mocap_ros.vision.outline import camera_arrays, capsule_discs, fill_capsules, fill_outlines, outline_mask

from test_render import random_capsules, stick_figure

CAM = look_at([2.6, -2.2, 2.3], [0, 0, 0.95], fov_deg=50, width=160, height=120, name="outline")
CAM_DIST = look_at([2.6, -2.2, 2.3], [0, 0, 0.95], fov_deg=70, width=160, height=120, name="outline_wide",
                   dist=[-0.25, 0.08, 0.002, -0.001, -0.01])


def test_fill_matches_the_hull_of_two_discs_pixel_by_pixel():
    # the hull of two discs is the hull of two balls cut by the plane of their centres: capsule_contains (a
    # golden-section search, nothing shared with the scanline kernel) decides each pixel centre
    rng = np.random.default_rng(3)
    H, W = 50, 70
    v, u = np.mgrid[0:H, 0:W].astype(float)
    X = np.stack([u, v, np.zeros_like(u)], axis=-1)
    for _ in range(40):
        c = rng.uniform([-5, -5], [W + 5, H + 5], (1, 2, 2))
        if rng.random() < 0.2:
            c[0, 1] = c[0, 0] + rng.normal(0, 0.3, 2)       # nearly one disc (one may hold the other)
        r = rng.uniform(0.7, 12.0, (1, 2))
        out = np.zeros((H, W), np.uint8)
        fill_outlines(c, r, np.ones(1, bool), out, np.uint8(255))
        E = np.concatenate([c, np.zeros((1, 2, 1))], axis=2)
        ref = capsule_contains(X, E, r)[..., 0]
        assert np.array_equal(out > 0, ref)


def test_compiled_projection_gives_the_cameras_discs():
    rng = np.random.default_rng(0)
    for cam in (CAM, CAM_DIST):
        for k in range(5):
            E, R = random_capsules(rng, 12) if k else stick_figure()
            a = np.zeros((cam.height, cam.width), np.uint8)
            b = np.zeros_like(a)
            fill_outlines(*capsule_discs(cam, E, R, 2.0), a, np.uint8(255))
            fill_capsules(np.ascontiguousarray(E), np.ascontiguousarray(R), *camera_arrays(cam), 2.0, b, np.uint8(255))
            assert np.array_equal(a, b) and a.any()


def test_outline_is_close_to_the_exact_silhouette():
    E, R = stick_figure()
    exact = render_mask(CAM, E, R) > 0
    approx = outline_mask(CAM, E, R) > 0
    iou = np.count_nonzero(exact & approx) / np.count_nonzero(exact | approx)
    assert iou > 0.97, iou
    grown = outline_mask(CAM, E, R, margin_px=2) > 0
    assert not np.any(exact & ~grown)                  # the disc error is under 2 px here


def test_capsules_behind_the_camera_are_left_out_and_bad_input_raises():
    E, R = stick_figure()
    behind = E.copy()
    behind[:, :, 0] += 8.0                               # beyond the camera (at x 2.6, looking towards -x)
    assert not outline_mask(CAM, behind, R).any()
    with pytest.raises(VisionError, match="endpoints, radii"):
        outline_mask(CAM, E[:, 0], R)
    with pytest.raises(VisionError, match="margin_px"):
        outline_mask(CAM, E, R, margin_px=-1)
