"""The tracker's objective as the optimizers see it: data term plus prior, with ``restrict``."""
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
