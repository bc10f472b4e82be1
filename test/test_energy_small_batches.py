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
