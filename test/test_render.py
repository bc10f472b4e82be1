"""Renderer: silhouettes against independent rasterizations, occlusion, shading, backgrounds, bad input."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from isa_mocap_ros.vision import (Camera, VisionError, capsule_contains, capsule_data, clothing_colors, look_at,
                                  make_background, render, render_labels, render_labels_at, render_mask)

# A hand-made stick figure (joint centres, metres) and its capsules: (joint a, joint b, r_a, r_b).
JOINTS = dict(pelvis=(0, 0, 0.95), neck=(0, 0, 1.45), head=(0, 0, 1.62), lsh=(0, 0.19, 1.42), rsh=(0, -0.19, 1.42),
              lel=(0.05, 0.25, 1.15), rel=(-0.05, -0.25, 1.15), lwr=(0.2, 0.28, 1.0), rwr=(0.1, -0.3, 0.92),
              lhip=(0, 0.1, 0.92), rhip=(0, -0.1, 0.92), lkn=(0.15, 0.11, 0.52), rkn=(-0.05, -0.1, 0.5),
              lan=(0.05, 0.12, 0.1), ran=(-0.2, -0.1, 0.1), ltoe=(0.2, 0.12, 0.04), rtoe=(-0.06, -0.1, 0.03))
SEGMENTS = [("pelvis", "neck", 0.14, 0.15), ("neck", "head", 0.05, 0.1), ("lsh", "lel", 0.055, 0.045),
            ("rsh", "rel", 0.055, 0.045), ("lel", "lwr", 0.045, 0.035), ("rel", "rwr", 0.045, 0.035),
            ("lhip", "lkn", 0.08, 0.055), ("rhip", "rkn", 0.08, 0.055), ("lkn", "lan", 0.055, 0.04),
            ("rkn", "ran", 0.055, 0.04), ("lan", "ltoe", 0.04, 0.035), ("ran", "rtoe", 0.04, 0.035),
            ("lsh", "rsh", 0.06, 0.06), ("lhip", "rhip", 0.09, 0.09), ("head", "head", 0.1, 0.1),
            ("lwr", "lwr", 0.04, 0.04)]


def stick_figure(offset=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    E = np.array([[JOINTS[a], JOINTS[b]] for a, b, _, _ in SEGMENTS], float) + np.asarray(offset)
    R = np.array([[ra, rb] for _, _, ra, rb in SEGMENTS], float)
    return E, R


def random_capsules(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    a = rng.uniform([-0.6, -0.6, 0.3], [0.6, 0.6, 1.7], (n, 3))
    d = rng.normal(size=(n, 3))
    d *= rng.uniform(0.0, 0.6, (n, 1)) / np.linalg.norm(d, axis=1, keepdims=True)
    R = rng.uniform(0.02, 0.15, (n, 2))
    return np.stack([a, a + d], axis=1), R


def reference_mask(cam: Camera, E: np.ndarray, R: np.ndarray, *, use_cv2_undistort: bool) -> np.ndarray:
    """Pure numpy per-pixel reference: a ray hits the hull of two balls iff min_s dist(ray, p(s)) - r(s) <= 0.

    Rays are built here (K^-1, or OpenCV's undistortPoints for a distorted camera), and the convex 1-D
    minimisation over s is a golden-section search: independent of the renderer's analytic intersection.
    """
    v, u = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    uv = np.stack([u.ravel(), v.ravel()], axis=-1)
    if use_cv2_undistort:
        xy = cv2.undistortPoints(uv[:, None, :], cam.K, cam.dist,
                                 criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))[:, 0]
    else:
        xy = (uv - cam.K[:2, 2]) / np.diag(cam.K)[:2]
    d = np.hstack([xy, np.ones((len(xy), 1))]) @ cam.R
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = -cam.R.T @ cam.t
    hit = np.zeros(len(d), bool)
    g = (np.sqrt(5.0) - 1.0) / 2.0
    for (a, b), (ra, rb) in zip(E, R):
        def f(s):
            p = a + s[:, None] * (b - a) - o
            along = (p * d).sum(1)
            return np.linalg.norm(p - along[:, None] * d, axis=1) - (ra + s * (rb - ra)), along

        lo, hi = np.zeros(len(d)), np.ones(len(d))
        for _ in range(50):
            m1, m2 = hi - g * (hi - lo), lo + g * (hi - lo)
            left = f(m1)[0] < f(m2)[0]
            hi, lo = np.where(left, m2, hi), np.where(left, lo, m1)
        val, along = f((lo + hi) / 2)
        hit |= (val <= 0) & (along > 0)
    return hit.reshape(cam.height, cam.width)


def polygon_mask(cam: Camera, E: np.ndarray, R: np.ndarray) -> np.ndarray:
    """OpenCV reference: fill the convex hull of the projected surface samples of each solid.

    OpenCV fills every pixel an edge touches, so the polygons are filled on a canvas ``S = 7`` times
    finer and read at the fine pixels holding the coarse pixel centres (``S u + 3``): pixel-centre
    sampling up to 1/7 px.
    """
    n, S = 300, 7
    i = np.arange(n) + 0.5
    phi, theta = np.arccos(1 - 2 * i / n), np.pi * (1 + 5 ** 0.5) * i
    sphere = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=-1)
    fine = np.zeros((cam.height * S, cam.width * S), np.uint8)
    rvec, _ = cv2.Rodrigues(cam.R)
    for (a, b), (ra, rb) in zip(E, R):
        s = np.linspace(0, 1, 41)[:, None, None]
        pts = (a + s * (b - a)) + (ra + s * (rb - ra)) * sphere[None]
        uv, _ = cv2.projectPoints(pts.reshape(-1, 3), rvec, cam.t, cam.K, cam.dist)
        uv_fine = S * (uv[:, 0, :] + 0.5) - 0.5
        hull = cv2.convexHull(np.round(uv_fine * 256).astype(np.int32))
        cv2.fillConvexPoly(fine, hull, 255, lineType=cv2.LINE_8, shift=8)
    return fine[S // 2::S, S // 2::S] > 0


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max(1, (a | b).sum()))


CAM = look_at([2.6, -2.2, 2.3], [0, 0, 0.95], fov_deg=50, width=96, height=72, name="small")
CAM_DIST = look_at([2.6, -2.2, 2.3], [0, 0, 0.95], fov_deg=70, width=96, height=72, name="wide",
                   dist=[-0.25, 0.08, 0.002, -0.001, -0.01])


@pytest.mark.parametrize("cam", [CAM, CAM_DIST], ids=["pinhole", "distorted"])
def test_mask_matches_per_pixel_reference(cam):
    rng = np.random.default_rng(42)
    scenes = [stick_figure(), random_capsules(rng, 6), random_capsules(rng, 3)]
    for E, R in scenes:
        ref = reference_mask(cam, E, R, use_cv2_undistort=cam.has_distortion)
        got = render_mask(cam, E, R) > 0
        assert ref.sum() > 50
        # exact up to pixels whose centre lies within numerical noise of the outline
        assert (got != ref).sum() <= 2, (got != ref).sum()
        assert iou(got, ref) > 0.99


def test_mask_matches_opencv_polygon_fill():
    cam = look_at([2.6, -2.2, 2.3], [0, 0, 0.95], fov_deg=50, width=320, height=240)
    rng = np.random.default_rng(7)
    for E, R in [stick_figure(), random_capsules(rng, 8)]:
        got = render_mask(cam, E, R) > 0
        ref = polygon_mask(cam, E, R)
        assert iou(got, ref) > 0.97, iou(got, ref)


def test_special_solids():
    """Equal radii (capsule), one ball inside the other (a sphere), a zero-length segment, solids at the edges."""
    cam = CAM
    E = np.array([[[0, 0, 1.0], [0, 0.5, 1.0]],       # plain capsule
                  [[0.3, 0, 0.3], [0.32, 0, 0.3]],     # big ball swallows small one
                  [[-0.4, 0.3, 1.5], [-0.4, 0.3, 1.5]],  # a sphere given as a point segment
                  [[2.0, -3.0, 1.0], [0.5, -1.0, 2.2]]])  # long, crosses the image border
    R = np.array([[0.08, 0.08], [0.2, 0.05], [0.1, 0.1], [0.1, 0.3]])
    ref = reference_mask(cam, E, R, use_cv2_undistort=False)
    got = render_mask(cam, E, R) > 0
    assert (got != ref).sum() <= 2
    assert got[:, 0].any() or got[0].any() or got[-1].any() or got[:, -1].any()


def test_render_mask_equals_render_and_labels():
    rng = np.random.default_rng(3)
    E, R = stick_figure()
    rgb, mask = render(CAM, E, R, background=make_background(96, 72, rng=rng))
    assert rgb.shape == (72, 96, 3) and rgb.dtype == np.uint8
    assert mask.dtype == np.uint8 and set(np.unique(mask)) == {0, 255}
    np.testing.assert_array_equal(mask, render_mask(CAM, E, R))
    labels, depth = render_labels(CAM, E, R)
    np.testing.assert_array_equal(labels >= 0, mask > 0)
    assert np.all(np.isnan(depth[mask == 0])) and np.all(depth[mask > 0] > 0)


def test_labels_at_some_pixels_are_render_labels_there_bit_for_bit():
    """Every pixel (label -1 and depth NaN off the silhouette) and a shuffled subset, with the capsule
    data made once or per call; sizes that are not multiples of the tile; bad pixels named."""
    rng = np.random.default_rng(8)
    cam = look_at([1.2, 0.0, 1.0], [0, 0, 1.0], fov_deg=80, width=61, height=45)
    for trial in range(6):
        E, R = stick_figure(rng.normal(0, 0.05, 3)) if trial % 2 else random_capsules(rng, 12)
        c = cam if trial < 3 else CAM
        labels, depth = render_labels(c, E, R)
        v, u = np.mgrid[0:c.height, 0:c.width]
        every = np.stack([u.ravel(), v.ravel()], axis=1)
        lab, dep = render_labels_at(c, E, R, every, capsules=capsule_data(E, R))
        assert lab.dtype == np.int32 and dep.dtype == np.float32
        np.testing.assert_array_equal(lab, labels.ravel())
        np.testing.assert_array_equal(dep, depth.ravel())               # NaN where NaN
        some = every[rng.permutation(len(every))[:50]]
        lab, dep = render_labels_at(c, E, R, some)
        np.testing.assert_array_equal(lab, labels[some[:, 1], some[:, 0]])
        np.testing.assert_array_equal(dep, depth[some[:, 1], some[:, 0]])
        np.testing.assert_array_equal(render_mask(c, E, R, capsules=capsule_data(E, R)), render_mask(c, E, R))
    E, R = stick_figure()
    assert [a.shape for a in render_labels_at(CAM, E, R, np.zeros((0, 2), int))] == [(0,), (0,)]
    with pytest.raises(VisionError, match=r"pixels: expected u in \[0, 96\) and v in \[0, 72\)"):
        render_labels_at(CAM, E, R, np.array([[96, 0]]))
    with pytest.raises(VisionError, match=r"pixels: expected integer \(u, v\) rows of shape \(k, 2\)"):
        render_labels_at(CAM, E, R, np.array([[1.5, 2.0]]))


def test_occlusion_near_colour_wins():
    cam = look_at([4.0, 0, 1.0], [0, 0, 1.0], fov_deg=40, width=80, height=60)
    near = [[1.0, 0, 0.8], [1.0, 0, 1.2]]
    far = [[-1.0, -0.4, 1.0], [-1.0, 0.4, 1.0]]
    R = [[0.15, 0.15], [0.3, 0.3]]
    red, blue = (220, 20, 20), (20, 20, 220)
    for order in (0, 1):
        E = np.array([near, far] if order == 0 else [far, near], float)
        rad = np.array(R if order == 0 else R[::-1], float)
        col = np.array([red, blue] if order == 0 else [blue, red], np.uint8)
        rgb, mask = render(cam, E, rad, col)
        labels, depth = render_labels(cam, E, rad)
        cy, cx = 30, 40
        assert mask[cy, cx] == 255
        assert rgb[cy, cx, 0] > 3 * rgb[cy, cx, 2]  # the near red capsule covers the far blue one
        assert labels[cy, cx] == (0 if order == 0 else 1)
        assert depth[cy, cx] == pytest.approx(4.0 - 1.0 - 0.15, abs=0.02)  # front of the near capsule
        # beside the near capsule the far one shows through
        assert rgb[cy, cx + 12, 2] > 3 * rgb[cy, cx + 12, 0]


def test_shading_and_colours():
    cam = look_at([3.0, -3.0, 1.5], [0, 0, 1.0], fov_deg=30, width=120, height=90)
    E = np.array([[[0, 0, 0.6], [0, 0, 1.4]]])
    R = np.array([[0.2, 0.2]])
    rgb, mask = render(cam, E, R, np.array([[200, 100, 50]], np.uint8))
    px = rgb[mask > 0].astype(int)
    assert np.all(px <= np.array([200, 100, 50]) + 1)
    assert px[:, 0].max() - px[:, 0].min() > 40  # shaded, not flat
    np.testing.assert_array_equal(rgb[mask == 0], 48)  # default background grey
    # brighter on the side facing the light
    lit, _ = render(cam, E, R, np.array([[200, 200, 200]], np.uint8), light_dir=(1, -1, 0))
    dark, _ = render(cam, E, R, np.array([[200, 200, 200]], np.uint8), light_dir=(-1, 1, 0))
    assert lit[mask > 0].mean() > dark[mask > 0].mean() + 20


def test_nothing_to_draw():
    bg = make_background(96, 72, rng=np.random.default_rng(0))
    rgb, mask = render(CAM, np.zeros((0, 2, 3)), np.zeros((0, 2)), background=bg)
    np.testing.assert_array_equal(rgb, bg)
    assert not np.shares_memory(rgb, bg)          # drawn on a copy: the caller's background is never written
    assert not mask.any()
    behind = CAM.center + 0.5 * (CAM.center - np.array([0, 0, 0.95]))  # behind the camera
    assert not render_mask(CAM, np.array([[behind, behind + [0, 0, 0.1]]]), np.array([[0.2, 0.2]])).any()


def test_background_textured_and_deterministic():
    for kind in ("textured", "noise"):
        a = make_background(320, 240, rng=np.random.default_rng(5), kind=kind)
        b = make_background(320, 240, rng=np.random.default_rng(5), kind=kind)
        c = make_background(320, 240, rng=np.random.default_rng(6), kind=kind)
        assert a.shape == (240, 320, 3) and a.dtype == np.uint8
        np.testing.assert_array_equal(a, b)
        assert np.abs(a.astype(int) - c).mean() > 5
        assert a.reshape(-1, 3).std(axis=0).min() > 5  # not uniform
        assert len(np.unique(a.reshape(-1, 3), axis=0)) > 1000
        # texture at small scale too: neighbouring pixels differ
        assert np.abs(np.diff(a.astype(int), axis=1)).mean() > 1.0
    with pytest.raises(VisionError, match="kind"):
        make_background(10, 10, rng=np.random.default_rng(0), kind="photo")
    with pytest.raises(VisionError, match="rng"):
        make_background(10, 10, rng=0)
    with pytest.raises(VisionError, match="width"):
        make_background(0, 10, rng=np.random.default_rng(0))


def test_clothing_colors():
    c = clothing_colors(20)
    assert c.shape == (20, 3) and c.dtype == np.uint8
    np.testing.assert_array_equal(c, clothing_colors(20))
    assert len({tuple(x) for x in c[:12]}) == 12
    r1 = clothing_colors(5, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(r1, clothing_colors(5, rng=np.random.default_rng(1)))
    hsv = cv2.cvtColor(r1[None], cv2.COLOR_RGB2HSV)[0]
    assert hsv[:, 1].min() >= 130  # saturated
    assert clothing_colors(0).shape == (0, 3)
    with pytest.raises(VisionError, match="n_capsules"):
        clothing_colors(-1)


def test_capsule_contains():
    E = np.array([[[0, 0, 0], [1, 0, 0]]], float)
    R = np.array([[0.3, 0.1]])
    pts = np.array([[0, 0, 0.29], [0, 0, 0.31], [1.09, 0, 0], [1.11, 0, 0], [0.5, 0.19, 0], [0.5, 0.23, 0]])
    # the tangent cone at x = 0.5 has radius (0.2) / cos(a) ... check against the definition by dense sampling
    s = np.linspace(0, 1, 100001)
    dense = [(np.linalg.norm(p - s[:, None] * [1, 0, 0], axis=1) - (0.3 - 0.2 * s)).min() <= 0 for p in pts]
    np.testing.assert_array_equal(capsule_contains(pts, E, R)[:, 0], dense)
    assert dense == [True, False, True, False, True, False]


@pytest.mark.parametrize("kwargs,match", [
    (dict(endpoints=np.zeros((3, 3))), r"endpoints: expected shape \(C, 2, 3\)"),
    (dict(radii=np.ones((2, 2)) * 0.1), r"radii: expected shape \(1, 2\)"),
    (dict(radii=np.array([[0.1, -0.1]])), "radii: expected finite positive"),
    (dict(endpoints=np.full((1, 2, 3), np.nan)), "endpoints: expected finite"),
    (dict(colors=np.zeros((2, 3), np.uint8)), r"colors: expected shape \(1, 3\)"),
    (dict(colors=np.full((1, 3), 300)), r"colors: expected integers in \[0, 255\]"),
    (dict(background=np.zeros((10, 10, 3), np.uint8)), r"background: expected uint8 of shape \(72, 96, 3\)"),
    (dict(background=np.zeros((72, 96, 3), np.float32)), "background: expected uint8"),
    (dict(light_dir=(0, 0, 0)), "light_dir"),
    (dict(camera="cam0"), "camera: expected a Camera"),
])
def test_render_bad_input(kwargs, match):
    args = dict(camera=CAM, endpoints=np.array([[[0, 0, 1.0], [0, 0, 1.5]]]), radii=np.array([[0.1, 0.1]]))
    args.update(kwargs)
    with pytest.raises(VisionError, match=match):
        render(**args)


def test_solids_close_to_the_camera():
    """Solids filling much of the view, near the camera (the tile culling must not lose any pixel)."""
    cam = look_at([1.2, 0.0, 1.0], [0, 0, 1.0], fov_deg=80, width=61, height=45)  # not multiples of the tile
    E = np.array([[[0.2, -0.5, 0.8], [0.3, 0.6, 1.2]], [[0.8, 0.1, 0.7], [0.7, 0.2, 1.1]],
                  [[0.0, 0.0, 0.2], [0.0, 0.0, 2.0]]])
    R = np.array([[0.2, 0.1], [0.05, 0.15], [0.25, 0.25]])
    ref = reference_mask(cam, E, R, use_cv2_undistort=False)
    got = render_mask(cam, E, R) > 0
    assert ref.mean() > 0.3
    assert (got != ref).sum() <= 2


def test_body_model_in_default_views():
    """The 39-DOF body at rest, standing at the centre, is seen whole by every default camera."""
    body = pytest.importorskip("isa_mocap_ros.body")
    from isa_mocap_ros.vision import default_rig

    model = body.make_model(39)
    E = body.capsule_endpoints(model, model.rest_pose()[None])[0]
    for cam in default_rig():
        mask = render_mask(cam, E, model.capsule_radii)
        ys, xs = np.nonzero(mask)
        assert len(ys) > 500
        assert ys.min() > 0 and ys.max() < cam.height - 1 and xs.min() > 0 and xs.max() < cam.width - 1
        # the silhouette is about as tall as the body (floor to head top) projected at the centre
        floor, top = cam.project([[0, 0, 0], [0, 0, (E[..., 2] + model.capsule_radii).max()]])
        expected = floor[1] - top[1]
        assert abs((ys.max() - ys.min()) - expected) < 0.15 * expected


def test_mask_any_hit_path_equals_the_nearest_hit_path_on_the_body():
    """render_mask stops at a pixel's first hit (the capsule that hit the previous pixel tried first, the
    tangent cone before the balls); render_labels finds the nearest hit: the same pixels, on the body model
    in varied poses at 320x240 (several super-tiles of candidates)."""
    from isa_mocap_ros.body import capsule_endpoints, make_model

    model = make_model(39)
    cam = look_at([3.2, -2.6, 2.0], [0, 0, 0.95], fov_deg=50, width=320, height=240)
    rng = np.random.default_rng(11)
    for _ in range(4):
        x = np.clip(model.rest_pose() + rng.normal(0, 0.5, model.dof), model.lower, model.upper)
        E = capsule_endpoints(model, x)[0]
        mask = render_mask(cam, E, model.capsule_radii)
        labels, _ = render_labels(cam, E, model.capsule_radii)
        assert mask.sum() > 255 * 500
        np.testing.assert_array_equal(mask > 0, labels >= 0)


def test_capsule_data_compiled_equals_numpy():
    """capsule_data's compiled per-capsule numbers are the numpy version's to the bit: posed bodies, fat short
    capsules (one ball holds the other: no cone) and a zero-length one."""
    from isa_mocap_ros.body import capsule_endpoints, make_model
    from isa_mocap_ros.vision.capsule_solid import _capsule_params, _capsule_params_compiled

    rng = np.random.default_rng(0)
    model = make_model(39)
    cone = 0
    for i in range(300):
        E = capsule_endpoints(model, model.rest_pose() + rng.normal(0, 0.3, model.dof))[0]
        R = np.ascontiguousarray(model.capsule_radii, dtype=float) * (rng.uniform(0.5, 4, (len(E), 2)) if i % 2 else 1)
        if i % 5 == 0:
            E[0, 1] = E[0, 0]
        want, got = _capsule_params(E, R), _capsule_params_compiled(np.ascontiguousarray(E), R)
        for a, b in zip(want, got):
            assert a.dtype == b.dtype and np.array_equal(a, b)
        cone += int((want[0][:, 12] == 0).sum())
    assert cone > 0
