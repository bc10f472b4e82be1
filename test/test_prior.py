"""Parzen-Rosenblatt pose prior (ISA 13.32-13.33)."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.energy.prior import ParzenPrior, PriorError, second_nearest_neighbour_sigma


def walk_like_poses(rng: np.random.Generator, n: int = 200, d_joints: int = 12) -> np.ndarray:
    """Pose vectors (n, 6 + d_joints): a root that wanders, joint angles on a noisy cycle."""
    phase = np.linspace(0, 4 * np.pi, n)
    freqs = rng.uniform(0.5, 1.5, d_joints)
    offsets = rng.uniform(0, 2 * np.pi, d_joints)
    joints = 0.6 * np.sin(phase[:, None] * freqs + offsets) + rng.normal(0, 0.02, (n, d_joints))
    root = np.hstack([np.cumsum(rng.normal(0, 0.05, (n, 3)), axis=0), rng.normal(0, 0.5, (n, 3))])
    return np.hstack([root, joints])


@pytest.fixture
def poses():
    return walk_like_poses(np.random.default_rng(3))


def brute_force_sigma(S: np.ndarray) -> float:
    D = np.sqrt(((S[:, None, :] - S[None, :, :]) ** 2).sum(-1))
    np.fill_diagonal(D, np.inf)
    return float(np.sort(D, axis=1)[:, 1].max())


def brute_force_log_density(S: np.ndarray, x: np.ndarray, sigma: float) -> float:
    d = S.shape[1]
    k = np.exp(-((S - x) ** 2).sum(1) / (2 * sigma ** 2))
    return float(np.log(k.sum() / ((2 * np.pi * sigma ** 2) ** (d / 2) * S.shape[0])))


def test_sigma_is_max_second_nearest_neighbour_distance(poses):
    prior = ParzenPrior(poses)
    S = poses[:, 6:]
    assert prior.sigma == pytest.approx(brute_force_sigma(S), rel=1e-12)


def test_sigma_with_duplicates_matches_brute_force():
    rng = np.random.default_rng(4)
    S = rng.normal(size=(30, 3))
    S = np.vstack([S, S[:10]])                 # exact duplicates
    assert second_nearest_neighbour_sigma(S) == pytest.approx(brute_force_sigma(S), rel=1e-12)


def test_default_dims_are_joint_angles(poses):
    prior = ParzenPrior(poses)
    assert prior.dims.tolist() == list(range(6, poses.shape[1]))
    assert prior.n_train == len(poses) and prior.n_dof == poses.shape[1]
    x = poses[:5].copy()
    moved = x.copy()
    moved[:, :6] += 10.0                       # root translation/rotation do not matter
    np.testing.assert_array_equal(prior.log_density(x), prior.log_density(moved))


def test_log_density_matches_formula_13_32(poses):
    prior = ParzenPrior(poses)
    rng = np.random.default_rng(5)
    X = poses[rng.choice(len(poses), 6)] + rng.normal(0, 0.2, (6, poses.shape[1]))
    got = prior.log_density(X)
    want = [brute_force_log_density(poses[:, 6:], x[6:], prior.sigma) for x in X]
    np.testing.assert_allclose(got, want, rtol=1e-10)


def test_density_is_higher_at_training_poses_than_far_away(poses):
    prior = ParzenPrior(poses)
    far = poses[:20].copy()
    far[:, 6:] += 2.0
    assert np.all(prior.log_density(poses[:20]) > prior.log_density(far) + 10)
    # and the energy is correspondingly lower
    assert np.all(prior.energy(poses[:20]) < prior.energy(far))


def test_energy_is_shifted_minus_eta_log_density(poses):
    prior = ParzenPrior(poses)
    rng = np.random.default_rng(6)
    X = poses[:10] + rng.normal(0, 0.1, (10, poses.shape[1]))
    e8, e2 = prior.energy(X), prior.energy(X, eta=2.0)
    lp = prior.log_density(X)
    diffs = e8 + 8.0 * lp                        # the shift is a constant
    np.testing.assert_allclose(diffs, diffs[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(e8, 4.0 * e2, rtol=1e-12)
    assert np.all(e8 >= 0)
    # the infimum 0 is reached when all training poses coincide with x
    same = np.tile(poses[:1], (5, 1))
    tight = ParzenPrior(same, sigma=0.3)
    np.testing.assert_allclose(tight.energy(poses[:1]), 0.0, atol=1e-12)


def test_far_away_is_finite_no_underflow(poses):
    prior = ParzenPrior(poses)
    X = poses[:3].copy()
    X[:, 6:] += 1e3
    lp = prior.log_density(X)
    assert np.all(np.isfinite(lp)) and np.all(lp < -1e6)


def test_vectorized_equals_looped_and_chunking(poses, monkeypatch):
    prior = ParzenPrior(poses)
    rng = np.random.default_rng(7)
    X = poses[rng.choice(len(poses), 50)] + rng.normal(0, 0.3, (50, poses.shape[1]))
    batch = prior.energy(X)
    looped = np.array([prior.energy(x[None])[0] for x in X])
    np.testing.assert_allclose(batch, looped, rtol=1e-12, atol=1e-12)
    import isa_mocap_ros.energy.prior as mod
    monkeypatch.setattr(mod, "_CHUNK_ELEMENTS", 3 * len(poses))   # blocks of 3 rows
    np.testing.assert_allclose(prior.energy(X), batch, rtol=1e-12, atol=1e-12)


def test_save_load_round_trip(poses, tmp_path):
    prior = ParzenPrior(poses, dims=np.array([6, 8, 10, 11]))
    path = tmp_path / "prior.npz"
    prior.save(path)
    back = ParzenPrior.load(path)
    assert back.sigma == prior.sigma and back.n_train == prior.n_train
    assert back.n_dof == prior.n_dof and back.dims.tolist() == [6, 8, 10, 11]
    X = poses[::7]
    np.testing.assert_array_equal(back.log_density(X), prior.log_density(X))
    np.testing.assert_array_equal(back.energy(X), prior.energy(X))
    assert path.stat().st_size < 50_000


def test_load_rejects_other_files(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, a=np.zeros(3))
    with pytest.raises(PriorError, match="expected a ParzenPrior file"):
        ParzenPrior.load(path)
    with pytest.raises(PriorError, match="cannot read"):
        ParzenPrior.load(tmp_path / "missing.npz")


def test_from_motion_subsamples(poses):
    prior = ParzenPrior.from_motion(poses, stride=4)
    assert prior.n_train == len(poses[::4])
    np.testing.assert_array_equal(prior.training_samples, poses[::4, 6:])
    capped = ParzenPrior.from_motion(poses, stride=1, max_poses=25)
    assert capped.n_train == 25
    np.testing.assert_array_equal(capped.training_samples[[0, -1]], poses[[0, -1], 6:])


def test_nan_and_bad_input_raise(poses):
    prior = ParzenPrior(poses)
    X = poses[:3].copy()
    X[1, 7] = np.nan
    with pytest.raises(PriorError, match=r"X: expected finite values, got nan at row 1, column 7"):
        prior.log_density(X)
    with pytest.raises(PriorError, match=r"X: expected finite"):
        prior.energy(X)
    with pytest.raises(PriorError, match=r"X: expected shape \(n, 18\), got \(3, 17\)"):
        prior.energy(poses[:3, :-1])
    bad = poses.copy()
    bad[4, 2] = np.inf
    with pytest.raises(PriorError, match="training_poses: expected finite"):
        ParzenPrior(bad)
    with pytest.raises(PriorError, match=r"dims: expected distinct indices in \[0, 18\)"):
        ParzenPrior(poses, dims=[6, 30])
    with pytest.raises(PriorError, match="sigma: expected a finite number > 0"):
        ParzenPrior(poses, sigma=0.0)
    with pytest.raises(PriorError, match="at least 3 training poses"):
        ParzenPrior(poses[:2])
    with pytest.raises(PriorError, match="not all identical"):
        ParzenPrior(np.tile(poses[:1], (4, 1)))
    with pytest.raises(PriorError, match="eta"):
        prior.energy(poses[:2], eta=-1.0)
