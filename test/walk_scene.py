"""Generated motions rendered into exact masks by the default rig: the synthetic scenes the tracker tests share."""
from __future__ import annotations

import numpy as np

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.body.motion import generate_motion
from isa_mocap_ros.vision import default_rig, render_mask


def motion_scene(motion: str, *, width: int, height: int, frames: int, duration_s: float, seed: int):
    """``(model, cameras, poses, masks)``: the first ``frames`` poses of a generated ``motion`` of
    ``duration_s`` (39 DOF, 30 fps, ``default_rng(seed)``) and per pose one mask per camera of
    ``default_rig(width, height)``."""
    model = make_model(39)
    rig = default_rig(width=width, height=height)
    poses = generate_motion(motion, model, duration_s=duration_s, fps=30, rng=np.random.default_rng(seed))[:frames]
    masks = [[render_mask(c, capsule_endpoints(model, x)[0], model.capsule_radii) for c in rig.cameras]
             for x in poses]
    return model, rig.cameras, poses, masks


def walk_scene(*, width: int, height: int, frames: int, duration_s: float, seed: int):
    """:func:`motion_scene` of a walk."""
    return motion_scene("walk", width=width, height=height, frames=frames, duration_s=duration_s, seed=seed)
