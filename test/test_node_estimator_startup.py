"""The estimator node's start-up, with a real process: the per-camera data (tracking/camera_data.py) are built from
the camera_infos and extrinsics while the worker waits, before the first frame set, and the tracker made on that set
finds them (the same camera geometry, ``Camera.key``)."""
from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import pytest

from rosnode import mask_publishers, masks_by_stamp, ros_node, spin_until

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]
HERE = Path(__file__).parent
FIXTURE = HERE.parent / "bags" / "fixture"
CONFIG = HERE.parent / "config" / "pipeline.yaml"


def _diag(msg) -> dict:
    return {kv.key: kv.value for st in msg.status if st.name.endswith("estimator") for kv in st.values}


def test_the_camera_data_are_built_from_the_camera_infos_before_the_first_frame_set(spawn, rosenv):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Header

    import msg_adapters as ma

    frames, latched = masks_by_stamp(FIXTURE)
    stamps = sorted(frames)
    est = spawn("estimator", "-m", "isa_mocap_ros.nodes.estimator", "--ros-args", "-r", "__ns:=/mocap",
                "--params-file", str(CONFIG), "-p", "evals:=200", "-p", "optimizer:=isa", "-p", "use_prediction:=false")
    assert est.wait_for_output("estimator: ready", 120), est.output()
    with ros_node(rosenv, "startup_test") as (node, ex):
        pubs = mask_publishers(node, frames, latched)
        diag, done = [{}], set()
        node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: diag.__setitem__(0, _diag(m) or diag[0]), 10)
        node.create_subscription(Header, "/mocap/estimator/done", lambda h: done.add(ma.stamp_to_ns(h)), 10)
        assert spin_until(ex, lambda: all(p.get_subscription_count() > 0 for p in pubs.values()), 30)
        time.sleep(1.0)
        assert spin_until(ex, lambda: diag[0].get("cameras_built_ahead") == "0", 10), diag[0]
        # the first set's camera_infos alone: the worker builds the four cameras' data while it waits
        for topic, msg in sorted(frames[stamps[0]].items()):
            if topic.endswith("camera_info"):
                pubs[topic].publish(msg)
        assert spin_until(ex, lambda: diag[0].get("cameras_built_ahead") == "4", 20), (diag[0], est.output()[-2000:])
        assert float(diag[0]["camera_data_ahead_ms"]) > 0
        assert diag[0]["frames"] == "0"                 # no frame set yet: built ahead of it
        for s in stamps[:3]:                             # then the sets, masks and camera_infos
            for topic, msg in sorted(frames[s].items()):
                pubs[topic].publish(msg)
            assert spin_until(ex, lambda: s in done, 30), est.output()[-3000:]
        assert spin_until(ex, lambda: diag[0].get("frames") == "3", 5), diag[0]
        # the tracker made on the first set found all four (the same geometry as its cameras'), none built twice
        assert diag[0]["cameras_ready_ahead"] == "4", diag[0]
        assert diag[0]["cameras_built_ahead"] == "4", diag[0]
        assert json.loads(diag[0]["problems"]) == {}, diag[0]
    est.stop(signal.SIGINT)
    assert est.popen.returncode == 0, est.output()[-2000:]


def test_the_initialization_is_rehearsed_on_the_real_cameras_while_the_frame_sets_are_empty(spawn, rosenv):
    """``startup_rehearsal``: after 2 sets without foreground the idle worker runs the first-frame hull once on the
    tracker's cameras (a rendered body), so the first real initialization does not pay its one-time costs; then the real
    sets initialize and track as usual."""
    import copy

    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Header

    import msg_adapters as ma

    frames, latched = masks_by_stamp(FIXTURE)
    stamps = sorted(frames)
    est = spawn("estimator", "-m", "isa_mocap_ros.nodes.estimator", "--ros-args", "-r", "__ns:=/mocap",
                "--params-file", str(CONFIG), "-p", "evals:=200", "-p", "optimizer:=isa", "-p", "use_prediction:=false",
                "-p", "lockstep:=true")
    assert est.wait_for_output("estimator: ready", 120), est.output()
    with ros_node(rosenv, "rehearsal_test") as (node, ex):
        pubs = mask_publishers(node, frames, latched)
        diag, done, estimates = [{}], set(), {}
        node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: diag.__setitem__(0, _diag(m) or diag[0]), 10)
        node.create_subscription(Header, "/mocap/estimator/done", lambda h: done.add(ma.stamp_to_ns(h)), 10)
        node.create_subscription(JointState, "/mocap/joint_states",
                                 lambda m: estimates.__setitem__(ma.stamp_to_ns(m.header), m), 10)
        assert spin_until(ex, lambda: all(p.get_subscription_count() > 0 for p in pubs.values()), 30)
        time.sleep(1.0)

        def publish(s, empty):
            for topic, msg in sorted(frames[s].items()):
                if empty and topic.endswith("mask"):
                    msg = copy.deepcopy(msg)
                    msg.data = bytes(len(msg.data))          # nobody in view (a learning frame's mask)
                pubs[topic].publish(msg)
            assert spin_until(ex, lambda: s in done, 60), est.output()[-3000:]

        publish(stamps[0], True)
        time.sleep(0.5)
        assert spin_until(ex, lambda: diag[0].get("frames") == "1", 5), diag[0]
        assert diag[0]["init_rehearsal_ms"] == "0.0", diag[0]           # 1 empty set: not yet
        for s in stamps[1:3]:
            publish(s, True)
        assert spin_until(ex, lambda: float(diag[0].get("init_rehearsal_ms", 0)) > 0, 60), (diag[0], est.output()[-3000:])
        for s in stamps[3:6]:
            publish(s, False)
        assert spin_until(ex, lambda: diag[0].get("frames") == "6" and set(stamps[3:6]) <= set(estimates), 10), diag[0]
        assert float(diag[0]["init_cpu_ms"]) > 0, diag[0]
        assert not estimates.keys() & set(stamps[:3])                     # the empty sets: no estimate
        assert "rehearsal" not in json.loads(diag[0]["events"]), diag[0]   # (a failure would be an event)
        assert json.loads(diag[0]["problems"]) == {}, diag[0]
    est.stop(signal.SIGINT)
    assert est.popen.returncode == 0, est.output()[-2000:]
