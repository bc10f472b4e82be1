"""The frame being tracked (:class:`FrameContext`): built once per step of one hypothesis
(:meth:`~.tracker.Tracker.frame_context`) and handed explicitly to the prediction (:mod:`.frame_prediction`),
the mask filters (:mod:`.frame_masks`), the searches and stages (:mod:`.stages`), the first frame
(:mod:`.first_frame`) and the heading check (:mod:`.heading`), which read no private state of the tracker.
Pure: no ROS import.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .config import frame_rng
from .objective import TotalEnergy
from .plan import FrameBudget

__all__ = ["FrameContext"]


@dataclass(eq=False)
class FrameContext:
    """One hypothesis' frame.

    Attributes
    ----------
    frame_index : int
        The frame key (index or stamp) of the frame's random streams.
    seed : int
        ``TrackerConfig.search.seed``: the streams are ``default_rng([seed, frame_index, ...])`` (:meth:`rng`).
    budget : FrameBudget
        The plan: what this hypothesis may spend on the frame and whether the contour stage runs.
    objective : TotalEnergy
        The energy the searches minimise this frame: data term, prior and the frame's keypoint term.
    external_prediction : (D,) array_like or None
        The prediction given to the step (e.g. the prediction node's), None for the tracker's own.
    notes : list of str
        What was skipped or replaced, and why (``FrameResult.notes``).
    raw_masks : list or None
        Per view the checked mask (None: unusable), before the mask gate and the hull filter.
    masks : list or None
        The filtered masks: what the energy scores and the contour stage fits.
    prediction : (D,) ndarray or None
        The frame's damped prediction, once made (:func:`.frame_prediction.prediction`).
    prediction_joints : (J, 3) ndarray or None
        Its joint positions, once computed (:func:`.frame_prediction.prediction_joints`: the gate's, the hull
        filter's and the view weights').
    weights : (V,) ndarray or None
        Eq. 5's view weights (``TrackerConfig.objective.view_weights``), None = views counted alike.
    after_gap : bool
        The prediction was made across a gap (:func:`.frame_prediction.recentre` moved its root): the limbs'
        phase is unknown, the search starts from the better side (:func:`.frame_prediction.better_side`).
    t0 : float
        ``time.perf_counter()`` when the step started.
    """

    frame_index: int
    seed: int
    budget: FrameBudget
    objective: TotalEnergy
    external_prediction: np.ndarray | None = None
    notes: list = field(default_factory=list)
    raw_masks: list | None = None
    masks: list | None = None
    prediction: np.ndarray | None = None
    prediction_joints: np.ndarray | None = None
    weights: np.ndarray | None = None
    after_gap: bool = False
    t0: float = 0.0

    def rng(self, *stream: int) -> np.random.Generator:
        """A fresh generator of the frame's stream ``default_rng([seed, frame_index, *stream])``."""
        return frame_rng(self.seed, self.frame_index, *stream)
