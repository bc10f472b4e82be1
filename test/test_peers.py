"""Reference optimizers wrapped as peers (isa_mocap_ros.eval.peers): budgets, seeds, convergence, registry."""
import numpy as np
import pytest

from isa_mocap_ros.eval.peers import PEERS, PycmaEs, ScipyDe, register_peers
from isa_mocap_ros.optim import OPTIMIZERS, OptimError, make_optimizer, minimize

register_peers()  # explicit: importing eval.peers registers nothing


class Counting:
    def __init__(self, d):
        self.rows = 0
        self.c = np.linspace(-0.4, 0.4, d)

    def __call__(self, X):
        X = np.asarray(X)
        self.rows += X.shape[0]
        return ((X - self.c) ** 2).sum(axis=1)


def _run(name, budget, seed, d=12, **kw):
    f = Counting(d)
    opt = make_optimizer(name, np.zeros(d), 0.5, rng=np.random.default_rng(seed),
                         bounds=(np.full(d, -2.0), np.full(d, 2.0)), **kw)
    res = minimize(opt, f, max_evals=budget)
    return res, f


@pytest.mark.parametrize("name", list(PEERS))
@pytest.mark.parametrize("budget", [37, 200, 501, 1499])
def test_budget_counted_exactly_and_never_exceeded(name, budget):
    res, f = _run(name, budget, 3)
    assert f.rows == res.n_evals == budget     # every evaluated row counted, budget spent, never exceeded


@pytest.mark.parametrize("name", list(PEERS))
def test_same_seed_same_result_other_seed_differs(name):
    a, _ = _run(name, 400, 11)
    np.random.seed(123)                       # global numpy state must not matter
    np.random.rand(7)
    b, _ = _run(name, 400, 11)
    c, _ = _run(name, 400, 12)
    assert np.array_equal(a.x, b.x) and a.best_energy == b.best_energy
    assert not np.array_equal(a.x, c.x)


def test_pycma_leaves_global_random_state_alone():
    st = np.random.get_state()
    _run("pycma", 300, 1)
    assert np.array_equal(np.random.get_state()[1], st[1])


@pytest.mark.parametrize("name", list(PEERS))
def test_converges_on_sphere(name):
    res, f = _run(name, 6000, 0, d=8)
    assert res.best_energy < 1e-6
    assert np.allclose(res.best_x, f.c, atol=1e-3)
    assert np.all(res.x >= -2.0) and np.all(res.x <= 2.0)


def test_bounds_respected_in_every_evaluation():
    seen = []

    def f(X):
        seen.append(np.array(X))
        return ((X - 5.0) ** 2).sum(axis=1)      # optimum outside the box

    for name in PEERS:
        opt = make_optimizer(name, np.zeros(4), 1.0, rng=np.random.default_rng(0), bounds=(-np.ones(4), np.ones(4)))
        res = minimize(opt, f, max_evals=600)
        X = np.vstack(seen)
        assert X.min() >= -1.0 and X.max() <= 1.0
        assert np.allclose(res.best_x, 1.0, atol=0.05)
        seen.clear()


def test_tracker_style_arguments_and_registry():
    register_peers()
    assert OPTIMIZERS["pycma"] is PycmaEs and OPTIMIZERS["scipy-de"] is ScipyDe
    from isa_mocap_ros.tracking import TrackerConfig
    assert TrackerConfig.from_flat(optimizer="pycma").search.optimizer == "pycma"
    d = 9
    lo, hi = np.full(d, -0.5), np.full(d, 0.5)
    lo[2], hi[2] = 0.1, 0.1 + 1e-6                 # the tracker's sliver for a prediction on a limit
    P = np.zeros((ScipyDe(np.zeros(d), 0.1, rng=np.random.default_rng(0)).generation_size, d))
    for name in PEERS:
        n = make_optimizer(name, np.zeros(d), 0.1, rng=np.random.default_rng(0), bounds=(lo, hi)).generation_size
        opt = make_optimizer(name, np.zeros(d), 0.1, rng=np.random.default_rng(1), bounds=(lo, hi),
                             rotation_blocks=[(3, 4, 5)], initial_population=P[:n])
        res = minimize(opt, lambda X: (X ** 2).sum(axis=1), max_evals=300)
        assert res.n_evals == 300 and lo[2] <= res.x[2] <= hi[2]


def test_bad_parameters():
    with pytest.raises(OptimError, match="popsize"):
        ScipyDe(np.zeros(3), 0.1, rng=np.random.default_rng(0), popsize=3)
    with pytest.raises(OptimError, match="options"):
        PycmaEs(np.zeros(3), 0.1, rng=np.random.default_rng(0), options={"seed": 3})
    with pytest.raises(OptimError, match="budget"):
        _run("scipy-de", 10, 0)                   # below one generation of 20
