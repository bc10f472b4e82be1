"""Tracker with the keypoint term (config.keypoints.keypoint_weight): the keypoints decide the heading of the
automatic initialization, weight 0 changes nothing, bad keypoints are a note."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.geometry import exp_so3
from isa_mocap_ros.tracking import Tracker, TrackerConfig, TrackerError

from test_energy_keypoints import true_keypoints
from walk_scene import walk_scene


@pytest.fixture(scope="module")
def scene():
    return walk_scene(width=160, height=120, frames=2, duration_s=0.3, seed=0)


def _heading(x) -> float:
    f = exp_so3(np.asarray(x[3:6], float)) @ [1.0, 0.0, 0.0]        # the body's forward axis
    return float(np.arctan2(f[1], f[0]))


def _off_deg(a: float, b: float) -> float:
    return abs(np.rad2deg(np.angle(np.exp(1j * (a - b)))))


def _turned(model, x):
    """``x`` turned by pi about the vertical through its root."""
    from isa_mocap_ros.geometry import log_so3
    y = x.copy()
    y[3:6] = log_so3(exp_so3([0.0, 0.0, np.pi]) @ exp_so3(x[3:6]))
    return y


def test_keypoints_decide_the_initial_heading(scene):
    model, cams, poses, masks = scene
    cfg = TrackerConfig.from_flat(evals=300, init_refine_evals=200, seed=1, keypoint_weight=1.0)
    truth = _heading(poses[0])
    right = Tracker(model, cams, cfg).step(masks[0], 0, keypoints=true_keypoints(model, cams, poses[0]))
    assert right.initialized and any(n.startswith("keypoints: 56 in 4 views") for n in right.notes)
    assert _off_deg(_heading(right.x), truth) < 45
    # keypoints of the body turned around (a detector that took the back for the front): the term
    # alone turns the initialization, so it is what decides
    wrong = Tracker(model, cams, cfg).step(masks[0], 0, keypoints=true_keypoints(model, cams, _turned(model, poses[0])))
    assert _off_deg(_heading(wrong.x), truth) > 135


def test_weight_zero_or_no_keypoints_change_nothing(scene):
    model, cams, poses, masks = scene
    kp = true_keypoints(model, cams, poses[0])
    a = Tracker(model, cams, TrackerConfig.from_flat(evals=300, init_refine_evals=200, seed=1)).step(masks[0], 0)
    b = Tracker(model, cams, TrackerConfig.from_flat(evals=300, init_refine_evals=200, seed=1)).step(
        masks[0], 0, keypoints=kp)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.notes == b.notes


def test_bad_keypoints_are_a_note_and_bad_weights_raise(scene):
    model, cams, poses, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, init_refine_evals=200, seed=1, keypoint_weight=1.0))
    r = tr.step(masks[0], 0, keypoints=[None, (np.zeros((5, 2)), np.zeros(5)), None, None])
    assert r.initialized and any("keypoints ignored" in n and "keypoints[1]" in n for n in r.notes)
    r = tr.step(masks[1], 1, keypoints=[None] * 4)
    assert any("keypoints: none usable" in n for n in r.notes)
    with pytest.raises(TrackerError, match="keypoint_weight"):
        TrackerConfig.from_flat(keypoint_weight=-1.0)
    with pytest.raises(TrackerError, match="keypoint_sigma_m"):
        TrackerConfig.from_flat(keypoint_sigma_m=0.0)
