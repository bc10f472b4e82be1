"""Hierarchical driver: partitions, one partition at a time, budget split."""
import numpy as np
import pytest

from isa_mocap_ros.optim import (Hierarchical, OptimError, make_optimizer, minimize,
                                 split_budget)


def sphere(X):
    return np.sum((X - 1.0) ** 2, axis=1)


PARTS = [np.array([0, 1, 2]), np.array([3, 4]), np.array([6])]   # coordinate 5 not covered


@pytest.mark.parametrize("inner", ["isa", "apf", "cmaes", "de", "pso"])
def test_only_one_partition_moves_at_a_time(inner):
    x0 = np.zeros(7)
    batches = []

    def en(X):
        batches.append(X.copy())
        return sphere(X)

    opt = Hierarchical(x0, 0.5, partitions=PARTS, optimizer=inner, rng=np.random.default_rng(0))
    res = minimize(opt, en, max_evals=1200)
    assert res.n_evals == sum(len(b) for b in batches) <= 1200
    order = []
    for X in batches:
        moving = np.flatnonzero(np.ptp(X, axis=0) > 0)
        if moving.size == 0:        # a collapsed population (possible with DE in 1-D)
            continue
        owner = [k for k, p in enumerate(PARTS) if set(moving) <= set(p.tolist())]
        assert len(owner) == 1, f"batch moved coordinates {moving} across partitions"
        if not order or order[-1] != owner[0]:
            order.append(owner[0])
    assert order == [0, 1, 2]                       # in the given order, each once
    assert np.all(np.concatenate(batches)[:, 5] == 0.0) and res.x[5] == 0.0   # uncovered: fixed
    assert sphere(res.x[None])[0] < sphere(x0[None])[0]


def test_budget_split_is_proportional_with_remainder_to_the_first():
    assert split_budget(1000, [3, 2, 1]) == [501, 333, 166]
    assert sum(split_budget(997, [6, 3, 7, 7, 8, 8])) == 997
    opt = Hierarchical(np.zeros(7), 0.5, partitions=PARTS, optimizer="pso",
                       rng=np.random.default_rng(0))
    minimize(opt, sphere, max_evals=1000)
    assert [n for _, n in opt.partition_log] + [opt._inner_used] == [501, 333, 166]


def test_whole_generations_split():
    # 866 over the 39-DOF partitions (6, 6, 6, 9, 6, 6), generations of 30: floors 133 -> 120, 199 -> 180,
    # then 746 - 720... handed out a generation at a time in order while one fits
    assert split_budget(866, [6, 6, 6, 9, 6, 6], [30] * 6) == [150, 150, 120, 180, 120, 120]
    # a partition whose proportional share is below a generation gets one first
    assert split_budget(100, [8, 1], [20, 20]) == [80, 20]
    assert split_budget(100, [8, 1], [30, 30]) == [60, 30]           # 10 stay unspent
    for B in range(60, 2000, 37):
        shares = split_budget(B, [6, 6, 6, 9, 6, 6], [30] * 6)
        assert all(s % 30 == 0 for s in shares) and B - 30 < sum(shares) <= B


@pytest.mark.parametrize("inner", ["isa", "cmaes", "pso"])
def test_whole_generations_run_no_truncated_generation(inner):
    """A run with ``whole_generations`` spends whole generations of every partition (what remains of the
    budget, less than one generation, stays unspent); the same draws as far as the shares agree."""
    opt = Hierarchical(np.zeros(7), 0.5, partitions=PARTS, optimizer=inner, whole_generations=True,
                       rng=np.random.default_rng(0))
    res = minimize(opt, sphere, max_evals=1000)
    gens = [make_optimizer(inner, np.zeros(len(p)), 0.5, rng=np.random.default_rng(0)).generation_size
            for p in PARTS]
    spent = [n for _, n in opt.partition_log] + [opt._inner_used]
    assert spent == split_budget(1000, [3, 2, 1], gens)
    assert all(n % g == 0 for n, g in zip(spent, gens)) and res.n_evals == sum(spent) > 1000 - max(gens)
    steps = np.diff([0] + [h.n_evals for h in res.history])          # every generation evaluated whole
    assert set(steps.tolist()) <= set(gens)


@pytest.mark.parametrize("parts,msg", [
    ([[0, 1], [1, 2]], r"index 1 is in partitions\[0\] and partitions\[1\]"),
    ([[0, 9]], r"partitions\[0\]: indices must lie in \[0, 4\)"),
    ([[0], []], r"partitions\[1\]: expected a non-empty"),
    ([[0, 0]], r"partitions\[0\]: repeated index"),
    ([], "partitions: expected a non-empty list"),
    ([[0.5, 1]], r"partitions\[0\]: expected integer indices"),
])
def test_inconsistent_partitions_raise(parts, msg):
    with pytest.raises(OptimError, match=msg):
        Hierarchical(np.zeros(4), 0.5, partitions=parts, rng=np.random.default_rng(0))


def test_rotation_block_split_across_partitions_raises():
    with pytest.raises(OptimError, match="rotation_blocks: triple .* split across partitions"):
        Hierarchical(np.zeros(6), 0.5, partitions=[[0, 1], [2, 3, 4, 5]],
                     rotation_blocks=[(1, 2, 3)], rng=np.random.default_rng(0))


def test_share_smaller_than_inner_generation_raises():
    with pytest.raises(OptimError, match=r"partition 2 .* fewer than one generation"):
        minimize(make_optimizer("h-isa", np.zeros(7), 0.5, rng=np.random.default_rng(0),
                                partitions=PARTS), sphere, max_evals=200)


def test_hierarchical_needs_partitions_and_a_flat_inner_name():
    with pytest.raises(OptimError, match="partitions: optimizer 'h-de' needs partitions"):
        make_optimizer("h-de", np.zeros(3), 0.5, rng=np.random.default_rng(0))
    with pytest.raises(OptimError, match="optimizer: expected a flat optimizer name"):
        Hierarchical(np.zeros(3), 0.5, partitions=[[0]], optimizer="h-isa",
                     rng=np.random.default_rng(0))


def test_unbound_hierarchical_needs_shares_and_uses_them():
    opt = Hierarchical(np.zeros(7), 0.5, partitions=PARTS, optimizer="pso",
                       rng=np.random.default_rng(0))
    with pytest.raises(OptimError, match="evals_per_partition: no budget to split"):
        opt.ask()
    opt = Hierarchical(np.zeros(7), 0.5, partitions=PARTS, optimizer="pso",
                       evals_per_partition=[30, 20, 20], rng=np.random.default_rng(0))
    while not opt.stop():
        X = opt.ask()
        opt.tell(X, sphere(X))
    assert opt.n_evals == 70 and [n for _, n in opt.partition_log] + [opt._inner_used] == [30, 20, 20]


def test_inner_optimizer_names():
    from isa_mocap_ros.optim import OPTIMIZERS, inner_optimizer

    assert inner_optimizer("h-isa") == "isa" and inner_optimizer("psapf") == "apf"
    assert inner_optimizer("h-pso") == "pso" and inner_optimizer("cmaes") is None
    assert all(inner_optimizer(k) in OPTIMIZERS for k in OPTIMIZERS if inner_optimizer(k) is not None)
