"""The silhouette energy's coarse level (two views) and the compiled search's use of it in early generations."""
import numpy as np
import pytest

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.energy import SilhouetteEnergy
from isa_mocap_ros.energy import silhouette_kernel as K
from isa_mocap_ros.optim import compiled_search, make_optimizer
from isa_mocap_ros.optim._base import OptimError
from isa_mocap_ros.tracking import TrackerConfig
from isa_mocap_ros.tracking.config import TrackerError
from isa_mocap_ros.vision import default_rig, render_mask


@pytest.fixture(scope="module")
def scene():
    model = make_model(39)
    rig = default_rig(n_views=4, width=160, height=120)
    x0 = model.rest_pose()
    x0[model.knee_dofs[0]] = 0.5
    x0[model.dof_names.index("left_hip_y")] = -0.3
    masks = [render_mask(c, capsule_endpoints(model, x0)[0], model.capsule_radii) for c in rig]
    return model, rig, x0, masks


def test_the_coarse_level_is_the_energy_of_its_two_views(scene):
    model, rig, x0, masks = scene
    en = SilhouetteEnergy(model, rig, masks, n_model_points=320, n_mask_points=192, rng=np.random.default_rng(3))
    k = en.coarse_views()
    # the two views closest to perpendicular: in the default ring of four, two neighbours (not opposite views)
    assert len(k) == 2 and abs(float(np.dot(rig[int(k[0])].R[2], rig[int(k[1])].R[2]))) < 0.2
    w = np.zeros(4)
    w[k] = 1.0
    # the same samples (same seed), the other views weighed 0: the coarse level's values to the bit
    ref = SilhouetteEnergy(model, rig, None, n_model_points=320, n_mask_points=192, rng=np.random.default_rng(3))
    ref.set_masks(masks, weights=w)
    rng = np.random.default_rng(0)
    X = x0 + np.concatenate([rng.normal(0, 0.03, (24, 6)), rng.normal(0, 0.15, (24, model.dof - 6))], axis=1)
    out = np.empty(24)
    K.silhouette_batch(X, *en.coarse_kernel_args(), 2, out)
    np.testing.assert_array_equal(out, ref(X))
    assert not np.array_equal(out, en(X))           # fewer views: another estimate of the same quantity
    assert np.abs(out - en(X)).mean() < 0.05
    # the restricted kernel's coarse stage, likewise
    coords = np.asarray(model.partitions["right_arm"])
    Xr = np.repeat(x0[None], 24, axis=0)
    Xr[:, coords] = X[:, coords]
    rest = en.restrict(x0, coords)
    K.silhouette_restricted(Xr, *rest.coarse_kernel_args(), 2, out)
    np.testing.assert_array_equal(out, ref(Xr))
    assert en.coarse_kernel_args() is en.coarse_kernel_args()      # built once per frame
    # the second pair: the other two views (the search alternates the pairs)
    k2 = en.coarse_views(second=True)
    assert sorted(k2.tolist() + k.tolist()) == [0, 1, 2, 3]
    w2 = np.zeros(4)
    w2[k2] = 1.0
    ref2 = SilhouetteEnergy(model, rig, None, n_model_points=320, n_mask_points=192, rng=np.random.default_rng(3))
    ref2.set_masks(masks, weights=w2)
    K.silhouette_batch(X, *en.coarse_kernel_args(second=True), 2, out)
    np.testing.assert_array_equal(out, ref2(X))
    K.silhouette_restricted(Xr, *rest.coarse_kernel_args(second=True), 2, out)
    np.testing.assert_array_equal(out, ref2(Xr))


def test_the_search_evaluates_its_early_generations_coarse(scene):
    model, rig, x0, masks = scene
    en = SilhouetteEnergy(model, rig, masks, n_model_points=320, n_mask_points=192, rng=np.random.default_rng(3))
    parts = [np.asarray(model.partitions[k]) for k in ("root", "left_arm", "right_arm", "torso", "left_leg",
                                                        "right_leg")]
    start = x0.copy()
    start[model.knee_dofs[0]] -= 0.2
    lo, hi = np.maximum(start - 0.5, model.lower), np.minimum(start + 0.5, model.upper)
    spread = np.full(model.dof, 0.05)
    spread[:3] = 0.015

    def run(frac):
        opt = make_optimizer("h-isa", start, spread, rng=np.random.default_rng(5), bounds=(lo, hi),
                             rotation_blocks=model.rotation_blocks, partitions=parts, n_particles=30, kernel="s2",
                             schedule="adaptive", target_ess=0.3, c=0.5, variance="selected",
                             whole_generations=True)
        return compiled_search.search(opt, en, 900, coarse_fraction=frac)

    full, coarse = run(0.0), run(0.5)
    assert full.n_evals == coarse.n_evals == 900
    assert not np.array_equal(full.x, coarse.x)
    # 900 evaluations, 6 partitions of 5 generations: the first 2 of each coarse, whose best particles are not kept
    assert len(coarse.history) == 30
    best = en(coarse.best_x[None])[0]
    assert best == coarse.best_energy
    # both move the knee back towards the rendered pose (0.2 rad off at the start) and lower the energy
    e0 = en(start[None])[0]
    for r in (full, coarse):
        assert abs(r.x[model.knee_dofs[0]] - x0[model.knee_dofs[0]]) < 0.15
        assert en(r.x[None])[0] < 0.8 * e0
    with pytest.raises(OptimError, match="coarse_fraction"):
        run(1.0)
    with pytest.raises(TrackerError, match="coarse_fraction"):
        TrackerConfig.from_flat(coarse_fraction=1.5)


def test_the_scanline_coarse_level_counts_every_second_row(scene):
    """method="raster": the coarse level is every view on every second pixel row, the same bits as the energy made
    with downsample 2 (full and restricted kernel), its foreground packed from the full-resolution words; the compiled
    search runs its early generations on it."""
    from isa_mocap_ros.energy import raster_kernel as RK
    from isa_mocap_ros.energy.coarse import raster_rows_subset

    model, rig, x0, masks = scene
    en = SilhouetteEnergy(model, rig, masks, method="raster")
    ref = SilhouetteEnergy(model, rig, masks, method="raster", downsample=2)
    got, want = raster_rows_subset(en.kernel_args()[2]), ref.kernel_args()[2]
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b)
    rng = np.random.default_rng(0)
    X = x0 + np.concatenate([rng.normal(0, 0.03, (24, 6)), rng.normal(0, 0.15, (24, model.dof - 6))], axis=1)
    out = np.empty(24)
    RK.raster_batch(X, *en.coarse_kernel_args(), 2, out)
    np.testing.assert_array_equal(out, ref(X))
    assert en.coarse_kernel_args() is en.coarse_kernel_args(second=True)     # one level, built once per frame
    coords = np.asarray(model.partitions["left_leg"])
    Xr = np.repeat(x0[None], 24, axis=0)
    Xr[:, coords] = X[:, coords]
    rest = en.restrict(x0, coords)
    RK.raster_restricted(Xr, *rest.coarse_kernel_args(), 2, out)
    np.testing.assert_array_equal(out, ref(Xr))
    parts = [np.asarray(model.partitions[k]) for k in ("root", "left_arm", "torso")]
    spread = np.full(model.dof, 0.05)

    def run(frac):
        opt = make_optimizer("h-isa", x0, spread, rng=np.random.default_rng(5), bounds=(model.lower, model.upper),
                             rotation_blocks=model.rotation_blocks, partitions=parts, n_particles=30, kernel="s2",
                             schedule="adaptive", target_ess=0.3, c=0.5, variance="selected", whole_generations=True)
        return compiled_search.search(opt, en, 450, coarse_fraction=frac)

    full, coarse = run(0.0), run(0.5)
    assert full is not None and coarse is not None and full.n_evals == coarse.n_evals == 450
    assert not np.array_equal(full.x, coarse.x) and en(coarse.best_x[None])[0] == coarse.best_energy
