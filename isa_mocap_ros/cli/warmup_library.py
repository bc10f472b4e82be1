"""The library's numba kernels beyond the two nodes' (``isa-mocap warmup`` runs this beside them).

The estimator node's warm-up compiles what a real-time run calls first (:func:`.tracking.realtime.warm_up`: the
scanline energy, the tracker's stages, the automatic initialization). ``track``'s defaults, ``synth`` and the
other commands call more: the sampled energy (:class:`.energy.SilhouetteEnergy`'s default method, ``track
--energy fast``, the benches'), its restricted evaluation, the tracker on it, the triangle rasterizer of ``synth
--body mesh``. numba compiles a kernel for the argument types of its call, so this module makes those calls on a
tiny synthetic frame (the rest pose in 4 views of 80×60), in groups; ``isa-mocap warmup`` runs them in two
processes beside the nodes:

``python -m isa_mocap_ros.cli.warmup_library GROUP...`` with GROUP one of :data:`GROUPS`; prints
``warmup_library: GROUP done (N s)`` after each. Changes nothing but numba's on-disk cache.
"""
from __future__ import annotations

import sys
import time

import numpy as np


def _scene(n_views: int = 4, width: int = 80, height: int = 60):
    from isa_mocap_ros.body import capsule_endpoints, make_model
    from isa_mocap_ros.vision import default_rig, render_mask

    model = make_model(39)
    rig = default_rig(n_views=n_views, width=width, height=height)
    x = model.rest_pose()
    ends = capsule_endpoints(model, x[None])[0]
    masks = [render_mask(c, ends, model.capsule_radii) for c in rig.cameras]
    return model, rig, x, masks


def _sampled(downsample: int) -> None:
    from isa_mocap_ros.energy import SilhouetteEnergy
    from isa_mocap_ros.energy.restricted import RestrictedSilhouetteEnergy

    model, rig, x, masks = _scene()
    rng = np.random.default_rng(0)
    X = x + rng.normal(0.0, 0.02, (8, x.size))
    f = SilhouetteEnergy(model, rig, masks, method="fast", downsample=downsample, rng=np.random.default_rng(0))
    f(X)
    f(X[:1])
    coords = np.arange(x.size - 4, x.size)               # the last joints' coordinates: a limb moves
    Xr = np.repeat(x[None], 8, axis=0)
    Xr[:, coords] = X[:, coords]
    RestrictedSilhouetteEnergy(f, x, coords)(Xr)


def sampled_energy() -> None:
    """The sampled silhouette energy (``method="fast"``) on full-size masks (uint8): parallel and one-row
    (serial) batches, and its restricted evaluation."""
    _sampled(1)


def sampled_coverage() -> None:
    """The same on the area-averaged coverage (``downsample`` 2: float32, other signatures)."""
    _sampled(2)


def kinematics_batch() -> None:
    """The forward kinematics' parallel kernel (batches of :data:`.body.kinematics.SERIAL_BELOW` poses or more;
    the warm-ups' trackers call the serial one)."""
    from isa_mocap_ros.body import capsule_endpoints, joint_positions, make_model
    from isa_mocap_ros.body.kinematics import SERIAL_BELOW

    model = make_model(39)
    X = np.repeat(model.rest_pose()[None], max(2, SERIAL_BELOW), axis=0)
    joint_positions(model, X)
    capsule_endpoints(model, X)


def tracker_fast() -> None:
    """The tracker on the sampled energy (``track --energy fast``): the steps of the estimator's warm-up."""
    from isa_mocap_ros.tracking.config import TrackerConfig
    from isa_mocap_ros.tracking.realtime import warm_up

    model, _, _, _ = _scene()
    warm_up(model, TrackerConfig.from_flat(energy="fast"))


def mesh_render() -> None:
    """The triangle rasterizer of ``synth --body mesh`` (:func:`.vision.raster.render_mesh`), on a tetrahedron."""
    from isa_mocap_ros.vision import default_rig
    from isa_mocap_ros.vision.raster import mesh_mask, render_mesh

    cam = default_rig(n_views=1, width=80, height=60).cameras[0]
    verts = np.array([[0.0, 0.0, 0.6], [0.3, 0.0, 1.2], [0.0, 0.3, 1.2], [-0.2, -0.2, 1.6]])
    tris = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
    render_mesh(cam, verts, tris, np.full((4, 3), 200, np.uint8))
    mesh_mask(cam, verts, tris)


#: group name → the calls it makes, in order
GROUPS = {"sampled_energy": sampled_energy, "tracker_fast": tracker_fast, "sampled_coverage": sampled_coverage,
          "kinematics_batch": kinematics_batch, "mesh_render": mesh_render}


def main(argv: list[str] | None = None) -> int:
    names = sys.argv[1:] if argv is None else argv
    unknown = [n for n in names if n not in GROUPS]
    if unknown or not names:
        print(f"warmup_library: expected groups among {', '.join(GROUPS)}, got {' '.join(names) or 'none'}",
              file=sys.stderr)
        return 2
    for name in names:
        t0 = time.monotonic()
        GROUPS[name]()
        print(f"warmup_library: {name} done ({time.monotonic() - t0:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
