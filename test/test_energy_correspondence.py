"""Correspondence energy with Plücker lines (ISA Eq. 13.30-13.31)."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.energy import CorrespondenceEnergy, EnergyError, plucker_lines
from isa_mocap_ros.vision import default_rig, render_mask


@pytest.fixture(scope="module")
def scene():
    model = make_model(39)
    rig = default_rig()
    x0 = model.rest_pose()
    x0[model.knee_dofs[1]] = 0.5
    x0[model.dof_names.index("left_shoulder_x")] = 0.5
    E = capsule_endpoints(model, x0)[0]
    masks = [render_mask(c, E, model.capsule_radii) for c in rig]
    return model, rig, x0, masks


def test_plucker_distance_is_point_to_ray_distance(scene):
    cam = scene[1].cameras[0]
    n, m = plucker_lines(cam, [[100.0, 80.0]])
    on = cam.center + 2.5 * n[0]
    assert np.linalg.norm(np.cross(on, n[0]) - m[0]) < 1e-12
    side = np.cross(n[0], [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    off = on + 0.3 * side
    assert np.linalg.norm(np.cross(off, n[0]) - m[0]) == pytest.approx(0.3, abs=1e-12)
    with pytest.raises(EnergyError, match="pixels"):
        plucker_lines(cam, [1.0, 2.0])


def test_zero_at_truth_and_increasing_with_displacement(scene):
    model, rig, x0, masks = scene
    f = CorrespondenceEnergy(model, rig, masks, x0, n_contour_points=150)
    assert f.n_views_used == 4 and f.n_correspondences == 600
    X = np.repeat(x0[None], 5, axis=0)
    X[:, 0] += [0.0, 0.005, 0.02, 0.05, 0.15]
    e = f(X)
    assert e.shape == (5,)
    assert e[0] < 1e-20
    assert np.all(np.diff(e) > 0)
    k = np.repeat(x0[None], 3, axis=0)
    k[:, model.knee_dofs[1]] += [0.0, 0.1, 0.3]
    assert np.all(np.diff(f(k)) > 0)


def test_batch_equals_single_and_bad_rows(scene):
    model, rig, x0, masks = scene
    f = CorrespondenceEnergy(model, rig, masks, x0, n_contour_points=80)
    X = x0 + np.random.default_rng(0).normal(0, 0.05, (6, model.dof))
    np.testing.assert_allclose(f(X), [f(x[None])[0] for x in X], rtol=1e-12)
    assert f.n_evals == 12
    X[2, 4] = np.nan
    e = f(X)
    assert np.isinf(e[2]) and np.all(np.isfinite(np.delete(e, 2)))
    with pytest.raises(EnergyError, match="X"):
        f(np.zeros((2, 5)))


def test_skipped_views_and_bad_input(scene):
    model, rig, x0, masks = scene
    f = CorrespondenceEnergy(model, rig, [None, masks[1], np.zeros_like(masks[2]), masks[3][:, :50]], x0)
    assert [v for v, _ in f.skipped_views] == [0, 2, 3] and f.n_views_used == 1
    with pytest.raises(EnergyError, match="at least one usable view"):
        CorrespondenceEnergy(model, rig, [None] * 4, x0)
    bad = x0.copy()
    bad[3] = np.nan
    with pytest.raises(EnergyError, match="x_pred"):
        CorrespondenceEnergy(model, rig, masks, bad)
    with pytest.raises(EnergyError, match="n_contour_points"):
        CorrespondenceEnergy(model, rig, masks, x0, n_contour_points=0)


def test_model_contour_points_are_those_of_the_full_label_image_bit_for_bit(scene):
    """The contour points come from the silhouette and labels at the chosen contour pixels only; they
    are what labelling every pixel (``render_labels``, the first formulation) gives, to the bit."""
    from isa_mocap_ros.body import forward_kinematics
    from isa_mocap_ros.energy.correspondence import mask_contour_pixels, capsule_frames, model_contour_points
    from isa_mocap_ros.vision import render_labels

    model, rig, x0, _ = scene
    rng = np.random.default_rng(2)
    for trial in range(4):
        x = np.clip(x0 + rng.normal(0, 0.15, model.dof) * (trial > 0), model.lower, model.upper)
        E, T = capsule_endpoints(model, x)[0], forward_kinematics(model, x)[0]
        for cam in rig:
            n_points = (50, 200, 10_000)[trial % 3]
            labels, depth = render_labels(cam, E, model.capsule_radii)
            pix = mask_contour_pixels(labels >= 0)
            if len(pix) > n_points:
                pix = pix[np.floor(np.arange(n_points) * (len(pix) / n_points)).astype(np.int64)]
            cap, z = labels[pix[:, 1], pix[:, 0]], depth[pix[:, 1], pix[:, 0]].astype(np.float64)
            c, d = cam.ray(pix[:, 0].astype(float), pix[:, 1].astype(float))
            d = np.asarray(d).reshape(-1, 3)
            X = c + (z / (d @ cam.R[2]))[:, None] * d
            frames = capsule_frames(model)[cap]
            local = np.einsum("kji,kj->ki", T[frames, :3, :3], X - T[frames, :3, 3])
            got = model_contour_points(model, cam, x, n_points=n_points)
            assert len(pix) > 0
            for a, b in zip(got, (pix, frames, local)):
                np.testing.assert_array_equal(a, b)
