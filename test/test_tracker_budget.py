"""Tracker.step(evals=): one frame's budget instead of the configuration's (the estimator's lowered budget
under load, tracking/load.py)."""
import numpy as np
import pytest

from isa_mocap_ros.tracking import Tracker, TrackerConfig, TrackerError

from walk_scene import walk_scene


@pytest.fixture(scope="module")
def scene():
    return walk_scene(width=160, height=120, frames=3, duration_s=0.2, seed=0)


def _steps(scene, evals, contour=True):
    model, cams, walk, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=1500, seed=3))
    tr.initialize(pose=walk[0])
    return [tr.step(masks[k], k, evals=evals, contour_stage=contour) for k in (1, 2)]


def test_a_lowered_budget_is_spent_instead_of_the_configured_one(scene):
    full = _steps(scene, None)
    same = _steps(scene, 1500)
    low = _steps(scene, 500, contour=False)
    for f, s, lo in zip(full, same, low):
        np.testing.assert_array_equal(f.x, s.x)          # evals = config.evals: the same frame to the bit
        assert 1500 - 4 < f.n_evals <= 1500
        assert 500 - 4 < lo.n_evals <= 500 and not lo.fell_back and np.isfinite(lo.energy)


@pytest.mark.parametrize("bad", [0, -5, 2.5, True, "500"])
def test_bad_budget(scene, bad):
    model, cams, walk, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, seed=3))
    tr.initialize(pose=walk[0])
    with pytest.raises(TrackerError, match="evals: expected an integer >= 1 or None"):
        tr.step(masks[1], 1, evals=bad)
