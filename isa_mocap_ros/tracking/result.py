"""What one :meth:`~.tracker.Tracker.step` produced (:class:`FrameResult`). Pure: no ROS import."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FrameResult"]


@dataclass(frozen=True, eq=False)
class FrameResult:
    """What one :meth:`Tracker.step` produced.

    Attributes
    ----------
    x : (D,) ndarray or None
        The estimate (None only when the tracker has never had an estimate: no usable masks yet).
    energy : float
        Energy of the estimate as the optimizer reports it (nan when no optimization ran).
    n_evals : int
        Evaluations this frame (initialization included).
    spread : float
        Final population spread (mean over coordinates of the standard deviation), nan if none.
    time_s : float
        Wall time of the call.
    views_used : int
        Views whose mask entered the energy.
    notes : tuple of str
        Everything skipped or replaced, and why (``"view 2: empty mask; skipped"``, ...); with the
        mask gate (``gate_margin_px``) also each view that lost more than :data:`~.config.GATE_NOTE_SHARE`
        of its foreground (``"view 1: the gate removed 812 of 2440 foreground pixels (33 %)"``).
    fell_back : bool
        True when no optimization ran and ``x`` is the last estimate.
    prediction : (D,) ndarray or None
        The prediction the search was centred on.
    initialized : bool
        True on the frame that ran the automatic initialization.
    """

    x: np.ndarray | None
    energy: float
    n_evals: int
    spread: float
    time_s: float
    views_used: int
    notes: tuple = ()
    fell_back: bool = False
    prediction: np.ndarray | None = None
    initialized: bool = False
