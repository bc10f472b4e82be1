"""The compiled ISA generation (weights, selection, dynamic variance, mutation, diagnostics) and the
compiled SO(3) helpers of the rotation mean are bit-identical to their numpy formulations, and a
process that compiles them computes the same bits as one that loads them from numba's cache."""
import numpy as np
import pytest

from isa_mocap_ros.geometry import nearest_rotvec
from isa_mocap_ros.optim import Hierarchical, Isa, make_optimizer, minimize
from isa_mocap_ros.optim import _fast, _fast_so3
from isa_mocap_ros.optim._rotations import exp_so3, log_so3, rotation_mean
from isa_mocap_ros.optim.resampling import ess, normalise_log
from libm_probe import NUMPY_IS_LIBM


def _energies(rng, n, trial):
    E = rng.random(n) * 10.0 ** rng.uniform(-6, 3)
    if trial % 3 == 0:
        E[rng.random(n) < 0.2] = np.inf
    if trial % 7 == 0:
        E[rng.random(n) < 0.1] = np.nan
    if trial % 11 == 0:
        E[:] = np.inf
    return E


def test_annealed_weights_and_ess_are_the_numpy_formulation_bit_for_bit():
    rng = np.random.default_rng(0)
    for trial in range(400):
        n = int(rng.integers(1, 200))
        E = _energies(rng, n, trial)
        E[~np.isfinite(E)] = np.inf               # as check_energies hands them on
        beta = float(10.0 ** rng.uniform(-3, 6)) if trial % 13 else 0.0
        fin = np.isfinite(E)
        E0 = E[fin].min() if fin.any() else 0.0
        with np.errstate(invalid="ignore"):
            ref = normalise_log(np.where(fin, -beta * (E - E0), -np.inf))
        W = np.empty(n)
        e = _fast.annealed_weights(E, beta, W)
        if NUMPY_IS_LIBM:                   # numpy's exp is libm's (AVX2): the same bits
            np.testing.assert_array_equal(W, ref)
            assert e == ess(ref)
        else:                               # numpy's AVX-512 exp of its own: to rounding
            np.testing.assert_allclose(W, ref, rtol=1e-12, atol=1e-300)
            assert e == pytest.approx(ess(ref), rel=1e-12)


def test_generation_stats_are_numpys_mean_and_std_bit_for_bit():
    rng = np.random.default_rng(1)
    for trial in range(300):
        n, d = int(rng.integers(1, 60)), int(rng.integers(1, 45)) if trial % 4 else 1
        E = _energies(rng, n, trial)
        E[~np.isfinite(E)] = np.inf
        P = rng.standard_normal((n, d)) * 10.0 ** rng.uniform(-4, 2, d) + rng.uniform(-5, 5, d)
        if trial % 3 == 1:
            P = np.asfortranarray(P)          # as a hierarchical run hands its inner optimizer
        fin = E[np.isfinite(E)]
        mean_energy, spread = _fast.generation_stats(E, P)
        assert (np.isnan(mean_energy) and fin.size == 0) or mean_energy == fin.mean()
        assert spread == np.mean(np.std(P, axis=0))
    assert np.isnan(_fast.generation_stats(np.ones(0), np.zeros((0, 3)))[1])


def _run(kernel, fused, *, rotations, seed, d=7, evals=900, energies=None, variance="population"):
    d = 1 if seed == 2 and not rotations else d
    opt = Isa(np.full(d, 0.2), 0.4, n_particles=30, kernel=kernel, schedule="adaptive", target_ess=0.3,
              c=0.5, variance=variance, rng=np.random.default_rng(seed), bounds=(np.full(d, -1.0), np.full(d, 1.5)),
              rotation_blocks=((1, 2, 3),) if rotations else ())
    opt._fused = fused

    def f(X):
        E = np.sum((X - 0.3) ** 2, axis=1) + 0.05 * np.sin(20 * X).sum(axis=1)
        if energies == "some-nonfinite":
            E[::7] = np.nan
            E[3::11] = np.inf
        return E
    return minimize(opt, f, max_evals=evals)


@pytest.mark.parametrize("kernel", ["s1", "s2", "s3"])
@pytest.mark.parametrize("rotations", [False, True])
@pytest.mark.parametrize("energies", ["finite", "some-nonfinite"])
@pytest.mark.parametrize("variance", ["population", "selected"])
def test_fused_selection_and_mutation_give_the_numpy_run_bit_for_bit(kernel, rotations, energies, variance):
    for seed in range(3):
        a = _run(kernel, True, rotations=rotations, seed=seed, energies=energies, variance=variance)
        b = _run(kernel, False, rotations=rotations, seed=seed, energies=energies, variance=variance)
        np.testing.assert_array_equal(a.x, b.x)
        np.testing.assert_array_equal(a.population, b.population)
        np.testing.assert_array_equal(a.weights, b.weights)
        assert repr(a.history) == repr(b.history)        # repr: nan fields compare unequal


@pytest.mark.parametrize("variance", ["population", "selected"])
def test_fused_h_isa_gives_the_numpy_run_bit_for_bit(variance):
    """Hierarchical hands its inner ISA F-ordered columns (as X[:, index_array] gave)."""
    res = {}
    for fused in (True, False):
        def factory(x, s, **kw):
            opt = Isa(x, s, n_particles=30, kernel="s2", schedule="adaptive", target_ess=0.3,
                      variance=variance, **kw)
            opt._fused = fused
            inner.append(opt)
            return opt
        inner = []
        opt = Hierarchical(np.full(9, 0.1), 0.3, rng=np.random.default_rng(6), optimizer=factory,
                           partitions=[[0, 1, 2, 3, 4, 5], [6, 8, 7]], rotation_blocks=((3, 4, 5),))
        res[fused] = (minimize(opt, lambda X: np.sum((X - 0.5) ** 2, axis=1), max_evals=900),
                      [repr(o.history) for o in inner])
    (a, ha), (b, hb) = res[True], res[False]
    np.testing.assert_array_equal(a.x, b.x)
    assert repr(a.history) == repr(b.history) and ha == hb


@pytest.mark.parametrize("fused", [True, False])
@pytest.mark.parametrize("variance", ["population", "selected"])
def test_c_on_the_deviation_is_its_square_on_the_covariance_bit_for_bit(fused, variance):
    """``c_scale="deviation"`` (the book's Fig. 13.13 and Ackley tables) is (13.16) with ``c^2``."""
    runs = []
    for c, c_scale in ((0.7, "deviation"), (0.7 * 0.7, "covariance")):
        opt = Isa(np.full(3, 0.2), 0.4, n_particles=20, kernel="s2", schedule="polynomial", b=0.9, c=c,
                  c_scale=c_scale, variance=variance, rng=np.random.default_rng(4),
                  bounds=(np.full(3, -1.0), np.full(3, 1.5)))
        opt._fused = fused
        runs.append(minimize(opt, lambda X: np.sum((X - 0.3) ** 2, axis=1), max_evals=400))
    (a, b), other = runs, Isa(np.zeros(3), 0.4, c=0.7, rng=np.random.default_rng(4))
    np.testing.assert_array_equal(a.population, b.population)
    assert repr(a.history) == repr(b.history)
    assert other.c_scale == "covariance" and other.c_cov == 0.7          # the default: (13.16) as printed


def _assert_same(a, b):
    """Bit equality where numpy's 3x3 ``@`` accumulates as _fast_so3 does (OpenBLAS's Haswell dgemm)
    and numpy's sin/cos/arccos are libm's (``libm_probe``: AVX2 machines); with another BLAS kernel
    or numpy's AVX-512 ufuncs only agreement to rounding can be asked for."""
    if _BLAS_LIKE_FMA and NUMPY_IS_LIBM:
        np.testing.assert_array_equal(a, b)
    else:                                           # other BLAS kernel, or AVX-512 numpy ufuncs
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def _numpy_matmul_accumulates_like_fma():
    rng = np.random.default_rng(0)
    C = np.empty((3, 3))
    for _ in range(200):
        A, B = rng.standard_normal((3, 3)), rng.standard_normal((3, 3))
        _fast_so3._matmul(A, B, C)
        if not np.array_equal(A @ B, C):
            return False
    return True


_BLAS_LIKE_FMA = _numpy_matmul_accumulates_like_fma()


def test_compiled_exp_and_log_are_the_numpy_reference_bit_for_bit():
    rng = np.random.default_rng(2)
    axes = rng.normal(size=(3000, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([[0.0, 1e-12, 1e-7, 1e-5, 1e-4, 2e-4], rng.uniform(0, np.pi, 2980),
                             np.pi - np.array([0.0, 1e-7, 1e-5, 1e-4, 9e-4, 1.1e-3, 2e-3, 1e-2]),
                             [3.0, 6.0, 10.0, 1e-3, 5e-5, 1e-9]])
    r = axes * angles[:, None]
    R = _fast_so3.exp_many(r)
    _assert_same(R, exp_so3(r))
    for mean in (r[0], r[100], r[2990]):
        _assert_same(_fast_so3.relative_logs(mean, R), log_so3(exp_so3(mean).T @ R))
    for a, b in zip(r[::97], r[5::97]):
        _assert_same(_fast_so3.compose(a, b), log_so3(exp_so3(a) @ exp_so3(b)))


def _numpy_rotation_mean(rotvecs, weights, n_iter=20, tol=1e-12):
    """rotation_mean as it was written with the numpy helpers (the reference)."""
    r = np.asarray(rotvecs, dtype=float)
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    Ri = exp_so3(r)
    mean = r[int(np.argmax(w))].copy()
    for _ in range(n_iter):
        M = exp_so3(mean)
        step = w @ log_so3(M.T @ Ri)
        mean = log_so3(M @ exp_so3(step))
        if step @ step < tol:
            break
    return nearest_rotvec(mean, r[int(np.argmax(w))])


def test_rotation_mean_keeps_the_particles_side_of_a_half_turn():
    """Particles around a yaw of 180° (|r| near pi, on both sides): the mean stays on the side of
    the particle of largest weight instead of jumping to the canonical |r| <= pi representative."""
    r = np.array([[0.0, 0.0, 3.10], [0.0, 0.0, 3.14], [0.0, 0.0, 3.20], [0.01, 0.0, 3.16]])
    m = rotation_mean(r, np.ones(4))
    np.testing.assert_allclose(m, [0.0025, 0.0, 3.15], atol=1e-3)
    m = rotation_mean(-r, np.ones(4))
    np.testing.assert_allclose(m, [-0.0025, 0.0, -3.15], atol=1e-3)
    np.testing.assert_allclose(rotation_mean(np.array([[0.0, 0.0, 0.4]]), np.ones(1)), [0.0, 0.0, 0.4], atol=1e-12)


def test_rotation_mean_is_the_numpy_reference_bit_for_bit():
    rng = np.random.default_rng(3)
    for trial in range(300):
        n = int(rng.integers(1, 40))
        center = rng.normal(size=3) * rng.uniform(0, 3)
        r = center + rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-4, 0)
        w = rng.random(n) ** 3
        _assert_same(rotation_mean(r, w), _numpy_rotation_mean(r, w))


_HASH_SCRIPT = """
import hashlib, numpy as np
from isa_mocap_ros.optim import make_optimizer, minimize
h = hashlib.sha1()
for name in ("h-isa", "isa"):
    kw = {"partitions": [[0, 1, 2, 3, 4, 5], [6, 7, 8]]} if name == "h-isa" else {}
    opt = make_optimizer(name, np.full(9, 0.2), 0.3, rng=np.random.default_rng(5), n_particles=30, kernel="s2",
                         schedule="adaptive", target_ess=0.3, rotation_blocks=((3, 4, 5),), **kw)
    r = minimize(opt, lambda X: np.sum((X - 0.5) ** 2, axis=1) + 0.1 * np.sin(9 * X).sum(axis=1), max_evals=1500)
    h.update(r.x.tobytes()); h.update(r.population.tobytes())
    h.update(np.array([(g.mean_energy, g.spread, g.beta, g.ess) for g in r.history]).tobytes())
print(h.hexdigest())
"""


def test_fresh_and_cached_compiled_optimizer_agree_bit_for_bit(tmp_path):
    """A process that compiles the optimizer's numba functions and one that loads them from the cache
    must compute the same bits (no fastmath in optim)."""
    from numba_cache import stdout_compiled_then_cached

    out = stdout_compiled_then_cached(_HASH_SCRIPT, tmp_path / "numba", timeout=600)
    assert any((tmp_path / "numba").rglob("*_fast*.nbc"))      # the second run loaded what the first compiled
    assert out[0] == out[1]
    assert len(out[0].strip()) == 40


def test_h_isa_runs_are_reproducible_for_a_seed():
    kw = dict(partitions=[[0, 1, 2], [3, 4, 5]], n_particles=30, kernel="s2", schedule="adaptive",
              rotation_blocks=((3, 4, 5),))
    res = [minimize(make_optimizer("h-isa", np.zeros(6), 0.3, rng=np.random.default_rng(8), **kw),
                    lambda X: np.sum((X - 0.2) ** 2, axis=1), max_evals=600) for _ in range(2)]
    np.testing.assert_array_equal(res[0].x, res[1].x)
    assert repr(res[0].history) == repr(res[1].history)


@pytest.mark.parametrize("name, builds", [("isa", 3), ("de", 5), ("cmaes", 3)])
def test_hierarchical_reuses_its_probes_only_when_building_them_drew_no_random_numbers(name, builds):
    """bind() builds every partition's optimizer to validate the shares; they are reused unless
    building them consumed random numbers (DE), and the run equals one that rebuilds them."""
    def f(X):
        return np.sum((X - 0.4) ** 2, axis=1)

    built = []

    def factory(x, s, **kw):
        built.append(name)
        return make_optimizer(name, x, s, **kw)
    kw = dict(optimizer=factory, partitions=[[0, 1], [2, 3, 4], [5]], rotation_blocks=((2, 3, 4),))
    reused = minimize(Hierarchical(np.zeros(6), 0.3, rng=np.random.default_rng(9), **kw), f, max_evals=900)
    assert len(built) == builds
    rebuilt = Hierarchical(np.zeros(6), 0.3, rng=np.random.default_rng(9), **kw).bind(f, max_evals=900)
    rebuilt._probes = None                   # every later partition built when it starts
    for _ in rebuilt:
        pass
    np.testing.assert_array_equal(reused.x, rebuilt.result().x)
    assert repr(reused.history) == repr(rebuilt.result().history)
