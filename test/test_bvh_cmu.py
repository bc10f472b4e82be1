"""Retargeting real motion capture (CMU 131_01, 120 Hz, metres) onto the body models.

Uses a 2-second slice to stay fast; the whole file is measured by ``scripts``/bench (see
docs/body_models.md for the figures).
"""
from functools import lru_cache

import numpy as np
import pytest

from isa_mocap_ros.body import joint_positions
from isa_mocap_ros.body.bvh import load_bvh
from isa_mocap_ros.body.retarget import map_skeleton, model_from_bvh, retarget


@lru_cache(maxsize=1)
def _load(path):
    return load_bvh(path)


@pytest.fixture
def walk_slice(cmu_walk):
    motion = _load(cmu_walk)
    return motion, motion.slice(300, 540)  # 2 s including the stylised steps around frame 350


def test_cmu_skeleton_detected(walk_slice):
    motion, _ = walk_slice
    assert motion.scale == 1.0 and motion.fps == pytest.approx(120, rel=1e-3)
    mapping = map_skeleton(motion)
    assert mapping["pelvis"] == "Hips" and mapping["left_knee"] == "LeftKnee"
    assert mapping["right_shoulder"] == "RightShoulder" and mapping["spine_upper"] == "Chest2"
    P = motion.world_positions()
    j = motion.joint_index
    assert np.all(P[:, j("Head"), 2] > P[:, j("Hips"), 2])        # z up
    assert abs(np.ptp(P[:, 0, 0])) > 1.0                          # walks along x


@pytest.mark.parametrize("dof,limit_mm", [(39, 20.0), (28, 30.0), (18, 20.0)])
def test_cmu_retarget_residual(walk_slice, dof, limit_mm):
    motion, part = walk_slice
    model = model_from_bvh(motion, dof)
    X, report = retarget(part, model)
    # FK of the retargeted poses against the BVH's own joint positions (independent of the report)
    P = joint_positions(model, X)
    W = part.world_positions()
    d = np.stack([np.linalg.norm(P[:, model.joint_index(n)] - W[:, part.joint_index(b)], axis=-1)
                  for n, b in report.mapping.items()], axis=1) * 1000
    assert d.mean() == pytest.approx(report.mean_mm, rel=1e-9)
    assert report.mean_mm < limit_mm
    if dof == 39:
        assert report.max_frame_mm < 20.0
    # root rotation vectors continuous over time, poses within limits
    assert np.max(np.linalg.norm(np.diff(X[:, 3:6], axis=0), axis=1)) < 0.2
    assert np.all(X[:, 6:] >= model.lower[6:] - 1e-12) and np.all(X[:, 6:] <= model.upper[6:] + 1e-12)
    # knees bend during the walk
    assert np.ptp(X[:, model.knee_dofs[0]]) > np.deg2rad(30)
