"""Ackley reproduction of gall_isa_introduction §13.4.1 (Tables 13.1-13.2) with ISA S1/S2/S3, plus CMA-ES.

Protocol (§13.4.1): 2-D Ackley on E = [-4, 4]^2, particles drawn uniformly on E, run stopped when
the estimate (ISA: weighted mean) is within delta = 1e-3 of (0, 0), at most 999 steps, 50 runs.
Noisy variant: ``max(0, f(x) + W)``, ``W ~ N(0, 0.5^2)`` drawn per evaluation, delta = 1e-2.

Step convention: ``steps`` is the time index ``t`` of Algorithm 6 (``t = 0`` for the initial
particles) of the first generation whose estimate is within delta, i.e. the number of
selection+mutation transitions performed; evaluations = ``n (t + 1)``. Success = reached within
999 steps; ``mean_steps``/``mean_evals`` average the successful runs.
ISA rows run once per reading of the dynamic variance scheme (13.16) (:data:`READINGS`): which
particles it is computed over (``Isa(variance=...)``, a row's ``variance``): ``population`` -- the
equation as printed -- or ``selected`` -- the text's "after resampling"; and what the book's ``c``
multiplies (``Isa(c_scale=...)``, a row's ``c_scale``): the standard deviation, ``deviation`` -- as
Fig. 13.13 says ("the standard deviations ..., which are scaled by c"), and only with it is the
book's ``c`` (0.7-0.8, "c in the range 0.5-1.0") near our best -- or the covariance as (13.16) prints
it, ``covariance``. The first reading, population / deviation, is the benchmark's; docs/optimizers.md
compares them.
CMA-ES rows (ours and pycma, the reference) start at a uniform point of E with sigma0 = 2 and
bounds E; their estimate is the distribution mean; steps = generations (``t`` as above).

The book's Tables 13.1 and 13.2 are the results of searches: the (b, c) with the lowest average
steps at n = 50 over Fig. 13.5's grid (b in [0.1, 0.999], c in [0.1, 3]), then the n with the lowest
cost n * t over Fig. 13.6's (4..200 step 2). The benchmark gives both: rows at the book's
parameters, and rows where b, c and n are searched the same way (:func:`searched_rows`: chosen on
300 runs, measured on 300 held-out runs, exact branch-and-bound so the grids cost seconds).
"""
from __future__ import annotations

import argparse
import json
import math
import warnings

import numpy as np

from isa_mocap_ros.optim import CmaEs, Isa
from isa_mocap_ros.optim.isa import C_SCALES, VARIANCE_READINGS

MAX_STEPS = 999
LO, HI = -4.0, 4.0

# (kernel, noise, n, b, c, paper t) -- Table 13.1 (n = 50) and Table 13.2 (best n, same b and c)
TABLE_13_1 = [("s1", False, 50, 0.993, 0.8, 14.34), ("s2", False, 50, 0.987, 0.7, 15.14),
              ("s3", False, 50, 0.984, 0.7, 14.58), ("s1", True, 50, 0.25, 0.7, 7.36),
              ("s2", True, 50, 0.35, 0.7, 7.54), ("s3", True, 50, 0.27, 0.9, 7.5)]
TABLE_13_2 = [("s1", False, 30, 0.993, 0.8, 22.4), ("s2", False, 30, 0.987, 0.7, 20.3),
              ("s3", False, 28, 0.984, 0.7, 21.54), ("s1", True, 50, 0.25, 0.7, 7.36),
              ("s2", True, 50, 0.35, 0.7, 7.54), ("s3", True, 26, 0.27, 0.9, 12.54)]
# the grids of the searches: Fig. 13.5's ranges b in [0.1, 0.999], c in [0.1, 3]; Fig. 13.6's n in 4..200 step 2
GRID_B = (0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99, 0.993, 0.995, 0.999)
GRID_C = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.5, 2.0, 2.5, 3.0)
GRID_N = tuple(range(4, 201, 2))
SEARCH_SEEDS = 6   # seeds the searches choose on (runs each); as many held-out seeds measure the choice
#: readings of (13.16), ``(variance, c_scale)`` of :class:`Isa`; the first is the benchmark's (module doc)
READINGS = (("population", "deviation"), ("population", "covariance"), ("selected", "covariance"),
            ("selected", "deviation"))
VARIANCE, C_SCALE = READINGS[0]


def ackley(X: np.ndarray) -> np.ndarray:
    """Ackley function ``(n,)`` of points ``X : (n, d)`` (§13.4.1)."""
    X = np.asarray(X, dtype=float)
    return (-20.0 * np.exp(-0.2 * np.sqrt(np.mean(X * X, axis=1)))
            - np.exp(np.mean(np.cos(2 * np.pi * X), axis=1)) + 20.0 + np.e)


def _energy(noise: bool, rng: np.random.Generator):
    if not noise:
        return ackley
    return lambda X: np.maximum(0.0, ackley(X) + rng.normal(0.0, 0.5, size=len(X)))


def _isa_steps(kernel: str, n: int, b: float, c: float, noise: bool, seed: int, r: int, *, rho: float = 1e-4,
               variance: str = VARIANCE, c_scale: str = C_SCALE, limit: int = MAX_STEPS) -> int | None:
    """Steps ``t`` of run ``r`` (random stream ``(seed, r)``) to reach delta, or None if not within ``limit``."""
    delta = 1e-2 if noise else 1e-3
    rng = np.random.default_rng([seed, r])
    P0 = rng.uniform(LO, HI, size=(n, 2))
    opt = Isa(np.zeros(2), 4.0, n_particles=n, kernel=kernel, schedule="polynomial", b=b,
              c=c, c_scale=c_scale, rho=rho, variance=variance, bounds=(np.full(2, LO), np.full(2, HI)), rng=rng,
              initial_population=P0)
    opt.bind(_energy(noise, rng))
    for t in range(limit + 1):
        next(opt)
        if np.linalg.norm(opt.estimate()[0]) < delta:
            return t
    return None


def run_isa(kernel: str, n: int, b: float, c: float, noise: bool, runs: int, seed: int = 0,
            rho: float = 1e-4, variance: str = VARIANCE, c_scale: str = C_SCALE, seeds=None) -> dict:
    """Mean steps, success rate and mean evaluations of ISA on the protocol (``runs`` runs of each
    seed in ``seeds``, default ``(seed,)``)."""
    steps, evals, total = [], [], 0
    for s in (seed,) if seeds is None else seeds:
        for r in range(runs):
            total += 1
            t = _isa_steps(kernel, n, b, c, noise, s, r, rho=rho, variance=variance, c_scale=c_scale)
            if t is not None:
                steps.append(t)
                evals.append(n * (t + 1))
    return _summary(steps, evals, total)


def _cell_cost(kernel, n, b, c, noise, streams, reading, weight, bound):
    """Total steps ``sum t`` of one cell over the runs ``streams`` (``(seed, run)`` pairs) if every
    run reaches delta and ``weight * sum < bound``, else None. Runs are cut as soon as the cell can no
    longer beat ``bound`` (steps are >= 0), so the search finds exactly the cell that evaluating
    every cell in full would find, in a fraction of the time."""
    max_sum = MAX_STEPS * len(streams) if not math.isfinite(bound) else math.ceil(bound / weight) - 1
    total = 0
    for seed, r in streams:
        limit = min(MAX_STEPS, max_sum - total)
        if limit < 0:
            return None
        t = _isa_steps(kernel, n, b, c, noise, seed, r, variance=reading[0], c_scale=reading[1], limit=limit)
        if t is None:
            return None
        total += t
    return total if weight * total < bound else None


def _streams(runs: int, seeds) -> list[tuple[int, int]]:
    return [(s, r) for s in seeds for r in range(runs)]


def _best_cell(cells, settings, weight, kernel, noise, streams, reading):
    """Branch and bound over ``cells`` (duplicates tried once, in order): the first with the lowest
    ``weight(cell) * sum t`` among those where every run reaches delta; ``settings(cell)`` gives its
    ``(n, b, c)``. Returns ``(cell, total steps)`` or ``(None, None)``, and the cells tried."""
    best, best_total, best_cost, tried = None, None, math.inf, 0
    for cell in dict.fromkeys(cells):
        tried += 1
        n, b, c = settings(cell)
        total = _cell_cost(kernel, n, b, c, noise, streams, reading, weight(cell), best_cost)
        if total is not None:
            best, best_total, best_cost = cell, total, weight(cell) * total
    return best, best_total, tried


def search_bc(kernel: str, noise: bool, n: int, runs: int, seeds=(0,), *, grid_b=GRID_B, grid_c=GRID_C,
              first=None, variance: str = VARIANCE, c_scale: str = C_SCALE) -> dict:
    """Table 13.1's search: the (b, c) of the polynomial schedule (13.19) and the dynamic variance
    (13.16) with the lowest mean steps over ``runs`` runs of each seed in ``seeds``, among the cells
    where every run reaches delta (``first``, e.g. the book's cell, is tried first and is a
    candidate too)."""
    cells = ([tuple(first)] if first is not None else []) + [(b, c) for b in grid_b for c in grid_c]
    streams = _streams(runs, seeds)
    best, total, tried = _best_cell(cells, lambda bc: (n, *bc), lambda bc: 1, kernel, noise, streams,
                                    (variance, c_scale))
    if best is None:
        return {"b": None, "c": None, "selection_mean_steps": None, "cells": tried}
    return {"b": best[0], "c": best[1], "selection_mean_steps": total / len(streams), "cells": tried}


def scan_n(kernel: str, noise: bool, b: float, c: float, runs: int, seeds=(0,), *, grid_n=GRID_N,
           first=None, variance: str = VARIANCE, c_scale: str = C_SCALE) -> dict:
    """Table 13.2's search (Fig. 13.6): the number of particles with the lowest mean cost
    ``n_t = n * t`` (13.17) over ``runs`` runs of each seed in ``seeds``, among the n where every
    run reaches delta."""
    ns = ([int(first)] if first is not None else []) + [int(n) for n in grid_n]
    streams = _streams(runs, seeds)
    best, total, _ = _best_cell(ns, lambda n: (n, b, c), lambda n: n, kernel, noise, streams, (variance, c_scale))
    if best is None:
        return {"n": None, "selection_mean_steps": None}
    return {"n": best, "selection_mean_steps": total / len(streams)}


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


def _searched_spec(spec, runs, reading, chosen_on, held_out, grid_b, grid_c, grid_n) -> list[dict]:
    """The searched rows (Table 13.1, Table 13.2) of one kernel and noise (``spec``: a TABLE_13_1 row)."""
    kernel, noise, n, pb, pc, paper = spec
    pn, pt = next((r[2], r[5]) for r in TABLE_13_2 if r[:2] == (kernel, noise))
    rd = dict(variance=reading[0], c_scale=reading[1])
    base = {"kernel": kernel, **rd, "noise": 0.5 if noise else 0.0,
            "selection_runs": runs * len(chosen_on), "held_out_runs": runs * len(held_out)}
    bc = search_bc(kernel, noise, n, runs, chosen_on, grid_b=grid_b, grid_c=grid_c, first=(pb, pc), **rd)
    if bc["b"] is None:
        return []
    s = run_isa(kernel, n, bc["b"], bc["c"], noise, runs, seeds=held_out, **rd)
    rows = [{"method": f"ISA_{kernel.upper()} (Table 13.1, searched)", **base, "n": n, "b": bc["b"], "c": bc["c"],
             **s, "paper_mean_steps": paper, "paper_n": n, "paper_b": pb, "paper_c": pc,
             "selection_mean_steps": bc["selection_mean_steps"]}]
    sn = scan_n(kernel, noise, bc["b"], bc["c"], runs, chosen_on, grid_n=grid_n, first=pn, **rd)
    if sn["n"] is not None:
        s = run_isa(kernel, sn["n"], bc["b"], bc["c"], noise, runs, seeds=held_out, **rd)
        rows.append({"method": f"ISA_{kernel.upper()} (Table 13.2, searched)", **base, "n": sn["n"], "b": bc["b"],
                     "c": bc["c"], **s, "paper_mean_steps": pt, "paper_n": pn, "paper_b": pb, "paper_c": pc,
                     "selection_mean_steps": sn["selection_mean_steps"]})
    return rows


def searched_rows(runs: int, seed: int = 0, reading=READINGS[0], *, n_seeds: int = SEARCH_SEEDS,
                  grid_b=GRID_B, grid_c=GRID_C, grid_n=GRID_N, jobs: int = 1) -> list[dict]:
    """Tables 13.1 and 13.2 reproduced as the book made them, by search: per kernel and noise, the
    (b, c) with the lowest mean steps at n = 50 (Fig. 13.5's grid, the book's cell included), then
    with those b and c the n with the lowest cost n * t (Fig. 13.6's grid, 4..200 step 2), among the
    cells where every run reaches delta. The book chose on 50 runs; a cell that fails 2 % of its
    runs passes 50 runs 36 % of the time, and the minimum of many noisy means is biased low. So
    both searches choose on ``runs`` runs of each of the ``n_seeds`` seeds ``seed, seed + 1, ...``
    and each chosen cell is measured again on as many held-out runs (the next ``n_seeds`` seeds):
    those figures are the row's ``mean_steps`` / ``success_rate``. ``jobs`` worker processes share
    the six (kernel, noise) searches (same rows for any ``jobs``). ``reading``: ``(variance, c_scale)``."""
    chosen_on = tuple(range(seed, seed + n_seeds))
    held_out = tuple(range(seed + n_seeds, seed + 2 * n_seeds))
    args = [(spec, runs, tuple(reading), chosen_on, held_out, grid_b, grid_c, grid_n) for spec in TABLE_13_1]
    if jobs <= 1:
        parts = [_searched_spec(*a) for a in args]
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as ex:
            parts = list(ex.map(_searched_spec, *zip(*args)))
    return [r for part in parts for r in part]


def collect(runs: int, seed: int = 0, readings=READINGS, *, search: bool = True, quick: bool = False,
            search_readings=READINGS[:1], jobs: int = 1) -> list[dict]:
    """All rows of the benchmark (the JSON ``rows``): the ISA rows at the book's parameters once per
    reading ``(variance, c_scale)`` in ``readings``, the searched rows (:func:`searched_rows`) for the
    readings in ``search_readings`` (``quick``: small grids, one seed each way), then CMA-ES (ours and
    pycma)."""
    rows = []
    for variance, c_scale in readings:
        for table, spec in (("13.1", TABLE_13_1), ("13.2", TABLE_13_2)):
            for kernel, noise, n, b, c, paper in spec:
                s = run_isa(kernel, n, b, c, noise, runs, seed, variance=variance, c_scale=c_scale)
                rows.append({"method": f"ISA_{kernel.upper()} (Table {table})", "kernel": kernel,
                             "variance": variance, "c_scale": c_scale, "n": n, "b": b, "c": c,
                             "noise": 0.5 if noise else 0.0, **s, "paper_mean_steps": paper})
    if search:
        kw = dict(n_seeds=1, grid_b=(0.99, 0.993), grid_c=(0.5, 0.8), grid_n=(20, 30, 50)) if quick else {}
        for reading in search_readings:
            rows += searched_rows(runs, seed, reading, jobs=jobs, **kw)
    for ref in (False, True):
        for noise in (False, True):
            s = run_cmaes(noise, runs, seed, reference=ref)
            n = s.pop("n")
            rows.append({"method": "pycma" if ref else "CmaEs (ours)", "kernel": None, "variance": None,
                         "c_scale": None, "n": n, "b": None, "c": None, "noise": 0.5 if noise else 0.0, **s,
                         "paper_mean_steps": None})
    return rows


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    parser.add_argument("--runs", type=int, default=50, help="repetitions per row (paper: 50)")
    parser.add_argument("--quick", action="store_true",
                        help="5 runs per row, small search grids, one held-out seed (smoke test)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the rows at the book's parameters; the searches choose on seeds SEED..SEED+5 "
                             "and measure the choice on SEED+6..SEED+11")
    parser.add_argument("--variance", choices=(*VARIANCE_READINGS, "both"), default="both",
                        help="particles of the dynamic variance scheme (13.16) for the ISA rows (default both)")
    parser.add_argument("--c-scale", choices=(*C_SCALES, "both"), default="both",
                        help="what the book's c multiplies in (13.16) for the ISA rows (default both)")
    parser.add_argument("--no-search", action="store_true",
                        help="skip the searched Tables 13.1-13.2 (b, c and n chosen by search, as the book did)")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes for the searches (default 2)")


def _fmt(v, f="{:.2f}"):
    return "-" if v is None else f.format(v)


def _diff(m, p):
    return _fmt(None if (p is None or m is None) else 100 * (m - p) / p, "{:+.0f}%")


def run(args: argparse.Namespace) -> int:
    runs = 5 if args.quick else args.runs
    if runs < 1:
        print("bench ackley: --runs must be >= 1")
        return 2
    readings = [r for r in READINGS if args.variance in ("both", r[0]) and args.c_scale in ("both", r[1])]
    # the searches run for the benchmark's reading, or for the one asked for
    search_readings = readings if len(readings) == 1 else readings[:1]
    rows = collect(runs, args.seed, readings, search=not args.no_search, quick=args.quick,
                   search_readings=search_readings, jobs=max(1, args.jobs))
    if args.json:
        print(json.dumps({"rows": rows}))
        return 0
    print(f"Ackley 2-D, E=[-4,4]^2, {runs} runs per row, <= {MAX_STEPS} steps "
          f"(delta 1e-3; noisy: sigma 0.5, delta 1e-2)")
    print("\nAt the book's parameters (b, c of Table 13.1; n of Table 13.2)")
    hdr = f"{'method':28s} {'(13.16)':10s} {'c scales':10s} {'noise':>5s} {'n':>4s} {'b':>6s} {'c':>4s} " \
          f"{'steps':>7s} " \
          f"{'paper':>6s} {'diff':>7s} {'success':>8s} {'evals':>8s}"
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        if "selection_mean_steps" in r:
            continue
        p, m = r["paper_mean_steps"], r["mean_steps"]
        print(f"{r['method']:28s} {r['variance'] or '-':10s} {r['c_scale'] or '-':10s} {r['noise']:5.1f} {r['n']:4d} {_fmt(r['b'], '{:.3f}'):>6s} "
              f"{_fmt(r['c'], '{:.1f}'):>4s} {_fmt(m):>7s} {_fmt(p):>6s} {_diff(m, p):>7s} "
              f"{100 * r['success_rate']:7.0f}% {_fmt(r['mean_evals'], '{:.0f}'):>8s}")
    searched = [r for r in rows if "selection_mean_steps" in r]
    if searched:
        r0 = searched[0]
        k = r0["selection_runs"] // runs
        print(f"\nSearched as the book did (Table 13.1: b, c at n = 50; Table 13.2: n by lowest n*t with those b, c), "
              f"chosen on {r0['selection_runs']} runs (seeds {args.seed}..{args.seed + k - 1}), measured on "
              f"{r0['held_out_runs']} held-out runs (seeds {args.seed + k}..{args.seed + 2 * k - 1})")
        hdr = f"{'method':30s} {'(13.16)':10s} {'c scales':10s} {'noise':>5s} {'paper n/b/c':>17s} " \
              f"{'ours n/b/c':>17s} {'chosen':>7s} " \
              f"{'steps':>7s} {'paper':>6s} {'diff':>6s} {'success':>8s} {'n*t':>7s} {'paper':>7s}"
        print(hdr)
        print("-" * len(hdr))
        for r in searched:
            m, p = r["mean_steps"], r["paper_mean_steps"]
            pbc = f"{r['paper_n']}/{r['paper_b']:.3f}/{r['paper_c']:.1f}"
            obc = f"{r['n']}/{r['b']:.3f}/{r['c']:.1f}"
            print(f"{r['method']:30s} {r['variance']:10s} {r['c_scale']:10s} {r['noise']:5.1f} {pbc:>17s} {obc:>17s} "
                  f"{_fmt(r['selection_mean_steps']):>7s} {_fmt(m):>7s} {_fmt(p):>6s} {_diff(m, p):>6s} "
                  f"{100 * r['success_rate']:7.1f}% {_fmt(None if m is None else r['n'] * m, '{:.0f}'):>7s} "
                  f"{r['paper_n'] * p:7.0f}")
    return 0
