"""The temporal term (energy/temporal.py): its value against a plain numpy reference, its combination with the
keypoint term in one kernel term, bad input, and the tracker with it (off changes nothing; on, the compiled search
and the protocol's objective score alike)."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.body import joint_positions, make_model
from isa_mocap_ros.energy import EnergyError, KeypointEnergy
from isa_mocap_ros.energy.keypoint_kernel import keypoint_batch
from isa_mocap_ros.energy.temporal import TemporalTerm, combined_term
from isa_mocap_ros.tracking import Tracker, TrackerConfig, TrackerError, objective

from test_energy_keypoints import true_keypoints
from walk_scene import walk_scene

JOINTS = ("left_ankle", "right_ankle", "left_knee")


@pytest.fixture(scope="module")
def scene():
    return walk_scene(width=160, height=120, frames=3, duration_s=0.3, seed=0)


def _reference(model, x0, X, joints, sigma):
    """Σ_j Σ_a w ρ(d_ja²) from the joint positions, in numpy (the module docstring's formula)."""
    idx = [model.joint_names.index(j) for j in joints]
    p = joint_positions(model, np.asarray(x0)[None])[0][idx]
    P = joint_positions(model, np.atleast_2d(X))[:, idx]               # (n, J, 3)
    diff = P - p[None]
    d2 = (diff ** 2).sum(-1)[..., None] - diff ** 2                    # distance² from the line along each axis
    return (d2 / (d2 + sigma ** 2)).sum(axis=(1, 2)) / (3 * len(idx))


def test_the_term_is_the_robust_distance_from_the_reference_joints():
    model = make_model(39)
    rng = np.random.default_rng(0)
    x0 = model.rest_pose()
    X = x0 + rng.normal(0.0, 0.15, (6, model.dof))
    t = TemporalTerm(model, x0, JOINTS, sigma_m=0.1)
    E = t(np.vstack([x0, X]))
    assert E[0] == 0.0 and np.all(E[1:] > 0) and np.all(E < 1)
    np.testing.assert_allclose(E[1:], _reference(model, x0, X, JOINTS, 0.1), rtol=1e-9, atol=1e-12)
    assert t.n_evals == 7
    # a pose whose chosen joints are where the reference has them costs nothing, whatever else moved
    y = x0.copy()
    y[model.dof_names.index("left_elbow_y")] += 0.5
    y[model.dof_names.index("left_ankle_y")] += 0.3            # the ankle joint's own turn moves the foot, not it
    assert t(y[None])[0] == 0.0


def test_combined_term_is_the_weighted_sum_in_one_kernel_call(scene):
    model, cams, poses, masks = scene
    kp = KeypointEnergy(model, cams, true_keypoints(model, cams, poses[0]), sigma_m=0.1)
    t = TemporalTerm(model, poses[1], JOINTS, sigma_m=0.1)
    X = np.stack([poses[0], poses[1], poses[2]])
    c = combined_term([(kp, 0.7), (t, 2.5)])
    want = 0.7 * kp(X) + 2.5 * t(X)
    np.testing.assert_allclose(c(X), want, rtol=1e-12)
    k = c.kernel_term(2.0)                          # what the compiled search calls: scale × the same sum
    out = np.empty(len(X))
    keypoint_batch(np.ascontiguousarray(X), *k[:-1], out)
    np.testing.assert_allclose(k.scale * out, 2.0 * want, rtol=1e-12)
    n_kp, n_t = kp.n_evals, t.n_evals
    c.n_evals += 30                                 # the compiled search's count reaches both terms
    assert (kp.n_evals, t.n_evals) == (n_kp + 30, n_t + 30)


def test_bad_input_raises_one_clear_error():
    model = make_model(39)
    x0 = model.rest_pose()
    with pytest.raises(EnergyError, match="joints: expected one or more of the model's joints.*unknown: nose"):
        TemporalTerm(model, x0, ["left_ankle", "nose"], sigma_m=0.1)
    with pytest.raises(EnergyError, match="sigma_m: expected a positive number"):
        TemporalTerm(model, x0, JOINTS, sigma_m=0.0)
    with pytest.raises(EnergyError, match="reference: expected 39 finite numbers"):
        TemporalTerm(model, x0[:10], JOINTS, sigma_m=0.1)
    a, b = TemporalTerm(model, x0, JOINTS, sigma_m=0.1), TemporalTerm(model, x0, JOINTS, sigma_m=0.2)
    with pytest.raises(EnergyError, match="one sigma_m"):
        combined_term([(a, 1.0), (b, 1.0)])
    with pytest.raises(TrackerError, match="temporal_weight"):
        TrackerConfig.from_flat(temporal_weight=-1.0)
    with pytest.raises(TrackerError, match="temporal_joints"):
        TrackerConfig.from_flat(temporal_joints=",")


def test_tracker_with_the_term(scene):
    model, cams, poses, masks = scene
    kw = dict(evals=300, init_refine_evals=200, seed=1)

    def track(**extra):
        tr = Tracker(model, cams, TrackerConfig.from_flat(**kw, **extra))
        return tr, [tr.step(masks[k], k) for k in range(2)]

    _, off = track()
    _, zero = track(temporal_weight=0.0, temporal_joints="left_knee")   # weight 0: no term, the same numbers
    for a, b in zip(off, zero):
        np.testing.assert_array_equal(a.x, b.x)
    tr, on = track(temporal_weight=5.0, temporal_joints="left_ankle, right_ankle")   # the default joints, spaced
    np.testing.assert_array_equal(on[0].x, off[0].x)        # the first frame (initialization) has no prediction
    assert not np.array_equal(on[1].x, off[1].x)
    # the objective the protocol path would minimise and the term the compiled search adds agree
    ctx = tr.frame_context(2)
    ctx.objective.temporal_term = objective.temporal_term(tr, on[1].x)
    term, w = ctx.objective.weighted_keypoints
    X = np.stack([on[0].x, on[1].x])
    np.testing.assert_allclose(ctx.objective(X), np.asarray(tr.energy(X)) + 5.0 * term(X), rtol=1e-12)
    assert w == 5.0 and term(X)[1] == 0.0
