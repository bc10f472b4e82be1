"""The README's subscriber example works against a replayed bag (real processes over DDS)."""
from __future__ import annotations

from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]
REPO = Path(__file__).resolve().parents[1]


def test_subscribe_example_receives_joint_states(spawn):
    listener = spawn("listener", str(REPO / "examples" / "subscribe_joint_states.py"), "--count", "5")
    player = spawn("player", "-m", "isa_mocap_ros.cli.main", "play", str(REPO / "bags" / "fixture"),
                   "--topics", "/mocap/ground_truth/joint_states",
                   "--remap", "/mocap/ground_truth/joint_states:=/mocap/joint_states",
                   "--wait-for-subscribers", "30")
    assert player.popen.wait(60) == 0, player.output()
    assert listener.popen.wait(30) == 0, listener.output()
    lines = [l for l in listener.output().splitlines() if "left knee=" in l]
    assert len(lines) == 5 and "root=(" in lines[0]
