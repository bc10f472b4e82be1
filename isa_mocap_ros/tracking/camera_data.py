"""The per-camera data of the tracker's frames, built once when it gets its cameras (pure, no ROS).

The renderer's rays and tile cones (:func:`isa_mocap_ros.vision.render.pixel_rays`: the contour stage, the exact
silhouettes) and the visual-hull filter's rays and pinhole maps (:func:`.hull.prepare_cameras`) depend on the
calibration only and are cached per camera geometry (:meth:`Camera.key`). Built at first use they fell on the
start-up's frames: ~20-24 ms per 320x240 camera for the renderer's on the initialized frame (its polish runs the
tracker's first contour stage) and ~20 ms for the hull filter's on the next frame, measured under load
(docs/history/issue35_speed.md, session 27). :class:`~.tracker.Tracker` calls :func:`prepare_cameras` when it is
made; the estimator node calls it earlier, while its worker waits, on the cameras the camera_infos announce, so the
tracker it makes on the first frame set finds them built (docs/nodes.md, "Start-up"). The data are the same arrays
either way (the tracks are bit-identical).
"""
from __future__ import annotations

from typing import Sequence

from isa_mocap_ros.vision.camera import Camera
from isa_mocap_ros.vision.render import pixel_rays

from . import hull

__all__ = ["prepare_cameras"]


def prepare_cameras(cameras: Sequence, config=None) -> None:
    """Build the renderer's per-camera data of ``cameras`` and, unless ``config`` (a
    :class:`~.config.TrackerConfig`) turns the hull filter off, the hull filter's (objects other than a
    :class:`~isa_mocap_ros.vision.camera.Camera` are left to fail where they are used, with that use's message)."""
    cams = [c for c in cameras if isinstance(c, Camera)]
    for cam in cams:
        pixel_rays(cam)
    if config is None or config.masks.hull_filter:
        hull.prepare_cameras(cams)
