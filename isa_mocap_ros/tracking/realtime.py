"""The real-time estimator's schedule: which frame sets the tracker gets, at what budget, and what it does
after each one (pure: no clock, no threads; the estimator node and :func:`emulate` drive it).

A real-time estimator cannot track every frame set when a step takes longer than the frame period. The
schedule puts the policies of :mod:`.load` and :mod:`.sync` together in the order the node applies them:

1. **Take** (:meth:`RealTimeSchedule.take`): the oldest waiting set (:class:`~.sync.LatestSlot`: beyond
   ``backlog`` waiting sets the oldest are dropped). Before the tracker's (re-)initialization it holds the
   sets that follow in sequence (the heading check compares consecutive frames, the start-up catch-up tracks
   them, :class:`~.load.StartupCatchUp`); before a heading re-check (:meth:`Tracker.heading_recheck_pending`)
   the heading check's sets alike.
2. **Budget** (:meth:`RealTimeSchedule.budget`): the governor's lowered budget under load
   (:class:`~.load.LoadGovernor`), the catch-up budget for the start-up's waiting sets, and no contour stage
   for a set that waited longer than ``catch_up_ms``.
3. **After** (:meth:`RealTimeSchedule.after`): the governor's account of the step (a track lost for
   ``reset_after`` sets re-initializes the tracker: it finds the person again by itself; the start-up's frames —
   the initialization, the heading check's — and the sets dropped meanwhile are not load and not counted), the
   recovery's (:mod:`.recovery`: after a drift at a lowered budget, a second opinion on the same set is due:
   :attr:`RealTimeSchedule.probe_due`, :meth:`RealTimeSchedule.probe`), then the catch-up's (the rest of the held
   sets dropped once it stops).

:func:`emulate` runs a tracker through the schedule on a virtual clock (sets arrive every ``period_s``, a
step lasts what ``step_s(result)`` says): the node's decisions, reproducible on any machine, for tests and
benchmarks of what load does to a track. Lockstep (``lockstep=True``) tracks every set at the full budget.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Sequence

from .load import Decision, LoadGovernor, LoadSettings, StartupCatchUp
from .recovery import Recovery, second_opinion
from .sync import LatestSlot

__all__ = ["RealTimeSchedule", "Budget", "EmulatedStep", "emulate", "step_cost", "warm_up", "rehearse"]


@dataclasses.dataclass(frozen=True)
class Budget:
    """The next step's budget: ``evals`` (None = the configured one), the contour stage on or off, and whether
    the set is ``late`` (it waited longer than ``catch_up_ms``: tracked without the contour stage)."""
    evals: int | None
    contour_stage: bool
    late: bool


class RealTimeSchedule:
    """The estimator's real-time schedule (see the module docstring).

    Parameters
    ----------
    evals : int
        The configured evaluations per frame set.
    heading_sets : int
        The heading check's frames (``init_confirm_frames``): sets held in sequence before a heading re-check.
    lockstep : bool
        Every set tracked in order at the full budget (no drop, no hold, no governor).
    backlog : int
        Sets kept waiting while the tracker is busy (the newest).
    catch_up_ms : float
        A set that waited longer than this is tracked without the contour stage (0 = never).
    startup : StartupCatchUp
        The start-up's held sets, tracked after the initialization.
    governor : LoadGovernor or None
        The budget under load (None: always the full budget).
    recovery : Recovery or None
        The second opinion on a track that drifted at a lowered budget (None: never; it needs the governor's account,
        so lockstep never asks).
    """

    def __init__(self, *, evals: int, heading_sets: int, lockstep: bool = False, backlog: int = 1,
                 catch_up_ms: float = 15.0, startup: StartupCatchUp | None = None,
                 governor: LoadGovernor | None = None, recovery: Recovery | None = None) -> None:
        self.evals = int(evals)
        self.heading_sets = int(heading_sets)
        self.lockstep = bool(lockstep)
        self.catch_up_ms = float(catch_up_ms)
        self.slot = LatestSlot(keep_all=self.lockstep, depth=backlog)
        self.startup = startup if startup is not None else StartupCatchUp(sets=0, evals=1, limit_ms=0.0)
        self.governor = None if self.lockstep else governor
        self.recovery = None if self.governor is None else recovery
        self.probe_due = False             # the set tracked last is due a second opinion (see probe)
        self.probe_log: list[dict] = []    # per probe: frame key, the probe's and the track's energy, adopted
        self.frames_caught_up = 0          # sets tracked without the contour stage because they were late
        self.last_decision: Decision | None = None   # the governor's last change of budget
        self.last_account: dict | None = None        # the governor's account of the last step (None: not counted)
        self._dropped_seen = 0
        self._checking = False             # the set taken last is a heading check's frame
        self._took_held = False            # the set taken last was a held one (in sequence with the one before)

    def take(self, tracker, masks_of: Callable = lambda item: item[0].items, waited_ms: Callable | None = None):
        """The next waiting set (None: none waits), with the holds its step needs (see the module docstring);
        ``tracker``: the tracker about to step it (None: not made yet); ``masks_of(item)``: its masks;
        ``waited_ms(item)``: how long it has waited (for the start-up catch-up's stale sets, dropped here)."""
        if waited_ms is not None and tracker is not None and tracker.initialized and not tracker.checking_heading:
            # the start-up catch-up: held sets too old to be worth an estimate go, the oldest first (never the newest)
            while self.slot.held and len(self.slot) > 1 and self.startup.stale(waited_ms(self.slot.oldest())):
                self.slot.drop_oldest()
        self._took_held = self.slot.held > 0
        item = self.slot.take()
        if item is None or self.lockstep:
            return item
        if tracker is None or not tracker.initialized:
            # this set may initialize the tracker: keep the sets that follow it in sequence for the heading
            # check (Tracker.checking_heading) and the catch-up after it
            self.slot.hold(self.startup.hold(self.heading_sets))
        elif tracker.heading_recheck_pending(masks_of(item)):
            # the same for a heading re-check (more views see the person, an undecided check or one a gap ended,
            # the track moving backwards): else its check ends at the gap after the re-check's own, longer frame
            self.slot.hold(self.heading_sets)
        return item

    def budget(self, tracker, waited_ms: float) -> Budget:
        """The budget of the set taken last, which waited ``waited_ms`` before its step."""
        if self.lockstep:
            return Budget(None, True, False)
        late = 0 < self.catch_up_ms < waited_ms
        self._checking = tracker.checking_heading      # a heading check's frame: its rival doubles the step
        d = self.governor.decision() if self.governor is not None else None
        evals = self.evals if d is None or d.level == 0 else d.evals
        evals, contour = self.startup.budget(evals, initialized=tracker.initialized,
                                             checking_heading=tracker.checking_heading, in_sequence=self._took_held)
        contour = contour and not late and (d is None or d.contour_stage)
        return Budget(None if evals == self.evals else evals, contour, late)

    def after(self, tracker, result, *, budget: Budget, waited_ms: float, step_s: float | None = None) -> Decision | None:
        """Account for the step of the set taken last (``result``, its :class:`~.config.FrameResult`; ``budget``:
        what :meth:`budget` gave; ``waited_ms``: from its arrival to now; ``step_s``: the step's duration, default
        ``result.time_s``). Re-initializes the tracker when the governor says the track stayed lost; returns the
        governor's decision when it changed the budget."""
        if self.lockstep:
            return None
        if budget.late and result.x is not None and not result.fell_back and not result.initialized:
            self.frames_caught_up += 1
        changed = self.last_account = None
        self.probe_due = False
        if self.governor is not None and result.x is not None and not result.initialized and not self._checking:
            # the start-up's frames are not load: the initialization and the heading check's frames (the rival's
            # step beside the track's) take several periods by design, and the sets dropped meanwhile or when the
            # check ends are theirs; counted as overload they lowered the budget right after every start-up
            dropped = self.slot.dropped - self._dropped_seen
            self._dropped_seen = self.slot.dropped
            reference = self.governor.reference_energy
            d = self.governor.observe(step_s=result.time_s if step_s is None else step_s, energy=result.energy,
                                      fell_back=result.fell_back, dropped=dropped)
            self.last_account = dict(energy=float(result.energy), reference=reference, lost=self.governor.lost_sets,
                                     level=d.level, dropped=dropped, reset=d.reset, reason=d.reason)
            if d.reason:
                changed = self.last_decision = d
            if d.reset:
                tracker.reset()          # the next set initializes automatically
            elif self.recovery is not None:
                self.probe_due = self.recovery.observe(energy=float(result.energy), level=d.level)
        if result.initialized and self.recovery is not None:
            self.recovery.restart()
        if tracker.initialized and not tracker.checking_heading:
            # the start-up's sets still waiting are tracked in order (catch-up) until none waits or one waited
            # too long; then (or with no catch-up) on with the newest set
            going_on = self.startup.after(waiting=len(self.slot), waited_ms=waited_ms)
            if self.slot.held and not going_on:
                self.slot.hold(0)
        if result.initialized or self._checking:
            self._dropped_seen = self.slot.dropped       # (the start-up's drops: not the governor's to count)
        return changed

    def probe(self, result, masks, frame_index: int, make_tracker: Callable):
        """The second opinion :attr:`probe_due` asked for on the set just tracked (``masks``, frame key
        ``frame_index``; ``result``: the track's) by a new tracker from ``make_tracker()``
        (:func:`.recovery.second_opinion`; touches nothing the caller shares). Returns ``(probe tracker, probe
        result, adopted)``; an adopted probe replaces the track: the caller then calls :meth:`recovered`, and in any
        case :meth:`seen_drops` once the probe's time has passed (the sets dropped meanwhile are the probe's, not
        load the governor counts)."""
        self.probe_due = False
        probe, r, adopted = second_opinion(make_tracker, masks, frame_index, result, self.recovery)
        self.probe_log.append(dict(frame=int(frame_index), probe_energy=float(r.energy),
                                   track_energy=float(result.energy), adopted=bool(adopted)))
        return probe, r, adopted

    def recovered(self, tracker) -> None:
        """An adopted probe, ``tracker``, is the track now: the governor's energies start anew, and the sets after it
        are held in sequence for its heading check."""
        self.governor.restart_energies()
        if tracker.checking_heading:
            self.slot.hold(self.heading_sets)

    def seen_drops(self) -> None:
        """The sets dropped so far are not the governor's to count (dropped while a probe ran)."""
        self._dropped_seen = self.slot.dropped


def step_cost(*, fixed_s: float = 0.005, per_eval_s: float = 28e-6, load: float = 1.0) -> Callable:
    """A step's duration from its evaluations: ``load × (fixed_s + per_eval_s × n_evals)`` (defaults: bags/demo
    idle on this project's 2-core machine, ~47 ms for a 1500-evaluation frame, ~270 ms for the
    initialization's ~9400; ``load`` 2: another process takes half the core)."""
    return lambda result, budget=None: load * (fixed_s + per_eval_s * result.n_evals)


@dataclasses.dataclass(frozen=True)
class EmulatedStep:
    """One set :func:`emulate` tracked: its index ``k`` in the sequence, the tracker's result, the budget it
    had, its latency (arrival to estimate, seconds of the virtual clock) and the frame periods since the set
    tracked before it (``gap``)."""
    k: int
    result: object
    budget: Budget
    latency_s: float
    gap: int


def emulate(tracker, masks: Sequence, schedule: RealTimeSchedule, *, period_s: float,
            step_s: Callable, frame_key: Callable[[int], int] = lambda k: k,
            make_tracker: Callable | None = None) -> tuple[list[EmulatedStep], int]:
    """Real time on a virtual clock: set ``k`` (``masks[k]``, one mask per view) arrives at ``k × period_s``; the
    tracker steps the set :meth:`RealTimeSchedule.take` gives whenever it is free, for ``step_s(result, budget)``
    seconds (:func:`step_cost`, or a cost model that sees the budget: ``tools/emulate_realtime.py``). With
    ``make_tracker`` (a new tracker like ``tracker``) the schedule's second opinions run (:meth:`RealTimeSchedule.probe`,
    the probe's step time added; an adopted probe tracks on and its step replaces the track's). Returns the tracked
    steps and the number of sets dropped."""
    n = len(masks)
    t_free, arrived, prev = 0.0, 0, None

    def arrive(until: float) -> None:
        nonlocal arrived
        while arrived < n and arrived * period_s <= until + 1e-12:
            schedule.slot.put((arrived, arrived * period_s))
            arrived += 1

    steps: list[EmulatedStep] = []
    while True:
        arrive(t_free)
        item = schedule.take(tracker, masks_of=lambda it: masks[it[0]], waited_ms=lambda it: (t_free - it[1]) * 1e3)
        if item is None:
            if arrived >= n:
                break
            t_free = arrived * period_s        # idle until the next set
            continue
        k, t_ready = item
        b = schedule.budget(tracker, (t_free - t_ready) * 1e3)
        gap = 1 if prev is None else k - prev
        prev = k
        r = tracker.step(masks[k], frame_key(k), frames_elapsed=gap, contour_stage=b.contour_stage, evals=b.evals)
        dt = step_s(r, b)
        t_free += dt
        arrive(t_free)
        schedule.after(tracker, r, budget=b, waited_ms=(t_free - t_ready) * 1e3, step_s=dt)
        if schedule.probe_due and make_tracker is not None:
            probe, p, adopted = schedule.probe(r, masks[k], frame_key(k), make_tracker)
            t_free += step_s(p, b)
            arrive(t_free)
            schedule.seen_drops()
            if adopted:
                tracker, r = probe, p
                schedule.recovered(tracker)
        steps.append(EmulatedStep(k, r, b, t_free - t_ready, gap))
    return steps, schedule.slot.dropped


def governor_for(evals: int, period_s: float, **settings) -> LoadGovernor:
    """A :class:`~.load.LoadGovernor` of ``evals`` per set and frame period ``period_s`` (other settings as
    :class:`~.load.LoadSettings`)."""
    return LoadGovernor(LoadSettings(evals=evals, period_s=period_s, **settings))


def warm_up(model, config) -> list:
    """Load (or compile) the kernels of the estimator's first frames ahead, on a tiny synthetic frame: the rest pose
    of ``model`` rendered into 4 views of 80×60, stepped three times by a :class:`~.tracker.Tracker` with ``config``
    (its budget and stages): the automatic initialization (first-frame hull, grid, root refinements, candidate runs,
    polish, the heading check's rival), a tracked frame with every stage, and one predicted from two past poses (the
    autoregression's compiled root, :func:`.predict._ar_root`), the predictor fed and read through the JointState
    conversions as the node's (:class:`.published.PublishedPredictor`; compiled too). numba loads a kernel's machine code
    from its cache on the first call in a process (~5-30 ms each): a warm-up from a given pose left the automatic
    initialization's kernels to the first real frame, ~50 CPU ms more there (docs/history/issue35_speed.md,
    session 27). Returns the three steps' :class:`~.result.FrameResult`."""
    from isa_mocap_ros.body import capsule_endpoints
    from isa_mocap_ros.vision import default_rig, render_mask

    from .published import PublishedPredictor
    from .tracker import Tracker

    rig = default_rig(n_views=4, width=80, height=60)
    x = model.rest_pose()
    ends = capsule_endpoints(model, x[None])[0]
    masks = [render_mask(c, ends, model.capsule_radii) for c in rig.cameras]
    tracker = Tracker(model, rig.cameras, config)
    # the estimator node's predictor goes through the JointState conversions (compiled: body/urdf.py) as here
    tracker.predictor = PublishedPredictor(model, tracker.predictor)
    return [tracker.step(masks, k) for k in range(3)]


def rehearse(model, cameras) -> list:
    """The first-frame hull (:func:`.init_hull.person_masks`) once on ``cameras`` themselves, at their size, before the
    person is in view: the rest pose of ``model`` standing in the middle of the rig's capture volume
    (:func:`.init_hull.capture_volume`), rendered into every camera. :func:`warm_up` loads the kernels on 80×60 views;
    this call touches the hull's arrays at the cameras' size, so the first real initialization does not pay their
    first-touch page faults (figures: docs/history/issue35_speed.md, session 30), and builds the capture volume's
    grid and its pixels in every camera, which the hull keeps for the cameras' initializations. The estimator node calls it on an
    empty frame set (docs/nodes.md, "Start-up"); it changes no estimate (nothing it computes is kept but the process's
    memory). Returns the rendered masks cut to the hull's blob."""
    from isa_mocap_ros.body import capsule_endpoints
    from isa_mocap_ros.vision import render_mask

    from .init_hull import capture_volume, person_masks

    lo, hi = capture_volume(cameras)
    x = model.rest_pose()
    x[:2] = 0.5 * (lo[:2] + hi[:2])
    ends = capsule_endpoints(model, x[None])[0]
    masks = [render_mask(c, ends, model.capsule_radii) for c in cameras]
    return person_masks(masks, list(cameras))[0]
