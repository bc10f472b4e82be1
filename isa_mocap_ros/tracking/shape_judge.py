"""The shape calibration's restarts judged by tracking (``ShapeCalibrationConfig.judge = "track"``).

By default (``judge = "fit"``) each restart of :func:`~.shape_calibration.calibrate_shape` is judged by the
silhouette energy of its own shape fit: its calibrated shape with its own poses on its own calibration
frames. On mesh bags that energy does not predict how well the shape tracks (a restart can fit its six frames
better with poses that the tracker does not find again). The ``"track"`` judge asks the question the shape is
for: each restart's shape tracks the first ``judge_frames`` frames from the automatic initialization with one
tracker seed for every restart, and the lowest mean tracker energy wins. See ``docs/shape_calibration.md``.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["tracked_energy"]


def tracked_energy(dof: int, cameras: Sequence, frames: Sequence, shape, tracker_config) -> float:
    """Mean tracker energy of ``frames`` ((key, masks, keypoints or None) each) tracked with the body ``shape``
    from the automatic initialization under ``tracker_config`` (its seed picks every random stream).

    A frame the tracker leaves without an estimate counts as the worst energy any frame reached (1.0 when
    none did): a shape that loses the person must not win by averaging fewer frames."""
    from isa_mocap_ros.body import make_model

    from .tracker import Tracker

    tr = Tracker(make_model(dof, shape=shape), cameras, tracker_config)
    energies = []
    for key, masks, kp in frames:
        r = tr.step(masks, int(key), keypoints=kp)
        energies.append(float(r.energy) if r.x is not None and np.isfinite(r.energy) else np.nan)
    e = np.array(energies, dtype=float)
    if not np.any(np.isfinite(e)):
        return 1.0
    return float(np.mean(np.where(np.isfinite(e), e, np.nanmax(e))))
