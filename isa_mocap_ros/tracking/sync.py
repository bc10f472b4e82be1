"""Frame-set synchronization of V per-view streams (masks) by header stamp.

Pure logic for the estimator node (no rclpy), with the semantics of ROS's Python
``message_filters``:

* **exact** (``slop_ns == 0``, like ``TimeSynchronizer``): a frame set is emitted when every view
  holds a message with the same stamp;
* **approximate** (``slop_ns > 0``, like ``ApproximateTimeSynchronizer``): when a message arrives,
  the other views' queued stamps within ``slop`` of it are tried, closest first, and the first
  combination whose spread ``max - min`` is below ``slop`` is emitted;

in both, each view keeps at most ``queue_size`` stamps (the oldest is dropped), and emitted
messages leave their queues.

A view that stops publishing would block every set, so (an addition to message_filters) a stamp
held by at least ``min_views`` views for longer than ``max_wait_s`` is emitted as a *partial* set
with ``None`` for the missing views (:meth:`FrameSynchronizer.poll`). Messages older than the last
emitted stamp are rejected (out-of-order input).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any


class SyncError(ValueError):
    """Bad synchronizer configuration or input."""


@dataclass(frozen=True)
class FrameSet:
    """One synchronized set: ``items[v]`` is view v's payload (None when missing)."""

    stamp_ns: int
    items: tuple
    stamps_ns: tuple

    @property
    def missing(self) -> tuple[int, ...]:
        return tuple(v for v, it in enumerate(self.items) if it is None)


class FrameSynchronizer:
    """Collects per-view messages and emits :class:`FrameSet` objects.

    Parameters
    ----------
    n_views : int
    queue_size : int
        Stamps kept per view.
    slop_ns : int
        0 = exact matching; otherwise the approximate window in nanoseconds.
    max_wait_s, min_views :
        Partial sets (see module docstring); ``max_wait_s <= 0`` disables them.
    """

    def __init__(self, n_views: int, *, queue_size: int = 10, slop_ns: int = 0,
                 max_wait_s: float = 0.0, min_views: int = 1) -> None:
        if n_views < 1:
            raise SyncError(f"n_views must be >= 1, got {n_views}")
        if queue_size < 1:
            raise SyncError(f"queue_size must be >= 1, got {queue_size}")
        if slop_ns < 0:
            raise SyncError(f"slop must be >= 0 ns, got {slop_ns}")
        if not 1 <= min_views <= n_views:
            raise SyncError(f"min_views must be in [1, {n_views}], got {min_views}")
        self.n_views = n_views
        self.queue_size = queue_size
        self.slop_ns = int(slop_ns)
        self.max_wait_s = float(max_wait_s)
        self.min_views = min_views
        self._queues: list[dict[int, tuple[Any, float]]] = [{} for _ in range(n_views)]
        self.last_emitted_ns: int | None = None
        self.dropped = 0  # messages evicted by queue_size or left behind by a newer set

    # -- input -----------------------------------------------------------------------------------
    def add(self, view: int, stamp_ns: int, item: Any, now_s: float) -> list[FrameSet]:
        """Queue ``item`` of ``view``; return the frame sets this completes (0 or 1)."""
        if not 0 <= view < self.n_views:
            raise SyncError(f"view must be in [0, {self.n_views}), got {view}")
        if self.last_emitted_ns is not None and stamp_ns <= self.last_emitted_ns:
            raise SyncError(f"view {view}: stamp {stamp_ns} is not newer than the last emitted frame set "
                            f"({self.last_emitted_ns}); out-of-order message dropped")
        q = self._queues[view]
        q[stamp_ns] = (item, now_s)
        while len(q) > self.queue_size:
            del q[min(q)]
            self.dropped += 1
        found = self._exact(stamp_ns) if self.slop_ns == 0 else self._approximate(view, stamp_ns)
        return [self._emit(found)] if found is not None else []

    def poll(self, now_s: float) -> list[FrameSet]:
        """Emit partial sets whose oldest message waited longer than ``max_wait_s``."""
        out = []
        if self.max_wait_s <= 0:
            return out
        while True:
            pivot = self._oldest()
            if pivot is None:
                return out
            v0, s0 = pivot
            if now_s - self._queues[v0][s0][1] < self.max_wait_s:
                return out
            combo = [self._closest(v, s0) for v in range(self.n_views)]
            if sum(s is not None for s in combo) >= self.min_views:
                out.append(self._emit(combo))
            else:  # too few views for this stamp: give it up
                del self._queues[v0][s0]
                self.dropped += 1

    # -- matching --------------------------------------------------------------------------------
    def _exact(self, stamp_ns: int):
        if all(stamp_ns in q for q in self._queues):
            return [stamp_ns] * self.n_views
        return None

    def _approximate(self, view: int, stamp_ns: int):
        candidates = []
        for v, q in enumerate(self._queues):
            if v == view:
                continue
            near = sorted((abs(s - stamp_ns), s) for s in q if abs(s - stamp_ns) <= self.slop_ns)
            if not near:
                return None
            candidates.append([s for _, s in near])
        for combo in itertools.product(*candidates):
            stamps = list(combo)
            stamps.insert(view, stamp_ns)
            if max(stamps) - min(stamps) < self.slop_ns:
                return stamps
        return None

    def _closest(self, view: int, stamp_ns: int) -> int | None:
        near = [(abs(s - stamp_ns), s) for s in self._queues[view] if abs(s - stamp_ns) <= self.slop_ns]
        return min(near)[1] if near else None

    def _oldest(self) -> tuple[int, int] | None:
        best = None
        for v, q in enumerate(self._queues):
            if q:
                s = min(q)
                if best is None or s < best[1]:
                    best = (v, s)
        return best

    def _emit(self, stamps: list[int | None]) -> FrameSet:
        items = tuple(None if s is None else self._queues[v].pop(s)[0] for v, s in enumerate(stamps))
        stamp = next(s for s in stamps if s is not None)
        newest = max(s for s in stamps if s is not None)
        self.last_emitted_ns = newest if self.last_emitted_ns is None else max(self.last_emitted_ns, newest)
        for q in self._queues:  # anything at or before the emitted set can never complete now
            for s in [s for s in q if s <= self.last_emitted_ns]:
                del q[s]
                self.dropped += 1
        return FrameSet(stamp_ns=stamp, items=items, stamps_ns=tuple(stamps))


class LatestSlot:
    """Real-time hand-over between the synchronizer and a slower worker: keeps the newest sets.

    ``put`` appends a set; beyond ``depth`` sets waiting, the oldest are dropped (counted in
    ``dropped``); ``take`` gives the oldest waiting set. ``depth=1`` keeps only the newest. In
    lockstep mode use ``keep_all=True``: every set is queued, none dropped.

    ``hold(n)`` keeps, besides the ``depth`` newest, the ``n`` oldest sets waiting, so that the worker
    gets the sets that follow the one it is busy with in sequence (the tracker's heading check after
    its automatic initialization compares consecutive frames, and the initialization takes several
    frame periods); the sets between are dropped. ``hold(0)`` ends it and drops the held sets that are
    still waiting, so the worker goes on with the newest.
    """

    def __init__(self, *, keep_all: bool = False, depth: int = 1) -> None:
        if isinstance(depth, bool) or not isinstance(depth, int) or depth < 1:
            raise SyncError(f"depth: expected an integer >= 1, received {depth!r}")
        self.keep_all = keep_all
        self.depth = depth
        self._items: list = []
        self._hold = 0
        self.dropped = 0

    @property
    def held(self) -> int:
        """How many of the oldest waiting sets are kept (``hold``)."""
        return self._hold

    def hold(self, n: int) -> None:
        """Keep the ``n`` oldest waiting sets besides the ``depth`` newest (0: stop, see the class)."""
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise SyncError(f"hold: expected an integer >= 0, received {n!r}")
        self._hold = n
        self._trim()

    def put(self, item) -> None:
        self._items.append(item)
        self._trim()

    def _trim(self) -> None:
        """Drop (and count) the sets waiting beyond the ``held`` oldest and the ``depth`` newest."""
        n = len(self._items) - self._hold - self.depth
        if not self.keep_all and n > 0:
            self.dropped += n
            del self._items[self._hold:self._hold + n]

    def oldest(self):
        """The oldest waiting set (the next :meth:`take`), or None."""
        return self._items[0] if self._items else None

    def drop_oldest(self) -> None:
        """Drop (and count) the oldest waiting set, a held one first (the start-up catch-up's stale sets)."""
        if self._items:
            del self._items[0]
            self.dropped += 1
            if self._hold:
                self._hold -= 1

    def take(self):
        item = self._items.pop(0) if self._items else None
        if item is not None and self._hold:
            self._hold -= 1          # a held set was taken: the next one in sequence is the oldest now
        return item

    def __len__(self) -> int:
        return len(self._items)
