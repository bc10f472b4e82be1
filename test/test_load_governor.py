"""tracking/load.py: the budget ladder under load, driven by a fake clock (no real time)."""
import numpy as np
import pytest

from isa_mocap_ros.tracking.load import LEVELS, LoadError, LoadGovernor, LoadSettings

PERIOD = 1 / 30


def step_time(d, *, load=1.0, fixed=0.004, per_eval=10e-6, contour=0.008):
    """A tracker whose step costs a fixed part, a part per evaluation and the contour stage, all
    stretched by ``load`` (2: another process takes half the CPU)."""
    return load * (fixed + per_eval * d.evals + (contour if d.contour_stage else 0.0))


def simulate(gov, loads, *, n_sets=300, energy=0.1):
    """Frame sets arrive every PERIOD (fake clock); a busy tracker keeps only the newest waiting set
    (the estimator's backlog of 1), the others are dropped. ``loads(k)``: the load while set k is
    tracked. Returns (tracked set indices, dropped count, decisions)."""
    t_free = 0.0
    waiting = None
    tracked, dropped, decisions = [], 0, []
    dropped_since = 0
    d = gov.decision() if gov is not None else None
    full = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD)).decision()
    for k in range(n_sets):
        t = k * PERIOD
        # the tracker finishes the sets it can before this one arrives
        while waiting is not None and t_free <= t:
            start = max(t_free, waiting * PERIOD)
            dd = d if gov is not None else full
            s = step_time(dd, load=loads(waiting))
            t_free = start + s
            tracked.append(waiting)
            if gov is not None:
                d = gov.observe(step_s=s, energy=energy, dropped=dropped_since)
                decisions.append(d)
            dropped_since = 0
            waiting = None
        if waiting is not None:
            dropped += 1
            dropped_since += 1
        waiting = k
    return tracked, dropped, decisions


def test_full_budget_while_it_fits():
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD))
    for _ in range(50):
        d = g.observe(step_s=0.025, energy=0.1)
    assert (d.evals, d.contour_stage, d.level, d.reason) == (1500, True, 0, "")
    assert g.lowered == 0


def test_one_slow_set_is_noise():
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, down_after=2))
    g.observe(step_s=0.025, energy=0.1)
    assert g.observe(step_s=0.060, energy=0.1).level == 0
    assert g.observe(step_s=0.025, energy=0.1).level == 0
    d = g.observe(step_s=0.060, energy=0.1)
    assert d.level == 0
    d = g.observe(step_s=0.060, energy=0.1)
    # 60 ms: without the contour stage ~42 ms (over 0.85 × 33), at 67 % of the evaluations ~32 ms (its fixed share,
    # 0.3, does not scale), at 50 % 60 × 0.65 × 0.7 = 27 ms (fits)
    assert d.level == 3 and not d.contour_stage and d.evals == 750 and "over the frame period" in d.reason


def test_steps_down_the_ladder_and_not_below():
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, down_after=1, min_evals=600, fixed_share=0.0))
    levels = [g.observe(step_s=0.035, energy=0.1).level for _ in range(10)]     # just over: one level at a time
    assert levels == [1, 2, 3, 4, 4, 4, 4, 4, 4, 4]
    assert [g.budget(k) for k in range(len(LEVELS))] == [(1500, True), (1500, False), (1005, False), (750, False),
                                                         (600, False)]       # 0.33 × 1500 = 495 < min_evals
    assert g.lowered == 4


def test_far_over_the_period_steps_down_to_the_level_that_fits_at_once():
    """A step at three times the period goes to the level projected to fit (the whole step scaled with the
    evaluations, less the contour stage's share), not one level per down_after sets: each of those sets dropped
    one or two sets on the way down."""
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, down_after=2, min_evals=300))
    g.observe(step_s=0.1, energy=0.1)
    d = g.observe(step_s=0.1, energy=0.1)
    assert d.level == len(LEVELS) - 1 and d.evals == 495 and g.lowered == 1     # 100 × 0.7 × 0.33 = 23 ms
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, down_after=2, contour_share=0.0, fixed_share=0.0))
    g.observe(step_s=0.05, energy=0.1)
    assert g.observe(step_s=0.05, energy=0.1).level == 3                          # 50 × 0.5 = 25 ms
    # the step's fixed share does not scale: 50 × (0.3 + 0.7 × 0.5) = 32.5 ms at 750 is over, 26.5 ms at 495 fits
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, down_after=2, contour_share=0.0, fixed_share=0.3))
    g.observe(step_s=0.05, energy=0.1)
    assert g.observe(step_s=0.05, energy=0.1).level == 4
    with pytest.raises(LoadError, match="fixed_share"):
        LoadSettings(evals=1500, period_s=PERIOD, fixed_share=1.0)
    with pytest.raises(LoadError, match="contour_share"):
        LoadSettings(evals=1500, period_s=PERIOD, contour_share=1.0)


def test_drops_count_as_overload_beside_a_slow_step_only():
    """A set dropped beside a step that fit (under headroom × period) is not the budget's: bunched arrivals, the
    start-up's bursts. Beside a step over it (but under the period) it is; ``slow_drops_only=False`` counts every drop."""
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, down_after=2))
    for _ in range(5):
        d = g.observe(step_s=0.02, energy=0.1, dropped=2)
    assert d.level == 0 and g.lowered == 0
    g.observe(step_s=0.03, energy=0.1, dropped=1)              # 30 ms: under the period, over 0.85 × 33
    d = g.observe(step_s=0.03, energy=0.1, dropped=2)
    assert d.level == 1 and "2 set(s) dropped" in d.reason
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, down_after=2, slow_drops_only=False))
    g.observe(step_s=0.02, energy=0.1, dropped=1)
    d = g.observe(step_s=0.02, energy=0.1, dropped=2)
    assert d.level == 1 and "2 set(s) dropped" in d.reason


def test_no_step_up_to_the_contour_stage_that_cannot_fit():
    """At the full evaluations without the contour stage, a step of 25 ms fits 0.85 × 33 ms, but with the stage
    (projected 25 / (1 - contour_share) = 36 ms) it cannot: no try. Without ``contour_up_cost`` (the earlier policy)
    the stage's cost was not projected: it tried, came back down, and tried again after twice as many sets. Which
    drops count (``slow_drops_only``) does not change this: no set is dropped here."""
    for up_cost, slow_only, tries in ((True, True, 0), (False, True, 3), (True, False, 0), (False, False, 3)):
        g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, up_after=5, contour_up_cost=up_cost,
                                      slow_drops_only=slow_only, fixed_share=0.0))
        levels = [g.observe(step_s=0.036 if g.level == 0 else 0.025, energy=0.1).level for _ in range(120)]
        assert levels[1] == 1
        assert sum(a == 1 and b == 0 for a, b in zip(levels, levels[1:])) >= tries
        if not tries:
            assert set(levels[1:]) == {1}


def test_returns_to_the_full_budget_when_the_load_goes():
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, up_after=5))
    busy = [g.observe(step_s=step_time(g.decision(), load=2.5), energy=0.1).level for _ in range(30)]
    assert max(busy) >= 2
    idle = [g.observe(step_s=step_time(g.decision(), load=1.0), energy=0.1) for _ in range(60)]
    assert idle[-1].level == 0 and idle[-1].evals == 1500 and idle[-1].contour_stage
    # one level at a time, each after up_after sets with room
    ups = [d for d in idle if d.reason.startswith("caught up")]
    assert len(ups) == busy[-1]
    # an idle tracker at the full budget stays there
    assert all(d.level == 0 for d in idle[-20:])


def test_a_step_up_that_does_not_fit_waits_longer_next_time():
    # the full budget never fits (the contour stage alone is over), level 1 does: the governor tries the
    # full budget again, each time after twice as many sets, up to max_backoff
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, up_after=4, down_after=2, max_backoff=4))
    levels = [g.observe(step_s=step_time(g.decision(), contour=0.030), energy=0.1).level for _ in range(200)]
    tries = [i for i in range(1, len(levels)) if levels[i] == 0 and levels[i - 1] == 1]
    gaps = np.diff(tries)
    assert len(tries) >= 4 and list(gaps[:2]) == sorted(gaps[:2]) and gaps[1] > gaps[0]
    assert gaps[-1] == gaps[-2]                                  # capped at max_backoff × up_after
    assert sum(lv == 0 for lv in levels[20:]) < 0.2 * len(levels[20:])


def test_keeps_up_under_load_with_fewer_drops_than_the_full_budget():
    load = lambda k: 2.0 if 60 <= k < 240 else 1.0            # one core busy for 6 s of 10
    tracked_full, dropped_full, _ = simulate(None, load)
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD))
    tracked, dropped, decisions = simulate(g, load)
    assert dropped_full > 0.2 * 300
    assert dropped <= 0.10 * 300 and dropped < dropped_full / 3
    assert max(d.level for d in decisions) >= 1
    assert decisions[-1].level == 0                            # back to the full budget after the load


def test_lost_track_returns_to_full_budget_then_resets():
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, down_after=1, reset_after=4))
    for _ in range(10):
        g.observe(step_s=0.02, energy=0.1)
    g.observe(step_s=0.04, energy=0.1)          # 40 ms: without the contour stage 28 ms fits
    assert g.level == 1
    d = g.observe(step_s=0.1, energy=0.5)                      # 5 × the median energy: lost
    assert d.level == 0 and d.contour_stage and "track lost" in d.reason and not d.reset
    out = [g.observe(step_s=0.02, energy=0.5) for _ in range(3)]
    assert [o.reset for o in out] == [False, False, True] and "re-initializing" in out[-1].reason
    assert g.resets == 1
    # after the reset the energy statistics start anew: the new level is not "lost"
    assert all(not g.observe(step_s=0.02, energy=0.5).reset for _ in range(10))


def test_the_reset_restarts_the_energy_statistics_through_restart_energies():
    """The reset branch forgets the energies the one way a new track does (``restart_energies``, also the
    recovery's), so whatever that method forgets the reset forgets too."""
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, reset_after=2))
    calls = []
    original = g.restart_energies
    g.restart_energies = lambda: (calls.append(True), original())[1]
    for _ in range(6):
        g.observe(step_s=0.02, energy=0.1)
    assert g.reference_energy == 0.1 and not calls
    assert not g.observe(step_s=0.02, energy=0.5).reset
    assert g.observe(step_s=0.02, energy=0.5).reset
    assert calls == [True] and np.isnan(g.reference_energy) and g.lost_sets == 0


def test_reference_energy_and_lost_count_are_readable():
    """What a trace reports: the running median the lost test compares with (nan before 5 sets) and the lost count."""
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, reset_after=3))
    for e in (0.1, 0.3, 0.2, 0.1):
        g.observe(step_s=0.02, energy=e)
    assert np.isnan(g.reference_energy) and g.lost_sets == 0
    g.observe(step_s=0.02, energy=0.1)
    assert g.reference_energy == 0.1
    g.observe(step_s=0.02, energy=0.5)                          # 5 × the median: lost, not in the median
    assert g.lost_sets == 1 and g.reference_energy == 0.1


def test_fell_back_and_non_finite_energy_count_as_lost():
    g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, reset_after=2))
    assert not g.observe(step_s=0.02, energy=0.1, fell_back=True).reset
    assert g.observe(step_s=0.02, energy=float("nan")).reset


def test_same_inputs_same_decisions():
    rng = np.random.default_rng(3)
    steps = rng.uniform(0.01, 0.08, 200)
    energies = rng.uniform(0.05, 0.3, 200)

    def run():
        g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD))
        return [g.observe(step_s=s, energy=e) for s, e in zip(steps, energies)]
    assert run() == run()


@pytest.mark.parametrize("kw, match", [
    (dict(evals=0), "evals: expected an integer >= 1"),
    (dict(evals=1500.0), r"evals: expected an integer >= 1, received 1500\.0"),
    (dict(period_s=0.0), r"period_s: expected a finite number > 0\.0, received 0\.0"),
    (dict(period_s=float("inf")), "period_s: expected a finite number > 0"),
    (dict(headroom=1.5), r"headroom: expected a finite number in \(0\.0, 1\.0\], received 1\.5"),
    (dict(down_after=True), "down_after: expected an integer >= 1, received True"),
    (dict(lost_factor=0.5), r"lost_factor: expected a finite number > 1\.0"),
    (dict(max_backoff=0), "max_backoff: expected an integer >= 1, received 0"),
])
def test_bad_settings(kw, match):
    base = dict(evals=1500, period_s=PERIOD)
    with pytest.raises(LoadError, match=match):
        LoadSettings(**{**base, **kw})
    with pytest.raises(LoadError, match="settings: expected LoadSettings"):
        LoadGovernor({"evals": 1500})


def test_numpy_numbers_are_settings_too():
    # a budget read from an array (np.int64) is an integer; a numpy float a number
    g = LoadGovernor(LoadSettings(evals=np.int64(1500), period_s=np.float64(PERIOD), min_evals=np.int32(150)))
    assert g.decision().evals == 1500


def test_startup_catch_up_holds_the_sets_then_tracks_them_cheaply_until_none_waits():
    from isa_mocap_ros.tracking.load import StartupCatchUp

    c = StartupCatchUp(sets=12, evals=300, limit_ms=600.0)
    assert c.budget(1500, initialized=True, checking_heading=False) == (1500, True)   # nothing to catch up yet
    assert c.hold(3) == 12 and c.active
    # the initialization itself and the heading check's sets: the full budget
    assert c.budget(1500, initialized=False, checking_heading=False) == (1500, True)
    assert c.budget(1500, initialized=True, checking_heading=True) == (1500, True)
    # then the waiting sets: the catch-up budget (never above the governor's), no contour stage
    assert c.budget(1500, initialized=True, checking_heading=False) == (300, False)
    assert c.budget(200, initialized=True, checking_heading=False) == (200, False)
    assert c.after(waiting=5, waited_ms=250.0) is True
    c.budget(1500, initialized=True, checking_heading=False)
    assert c.after(waiting=3, waited_ms=200.0) is True                       # gaining
    c.budget(1500, initialized=True, checking_heading=False)
    assert c.after(waiting=0, waited_ms=40.0) is False and not c.active       # caught up
    assert c.budget(1500, initialized=True, checking_heading=False) == (1500, True)
    assert c.caught_up == 4
    # a caught-up set that waited too long, or no shorter than the one before, ends it (not gaining)
    c.hold(3)
    c.budget(1500, initialized=True, checking_heading=False)
    assert c.after(waiting=8, waited_ms=700.0) is False
    c.hold(3)
    assert c.after(waiting=8, waited_ms=300.0) is True        # a heading-check set (full budget): not compared
    c.budget(1500, initialized=True, checking_heading=False)
    assert c.after(waiting=8, waited_ms=320.0) is True
    c.budget(1500, initialized=True, checking_heading=False)
    assert c.after(waiting=9, waited_ms=330.0) is False
    # stale sets (stale_ms): only while catching up, only those that waited longer
    assert not c.stale(1e6)                                   # (not catching up now)
    s = StartupCatchUp(sets=12, evals=300, limit_ms=1000.0, stale_ms=50.0)
    assert not s.stale(80.0)
    s.hold(3)
    assert s.stale(80.0) and not s.stale(50.0) and not s.stale(20.0)
    assert not StartupCatchUp(sets=12, evals=300, limit_ms=1000.0).stale(1e6)    # 0: never
    # off: only the heading check's sets are held
    off = StartupCatchUp(sets=0, evals=300, limit_ms=600.0)
    assert off.hold(3) == 3 and not off.active
    assert off.budget(1500, initialized=True, checking_heading=False) == (1500, True)


@pytest.mark.parametrize("kwargs, match", [
    (dict(sets=-1, evals=300, limit_ms=1.0), "sets: expected an integer >= 0, received -1"),
    (dict(sets=2, evals=0, limit_ms=1.0), "evals: expected an integer >= 1, received 0"),
    (dict(sets=2, evals=True, limit_ms=1.0), "evals: expected an integer >= 1, received True"),
    (dict(sets=2, evals=10, limit_ms=float("nan")), "limit_ms: expected a finite number >= 0"),
    (dict(sets=2, evals=10, limit_ms=-1.0), "limit_ms: expected a finite number >= 0"),
    (dict(sets=2, evals=10, limit_ms=1.0, stale_ms=-1.0), "stale_ms: expected a finite number >= 0")])
def test_startup_catch_up_bad_settings(kwargs, match):
    from isa_mocap_ros.tracking.load import LoadError, StartupCatchUp

    with pytest.raises(LoadError, match=match):
        StartupCatchUp(**kwargs)


def test_the_fixed_share_lets_the_budget_climb_to_the_level_that_fits():
    """A tracker whose step is 8 ms plus 13 µs an evaluation (one thread, session 33's measured fit; 1500 evaluations
    26 ms, fits 0.85 × 33 ms; 1005 evaluations 21 ms): projected as if the whole step scaled with the evaluations
    (fixed_share 0) the climb from 1005 stops there (21 × 1.49 = 31 ms > 28), with the fixed share it reaches 1500."""
    cost = lambda d: 0.008 + 13e-6 * d.evals + (0.008 if d.contour_stage else 0.0)
    for fixed, top in ((0.0, 2), (0.3, 1)):
        g = LoadGovernor(LoadSettings(evals=1500, period_s=PERIOD, up_after=5, fixed_share=fixed))
        for _ in range(3):
            g.observe(step_s=0.1, energy=0.1)                   # a burst of load: down to the last level
        assert g.level == len(LEVELS) - 1
        levels = [g.observe(step_s=cost(g.decision()), energy=0.1).level for _ in range(100)]
        assert min(levels) == top and levels[-1] == top
