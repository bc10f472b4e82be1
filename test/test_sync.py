"""Frame-set synchronizer: exact and approximate (message_filters semantics), partial sets, order."""
from __future__ import annotations

import pytest

from isa_mocap_ros.tracking.sync import FrameSynchronizer, LatestSlot, SyncError

MS = 1_000_000


def test_exact_emits_when_every_view_has_the_stamp():
    s = FrameSynchronizer(3)
    assert s.add(0, 100, "a0", 0.0) == []
    assert s.add(2, 100, "c0", 0.0) == []
    out = s.add(1, 100, "b0", 0.0)
    assert len(out) == 1 and out[0].items == ("a0", "b0", "c0") and out[0].stamp_ns == 100
    assert out[0].missing == ()


def test_exact_out_of_order_views_and_interleaved_stamps():
    s = FrameSynchronizer(2)
    assert s.add(0, 100, "a0", 0) == [] and s.add(0, 200, "a1", 0) == []
    assert [f.stamp_ns for f in s.add(1, 100, "b0", 0)] == [100]
    assert [f.items for f in s.add(1, 200, "b1", 0)] == [("a1", "b1")]


def test_queue_size_drops_oldest():
    s = FrameSynchronizer(2, queue_size=2)
    for k in range(3):
        s.add(0, 100 * (k + 1), k, 0)
    assert s.dropped == 1
    assert s.add(1, 100, "late", 0) == []  # stamp 100 was evicted from view 0
    assert [f.items for f in s.add(1, 200, "b", 0)] == [(1, "b")]


def test_approximate_matches_within_slop_closest_first():
    s = FrameSynchronizer(2, slop_ns=10 * MS)
    s.add(0, 100 * MS, "a-far", 0)
    s.add(0, 104 * MS, "a-near", 0)
    out = s.add(1, 105 * MS, "b", 0)
    assert len(out) == 1 and out[0].items == ("a-near", "b")
    # a-far is older than the emitted set: it can never be used, it is dropped
    assert s.dropped == 1


def test_approximate_rejects_spread_at_or_above_slop():
    s = FrameSynchronizer(3, slop_ns=10 * MS)
    s.add(0, 100 * MS, "a", 0)
    s.add(1, 109 * MS, "b", 0)
    assert s.add(2, 91 * MS, "c", 0) == []  # b is 18 ms from c: no set
    assert s.add(2, 105 * MS, "c2", 0)[0].items == ("a", "b", "c2")


def test_partial_set_after_a_view_goes_silent():
    s = FrameSynchronizer(3, max_wait_s=0.5, min_views=2)
    s.add(0, 100, "a", 10.0)
    s.add(1, 100, "b", 10.1)
    assert s.poll(10.3) == []
    out = s.poll(10.6)
    assert len(out) == 1 and out[0].items == ("a", "b", None) and out[0].missing == (2,)
    s.add(0, 200, "lonely", 11.0)
    assert s.poll(12.0) == [] and s.dropped == 1  # one view is below min_views: given up


def test_out_of_order_stamp_rejected():
    s = FrameSynchronizer(1)
    assert len(s.add(0, 200, "x", 0)) == 1
    with pytest.raises(SyncError, match="not newer than the last emitted"):
        s.add(0, 100, "old", 0)


@pytest.mark.parametrize("kw", [dict(n_views=0), dict(n_views=2, queue_size=0), dict(n_views=2, slop_ns=-1),
                                dict(n_views=2, min_views=3)])
def test_bad_configuration(kw):
    with pytest.raises(SyncError):
        FrameSynchronizer(**kw)


def test_latest_slot_keeps_newest_and_counts_drops():
    slot = LatestSlot()
    for k in range(4):
        slot.put(k)
    assert slot.take() == 3 and slot.dropped == 3 and slot.take() is None
    lock = LatestSlot(keep_all=True)
    for k in range(4):
        lock.put(k)
    assert [lock.take() for _ in range(4)] == [0, 1, 2, 3] and lock.dropped == 0


def test_latest_slot_with_depth_keeps_the_newest_sets_in_order():
    slot = LatestSlot(depth=2)
    for k in range(5):
        slot.put(k)
    assert slot.dropped == 3 and [slot.take(), slot.take(), slot.take()] == [3, 4, None]
    for bad in (0, -1, 1.5, True):
        with pytest.raises(SyncError, match="depth: expected an integer >= 1"):
            LatestSlot(depth=bad)


def test_latest_slot_hold_keeps_the_sets_in_sequence():
    # the worker is busy with set 0 (an initialization): the 3 sets after it are held, the rest is
    # replaced by the newest; each held set taken shortens the hold
    slot = LatestSlot()
    slot.hold(3)
    for k in range(1, 8):
        slot.put(k)
    assert slot.held == 3 and slot.dropped == 3 and len(slot) == 4
    assert slot.take() == 1 and slot.held == 2
    slot.put(8)                                       # 7 replaced by 8, 2 and 3 still held
    assert slot.dropped == 4 and slot.take() == 2 and slot.held == 1
    # the hold ends (the heading check decided): the held set still waiting goes, the newest stays
    slot.hold(0)
    assert slot.dropped == 5 and slot.take() == 8 and slot.take() is None
    slot.put(9)
    slot.put(10)
    assert slot.take() == 10 and slot.dropped == 6  # back to keeping the newest only
    slot.hold(0)                                      # no hold: nothing to drop
    assert slot.dropped == 6
    lock = LatestSlot(keep_all=True)
    lock.hold(2)
    for k in range(5):
        lock.put(k)
    lock.hold(0)
    assert [lock.take() for _ in range(5)] == [0, 1, 2, 3, 4] and lock.dropped == 0


def test_latest_slot_drop_oldest_takes_a_held_set_first_and_counts_it():
    slot = LatestSlot()
    assert slot.oldest() is None
    slot.drop_oldest()                                # nothing waits: nothing dropped
    assert slot.dropped == 0
    slot.hold(3)
    for k in range(5):
        slot.put(k)                                   # held 0, 1, 2 and the newest 4 (3 replaced)
    assert slot.dropped == 1 and slot.oldest() == 0 and slot.held == 3
    slot.drop_oldest()                                # the start-up catch-up's stale set
    assert slot.dropped == 2 and slot.held == 2 and slot.oldest() == 1 and len(slot) == 3
    assert slot.take() == 1 and slot.held == 1
    slot.drop_oldest()
    slot.drop_oldest()                                # past the hold: the newest goes too when asked
    assert slot.held == 0 and len(slot) == 0 and slot.dropped == 4


@pytest.mark.parametrize("bad", [-1, 1.5, True, "2"])
def test_latest_slot_bad_hold(bad):
    with pytest.raises(SyncError, match="hold: expected an integer >= 0"):
        LatestSlot().hold(bad)
