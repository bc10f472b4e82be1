"""Cameras: projection against OpenCV, rays, look_at, scaling, batch projection, bad input."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from isa_mocap_ros.vision import Camera, VisionError, look_at, project_batch


def random_camera(rng: np.random.Generator, *, n_dist: int = 5, strength: float = 1.0, name: str = "c") -> Camera:
    rvec = rng.normal(size=3)
    R, _ = cv2.Rodrigues(rvec)
    t = rng.normal(size=3)
    W, H = int(rng.integers(80, 800)), int(rng.integers(60, 600))
    f = rng.uniform(0.6, 1.5) * W
    K = np.array([[f, 0, W / 2 + rng.normal(0, 5)], [0, f * rng.uniform(0.95, 1.05), H / 2 + rng.normal(0, 5)],
                  [0, 0, 1]])
    dist = np.zeros(n_dist)
    if n_dist:
        scales = np.array([0.2, 0.05, 0.002, 0.002, 0.01, 0.05, 0.01, 0.005])[:n_dist]
        dist = strength * rng.normal(size=n_dist) * scales
    return Camera(name, W, H, K, dist, R, t)


def points_in_front(rng: np.random.Generator, cam: Camera, n: int) -> np.ndarray:
    """World points inside the (undistorted) view cone at depths 1-6."""
    x = rng.uniform(-0.5, 0.5, n)
    y = rng.uniform(-0.4, 0.4, n)
    z = rng.uniform(1.0, 6.0, n)
    Xc = np.stack([x * z, y * z, z], axis=-1)
    return (Xc - cam.t) @ cam.R  # R^T (Xc - t)


@pytest.mark.parametrize("n_dist", [0, 4, 5, 8])
def test_project_matches_cv2(n_dist):
    rng = np.random.default_rng(100 + n_dist)
    for _ in range(10):
        cam = random_camera(rng, n_dist=n_dist)
        P = points_in_front(rng, cam, 200)
        rvec, _ = cv2.Rodrigues(cam.R)
        ref, _ = cv2.projectPoints(P, rvec, cam.t, cam.K, cam.dist if n_dist else None)
        np.testing.assert_allclose(cam.project(P), ref[:, 0, :], rtol=0, atol=1e-6)


def test_project_zero_distortion_is_pinhole():
    rng = np.random.default_rng(1)
    cam = random_camera(rng, n_dist=5, strength=0.0)
    P = points_in_front(rng, cam, 50)
    Xc = P @ cam.R.T + cam.t
    uvw = Xc @ cam.K.T
    np.testing.assert_allclose(cam.project(P), uvw[:, :2] / uvw[:, 2:], atol=1e-9)
    np.testing.assert_allclose(cam.depth(P), Xc[:, 2], atol=1e-12)
    np.testing.assert_allclose(cam.to_camera(P), Xc, atol=1e-12)
    assert cam.project(P.reshape(5, 10, 3)).shape == (5, 10, 2)


@pytest.mark.parametrize("n_dist", [0, 5, 8])
def test_ray_through_projected_point(n_dist):
    rng = np.random.default_rng(7 + n_dist)
    cam = random_camera(rng, n_dist=n_dist, strength=0.5)
    P = points_in_front(rng, cam, 100)
    uv = cam.project(P)
    o, d = cam.ray(uv[:, 0], uv[:, 1])
    np.testing.assert_allclose(o, cam.center, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12)
    v = P - o
    dist = np.linalg.norm(v - (v * d).sum(-1, keepdims=True) * d, axis=-1)
    assert dist.max() < 1e-7
    assert np.all((v * d).sum(-1) > 0)  # the ray points towards the point


def test_undistort_agrees_with_cv2():
    rng = np.random.default_rng(3)
    cam = random_camera(rng, n_dist=5, strength=0.5)
    uv = np.stack([rng.uniform(0, cam.width, 300), rng.uniform(0, cam.height, 300)], axis=-1)
    ref = cv2.undistortPoints(uv[:, None, :], cam.K, cam.dist)[:, 0, :]
    x, y = cam.undistort_pixels(uv[:, 0], uv[:, 1])
    np.testing.assert_allclose(np.stack([x, y], -1), ref, atol=1e-5)


def test_undistort_of_a_pixel_does_not_depend_on_its_batch():
    # each point's Newton iteration stops on its own: the same bits alone, in any batch, in any shape (a table
    # of every pixel built once gives what undistorting a frame's pixels gives)
    rng = np.random.default_rng(5)
    cam = random_camera(rng, n_dist=8, strength=0.5)
    uv = np.stack([rng.uniform(0, cam.width, 400), rng.uniform(0, cam.height, 400)], axis=-1)
    x, y = cam.undistort_pixels(uv[:, 0], uv[:, 1])
    for i in (0, 17, 399):
        xi, yi = cam.undistort_pixels(uv[i, 0], uv[i, 1])
        assert np.shape(xi) == () and xi == x[i] and yi == y[i]
    x2, y2 = cam.undistort_pixels(uv[::-1, 0].reshape(20, 20), uv[::-1, 1].reshape(20, 20))
    assert x2.shape == (20, 20)
    np.testing.assert_array_equal(x2.ravel()[::-1], x)
    np.testing.assert_array_equal(y2.ravel()[::-1], y)


def test_pixel_areas_are_kept_and_give_the_same_bits():
    from isa_mocap_ros.vision.camera import PixelAreas

    rng = np.random.default_rng(6)
    cam = random_camera(rng, n_dist=5, strength=0.5)

    def direct(u, v):                       # each pixel's area computed anew (what every frame did)
        u, v = u.astype(float), v.astype(float)
        xu0, yu0 = cam.undistort_pixels(u - 0.5, v)
        xu1, yu1 = cam.undistort_pixels(u + 0.5, v)
        xv0, yv0 = cam.undistort_pixels(u, v - 0.5)
        xv1, yv1 = cam.undistort_pixels(u, v + 0.5)
        return np.abs((xu1 - xu0) * (yv1 - yv0) - (xv1 - xv0) * (yu1 - yu0))

    areas = PixelAreas(cam)
    for k in range(3):                      # overlapping pixel sets: the second and third reuse the table
        v, u = np.nonzero(rng.random((cam.height, cam.width)) < 0.3)
        a = areas.of(u, v)
        ref = direct(u, v)
        np.testing.assert_array_equal(a, ref)
        assert a.sum() == ref.sum()
    assert 0 < np.count_nonzero(np.isfinite(areas._table)) < cam.height * cam.width


def test_look_at_geometry():
    eye, target = np.array([3.0, -2.0, 2.5]), np.array([0.2, 0.1, 1.0])
    cam = look_at(eye, target, fov_deg=60, width=320, height=240)
    np.testing.assert_allclose(cam.center, eye, atol=1e-12)
    np.testing.assert_allclose(cam.project(target), [(320 - 1) / 2, (240 - 1) / 2], atol=1e-9)
    assert cam.depth(target) == pytest.approx(np.linalg.norm(target - eye))
    assert np.linalg.det(cam.R) == pytest.approx(1.0)
    # up in the world is up in the image (smaller v); the horizontal field of view is 60 degrees
    above = cam.project(target + [0, 0, 0.5])
    assert above[1] < (240 - 1) / 2
    assert abs(above[0] - (320 - 1) / 2) < 1e-6  # world vertical stays vertical (no roll)
    assert cam.fx == pytest.approx(160 / np.tan(np.radians(30)))
    # the camera's right in the image is the world direction forward x up
    right = np.cross(target - eye, [0, 0, 1])
    assert cam.project(target + 0.1 * right / np.linalg.norm(right))[0] > (320 - 1) / 2


def test_look_at_bad_input():
    with pytest.raises(VisionError, match="up"):
        look_at([0, 0, 3], [0, 0, 0])  # looking straight down along up
    with pytest.raises(VisionError, match="target"):
        look_at([1, 1, 1], [1, 1, 1])
    with pytest.raises(VisionError, match="fov_deg"):
        look_at([3, 0, 1], [0, 0, 1], fov_deg=180)
    with pytest.raises(VisionError, match="at most one"):
        look_at([3, 0, 1], [0, 0, 1], fov_deg=60, K=np.eye(3))
    with pytest.raises(VisionError, match="eye"):
        look_at([3, 0], [0, 0, 1])


def test_scaled_camera_matches_resized_pixels():
    cam = look_at([3, 1, 2], [0, 0, 1], width=320, height=240, dist=[0.05, -0.01, 0, 0, 0])
    rng = np.random.default_rng(5)
    P = rng.uniform(-0.5, 0.5, (50, 3)) + [0, 0, 1]
    half = cam.scaled(0.5)
    assert (half.width, half.height) == (160, 120)
    np.testing.assert_allclose(half.project(P), 0.5 * (cam.project(P) + 0.5) - 0.5, atol=1e-9)
    # a disc drawn at full size and area-downsampled lands where the half-size camera projects it
    uv = cam.project(P[0])
    img = np.zeros((240, 320), np.float32)
    cv2.circle(img, (int(round(uv[0] * 16)), int(round(uv[1] * 16))), 8 * 16, 1.0, -1, shift=4)
    small = cv2.resize(img, (160, 120), interpolation=cv2.INTER_AREA)
    ys, xs = np.nonzero(small)
    w = small[ys, xs]
    centroid = np.array([(xs * w).sum(), (ys * w).sum()]) / w.sum()
    np.testing.assert_allclose(centroid, half.project(P[0]), atol=0.1)
    assert cam.scaled(1.0) == cam
    with pytest.raises(VisionError, match="factor"):
        cam.scaled(0)
    with pytest.raises(VisionError, match="factor"):
        cam.scaled(1e-4)


def test_project_batch_matches_project():
    rng = np.random.default_rng(11)
    cams = [random_camera(rng, n_dist=n, name=f"c{n}") for n in (0, 5, 8)]
    P = rng.normal(size=(7, 13, 3)) * 0.3 + points_in_front(rng, cams[0], 1)
    uv = project_batch(cams, P)
    assert uv.shape == (3, 7, 13, 2)
    for v, cam in enumerate(cams):
        np.testing.assert_allclose(uv[v], cam.project(P), rtol=1e-12, atol=1e-9)
    assert project_batch(cams, np.zeros((0, 4, 3))).shape == (3, 0, 4, 2)
    with pytest.raises(VisionError, match=r"P: expected shape \(n, K, 3\)"):
        project_batch(cams, np.zeros((4, 3)))
    with pytest.raises(VisionError, match="cams"):
        project_batch([], P)


def test_camera_equality_and_readonly():
    rng = np.random.default_rng(2)
    a = random_camera(rng)
    b = Camera(a.name, a.width, a.height, a.K.copy(), a.dist.copy(), a.R.copy(), a.t.copy())
    assert a == b
    assert a != Camera(a.name, a.width, a.height, a.K, a.dist, a.R, a.t + 1e-9)
    assert Camera("z", 10, 10, np.eye(3), np.zeros(4)) == Camera("z", 10, 10, np.eye(3), np.zeros(5))
    with pytest.raises(ValueError):
        a.K[0, 0] = 1.0


GOOD = dict(name="c", width=320, height=240, K=np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]]),
            dist=np.zeros(5), R=np.eye(3), t=np.zeros(3))


@pytest.mark.parametrize("field,value,match", [
    ("R", np.zeros((3, 3)), "R: expected an orthonormal rotation"),
    ("R", np.diag([1.0, 1.0, -1.0]), r"R: expected det\(R\) = \+1"),
    ("R", np.eye(3) * 1.01, "R: expected an orthonormal"),
    ("R", np.eye(4), r"R: expected shape \(3, 3\)"),
    ("R", np.full((3, 3), np.nan), "R: expected finite"),
    ("K", np.zeros((3, 3)), "K: expected fx"),
    ("K", np.array([[-300.0, 0, 160], [0, 300, 120], [0, 0, 1]]), "K: expected fx"),
    ("K", np.array([[300.0, 1, 160], [0, 300, 120], [0, 0, 1]]), r"K: expected \[\[fx, 0, cx\]"),
    ("K", np.array([[np.inf, 0, 160], [0, 300, 120], [0, 0, 1]]), "K: expected finite"),
    ("K", np.eye(2), r"K: expected shape \(3, 3\)"),
    ("t", np.zeros(4), r"t: expected shape \(3,\)"),
    ("t", [0, 0, np.nan], "t: expected finite"),
    ("dist", np.zeros(3), "dist: expected"),
    ("dist", [0.1, 0, 0, np.inf], "dist: expected finite"),
    ("width", 0, "width: expected a positive integer"),
    ("height", 2.5, "height: expected a positive integer"),
    ("name", "", "name: expected a non-empty string"),
    ("K", "abc", "K: expected a numeric array"),
])
def test_camera_bad_input(field, value, match):
    kw = dict(GOOD)
    kw[field] = value
    with pytest.raises(VisionError, match=match):
        Camera(**kw)


def test_points_bad_shape():
    cam = Camera(**GOOD)
    with pytest.raises(VisionError, match=r"P: expected shape \(\.\.\., 3\)"):
        cam.project(np.zeros((4, 2)))


def test_camera_info_and_transform_round_trip():
    """Camera -> CameraInfo + TransformStamped (msg_adapters) -> Camera."""
    ci = pytest.importorskip("msg_adapters.camera_info")
    tf = pytest.importorskip("msg_adapters.transform")
    rng = np.random.default_rng(8)
    for n_dist in (0, 5, 8):
        cam = random_camera(rng, n_dist=n_dist, name="cam3")
        info = ci.intrinsics_to_camera_info(ci.Intrinsics(**cam.intrinsics_fields()), frame_id="cam3_optical_frame")
        R_wc, t_wc = cam.pose_in_world()
        msg = tf.rt_to_transform(R_wc, t_wc, parent_frame="world", child_frame="cam3_optical_frame")
        assert info.distortion_model == cam.distortion_model and len(info.d) == (8 if n_dist == 8 else 5)
        np.testing.assert_allclose(t_wc, cam.center)
        intr = ci.camera_info_to_intrinsics(info)
        R2, t2 = tf.transform_to_rt(msg)
        back = Camera.from_intrinsics_and_pose("cam3", K=intr.K, D=intr.D, width=intr.width, height=intr.height,
                                               R_wc=R2, t_wc=t2)
        P = points_in_front(rng, cam, 20)
        np.testing.assert_allclose(back.project(P), cam.project(P), atol=1e-6)
        np.testing.assert_allclose(back.R, cam.R, atol=1e-12)
