"""Keypoint correspondence energy (ISA 13.30-13.31 on BlazePose landmarks): zero at the truth, front
differs from back, a wrong view does not drag the pose, batch = single, bad input named."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from isa_mocap_ros.body import joint_positions, make_model
from isa_mocap_ros.energy import LANDMARK_TO_JOINT, EnergyError, KeypointEnergy
from isa_mocap_ros.energy.keypoints import geman_mcclure
from isa_mocap_ros.vision import default_rig
from isa_mocap_ros.vision.landmarks import LANDMARK_NAMES


def true_keypoints(model, rig, x, *, conf=0.9):
    """What a perfect detector would report: each mapped landmark at its joint's projection."""
    P = joint_positions(model, x)[0]
    out = []
    for cam in rig:
        uv = np.full((33, 2), np.nan)
        c = np.zeros(33)
        for lm, j in LANDMARK_TO_JOINT.items():
            if j in model.joint_names:
                uv[LANDMARK_NAMES.index(lm)] = cam.project(P[model.joint_names.index(j)][None])[0]
                c[LANDMARK_NAMES.index(lm)] = conf
        out.append((uv, c))
    return out


@pytest.fixture(scope="module")
def scene():
    model = make_model(39)
    rig = default_rig()
    x0 = model.rest_pose()
    x0[model.knee_dofs[1]] = 0.6
    x0[model.dof_names.index("left_shoulder_x")] = 0.7
    x0[model.dof_names.index("right_elbow_y")] = -0.8
    return model, rig, x0, true_keypoints(model, rig, x0)


def test_zero_at_truth_growing_with_displacement(scene):
    model, rig, x0, kp = scene
    f = KeypointEnergy(model, rig, kp)
    assert f.n_correspondences == 4 * 14
    np.testing.assert_allclose(f.weights.sum(), 1.0)
    X = np.repeat(x0[None], 5, axis=0)
    X[:, 0] += [0.0, 0.01, 0.03, 0.08, 0.2]
    e = f(X)
    assert e[0] < 1e-20 and np.all(np.diff(e) > 0) and e[-1] < 1.0
    np.testing.assert_allclose(f.distances(x0[None]), 0.0, atol=1e-9)


def test_facing_backwards_and_swapped_legs_cost_more_than_the_truth(scene):
    """The silhouette of a body turned by pi about the vertical is nearly the same; its keypoints are not."""
    model, rig, x0, kp = scene
    f = KeypointEnergy(model, rig, kp)
    back = x0.copy()
    back[5] += np.pi                                       # root rotation vector z: turn around
    swapped = x0.copy()
    li, ri = model.knee_dofs
    swapped[li], swapped[ri] = x0[ri], x0[li]
    e0, eb, es = f(np.stack([x0, back, swapped]))
    assert eb > 0.3 and es > 0.02 and e0 < 1e-12


def test_a_wrong_view_does_not_drag_the_pose(scene):
    """View 0 reports every landmark 60 px to the right with full confidence. Fitting the root
    position and rotation: the robust energy stays within 1 cm of the truth, the same energy with a
    near-quadratic loss (huge sigma) is dragged several cm."""
    model, rig, x0, kp = scene
    bad = [(uv + [60.0, 0.0], c) for uv, c in kp[:1]] + list(kp[1:])
    robust = KeypointEnergy(model, rig, bad, sigma_m=0.05)
    plain = KeypointEnergy(model, rig, bad, sigma_m=100.0)
    start = x0.copy()
    start[:3] += [0.05, -0.04, 0.03]

    def fit(f):
        def g(r):
            x = x0.copy()
            x[:6] = r
            return float(f(x[None])[0])
        res = minimize(g, start[:6], method="Powell", options={"xtol": 1e-6, "ftol": 1e-12, "maxfev": 20000})
        return np.linalg.norm(res.x[:3] - x0[:3])

    e_robust, e_plain = fit(robust), fit(plain)
    assert e_robust < 0.01
    assert e_plain > 0.03 and e_plain > 4 * e_robust


def test_batch_equals_single_confidence_weights_and_dropped_entries(scene):
    model, rig, x0, kp = scene
    f = KeypointEnergy(model, rig, kp)
    X = x0 + np.random.default_rng(0).normal(0, 0.05, (6, model.dof))
    np.testing.assert_array_equal(f(X), [f(x[None])[0] for x in X])
    assert f.n_evals == 12
    # the compiled kernel against the numpy reference: Geman-McClure of the point-to-ray distances, weighted
    np.testing.assert_allclose(f(X), geman_mcclure(f.distances(X) ** 2, f.sigma_m) @ f.weights, rtol=1e-12)
    X[2, 3] = np.nan
    e = f(X)
    assert np.isinf(e[2]) and np.all(np.isfinite(np.delete(e, 2)))
    # low confidence, NaN pixels and missing views drop correspondences
    uv, c = kp[1]
    c = c.copy()
    c[LANDMARK_NAMES.index("left_knee")] = 0.2
    uv = uv.copy()
    uv[LANDMARK_NAMES.index("right_knee")] = np.nan
    g = KeypointEnergy(model, rig, [None, (uv, c), None, kp[3]])
    assert g.n_correspondences == 14 + 12 and set(g.views.tolist()) == {1, 3}
    # a lower-confidence view weighs less
    h = KeypointEnergy(model, rig, [(kp[0][0], kp[0][1] * 0 + 0.6), kp[1], None, None])
    assert h.weights[h.views == 0].sum() < h.weights[h.views == 1].sum()
    # nothing usable: the term adds nothing
    z = KeypointEnergy(model, rig, [None] * 4)
    assert z.n_correspondences == 0 and np.all(z(X[:2]) == 0)


def test_lower_body_model_uses_its_joints_only():
    model = make_model(18)
    rig = default_rig()
    x = model.rest_pose()
    f = KeypointEnergy(model, rig, true_keypoints(model, rig, x))
    assert f.n_correspondences == 4 * 8 and f(x[None])[0] < 1e-20


def test_bad_input_is_named(scene):
    model, rig, x0, kp = scene
    with pytest.raises(EnergyError, match="keypoints: expected 4"):
        KeypointEnergy(model, rig, kp[:2])
    with pytest.raises(EnergyError, match=r"keypoints\[1\]"):
        KeypointEnergy(model, rig, [kp[0], (np.zeros((17, 2)), np.zeros(17)), None, None])
    with pytest.raises(EnergyError, match="sigma_m"):
        KeypointEnergy(model, rig, kp, sigma_m=0)
    with pytest.raises(EnergyError, match="min_confidence"):
        KeypointEnergy(model, rig, kp, min_confidence=2)
    with pytest.raises(EnergyError, match="X"):
        KeypointEnergy(model, rig, kp)(np.zeros((2, 5)))
