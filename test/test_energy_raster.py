"""The scanline silhouette energy (``SilhouetteEnergy(method="raster")``): Eq. 4 counted on the pixel grid
from the projected 2-D hulls, against a brute-force count of the same hulls and against the exact renderer."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import spearmanr

from isa_mocap_ros.body import capsule_endpoints, joint_positions, make_model
from isa_mocap_ros.energy import EnergyError, SilhouetteEnergy
from isa_mocap_ros.energy import silhouette_kernel as K
from isa_mocap_ros.energy.silhouette import kinematic_tables
from isa_mocap_ros.energy.undistort import pinhole, undistort_mask
from isa_mocap_ros.vision import Camera, default_rig, render_mask


@pytest.fixture(scope="module")
def scene():
    model = make_model(39)
    rig = default_rig()
    x0 = model.rest_pose()
    x0[model.knee_dofs[0]] = 0.6
    x0[model.dof_names.index("left_shoulder_y")] = -0.5
    x0[model.dof_names.index("right_shoulder_x")] = -0.4
    x0[5] = 0.3
    E = capsule_endpoints(model, x0)[0]
    masks = [render_mask(c, E, model.capsule_radii) for c in rig]
    rng = np.random.default_rng(11)
    X = x0 + np.concatenate([rng.normal(0, 0.03, (60, 3)), rng.normal(0, 0.05, (60, 3)),
                             rng.normal(0, 0.12, (60, model.dof - 6))], axis=1)
    X[0] = x0
    return model, rig, x0, masks, X


def _hull_pixels(model, cam, v, x, stride):
    """The pixel centres (every ``stride``-th row) inside the union of the capsules' projected 2-D hulls,
    tested point by point (``silhouette_kernel.inside_points``): what the scanlines must fill."""
    parents, offsets, ptr, dofs, axes = kinematic_tables(model)
    P = joint_positions(model, x[None])[0]
    caps = np.ascontiguousarray(model.capsules, dtype=np.int64)
    radii = np.ascontiguousarray(model.capsule_radii, dtype=np.float64)
    G = K.project_capsules(P, caps, radii, cam.R[None].copy(), cam.t[None].copy(), 0)
    vv, uu = np.mgrid[0:cam.height:stride, 0:cam.width]
    pts = np.stack([(uu.ravel() - cam.cx) / cam.fx, (vv.ravel() - cam.cy) / cam.fy], axis=1)
    M = np.zeros((cam.height, cam.width), bool)
    M[vv.ravel(), uu.ravel()] = K.inside_points(G, pts)
    return M


@pytest.mark.parametrize("stride", [1, 2])
def test_raster_counts_the_hulls_pixels(scene, stride):
    """Per view, Eq. 4 from the brute-force pixel set of the same hulls (float32 spans may move a pixel
    centre that lies on a hull's edge to the bit: a few pixels at most)."""
    model, rig, x0, masks, X = scene
    for i in (0, 7, 31):
        for v, cam in enumerate(rig):
            f = SilhouetteEnergy(model, [cam], [masks[v]], method="raster", downsample=stride)(X[i][None])[0]
            M = _hull_pixels(model, cam, v, X[i], stride)
            F = np.zeros_like(M)
            F[::stride] = masks[v][::stride] > 0
            want = 0.5 * np.sum(M & ~F) / M.sum() + 0.5 * np.sum(F & ~M) / F.sum()
            assert f == pytest.approx(want, abs=2.0 / M.sum()), (i, v)


def test_raster_agrees_with_exact(scene):
    """Closer to the exact renderer than the sampled kernel: only the disc approximation differs."""
    model, rig, x0, masks, X = scene
    exact = SilhouetteEnergy(model, rig, masks, method="exact")(X)
    raster = SilhouetteEnergy(model, rig, masks, method="raster")
    r = raster(X)
    fast = SilhouetteEnergy(model, rig, masks, n_model_points=640, n_mask_points=384,
                            rng=np.random.default_rng(0))(X)
    assert np.abs(r - exact).mean() < 0.002
    assert np.abs(r - exact).mean() < 0.5 * np.abs(fast - exact).mean()
    assert spearmanr(r, exact)[0] > 0.995
    assert 0.0 <= r[0] < 0.005                    # the rendered pose
    assert np.argmin(r) == np.argmin(exact) == 0
    r2 = SilhouetteEnergy(model, rig, masks, method="raster", downsample=2)(X)
    assert np.abs(r2 - exact).mean() < 0.003 and spearmanr(r2, exact)[0] > 0.99


def test_raster_batches_and_small_batches_give_the_same_bits(scene):
    model, rig, x0, masks, X = scene
    f = SilhouetteEnergy(model, rig, masks, method="raster")
    whole = f(X)
    one_by_one = np.array([f(X[i:i + 1])[0] for i in range(12)])   # the serial kernel
    assert np.array_equal(whole[:12], one_by_one)
    assert np.array_equal(f(X[:5]), whole[:5])
    assert f.n_evals == 60 + 12 + 5


def test_raster_model_out_of_view_and_bad_rows(scene):
    model, rig, x0, masks, X = scene
    f = SilhouetteEnergy(model, rig, masks, method="raster")
    far = x0.copy()
    far[0] += 50.0
    bad = x0.copy()
    bad[7] = np.nan
    out = f(np.stack([far, bad, x0]))
    assert out[0] == 1.0 and out[1] == np.inf and out[2] < 0.005


def test_raster_weights_and_skipped_views(scene):
    model, rig, x0, masks, X = scene
    per_view = [SilhouetteEnergy(model, [c], [m], method="raster")(X[:6]) for c, m in zip(rig, masks)]
    w = np.array([1.0, 0.0, 2.0, 0.5])
    f = SilhouetteEnergy(model, rig, method="raster")
    f.set_masks(masks, weights=w)
    assert np.allclose(f(X[:6]), np.tensordot(w, per_view, 1) / w.sum(), rtol=0, atol=1e-15)
    f.set_masks([masks[0], None, masks[2], np.zeros_like(masks[3])])
    assert [v for v, _ in f.skipped_views] == [1, 3]
    assert np.allclose(f(X[:6]), (per_view[0] + per_view[2]) / 2, rtol=0, atol=1e-15)


def test_raster_refuses_what_it_cannot_count(scene):
    model, rig, x0, masks, X = scene
    with pytest.raises(EnergyError, match="core_px=3"):
        SilhouetteEnergy(model, rig, method="raster", core_px=3)
    with pytest.raises(EnergyError, match="'fast', 'exact' or 'raster'"):
        SilhouetteEnergy(model, rig, method="rasterize")
    r = SilhouetteEnergy(model, rig, masks, method="raster").restrict(x0, [20, 21])
    Xr = np.repeat(x0[None], 4, axis=0)
    Xr[:, 20:22] += np.linspace(-0.3, 0.3, 8).reshape(4, 2)
    assert not r.full and np.array_equal(r(Xr), SilhouetteEnergy(model, rig, masks, method="raster")(Xr))


PARTS = ("root", "torso", "left_arm", "right_arm", "left_leg", "right_leg")


@pytest.mark.parametrize("stride, weights", [(1, None), (2, (1.0, 0.25, 0.0, 0.6))])
def test_raster_restricted_equals_full_bit_for_bit(scene, stride, weights):
    """Bases off the rendered pose and 0.4 rad moves, so moving capsules overlap fixed ones: the same bits."""
    model, rig, x0, masks, X = scene
    en = SilhouetteEnergy(model, rig, method="raster", downsample=stride)
    en.set_masks(masks, weights)
    rng = np.random.default_rng(1)
    for part in PARTS:
        cols = model.partitions[part]
        for _ in range(2):
            base = np.clip(x0 + rng.normal(0, 0.2, model.dof), model.lower, model.upper)
            Xp = np.repeat(base[None], 60, axis=0)
            Xp[:, cols] += rng.normal(0, 0.4, (60, len(cols))) * np.where(cols < 3, 0.25, 1.0)
            f = en.restrict(base, cols)
            assert f.full == (part == "root")
            np.testing.assert_array_equal(f(Xp), en(Xp), err_msg=part)
    f = en.restrict(x0, model.partitions["left_leg"])
    bad = np.repeat(x0[None], 3, axis=0)
    bad[1, 7] += 1e-12                        # outside the coordinates: never a silent value
    with pytest.raises(EnergyError, match=r"row 1 with coordinate 7"):
        f(bad)
    # its coarse level: every second row (test_energy_coarse checks its values)
    assert f.coarse_kernel_args()[3].stride == 2 * en.downsample and f.coarse_kernel_args() is f.coarse_kernel_args()


def test_compiled_search_on_the_raster_energy_equals_the_protocol(scene):
    """The tracker's compiled h-isa runs on the scanline energy (full kernel in the root partition, restricted in
    the others) with the protocol's numbers, bit for bit; with a coarse level (every second row) it runs compiled too."""
    from isa_mocap_ros.optim import compiled_search, make_optimizer, minimize

    model, rig, x0, masks, X = scene
    energy = SilhouetteEnergy(model, rig, masks, method="raster")

    class Restrictable:
        def __call__(self, X):
            return energy(X)

        def restrict(self, x, coords):
            return energy.restrict(x, coords)

    def hier():
        parts = [np.asarray(model.partitions[k]) for k in PARTS]
        spread = np.full(model.dof, 0.05)
        spread[:3] = 0.015
        x = x0 + 0.02
        lo, hi = np.maximum(x - 0.5, model.lower), np.minimum(x + 0.5, model.upper)
        return make_optimizer("h-isa", np.clip(x, lo, hi), spread, rng=np.random.default_rng([5, 9]), bounds=(lo, hi),
                              rotation_blocks=model.rotation_blocks, partitions=parts, n_particles=30, kernel="s2",
                              schedule="adaptive", target_ess=0.3, c=0.5, variance="selected")

    ref_opt = hier()
    ref = minimize(ref_opt, Restrictable(), max_evals=900)
    opt = hier()
    got = compiled_search.search(opt, energy, 900)
    assert got is not None
    for name in ("x", "best_x", "population"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    assert (got.energy, got.n_evals, got.n_iter) == (ref.energy, ref.n_evals, ref.n_iter)
    assert opt.rng.bit_generator.state == ref_opt.rng.bit_generator.state
    coarse = compiled_search.search(hier(), energy, 900, coarse_fraction=0.5)
    assert coarse is not None and coarse.n_evals == 900 and not np.array_equal(coarse.x, got.x)


# ---------------------------------------------------------------------- lens distortion
DIST = ((-0.2, 0.05, 0.001, -0.001, 0.0), (-0.05, 0.12, 0.0, 0.0, 0.0), (0.08, -0.02, -0.002, 0.001, 0.0),
        (-0.12, 0.03, 0.0, 0.0, -0.01, 0.001, 0.0, 0.0))


@pytest.fixture(scope="module")
def distorted(scene):
    """The scene moved off the rig's centre (1 m, 0.5 m: towards the image borders, where distortion moves pixels)
    and seen by the default rig's cameras with lens distortion (barrel, mild, pincushion, rational); the masks
    rendered through the distorted cameras (exact: a pixel's ray, distortion removed, against the solids)."""
    model, rig, x0, masks, X = scene
    X = X.copy()
    X[:, :2] += (1.0, 0.5)
    cams = [Camera(c.name, c.width, c.height, c.K, d, c.R, c.t) for c, d in zip(rig, DIST)]
    E = capsule_endpoints(model, X[0])[0]
    return cams, X, [render_mask(c, E, model.capsule_radii) for c in cams]


def test_undistorted_mask_is_the_pinhole_render(scene, distorted):
    """A distorted render resampled onto the pinhole twin is the pinhole render up to the outline's pixels: far
    closer than the distorted render itself."""
    model, rig, x0, masks, X = scene
    cams, Xd, dmasks = distorted
    E = capsule_endpoints(model, Xd[0])[0]
    off, raw = 0, 0
    for cam, m in zip(cams, dmasks):
        twin = pinhole(cam)
        assert not twin.has_distortion and twin.name == cam.name and np.array_equal(twin.K, cam.K)
        want = render_mask(twin, E, model.capsule_radii) > 0
        got = undistort_mask(cam, m)
        assert got.shape == want.shape and got.dtype == bool
        assert np.sum(got & want) / np.sum(got | want) > 0.94, cam.name
        off += np.sum(got != want)
        raw += np.sum(want != (m > 0))
    assert off < 0.6 * raw
    assert np.array_equal(undistort_mask(rig[0], masks[0]), masks[0] > 0) and pinhole(rig[0]) is rig[0]
    with pytest.raises(ValueError, match="camera cam0"):
        undistort_mask(cams[0], dmasks[0][:, :-1])


def test_raster_serves_distorted_cameras(scene, distorted):
    """With lens distortion the scanline count (on the pinhole twins, masks resampled once per frame) agrees with
    the exact energy on the distorted cameras better than the sampled kernel, which models the distortion itself,
    and than counting the distorted masks as if they were pinhole images; its restriction gives the full kernel's
    bits as without distortion."""
    model, rig, x0, masks, X = scene
    cams, X, dmasks = distorted
    exact = SilhouetteEnergy(model, cams, dmasks, method="exact")(X)
    raster = SilhouetteEnergy(model, cams, dmasks, method="raster")
    r = raster(X)
    fast = SilhouetteEnergy(model, cams, dmasks, n_model_points=640, n_mask_points=384,
                            rng=np.random.default_rng(0))(X)
    naive = SilhouetteEnergy(model, [pinhole(c) for c in cams], dmasks, method="raster")(X)
    err = np.abs(r - exact).mean()
    assert err < 0.006 and err < np.abs(fast - exact).mean() and err < 0.7 * np.abs(naive - exact).mean()
    assert spearmanr(r, exact)[0] > 0.995
    assert np.argmin(r) == np.argmin(exact) == 0 and r[0] < 0.025
    leg = model.partitions["left_leg"]
    f = raster.restrict(X[0], leg)
    Xr = np.repeat(X[:1], 8, axis=0)
    Xr[:, leg] += np.random.default_rng(2).normal(0, 0.3, (8, len(leg)))
    assert not f.full and np.array_equal(f(Xr), raster(Xr))
    raster.set_masks(raster.prepare_masks(dmasks))          # prepared masks: the same bits
    assert np.array_equal(raster(X), r)


def test_tracker_on_distorted_cameras_with_the_raster_energy(scene, distorted):
    """The tracker (compiled search, restrictions, stages) runs the scanline count on distorted cameras unchanged:
    a frame tracked from the true pose stays on the masks (its energy as the energy gives it), deterministic."""
    from isa_mocap_ros.tracking import Tracker, TrackerConfig

    model, rig, x0, masks, X = scene
    cams, Xd, dmasks = distorted
    runs = []
    for _ in range(2):
        tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, seed=3, energy="raster"))
        tr.initialize(pose=Xd[0])
        r = tr.step(dmasks, 1)
        runs.append(r)
    r = runs[0]
    assert tr.energy.method == "raster" and np.array_equal(runs[1].x, r.x)
    assert r.energy == pytest.approx(float(tr.energy(r.x[None])[0]), abs=1e-12) and r.energy < 0.05
    err = np.linalg.norm(joint_positions(model, r.x[None])[0] - joint_positions(model, Xd[:1])[0], axis=1).mean()
    assert err < 0.03, err


@pytest.mark.parametrize("stride", [1, 2, 3])
def test_foreground_bits_are_numpys_packed_rows(stride):
    """``raster_kernel.foreground_bits`` (compiled) packs each view's rows as ``numpy.packbits(..., bitorder="little")``
    does, word-major, and counts the bits: views of different sizes and widths not a multiple of 64, bool and uint8."""
    from isa_mocap_ros.energy.raster_kernel import foreground_bits

    rng = np.random.default_rng(4)
    F = [rng.random(s) < p for s, p in (((24, 70), 0.3), ((17, 64), 0.02), ((5, 130), 1.0), ((1, 1), 0.0))]
    H, nw = 24, 3
    Hs = -(-H // stride)
    want = np.zeros((len(F), nw * Hs + 8), np.uint64)
    for v, f in enumerate(F):
        b = np.zeros((Hs * stride, nw * 64), np.uint8)
        b[:f.shape[0], :f.shape[1]] = f
        want[v, :nw * Hs] = np.packbits(b[::stride], axis=1, bitorder="little").view("<u8").T.reshape(-1)
    for masks in (F, [f.astype(np.uint8) * 255 for f in F]):
        fbits, nfg, n_words = foreground_bits(masks, stride)
        assert n_words == nw and np.array_equal(fbits, want)
        assert nfg.tolist() == [int(np.count_nonzero(f[::stride])) for f in F]
