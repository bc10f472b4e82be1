"""Friedman / Holm (isa_mocap_ros.eval.stats) against scipy, Demšar (2006) and the EA-vs-PF paper's tables."""
import numpy as np
import pytest
from scipy import stats as st

from isa_mocap_ros.eval.stats import (StatsError, average_ranks, format_ranking_table, friedman, friedman_from_ranks,
                                      holm, rank_matrix, ranking_table)


def test_ranks_lowest_error_first_and_ties_averaged():
    R = rank_matrix([[3.0, 1.0, 2.0], [5.0, 5.0, 1.0]])
    assert R.tolist() == [[3.0, 1.0, 2.0], [2.5, 2.5, 1.0]]
    assert average_ranks([[3.0, 1.0, 2.0], [5.0, 5.0, 1.0]]).tolist() == [2.75, 1.75, 1.5]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_friedman_equals_scipy_with_and_without_ties(seed):
    rng = np.random.default_rng(seed)
    E = rng.normal(size=(9, 6)) + np.arange(6) * 0.3
    if seed == 2:
        E = np.round(E)          # many ties
    ref = st.friedmanchisquare(*E.T)
    r = friedman(E)
    assert r.statistic == pytest.approx(ref.statistic, rel=1e-12)
    assert r.pvalue == pytest.approx(ref.pvalue, rel=1e-9)
    assert r.df == 5 and r.n_problems == 9


def test_friedman_all_ties_is_zero():
    r = friedman(np.ones((4, 3)))
    assert r.statistic == 0.0 and r.pvalue == 1.0 and not r.reject


def test_demsar_2006_friedman_from_average_ranks():
    # Demšar 2006 §3.2.2: k = 4 C4.5 variants, N = 14 data sets, chi2_F = 9.28
    chi2 = friedman_from_ranks([3.143, 2.000, 2.893, 1.964], 14)
    assert chi2 == pytest.approx(9.28, abs=0.01)


def test_demsar_2006_holm_rejects_only_c45():
    rows = holm([3.143, 2.000, 2.893, 1.964], 14, ["C4.5", "C4.5+m", "C4.5+cf", "C4.5+m+cf"])
    assert rows[0].algorithm == "C4.5+m+cf" and rows[0].control
    got = {r.algorithm: r for r in rows[1:]}
    assert got["C4.5"].z == pytest.approx((3.143 - 1.964) / np.sqrt(20 / 84))
    assert got["C4.5"].pvalue == pytest.approx(0.016, abs=1e-3) and got["C4.5"].reject
    assert got["C4.5+cf"].pvalue == pytest.approx(0.057, abs=1e-3) and not got["C4.5+cf"].reject
    assert not got["C4.5+m"].reject


# The paper's Table 4, 39 DOF / 500 evaluations (k = 8 algorithms, N = 9 sequences)
TABLE4 = [("H-CMAES", 1.222, None), ("H-PSO", 2.333, 0.335), ("CMAES", 3.000, 0.123), ("H-DE", 3.555, 0.043),
          ("DE", 5.111, 7.57e-4), ("PSO", 5.888, 5.31e-5), ("APF", 7.000, 5.62e-7), ("PSAPF", 7.888, 7.76e-9)]


def test_paper_table4_pvalues_thresholds_and_friedman_statistic():
    names = [n for n, _, _ in TABLE4]
    R = [r for _, r, _ in TABLE4]
    rows = holm(R, 9, names)
    assert [r.algorithm for r in rows] == names
    for row, (_, _, p) in zip(rows[1:], TABLE4[1:]):
        assert row.pvalue == pytest.approx(p, rel=0.05)
    assert [round(r.threshold, 3) for r in rows[1:]] == [0.05, 0.025, 0.017, 0.013, 0.01, 0.008, 0.007]
    # the text: rejected for DE, PSO, APF and PSAPF (H-DE: 0.043 > 0.0125 stops the step-down)
    assert [r.algorithm for r in rows if r.reject] == ["DE", "PSO", "APF", "PSAPF"]
    assert friedman_from_ranks(R, 9) == pytest.approx(57.925, abs=0.1)


def test_ranking_table_and_format():
    rng = np.random.default_rng(5)
    E = rng.normal(size=(6, 4)) + np.array([0.0, 1.0, 2.0, 3.0])
    t = ranking_table(E, ["a", "b", "c", "d"])
    assert t.control == "a" and t.rows[0].rank == min(r.rank for r in t.rows)
    assert [r.rank for r in t.rows] == sorted(r.rank for r in t.rows)
    d = t.to_dict()
    assert d["rows"][0]["pvalue"] is None and d["friedman"]["df"] == 3
    md = format_ranking_table([t, t], titles=["x", "y"])
    assert md.count("\n") == 2 + 4 and "Fried. Stat." in md and "0.050" in md


def test_bad_input():
    with pytest.raises(StatsError, match="algorithms"):
        friedman(np.ones((3, 1)))
    with pytest.raises(StatsError, match="NaN"):
        friedman([[1.0, np.nan]])
    with pytest.raises(StatsError, match="names"):
        friedman(np.ones((3, 2)), ["a"])
    with pytest.raises(StatsError, match="alpha"):
        holm([1.0, 2.0], 3, alpha=1.5)
