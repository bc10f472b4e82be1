"""isa_mocap_ros.vision: cameras, calibration files, rigs, the capsule renderer and image distortions.

See ``docs/vision.md``. Modules: :mod:`.camera` (pinhole + distortion, ``look_at``,
``project_batch``), :mod:`.calibration` (camera_calibration-style YAML, rigs), :mod:`.render`
(ray-cast capsule renderer with exact silhouettes), :mod:`.background` (synthetic rooms, clothing
colours), :mod:`.distort` (the ISA paper's pixel noise and occluding rectangles, §13.4.2).
"""
from .errors import VisionError
from .camera import Camera, look_at, project_batch
from .calibration import (Rig, camera_from_dict, camera_to_dict, default_rig, load_camera, load_rig, ring_rig,
                          save_camera, save_rig)
from .background import clothing_colors, make_background
from .render import capsule_contains, capsule_data, render, render_labels, render_labels_at, render_mask
from .distort import occluders, pixel_noise

__all__ = ["VisionError", "Camera", "look_at", "project_batch", "Rig", "load_camera", "save_camera", "load_rig",
           "save_rig", "default_rig", "ring_rig", "camera_to_dict", "camera_from_dict", "make_background",
           "clothing_colors", "render", "render_mask", "render_labels", "render_labels_at", "capsule_data",
           "capsule_contains", "pixel_noise", "occluders"]
