"""Rotation-vector helpers and the rotation mean (ISA 13.20-13.24)."""
import numpy as np
import pytest

from isa_mocap_ros.optim import Isa, rotation_mean, weighted_estimate
from isa_mocap_ros.optim._rotations import exp_so3, log_so3


def test_exp_log_roundtrip_including_small_and_large_angles():
    rng = np.random.default_rng(0)
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([[0.0, 1e-12, 1e-7, 1e-4], rng.uniform(0, np.pi - 1e-2, 192),
                             [np.pi - 1e-3, np.pi - 1e-5, np.pi - 1e-7, 3.0]])
    r = axes * angles[:, None]
    R = exp_so3(r)
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(log_so3(R), r, atol=1e-6)


def test_mean_of_identical_rotations_is_that_rotation():
    r = np.array([0.3, -1.2, 0.7])
    assert np.allclose(rotation_mean(np.tile(r, (9, 1)), np.random.default_rng(0).random(9)), r)
    assert np.allclose(rotation_mean(np.zeros((4, 3)), np.ones(4)), 0.0)


def test_weighted_mean_of_two_rotations_about_one_axis_is_on_the_geodesic():
    axis = np.array([0.0, 0.6, 0.8])
    r = np.array([0.4 * axis, 1.6 * axis])
    assert np.allclose(rotation_mean(r, np.array([1.0, 1.0])), 1.0 * axis, atol=1e-9)
    assert np.allclose(rotation_mean(r, np.array([3.0, 1.0])), 0.7 * axis, atol=1e-9)


def test_mean_across_the_pi_seam_is_not_the_euclidean_mean():
    # rotations by +-(pi - 0.1) about z are 0.2 rad apart; the mean is the rotation by pi
    r = np.array([[0, 0, np.pi - 0.1], [0, 0, -(np.pi - 0.1)]])
    m = rotation_mean(r, np.ones(2))
    assert np.allclose(np.abs(m), [0, 0, np.pi], atol=1e-6)
    assert not np.allclose(r.mean(axis=0), m)


def test_weighted_estimate_uses_the_rotation_mean_on_declared_blocks():
    X = np.array([[1.0, 0, 0, np.pi - 0.1], [3.0, 0, 0, -(np.pi - 0.1)]])
    x = weighted_estimate(X, np.array([0.5, 0.5]), rotation_blocks=[(1, 2, 3)])
    assert x[0] == pytest.approx(2.0) and abs(x[3]) == pytest.approx(np.pi, abs=1e-6)
    opt = Isa(np.zeros(4), 0.1, rng=np.random.default_rng(0), rotation_blocks=[(1, 2, 3)])
    opt.tell(X[[0, 1] * 25], np.zeros(50))
    assert abs(opt.result().x[3]) == pytest.approx(np.pi, abs=1e-6)
