"""Ackley reproduction of gall_isa_introduction §13.4.1 (Tables 13.1-13.2) with ISA S1/S2/S3, plus CMA-ES.

Protocol (§13.4.1): 2-D Ackley on E = [-4, 4]^2, particles drawn uniformly on E, run stopped when
the estimate (ISA: weighted mean) is within delta = 1e-3 of (0, 0), at most 999 steps, 50 runs.
Noisy variant: ``max(0, f(x) + W)``, ``W ~ N(0, 0.5^2)`` drawn per evaluation, delta = 1e-2.

Step convention: ``steps`` is the time index ``t`` of Algorithm 6 (``t = 0`` for the initial
particles) of the first generation whose estimate is within delta, i.e. the number of
selection+mutation transitions performed; evaluations = ``n (t + 1)``. Success = reached within
999 steps; ``mean_steps``/``mean_evals`` average the successful runs.
ISA rows run once per reading of the dynamic variance scheme (13.16) (``Isa(variance=...)``):
``population`` -- the equation as printed, the default -- and ``selected`` -- the text's "after
resampling" reading (the ``variance`` field of a row; docs/optimizers.md compares them).
CMA-ES rows (ours and pycma, the reference) start at a uniform point of E with sigma0 = 2 and
bounds E; their estimate is the distribution mean; steps = generations (``t`` as above).
"""
from __future__ import annotations

import argparse
import json
import warnings

import numpy as np

from isa_mocap_ros.optim import CmaEs, Isa
from isa_mocap_ros.optim.isa import VARIANCE_READINGS

MAX_STEPS = 999
LO, HI = -4.0, 4.0

# (kernel, noise, n, b, c, paper t) -- Table 13.1 (n = 50) and Table 13.2 (best n, same b and c)
TABLE_13_1 = [("s1", False, 50, 0.993, 0.8, 14.34), ("s2", False, 50, 0.987, 0.7, 15.14),
              ("s3", False, 50, 0.984, 0.7, 14.58), ("s1", True, 50, 0.25, 0.7, 7.36),
              ("s2", True, 50, 0.35, 0.7, 7.54), ("s3", True, 50, 0.27, 0.9, 7.5)]
TABLE_13_2 = [("s1", False, 30, 0.993, 0.8, 22.4), ("s2", False, 30, 0.987, 0.7, 20.3),
              ("s3", False, 28, 0.984, 0.7, 21.54), ("s1", True, 50, 0.25, 0.7, 7.36),
              ("s2", True, 50, 0.35, 0.7, 7.54), ("s3", True, 26, 0.27, 0.9, 12.54)]


def ackley(X: np.ndarray) -> np.ndarray:
    """Ackley function ``(n,)`` of points ``X : (n, d)`` (§13.4.1)."""
    X = np.asarray(X, dtype=float)
    return (-20.0 * np.exp(-0.2 * np.sqrt(np.mean(X * X, axis=1)))
            - np.exp(np.mean(np.cos(2 * np.pi * X), axis=1)) + 20.0 + np.e)


def _energy(noise: bool, rng: np.random.Generator):
    if not noise:
        return ackley
    return lambda X: np.maximum(0.0, ackley(X) + rng.normal(0.0, 0.5, size=len(X)))


def run_isa(kernel: str, n: int, b: float, c: float, noise: bool, runs: int, seed: int = 0,
            rho: float = 1e-4, variance: str = VARIANCE_READINGS[0]) -> dict:
    """Mean steps, success rate and mean evaluations of ISA on the protocol."""
    delta = 1e-2 if noise else 1e-3
    steps, evals = [], []
    for r in range(runs):
        rng = np.random.default_rng([seed, r])
        P0 = rng.uniform(LO, HI, size=(n, 2))
        opt = Isa(np.zeros(2), 4.0, n_particles=n, kernel=kernel, schedule="polynomial", b=b,
                  c=c, rho=rho, variance=variance, bounds=(np.full(2, LO), np.full(2, HI)), rng=rng,
                  initial_population=P0)
        opt.bind(_energy(noise, rng))
        for t in range(MAX_STEPS + 1):
            next(opt)
            if np.linalg.norm(opt._x) < delta:
                steps.append(t)
                evals.append(opt.n_evals)
                break
    return _summary(steps, evals, runs)


def run_cmaes(noise: bool, runs: int, seed: int = 0, *, reference: bool = False) -> dict:
    """CMA-ES (ours, or pycma with ``reference=True``) on the protocol."""
    delta = 1e-2 if noise else 1e-3
    steps, evals = [], []
    lam = None
    for r in range(runs):
        rng = np.random.default_rng([seed, 1000 + r])
        x0 = rng.uniform(LO, HI, size=2)
        en = _energy(noise, rng)
        if reference:
            import cma
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                es = cma.CMAEvolutionStrategy(x0, 2.0, {
                    "bounds": [LO, HI], "seed": 1 + seed * 100003 + r, "verbose": -9,
                    "maxiter": MAX_STEPS + 1, "tolfun": 0, "tolx": 0, "tolfunhist": 0,
                    "tolflatfitness": 10**9, "tolstagnation": 10**9})
                lam = es.popsize
                ne = 0
                for t in range(MAX_STEPS + 1):
                    if es.stop():
                        break
                    X = es.ask()
                    es.tell(X, en(np.asarray(X)).tolist())
                    ne += len(X)
                    if np.linalg.norm(es.mean) < delta:
                        steps.append(t)
                        evals.append(ne)
                        break
        else:
            opt = CmaEs(x0, 2.0, bounds=(np.full(2, LO), np.full(2, HI)), rng=rng, tol_sigma=0)
            lam = opt.generation_size
            opt.bind(en)
            for t in range(MAX_STEPS + 1):
                if opt.stop():
                    break
                next(opt)
                if np.linalg.norm(opt.m) < delta:
                    steps.append(t)
                    evals.append(opt.n_evals)
                    break
    out = _summary(steps, evals, runs)
    out["n"] = lam
    return out


def _summary(steps, evals, runs):
    return {"mean_steps": float(np.mean(steps)) if steps else None,
            "success_rate": len(steps) / runs,
            "mean_evals": float(np.mean(evals)) if evals else None}


def collect(runs: int, seed: int = 0, readings=VARIANCE_READINGS) -> list[dict]:
    """All rows of the benchmark (the JSON ``rows``): the ISA rows once per reading of (13.16)."""
    rows = []
    for variance in readings:
        for table, spec in (("13.1", TABLE_13_1), ("13.2", TABLE_13_2)):
            for kernel, noise, n, b, c, paper in spec:
                s = run_isa(kernel, n, b, c, noise, runs, seed, variance=variance)
                rows.append({"method": f"ISA_{kernel.upper()} (Table {table})", "kernel": kernel,
                             "variance": variance, "n": n, "b": b, "c": c, "noise": 0.5 if noise else 0.0,
                             **s, "paper_mean_steps": paper})
    for ref in (False, True):
        for noise in (False, True):
            s = run_cmaes(noise, runs, seed, reference=ref)
            n = s.pop("n")
            rows.append({"method": "pycma" if ref else "CmaEs (ours)", "kernel": None, "variance": None, "n": n,
                         "b": None, "c": None, "noise": 0.5 if noise else 0.0, **s,
                         "paper_mean_steps": None})
    return rows


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    parser.add_argument("--runs", type=int, default=50, help="repetitions per row (paper: 50)")
    parser.add_argument("--quick", action="store_true", help="5 runs per row (smoke test)")
    parser.add_argument("--seed", type=int, default=0, help="base seed")
    parser.add_argument("--variance", choices=(*VARIANCE_READINGS, "both"), default="both",
                        help="reading of the dynamic variance scheme (13.16) for the ISA rows (default both)")


def _fmt(v, f="{:.2f}"):
    return "-" if v is None else f.format(v)


def run(args: argparse.Namespace) -> int:
    runs = 5 if args.quick else args.runs
    if runs < 1:
        print("bench ackley: --runs must be >= 1")
        return 2
    readings = VARIANCE_READINGS if args.variance == "both" else (args.variance,)
    rows = collect(runs, args.seed, readings)
    if args.json:
        print(json.dumps({"rows": rows}))
        return 0
    print(f"Ackley 2-D, E=[-4,4]^2, {runs} runs per row, <= {MAX_STEPS} steps "
          f"(delta 1e-3; noisy: sigma 0.5, delta 1e-2)")
    hdr = f"{'method':28s} {'(13.16)':10s} {'noise':>5s} {'n':>4s} {'b':>6s} {'c':>4s} {'steps':>7s} " \
          f"{'paper':>6s} {'diff':>7s} {'success':>8s} {'evals':>8s}"
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        p, m = r["paper_mean_steps"], r["mean_steps"]
        diff = _fmt(None if (p is None or m is None) else 100 * (m - p) / p, "{:+.0f}%")
        print(f"{r['method']:28s} {r['variance'] or '-':10s} {r['noise']:5.1f} {r['n']:4d} {_fmt(r['b'], '{:.3f}'):>6s} "
              f"{_fmt(r['c'], '{:.1f}'):>4s} {_fmt(m):>7s} {_fmt(p):>6s} {diff:>7s} "
              f"{100 * r['success_rate']:7.0f}% {_fmt(r['mean_evals'], '{:.0f}'):>8s}")
    return 0
