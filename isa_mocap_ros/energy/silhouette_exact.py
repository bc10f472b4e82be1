"""EA-vs-PF Eq. 4 literally (the exact raster reference of :mod:`.silhouette`) and the mask checks it shares.

:func:`exact_view_energy` rasterizes the model's silhouette with :func:`isa_mocap_ros.vision.render_mask`
(pixel-centre rays against the exact capsule solids) and counts pixels; :class:`.silhouette.SilhouetteEnergy`
uses it with ``method="exact"`` and as the reference its compiled estimate is measured against.
"""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from ..body import BodyModel, capsule_endpoints
from ..vision import Camera, render_mask
from ._checks import EnergyError, _check_model, _check_poses

__all__ = ["exact_view_energy", "mask_problem", "core_weights"]


def _foreground(mask: np.ndarray) -> np.ndarray:
    return np.asarray(mask) > 0


def mask_problem(mask: Any, camera: Camera) -> str | None:
    """Why ``mask`` cannot be used for ``camera`` (None: usable)."""
    if mask is None:
        return "no mask (view missing)"
    m = np.asarray(mask)
    if m.dtype == object or not (np.issubdtype(m.dtype, np.number) or m.dtype == np.bool_):
        return f"mask of dtype {m.dtype}, expected uint8 or bool"
    if m.shape != (camera.height, camera.width):
        return f"mask of shape {m.shape}, expected ({camera.height}, {camera.width}) for camera {camera.name}"
    if not (m.any() if m.dtype == np.uint8 or m.dtype == np.bool_ else np.any(m > 0)):   # unsigned: nonzero = > 0
        return "empty mask (nobody in view)"
    return None


def core_weights(F: np.ndarray, core_px: float) -> np.ndarray | None:
    """Weights ``(H, W)`` of the foreground pixels in term 2 of Eq. 4: ``min(1, d / core_px)``, ``d`` a
    pixel's distance to the background (1 at the silhouette's edge; ``cv2.distanceTransform``, exact L2);
    None when ``core_px <= 1`` (every pixel counts 1: Eq. 4 as printed)."""
    if core_px <= 1.0:
        return None
    d = cv2.distanceTransform(F.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.minimum(1.0, d.astype(np.float64) / core_px) * F


def _view_terms(camera: Camera, F: np.ndarray, n_fg: int, E: np.ndarray, radii: np.ndarray,
                core: np.ndarray | None = None) -> np.ndarray:
    """Eq. 4 for each pose: ``E (n, C, 2, 3)`` end points, ``F (H, W)`` bool foreground; ``core`` the
    foreground pixels' weights in term 2 (:func:`core_weights`; None: all 1)."""
    out = np.empty(E.shape[0])
    for i in range(E.shape[0]):
        M = render_mask(camera, E[i], radii) > 0
        n_model = int(np.count_nonzero(M))
        if core is None:
            miss = int(np.count_nonzero(F & ~M))        # Σ_{p ∈ D(F)} F(p) − M(x, p)
        else:
            miss = float(core[~M].sum()) / float(core.sum()) * n_fg
        if n_model == 0:
            out[i] = 0.5 + 0.5 * miss / n_fg
            continue
        off = int(np.count_nonzero(M & ~F))         # Σ_{p ∈ D(M)} M(x, p) − F(p)
        out[i] = 0.5 * off / n_model + 0.5 * miss / n_fg
    return out


def exact_view_energy(model: BodyModel, camera: Camera, mask: Any, X: Any) -> np.ndarray:
    """Eq. 4 for one view, literally: rasterize the model's silhouette and count pixels.

    Parameters
    ----------
    model : BodyModel
    camera : Camera
        The view; ``mask`` must have its size.
    mask : (H, W) uint8 or bool
        Foreground (nonzero = 1); must hold at least one foreground pixel.
    X : (n, D) or (D,) array_like
        Finite pose vectors.

    Returns
    -------
    f : (n,) ndarray
        ``f_v(x)`` in ``[0, 1]``; 1 when the model has no pixel in the view.
    """
    model = _check_model(model)
    if not isinstance(camera, Camera):
        raise EnergyError(f"camera: expected a Camera, received {type(camera).__name__}")
    problem = mask_problem(mask, camera)
    if problem is not None:
        raise EnergyError(f"mask: expected a non-empty ({camera.height}, {camera.width}) uint8 mask, "
                          f"received {problem}")
    X, ok = _check_poses(model, X)
    if not ok.all():
        raise EnergyError(f"X: expected finite poses, received non-finite values in row {int(np.argmin(ok))}")
    F = _foreground(mask)
    E = capsule_endpoints(model, X)
    return _view_terms(camera, F, int(np.count_nonzero(F)), E, np.asarray(model.capsule_radii, dtype=np.float64))
