"""Shedding late frame sets whole: which images a node under load skips so that it drops sets, not views.

A node that cannot keep up with its images (the segmentation on a loaded machine) loses them in its best-effort
input queues, a view at a time, so most lost frame sets are partial and the work on their other views is wasted
(docs/history/issue35_speed.md, session 32). :class:`LateSetShedder` decides per frame set, at the first image of
the set the node handles: the set is skipped in every view when that image is older than ``max_age_ns``.

The age is read from the header stamp: ``arrival - stamp`` less the stream's offset, the smallest ``arrival - stamp``
seen (the transport's delay and the stamp clock's base). The offset is constant for a live camera (stamps are the
capture times) and for a replay at rate 1.0; it leaks upwards by ``leak`` seconds per second of arrival time (a slow
drift between the camera's clock and ours is forgotten), and restarts at a sample more than ``reset_ns`` above it (the
stream jumped: a bag looped, a camera restarted). A replay at another rate has no constant offset: leave it off there.
Pure: no ROS, no clock of its own (the caller passes the arrival time).
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

__all__ = ["Burst", "LateSetShedder"]


@dataclass(frozen=True)
class Burst:
    """Consecutive shed sets (for one log line): how many, their first and last stamps, the largest age."""

    sets: int
    first_stamp_ns: int
    last_stamp_ns: int
    max_age_ns: int


class LateSetShedder:
    """Per frame set stamp: shed (skip in every view) or not, decided at the set's first image.

    Parameters
    ----------
    max_age_ns : a set whose first image is older than this is shed (0 = never: every image is kept).
    reset_ns : an ``arrival - stamp`` this far above the offset restarts the offset (the stream jumped).
    leak : the offset's upward drift, seconds per second of arrival time.
    remember : how many recent sets' decisions are kept (a set's later views are judged by its first one).

    Examples
    --------
    >>> s = LateSetShedder(max_age_ns=50_000_000, leak=0.0)
    >>> s.shed(1_000_000_000, arrival_ns=1_002_000_000)   # learns the offset (2 ms)
    False
    >>> s.shed(1_033_000_000, arrival_ns=1_135_000_000)   # 100 ms late: shed
    True
    >>> s.shed(1_033_000_000, arrival_ns=1_136_000_000)   # the same set's next view: shed too
    True
    >>> s.shed(1_066_000_000, arrival_ns=1_070_000_000), s.shed_sets
    (False, 1)
    >>> s.pop_burst()
    Burst(sets=1, first_stamp_ns=1033000000, last_stamp_ns=1033000000, max_age_ns=100000000)
    """

    def __init__(self, max_age_ns: int, *, reset_ns: int = 5_000_000_000, leak: float = 1e-3,
                 remember: int = 256) -> None:
        if max_age_ns < 0 or reset_ns <= 0 or leak < 0 or remember < 1:
            raise ValueError(f"LateSetShedder: expected max_age_ns >= 0, reset_ns > 0, leak >= 0, remember >= 1, "
                             f"received {max_age_ns}, {reset_ns}, {leak}, {remember}")
        self.max_age_ns, self.reset_ns, self.leak, self.remember = int(max_age_ns), int(reset_ns), leak, remember
        self.offset_ns: int | None = None
        self._last_arrival_ns: int | None = None
        self._decided: OrderedDict[int, bool] = OrderedDict()
        self.shed_sets = 0
        self._burst: list[int] | None = None      # [sets, first stamp, last stamp, max age]
        self._ended: Burst | None = None

    @property
    def enabled(self) -> bool:
        return self.max_age_ns > 0

    def age_ns(self, stamp_ns: int, arrival_ns: int) -> int:
        """The image's age against the stream's offset, which this sample updates first."""
        sample = arrival_ns - stamp_ns
        if self.offset_ns is not None and self._last_arrival_ns is not None:
            self.offset_ns += int(self.leak * max(0, arrival_ns - self._last_arrival_ns))
        self._last_arrival_ns = arrival_ns
        if self.offset_ns is None or sample < self.offset_ns or sample - self.offset_ns > self.reset_ns:
            self.offset_ns = sample
        return sample - self.offset_ns

    def shed(self, stamp_ns: int, *, arrival_ns: int) -> bool:
        """Whether the image of ``stamp_ns`` (one view's) is to be skipped: its set's decision, made now if this
        is the first image of the set seen."""
        if not self.enabled:
            return False
        age = self.age_ns(stamp_ns, arrival_ns)
        if stamp_ns in self._decided:
            return self._decided[stamp_ns]
        late = age > self.max_age_ns
        self._decided[stamp_ns] = late
        while len(self._decided) > self.remember:
            self._decided.popitem(last=False)
        if late:
            self.shed_sets += 1
            b = self._burst
            self._burst = [1, stamp_ns, stamp_ns, age] if b is None else [b[0] + 1, b[1], stamp_ns, max(b[3], age)]
        elif self._burst is not None:
            self._ended, self._burst = Burst(*self._burst), None
        return late

    def pop_burst(self, *, flush: bool = False) -> Burst | None:
        """The burst that ended (a kept set came after shed ones) since the last call, else None; ``flush``
        ends a burst still going on (at shutdown)."""
        if flush and self._burst is not None and self._ended is None:
            self._ended, self._burst = Burst(*self._burst), None
        ended, self._ended = self._ended, None
        return ended
