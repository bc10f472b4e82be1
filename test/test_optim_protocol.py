"""The common optimizer protocol: budgets, determinism, bounds, bad input, iteration."""
import numpy as np
import pytest

from isa_mocap_ros.optim import (OPTIMIZERS, AnnealedParticleFilter, CmaEs, GenerationInfo, Isa,
                                 OptimError, Result, make_optimizer, minimize)
from isa_mocap_ros.eval.peers import register_peers

register_peers()  # the reference peers run through the same protocol

FLAT = ["isa", "apf", "cmaes", "de", "pso"]
ALL = list(OPTIMIZERS)


def sphere(X):
    return np.sum((X - 0.3) ** 2, axis=1)


def build(name, d=6, seed=0, **kw):
    if name == "psapf" or name.startswith("h-"):
        kw.setdefault("partitions", [np.arange(0, d // 2), np.arange(d // 2, d)])
    return make_optimizer(name, np.zeros(d), 0.5, rng=np.random.default_rng(seed), **kw)


class Counting:
    def __init__(self, f=sphere):
        self.f, self.rows, self.calls = f, 0, 0

    def __call__(self, X):
        self.rows += len(X)
        self.calls += 1
        return self.f(X)


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("budget", [997, 1000, 1301])
def test_budget_is_never_exceeded_and_counted_exactly(name, budget):
    en = Counting()
    res = minimize(build(name), en, max_evals=budget)
    assert res.n_evals == en.rows <= budget
    assert isinstance(res, Result) and res.history and isinstance(res.history[-1], GenerationInfo)
    assert res.history[-1].n_evals == res.n_evals
    # algorithms without their own end use the whole budget
    if name not in ("apf", "psapf", "h-apf", "cmaes", "h-cmaes"):
        assert res.n_evals == budget and "max_evals" in res.reason


@pytest.mark.parametrize("name", ALL)
def test_same_seed_same_result(name):
    r1 = minimize(build(name, seed=5), sphere, max_evals=600)
    r2 = minimize(build(name, seed=5), sphere, max_evals=600)
    r3 = minimize(build(name, seed=6), sphere, max_evals=600)
    assert np.array_equal(r1.x, r2.x) and np.array_equal(r1.population, r2.population)
    assert r1.n_evals == r2.n_evals and r1.best_energy == r2.best_energy
    assert not np.array_equal(r1.population, r3.population)


@pytest.mark.parametrize("name", ALL)
def test_bounds_are_respected(name):
    lo, hi = np.full(6, -0.2), np.full(6, 0.25)
    seen = []

    def en(X):
        seen.append(X.copy())
        return np.sum((X - 3.0) ** 2, axis=1)   # optimum outside the box pulls to the bound

    res = minimize(build(name, bounds=(lo, hi)), en, max_evals=800)
    allX = np.concatenate(seen)
    assert np.all(allX >= lo) and np.all(allX <= hi)
    assert np.all(res.x >= lo - 1e-12) and np.all(res.x <= hi + 1e-12)
    assert res.best_energy < en(np.zeros((1, 6)))[0]


@pytest.mark.parametrize("name", ALL)
def test_nan_and_inf_energies_are_worst_and_counted(name):
    def en(X):
        E = sphere(X)
        E[::3] = np.nan
        E[1::5] = np.inf
        return E

    res = minimize(build(name), en, max_evals=600)
    assert np.isfinite(res.best_energy) and np.all(np.isfinite(res.x))
    assert res.n_nonfinite > 0 and res.n_nonfinite <= res.n_evals


def test_all_nonfinite_energies_do_not_crash():
    res = minimize(Isa(np.zeros(3), 1.0, rng=np.random.default_rng(0)),
                   lambda X: np.full(len(X), np.nan), max_evals=200)
    assert res.n_nonfinite == 200 and res.best_energy == np.inf and np.all(np.isfinite(res.x))


@pytest.mark.parametrize("bad", [lambda X: np.zeros((len(X), 1)), lambda X: np.zeros(len(X) + 1),
                                 lambda X: 0.0])
def test_wrong_energy_shape_raises(bad):
    with pytest.raises(OptimError, match=r"energy: expected an array of shape \(\d+,\)"):
        minimize(CmaEs(np.zeros(3), 1.0, rng=np.random.default_rng(0)), bad, max_evals=100)


@pytest.mark.parametrize("spread", [0.0, -1.0, [1.0, 0.0, 1.0], np.nan])
def test_zero_or_negative_spread_raises(spread):
    with pytest.raises(OptimError, match="spread: expected finite values > 0"):
        Isa(np.zeros(3), spread, rng=np.random.default_rng(0))


def test_bad_shapes_and_arguments_raise():
    rng = np.random.default_rng(0)
    with pytest.raises(OptimError, match=r"spread: expected a float or shape \(3,\)"):
        CmaEs(np.zeros(3), [1.0, 1.0], rng=rng)
    with pytest.raises(OptimError, match="bounds: expected lo < hi"):
        CmaEs(np.zeros(2), 1.0, rng=rng, bounds=([0, 0], [1, -1]))
    with pytest.raises(OptimError, match="rng: expected a numpy.random.Generator"):
        CmaEs(np.zeros(2), 1.0, rng=0)
    with pytest.raises(OptimError, match="kernel: expected one of"):
        Isa(np.zeros(2), 1.0, rng=rng, kernel="s4")
    with pytest.raises(OptimError, match="variance: expected one of"):
        Isa(np.zeros(2), 1.0, rng=rng, variance="weighted")
    with pytest.raises(OptimError, match=r"c_scale: expected one of \['covariance', 'deviation'\], got 'std'"):
        Isa(np.zeros(2), 1.0, rng=rng, c_scale="std")
    with pytest.raises(OptimError, match="name: expected one of"):
        make_optimizer("nelder-mead", np.zeros(2), 1.0, rng=rng)
    with pytest.raises(OptimError, match="initial_population: expected 40 rows"):
        minimize(Isa(np.zeros(2), 1.0, rng=rng, n_particles=40,
                     initial_population=np.zeros((7, 2))), sphere, max_evals=100)
    with pytest.raises(OptimError, match=r"initial_population: expected shape \(n, 2\)"):
        Isa(np.zeros(2), 1.0, rng=rng, initial_population=np.zeros((7, 3)))
    with pytest.raises(OptimError, match="rotation_blocks: expected triples"):
        Isa(np.zeros(4), 1.0, rng=rng, rotation_blocks=[(0, 1, 7)])


@pytest.mark.parametrize("name,budget", [("isa", 49), ("cmaes", 5), ("de", 9), ("pso", 3),
                                         ("apf", 19), ("h-cmaes", 8)])
def test_budget_smaller_than_a_generation_raises(name, budget):
    with pytest.raises(OptimError, match="max_evals: .*(smaller than one generation|at least|"
                                         "fewer than one generation)"):
        minimize(build(name), sphere, max_evals=budget)


def test_last_generation_is_truncated_not_exceeded():
    en = Counting()
    opt = Isa(np.zeros(2), 1.0, n_particles=50, rng=np.random.default_rng(0))
    res = minimize(opt, en, max_evals=120)
    assert res.n_evals == 120 and res.n_iter == 3 and en.calls == 3   # 50 + 50 + 20


def test_callback_stops_and_receives_generation_info():
    got = []

    def cb(info):
        got.append(info)
        return info.n_iter == 4

    res = minimize(CmaEs(np.ones(3), 0.5, rng=np.random.default_rng(0)), sphere,
                   max_evals=10_000, callback=cb)
    assert res.n_iter == 4 and "callback" in res.reason
    assert all(isinstance(g, GenerationInfo) for g in got)
    assert [g.n_iter for g in got] == [1, 2, 3, 4]


def test_ask_tell_by_hand_matches_the_iterator():
    a = Isa(np.ones(3), 0.5, rng=np.random.default_rng(9))
    b = Isa(np.ones(3), 0.5, rng=np.random.default_rng(9)).bind(sphere)
    for _ in range(5):
        X = a.ask()
        a.tell(X, sphere(X))
        next(b)
    ra, rb = a.result(), b.result()
    assert np.array_equal(ra.x, rb.x) and ra.n_evals == rb.n_evals == 250
    assert ra.weights is not None and ra.weights.sum() == pytest.approx(1.0)
    assert np.isfinite(ra.history[-1].beta) and 1 <= ra.history[-1].ess <= 50


def test_next_without_energy_raises():
    with pytest.raises(OptimError, match="call bind"):
        next(Isa(np.ones(2), 0.5, rng=np.random.default_rng(0)))


def test_apf_runs_its_layers_and_sizes_itself_from_the_budget():
    opt = AnnealedParticleFilter(np.ones(4), 0.5, rng=np.random.default_rng(0))
    res = minimize(opt, sphere, max_evals=500)
    assert res.n_iter == 10 and res.n_evals == 500 and opt.n == 50 and "n_layers" in res.reason
    # Eq. 7-8: each layer's beta gives a survival rate (ESS / N) of 0.5
    assert all(g.ess / 50 == pytest.approx(0.5, abs=0.01) for g in res.history)


def test_warm_start_from_final_population():
    r1 = minimize(Isa(np.ones(3), 0.5, rng=np.random.default_rng(1)), sphere, max_evals=500)
    opt = Isa(r1.x, 0.5, rng=np.random.default_rng(2), initial_population=r1.population)
    assert np.array_equal(opt.ask(), r1.population)
