"""Draw an estimated body on a camera image (for ``/mocap/cam<i>/overlay`` and run reports).

Pure OpenCV: the model's capsules are projected with the camera and drawn as thick bones with
joint dots; the silhouette mask, when given, is tinted underneath so fit errors are visible.
"""
from __future__ import annotations

import cv2
import numpy as np

from .camera import Camera


def draw_overlay(image: np.ndarray, camera: Camera, endpoints: np.ndarray, radii: np.ndarray, *,
                 mask: np.ndarray | None = None, color=(40, 255, 40)) -> np.ndarray:
    """Return a copy of ``image`` (H, W, 3) RGB with the capsules ``endpoints (C, 2, 3)`` drawn.

    Bone thickness follows the projected mean radius; points behind the camera are skipped.
    """
    img = np.ascontiguousarray(image[..., :3] if image.ndim == 3 else np.repeat(image[..., None], 3, 2)).copy()
    if mask is not None and mask.shape[:2] == img.shape[:2]:
        fg = mask > 0
        img[fg] = (0.6 * img[fg] + 0.4 * np.array([255, 60, 200])).astype(np.uint8)
    E = np.asarray(endpoints, dtype=float).reshape(-1, 2, 3)
    depth = camera.depth(E.reshape(-1, 3)).reshape(-1, 2)
    uv = camera.project(E.reshape(-1, 3)).reshape(-1, 2, 2)
    r = np.asarray(radii, dtype=float).reshape(-1, 2).mean(axis=1)
    for c in range(E.shape[0]):
        if np.any(depth[c] <= 0.05) or not np.all(np.isfinite(uv[c])):
            continue
        thick = int(np.clip(camera.fx * r[c] / depth[c].mean(), 1, 40))
        p0 = tuple(int(round(v)) for v in uv[c, 0])
        p1 = tuple(int(round(v)) for v in uv[c, 1])
        cv2.line(img, p0, p1, color, max(1, thick // 2), cv2.LINE_AA)
        cv2.circle(img, p0, max(2, thick // 3), (255, 255, 0), -1, cv2.LINE_AA)
        cv2.circle(img, p1, max(2, thick // 3), (255, 255, 0), -1, cv2.LINE_AA)
    return img
