"""Non-parametric comparison of several algorithms over several problems (pure numpy + scipy.stats).

Source: yeguas_ea_vs_pf_mocap §5.4 and its Tables 4-7 (after Demšar 2006 / García & Herrera 2008):

1. **Friedman test** (omnibus). Rank the ``k`` algorithms on each of the ``N`` problems (1 = lowest
   error, ties get the average rank), average the ranks per algorithm (``R_j``) and compute::

       χ²_F = 12 N / (k (k+1)) · [ Σ_j R_j² − k (k+1)² / 4 ]

   divided by the tie correction ``1 − Σ (t³ − t) / (N (k³ − k))`` (as
   :func:`scipy.stats.friedmanchisquare`), distributed as χ² with ``k − 1`` degrees of freedom.
2. **Holm post-hoc** against the control (best-ranked) algorithm. For every other algorithm ``i``::

       z_i = (R_i − R_1) / sqrt(k (k+1) / (6 N))

   with the unadjusted two-sided normal p-value ``p_i = 2 (1 − Φ(|z_i|))``. Sorting the ``k − 1``
   p-values ascending, hypothesis ``i`` (1-based position) is compared with ``α / (k − i)``; Holm's
   step-down rejects until the first p-value at or above its threshold and retains the rest. In
   the paper's tables (rows in ascending rank order) the threshold of the row at rank position
   ``r`` is ``α / (r − 1)``: 0.050, 0.025, 0.016, ... .

:func:`ranking_table` bundles both and :func:`format_ranking_table` renders one in the layout of the
paper's Tables 4-7 (Algorithm, Rank, p-value, Holm; the Friedman statistic on the last row).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["StatsError", "FriedmanResult", "HolmRow", "RankingTable", "rank_matrix", "average_ranks", "friedman",
           "friedman_from_ranks", "holm", "ranking_table", "format_ranking_table"]


class StatsError(ValueError):
    """Bad input to a test (names the argument, the expected and the received value)."""


@dataclass(frozen=True)
class FriedmanResult:
    """Friedman test over ``n_problems`` problems and ``len(algorithms)`` algorithms.

    Attributes
    ----------
    algorithms : tuple of str
    mean_ranks : tuple of float
        Average rank of each algorithm (1 = best), in ``algorithms`` order.
    statistic : float
        χ²_F (tie-corrected).
    pvalue : float
        ``P(χ²(k−1) ≥ statistic)``.
    df : int
        ``k − 1``.
    n_problems : int
    critical_value : float
        χ² critical value at ``alpha`` (``statistic > critical_value`` ⇔ reject at ``alpha``).
    alpha : float
    """

    algorithms: tuple
    mean_ranks: tuple
    statistic: float
    pvalue: float
    df: int
    n_problems: int
    critical_value: float
    alpha: float

    @property
    def reject(self) -> bool:
        return bool(self.statistic > self.critical_value)


@dataclass(frozen=True)
class HolmRow:
    """One row of a Holm table (the control has ``z = p = threshold = nan`` and ``reject=False``)."""

    algorithm: str
    rank: float
    z: float
    pvalue: float
    threshold: float
    reject: bool
    control: bool = False


@dataclass(frozen=True)
class RankingTable:
    """A Friedman test and the Holm rows in ascending rank order (control first)."""

    friedman: FriedmanResult
    rows: tuple

    @property
    def control(self) -> str:
        return self.rows[0].algorithm

    def to_dict(self) -> dict:
        f = self.friedman
        return {"friedman": {"statistic": f.statistic, "pvalue": f.pvalue, "df": f.df, "n_problems": f.n_problems,
                             "critical_value": f.critical_value, "alpha": f.alpha, "reject": f.reject},
                "control": self.control,
                "rows": [{"algorithm": r.algorithm, "rank": r.rank, "z": _nan_none(r.z), "pvalue": _nan_none(r.pvalue),
                          "threshold": _nan_none(r.threshold), "reject": r.reject, "control": r.control}
                         for r in self.rows]}



def _scipy_stats():
    """``scipy.stats``, imported on first use (it costs ~1 s, and every ``isa-mocap`` command imports this
    module through the bench registry)."""
    from scipy import stats

    return stats

def _nan_none(v: float):
    return None if v is None or not np.isfinite(v) else float(v)


def _matrix(errors) -> np.ndarray:
    a = np.asarray(errors, dtype=float)
    if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 2:
        raise StatsError(f"errors: expected a (problems, algorithms) matrix with >= 1 problem and >= 2 algorithms, "
                         f"received shape {a.shape}")
    if np.isnan(a).any():
        i, j = np.argwhere(np.isnan(a))[0]
        raise StatsError(f"errors: expected no NaN, received NaN at problem {i}, algorithm {j}")
    return a


def _names(algorithms, k: int) -> tuple:
    if algorithms is None:
        return tuple(f"A{j + 1}" for j in range(k))
    names = tuple(str(a) for a in algorithms)
    if len(names) != k:
        raise StatsError(f"algorithms: expected {k} names (one per column), received {len(names)}")
    if len(set(names)) != k:
        raise StatsError(f"algorithms: expected distinct names, received {names}")
    return names


def _alpha(alpha: float) -> float:
    a = float(alpha)
    if not 0.0 < a < 1.0:
        raise StatsError(f"alpha: expected a level in (0, 1), received {alpha!r}")
    return a


def rank_matrix(errors) -> np.ndarray:
    """Ranks ``(N, k)`` of the algorithms on each problem: 1 = lowest error, ties averaged
    (``+inf`` errors rank last)."""
    a = _matrix(errors)
    return np.vstack([_scipy_stats().rankdata(row) for row in a])


def average_ranks(errors) -> np.ndarray:
    """Average rank ``(k,)`` of each algorithm over the problems (rows)."""
    return rank_matrix(errors).mean(axis=0)


def friedman_from_ranks(mean_ranks: Sequence[float], n_problems: int) -> float:
    """χ²_F from average ranks (no tie correction), e.g. to check a published table."""
    R = np.asarray(mean_ranks, dtype=float)
    k = R.size
    N = int(n_problems)
    if k < 2 or N < 1:
        raise StatsError(f"mean_ranks, n_problems: expected >= 2 ranks and >= 1 problem, received {k} and {N}")
    return float(12.0 * N / (k * (k + 1)) * (np.sum(R * R) - k * (k + 1) ** 2 / 4.0))


def friedman(errors, algorithms: Sequence[str] | None = None, *, alpha: float = 0.05) -> FriedmanResult:
    """Friedman test of a ``(problems, algorithms)`` error matrix (lower is better).

    Equals :func:`scipy.stats.friedmanchisquare` (same tie correction) where that applies (k >= 3);
    also defined for ``k = 2``. A matrix where every problem ties every algorithm gives statistic 0,
    p-value 1.

    Examples
    --------
    >>> r = friedman([[1.0, 2.0, 3.0], [1.0, 3.0, 2.0]], ["a", "b", "c"])
    >>> r.mean_ranks, round(r.statistic, 6)
    ((1.0, 2.5, 2.5), 3.0)
    """
    alpha = _alpha(alpha)
    a = _matrix(errors)
    N, k = a.shape
    names = _names(algorithms, k)
    ranks = rank_matrix(a)
    R = ranks.mean(axis=0)
    ties = 0.0
    for row in ranks:
        _, t = np.unique(row, return_counts=True)
        ties += float(np.sum(t ** 3 - t))
    corr = 1.0 - ties / (N * (k ** 3 - k))
    raw = friedman_from_ranks(R, N)
    stat = 0.0 if corr <= 0 else max(0.0, raw / corr)
    df = k - 1
    p = float(_scipy_stats().chi2.sf(stat, df))
    return FriedmanResult(algorithms=names, mean_ranks=tuple(float(x) for x in R), statistic=float(stat), pvalue=p,
                          df=df, n_problems=N, critical_value=float(_scipy_stats().chi2.ppf(1.0 - alpha, df)), alpha=alpha)


def holm(mean_ranks: Sequence[float], n_problems: int, algorithms: Sequence[str] | None = None, *,
         alpha: float = 0.05) -> tuple:
    """Holm's step-down procedure against the best-ranked (control) algorithm.

    Parameters
    ----------
    mean_ranks : (k,) sequence of float
        Average ranks (1 = best).
    n_problems : int
        ``N`` (problems the ranks were averaged over).
    algorithms : sequence of str, optional
    alpha : float

    Returns
    -------
    tuple of HolmRow
        In ascending rank order (ties: input order), the control first; row at rank position ``r``
        (1-based) has ``threshold = α / (r − 1)``, ``z = (R_r − R_1) / sqrt(k (k+1) / (6 N))`` and the
        two-sided p-value; ``reject`` follows the step-down rule (see the module docstring).

    Examples
    --------
    Demšar (2006), §3.2.2: four classifiers on 14 data sets, C4.5+m+cf the control.

    >>> rows = holm([3.143, 2.000, 2.893, 1.964], 14, ["C4.5", "C4.5+m", "C4.5+cf", "C4.5+m+cf"])
    >>> [(r.algorithm, round(r.pvalue, 3), round(r.threshold, 4), r.reject) for r in rows[1:]]
    [('C4.5+m', 0.941, 0.05, False), ('C4.5+cf', 0.057, 0.025, False), ('C4.5', 0.016, 0.0167, True)]
    """
    alpha = _alpha(alpha)
    R = np.asarray(mean_ranks, dtype=float)
    if R.ndim != 1 or R.size < 2 or not np.all(np.isfinite(R)):
        raise StatsError(f"mean_ranks: expected >= 2 finite average ranks, received {np.asarray(mean_ranks).tolist()}")
    k = R.size
    N = int(n_problems)
    if N < 1:
        raise StatsError(f"n_problems: expected an integer >= 1, received {n_problems!r}")
    names = _names(algorithms, k)
    order = np.argsort(R, kind="stable")
    se = np.sqrt(k * (k + 1) / (6.0 * N))
    c = order[0]
    z = (R - R[c]) / se
    p = 2.0 * _scipy_stats().norm.sf(np.abs(z))
    # step-down over ascending p-values: the largest rank differences first
    others = [j for j in order[1:]]
    by_p = sorted(others, key=lambda j: (p[j], -R[j]))
    reject = {j: False for j in others}
    for i, j in enumerate(by_p):            # i = 0 .. k-2 ; threshold α / (k - 1 - i)
        if p[j] < alpha / (k - 1 - i):
            reject[j] = True
        else:
            break
    rows = [HolmRow(names[c], float(R[c]), float("nan"), float("nan"), float("nan"), False, True)]
    for pos, j in enumerate(others, start=2):
        rows.append(HolmRow(names[j], float(R[j]), float(z[j]), float(p[j]), alpha / (pos - 1), reject[j]))
    return tuple(rows)


def ranking_table(errors, algorithms: Sequence[str] | None = None, *, alpha: float = 0.05) -> RankingTable:
    """Friedman test and Holm rows of a ``(problems, algorithms)`` error matrix (one column of the
    paper's Tables 4-7)."""
    f = friedman(errors, algorithms, alpha=alpha)
    return RankingTable(f, holm(f.mean_ranks, f.n_problems, f.algorithms, alpha=alpha))


def _p(v: float) -> str:
    if not np.isfinite(v):
        return "-"
    return f"{v:.2E}" if v < 1e-3 else f"{v:.3f}"


def format_ranking_table(tables: Sequence[RankingTable], *, titles: Sequence[str] | None = None) -> str:
    """Markdown table with one (Algorithm, Rank, p-value) block per test side by side and the Holm
    thresholds in the last column, rejected p-values in bold, "Fried. Stat." (and its p-value) last.

    All tables must have the same number of algorithms (as the paper's blocks)."""
    tables = list(tables)
    if not tables:
        raise StatsError("tables: expected at least one RankingTable, received none")
    k = len(tables[0].rows)
    if any(len(t.rows) != k for t in tables):
        raise StatsError(f"tables: expected the same number of algorithms in every block, received "
                         f"{[len(t.rows) for t in tables]}")
    head = []
    for i, _ in enumerate(tables):
        t = titles[i] if titles else ""
        head += [f"Algorithm{(' (' + t + ')') if t else ''}", "Rank", "p-value"]
    head.append("Holm")
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    for r in range(k):
        cells = []
        thr = ""
        for t in tables:
            row = t.rows[r]
            pv = _p(row.pvalue)
            if row.reject:
                pv = f"**{pv}**"
            cells += [row.algorithm, f"{row.rank:.3f}", pv]
            if np.isfinite(row.threshold):
                thr = f"{row.threshold:.3f}"
        cells.append(thr)
        lines.append("| " + " | ".join(cells) + " |")
    cells = []
    for t in tables:
        cells += ["*Fried. Stat.*", f"{t.friedman.statistic:.3f}", f"p={_p(t.friedman.pvalue)}"]
    cells.append("")
    lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
