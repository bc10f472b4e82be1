"""The compiled h-isa search (optim/compiled_search.py) gives the optimizer protocol's numbers, bit for bit."""
import dataclasses

import numpy as np
import pytest

from isa_mocap_ros.energy.silhouette import SilhouetteEnergy
from isa_mocap_ros.optim import make_optimizer, minimize
from isa_mocap_ros.optim._rotations import rotation_mean as rotation_mean_py
from isa_mocap_ros.tracking import Tracker, TrackerConfig
from isa_mocap_ros.optim import compiled_search

from walk_scene import walk_scene


@pytest.fixture(scope="module")
def scene():
    return walk_scene(width=320, height=240, frames=6, duration_s=0.5, seed=1)


def _hier(model, x, seed, **params):
    parts = [np.asarray(model.partitions[k]) for k in ("root", "torso", "left_arm", "right_arm", "left_leg",
                                                        "right_leg")]
    spread = np.full(model.dof, 0.05)
    spread[:3] = 0.015
    lo, hi = np.maximum(x - 0.5, model.lower), np.minimum(x + 0.5, model.upper)
    base = {"n_particles": 30, "kernel": "s2", "schedule": "adaptive", "target_ess": 0.3, "c": 0.5,
            "variance": "selected"}
    base.update(params)
    return make_optimizer("h-isa", np.clip(x, lo, hi), spread, rng=np.random.default_rng([seed, 9]),
                          bounds=(lo, hi), rotation_blocks=model.rotation_blocks, partitions=parts, **base)


class _Restrictable:
    """The tracker's `_TotalEnergy` without the prior: the energy and its restriction per partition."""

    def __init__(self, energy):
        self.energy = energy

    def __call__(self, X):
        return self.energy(X)

    def restrict(self, x, coords):
        return self.energy.restrict(x, coords)


@pytest.mark.parametrize("params, budget", [
    ({}, 1241),                                                   # the tracker's: truncated last generations
    ({"kernel": "s1", "variance": "population"}, 900),
    ({"kernel": "s3", "n_particles": 20, "target_ess": 0.5, "c": 0.8, "rho": 1e-3}, 1000),
    ({"kernel": "s1", "variance": "population", "c": 0.7, "c_scale": "deviation"}, 900),
])
def test_compiled_hisa_equals_the_protocol(scene, params, budget):
    model, cams, walk, masks = scene
    energy = SilhouetteEnergy(model, cams, masks[2], n_model_points=640, n_mask_points=384,
                              rng=np.random.default_rng(3))
    x = walk[1] + 0.02
    ref_opt = _hier(model, x, 5, **params)
    ref = minimize(ref_opt, _Restrictable(energy), max_evals=budget)
    n_ref = energy.n_evals
    opt = _hier(model, x, 5, **params)
    assert compiled_search.supported(opt, energy, False)
    got = compiled_search.search(opt, energy, budget)           # the entry point the tracker calls
    assert energy.n_evals == 2 * n_ref
    for name in ("x", "best_x", "population"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    for name in ("energy", "best_energy", "n_evals", "n_iter", "reason", "n_nonfinite"):
        assert getattr(got, name) == getattr(ref, name), name
    np.testing.assert_array_equal([dataclasses.astuple(h) for h in got.history],      # nan == nan here
                                  [dataclasses.astuple(h) for h in ref.history])
    assert got.weights is None and ref.weights is None
    assert opt.rng.bit_generator.state == ref_opt.rng.bit_generator.state     # the same draws, in order


class _WithKeypoints(_Restrictable):
    """The tracker's objective with the keypoint term: ``energy(X) + w * keypoints(X)`` (tracking/objective.py)."""

    def __init__(self, energy, term, weight):
        super().__init__(energy)
        self.term, self.weight = term, weight

    def __call__(self, X):
        return self.energy(X) + self.weight * self.term(X)

    def restrict(self, x, coords):
        data = self.energy.restrict(x, coords)
        return lambda X: data(X) + self.weight * self.term(X)


def _noisy_keypoints(model, cams, x, seed):
    """The model's joints at ``x`` projected, 3 px of noise, one view's left and right exchanged."""
    from test_energy_keypoints import true_keypoints
    from isa_mocap_ros.vision.landmarks import LANDMARK_NAMES

    rng = np.random.default_rng(seed)
    kp = [(uv + rng.normal(0, 3.0, uv.shape), c * rng.uniform(0.6, 1.0, c.shape))
          for uv, c in true_keypoints(model, cams, x)]
    swap = [LANDMARK_NAMES.index(n.replace("left", "R").replace("right", "left").replace("R", "right"))
            if ("left" in n or "right" in n) else i for i, n in enumerate(LANDMARK_NAMES)]
    kp[1] = (kp[1][0][swap], kp[1][1][swap])
    return kp


@pytest.mark.parametrize("params, budget, weight", [({}, 1241, 1.0), ({"kernel": "s1", "variance": "population"}, 900, 0.3)])
def test_compiled_hisa_with_keypoints_equals_the_protocol(scene, params, budget, weight):
    # the keypoint term inside the compiled search: the protocol on `silhouette + w * keypoints`, bit for bit
    from isa_mocap_ros.energy import KeypointEnergy

    model, cams, walk, masks = scene
    energy = SilhouetteEnergy(model, cams, masks[2], rng=np.random.default_rng(3))
    term = KeypointEnergy(model, cams, _noisy_keypoints(model, cams, walk[2], 7))
    x = walk[1] + 0.02
    ref_opt = _hier(model, x, 5, **params)
    ref = minimize(ref_opt, _WithKeypoints(energy, term, weight), max_evals=budget)
    n_ref = term.n_evals
    opt = _hier(model, x, 5, **params)
    got = compiled_search.search(opt, energy, budget, keypoints=(term, weight))
    assert term.n_evals == 2 * n_ref
    for name in ("x", "best_x", "population"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    for name in ("energy", "best_energy", "n_evals", "n_iter"):
        assert getattr(got, name) == getattr(ref, name), name
    np.testing.assert_array_equal([dataclasses.astuple(h) for h in got.history],
                                  [dataclasses.astuple(h) for h in ref.history])
    assert opt.rng.bit_generator.state == ref_opt.rng.bit_generator.state
    # and the term counts: without it the search ends elsewhere
    plain = compiled_search.search(_hier(model, x, 5, **params), energy, budget)
    assert not np.array_equal(plain.x, got.x)


def test_tracker_with_keypoints_with_and_without_the_compiled_search(scene):
    # every frame with keypoints (automatic initialization, its candidates' paused runs, tracked frames)
    model, cams, walk, masks = scene
    out = []
    for compiled in (True, False):
        tr = Tracker(model, cams, TrackerConfig.from_flat(seed=4, keypoint_weight=1.0))
        tr.use_compiled_search = compiled
        out.append([tr.step(masks[k], k, keypoints=_noisy_keypoints(model, cams, walk[k], k)) for k in range(4)])
    assert any(n.startswith("keypoints:") for n in out[0][1].notes)
    for a, b in zip(*out):
        np.testing.assert_array_equal(a.x, b.x)
        assert (a.energy, a.spread, a.n_evals, a.notes) == (b.energy, b.spread, b.n_evals, b.notes)


@pytest.mark.parametrize("init", ["given", "automatic"])
def test_tracker_with_and_without_the_compiled_search(scene, init):
    # automatic: the first frame's candidate runs pause after their first partition (init_keep)
    model, cams, walk, masks = scene
    out = []
    for compiled in (True, False):
        tr = Tracker(model, cams, TrackerConfig.from_flat(seed=4))
        tr.use_compiled_search = compiled
        first = []
        if init == "given":
            tr.initialize(pose=walk[0])
        else:
            first = [tr.step(masks[0], 0)]
            assert first[0].initialized and any("2 searched to the end" in n for n in first[0].notes)
        out.append(first + [tr.step(masks[k], k) for k in range(1, len(masks))])
    for a, b in zip(*out):
        np.testing.assert_array_equal(a.x, b.x)
        assert (a.energy, a.spread, a.n_evals, a.notes) == (b.energy, b.spread, b.n_evals, b.notes)


def test_compiled_rotation_mean_equals_numpy():
    rng = np.random.default_rng(0)
    for k in range(300):
        n = int(rng.integers(2, 40))
        centre = rng.standard_normal(3)
        centre *= (np.pi - 0.05 * rng.random()) / np.linalg.norm(centre) if k % 3 == 0 else 1.0  # near a half turn
        r = np.ascontiguousarray(centre + 0.1 * rng.standard_normal((n, 3)))
        w = rng.random(n)
        w /= w.sum()
        np.testing.assert_array_equal(compiled_search.rotation_mean(r, w, 20, 1e-12), rotation_mean_py(r, w))


def test_what_the_compiled_search_does_not_cover_runs_through_the_protocol(scene):
    model, cams, walk, masks = scene
    energy = SilhouetteEnergy(model, cams, masks[2], rng=np.random.default_rng(3))
    x = walk[1]
    assert compiled_search.supported(_hier(model, x, 0), energy, False)
    assert not compiled_search.supported(_hier(model, x, 0), energy, True)                     # prior on
    assert not compiled_search.supported(_hier(model, x, 0, schedule="polynomial"), energy, False)
    assert not compiled_search.supported(_hier(model, x, 0, resampling="systematic"), energy, False)
    exact = SilhouetteEnergy(model, cams, masks[2], method="exact")
    assert not compiled_search.supported(_hier(model, x, 0), exact, False)
    flat = make_optimizer("isa", x, 0.05, rng=np.random.default_rng(0))
    assert not compiled_search.supported(flat, energy, False)
    # the entry point answers None for each of these: the caller runs the protocol
    assert compiled_search.search(_hier(model, x, 0), energy, 900, extra_terms=True) is None        # the prior
    assert compiled_search.search(_hier(model, x, 0, schedule="polynomial"), energy, 900) is None
    assert compiled_search.search(_hier(model, x, 0), exact, 900) is None
    seeded = make_optimizer("isa", x, 0.05, rng=np.random.default_rng(0), initial_population=np.tile(x, (100, 1)))
    assert compiled_search.search(seeded, energy, 900) is None
    assert compiled_search.search(flat, energy, 900, paused=True) is None
    assert isinstance(compiled_search.search(_hier(model, x, 0), energy, 900, paused=True), compiled_search.HisaRun)


def test_cached_code_depends_on_the_kernels_it_calls():
    # numba keys a cached function on its own file; the compiled search calls the energy kernels and the
    # optimizer helpers of other files, so its cache stamp carries their hashes too (a git pull that
    # changes a kernel recompiles it instead of loading old machine code)
    import hashlib
    import os

    from isa_mocap_ros import numba_cache
    from isa_mocap_ros.body import kinematics
    from isa_mocap_ros.energy import keypoint_kernel, raster_kernel, silhouette_kernel
    from isa_mocap_ros.optim import _fast, _fast_so3

    deps = (silhouette_kernel, raster_kernel, keypoint_kernel, kinematics, _fast, _fast_so3)
    assert set(compiled_search.DEPENDENCIES) == set(deps)
    files = numba_cache.dependencies(compiled_search.__file__)      # these, then what they depend on in turn
    assert {os.path.abspath(m.__file__) for m in deps} <= set(files)
    for fn in (compiled_search._partition, compiled_search.rotation_mean):
        locator = fn._cache._impl.locator
        assert type(locator).__name__ == "_DependentLocator"
        h = hashlib.sha256()
        for f in files:
            h.update(open(f, "rb").read())
        assert locator.get_source_stamp()[1] == h.hexdigest()
        # and the cache files' names carry the dependencies' module names: an index pickled before one was
        # renamed names a module that is gone, and must be missed rather than loaded (ModuleNotFoundError)
        names = numba_cache.dependency_names(compiled_search.__file__)
        assert {m.__name__ for m in deps} <= set(names) and len(names) == len(files)
        tag = hashlib.sha256(" ".join(names).encode()).hexdigest()[:8]
        assert locator.get_disambiguator() == f"{locator._inner.get_disambiguator()}-{tag}"


@pytest.mark.parametrize("params, budget", [
    ({"n_particles": 30, "kernel": "s2", "schedule": "adaptive", "target_ess": 0.3, "c": 0.5, "variance": "selected"},
     224),                                                        # the pelvis stage's (truncated last generation)
    ({"n_particles": 17, "kernel": "s1", "schedule": "adaptive", "target_ess": 0.5}, 170),
    ({"n_particles": 20, "kernel": "s3", "schedule": "adaptive", "variance": "population", "rho": 1e-3}, 333),
    ({"n_particles": 20, "kernel": "s2", "schedule": "adaptive", "c": 0.6, "c_scale": "deviation"}, 333),
])
def test_compiled_flat_isa_equals_the_protocol(params, budget):
    from isa_mocap_ros.optim import Isa

    def energy(X):                      # a rugged energy with a rotation block, NaN rows counted as +inf
        E = np.sum((X - 0.3) ** 2, axis=1) + 0.1 * np.sin(7 * X).sum(axis=1)
        E[X[:, 1] > 0.1] = np.nan
        return E

    def make(seed):
        return Isa(np.array([0.1, -0.2, 0.05, 0.4, 0.3, -2.9]), np.full(6, 0.2), rng=np.random.default_rng(seed),
                   bounds=(np.full(6, -1.0), np.array([1.0, 1.0, 1.0, 3.5, 3.5, 3.5])),
                   rotation_blocks=((3, 4, 5),), **params)
    ref_opt, opt = make(11), make(11)
    ref = minimize(ref_opt, energy, max_evals=budget)
    assert compiled_search.supported_flat(opt)
    got = compiled_search.search(opt, energy, budget)
    for name in ("x", "best_x", "population", "weights"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    for name in ("energy", "best_energy", "n_evals", "n_iter", "reason", "n_nonfinite"):
        assert getattr(got, name) == getattr(ref, name), name
    assert ref.n_nonfinite > 0
    np.testing.assert_array_equal([dataclasses.astuple(h) for h in got.history],
                                  [dataclasses.astuple(h) for h in ref.history])
    assert opt.rng.bit_generator.state == ref_opt.rng.bit_generator.state
    assert not compiled_search.supported_flat(Isa(np.zeros(6), 0.1, rng=np.random.default_rng(0), schedule="polynomial"))
