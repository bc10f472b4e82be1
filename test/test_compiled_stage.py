"""The pelvis and torso stages' compiled search (optim/compiled_stage.py) gives run_isa's numbers on the Python
energy (the move, the clip, the objective), bit for bit."""
import dataclasses
import hashlib

import numpy as np
import pytest

from isa_mocap_ros.energy import KeypointEnergy
from isa_mocap_ros.energy.silhouette import SilhouetteEnergy
from isa_mocap_ros.optim import compiled_search, compiled_stage, make_optimizer
from isa_mocap_ros.tracking.reaim import ReaimMove

from test_compiled_search import _noisy_keypoints
from walk_scene import walk_scene

PARAMS = {"n_particles": 30, "kernel": "s2", "schedule": "adaptive", "target_ess": 0.3, "c": 0.5,
          "variance": "selected"}


@pytest.fixture(scope="module")
def scene():
    return walk_scene(width=320, height=240, frames=4, duration_s=0.5, seed=1)


@pytest.mark.parametrize("stage, method, weight, budget", [("pelvis", "raster", 0.0, 210),
                                                           ("torso", "raster", 1.0, 197),
                                                           ("pelvis", "fast", 1.0, 180),
                                                           ("torso", "fast", 0.0, 150)])
def test_moved_search_equals_run_isa_on_the_python_energy(scene, stage, method, weight, budget):
    model, cams, walk, masks = scene
    energy = SilhouetteEnergy(model, cams, masks[2], method=method, rng=np.random.default_rng(3))
    term = KeypointEnergy(model, cams, _noisy_keypoints(model, cams, walk[2], 7)) if weight else None
    x = np.clip(walk[1] + 0.02, model.lower, model.upper)
    if stage == "pelvis":
        reaim = ReaimMove(model, [0])
        rest, blocks = None, ((3, 4, 5),)
    else:
        reaim = ReaimMove(model, sorted({int(model.dof_joint[d]) for d in model.partitions["torso"]}))
        changed = np.union1d(reaim.coords, [d for j in reaim.ops for d in model.joint_dofs[j]])
        rest, blocks = energy.restrict(x, changed), ()
        assert not rest.full
    move = reaim.around(x)
    data = energy if rest is None else rest

    def objective(C):                                   # tracking/stages.py's energy, the objective's terms
        X = np.clip(move(C), model.lower, model.upper)
        E = data(X)
        return E + weight * term(X) if term is not None else E

    def make():
        c = reaim.coords
        lo, hi = np.maximum(x[c] - 0.3, model.lower[c]), np.minimum(x[c] + 0.3, model.upper[c])
        return make_optimizer("isa", x[c], np.full(c.size, 0.04), rng=np.random.default_rng(21), bounds=(lo, hi),
                              rotation_blocks=blocks, **PARAMS)
    ref_opt, opt = make(), make()
    ref = compiled_search.search(ref_opt, objective, budget)             # run_isa, the energy in Python
    n_ref = energy.n_evals
    got = compiled_stage.run_isa_moved(opt, energy, budget, move=reaim.kernel_args(x), coords=reaim.coords,
                                       limits=(model.lower, model.upper), restricted=rest,
                                       keypoints=(term, weight) if term is not None else None)
    assert energy.n_evals == 2 * n_ref and (term is None or term.n_evals == 2 * n_ref)
    for name in ("x", "best_x", "population", "weights"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    for name in ("energy", "best_energy", "n_evals", "n_iter", "reason", "n_nonfinite"):
        assert getattr(got, name) == getattr(ref, name), name
    np.testing.assert_array_equal([dataclasses.astuple(h) for h in got.history],
                                  [dataclasses.astuple(h) for h in ref.history])
    assert opt.rng.bit_generator.state == ref_opt.rng.bit_generator.state       # the same draws, in order


def test_what_the_moved_search_does_not_cover(scene):
    model, cams, walk, masks = scene
    x = walk[1]
    reaim = ReaimMove(model, [0])
    flat = make_optimizer("isa", x[:6], 0.05, rng=np.random.default_rng(0), **PARAMS)
    exact = SilhouetteEnergy(model, cams, masks[2], method="exact")
    assert compiled_stage.supported_moved(flat, SilhouetteEnergy(model, cams, masks[2]))
    assert not compiled_stage.supported_moved(flat, exact)
    assert not compiled_stage.supported_moved(flat, SilhouetteEnergy(model, cams, None))          # no masks yet
    poly = make_optimizer("isa", x[:6], 0.05, rng=np.random.default_rng(0), schedule="polynomial")
    assert not compiled_stage.supported_moved(poly, SilhouetteEnergy(model, cams, masks[2]))
    assert compiled_stage.run_isa_moved(flat, exact, 90, move=reaim.kernel_args(x), coords=reaim.coords,
                                        limits=(model.lower, model.upper)) is None


def test_cached_stage_code_depends_on_the_kernels_it_calls():
    # as the compiled search's (test_compiled_search): the stage loop calls the search's helpers, the energy
    # kernels and the move's kernel of other files, so its cache stamp carries their hashes
    import os

    from isa_mocap_ros import numba_cache
    from isa_mocap_ros.body import reaim_kernel

    locator = compiled_stage._moved_isa._cache._impl.locator
    assert type(locator).__name__ == "_DependentLocator"
    h = hashlib.sha256()
    files = numba_cache.dependencies(compiled_stage.__file__)
    for m in (*compiled_search.DEPENDENCIES, reaim_kernel, compiled_search):
        assert os.path.abspath(m.__file__) in files
    for path in files:
        h.update(open(path, "rb").read())
    assert locator.get_source_stamp()[1] == h.hexdigest()
