"""The live network under the launcher: camera (synthetic person) -> segmentation -> estimator, with
the estimator killed mid-run (SIGKILL) and respawned; estimates resume, the other nodes keep going."""
from __future__ import annotations

import os
import re
import signal
import time
from pathlib import Path

import pytest
import yaml

from isa_mocap_ros.bag import BagReader

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.timeout(400)]
REPO = Path(__file__).resolve().parents[1]


def _count(bag: Path, topic: str) -> int:
    with BagReader(bag) as r:
        return r.topics[topic].message_count if topic in r.topics else 0


def test_estimator_killed_and_respawned_mid_run(spawn, tmp_path):
    params = yaml.safe_load((REPO / "config" / "pipeline.yaml").read_text())
    cam = params["/mocap/camera"]["ros__parameters"]
    cam.update(views=2, width=160, height=120, fps=5.0, empty_frames=3, motion="walk")
    params["/mocap/segmentation"]["ros__parameters"].update(views=2, learn_frames=3)
    params["/mocap/estimator"]["ros__parameters"].update(views=2, evals=200, optimizer="isa", min_views=1)
    pfile = tmp_path / "params.yaml"
    pfile.write_text(yaml.safe_dump(params))
    lf = tmp_path / "live.launch.yaml"
    lf.write_text((REPO / "launch" / "mocap.launch.yaml").read_text())
    launch = spawn("launch", "-m", "isa_mocap_ros.cli.main", "launch", str(lf), f"params:={pfile}")
    rec = spawn("recorder", "-m", "isa_mocap_ros.cli.main", "record", str(tmp_path / "rec"),
                "--topics", "/mocap/joint_states", "/mocap/cam0/mask")
    assert launch.wait_for_output("estimator: ready", 180), launch.output()[-3000:]
    deadline = time.monotonic() + 120
    while "estimator]: frame" not in launch.output() and time.monotonic() < deadline:
        time.sleep(0.5)
    time.sleep(4.0)
    pid = int(re.findall(r"started estimator \(pid (\d+)\)", launch.output())[-1])
    os.kill(pid, signal.SIGKILL)
    assert launch.wait_for_output("estimator exited with code -9; respawning", 30), launch.output()[-3000:]
    deadline = time.monotonic() + 180
    while launch.output().count("estimator: ready") < 2 and time.monotonic() < deadline:
        time.sleep(0.5)
    assert launch.output().count("estimator: ready") == 2, launch.output()[-3000:]
    t_back = time.monotonic()
    time.sleep(8.0)
    rec.stop(signal.SIGINT)
    assert launch.stop(signal.SIGINT, timeout=60) == 0, launch.output()[-3000:]
    out = launch.output()
    assert "Traceback" not in out
    # estimates before the kill and again after the respawned estimator was ready
    with BagReader(tmp_path / "rec") as r:
        times = [m.log_time_ns for m in r.messages(["/mocap/joint_states"])]
        masks = r.topics["/mocap/cam0/mask"].message_count
    back_ns = time.time_ns() - int((time.monotonic() - t_back) * 1e9)   # wall time of the second "ready"
    assert any(t < back_ns for t in times) and any(t > back_ns for t in times), (len(times), masks)
    assert masks > 20          # segmentation kept publishing throughout
