"""Resampling schemes, ISA selection kernels, weights and annealing schedules."""
import numpy as np
import pytest

from isa_mocap_ros.optim import (AdaptiveEss, Logarithmic, OptimError, Polynomial, beta_for_ess,
                                 ess, multinomial, normalise_log, residual, select_s1, select_s2,
                                 select_s3, stratified, systematic)


@pytest.mark.parametrize("seed", range(20))
def test_systematic_gives_floor_or_ceil_copies(seed):
    rng = np.random.default_rng(seed)
    W = rng.dirichlet(np.full(17, 0.5))
    m = 23
    counts = np.bincount(systematic(W, rng, m), minlength=W.size)
    assert counts.sum() == m
    assert np.all(counts >= np.floor(m * W)) and np.all(counts <= np.ceil(m * W))


def test_residual_keeps_the_integer_parts():
    rng = np.random.default_rng(3)
    W = np.array([0.5, 0.3, 0.15, 0.05])
    counts = np.bincount(residual(W, rng, 10), minlength=4)
    assert counts.sum() == 10 and np.all(counts >= np.floor(10 * W))


@pytest.mark.parametrize("scheme", [multinomial, stratified, systematic, residual])
def test_schemes_are_unbiased(scheme):
    rng = np.random.default_rng(7)
    W = np.array([0.05, 0.45, 0.2, 0.3])
    reps, m = 4000, 10
    tot = np.zeros(4)
    for _ in range(reps):
        tot += np.bincount(scheme(W, rng, m), minlength=4)
    mean = tot / reps
    # standard error of a multinomial count mean is <= sqrt(m W (1-W) / reps) ~ 0.025
    assert np.allclose(mean, m * W, atol=0.1)


def test_multinomial_never_picks_zero_weight():
    rng = np.random.default_rng(0)
    W = np.array([0.0, 1.0, 0.0, 0.0])
    assert np.all(multinomial(W, rng, 100) == 1)


def test_bad_weights_raise():
    rng = np.random.default_rng(0)
    with pytest.raises(OptimError, match="W: expected finite non-negative"):
        multinomial(np.array([0.5, -0.1]), rng)
    with pytest.raises(OptimError, match="W: expected a non-empty"):
        systematic(np.zeros((2, 2)), rng)


def test_normalise_log_handles_inf_and_all_inf():
    W = normalise_log(np.array([-np.inf, 0.0, np.log(3.0), np.nan]))
    assert np.allclose(W, [0, 0.25, 0.75, 0])
    assert np.allclose(normalise_log(np.full(4, -np.inf)), 0.25)
    assert ess(np.full(8, 1 / 8)) == pytest.approx(8)


def test_s3_always_keeps_the_best_particle_and_s1_s2_return_valid_indices():
    rng = np.random.default_rng(1)
    for _ in range(50):
        W = rng.dirichlet(np.ones(12))
        A = select_s3(W, rng)
        assert A[np.argmax(W)] == np.argmax(W)
        for sel in (select_s1, select_s2):
            A = sel(W, rng)
            assert A.shape == (12,) and A.min() >= 0 and A.max() < 12


def test_s2_and_s3_keep_more_particles_than_s1_on_flat_weights():
    rng = np.random.default_rng(2)
    W = np.full(50, 1 / 50)
    kept = {k: np.mean([np.mean(s(W, rng) == np.arange(50)) for _ in range(200)])
            for k, s in (("s1", select_s1), ("s2", select_s2), ("s3", select_s3))}
    assert kept["s3"] == 1.0                  # flat weights: W / max W = 1, all kept
    assert kept["s2"] > kept["s1"]            # keep prob 1/n on top of the multinomial draw


def test_schedules_follow_the_equations():
    assert Polynomial(0.5)(3) == pytest.approx(2.0)          # (t+1)^b (13.19)
    assert Logarithmic(2.0)(1) == pytest.approx(np.log(3))   # ln(t+b) (13.18)
    with pytest.raises(OptimError, match="b: logarithmic schedule expects b > 1"):
        Logarithmic(0.5)


@pytest.mark.parametrize("target", [0.1, 0.5, 0.9])
def test_beta_for_ess_hits_the_survival_rate(target):
    rng = np.random.default_rng(4)
    E = rng.exponential(size=200)
    beta = beta_for_ess(E, target)
    W = normalise_log(-beta * E)
    assert ess(W) / 200 == pytest.approx(target, abs=1e-3)
    assert AdaptiveEss(target)(0, E) == pytest.approx(beta)


def test_beta_for_ess_degenerate_inputs():
    assert beta_for_ess(np.ones(10), 0.5) == 0.0
    assert beta_for_ess(np.array([1.0, np.inf, np.inf]), 0.5) == 0.0
    with pytest.raises(OptimError, match="target: expected an ESS fraction"):
        beta_for_ess(np.ones(3), 0.0)
