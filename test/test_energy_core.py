"""Term 2 of the silhouette energy weighted towards the silhouette's core (``core_px``): the rim of a
silhouette wider than the capsules (clothes, soft tissue) asks less to be covered."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import spearmanr

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.energy import EnergyError, SilhouetteEnergy
from isa_mocap_ros.energy.silhouette import core_weights
from isa_mocap_ros.vision import default_rig, render_mask


@pytest.fixture(scope="module")
def clothed():
    """Masks of the model's pose drawn with every radius 1.6x (a body in loose clothes), the model itself
    with its own radii, and poses around the true one."""
    model = make_model(39)
    rig = default_rig()
    x0 = model.rest_pose()
    x0[model.knee_dofs[0]] = 0.5
    x0[model.dof_names.index("right_shoulder_x")] = -0.5
    E = capsule_endpoints(model, x0)[0]
    masks = [render_mask(c, E, 1.6 * np.asarray(model.capsule_radii)) for c in rig]
    rng = np.random.default_rng(5)
    X = x0 + np.concatenate([rng.normal(0, 0.02, (50, 6)), rng.normal(0, 0.15, (50, model.dof - 6))], axis=1)
    X[0] = x0
    return model, rig, x0, masks, X


def test_core_weights_ramp_from_the_edge():
    F = np.zeros((40, 40), bool)
    F[5:35, 5:35] = True
    w = core_weights(F, 4.0)
    assert w[0, 0] == 0.0 and w[20, 20] == 1.0
    assert w[5, 20] == pytest.approx(0.25)       # the edge pixel: distance 1
    assert np.all(w[F] > 0)
    assert core_weights(F, 1.0) is None and core_weights(F, 0.0) is None


def test_exact_core_energy_is_eq4_with_weighted_misses(clothed):
    model, rig, x0, masks, X = clothed
    cam, mask = rig.cameras[2], masks[2]
    F = mask > 0
    w = core_weights(F, 3.0)
    f = SilhouetteEnergy(model, [cam], [mask], method="exact", core_px=3.0)
    x = X[3]
    M = render_mask(cam, capsule_endpoints(model, x[None])[0], model.capsule_radii) > 0
    want = 0.5 * np.sum(M & ~F) / M.sum() + 0.5 * w[~M].sum() / w.sum()
    assert f(x[None])[0] == pytest.approx(want, abs=1e-12)


def test_fast_core_energy_agrees_with_exact(clothed):
    model, rig, _, masks, X = clothed
    exact = SilhouetteEnergy(model, rig, masks, method="exact", core_px=3.0)(X)
    fast = SilhouetteEnergy(model, rig, masks, n_model_points=640, n_mask_points=384, core_px=3.0,
                            rng=np.random.default_rng(2))(X)
    assert spearmanr(exact, fast)[0] >= 0.9
    assert np.mean(np.abs(fast - exact)) < 0.03


def test_the_core_term_leaves_less_to_gain_by_filling_the_rim(clothed):
    """With the clothed masks, the true pose's energy is mostly term 2 (the rim it does not cover); with
    the core weighting that part shrinks, and the true pose is still the best of the spread."""
    model, rig, x0, masks, X = clothed
    plain = SilhouetteEnergy(model, rig, masks, method="exact")(X)
    core = SilhouetteEnergy(model, rig, masks, method="exact", core_px=4.0)(X)
    assert core[0] < 0.7 * plain[0]
    assert np.argmin(core) == 0


def test_core_px_bad_input():
    model, rig = make_model(39), default_rig()
    for bad in (-1.0, float("nan"), "3", True):
        with pytest.raises(EnergyError, match="core_px"):
            SilhouetteEnergy(model, rig, core_px=bad)
    with pytest.raises(EnergyError, match="n_mask_points > 0"):
        SilhouetteEnergy(model, rig, core_px=3.0, n_mask_points=0)
