"""Correspondence energy with Plücker lines (ISA Eq. 13.30-13.31), the alternative data term.

Source: Gall et al., ISA §13.4.2, "Silhouette": 3-D-2-D correspondences ``(X_i, x_i)`` pair model
points on the contour of the *predicted* pose with their closest points on the extracted image
contour. Each image point ``x_i`` defines a projection ray, written as a Plücker line ``(n_i, m_i)``
(unit direction ``n_i``, moment ``m_i = c × n_i`` for the camera centre ``c``), so that
``x × n_i − m_i = 0`` for every point ``x`` on the ray and

    ‖x × n_i − m_i‖₂                                                               (13.30)

is the distance of ``x`` from the line. A model point moves with the kinematic chain above its limb,
and the pose error of a correspondence is (13.31)

    err_S(x, i) = ‖ (M(ω, t) M(θ_ι(1)) … M(θ_ι(s)) X_i)_{3×1} × n_i − m_i ‖₂.

Here the energy of a pose is the mean of ``err_S²`` over all correspondences of all usable views
(metres²). Choices (see ``docs/energy.md``):

* **Model contour points.** The predicted pose's silhouette is rendered per view; its outer contour
  (``cv2.findContours``, subsampled evenly to at most ``n_contour_points`` per view) is back-projected
  onto the visible capsule surface (capsule and depth at those pixels: ``render_labels_at``), and each
  point is stored in the frame of the joint that carries its capsule (both capsule end joints are fixed
  in that frame), so it moves rigidly with its limb.
* **Matching.** Each model contour pixel is matched to the closest pixel of the image contour
  (outer contours of the foreground mask, ``cv2.findContours``; :class:`scipy.spatial.cKDTree`),
  once, at construction (the ICP step of the paper without its iterations and optic flow).
"""
from __future__ import annotations

from typing import Any, Sequence

import cv2
import numpy as np
from scipy.spatial import cKDTree

from ..body import BodyModel, capsule_endpoints, forward_kinematics
from ..vision import Camera, capsule_data, render_labels_at, render_mask
from ..vision.render import pixel_rays
from ._checks import EnergyError, _check_cameras, _check_model, _check_poses
from .silhouette import mask_problem

__all__ = ["CorrespondenceEnergy", "plucker_lines", "pixel_plucker_lines", "model_contour_points", "capsule_frames", "mask_contour_pixels",
           "capsule_contour_points"]


def plucker_lines(camera: Camera, pixels: Any) -> tuple[np.ndarray, np.ndarray]:
    """Plücker lines of the projection rays of ``pixels``.

    Parameters
    ----------
    camera : Camera
    pixels : (m, 2) array_like
        Pixel coordinates ``(u, v)`` (lens distortion removed by :meth:`Camera.ray`).

    Returns
    -------
    n : (m, 3) ndarray
        Unit directions.
    moment : (m, 3) ndarray
        ``c × n`` with ``c`` the camera centre, so ``‖x × n − moment‖`` is the distance of ``x``
        from the ray's line (13.30).
    """
    uv = np.asarray(pixels, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise EnergyError(f"pixels: expected shape (m, 2), received shape {uv.shape}")
    c, d = camera.ray(uv[:, 0], uv[:, 1])
    d = np.asarray(d).reshape(-1, 3)
    return d, np.cross(c, d)


def pixel_plucker_lines(camera: Camera, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`plucker_lines` of integer pixels ``(m, 2)`` ``(u, v)`` inside the image, read from the renderer's
    per-camera ray table (:func:`~isa_mocap_ros.vision.render.pixel_rays`: :meth:`Camera.ray` at every pixel centre,
    built once per camera) instead of undistorting them again: the same numbers."""
    o, dirs, _ = pixel_rays(camera)
    d = dirs[pixels[:, 1] * camera.width + pixels[:, 0]]
    return d, np.cross(o, d)


def capsule_frames(model: BodyModel) -> np.ndarray:
    """``(C,)`` index of the joint frame in which both end joints of each capsule are fixed."""
    par = np.asarray(model.parents)
    out = np.empty(len(model.capsules), dtype=np.int64)
    for c, (a, b) in enumerate(np.asarray(model.capsules)):
        if par[b] == a:
            out[c] = a
        elif par[a] == b:
            out[c] = b
        elif par[a] == par[b] and par[a] >= 0:
            out[c] = par[a]
        elif a == b:
            out[c] = a
        else:  # pragma: no cover - every model capsule joins a parent and a child, or two siblings
            raise EnergyError(f"model: capsule {model.capsule_names[c]} is not rigid in one joint frame")
    return out


def mask_contour_pixels(mask: np.ndarray) -> np.ndarray:
    """``(k, 2)`` integer ``(u, v)`` of the outer contour pixels of a binary mask, in contour order."""
    contours, _ = cv2.findContours((mask > 0).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return np.zeros((0, 2), dtype=np.int64)
    return np.concatenate([c.reshape(-1, 2) for c in contours]).astype(np.int64)


def model_contour_points(model: BodyModel, camera: Camera, x: Any, *,
                         n_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Model points on the silhouette contour of pose ``x`` seen by ``camera``.

    Parameters
    ----------
    model : BodyModel
    camera : Camera
    x : (D,) array_like
        Finite pose.
    n_points : int
        At most this many points, evenly spaced along the contour.

    Returns
    -------
    pixels : (k, 2) int ndarray
        Contour pixels ``(u, v)`` of the rendered model silhouette.
    frames : (k,) int ndarray
        Joint frame carrying each point (see :func:`capsule_frames`).
    local : (k, 3) ndarray
        The surface point hit by the pixel's ray, in that joint's frame (metres).
    """
    x = np.asarray(x, dtype=np.float64)
    return capsule_contour_points(camera, capsule_endpoints(model, x)[0], model.capsule_radii,
                                  forward_kinematics(model, x)[0], capsule_frames(model), n_points)


def capsule_contour_points(camera: Camera, E: np.ndarray, radii, T: np.ndarray, cap_frames: np.ndarray,
                           n_points: int, capsules: tuple | None = None):
    """:func:`model_contour_points` from the pose's capsule end points ``E``, joint transforms ``T`` and
    :func:`capsule_frames` (computed once per pose for several views, as ``capsules``:
    :func:`~isa_mocap_ros.vision.capsule_data` of ``E``). The silhouette is rendered (rays stop at
    their first hit), the visible capsule and depth found at the chosen contour pixels only: the
    numbers :func:`~isa_mocap_ros.vision.render_labels` gives there, without labelling every pixel."""
    capsules = capsule_data(E, radii) if capsules is None else capsules
    pix = mask_contour_pixels(render_mask(camera, E, radii, capsules=capsules))
    if len(pix) > n_points:
        pix = pix[np.floor(np.arange(n_points) * (len(pix) / n_points)).astype(np.int64)]
    cap, z = render_labels_at(camera, E, radii, pix, capsules=capsules)
    z = z.astype(np.float64)
    c, d = camera.ray(pix[:, 0].astype(float), pix[:, 1].astype(float))
    d = np.asarray(d).reshape(-1, 3)
    X = c + (z / (d @ camera.R[2]))[:, None] * d       # depth is the camera-frame z of the hit
    frames = cap_frames[cap]
    Rf, pf = T[frames, :3, :3], T[frames, :3, 3]
    local = np.einsum("kji,kj->ki", Rf, X - pf)           # R^T (X - p)
    return pix, frames, local


class CorrespondenceEnergy:
    """Mean squared point-to-Plücker-line distance of contour correspondences (ISA 13.30-13.31).

    Parameters
    ----------
    model : BodyModel
    cameras : sequence of Camera (or a Rig)
    masks : sequence of (H, W) uint8 (or bool) or None
        Foreground masks of the frame, one per camera; ``None``, empty or wrongly sized masks are
        skipped (:attr:`skipped_views`), as are views where the predicted model has no contour.
    x_pred : (D,) array_like
        Predicted pose: its model contour is matched to the image contours.
    n_contour_points : int
        At most this many model contour points per view.

    Attributes
    ----------
    skipped_views : list of (int, str)
    n_views_used : int
    n_correspondences : int
    n_evals : int
        Poses evaluated (every row of every call).
    frames, local, directions, moments : ndarrays
        The correspondences: joint frame ``(K,)``, model point in that frame ``(K, 3)``, Plücker
        line ``(K, 3)`` + ``(K, 3)``.

    Notes
    -----
    ``energy(X (n, D)) -> (n,)`` in square metres; non-finite rows give ``+inf``.
    """

    def __init__(self, model: BodyModel, cameras: Sequence[Camera], masks: Sequence[Any], x_pred: Any, *,
                 n_contour_points: int = 200) -> None:
        self.model = _check_model(model)
        self.cameras = _check_cameras(cameras)
        if isinstance(n_contour_points, bool) or not isinstance(n_contour_points, (int, np.integer)) \
                or n_contour_points < 1:
            raise EnergyError(f"n_contour_points: expected an integer >= 1, received {n_contour_points!r}")
        xp = np.asarray(x_pred, dtype=np.float64) if x_pred is not None else np.zeros(0)
        if xp.shape != (model.dof,) or not np.all(np.isfinite(xp)):
            raise EnergyError(f"x_pred: expected a finite pose of shape ({model.dof},), received "
                              f"{'shape ' + str(xp.shape) if xp.shape != (model.dof,) else 'non-finite values'}")
        try:
            masks = list(masks)
        except TypeError as exc:
            raise EnergyError(f"masks: expected a sequence of {len(self.cameras)} masks, received "
                              f"{type(masks).__name__}") from exc
        if len(masks) != len(self.cameras):
            raise EnergyError(f"masks: expected {len(self.cameras)} masks (one per camera), received {len(masks)}")
        self.x_pred = xp
        self.skipped_views: list[tuple[int, str]] = []
        frames, local, dirs, moms = [], [], [], []
        for v, (mask, cam) in enumerate(zip(masks, self.cameras)):
            problem = mask_problem(mask, cam)
            if problem is not None:
                self.skipped_views.append((v, problem))
                continue
            pix, fr, loc = model_contour_points(model, cam, xp, n_points=int(n_contour_points))
            if len(pix) == 0:
                self.skipped_views.append((v, "the predicted model is not visible in this view"))
                continue
            image = mask_contour_pixels(np.asarray(mask))
            _, idx = cKDTree(image).query(pix.astype(float))
            n, m = plucker_lines(cam, image[idx].astype(float))
            frames.append(fr)
            local.append(loc)
            dirs.append(n)
            moms.append(m)
        if not frames:
            raise EnergyError("masks: expected at least one usable view, received none: "
                              + "; ".join(f"view {v}: {why}" for v, why in self.skipped_views))
        self.frames = np.concatenate(frames)
        self.local = np.concatenate(local)
        self.directions = np.concatenate(dirs)
        self.moments = np.concatenate(moms)
        self.n_views_used = len(frames)
        self.n_correspondences = len(self.frames)
        self.n_evals = 0

    def __call__(self, X: Any) -> np.ndarray:
        """Energies ``(n,)``: mean over correspondences of ``‖x_i(X) × n_i − m_i‖²`` (13.31)."""
        X, ok = _check_poses(self.model, X)
        self.n_evals += X.shape[0]
        out = np.full(X.shape[0], np.inf)
        if not ok.any():
            return out
        T = forward_kinematics(self.model, X[ok])                       # (n, J, 4, 4)
        R = T[:, self.frames, :3, :3]                                    # (n, K, 3, 3)
        p = T[:, :, :3, 3][:, self.frames]                               # (n, K, 3)
        x = p + np.einsum("nkij,kj->nki", R, self.local)                # model points moved with the pose
        err = np.cross(x, self.directions) - self.moments               # x × n − m  (13.30)
        out[ok] = np.einsum("nki,nki->n", err, err) / self.n_correspondences
        return out

    def __repr__(self) -> str:
        return (f"CorrespondenceEnergy(model={self.model.name!r}, views={self.n_views_used}/{len(self.cameras)}, "
                f"correspondences={self.n_correspondences})")
