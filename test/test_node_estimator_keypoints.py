"""The lockstep estimator waits for the keypoint node as long as it is there (a real estimator process over DDS).

This test plays the keypoint node: it answers each frame set's views with skip notices only after a pause longer
than the estimator's ``keypoint_wait_s``. A lockstep replay must not depend on how fast the keypoint node is on a
loaded machine: with a time limit (10 s by default) a slow detection made the run go on without the set's
keypoints and differ from ``isa-mocap track`` from the first frame with a person (test_network_keypoints under load).
Once no keypoint node is in the graph (its publishers gone), ``keypoint_wait_s`` applies and the set goes on.
"""
from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from rosnode import mask_publishers, masks_by_stamp, ros_node, spin_until

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]
HERE = Path(__file__).parent
FIXTURE = HERE.parent / "bags" / "fixture"
CONFIG = HERE.parent / "config" / "pipeline.yaml"
WAIT_S = 1.0          # the estimator's keypoint_wait_s here
ANSWER_AFTER_S = 2.5  # the stand-in keypoint node answers this much later


def test_lockstep_waits_for_a_slow_keypoint_node_and_goes_on_without_one(spawn, rosenv):
    from std_msgs.msg import Header

    import msg_adapters as ma

    frames, latched = masks_by_stamp(FIXTURE)
    stamps = sorted(frames)[:4]
    est = spawn("estimator", "-m", "isa_mocap_ros.nodes.estimator", "--ros-args", "-r", "__ns:=/mocap",
                "--params-file", str(CONFIG), "-p", "evals:=200", "-p", "optimizer:=isa", "-p", "lockstep:=true",
                "-p", "view_timeout_s:=0.0", "-p", "use_prediction:=false", "-p", "keypoint_weight:=1.0",
                "-p", f"keypoint_wait_s:={WAIT_S}")
    assert est.wait_for_output("estimator: ready", 120), est.output()
    with ros_node(rosenv, "slow_keypoints") as (node, ex):
        pubs = mask_publishers(node, frames, latched)
        skipped = [node.create_publisher(Header, f"/mocap/cam{v}/keypoints_skipped", 10) for v in range(4)]
        done: dict[int, float] = {}
        node.create_subscription(Header, "/mocap/estimator/done",
                                 lambda h: done.setdefault(ma.stamp_to_ns(h), time.monotonic()), 10)
        assert spin_until(ex, lambda: all(p.get_subscription_count() > 0 for p in [*pubs.values(), *skipped]), 30)
        time.sleep(1.0)
        for s in stamps[:3]:
            for topic, msg in sorted(frames[s].items()):
                pubs[topic].publish(msg)
            spin_until(ex, lambda: s in done, ANSWER_AFTER_S)
            assert s not in done, f"frame {s} went on after {WAIT_S} s without the keypoint node's answer"
            answered = time.monotonic()
            for v, p in enumerate(skipped):
                p.publish(ma.make_header(s, f"cam{v}_optical_frame"))
            assert spin_until(ex, lambda: s in done, 20), est.output()[-3000:]
            assert done[s] >= answered
        # the keypoint node leaves the graph: the next set waits keypoint_wait_s, then goes on without it
        for p in skipped:
            node.destroy_publisher(p)
        spin_until(ex, lambda: False, 1.5)
        s = stamps[3]
        for topic, msg in sorted(frames[s].items()):
            pubs[topic].publish(msg)
        assert spin_until(ex, lambda: s in done, 20), est.output()[-3000:]
    log = est.output()
    lost = [ln for ln in log.splitlines() if "no keypoints or skip notice" in ln]
    assert len(lost) == 1 and str(stamps[3]) in lost[0] and "without a keypoint node in the graph" in lost[0], log[-3000:]
    assert "Traceback" not in log
    est.stop(signal.SIGINT)
    assert est.popen.returncode == 0, est.output()[-2000:]
