"""The contour stage: Levenberg-Marquardt on Plücker-line contour correspondences (tracking/contour.py)."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.body import capsule_endpoints, forward_kinematics, make_model
from isa_mocap_ros.geometry import exp_so3, log_so3
from isa_mocap_ros.tracking.contour import ContourFit, ContourFitError, _normal_equations
from isa_mocap_ros.body.kinematics import joint_frames
from isa_mocap_ros.energy.correspondence import mask_contour_pixels
from isa_mocap_ros.vision import capsule_data, default_rig, render_mask


@pytest.fixture(scope="module")
def scene():
    model = make_model(39)
    rig = default_rig()
    x0 = model.rest_pose()
    x0[3:6] = [0.05, -0.1, 0.4]
    x0[model.knee_dofs[1]] = 0.6
    x0[model.dof_names.index("left_shoulder_x")] = 0.5
    x0[model.dof_names.index("right_hip_y")] = -0.3
    E = capsule_endpoints(model, x0)[0]
    masks = [render_mask(c, E, model.capsule_radii) for c in rig]
    return model, rig, x0, masks


def _residuals(model, x, frames, local, n, m):
    T = forward_kinematics(model, x)[0]
    X = T[frames, :3, 3] + np.einsum("kij,kj->ki", T[frames, :3, :3], local)
    return (np.cross(X, n) - m).ravel()


def _perturbed(model, x, d, h):
    """``x`` moved by ``h`` along coordinate ``d`` of the stage's parametrization (root rotation on the left)."""
    y = x.copy()
    if 3 <= d < 6:
        w = np.zeros(3)
        w[d - 3] = h
        y[3:6] = log_so3(exp_so3(w) @ exp_so3(x[3:6]))
    else:
        y[d] += h
    return y


def test_normal_equations_match_finite_differences(scene):
    model, rig, x0, masks = scene
    fit = ContourFit(model, rig, n_points=60, max_px=50.0)
    fit.set_masks(masks)
    x = x0 + np.random.default_rng(1).normal(0, 0.03, model.dof)
    frames, local, n, m, _ = fit.correspondences(x)
    assert len(frames) > 150
    e = _residuals(model, x, frames, local, n, m)
    h = 1e-6
    J = np.stack([(_residuals(model, _perturbed(model, x, d, h), frames, local, n, m) - e) / h
                  for d in range(model.dof)], axis=1)
    R, P, axes = joint_frames(model, x[None], want_axes=True)
    A, g = _normal_equations(R[0], P[0], axes[0], frames, local, n, m, np.asarray(model.dof_joint),
                             fit._below, np.ones(model.dof, np.bool_))
    np.testing.assert_allclose(A, J.T @ J, rtol=1e-4, atol=1e-7)
    np.testing.assert_allclose(g, J.T @ e, rtol=1e-4, atol=1e-8)
    # over some coordinates only (the stage's extra iterations): those rows and columns the same bits, the rest 0
    use = np.zeros(model.dof, np.bool_)
    coords = [0, 4, 9, *model.knee_dofs]
    use[coords] = True
    As, gs = _normal_equations(R[0], P[0], axes[0], frames, local, n, m, np.asarray(model.dof_joint), fit._below, use)
    assert np.array_equal(As[np.ix_(coords, coords)], A[np.ix_(coords, coords)]) and np.array_equal(gs[coords], g[coords])
    assert not As[~use].any() and not As[:, ~use].any() and not gs[~use].any()


def test_step_equals_the_numpy_formula(scene):
    """ContourFit.step's pose update (compiled: contour_kernel.compose_root / finish_step) is the numpy formula's
    to the bit: ``x + δ``, the root ``nearest_rotvec(log_so3(exp_so3(δ_r) @ exp_so3(r)), r)``, clipped."""
    from isa_mocap_ros.geometry.so3 import nearest_rotvec

    model, rig, x0, masks = scene
    fit = ContourFit(model, rig, n_points=80, max_px=20.0)
    fit.set_masks(masks)
    rng = np.random.default_rng(5)
    for k in range(12):
        x = x0 + rng.normal(0, 0.05, model.dof)
        x[3:6] = rng.standard_normal(3) * (3.1 if k % 3 == 0 else 1.0)       # turned far, through π too
        frames, local, n, m, _ = fit.correspondences(x)
        coords = None if k % 2 else np.array([0, 1, 2, 3, 4, 5, *model.knee_dofs])
        got = fit.step(x, frames, local, n, m, coords=coords)
        R, P, axes = joint_frames(model, x[None], want_axes=True)
        use = np.zeros(model.dof, np.bool_)
        use[np.arange(model.dof) if coords is None else coords] = True
        A, g = _normal_equations(R[0], P[0], axes[0], frames, local, n, m, np.asarray(model.dof_joint), fit._below,
                                 use)
        A[np.diag_indices(model.dof)] *= 1.0 + fit.damping
        A[np.diag_indices(model.dof)] += 1e-9
        c = np.arange(model.dof) if coords is None else coords
        delta = np.zeros(model.dof)
        delta[c] = -np.linalg.solve(A[np.ix_(c, c)], g[c])
        want = x + delta
        want[3:6] = nearest_rotvec(log_so3(exp_so3(delta[3:6]) @ exp_so3(x[3:6])), x[3:6])
        assert np.array_equal(got, np.clip(want, model.lower, model.upper))


def test_plucker_lines_from_the_ray_table():
    """The contour pixels' Plücker lines read from the renderer's per-pixel rays are plucker_lines' numbers (a
    camera with lens distortion too: the table holds Camera.ray's undistorted rays)."""
    from isa_mocap_ros.energy.correspondence import pixel_plucker_lines, plucker_lines
    import dataclasses

    cams = list(default_rig())
    cams.append(dataclasses.replace(cams[0], name="distorted", dist=np.array([-0.2, 0.05, 0.001, -0.002, 0.0])))
    assert cams[-1].has_distortion
    rng = np.random.default_rng(4)
    for cam in cams:
        pix = np.stack([rng.integers(0, cam.width, 500), rng.integers(0, cam.height, 500)], 1)
        for a, b in zip(pixel_plucker_lines(cam, pix), plucker_lines(cam, pix.astype(np.float64))):
            assert np.array_equal(a, b)


def test_fit_recovers_a_displaced_pose(scene):
    model, rig, x0, masks = scene
    fit = ContourFit(model, rig, max_px=20.0)
    assert fit.set_masks(masks) == 4
    x = x0.copy()
    x[0] += 0.03
    x[model.knee_dofs[1]] -= 0.15
    x[model.dof_names.index("left_shoulder_x")] += 0.12
    x1, info = fit.fit(x, iterations=6)
    assert info.iterations == 6 and not info.stopped
    assert info.rms_px[-1] < info.rms_px[0]
    j0 = forward_kinematics(model, x0)[0][:, :3, 3]
    before = np.linalg.norm(forward_kinematics(model, x)[0][:, :3, 3] - j0, axis=1).mean()
    after = np.linalg.norm(forward_kinematics(model, x1)[0][:, :3, 3] - j0, axis=1).mean()
    assert after < 0.25 * before
    assert abs(x1[model.knee_dofs[1]] - x0[model.knee_dofs[1]]) < np.deg2rad(2.0)
    assert np.all(x1 >= model.lower) and np.all(x1 <= model.upper)


def test_fit_over_some_coordinates_holds_the_others(scene):
    """``coords``: the steps move those coordinates only (the tracker's extra iterations on the legs)."""
    model, rig, x0, masks = scene
    fit = ContourFit(model, rig, max_px=20.0)
    fit.set_masks(masks)
    k = model.knee_dofs[1]
    x = x0.copy()
    x[k] -= 0.15
    x[model.dof_names.index("left_shoulder_x")] += 0.1
    legs = np.concatenate([model.partitions["left_leg"], model.partitions["right_leg"]])
    x1, info = fit.fit(x, iterations=4, coords=legs)
    assert info.iterations == 4 and not info.stopped
    others = np.setdiff1d(np.arange(model.dof), legs)
    np.testing.assert_array_equal(x1[others], x[others])
    assert abs(x1[k] - x0[k]) < 0.25 * abs(x[k] - x0[k])
    for bad in ([], [-1], [model.dof], [30, 30]):
        with pytest.raises(ContourFitError, match="coords: expected distinct coordinate indices"):
            fit.fit(x, iterations=1, coords=bad)


def test_at_the_true_pose_it_stays(scene):
    model, rig, x0, masks = scene
    fit = ContourFit(model, rig)
    fit.set_masks(masks)
    x1, _ = fit.fit(x0, iterations=2)
    j0 = forward_kinematics(model, x0)[0][:, :3, 3]
    assert np.linalg.norm(forward_kinematics(model, x1)[0][:, :3, 3] - j0, axis=1).mean() < 0.004


def test_too_few_pairs_leave_the_pose_and_say_why(scene):
    model, rig, x0, masks = scene
    fit = ContourFit(model, rig)
    assert fit.set_masks([None] * len(rig.cameras)) == 0
    x1, info = fit.fit(x0, iterations=3)
    np.testing.assert_array_equal(x1, x0)
    assert info.iterations == 0 and "fewer than" in info.stopped
    empty = [np.zeros_like(masks[0])] * len(rig.cameras)
    assert fit.set_masks(empty) == 0


def test_bad_settings_and_inputs(scene):
    model, rig, x0, masks = scene
    for kw, what in [({"n_points": 0}, "n_points"), ({"max_px": -1.0}, "max_px"), ({"damping": np.nan}, "damping"),
                     ({"n_points": 2.5}, "n_points")]:
        with pytest.raises(ContourFitError, match=what):
            ContourFit(model, rig, **kw)
    fit = ContourFit(model, rig)
    with pytest.raises(ContourFitError, match="one per camera"):
        fit.set_masks(masks[:2])
    with pytest.raises(ContourFitError, match="received shape"):
        fit.set_masks([np.zeros((5, 5), np.uint8)] * len(rig.cameras))
    fit.set_masks(masks)
    bad = x0.copy()
    bad[7] = np.nan
    with pytest.raises(ContourFitError, match="non-finite"):
        fit.fit(bad, iterations=1)
    with pytest.raises(ContourFitError, match="iterations"):
        fit.fit(x0, iterations=-1)


def test_compiled_steps_match_the_numpy_reference(scene):
    """The fit's compiled per-view steps (back-projection, matching; tracking/contour_kernel.py) give the
    pairs of the numpy reference (model_points, correspondences with a k-d tree). The pairs are taken at a
    pose moved off the rendered one, so no projection falls on a pixel centre (there, a distance of exactly
    max_px or two equidistant contour pixels make either path's pick a matter of rounding)."""
    from isa_mocap_ros.body.kinematics import frames_and_axes

    model, rig, x0, masks = scene
    fit = ContourFit(model, rig, n_points=120, max_px=3.0)
    fit.set_masks(masks)
    x = x0 + np.random.default_rng(2).normal(0, 0.02, model.dof)
    R, P, A = frames_and_axes(model, x)
    T = forward_kinematics(model, x)[0]
    assert np.array_equal(R, T[:, :3, :3]) and np.array_equal(P, T[:, :3, 3])
    np.testing.assert_allclose(A[6:], joint_frames(model, x[None], want_axes=True)[2][0][6:], atol=1e-12)
    # the reference renders the exact silhouette; the fit takes the scanline outline in a pinhole view (the next
    # test): here both from the exact one
    fit._silhouette_contour = lambda v, E, radii, capsules: mask_contour_pixels(
        render_mask(rig[v], E, radii, capsules=capsules))
    ref, new = fit.model_points(x), fit._points(R, P)
    assert [v for v, _, _ in ref] == [v for v, _, _ in new] == list(range(len(rig)))
    for (_, f1, l1), (_, f2, l2) in zip(ref, new):
        assert np.array_equal(f1, f2)
        np.testing.assert_allclose(l1, l2, atol=1e-12)
    y = x + np.random.default_rng(3).normal(0, 0.01, model.dof)
    Ry, Py, _ = frames_and_axes(model, y)
    a, b = fit.correspondences(y, ref, (Ry, Py)), fit._pairs(ref, Ry, Py)
    assert len(a[0]) > 200
    assert np.array_equal(a[0], b[0])
    for u, w in zip(a[1:], b[1:]):
        np.testing.assert_allclose(u, w, atol=1e-9)
    # masks of a new frame replace the old contour pixels (the index images are cleared, not rebuilt)
    fit.set_masks([np.zeros_like(m) for m in masks])
    assert fit._pairs(ref, Ry, Py)[0].size == 0
    fit.set_masks(masks)
    assert np.array_equal(fit._pairs(ref, Ry, Py)[0], b[0])


def test_model_contour_from_the_scanline_outline(scene):
    """In a view without lens distortion the model's contour is that of the capsules' scanline outlines (the
    scanline energy's silhouette, vision/outline.py) instead of the ray-cast one: every pixel of it within a
    pixel of the exact silhouette's contour and the other way round, and every one back-projected onto a
    capsule (the outline's discs lie inside the exact projection of the balls)."""
    from scipy.spatial import cKDTree

    from isa_mocap_ros.body.kinematics import frames_and_axes

    model, rig, x0, masks = scene
    fit = ContourFit(model, rig, n_points=100000)
    fit.set_masks(masks)
    R, P, _ = frames_and_axes(model, x0)
    E = np.ascontiguousarray(P[np.asarray(model.capsules)])
    total = 0
    for v, cam in enumerate(rig):
        assert not cam.has_distortion
        pix = fit._silhouette_contour(v, E, fit._radii, capsule_data(E, model.capsule_radii))
        exact = mask_contour_pixels(render_mask(cam, E, model.capsule_radii))
        assert cKDTree(exact).query(pix)[0].max() <= 1.0 and cKDTree(pix).query(exact)[0].max() <= 1.0
        total += len(pix)
    assert sum(len(f) for _, f, _ in fit._points(R, P)) == total


def test_outer_contour_in_the_foreground_box_is_the_whole_images():
    """The model silhouette's contour taken by OpenCV in the box of its pixels grown by one (tracking/contour.py) is
    the whole image's, point for point and in the same order: blobs inside, several blobs, blobs cut by each image
    border, an empty image; and so is the contour taken in the whole image's box."""
    import cv2

    from isa_mocap_ros.tracking.contour import _outer_contour

    rng = np.random.default_rng(5)
    for trial in range(60):
        img = np.zeros((48, 64), np.uint8)
        for _ in range(trial % 4):
            c = (int(rng.integers(-6, 70)), int(rng.integers(-6, 54)))
            cv2.ellipse(img, c, (int(rng.integers(1, 15)), int(rng.integers(1, 15))), float(rng.uniform(0, 180)),
                        0, 360, 255, -1)
        whole, _ = cv2.findContours(img, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        want = np.concatenate(whole).reshape(-1, 2) if whole else np.zeros((0, 2), np.int32)
        ys, xs = np.nonzero(img)
        box = (max(0, ys.min() - 1), min(48, ys.max() + 2), max(0, xs.min() - 1), min(64, xs.max() + 2)) \
            if len(ys) else (0, 0, 0, 0)
        for b in (box, (0, 48, 0, 64)):
            got = _outer_contour(img, b)
            assert got.dtype == want.dtype and np.array_equal(got, want)


def test_outline_box_holds_the_drawn_silhouette(scene):
    """The box the fit takes OpenCV's contour in (contour_kernel.outline_box, from the capsules' end discs) holds every
    pixel fill_capsules draws with a margin: the contour in it is the whole image's, for poses moved far off the
    scene's, parts of the body out of the image included."""
    import cv2

    from isa_mocap_ros.body.kinematics import frames_and_axes
    from isa_mocap_ros.tracking import contour_kernel
    from isa_mocap_ros.tracking.contour import _outer_contour
    from isa_mocap_ros.vision.outline import camera_arrays, fill_capsules

    model, rig, x0, _ = scene
    rng = np.random.default_rng(7)
    cut = 0
    for trial in range(40):
        x = x0 + rng.normal(0, 0.15, model.dof)
        x[:3] += rng.normal(0, 0.6, 3)
        _, P, _ = frames_and_axes(model, x)
        E = np.ascontiguousarray(P[np.asarray(model.capsules)])
        for cam in rig:
            sil = np.zeros((cam.height, cam.width), np.uint8)
            fill_capsules(E, np.asarray(model.capsule_radii, np.float64), *camera_arrays(cam), 0.0, sil, np.uint8(255))
            whole, _ = cv2.findContours(sil, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
            want = np.concatenate(whole).reshape(-1, 2) if whole else np.zeros((0, 2), np.int32)
            box = contour_kernel.outline_box(E, np.asarray(model.capsule_radii, np.float64), *camera_arrays(cam),
                                             cam.height, cam.width)
            assert np.array_equal(_outer_contour(sil, box), want)
            cut += bool(sil[0].any() or sil[-1].any() or sil[:, 0].any() or sil[:, -1].any())
    assert cut > 0            # some silhouettes reach the image border


def test_match_takes_the_first_nearest_pixel_in_raster_order():
    """``contour_kernel.match``'s pick is the raster-order scan's: the smallest distance within ``max_px``, of equal
    ones the first in raster order (lower row, then lower column), what any faster search must keep. Checked against
    that scan written out, on a lattice of contour pixels and half-pixel projections, where many pixels tie."""
    from isa_mocap_ros.tracking import contour_kernel

    H, W, max_px = 40, 50, 3.0
    index = np.full((H, W), -1, np.int32)
    ys, xs = np.mgrid[0:H:2, 0:W:3]
    index[ys.ravel(), xs.ravel()] = np.arange(ys.size)
    rng = np.random.default_rng(5)
    uv = np.concatenate([rng.integers(-8, 2 * W + 8, (300, 2)) / 2.0, rng.uniform(-4, W + 4, (100, 2))])
    uv[:, 1] = np.clip(uv[:, 1], -4, H + 4)
    n = len(uv)
    fx = 1.0                           # at depth 1: the projection of a point is (x + 20, y + 15)
    local = np.stack([uv[:, 0] - 20.0, uv[:, 1] - 15.0, np.zeros(n)], axis=1)
    uv = local[:, :2] + [20.0, 15.0]
    lines = np.arange(ys.size * 3, dtype=float).reshape(-1, 3)
    out = (np.empty(n, np.int64), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty(n))
    k = contour_kernel.match(np.zeros(n, np.int64), local, np.eye(3)[None], np.zeros((1, 3)), np.eye(3),
                             np.array([0.0, 0.0, 1.0]), np.array([fx, fx, 20.0, 15.0]), np.zeros(8), False, index,
                             max_px, lines, -lines, *out, 0)
    want = []
    py, px = np.nonzero(index >= 0)                  # the contour pixels in raster order
    for u, v in uv:
        d2 = (px - u) * (px - u) + (py - v) * (py - v)
        i = int(np.argmin(d2))                       # the first of the smallest: raster order
        if d2[i] <= max_px ** 2:
            want.append((index[py[i], px[i]], np.sqrt(d2[i])))
    assert k == len(want) > 100
    assert np.array_equal(out[2][:k, 0], lines[[r for r, _ in want], 0])
    np.testing.assert_allclose(out[4][:k], [d for _, d in want], rtol=1e-12)
