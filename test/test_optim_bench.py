"""`isa-mocap bench ackley --quick --json` runs and reports the paper's rows."""
import argparse
import json

import pytest

from isa_mocap_ros.bench import ackley as bench_ackley


def test_bench_ackley_quick_json(capsys):
    p = argparse.ArgumentParser()
    bench_ackley.add_arguments(p)
    assert bench_ackley.run(p.parse_args(["--quick", "--json"])) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    keys = {"method", "kernel", "variance", "c_scale", "n", "b", "c", "noise", "mean_steps", "success_rate",
            "mean_evals", "paper_mean_steps"}
    searched_keys = keys | {"paper_n", "paper_b", "paper_c", "selection_mean_steps", "selection_runs", "held_out_runs"}
    book = [r for r in rows if r["kernel"] is not None and "selection_mean_steps" not in r]
    searched = [r for r in rows if "selection_mean_steps" in r]
    assert len(book) == 48 and all(set(r) == keys for r in book)
    assert [(r["variance"], r["c_scale"]) for r in book[::12]] == list(bench_ackley.READINGS)
    assert bench_ackley.READINGS[0] == ("population", "deviation")
    assert {r["paper_mean_steps"] for r in book} >= {14.34, 15.14, 14.58, 22.4, 20.3, 21.54}
    assert {r["method"] for r in rows if r["kernel"] is None} == {"pycma", "CmaEs (ours)"}
    # noiseless n = 50 rows: every quick run succeeds, in a plausible number of steps
    for r in book[:3] + book[12:15] + book[24:27] + book[36:39]:
        assert r["success_rate"] == 1.0 and 5 < r["mean_steps"] < 40
        assert r["mean_evals"] == pytest.approx(r["n"] * (r["mean_steps"] + 1))
    # searched rows: both tables for the noiseless kernels of each reading, b, c and n from the grids
    assert all(set(r) == searched_keys for r in searched)
    assert {(r["variance"], r["c_scale"]) for r in searched} == {("population", "deviation")}   # the first only
    clean = {r["method"] for r in searched if r["noise"] == 0.0}
    assert clean == {f"ISA_S{k} (Table 13.{t}, searched)" for k in (1, 2, 3) for t in (1, 2)}
    for r in searched:
        assert (r["b"], r["c"]) in {(0.99, 0.5), (0.99, 0.8), (0.993, 0.5), (0.993, 0.8), (r["paper_b"], r["paper_c"])}
        assert r["n"] in {20, 30, 50, r["paper_n"]}
        assert r["selection_runs"] == r["held_out_runs"] == 5 and 0 < r["selection_mean_steps"] < 999


def test_the_searches_find_what_evaluating_every_cell_finds():
    """Branch and bound cuts runs that can no longer win; the chosen cell is the exhaustive one."""
    grid_b, grid_c, seeds = (0.9, 0.99, 0.995), (0.3, 0.8), (0, 1)
    got = bench_ackley.search_bc("s2", False, 20, 4, seeds, grid_b=grid_b, grid_c=grid_c)
    full = {(b, c): bench_ackley.run_isa("s2", 20, b, c, False, 4, seeds=seeds) for b in grid_b for c in grid_c}
    ok = {k: v["mean_steps"] for k, v in full.items() if v["success_rate"] == 1.0}
    best = min(ok, key=ok.get)                                   # first of equals, as the search keeps
    assert (got["b"], got["c"]) == best and got["selection_mean_steps"] == ok[best]
    assert got["cells"] == len(full)
    grid_n = (6, 10, 16, 24, 40)
    got = bench_ackley.scan_n("s1", False, 0.993, 0.8, 4, seeds, grid_n=grid_n)
    full = {n: bench_ackley.run_isa("s1", n, 0.993, 0.8, False, 4, seeds=seeds) for n in grid_n}
    ok = {n: n * v["mean_steps"] for n, v in full.items() if v["success_rate"] == 1.0}
    best = min(ok, key=ok.get)
    assert got["n"] == best and got["selection_mean_steps"] == full[best]["mean_steps"]


def test_the_printed_dynamic_variance_keeps_a_small_population_searching():
    """(13.16) over the generation's particles (as printed) vs over the selected ones: with 10
    particles the latter collapses onto a local minimum in a few steps (measured 42 % success over
    100 runs vs 93 %; the book reports 100 % for n >= 10)."""
    kw = dict(seed=3, c_scale="covariance")
    pop = bench_ackley.run_isa("s1", 10, 0.993, 0.8, False, 20, variance="population", **kw)
    sel = bench_ackley.run_isa("s1", 10, 0.993, 0.8, False, 20, variance="selected", **kw)
    assert pop["success_rate"] >= 0.8 and sel["success_rate"] <= 0.7


def test_searched_rows_are_the_same_with_worker_processes():
    kw = dict(n_seeds=1, grid_b=(0.99,), grid_c=(0.5,), grid_n=(20, 30))
    assert bench_ackley.searched_rows(3, 0, jobs=2, **kw) == bench_ackley.searched_rows(3, 0, jobs=1, **kw)


def test_one_reading_asked_for_is_the_only_one_run(capsys):
    p = argparse.ArgumentParser()
    bench_ackley.add_arguments(p)
    args = p.parse_args(["--quick", "--json", "--no-search", "--variance", "selected", "--c-scale", "deviation"])
    assert bench_ackley.run(args) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert {(r["variance"], r["c_scale"]) for r in rows if r["kernel"] is not None} == {("selected", "deviation")}


def test_the_book_s_noiseless_rows_are_met_with_its_c_on_the_deviation():
    """Issue #4's target on the benchmark's reading (population particles, the book's c scaling the
    standard deviation): every noiseless row of Tables 13.1-13.2 at the book's b, c, n reaches delta
    in all 50 runs (the paper's protocol, seed 0), in mean steps within 25 % of the book's."""
    for kernel, noise, n, b, c, paper in bench_ackley.TABLE_13_1 + bench_ackley.TABLE_13_2:
        if noise:
            continue
        r = bench_ackley.run_isa(kernel, n, b, c, noise, 50, seed=0)
        assert r["success_rate"] == 1.0, (kernel, n)
        assert abs(r["mean_steps"] / paper - 1) <= 0.25, (kernel, n, r["mean_steps"], paper)
