"""What one hypothesis carries from frame to frame (:class:`TrackState`): a :class:`~.tracker.Tracker`
holds one; when the heading check's rival wins, the tracker takes the rival's in one assignment.
Pure: no ROS import.
"""
from __future__ import annotations

import collections
from dataclasses import dataclass, field

import numpy as np

from .config import TRAVEL_FRAMES
from .predict import frames_kwargs

__all__ = ["TrackState", "HeadingCheckState"]


def _roots() -> collections.deque:
    return collections.deque(maxlen=TRAVEL_FRAMES + 1)


@dataclass(eq=False)
class TrackState:
    """The track of one hypothesis.

    Attributes
    ----------
    predictor : object
        The own predictor (``update(x)``, ``predict()``, ``reset()``), fed every accepted estimate.
    last : (D,) ndarray or None
        The last estimate (None before the first).
    elapsed : float
        Frame periods since the last estimate (``step``'s ``frames_elapsed``, summed).
    masks_last : list or None
        Usable masks of the last estimate's frame (re-centring).
    masks_now : list or None
        Usable (after the gate and the hull filter: filtered) masks of the frame being tracked.
    roots : deque of (clock, x, y)
        Root positions of the last ``TRAVEL_FRAMES + 1`` estimates (the heading check's travel cue).
    clock : float
        Frame periods since the start.
    """

    predictor: object
    last: np.ndarray | None = None
    elapsed: float = 0.0
    masks_last: list | None = None
    masks_now: list | None = None
    roots: collections.deque = field(default_factory=_roots)
    clock: float = 0.0

    def accept(self, x) -> None:
        """Take ``x`` as the frame's estimate: the predictor learns it, the clock and the root history
        advance, the frame's masks become the last estimate's."""
        self.last = np.array(x, dtype=float)
        self.predictor.update(self.last, **frames_kwargs(self.elapsed or 1))
        self.clock += self.elapsed or 1
        self.roots.append((self.clock, float(self.last[0]), float(self.last[1])))
        self.elapsed = 0.0
        self.masks_last = self.masks_now
        self.masks_now = None

    def forget(self) -> None:
        """Forget the estimates (the clock goes on)."""
        self.last = None
        self.elapsed = 0.0
        self.masks_last = None
        self.predictor.reset()
        self.roots.clear()


@dataclass(eq=False)
class HeadingCheckState:
    """The heading check's bookkeeping of a :class:`~.tracker.Tracker` (:mod:`.heading`); it stays with the
    tracker when the rival's :class:`TrackState` is taken over.

    Attributes
    ----------
    rival : Tracker or None
        The hypothesis heading the other way, tracked beside this one while a check runs.
    rival_start : (pose, energy, winner's energy) or None
        Where the rival starts (set on the initialized frame, used by the next step).
    confirm : list
        ``[frames compared, energy sum of this tracker, energy sum of the rival]``.
    views : int
        Views the heading was checked with (re-checked when more see the person).
    recheck_at : int or None
        ``Tracker.frames`` at which an undecided check is re-checked.
    rechecked_undecided : bool
        Whether that re-check ran.
    travel_recheck_after : int
        ``Tracker.frames`` from which the travel cue may start a re-check.
    gap_recheck_at : int or None
        ``Tracker.frames`` at which a check that a gap ended is re-checked (real time: the sets after its frame
        were dropped; the caller holds the next ones in sequence, :func:`.heading.heading_recheck_pending`).
    gap_rechecked : bool
        Whether a check that a gap ended was re-checked since the last check that decided (one re-check each).
    own_prediction_frames : int
        Frames left that ignore external predictions (after a switch).
    """

    rival: object = None
    rival_start: tuple | None = None
    confirm: list = field(default_factory=lambda: [0, 0.0, 0.0])
    views: int = 0
    recheck_at: int | None = None
    rechecked_undecided: bool = False
    travel_recheck_after: int = 0
    gap_recheck_at: int | None = None
    gap_rechecked: bool = False
    own_prediction_frames: int = 0
