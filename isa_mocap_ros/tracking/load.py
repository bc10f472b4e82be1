"""Graceful degradation under load: the frame budget a real-time tracker can keep up with.

When frame sets arrive faster than the tracker finishes them, a real-time estimator has two ways to
keep up: drop sets (the tracker then predicts across a gap, with a wider search and worse estimates)
or spend less on each set. :class:`LoadGovernor` does the second first: it steps down a ladder of
budgets (:data:`LEVELS`: the contour stage off, then fewer evaluations) while the measured step time
does not fit the frame period, and back up once the measured time at the current level leaves room
for the next one up (a step up that then does not fit comes back down, and the next try waits
twice as long: no oscillation at the edge; a step up that turns the contour stage on is projected with the stage's
cost, ``contour_up_cost``, so a level that cannot fit is not tried). Sets dropped count as overload only beside a step over the headroom
(``slow_drops_only``): a drop beside a step that fit (masks arriving bunched, the start-up) is not the budget's, and
counted it walked the budget down to the last level (decision 018). It is a pure policy: it never reads a clock
itself; the caller passes the monotonic time of each observation, so tests drive it with a fake clock.

A lost track: the estimate's energy far above its recent level (``lost_factor`` × the running median
of the last accepted frames) or a frame that fell back returns the governor to the full budget at once
(a lowered budget is the likeliest cause under load); when it stays lost for ``reset_after`` frame
sets, :meth:`LoadGovernor.observe` says so (``Decision.reset``) and the caller re-initializes the
tracker (its automatic initialization finds the person again).

The estimator node uses it in real time (``degrade`` parameters, docs/nodes.md) and reports the level
in ``/diagnostics``; lockstep never degrades.
"""
from __future__ import annotations

import dataclasses
from collections import deque

import numpy as np

from isa_mocap_ros.config_checks import check_number

#: The budget ladder: (share of the configured evaluations, contour stage on). Level 0 is the full
#: budget; each level down saves more of the step's time (the contour stage is the costliest stage per
#: evaluation, ``isa-mocap bench speed``'s profile).
LEVELS = ((1.0, True), (1.0, False), (0.67, False), (0.5, False), (0.33, False))


class LoadError(ValueError):
    """A bad setting of the governor (the message names it)."""


@dataclasses.dataclass(frozen=True)
class Decision:
    """The budget of the next frame set: ``evals`` evaluations, the contour stage on or off, the ladder
    ``level`` (0 = full), why it changed (``reason``, "" when it did not) and whether the caller should
    re-initialize the tracker (``reset``: the track stayed lost)."""
    evals: int
    contour_stage: bool
    level: int
    reason: str = ""
    reset: bool = False


@dataclasses.dataclass(frozen=True)
class LoadSettings:
    """The governor's settings (one line each, with unit and why)."""
    evals: int                      # the configured (full) evaluations per frame set
    period_s: float                 # the frame period the tracker must keep up with, seconds
    headroom: float = 0.85          # a level fits when its step time is below this share of the period
    down_after: int = 2             # consecutive frame sets over the period before stepping down (one slow set is noise)
    up_after: int = 15              # consecutive sets with room for the level above before stepping up (~0.5 s at 30 Hz)
    min_evals: int = 150            # never fewer evaluations than this (a generation or two of every partition)
    lost_factor: float = 2.0        # energy above this × the running median of the last frames = lost
    reset_after: int = 10           # frame sets lost in a row (at the full budget) before re-initializing
    window: int = 30                # frames in the running step-time and energy statistics
    max_backoff: int = 8            # a step up that did not fit doubles the wait before the next one, up to this factor
    contour_share: float = 0.3      # share of a step the contour stage takes (bench speed's profile: 32 % at 1500), to
                                    # project a step down without it (one step down may skip the levels that would not
                                    # fit) and a step up that turns it on (no try of a level that cannot fit)
    fixed_share: float = 0.3        # share of a full-budget step (no contour stage) that does not scale with the
                                    # evaluations, to project a step between levels (one tracker thread: 8 of 28 ms, 0.30,
                                    # docs/history/issue35_speed.md session 33; 0 = all of it scales, session 32's policy)
    slow_drops_only: bool = True    # a set dropped counts as overload only beside a step over headroom × period_s (a
                                    # drop beside a step that fit is not the budget's: bunched arrivals, the start-up;
                                    # False: every drop counts, session 32's policy)
    contour_up_cost: bool = True    # a step up that turns the contour stage on is projected with its contour_share, so
                                    # a level that cannot fit is not tried (False: projected without it and tried,
                                    # session 32's policy)

    def __post_init__(self) -> None:
        for name in ("evals", "down_after", "up_after", "min_evals", "reset_after", "window", "max_backoff"):
            check_number(name, getattr(self, name), lo=1, integer=True, error=LoadError)
        check_number("period_s", self.period_s, lo=0.0, lo_open=True, error=LoadError)
        check_number("headroom", self.headroom, lo=0.0, hi=1.0, lo_open=True, error=LoadError)
        check_number("lost_factor", self.lost_factor, lo=1.0, lo_open=True, error=LoadError)
        check_number("contour_share", self.contour_share, lo=0.0, hi=1.0, hi_open=True, error=LoadError)
        check_number("fixed_share", self.fixed_share, lo=0.0, hi=1.0, hi_open=True, error=LoadError)


class LoadGovernor:
    """The frame budget under load (see the module docstring).

    Examples
    --------
    >>> g = LoadGovernor(LoadSettings(evals=1500, period_s=1 / 30))
    >>> g.decision().evals, g.decision().contour_stage
    (1500, True)
    >>> for t in range(3):            # three sets of 50 ms each: over the 33 ms period
    ...     d = g.observe(step_s=0.05, energy=0.1)
    >>> d.level, d.evals, d.contour_stage        # projected: 50 x 0.7 = 35 ms > 28; x 0.77 (1005) x 0.7: 27 ms fits
    (2, 1005, False)
    """

    def __init__(self, settings: LoadSettings):
        if not isinstance(settings, LoadSettings):
            raise LoadError(f"settings: expected LoadSettings, received {type(settings).__name__}")
        self.settings = settings
        self.level = 0
        self._over = 0                  # consecutive sets over the period at this level
        self._room = 0                  # consecutive sets with room for the level above
        self._lost = 0                  # consecutive lost sets
        self._steps: deque[float] = deque(maxlen=settings.window)   # step seconds at the current level
        self._energies: deque[float] = deque(maxlen=settings.window)  # energies of the sets not lost
        self.lowered = 0                # times the level went down
        self._backoff = 1               # × up_after: doubled by each step up that did not fit
        self._since_up = None           # sets since the last step up (None: none pending)
        self.resets = 0                 # re-initializations asked for

    @property
    def reference_energy(self) -> float:
        """The energy a lost set is judged against (nan until ``5`` sets are accounted for)."""
        return float(np.median(self._energies)) if len(self._energies) >= 5 else float("nan")

    @property
    def lost_sets(self) -> int:
        """Sets lost in a row so far."""
        return self._lost

    def restart_energies(self) -> None:
        """Forget the energy statistics (a new track, e.g. a recovery's: its energies start anew)."""
        self._energies.clear()
        self._lost = 0

    def budget(self, level: int) -> tuple[int, bool]:
        """``(evaluations, contour stage)`` of ladder level ``level``."""
        share, contour = LEVELS[level]
        s = self.settings
        return max(min(s.evals, s.min_evals), int(round(share * s.evals))), contour

    def decision(self, reason: str = "", reset: bool = False) -> Decision:
        """The budget of the current level."""
        evals, contour = self.budget(self.level)
        return Decision(evals, contour, self.level, reason, reset)

    def _set_level(self, level: int) -> None:
        if level > self.level:
            self.lowered += 1
            if self._since_up is not None:       # the step up before did not fit: wait longer next time
                self._backoff = min(2 * self._backoff, self.settings.max_backoff)
            self._since_up = None
        elif level < self.level:
            self._since_up = 0
        self.level = level
        self._over = self._room = 0
        self._steps.clear()

    def _scale(self, evals_from: int, evals_to: int) -> float:
        """How a step scales from ``evals_from`` to ``evals_to`` evaluations: its ``fixed_share`` (of a full-budget
        step) stays, the rest scales with the evaluations."""
        f, n = self.settings.fixed_share, self.settings.evals
        return (f + (1.0 - f) * evals_to / n) / (f + (1.0 - f) * evals_from / n)

    def _level_that_fits(self, step_s: float, limit: float) -> int:
        """The level to step down to from this one, whose step ``step_s`` was over the period: the first level below
        whose projected step fits ``limit`` (the step scaled with the evaluations but its ``fixed_share``, less ``contour_share`` where
        the contour stage goes off), at least one level down, at most the last. Stepping one level at a time, each
        after ``down_after`` sets over the period, a tracker at twice its idle step time dropped a set or two per
        level on the way down (the emulated one-core-busy start-up, docs/history/issue35_speed.md, session 28)."""
        here, contour_here = self.budget(self.level)
        for level in range(self.level + 1, len(LEVELS)):
            evals, contour = self.budget(level)
            projected = step_s * self._scale(here, evals) * (1.0 - self.settings.contour_share
                                                             * (contour_here and not contour))
            if projected < limit:
                return level
        return len(LEVELS) - 1

    def observe(self, *, step_s: float, energy: float, fell_back: bool = False, dropped: int = 0) -> Decision:
        """Account for one tracked frame set and return the next one's budget.

        Parameters
        ----------
        step_s : float
            The set's tracking time, seconds (the tracker's step at the current level).
        energy : float
            The estimate's energy (nan when there was none).
        fell_back : bool
            The tracker kept its last estimate (no usable view, optimizer failure).
        dropped : int
            Frame sets dropped since the previous observation (the caller replaced them while busy): a
            sign of overload even when this step was quick.
        """
        s = self.settings
        # a lost track: back to the full budget at once; re-initialize when it stays lost
        lost = fell_back or not np.isfinite(energy) or (
            len(self._energies) >= 5 and energy > s.lost_factor * float(np.median(self._energies)))
        if lost:
            self._lost += 1
            if self._lost >= s.reset_after and self.level == 0:
                self.restart_energies()          # the re-initialized track's energies start anew
                self.resets += 1
                return self.decision(f"track lost for {s.reset_after} frame sets: re-initializing", reset=True)
            if self.level != 0:
                self._set_level(0)
                return self.decision(f"track lost (energy {energy:.3g}): full budget")
            return self.decision()
        self._lost = 0
        self._energies.append(float(energy))
        self._steps.append(float(step_s))
        limit = s.headroom * s.period_s
        typical = float(np.median(self._steps))
        if step_s > s.period_s or (dropped > 0 and (step_s > limit or not s.slow_drops_only)):
            self._over += 1
            self._room = 0
        else:
            self._over = 0
        if self._since_up is not None:
            self._since_up += 1
            if self._since_up > s.window:        # the step up held: the next one waits the base time again
                self._since_up = None
                self._backoff = 1
        if self._over >= s.down_after and self.level < len(LEVELS) - 1:
            # from the sets over the period (the last down_after), not the level's median: the load came with them
            recent = float(np.mean(list(self._steps)[-s.down_after:]))
            self._set_level(self._level_that_fits(recent, limit))
            evals, contour = self.budget(self.level)
            return self.decision(f"over the frame period ({1e3 * step_s:.0f} ms > {1e3 * s.period_s:.0f} ms"
                                 + (f", {dropped} set(s) dropped" if dropped else "")
                                 + f"): {evals} evaluations" + ("" if contour else ", no contour stage"))
        if self.level > 0:
            # the level above, from this level's typical time: the step less its fixed share scales with
            # the evaluations (fixed_share), and a contour stage turned on adds its share (contour_up_cost;
            # without it, it was not modelled but tried); a step up that does not fit comes down
            # after down_after sets, and the next try waits twice as long (up to max_backoff × up_after)
            here, contour_here = self.budget(self.level)
            up, contour_up = self.budget(self.level - 1)
            projected = typical * self._scale(here, up)
            if s.contour_up_cost and contour_up and not contour_here:
                projected /= 1.0 - s.contour_share
            self._room = self._room + 1 if projected < limit else 0
            if self._room >= s.up_after * self._backoff:
                self._set_level(self.level - 1)
                evals, contour = self.budget(self.level)
                return self.decision(f"caught up ({1e3 * typical:.0f} ms a set): {evals} evaluations"
                                     + (", contour stage on" if contour else ""))
        return self.decision()


class StartupCatchUp:
    """Real time: the frame sets that arrive while the tracker initializes itself, tracked afterwards instead
    of dropped.

    The automatic initialization takes several frame periods (~265 ms on bags/demo, idle: 8-9 sets at
    30 Hz), and a real-time estimator that kept only the newest set dropped them all. Here the worker keeps
    up to ``sets`` of them waiting in order (:meth:`hold`, for :class:`~.sync.LatestSlot.hold`); once the
    tracker is initialized (and its heading check, which needs consecutive sets, is done) it tracks them
    with ``evals`` evaluations and no contour stage (:meth:`budget`), a fraction of a frame period each, so it
    gains on the stream, until none waits (:meth:`after`). It gives up, and the rest is dropped, when a
    caught-up set waited longer than ``limit_ms`` or no shorter than the caught-up set before it: a tracker
    that does not gain on the stream (a loaded machine) would only fall further behind. With ``stale_ms`` > 0
    a held set that already waited longer than that when its turn comes is dropped instead (:meth:`stale`, the
    oldest first): its estimate would come too late to be of use, and tracking it would make the newer sets
    late too; the newer ones are caught up. A pure policy: the caller passes the waiting count and the times.

    Examples
    --------
    >>> c = StartupCatchUp(sets=12, evals=300, limit_ms=600.0)
    >>> c.hold(3)                       # initializing: keep 12 sets (at least the heading check's 3)
    12
    >>> c.budget(1500, initialized=True, checking_heading=False)
    (300, False)
    >>> c.after(waiting=0, waited_ms=120.0)   # none waits: caught up, on with the newest set
    False
    """

    def __init__(self, *, sets: int, evals: int, limit_ms: float, stale_ms: float = 0.0) -> None:
        check_number("sets", sets, lo=0, integer=True, error=LoadError)
        check_number("evals", evals, lo=1, integer=True, error=LoadError)
        check_number("limit_ms", limit_ms, lo=0.0, error=LoadError)
        check_number("stale_ms", stale_ms, lo=0.0, error=LoadError)
        self.sets, self.evals, self.limit_ms, self.stale_ms = int(sets), int(evals), float(limit_ms), float(stale_ms)
        self.active = False             # catching up (from an initialization until caught up or given up)
        self.caught_up = 0              # sets tracked at the catch-up budget (all initializations)
        self._cheap = False             # the last budget given was the catch-up budget
        self._last_wait = None          # the wait of the last caught-up set, ms

    def hold(self, heading_sets: int) -> int:
        """The tracker is about to initialize: how many waiting sets to keep in order (at least the
        heading check's ``heading_sets``)."""
        self.active = self.sets > 0
        self._cheap, self._last_wait = False, None
        return max(int(heading_sets), self.sets)

    def stale(self, waited_ms: float) -> bool:
        """Whether a held set that waited ``waited_ms`` when the catch-up would take it is dropped instead (``stale_ms``
        > 0 and it waited longer; see the class)."""
        return self.active and self.stale_ms > 0 and waited_ms > self.stale_ms

    def budget(self, evals: int, *, initialized: bool, checking_heading: bool,
               in_sequence: bool = True) -> tuple[int, bool]:
        """``(evaluations, contour stage allowed)`` of the next set, whose budget would otherwise be
        ``evals``; a set tracked at the catch-up budget is counted. Only a held set (``in_sequence``: it follows the
        set tracked before it) gets the catch-up budget: the set after the held ones comes after a gap, where the
        motion since the last estimate is larger and a cheap search loses limbs (measured: docs/history/issue35_speed.md)."""
        self._cheap = self.active and initialized and not checking_heading and in_sequence
        if not self._cheap:
            return int(evals), True
        self.caught_up += 1
        return min(int(evals), self.evals), False

    def after(self, *, waiting: int, waited_ms: float) -> bool:
        """After a tracked set that ``waited_ms`` before its step, with ``waiting`` sets left: whether to go
        on catching up (False: keep only the newest set from now on)."""
        if not self.active:
            return False
        if self._cheap:
            not_gaining = self._last_wait is not None and waited_ms >= self._last_wait
            if waited_ms > self.limit_ms or not_gaining:
                self.active = False
            self._last_wait = waited_ms
        if waiting <= 0:
            self.active = False
        return self.active
