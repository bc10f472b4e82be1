"""Which images a background model learns from: the first ``learn_frames`` frame *periods*, by stamp.

A :class:`~isa_mocap_ros.vision.segmentation.BackgroundSegmenter` learns its background from the first
``learn_frames`` images it is given. Fed by a node in real time, images get lost (a best-effort queue, a
busy core): counted by images, the learning then runs into the frames after the empty ones, and the person
there becomes part of the background. :class:`LearningWindows` bounds the learning in time instead: a model
learns only from images stamped within ``learn_frames`` frame periods of the first image of its frame sets,

    round((t - t0) / T) < learn_frames,      i.e.   t < t0 + (learn_frames - 1/2) T,

with ``t0`` the model's first stamp, or an earlier window's start of another view's model still learning
(at most ``learn_frames`` periods before it), so a view that lost the first image ends its window where
the others do. The first image past the window
ends the learning on the images received so far (:meth:`BackgroundSegmenter.finish_learning`); with every
image arriving (lockstep, offline) the count ends it first and nothing changes.

The period ``T``: ``frame_rate`` when given (Hz), else the smallest positive gap between two stamps of one
view seen so far, up to ``MAX_PERIOD_NS`` (the frame period as soon as two consecutive frames of a view arrived;
before that every image is inside). Gaps are taken within a view: cameras that do not share stamps give no
short gaps.

Pure (no ROS): the segmentation node holds one per node, shared by its views.
"""
from __future__ import annotations

import bisect
import weakref

__all__ = ["LearningWindows"]

#: distinct stamps kept per view for the period (the first ones of a stream)
MAX_STAMPS = 256
#: longer gaps between a view's stamps are not frame periods (a stream restart, a stray image)
MAX_PERIOD_NS = 1_000_000_000


class LearningWindows:
    """Learning windows by stamp for the background models of a node's views.

    Parameters
    ----------
    learn_frames : int
        Frame periods in a window (the models' ``learn_frames``).
    frame_rate : float
        Frames per second of the cameras; 0 = the smallest gap between the stamps seen.

    Examples
    --------
    >>> w = LearningWindows(3, frame_rate=10.0)
    >>> m = type("Model", (), {"learning": True})()
    >>> [w.admits(m, t) for t in (0, 100_000_000, 300_000_000)]    # the frame of 200 ms was lost
    [True, True, False]
    >>> w.learnt(m)
    [0, 100000000]
    """

    def __init__(self, learn_frames: int, *, frame_rate: float = 0.0) -> None:
        if learn_frames < 1:
            raise ValueError(f"learn_frames: expected >= 1, got {learn_frames}")
        if not frame_rate >= 0.0:
            raise ValueError(f"frame_rate: expected >= 0 (0 = from the stamps), got {frame_rate}")
        self.learn_frames = int(learn_frames)
        self.fixed_period_ns = int(round(1e9 / frame_rate)) if frame_rate > 0 else 0
        self._view_stamps: dict = {}            # view -> its sorted distinct stamps (the first MAX_STAMPS)
        self._gap_ns = 0                        # the smallest positive gap between two stamps of one view
        self._starts: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()   # model -> [t0, stamps learnt]

    def period_ns(self) -> int:
        """The frame period in ns (0 = not known yet)."""
        return self.fixed_period_ns or self._gap_ns

    def observe(self, stamp_ns: int, view=0) -> None:
        """Note a stamp seen in ``view`` (for the period: gaps within a view, whose cameras need not share
        stamps)."""
        own = self._view_stamps.setdefault(view, [])
        i = bisect.bisect_left(own, stamp_ns)
        if i < len(own) and own[i] == stamp_ns:
            return
        for j in (i - 1, i):
            if 0 <= j < len(own):
                gap = abs(own[j] - stamp_ns)
                if gap > MAX_PERIOD_NS:
                    continue
                self._gap_ns = gap if self._gap_ns == 0 else min(self._gap_ns, gap)
        if len(own) < MAX_STAMPS:
            own.insert(i, stamp_ns)

    def end_ns(self, model) -> int | None:
        """The stamp from which on ``model`` learns no more (None: no window yet or the period unknown)."""
        entry, T = self._starts.get(model), self.period_ns()
        if entry is None or T == 0:
            return None
        return entry[0] + (2 * self.learn_frames - 1) * T // 2

    def admits(self, model, stamp_ns: int, view=0) -> bool:
        """Whether the learning ``model`` may learn from the image of ``stamp_ns`` (recorded when it may).

        Its first image opens its window: at its stamp, or at the earliest start of another model's window
        still learning (``model.learning``) at most ``learn_frames`` periods before it (a first image this view
        lost)."""
        self.observe(stamp_ns, view)
        entry = self._starts.get(model)
        if entry is None:
            span = self.learn_frames * self.period_ns()
            t0 = min([stamp_ns] + [e[0] for m, e in list(self._starts.items())
                                   if getattr(m, "learning", True) and stamp_ns - span <= e[0] <= stamp_ns])
            entry = self._starts[model] = [t0, []]
        end = self.end_ns(model)
        if end is not None and stamp_ns >= end:
            return False
        entry[1].append(stamp_ns)
        return True

    def restart(self, model, stamp_ns: int) -> None:
        """Open ``model``'s window afresh at ``stamp_ns`` (it had learnt nothing when its window closed)."""
        self._starts[model] = [stamp_ns, [stamp_ns]]

    def start_ns(self, model) -> int | None:
        """The first stamp of ``model``'s window (None before its first image)."""
        entry = self._starts.get(model)
        return None if entry is None else entry[0]

    def learnt(self, model) -> list[int]:
        """The stamps ``model`` was admitted to learn from (in arrival order)."""
        entry = self._starts.get(model)
        return [] if entry is None else list(entry[1])

