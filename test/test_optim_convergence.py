"""Convergence smoke tests (fixed seed, fixed budget) on sphere, Rosenbrock and Ackley, 2-40 dims.

Thresholds: the worst best-energy measured over seeds 0-7 at the same budget, times a margin
(about 3-10x), and always far below the starting energy (given in the comment).
"""
import numpy as np
import pytest

from isa_mocap_ros.bench.ackley import ackley
from isa_mocap_ros.optim import make_optimizer, minimize


def sphere(X):
    return np.sum(X ** 2, axis=1)


def rosenbrock(X):
    return np.sum(100 * (X[:, 1:] - X[:, :-1] ** 2) ** 2 + (1 - X[:, :-1]) ** 2, axis=1)


# (problem, d, x0 value, spread, budget, algorithm, params, threshold, measured worst of 8 seeds)
CASES = [
    # sphere, d = 10, x0 = 1 (E = 10)
    ("sphere", 10, 1.0, 1.0, 3000, "isa", {}, 0.05, 0.0143),
    ("sphere", 10, 1.0, 1.0, 3000, "apf", {}, 4.0, 1.26),
    ("sphere", 10, 1.0, 1.0, 3000, "cmaes", {}, 1e-14, 3.4e-18),
    ("sphere", 10, 1.0, 1.0, 3000, "de", {}, 7.0, 3.31),
    ("sphere", 10, 1.0, 1.0, 3000, "pso", {}, 1e-4, 4.5e-6),
    ("sphere", 10, 1.0, 1.0, 3000, "h-isa", {}, 0.05, 0.0107),
    ("sphere", 10, 1.0, 1.0, 3000, "psapf", {}, 1.0, 0.262),
    ("sphere", 10, 1.0, 1.0, 3000, "h-cmaes", {}, 1e-12, 5.5e-16),
    ("sphere", 10, 1.0, 1.0, 3000, "h-de", {}, 4.0, 1.39),
    ("sphere", 10, 1.0, 1.0, 3000, "h-pso", {}, 1e-5, 1e-7),
    # sphere, d = 40, x0 = 1 (E = 40)
    ("sphere", 40, 1.0, 1.0, 8000, "isa", {"schedule": "logarithmic", "b": 2.0}, 3.0, 0.92),
    ("sphere", 40, 1.0, 1.0, 8000, "cmaes", {}, 1e-12, 6.8e-15),
    ("sphere", 40, 1.0, 1.0, 8000, "pso", {}, 0.5, 0.102),
    ("sphere", 40, 1.0, 1.0, 8000, "h-cmaes", {}, 1e-10, 6.2e-13),
    ("sphere", 40, 1.0, 1.0, 8000, "psapf", {}, 25.0, 14.3),
    # Rosenbrock, d = 2, x0 = (-1, -1) (E = 404)
    ("rosenbrock", 2, -1.0, 0.5, 3000, "isa", {"schedule": "adaptive"}, 0.1, 0.0062),
    ("rosenbrock", 2, -1.0, 0.5, 3000, "apf", {}, 2.0, 0.49),
    ("rosenbrock", 2, -1.0, 0.5, 3000, "cmaes", {}, 1e-12, 9.2e-26),
    ("rosenbrock", 2, -1.0, 0.5, 3000, "de", {}, 40.0, 17.8),
    ("rosenbrock", 2, -1.0, 0.5, 3000, "pso", {}, 1e-3, 4.5e-6),
    # Ackley, d = 2, x0 = 1.5 (E = 7.5)
    ("ackley", 2, 1.5, 1.0, 2000, "isa", {}, 0.02, 0.0016),
    ("ackley", 2, 1.5, 1.0, 2000, "apf", {}, 0.2, 0.035),
    ("ackley", 2, 1.5, 1.0, 2000, "cmaes", {}, 1e-9, 1.9e-12),
    ("ackley", 2, 1.5, 1.0, 2000, "de", {}, 1.0, 0.25),
    ("ackley", 2, 1.5, 1.0, 2000, "pso", {}, 1e-9, 4e-15),
    ("ackley", 2, 1.5, 1.0, 2000, "psapf", {}, 5e-3, 5e-4),
    ("ackley", 2, 1.5, 1.0, 2000, "h-pso", {}, 1e-5, 3.7e-8),
]
PROBLEMS = {"sphere": sphere, "rosenbrock": rosenbrock, "ackley": ackley}


@pytest.mark.parametrize("problem,d,x0,spread,budget,name,params,threshold,measured", CASES,
                         ids=[f"{c[0]}{c[1]}-{c[5]}" for c in CASES])
def test_converges_within_budget(problem, d, x0, spread, budget, name, params, threshold,
                                 measured):
    f = PROBLEMS[problem]
    kw = dict(params)
    if name == "psapf" or name.startswith("h-"):
        kw["partitions"] = np.array_split(np.arange(d), 2)
    opt = make_optimizer(name, np.full(d, x0), spread, rng=np.random.default_rng(3), **kw)
    res = minimize(opt, f, max_evals=budget)
    start = f(np.full((1, d), x0))[0]
    assert res.n_evals <= budget
    assert res.best_energy < threshold < start
    assert f(res.best_x[None])[0] == pytest.approx(res.best_energy)
