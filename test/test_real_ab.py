"""tools/real_ab.py: where the real recording's error exceeds the target (docs/history/issue34_real_recording.md)."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

_SPEC = importlib.util.spec_from_file_location("real_ab", Path(__file__).resolve().parents[1] / "tools" / "real_ab.py")
real_ab = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(real_ab)


def test_excess_is_split_by_joint_and_frame():
    # two joints, four frames: frame means 30, 40, 50, 60 -> 5 mm over 40 on average; frames above: 50 and 60
    x = real_ab.excess({"head": [40.0, 60.0, 80.0, 100.0], "neck": [20.0, 20.0, 20.0, 20.0]}, 40.0)
    assert x["mean_over_mm"] == pytest.approx(5.0)
    assert x["frames"] == 4 and x["frames_above"] == 2
    assert x["carried_mm"] == pytest.approx((10.0 + 20.0) / 4)
    assert x["per_joint_mm"] == pytest.approx({"head": (70.0 - 40.0) / 2, "neck": (20.0 - 40.0) / 2})
    assert sum(x["per_joint_mm"].values()) == pytest.approx(x["mean_over_mm"])


def test_missing_points_are_left_out():
    x = real_ab.excess({"a": [50.0, np.nan], "b": [50.0, 30.0]}, 40.0)
    assert x["frames_above"] == 1 and x["mean_over_mm"] == pytest.approx(0.0)      # frame means 50, 30


def test_blocks_of_ten_frames():
    assert real_ab._blocks(np.arange(25.0)) == [4.5, 14.5, 22.0]
