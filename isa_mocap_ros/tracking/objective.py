"""The tracker's objective as the optimizers see it: data term plus prior (and the frame's keypoint
term), with ``restrict``."""
from __future__ import annotations

import numpy as np


class TotalEnergy:
    """``tracker.total_energy`` with ``restrict`` (:meth:`Tracker.restricted_energy`), which
    ``Hierarchical`` asks for when a partition starts."""

    def __init__(self, tracker) -> None:
        self.tracker = tracker

    def __call__(self, X) -> np.ndarray:
        return self.tracker.total_energy(X)

    def restrict(self, x_base, coords):
        return self.tracker.restricted_energy(x_base, coords)


def keypoint_energy(tr, keypoints) -> tuple[object, str | None]:
    """The frame's :class:`~isa_mocap_ros.energy.KeypointEnergy` (or None) and a note on it."""
    if keypoints is None or tr.config.keypoints.keypoint_weight <= 0:
        return None, None
    from isa_mocap_ros.energy import KeypointEnergy
    try:
        term = KeypointEnergy(tr.model, tr.cameras, keypoints, sigma_m=tr.config.keypoints.keypoint_sigma_m)
    except ValueError as exc:
        return None, f"keypoints ignored: {exc}"
    if term.n_correspondences == 0:
        return None, "keypoints: none usable (no detection above the confidence floor)"
    return term, (f"keypoints: {term.n_correspondences} in {len(set(term.views.tolist()))} views, "
                  f"weight {tr.config.keypoints.keypoint_weight:g}")
