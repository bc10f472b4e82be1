"""A few poses go to the serial twin of the silhouette kernel (a parallel launch costs more than they do):
the same bits as the parallel kernel, on both sides of the switch."""
import numpy as np

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.energy import SilhouetteEnergy
from isa_mocap_ros.energy import silhouette_kernel as K
from isa_mocap_ros.vision import default_rig, render_mask


def test_serial_and_parallel_kernels_give_the_same_bits():
    model = make_model(39)
    rig = default_rig(n_views=3, width=160, height=120)
    x0 = model.rest_pose()
    x0[model.knee_dofs[0]] = 0.5
    masks = [render_mask(c, capsule_endpoints(model, x0)[0], model.capsule_radii) for c in rig]
    rng = np.random.default_rng(4)
    X = x0 + np.concatenate([rng.normal(0, 0.05, (40, 6)), rng.normal(0, 0.2, (40, model.dof - 6))], axis=1)
    en = SilhouetteEnergy(model, rig, masks, rng=np.random.default_rng(0))
    full = en(X)                                     # parallel (40 >= SERIAL_BELOW)
    a, b = np.empty(40), np.empty(40)
    K.silhouette_batch(X, *en.kernel_args(), 7, a)
    K.silhouette_batch_serial(X, *en.kernel_args(), 7, b)
    np.testing.assert_array_equal(a, full)
    np.testing.assert_array_equal(b, full)
    for n in (1, 2, K.SERIAL_BELOW - 1, K.SERIAL_BELOW):
        np.testing.assert_array_equal(en(X[:n]), full[:n])
    assert len(np.unique(full)) > 30                 # the poses differ: the comparison means something


def test_the_number_of_work_units_does_not_change_a_bit():
    # the energies take one work unit per numba thread (numba splits a parallel loop statically, so more units
    # only repeat their scratch set-up): any split gives the same values, full and restricted kernel
    model = make_model(39)
    rig = default_rig(n_views=3, width=160, height=120)
    x0 = model.rest_pose()
    x0[model.knee_dofs[1]] = 0.4
    masks = [render_mask(c, capsule_endpoints(model, x0)[0], model.capsule_radii) for c in rig]
    rng = np.random.default_rng(5)
    X = x0 + np.concatenate([rng.normal(0, 0.05, (30, 6)), rng.normal(0, 0.2, (30, model.dof - 6))], axis=1)
    en = SilhouetteEnergy(model, rig, masks, n_model_points=640, n_mask_points=384, rng=np.random.default_rng(1))
    coords = np.asarray(model.partitions["left_leg"])
    Xr = np.repeat(x0[None], 30, axis=0)
    Xr[:, coords] = X[:, coords]
    rest = en.restrict(x0, coords)
    assert not rest.full
    ref, ref_r = en(X), rest(Xr)
    for n_chunks in (1, 2, 3, 16, 30):
        a, b = np.empty(30), np.empty(30)
        K.silhouette_batch(X, *en.kernel_args(), n_chunks, a)
        K.silhouette_restricted(Xr, *rest.kernel_args(), n_chunks, b)
        np.testing.assert_array_equal(a, ref)
        np.testing.assert_array_equal(b, ref_r)
    assert len(np.unique(ref)) > 25 and len(np.unique(ref_r)) > 25
