"""Masks of a distorted camera resampled onto its pinhole image, for the scanline count (:mod:`.raster_kernel`).

The scanline kernel fills pixel rows of the undistorted image plane: a row of pixels is a straight line there
only without lens distortion. For a camera with distortion, :class:`~.silhouette.SilhouetteEnergy` with
``method="raster"`` counts on the camera's **pinhole twin** (:func:`pinhole`: the same size, ``K`` and pose,
no distortion) and resamples each frame's mask onto it once (:func:`undistort_mask`): pixel ``(u, v)`` of the
pinhole image reads the mask at the distorted position of its ray,
``K distort(K^-1 (u, v, 1))`` (OpenCV's model, the one :class:`~isa_mocap_ros.vision.Camera` projects with,
``cv2.initUndistortRectifyMap`` with the same ``K`` as the new camera). The maps are built once per camera
geometry (:meth:`Camera.key`) and kept (:data:`MAX_CACHED` cameras); per mask one ``cv2.remap``.

The mask is read bilinearly and thresholded at one half (a pixel is foreground when the mask is at least half
foreground around its source point): the silhouette's outline is placed to a fraction of a pixel rather than
rounded to the nearest source pixel. Pinhole pixels whose source lies outside the image read background (with
barrel distortion, ``k1 < 0``, there are none or a thin rim at the corners).
"""
from __future__ import annotations

import cv2
import numpy as np

from ..vision import Camera

__all__ = ["MAX_CACHED", "pinhole", "undistort_mask"]

#: camera geometries whose remap tables are kept (a rig has a few cameras; more are rebuilt when needed)
MAX_CACHED = 32
_MAPS: dict = {}


def pinhole(camera: Camera) -> Camera:
    """``camera`` without lens distortion (itself when it has none): the image its masks are resampled onto."""
    if not camera.has_distortion:
        return camera
    return Camera(camera.name, camera.width, camera.height, camera.K, np.zeros(5), camera.R, camera.t)


def _maps(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """The fixed-point remap tables of ``camera`` onto its pinhole twin (built once per geometry)."""
    key = camera.key()
    maps = _MAPS.get(key)
    if maps is None:
        if len(_MAPS) >= MAX_CACHED:
            _MAPS.clear()
        K = np.asarray(camera.K, dtype=np.float64)
        m1, m2 = cv2.initUndistortRectifyMap(K, np.asarray(camera.dist, dtype=np.float64), None, K,
                                             (camera.width, camera.height), cv2.CV_32FC1)
        maps = _MAPS[key] = cv2.convertMaps(m1, m2, cv2.CV_16SC2)
    return maps


def undistort_mask(camera: Camera, mask: np.ndarray) -> np.ndarray:
    """``mask (H, W)`` (nonzero = foreground, ``camera``'s size) resampled onto :func:`pinhole` ``(camera)``'s
    image: ``(H, W)`` bool. Without distortion the mask itself as bool."""
    m = np.asarray(mask)
    if not camera.has_distortion:
        return m if m.dtype == np.bool_ else m != 0
    F = m != 0
    if F.shape != (camera.height, camera.width):
        raise ValueError(f"mask: expected shape {(camera.height, camera.width)} for camera {camera.name}, received "
                         f"{F.shape}")
    m1, m2 = _maps(camera)
    out = cv2.remap(F.view(np.uint8) * np.uint8(255), m1, m2, interpolation=cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out >= 128
