"""Offline zero-phase smoothing of a tracked pose sequence (``isa-mocap track --smooth-hz F``).

Markerless systems filter their 3-D result after the whole recording is in: Pose2Sim low-passes its
triangulated points with a Butterworth filter (order 4, 6 Hz for the demo of ``docs/real_cameras.md``) run
forward and backward, so that the filter shifts nothing in time (``scipy.signal.filtfilt``). The same filter here
acts on the pose vectors: root translation, the root's rotation vector (made continuous first: of the vectors that
give one rotation, ``r + 2πk r/|r|``, each frame takes the one nearest its predecessor's), joint angles (clipped to
the model's limits afterwards). A zero-phase filter needs the frames after each one, so this is an option for an
offline result; the tracker and the node network estimate one frame at a time, unsmoothed.
"""
from __future__ import annotations

import numpy as np

__all__ = ["SmoothError", "continuous_rotation_vectors", "smooth_poses", "zero_phase_lowpass"]


class SmoothError(ValueError):
    """Bad arguments to :func:`smooth_poses` (names the argument)."""


def continuous_rotation_vectors(r: np.ndarray) -> np.ndarray:
    """``(F, 3)`` rotation vectors, each replaced by the equivalent ``r + 2πk r/|r|`` (k = -1, 0, 1) nearest the
    previous frame's (the same rotations, no jump of 2π where the angle passes π)."""
    r = np.array(r, dtype=float)
    for f in range(1, len(r)):
        n = np.linalg.norm(r[f])
        if n < 1e-12:
            continue
        cands = r[f][None] + (2.0 * np.pi * np.array([-1.0, 0.0, 1.0]))[:, None] * (r[f] / n)[None]
        r[f] = cands[np.argmin(np.linalg.norm(cands - r[f - 1], axis=1))]
    return r


def smooth_poses(model, X, fps: float, cutoff_hz: float, *, order: int = 4) -> np.ndarray:
    """Poses ``X`` ((F, D), consecutive frames at ``fps``) low-passed at ``cutoff_hz`` with a zero-phase
    Butterworth filter of ``order`` (module docstring). Fewer than 4 frames come back unchanged."""
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] != model.dof:
        raise SmoothError(f"poses: expected shape (F, {model.dof}), received {X.shape}")
    if not (np.isfinite(fps) and fps > 0):
        raise SmoothError(f"fps: expected a frame rate > 0, received {fps}")
    if not (np.isfinite(cutoff_hz) and 0 < cutoff_hz < fps / 2):
        raise SmoothError(f"cut-off: expected 0 < Hz < half the frame rate ({fps / 2:g} Hz), received {cutoff_hz}")
    if len(X) < 4:
        return X.copy()
    Y = X.copy()
    Y[:, 3:6] = continuous_rotation_vectors(X[:, 3:6])
    Y = zero_phase_lowpass(Y, fps, cutoff_hz, order=order)
    Y[:, 6:] = np.clip(Y[:, 6:], model.lower[6:], model.upper[6:])
    return Y


def zero_phase_lowpass(Y, fps: float, cutoff_hz: float, *, order: int = 4) -> np.ndarray:
    """``Y`` (frames along axis 0, at ``fps``) through a Butterworth low-pass of ``order`` at ``cutoff_hz``, run
    forward and backward (``scipy.signal.filtfilt``; its padding shortened to the sequence when that is shorter):
    Pose2Sim's filter of its points, used by :func:`smooth_poses` and by ``bench real``'s like-for-like figure."""
    from scipy.signal import butter, filtfilt

    b, a = butter(int(order), cutoff_hz / (fps / 2.0))
    return filtfilt(b, a, Y, axis=0, padlen=min(3 * max(len(a), len(b)), len(Y) - 1))
