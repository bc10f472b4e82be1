"""Energies of the pose search (minimised; batch form ``energy(X (n, D)) -> (n,)``).

* :class:`SilhouetteEnergy` — silhouette overlap per view (EA-vs-PF Eq. 4) averaged over views
  (Eq. 5): a fast compiled estimate and the exact raster reference (:func:`exact_view_energy`).
* :class:`CorrespondenceEnergy` — mean squared distance of model contour points to the Plücker
  lines of their matched image contour points (ISA Eq. 13.30-13.31).
* :class:`KeypointEnergy` — robust, confidence-weighted distance of model joints to the Plücker
  lines of learned 2-D keypoints (ISA Eq. 13.30-13.31 with BlazePose landmarks; docs/keypoints.md).
* :class:`ParzenPrior` — the Parzen-Rosenblatt pose prior (ISA Eq. 13.32-13.33).

See ``docs/energy.md`` and ``docs/segmentation_prior_prediction.md``.
"""
from .silhouette import EnergyError, SilhouetteEnergy, exact_view_energy
from .correspondence import CorrespondenceEnergy, model_contour_points, plucker_lines
from .keypoints import LANDMARK_TO_JOINT, KeypointEnergy
from .prior import ParzenPrior, PriorError

__all__ = ["EnergyError", "SilhouetteEnergy", "exact_view_energy", "CorrespondenceEnergy", "plucker_lines",
           "model_contour_points", "KeypointEnergy", "LANDMARK_TO_JOINT", "ParzenPrior", "PriorError"]
