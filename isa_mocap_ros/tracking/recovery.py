"""A lost track recovers by itself in real time: a second opinion on the same frame set, asked for only under load.

Under sustained load the real-time estimator tracks most sets at the budget ladder's last level
(:mod:`.load`: ~1/3 of the evaluations, no contour stage), where a track can turn slowly off the person. The
silhouette energy of such a track rises a few per cent a set, and so does the governor's running median: nothing
is ever "lost" against it, and no energy threshold, drifting or frozen, tells the drift from a good track across a
walk (docs/history/issue35_speed.md, session 32). What does tell them apart is a fresh automatic initialization on
the same masks: its energy is 0.41-0.87 of a lost track's and 0.57-1.38 of a good one's.

:class:`Recovery` decides when to ask for that second opinion and whether to take it (a pure policy):

- **due** (:meth:`Recovery.observe`): only on sets the governor counted (real time: lockstep and offline tracking
  never ask, so their estimates do not change), after ``low_sets`` counted sets in a row at a lowered budget (the
  drift's condition), when the median of the last ``recent`` energies is above ``suspect_factor`` × the track's
  floor (the lowest median of ``floor_sets`` since it began: a floor does not follow the drift), at most once every
  ``cooldown`` counted sets;
- **adopted** (:meth:`Recovery.adopt`): the probe (:func:`second_opinion`: a new tracker initialized automatically on
  the set, without the initialization's polish) replaces the track when its energy is below ``adopt_ratio`` × the
  track's on the same set; a false alarm then costs the probe's time only.

:func:`second_opinion` runs one probe for a caller (the estimator node, :func:`.realtime.emulate`).
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Sequence

import numpy as np

from isa_mocap_ros.config_checks import check_number

__all__ = ["RecoverySettings", "Recovery", "second_opinion"]


class RecoveryError(ValueError):
    """A bad recovery setting (the message names it)."""


@dataclasses.dataclass(frozen=True)
class RecoverySettings:
    """When a probe is due and when it is adopted (one line each, with why)."""
    low_sets: int = 10              # counted sets in a row at a lowered budget before a probe may be due (the drift
                                    # happens there; an idle network at the full budget never probes)
    suspect_factor: float = 1.3     # the last energies' median above this × the track's floor: suspect
    recent: int = 3                 # energies in the recent median
    floor_sets: int = 5             # energies in each median the floor is the lowest of
    cooldown: int = 45              # counted sets between two probes (a probe costs an initialization's time)
    adopt_ratio: float = 0.6        # the probe replaces the track below this × the track's energy on the same set
                                    # (lost tracks: 0.41-0.87, good ones 0.57-1.38; docs/history/issue35_speed.md)

    def __post_init__(self) -> None:
        for name in ("low_sets", "recent", "floor_sets", "cooldown"):
            check_number(name, getattr(self, name), lo=1, integer=True, error=RecoveryError)
        check_number("suspect_factor", self.suspect_factor, lo=1.0, error=RecoveryError)
        check_number("adopt_ratio", self.adopt_ratio, lo=0.0, hi=1.0, lo_open=True, error=RecoveryError)


class Recovery:
    """The second opinion's policy (see the module docstring).

    Examples
    --------
    >>> r = Recovery(RecoverySettings(low_sets=2, cooldown=5))
    >>> [r.observe(energy=e, level=4) for e in [0.08] * 6 + [0.12, 0.12]]
    [False, False, False, False, False, False, False, True]
    >>> r.adopt(0.05, 0.12), r.adopt(0.10, 0.12), r.probes, r.adopted
    (True, False, 1, 1)
    """

    def __init__(self, settings: RecoverySettings = RecoverySettings()) -> None:
        if not isinstance(settings, RecoverySettings):
            raise RecoveryError(f"settings: expected RecoverySettings, received {type(settings).__name__}")
        self.settings = settings
        self.probes = 0                 # second opinions asked for
        self.adopted = 0                # of them, taken: recoveries
        self.restart()

    def restart(self) -> None:
        """A new track (initialized, or a probe adopted): its floor starts anew."""
        self._energies: list[float] = []
        self._floor = float("inf")
        self._low = 0                   # counted sets in a row at a lowered budget
        self._since = self.settings.cooldown      # counted sets since the last probe

    def observe(self, *, energy: float, level: int) -> bool:
        """Account for a counted set (its estimate's ``energy``, the governor's ``level`` after it, 0 = full budget);
        whether to probe this set now."""
        s = self.settings
        self._since += 1
        self._low = self._low + 1 if level > 0 else 0
        if not np.isfinite(energy):
            return False
        e = self._energies
        e.append(float(energy))
        if len(e) >= s.floor_sets:
            self._floor = min(self._floor, float(np.median(e[-s.floor_sets:])))
        suspect = len(e) >= s.floor_sets and float(np.median(e[-s.recent:])) > s.suspect_factor * self._floor
        if suspect and self._low >= s.low_sets and self._since >= s.cooldown:
            self._since = 0
            self.probes += 1
            return True
        return False

    def adopt(self, probe_energy: float, track_energy: float) -> bool:
        """Whether the probe (its energy ``probe_energy``) replaces the track (``track_energy``, the same set)."""
        take = bool(np.isfinite(probe_energy) and (not np.isfinite(track_energy)
                                                  or probe_energy < self.settings.adopt_ratio * track_energy))
        self.adopted += take
        if take:
            self.restart()
            self._since = 0             # a new track, but the cooldown runs from the probe
        return take


def second_opinion(make_tracker: Callable, masks: Sequence, frame_index: int, track_result, recovery: Recovery):
    """One probe: ``make_tracker()`` (a new tracker like the track's, its predictor wrapped as the caller's) initialized
    automatically on ``masks`` (frame key ``frame_index``) without the initialization's polish, judged against
    ``track_result`` (the track's :class:`~.result.FrameResult` on the same set) by ``recovery``. Returns ``(probe
    tracker, probe result, adopted)``; the probe tracker keeps its configuration's polish for its later
    re-initializations."""
    probe = make_tracker()
    config = probe.config
    probe.config = config.replace(init_polish=False)
    try:
        result = probe.step(masks, frame_index)
    finally:
        probe.config = config
    adopted = result.x is not None and not result.fell_back and recovery.adopt(result.energy, track_result.energy)
    if adopted:
        result = dataclasses.replace(result, notes=result.notes + (
            f"recovered: a fresh initialization on this set ended {result.energy:.4g} against the track's "
            f"{track_result.energy:.4g}; it replaces the track",))
    return probe, result, adopted
