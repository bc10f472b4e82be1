"""Silhouette energy (EA-vs-PF Eq. 4-5): exact raster reference, fast kernel, agreement, bad input."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import spearmanr

from isa_mocap_ros.body import capsule_endpoints, joint_positions, make_model
from isa_mocap_ros.energy import EnergyError, SilhouetteEnergy, exact_view_energy
from isa_mocap_ros.energy import silhouette_kernel as K
from isa_mocap_ros.energy.silhouette import kinematic_tables
from isa_mocap_ros.vision import default_rig, look_at, render_mask


@pytest.fixture(scope="module")
def scene():
    model = make_model(39)
    rig = default_rig()
    x0 = model.rest_pose()
    x0[model.knee_dofs[0]] = 0.6                       # left knee bent
    x0[model.dof_names.index("left_shoulder_y")] = -0.5  # left arm forward
    x0[model.dof_names.index("right_shoulder_x")] = -0.4  # right arm out
    x0[5] = 0.3                                         # turned a little
    E = capsule_endpoints(model, x0)[0]
    masks = [render_mask(c, E, model.capsule_radii) for c in rig]
    return model, rig, x0, masks


@pytest.fixture(scope="module")
def spread(scene):
    model, _, x0, _ = scene
    rng = np.random.default_rng(11)
    X = x0 + np.concatenate([rng.normal(0, 0.03, (60, 3)), rng.normal(0, 0.05, (60, 3)),
                             rng.normal(0, 0.12, (60, model.dof - 6))], axis=1)
    X[0] = x0
    return X


@pytest.fixture(scope="module")
def exact_spread(scene, spread):
    model, rig, _, masks = scene
    return SilhouetteEnergy(model, rig, masks, method="exact")(spread)


def test_exact_is_zero_at_the_rendered_pose_and_in_unit_interval(scene, exact_spread):
    model, rig, x0, masks = scene
    f = SilhouetteEnergy(model, rig, masks, method="exact")
    assert f(x0[None])[0] == 0.0
    assert np.all((exact_spread >= 0) & (exact_spread <= 1))
    assert exact_spread[1:].min() > 0.02


def test_exact_view_energy_counts_pixels_as_eq4(scene):
    model, rig, x0, masks = scene
    cam = rig.cameras[1]
    x = x0.copy()
    x[0] += 0.08
    M = render_mask(cam, capsule_endpoints(model, x)[0], model.capsule_radii) > 0
    F = masks[1] > 0
    want = 0.5 * np.sum(M & ~F) / M.sum() + 0.5 * np.sum(F & ~M) / F.sum()
    assert exact_view_energy(model, cam, masks[1], x)[0] == pytest.approx(want, abs=1e-15)
    far = x0.copy()
    far[0] += 50.0                                       # nobody of the model in view: worst value 1
    assert exact_view_energy(model, cam, masks[1], far)[0] == 1.0
    with pytest.raises(EnergyError, match="mask"):
        exact_view_energy(model, cam, np.zeros_like(masks[1]), x0)


def test_fast_close_to_zero_at_the_rendered_pose(scene):
    model, rig, x0, masks = scene
    for ds in (1, 2):
        f = SilhouetteEnergy(model, rig, masks, downsample=ds, rng=np.random.default_rng(0))
        assert 0.0 <= f(x0[None])[0] < 0.035


def test_fast_agrees_with_exact_rank_and_minimiser(scene, spread, exact_spread):
    model, rig, _, masks = scene
    fast = SilhouetteEnergy(model, rig, masks, rng=np.random.default_rng(3))(spread)
    rho = spearmanr(exact_spread, fast)[0]
    assert rho >= 0.9, rho
    assert np.argmin(fast) == np.argmin(exact_spread) == 0
    assert np.all((fast >= 0) & (fast <= 1))
    assert np.mean(np.abs(fast - exact_spread)) < 0.03


def test_area_estimate_of_term2_agrees_too(scene, spread, exact_spread):
    model, rig, _, masks = scene
    fast = SilhouetteEnergy(model, rig, masks, n_mask_points=0, n_model_points=240,
                            rng=np.random.default_rng(3))(spread)
    assert spearmanr(exact_spread, fast)[0] >= 0.9
    assert np.argmin(fast) == 0


def test_grid_minimum_sits_at_the_rendered_pose(scene):
    model, rig, x0, masks = scene
    dx = np.array([-0.1, -0.05, 0.0, 0.05, 0.1])
    dk = np.array([-0.3, -0.15, 0.0, 0.15, 0.3])
    X = np.repeat(x0[None], dx.size * dk.size, axis=0)
    X[:, 0] += np.repeat(dx, dk.size)
    X[:, model.knee_dofs[0]] += np.tile(dk, dx.size)
    centre = (dx.size // 2) * dk.size + dk.size // 2
    for f in (SilhouetteEnergy(model, rig, masks, method="exact"),
              SilhouetteEnergy(model, rig, masks, rng=np.random.default_rng(1))):
        e = f(X)
        assert np.argmin(e) == centre, (f.method, e.reshape(dx.size, dk.size))


def test_same_rng_same_values(scene, spread):
    model, rig, _, masks = scene
    a = SilhouetteEnergy(model, rig, masks, rng=np.random.default_rng(7))(spread)
    b = SilhouetteEnergy(model, rig, masks, rng=np.random.default_rng(7))(spread)
    np.testing.assert_array_equal(a, b)


def test_batched_equals_one_by_one_with_eval_count(scene, spread):
    model, rig, _, masks = scene
    for method, X in (("fast", spread), ("exact", spread[:4])):
        f = SilhouetteEnergy(model, rig, masks, method=method, rng=np.random.default_rng(2))
        g = SilhouetteEnergy(model, rig, masks, method=method, rng=np.random.default_rng(2))
        batched = f(X)
        single = np.array([g(x[None])[0] for x in X])
        np.testing.assert_array_equal(batched, single)
        assert f.n_evals == g.n_evals == len(X)


def test_non_finite_rows_give_inf_and_bad_width_raises(scene, spread):
    model, rig, _, masks = scene
    f = SilhouetteEnergy(model, rig, masks)
    X = spread[:5].copy()
    X[1, 7] = np.nan
    X[3, 0] = np.inf
    e = f(X)
    assert np.isinf(e[1]) and np.isinf(e[3])
    np.testing.assert_array_equal(e[[0, 2, 4]], f(spread[[0, 2, 4]]))
    assert f.n_evals == 8
    with pytest.raises(EnergyError, match=r"X: expected shape \(n, 39\)"):
        f(np.zeros((3, 28)))
    assert f(spread[0]).shape == (1,)


def test_skipped_views_recorded(scene, spread):
    model, rig, x0, masks = scene
    f = SilhouetteEnergy(model, rig, [None, np.zeros_like(masks[1]), masks[2][:100], masks[3]])
    assert [v for v, _ in f.skipped_views] == [0, 1, 2]
    reasons = " | ".join(r for _, r in f.skipped_views)
    assert "missing" in reasons and "empty" in reasons and "shape (100, 320)" in reasons
    assert f.n_views_used == 1
    one = SilhouetteEnergy(model, rig.cameras[3:], [masks[3]])
    np.testing.assert_array_equal(f(spread[:10]), one(spread[:10]))
    f.set_masks(masks)
    assert f.skipped_views == [] and f.n_views_used == 4


@pytest.mark.parametrize("method", ["fast", "exact"])
def test_view_weights_weigh_eq5_and_ones_are_eq5_to_the_bit(scene, spread, method):
    """``set_masks(masks, weights)``: ``sum_v w_v f_v / sum_v w_v`` of the one-view energies (every
    foreground pixel sampled, so the views' values do not depend on the draw); all ones = no weights,
    bit for bit; a skipped view's weight is ignored."""
    model, rig, x0, masks = scene
    def energy(cams, ms):
        return SilhouetteEnergy(model, cams, ms, method=method, n_mask_points=100_000, rng=np.random.default_rng(4))

    X = spread[:12]
    plain = energy(rig, masks)(X)
    f = energy(rig, masks)
    f.set_masks(masks, [1, 1, 1, 1])
    np.testing.assert_array_equal(f(X), plain)
    one = [energy([c], [m])(X) for c, m in zip(rig, masks)]
    w = np.array([1.0, 0.25, 0.0, 0.6])
    f.set_masks(masks, w)
    np.testing.assert_allclose(f(X), sum(wv * e for wv, e in zip(w, one)) / w.sum(), rtol=0, atol=1e-12)
    f.set_masks([masks[0], None, masks[2], masks[3]], [0.5, 7.0, 0.0, 1.0])
    np.testing.assert_allclose(f(X), (0.5 * one[0] + one[3]) / 1.5, rtol=0, atol=1e-12)


def test_capsules_leaving_the_image_keep_their_points_in_it():
    """``_clip_cap``: a body raised until only its legs reach into the top of the images (7-12 % of
    it in view) — the shins leave the image along their axes. Their template rectangles are cut to
    the part that can meet the image, so the points land where they count: the spread of the
    estimate over 20 template draws, measured 0.0233 (0.0291 with the rectangles whole), and its
    mean stays the exact energy's."""
    model = make_model(39)
    cams = list(default_rig().cameras)
    x = model.rest_pose()
    x[model.knee_dofs[0]] = 0.6
    x[2] += 2.35
    masks = [render_mask(c, capsule_endpoints(model, x)[0], model.capsule_radii) for c in cams]
    rng = np.random.default_rng(3)
    X = x + np.concatenate([rng.normal(0, 0.03, (30, 3)), rng.normal(0, 0.05, (30, 3)),
                            rng.normal(0, 0.12, (30, model.dof - 6))], axis=1)
    F = np.array([SilhouetteEnergy(model, cams, masks, rng=np.random.default_rng(s))(X) for s in range(20)])
    assert F.std(axis=0).mean() < 0.026
    exact = SilhouetteEnergy(model, cams, masks, method="exact")(X)
    assert np.abs(F.mean(axis=0) - exact).mean() < 0.01       # measured 0.0051 (whole: 0.0068)


def test_bad_view_weights_are_named(scene):
    model, rig, x0, masks = scene
    f = SilhouetteEnergy(model, rig, masks)
    for bad, what in (([1, 1, 1], "expected 4 numbers"), ([1, np.nan, 1, 1], "finite numbers >= 0"),
                      ([1, -0.1, 1, 1], "finite numbers >= 0"), ("heavy", "4 numbers"),
                      ([0, 0, 0, 0], "positive sum over the usable views"),
                      ([0, 1, 0, 0], "positive sum over the usable views")):
        m = masks if what != "positive sum over the usable views" or bad[1] == 0 else [masks[0], None, masks[2],
                                                                                     masks[3]]
        with pytest.raises(EnergyError, match=what):
            f.set_masks(m, bad)


def test_all_views_bad_or_no_masks_raise(scene):
    model, rig, x0, masks = scene
    with pytest.raises(EnergyError, match="at least one usable view"):
        SilhouetteEnergy(model, rig, [None, None, np.zeros_like(masks[0]), None])
    with pytest.raises(EnergyError, match="expected 4 masks"):
        SilhouetteEnergy(model, rig, masks[:3])
    f = SilhouetteEnergy(model, rig)
    with pytest.raises(EnergyError, match="masks"):
        f(x0[None])
    with pytest.raises(EnergyError, match="method"):
        SilhouetteEnergy(model, rig, masks, method="slow")
    with pytest.raises(EnergyError, match="downsample"):
        SilhouetteEnergy(model, rig, masks, downsample=0)
    with pytest.raises(EnergyError, match="rng"):
        SilhouetteEnergy(model, rig, masks, rng=3)
    with pytest.raises(EnergyError, match="cameras"):
        SilhouetteEnergy(model, [], masks)


def test_compiled_fk_matches_body_kinematics(scene, spread):
    model = scene[0]
    P = K.fk_positions_batch(np.ascontiguousarray(spread), *kinematic_tables(model))
    np.testing.assert_allclose(P, joint_positions(model, spread), atol=1e-12)
    lower = make_model(18)
    X = lower.rest_pose() + np.random.default_rng(0).normal(0, 0.3, (5, 18))
    np.testing.assert_allclose(K.fk_positions_batch(X, *kinematic_tables(lower)), joint_positions(lower, X),
                               atol=1e-12)


def test_projected_capsules_match_the_rendered_solid(scene, spread):
    """The 2-D hulls of the fast kernel against render_mask (exact ray casting of the same solids)."""
    model, rig, _, _ = scene
    caps = np.ascontiguousarray(model.capsules, dtype=np.int64)
    radii = np.ascontiguousarray(model.capsule_radii, dtype=np.float64)
    Rs = np.stack([c.R for c in rig])
    ts = np.stack([c.t for c in rig])
    ious = []
    for x in spread[:4]:
        P = joint_positions(model, x)[0]
        E = capsule_endpoints(model, x)[0]
        for v, cam in enumerate(rig):
            G = K.project_capsules(P, caps, radii, Rs, ts, v)
            ref = render_mask(cam, E, radii) > 0
            vv, uu = np.mgrid[0:cam.height, 0:cam.width]
            xn, yn = cam.undistort_pixels(uu.ravel().astype(float), vv.ravel().astype(float))
            mine = K.inside_points(G, np.stack([xn, yn], 1)).reshape(ref.shape)
            ious.append((mine & ref).sum() / (mine | ref).sum())
    assert min(ious) > 0.95, ious
    assert np.mean(ious) > 0.97, ious


def test_distorted_camera_runs_and_is_small_at_truth(scene):
    model, _, x0, _ = scene
    cams = [look_at((3.0, -1.5, 2.0), (0, 0, 1.0), fov_deg=70, dist=(-0.2, 0.05, 0.001, -0.001, 0.0), name="d0"),
            look_at((-3.0, 1.0, 1.5), (0, 0, 1.0), fov_deg=70, dist=(0.1, -0.02, 0.0, 0.0, 0.0), name="d1")]
    E = capsule_endpoints(model, x0)[0]
    masks = [render_mask(c, E, model.capsule_radii) for c in cams]
    f = SilhouetteEnergy(model, cams, masks, rng=np.random.default_rng(0))
    x = x0.copy()
    x[0] += 0.1
    e = f(np.stack([x0, x]))
    assert e[0] < 0.05 and e[1] > e[0] + 0.1



@pytest.mark.parametrize("settings", [{}, {"downsample": 2}, {"core_px": 3.0}, {"method": "exact"}])
def test_prepared_masks_give_the_same_bits_for_any_model(scene, spread, settings):
    # what prepare_masks keeps does not depend on the model or the random sample: energies of two models
    # (other segment lengths: another template, so another random stream after it) built on masks prepared
    # by a third are the bits of the same energies given the raw masks; distorted views and a skipped one
    model, _, x0, _ = scene
    cams = [look_at((3.0, -1.5, 2.0), (0, 0, 1.0), fov_deg=70, dist=(-0.2, 0.05, 0.001, -0.001, 0.0), name="d0"),
            look_at((-3.0, 1.0, 1.5), (0, 0, 1.0), fov_deg=70, dist=(0.1, -0.02, 0.0, 0.0, 0.0), name="d1"),
            look_at((0.5, 3.2, 1.8), (0, 0, 1.0), fov_deg=60, name="p2")]
    E = capsule_endpoints(model, x0)[0]
    masks = [render_mask(c, E, model.capsule_radii) for c in cams[:2]] + [None]
    shp = {k: dict(v) for k, v in model.shape.items() if k in ("offsets", "radii")}
    shp["offsets"]["left_knee"] = shp["offsets"]["right_knee"] = [0.0, 0.0, -0.5]
    long_legs = make_model(39, shape=shp)
    pre = SilhouetteEnergy(make_model(28), cams, **settings).prepare_masks(masks)
    assert pre.used == (0, 1) and pre.skipped[0][0] == 2
    for m in (model, long_legs):
        X = spread if m.dof == 39 else spread[:, :m.dof]
        a = SilhouetteEnergy(m, cams, rng=np.random.default_rng(4), **settings)
        b = SilhouetteEnergy(m, cams, rng=np.random.default_rng(4), **settings)
        for frame in range(2):                          # the second frame draws a new sample from the rng
            a.set_masks(masks)
            b.set_masks(pre)
            assert b.skipped_views == a.skipped_views and b.n_views_used == 2
            assert np.array_equal(a(X), b(X))
    with pytest.raises(EnergyError, match="prepared for other cameras"):
        SilhouetteEnergy(model, cams[::-1], **settings).set_masks(pre)
    other = {"method": "exact"} if settings.get("method") != "exact" else {}
    with pytest.raises(EnergyError, match="prepared for method, downsample, core_px"):
        SilhouetteEnergy(model, cams, **other).set_masks(pre)
    with pytest.raises(EnergyError, match="expected at least one usable view"):
        SilhouetteEnergy(model, cams, **settings).set_masks(
            SilhouetteEnergy(model, cams, **settings).prepare_masks([None] * 3))

_HASH_SCRIPT = """
import hashlib, sys, numpy as np
from isa_mocap_ros.body import make_model
from isa_mocap_ros.energy.silhouette import SilhouetteEnergy
from isa_mocap_ros.vision import default_rig
m = make_model(39); rig = default_rig(width=160, height=120); x = m.rest_pose()
en = SilhouetteEnergy(m, rig.cameras, n_model_points=640, n_mask_points=384, rng=np.random.default_rng(0))
en.set_masks(list(np.load(sys.argv[1])))
X = np.clip(x + np.random.default_rng(1).normal(0, 0.1, (300, m.dof)), m.lower, m.upper)
print(hashlib.sha1(en(X).tobytes()).hexdigest())
"""


def test_fresh_and_cached_kernel_agree_bit_for_bit(tmp_path):
    """A process that compiles the kernel and one that loads it from numba's cache must compute the
    same bits (with fastmath "reassoc" they did not: lockstep network vs offline tracker differed).
    The masks are rendered here (this process's usual cache), so the fresh cache compiles the energy's
    kernel only, not the renderer's."""
    from numba_cache import stdout_compiled_then_cached

    m = make_model(39)
    rig = default_rig(width=160, height=120)
    E = capsule_endpoints(m, m.rest_pose())[0]
    np.save(tmp_path / "masks.npy", np.stack([render_mask(c, E, m.capsule_radii) for c in rig.cameras]))
    out = stdout_compiled_then_cached(_HASH_SCRIPT, tmp_path / "numba", timeout=300, args=(str(tmp_path / "masks.npy"),),
                                      NUMBA_NUM_THREADS="1")
    assert any((tmp_path / "numba").rglob("silhouette_kernel.silhouette_batch-*.nbc"))   # the second run loaded it
    assert out[0] == out[1]
