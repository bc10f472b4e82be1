"""Keypoint correspondence energy: learned 2-D landmarks to model joints via Plücker lines (ISA 13.30-13.31).

Source: Gall et al., ISA §13.4.2. A 2-D image point ``x_i`` defines its projection ray as a Plücker
line ``(n_i, m_i)`` (unit direction, moment ``c × n_i``); the distance of a 3-D point ``X`` from it is

    ‖X × n_i − m_i‖₂                                                               (13.30)

and the pose error of a correspondence whose model point moves with the kinematic chain is (13.31)

    err(x, i) = ‖ X_{j(i)}(x) × n_i − m_i ‖₂ .

Here the correspondences are not contour matches but learned keypoints: landmark ``l`` of the
BlazePose model (:mod:`isa_mocap_ros.vision.landmarks`) detected in view ``v`` pairs the model's joint
centre ``X_{j(l)}(x)`` (:data:`LANDMARK_TO_JOINT`) with the ray through the detected pixel. The energy
of a pose is the confidence-weighted mean of a robust loss of those distances (metres)::

    E(x) = Σ_{v,l} w_vl ρ(err_vl(x)) / Σ_{v,l} w_vl,    ρ(d) = d² / (d² + σ²)       (Geman-McClure)

``w_vl`` is the detection's confidence (pose score × visibility × presence); detections below
``min_confidence`` are dropped. ρ grows like ``(d/σ)²`` near 0 and is bounded by 1, so one wrong
detection (a swapped or misplaced landmark in one view) can add at most its weight share to the
energy and stops pulling once it is a few σ away: the other views decide. ``E`` lies in ``[0, 1)``.

Mapping (documented in ``docs/keypoints.md``): shoulders, elbows, wrists, hips, knees, ankles and
foot tips (BlazePose ``*_foot_index`` → our ``*_toe``), left to left: the 14 landmarks whose position
relative to a joint centre of our models is nearly fixed. Face and hand landmarks are not used. The
left/right labels of the detector are what separates front from back, which silhouettes cannot.
"""
from __future__ import annotations

import copy
from typing import Any, Sequence

import numpy as np

from ..body import BodyModel, joint_positions
from ..body.kinematics import kernel_tables
from ..vision import Camera
from ..vision.landmarks import LANDMARK_NAMES, N_LANDMARKS
from .correspondence import plucker_lines
from .keypoint_kernel import KeypointTerm, keypoint_batch
from ._checks import EnergyError, _check_cameras, _check_model, _check_poses

__all__ = ["LANDMARK_TO_JOINT", "KeypointEnergy", "geman_mcclure"]

#: BlazePose landmark name -> model joint name (only joints the model has are used).
LANDMARK_TO_JOINT: dict[str, str] = {
    "left_shoulder": "left_shoulder", "right_shoulder": "right_shoulder",
    "left_elbow": "left_elbow", "right_elbow": "right_elbow",
    "left_wrist": "left_wrist", "right_wrist": "right_wrist",
    "left_hip": "left_hip", "right_hip": "right_hip",
    "left_knee": "left_knee", "right_knee": "right_knee",
    "left_ankle": "left_ankle", "right_ankle": "right_ankle",
    "left_foot_index": "left_toe", "right_foot_index": "right_toe",
}


def geman_mcclure(d2: np.ndarray, sigma: float) -> np.ndarray:
    """ρ from squared distances: ``d² / (d² + σ²)``."""
    return d2 / (d2 + sigma * sigma)


class KeypointEnergy:
    """Robust, confidence-weighted distance of model joints to the rays of detected 2-D keypoints.

    Parameters
    ----------
    model : BodyModel
    cameras : sequence of Camera (or a Rig)
    keypoints : sequence of (uv (33, 2), confidence (33,)) or None
        One entry per camera: the detected pixel coordinates and confidences in ``[0, 1]``
        (:attr:`~isa_mocap_ros.vision.landmarks.Landmarks2D.confidence`); ``None`` = no detection in
        that view. Non-finite or out-of-range entries drop that landmark.
    sigma_m : float
        Scale of the Geman-McClure loss in metres (distance from a ray at which a keypoint's
        influence peaks; beyond a few σ it stops pulling).
    min_confidence : float
        Detections with a lower confidence are dropped.

    Attributes
    ----------
    joints, directions, moments, weights : ndarrays
        The correspondences: model joint index ``(K,)``, Plücker line ``(K, 3)`` + ``(K, 3)``,
        weight ``(K,)`` (summing to 1).
    views : (K,) int ndarray
        Camera of each correspondence.
    pixels : (K, 2) ndarray
        The detected pixel of each correspondence (as given, distortion not removed).
    confidences : (K,) ndarray
        Each correspondence's detection confidence (the weights before they are normalized).
    n_evals : int
        Poses evaluated.

    Notes
    -----
    ``energy(X (n, D)) -> (n,)``; non-finite rows give ``+inf``. With no usable correspondence the
    energy is 0 everywhere (:attr:`n_correspondences` is 0): a term that knows nothing adds nothing.
    """

    def __init__(self, model: BodyModel, cameras: Sequence[Camera], keypoints: Sequence[Any], *,
                 sigma_m: float = 0.1, min_confidence: float = 0.5) -> None:
        self.model = _check_model(model)
        self.cameras = _check_cameras(cameras)
        if not np.isfinite(sigma_m) or sigma_m <= 0:
            raise EnergyError(f"sigma_m: expected a positive number of metres, received {sigma_m!r}")
        if not 0.0 <= min_confidence <= 1.0:
            raise EnergyError(f"min_confidence: expected a number in [0, 1], received {min_confidence!r}")
        try:
            keypoints = list(keypoints)
        except TypeError as exc:
            raise EnergyError(f"keypoints: expected a sequence of {len(self.cameras)} entries, received "
                              f"{type(keypoints).__name__}") from exc
        if len(keypoints) != len(self.cameras):
            raise EnergyError(f"keypoints: expected {len(self.cameras)} entries (one per camera), received "
                              f"{len(keypoints)}")
        self.sigma_m = float(sigma_m)
        names = set(model.joint_names)
        pairs = [(LANDMARK_NAMES.index(lm), model.joint_names.index(j)) for lm, j in LANDMARK_TO_JOINT.items()
                 if j in names]
        lm_idx = np.array([p[0] for p in pairs], dtype=np.int64)
        jt_idx = np.array([p[1] for p in pairs], dtype=np.int64)
        joints, dirs, moms, w, views, pix = [], [], [], [], [], []
        for v, (entry, cam) in enumerate(zip(keypoints, self.cameras)):
            if entry is None:
                continue
            try:
                uv, conf = entry
                uv = np.asarray(uv, dtype=np.float64)
                conf = np.asarray(conf, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise EnergyError(f"keypoints[{v}]: expected (uv (33, 2), confidence (33,)) or None") from exc
            if uv.shape != (N_LANDMARKS, 2) or conf.shape != (N_LANDMARKS,):
                raise EnergyError(f"keypoints[{v}]: expected uv (33, 2) and confidence (33,), received "
                                  f"{uv.shape} and {conf.shape}")
            u, c = uv[lm_idx], conf[lm_idx]
            ok = np.all(np.isfinite(u), axis=1) & np.isfinite(c) & (c >= min_confidence) & (c <= 1.0)
            if not ok.any():
                continue
            n, m = plucker_lines(cam, u[ok])
            joints.append(jt_idx[ok])
            dirs.append(n)
            moms.append(m)
            w.append(c[ok])
            pix.append(u[ok])
            views.append(np.full(int(ok.sum()), v, dtype=np.int64))
        cat = (lambda a, shape: np.concatenate(a) if a else np.zeros(shape))
        self.joints = cat(joints, (0,)).astype(np.int64)
        self.directions = np.ascontiguousarray(cat(dirs, (0, 3)))
        self.moments = np.ascontiguousarray(cat(moms, (0, 3)))
        self.confidences = cat(w, (0,))
        self.pixels = cat(pix, (0, 2))
        self.views = cat(views, (0,)).astype(np.int64)
        self._finish()

    def _finish(self) -> None:
        c = self.confidences
        self.weights = np.ascontiguousarray(c / c.sum() if len(c) else c)
        self.n_correspondences = len(self.joints)
        self.n_evals = 0

    def subset(self, keep: Any) -> "KeypointEnergy":
        """A copy with only the correspondences where ``keep (K,)`` is true, weights normalized again (what a
        screen of the detections against other evidence keeps: :mod:`isa_mocap_ros.tracking.keypoint_screen`)."""
        keep = np.asarray(keep, dtype=bool)
        if keep.shape != (self.n_correspondences,):
            raise EnergyError(f"keep: expected shape ({self.n_correspondences},), received {keep.shape}")
        out = copy.copy(self)
        for name in ("joints", "directions", "moments", "confidences", "pixels", "views"):
            setattr(out, name, np.ascontiguousarray(getattr(self, name)[keep]))
        out._finish()
        return out

    def distances(self, X: Any) -> np.ndarray:
        """``(n, K)`` point-to-ray distances ``err(x, i)`` (13.31) in metres; rows of non-finite poses are inf."""
        X, ok = _check_poses(self.model, X)
        out = np.full((X.shape[0], self.n_correspondences), np.inf)
        if ok.any() and self.n_correspondences:
            P = joint_positions(self.model, X[ok])[:, self.joints]          # (n, K, 3)
            err = np.cross(P, self.directions) - self.moments                 # X × n − m  (13.30)
            out[ok] = np.sqrt(np.einsum("nki,nki->nk", err, err))
        return out

    def __call__(self, X: Any) -> np.ndarray:
        """Energies ``(n,)``: Σ w ρ(err²) with the Geman-McClure ρ (compiled: :mod:`.keypoint_kernel`, the
        same function the compiled search calls)."""
        X, ok = _check_poses(self.model, X)
        self.n_evals += X.shape[0]
        out = np.where(ok, 0.0, np.inf)
        if not self.n_correspondences or not ok.any():
            return out
        E = np.empty(int(ok.sum()))
        keypoint_batch(np.ascontiguousarray(X[ok]), *self.kernel_term(1.0)[:-1], E)
        out[ok] = E
        return out

    def kernel_term(self, scale: float) -> KeypointTerm:
        """This term weighted by ``scale`` as the compiled kernel takes it (:class:`KeypointTerm`; the compiled
        search adds ``scale`` times :func:`keypoint_batch` to the silhouette energy)."""
        return KeypointTerm(*kernel_tables(self.model), self.joints, self.directions, self.moments, self.weights,
                            self.sigma_m, float(scale))

    def __repr__(self) -> str:
        return (f"KeypointEnergy(model={self.model.name!r}, correspondences={self.n_correspondences}, "
                f"views={len(set(self.views.tolist()))}/{len(self.cameras)}, sigma_m={self.sigma_m})")
