"""`isa-mocap run`'s summary helpers (pure functions)."""
from isa_mocap_ros.cli.run_report import _first_gap


def test_start_up_drops_are_the_first_gap_after_the_first_estimate():
    played = list(range(20))
    # initialized on 0, the sets that came meanwhile dropped (no heading check)
    assert _first_gap([0, 5, 6, 7], played) == 4
    # real time with the hold: 0 initialized, 1-3 the heading check's held sets, then the jump
    assert _first_gap([0, 1, 2, 3, 12, 13, 15], played) == 8
    # lockstep: every set estimated; a gap at the very end is not the start-up's
    assert _first_gap(played, played) == 0
    assert _first_gap([0, 1, 2], played) == 0
    # sets before the first estimate (nobody in view yet) do not count
    assert _first_gap([4, 5, 9], played) == 3


def test_the_table_says_no_ground_truth_plainly():
    from isa_mocap_ros.cli.run_report import summary_rows

    base = {"fps": 5.0, "latency_ms_p50": 1.0, "latency_ms_p95": 2.0, "dropped_frames": 0, "bad_inputs": 0,
            "optimizer": "isa", "evals_per_frame": 300, "frames_estimated": 135}
    rows = dict(summary_rows({**base, "ground_truth": False, "accuracy": "no ground truth in the bag"}))
    assert rows["accuracy"] == "no ground truth in the bag"
    assert "mean joint error (mm)" not in rows and "frames (with ground truth)" not in rows
    assert rows["frames estimated"] == 135
    rows = dict(summary_rows({**base, "ground_truth": True, "frames": 120, "mpjpe_mm": 6.5}))
    assert rows["frames (with ground truth)"] == 120 and rows["mean joint error (mm)"] == 6.5
    assert "accuracy" not in rows
