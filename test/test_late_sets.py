"""LateSetShedder: sets decided at their first image, the stream's offset, bursts."""
from __future__ import annotations

import pytest

from isa_mocap_ros.late_sets import Burst, LateSetShedder

MS = 1_000_000
PERIOD = 33 * MS


def _feed(s, stamps_arrivals, views=4):
    """Each set's images arriving 1 ms apart from its first one's arrival; the sets' decisions per view."""
    return [[s.shed(t, arrival_ns=a + v * MS) for v in range(views)] for t, a in stamps_arrivals]


def test_a_set_late_at_its_first_image_is_shed_in_every_view_and_an_on_time_one_in_none():
    s = LateSetShedder(50 * MS, leak=0.0)
    base = 10**18
    # sets on time (5 ms transport), then three arriving 80-120 ms late, then on time again
    plan = [(base + k * PERIOD, base + k * PERIOD + 5 * MS + (80 + 20 * (k - 4)) * MS * (4 <= k <= 6))
            for k in range(10)]
    got = _feed(s, plan)
    assert got == [[k in (4, 5, 6)] * 4 for k in range(10)]
    assert s.shed_sets == 3
    assert s.pop_burst() == Burst(3, plan[4][0], plan[6][0], 120 * MS) and s.pop_burst() is None


def test_a_set_kept_at_its_first_image_keeps_its_later_views_however_late_they_come():
    s = LateSetShedder(50 * MS)
    s.shed(0, arrival_ns=5 * MS)
    assert not s.shed(PERIOD, arrival_ns=PERIOD + 10 * MS)
    assert not s.shed(PERIOD, arrival_ns=PERIOD + 300 * MS)     # the set is whole or nothing


def test_off_keeps_everything():
    s = LateSetShedder(0)
    assert not s.enabled
    assert not any(s.shed(k * PERIOD, arrival_ns=k * PERIOD + k * 100 * MS) for k in range(20))
    assert s.shed_sets == 0 and s.pop_burst(flush=True) is None


def test_the_offset_is_the_smallest_delay_and_restarts_when_the_stream_jumps():
    s = LateSetShedder(50 * MS, reset_ns=5000 * MS, leak=0.0)
    assert not s.shed(0, arrival_ns=1000 * MS)                  # any base: the offset is learnt (1 s)
    assert s.offset_ns == 1000 * MS
    assert not s.shed(PERIOD, arrival_ns=PERIOD + 990 * MS)     # a faster delivery lowers it
    assert s.offset_ns == 990 * MS
    assert s.shed(2 * PERIOD, arrival_ns=2 * PERIOD + 1100 * MS)
    # a bag looped: the stamps go back by 60 s, so arrival - stamp jumps; the offset restarts there
    assert not s.shed(3 * PERIOD - 60_000 * MS, arrival_ns=3 * PERIOD + 990 * MS)
    assert s.offset_ns == 60_990 * MS
    assert s.pop_burst() == Burst(1, 2 * PERIOD, 2 * PERIOD, 110 * MS)


def test_the_offset_leaks_upwards_so_a_clock_drift_is_forgotten():
    # the stamps' clock runs 0.5 ms/s slow: without the leak every set would be shed after 100 s
    drift = [(k * PERIOD, k * PERIOD + 5 * MS + (k * PERIOD) // 2000) for k in range(3000 * 3)]
    leaky, fixed = LateSetShedder(50 * MS), LateSetShedder(50 * MS, leak=0.0)
    assert not any([leaky.shed(t, arrival_ns=a) for t, a in drift])
    assert sum(fixed.shed(t, arrival_ns=a) for t, a in drift) > len(drift) // 2


def test_a_burst_still_going_at_shutdown_is_flushed_once():
    s = LateSetShedder(50 * MS, leak=0.0)
    s.shed(0, arrival_ns=0)
    s.shed(PERIOD, arrival_ns=PERIOD + 200 * MS)
    assert s.pop_burst() is None
    assert s.pop_burst(flush=True) == Burst(1, PERIOD, PERIOD, 200 * MS) and s.pop_burst(flush=True) is None


@pytest.mark.parametrize("bad", [dict(max_age_ns=-1), dict(max_age_ns=1, reset_ns=0), dict(max_age_ns=1, leak=-1.0),
                                 dict(max_age_ns=1, remember=0)])
def test_bad_settings_are_one_clear_error(bad):
    with pytest.raises(ValueError, match="LateSetShedder: expected"):
        LateSetShedder(**bad)


@pytest.mark.parametrize("lockstep, rate, forced_off", [(True, 1.0, True), (False, 2.0, True), (False, 1.0, False)])
def test_run_turns_the_shedding_off_in_lockstep_and_at_other_rates(tmp_path, lockstep, rate, forced_off):
    """``isa-mocap run``: lockstep stays bit for bit the offline tracker, and at a rate other than 1.0 the stamps'
    age is not readable; in real time at rate 1.0 the parameter file's ``late_set_s`` is left as it is."""
    import argparse

    from isa_mocap_ros.cli.run import _network

    args = argparse.Namespace(lockstep=lockstep, rate=rate, optimizer=None, evals=None, model=None, seed=None,
                              helper_nice=0, keypoints=False, single_process=False)
    specs = _network(args, "params.yaml", tmp_path, 4, 10)
    seg = dict(next(s for s in specs if s.name == "segmentation").params)
    assert (seg.get("late_set_s") == "0.0") == forced_off, seg
