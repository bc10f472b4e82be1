"""The tracker's objective as the optimizers see it (:class:`TotalEnergy`): data term plus the Parzen prior
``−η ln p(x)`` (13.33), the frame's weighted keypoint term (13.30-13.31) and the temporal term (off by default,
:mod:`~isa_mocap_ros.energy.temporal`), with ``restrict``; and the frame's keypoint term from the detections
(:func:`keypoint_energy`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["TotalEnergy", "keypoint_energy", "temporal_term"]


class TotalEnergy:
    """``E(X) = data(X) − η ln p(X) + w · keypoints(X)`` of poses ``X (n, D)`` under the tracker's current
    masks: the prior when ``TrackerConfig.objective.prior_eta > 0`` and the tracker has one, the keypoint
    term ``keypoint_term`` (or None) weighted by ``TrackerConfig.keypoints.keypoint_weight``.
    ``restrict(x_base, coords)`` gives the same values for poses equal to ``x_base`` outside ``coords``
    (the data term's ``restrict``; None when it has none), which ``Hierarchical`` asks for per partition."""

    def __init__(self, tracker, keypoint_term=None) -> None:
        self.tracker = tracker
        self.keypoint_term = keypoint_term
        # the frame's TemporalTerm (energy/temporal.py), set by the step once the prediction is made; None: off
        self.temporal_term = None

    @property
    def prior_active(self) -> bool:
        tr = self.tracker
        return tr.prior is not None and tr.config.objective.prior_eta > 0

    @property
    def extra_terms(self) -> bool:
        """Whether a term the compiled search does not take is active (the prior): the search then runs
        through the optimizer protocol on this objective."""
        return self.prior_active

    @property
    def weighted_keypoints(self):
        """``(keypoint term, its weight)`` for the compiled search, or None (no keypoint term this frame); with the
        temporal term, that term (and its weight) or both combined in one kernel term (weight 1)."""
        kw = self.tracker.config.keypoints.keypoint_weight
        if self.temporal_term is None:
            return None if self.keypoint_term is None else (self.keypoint_term, kw)
        tw = self.tracker.config.objective.temporal_weight
        if self.keypoint_term is None:
            return self.temporal_term, tw
        from isa_mocap_ros.energy.temporal import combined_term

        return combined_term([(self.keypoint_term, kw), (self.temporal_term, tw)]), 1.0

    def add_terms(self, X: np.ndarray, E: np.ndarray) -> np.ndarray:
        """``E`` (the data term of ``X``) plus the prior and the weighted keypoint term, if active."""
        tr = self.tracker
        if tr.prior is not None and tr.config.objective.prior_eta > 0:
            E = E + tr.prior.energy(X, eta=tr.config.objective.prior_eta)
        if self.keypoint_term is not None:
            E = E + tr.config.keypoints.keypoint_weight * self.keypoint_term(X)
        if self.temporal_term is not None:
            E = E + tr.config.objective.temporal_weight * self.temporal_term(X)
        return E

    def __call__(self, X) -> np.ndarray:
        X = np.atleast_2d(np.asarray(X, dtype=float))
        return self.add_terms(X, np.asarray(self.tracker.energy(X), dtype=float))

    def restrict(self, x_base, coords):
        restrict = getattr(self.tracker.energy, "restrict", None)
        data = restrict(x_base, coords) if callable(restrict) else None
        if data is None:
            return None

        def total(X):
            X = np.atleast_2d(np.asarray(X, dtype=float))
            return self.add_terms(X, np.asarray(data(X), dtype=float))
        return total


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


def temporal_term(tr, prediction) -> object | None:
    """The frame's :class:`~isa_mocap_ros.energy.temporal.TemporalTerm` around ``prediction`` (the joints
    ``TrackerConfig.objective.temporal_joints``, the keypoint term's loss scale), or None when the term is off."""
    obj = tr.config.objective
    if obj.temporal_weight <= 0 or prediction is None:
        return None
    from isa_mocap_ros.energy.temporal import TemporalTerm

    return TemporalTerm(tr.model, prediction, [j.strip() for j in obj.temporal_joints.split(",") if j.strip()],
                        sigma_m=tr.config.keypoints.keypoint_sigma_m)
