"""Compiled optimizer helpers are bit-identical to the numpy code; batched ≡ looped evaluation."""
import numpy as np
import pytest

from isa_mocap_ros.optim import OPTIMIZERS, make_optimizer, minimize
from isa_mocap_ros.optim._fast import pairwise_sum
from isa_mocap_ros.optim.resampling import ess, normalise_log
from isa_mocap_ros.optim.schedules import beta_for_ess
from libm_probe import NUMPY_IS_LIBM
from isa_mocap_ros.eval.peers import register_peers

register_peers()  # the reference peers run through the same protocol


def numpy_beta_for_ess(energies, target, beta_max=1e12, tol=1e-6):
    """The numpy formulation beta_for_ess had before it was compiled (the reference)."""
    E = np.asarray(energies, dtype=float)
    fin = np.isfinite(E)
    n = E.size
    if fin.sum() < 2:
        return 0.0
    Ef = E[fin] - E[fin].min()
    if Ef.max() <= 0:
        return 0.0

    def frac(beta):
        return ess(normalise_log(-beta * Ef)) / n

    if frac(0.0) <= target:
        return 0.0
    lo, hi = -12.0, np.log10(beta_max)
    lo += np.log10(1.0 / np.median(Ef[Ef > 0]))
    hi = max(hi, lo + 1)
    if frac(10 ** hi) >= target:
        return float(10 ** hi)
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if frac(10 ** mid) > target:
            lo = mid
        else:
            hi = mid
        if hi - lo < tol:
            break
    return float(10 ** (0.5 * (lo + hi)))


def test_pairwise_sum_is_numpys_sum_bit_for_bit():
    rng = np.random.default_rng(0)
    for n in list(range(1, 140)) + [255, 256, 257, 1000, 4099]:
        a = rng.standard_normal(n) * 10.0 ** rng.uniform(-4, 4)
        assert pairwise_sum(a) == a.sum()


def test_beta_for_ess_is_bit_identical_to_the_numpy_formulation():
    rng = np.random.default_rng(1)
    for trial in range(300):
        n = int(rng.integers(2, 300))
        E = rng.random(n) * 10.0 ** rng.uniform(-8, 3)
        if trial % 3 == 0:
            E[rng.random(n) < 0.2] = np.inf
        if trial % 5 == 0:
            E = np.round(E, 2)
        target = float(rng.uniform(0.05, 0.95))
        if NUMPY_IS_LIBM:       # numpy's exp / power are libm's (AVX2 machines): the same bits
            assert beta_for_ess(E, target) == numpy_beta_for_ess(E, target)
        else:                   # numpy's AVX-512 ufuncs: a last-bit difference may move one bisection
            # step (tol 1e-6 in log10 beta), so the two agree to 10 ** 1e-6 - 1 = 2.3e-6
            assert beta_for_ess(E, target) == pytest.approx(numpy_beta_for_ess(E, target), rel=3e-6, abs=0)


def sphere(X):
    return np.sum((X - 0.3) ** 2, axis=1)


@pytest.mark.parametrize("name", list(OPTIMIZERS))
def test_batched_and_looped_evaluation_give_the_same_run_and_count(name):
    d = 6
    rows = {"batched": 0, "looped": 0}

    def batched(X):
        rows["batched"] += len(X)
        return sphere(X)

    def looped(X):
        rows["looped"] += len(X)
        return np.array([float(sphere(x[None])[0]) for x in X])

    res = {}
    for key, f in (("batched", batched), ("looped", looped)):
        kw = {}
        if name == "psapf" or name.startswith("h-"):
            kw["partitions"] = [np.arange(0, 3), np.arange(3, d)]
        opt = make_optimizer(name, np.zeros(d), 0.5, rng=np.random.default_rng(4), **kw)
        res[key] = minimize(opt, f, max_evals=901)
    a, b = res["batched"], res["looped"]
    assert rows["batched"] == rows["looped"] == a.n_evals == b.n_evals <= 901
    assert a.n_iter == b.n_iter
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.best_x, b.best_x)
    assert a.energy == b.energy and a.best_energy == b.best_energy
