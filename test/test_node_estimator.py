"""Estimator node faults, with real processes: malformed masks, a wrong encoding, a silent view,
an out-of-order stamp and a prediction that never comes — it logs each and keeps estimating."""
from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from isa_mocap_ros.bag import BagReader
from rosnode import ros_node, spin_until

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]
HERE = Path(__file__).parent
FIXTURE = HERE.parent / "bags" / "fixture"
CONFIG = HERE.parent / "config" / "pipeline.yaml"


def test_estimator_survives_bad_input_and_keeps_estimating(spawn, rosenv, tmp_path):
    est = spawn("estimator", "-m", "isa_mocap_ros.nodes.estimator", "--ros-args", "-r", "__ns:=/mocap",
                "--params-file", str(CONFIG), "-p", "evals:=200", "-p", "optimizer:=isa",
                "-p", "view_timeout_s:=0.5", "-p", "min_views:=2")
    assert est.wait_for_output("estimator: ready", 120), est.output()
    rec = spawn("recorder", "-m", "isa_mocap_ros.cli.main", "record", str(tmp_path / "out"),
                "--topics", "/mocap/joint_states", "/mocap/estimator/done")
    assert rec.wait_for_output("recording to", 30)
    # the recorder's readers must be discovered before the first estimate goes out (once in CI under
    # load the first estimates went out before the match and the bag held 10 of 12)
    with ros_node(rosenv, "est_test") as (node, ex):
        assert spin_until(ex, lambda: node.count_subscribers("/mocap/joint_states") > 0
                          and node.count_subscribers("/mocap/estimator/done") > 0, 30)
    time.sleep(0.5)
    feeder = spawn("feeder", str(HERE / "mask_feeder.py"), str(FIXTURE))
    assert feeder.popen.wait(200) == 0, feeder.output()
    time.sleep(1.0)
    rec.stop(signal.SIGINT)
    assert est.popen.poll() is None, "the estimator must still be running"
    log = est.output()
    assert "cam1/mask dropped" in log and "data" in log            # length disagrees with height*step
    assert "cam2/mask dropped" in log and "mono8" in log            # wrong encoding
    assert "without views [" in log                                 # missing/silent views -> partial sets
    assert "not newer than the last emitted" in log                 # out-of-order stamp
    assert "Traceback" not in log
    fed = feeder.output()
    assert fed.count("done ") >= 14, fed                            # every frame set was answered
    with BagReader(tmp_path / "out") as r:
        n_js = r.topics["/mocap/joint_states"].message_count
    with BagReader(FIXTURE) as r:
        n_person = r.topics["/mocap/ground_truth/joint_states"].message_count
    assert n_js == n_person, (n_js, n_person)                       # an estimate for every person frame
    est.stop(signal.SIGINT)
    assert est.popen.returncode == 0, est.output()[-2000:]
