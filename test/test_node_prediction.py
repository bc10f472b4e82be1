"""Prediction node as a real process: exact extrapolation, next-frame stamps, reordered names, faults."""
from __future__ import annotations


import numpy as np
import pytest
import yaml
from sensor_msgs.msg import JointState

import msg_adapters as ma
from isa_mocap_ros.body import make_model, pose_to_joint_state
from isa_mocap_ros.geometry import exp_se3, matrix_to_pose, pose_to_matrix
from isa_mocap_ros.nodes import qos
from rosnode import ros_node, spin_until

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]
NODE = ["-m", "isa_mocap_ros.nodes.prediction", "--ros-args", "-r", "__ns:=/mocap"]
PERIOD_NS = 40_000_000
T0 = 1_700_000_000 * 10**9


def constant_twist_estimates(n: int, rng: np.random.Generator):
    """JointState positions of an 18-DOF body whose root moves by a constant twist, joints at constant speed."""
    model = make_model(18)
    step = exp_se3(np.concatenate([rng.normal(0, 0.03, 3), rng.normal(0, 0.05, 3)]))
    P = pose_to_matrix(np.concatenate([rng.normal(0, 0.5, 3), rng.normal(0, 0.3, 3)]))
    q0, dq = rng.normal(0, 0.3, model.dof - 6), rng.normal(0, 0.02, model.dof - 6)
    X = []
    for k in range(n):
        X.append(np.concatenate([matrix_to_pose(P), q0 + k * dq]))
        P = P @ step
    return model, pose_to_joint_state(model, np.array(X))


class Harness:
    def __init__(self, node, ex):
        self.node, self.ex = node, ex
        self.pub = node.create_publisher(JointState, "/mocap/joint_states", qos.RELIABLE)
        self.got: dict[int, JointState] = {}
        self.count = 0
        self.sub = node.create_subscription(JointState, "/mocap/prediction/joint_states", self._on, qos.RELIABLE)

    def _on(self, msg: JointState) -> None:
        self.got[ma.stamp_to_ns(msg.header)] = msg
        self.count += 1

    def connected(self) -> bool:
        # both directions matched on this side; the node's publisher may match our subscription a moment
        # later (a prediction published before that is lost), hence the settling spin in wait_connected
        return self.pub.get_subscription_count() > 0 and self.sub.get_publisher_count() > 0

    def wait_connected(self) -> bool:
        ok = spin_until(self.ex, self.connected, 20)
        spin_until(self.ex, lambda: False, 0.5)
        return ok

    def send(self, msg: JointState, *, expect: bool = True) -> JointState | None:
        want = ma.stamp_to_ns(msg.header) + PERIOD_NS
        before = self.count
        self.pub.publish(msg)
        if not expect:
            spin_until(self.ex, lambda: False, 0.3)
            assert self.count == before, "a dropped estimate gave a prediction"
            return None
        assert spin_until(self.ex, lambda: want in self.got, 10), f"no prediction stamped {want}"
        return self.got[want]


def _start(spawn, tmp_path, **extra):
    params = {"predictor": "ar", "order": 2, "frame_period_s": PERIOD_NS / 1e9, **extra}
    path = tmp_path / "pred.yaml"
    path.write_text(yaml.safe_dump({"/mocap/prediction": {"ros__parameters": params}}))
    proc = spawn("prediction", *NODE, "--params-file", str(path))
    assert proc.wait_for_output("prediction: ar order 2", 60), proc.output()
    return proc


def test_constant_twist_sequence_is_extrapolated_exactly_for_the_next_stamp(spawn, rosenv, tmp_path):
    proc = _start(spawn, tmp_path)
    model, Q = constant_twist_estimates(9, np.random.default_rng(5))
    names = list(model.dof_names)
    perm = np.random.default_rng(1).permutation(len(names))
    with ros_node(rosenv, "pred_test") as (node, ex):
        h = Harness(node, ex)
        assert h.wait_connected()
        for k in range(8):
            stamp = T0 + k * PERIOD_NS
            if k in (4, 6):   # joints listed in another order: reordered by name
                msg = ma.arrays_to_joint_state([names[i] for i in perm], Q[k][perm], stamp_ns=stamp, frame_id="world")
            else:
                msg = ma.arrays_to_joint_state(names, Q[k], stamp_ns=stamp, frame_id="world")
            pred = h.send(msg)
            assert list(pred.name) == names and pred.header.frame_id == "world"
            want = Q[k + 1] if k >= 1 else Q[k]   # one estimate: the pose itself
            np.testing.assert_allclose(np.array(pred.position), want, rtol=0, atol=1e-9)
    assert proc.popen.poll() is None
    assert proc.stop() == 0
    assert "8 predictions published, 0 estimates dropped" in proc.output()


def test_estimates_with_dropped_frames_still_give_the_exact_next_frame(spawn, rosenv, tmp_path):
    """The estimator dropped frame sets (real time): estimates of frames 0, 1, 3, 4, 7, 9. The node
    learns the motion per period from the stamps, so the prediction for the next frame stays exact."""
    proc = _start(spawn, tmp_path)
    model, Q = constant_twist_estimates(11, np.random.default_rng(8))
    names = list(model.dof_names)
    with ros_node(rosenv, "pred_gap_test") as (node, ex):
        h = Harness(node, ex)
        assert h.wait_connected()
        for i, k in enumerate([0, 1, 3, 4, 7, 9]):
            pred = h.send(ma.arrays_to_joint_state(names, Q[k], stamp_ns=T0 + k * PERIOD_NS, frame_id="world"))
            if i:
                np.testing.assert_allclose(np.array(pred.position), Q[k + 1], rtol=0, atol=1e-9)
    assert proc.stop() == 0


def test_nan_out_of_order_and_wrong_names_are_dropped_and_good_estimates_still_predicted(spawn, rosenv, tmp_path):
    proc = _start(spawn, tmp_path, restart_after_s=1.0)
    model, Q = constant_twist_estimates(6, np.random.default_rng(6))
    names = list(model.dof_names)
    js = lambda k, q=None, **kw: ma.arrays_to_joint_state(names, Q[k] if q is None else q,  # noqa: E731
                                                           stamp_ns=kw.get("stamp", T0 + k * PERIOD_NS))
    with ros_node(rosenv, "pred_test") as (node, ex):
        h = Harness(node, ex)
        assert h.wait_connected()
        for k in range(3):
            h.send(js(k))
        nan = js(3)
        nan.position[9] = float("nan")
        h.send(nan, expect=False)
        h.send(js(1), expect=False)                                   # older than the last (frame 2)
        h.send(js(2), expect=False)                                   # same stamp again
        short = ma.arrays_to_joint_state(names[:-1], Q[3][:-1], stamp_ns=T0 + 3 * PERIOD_NS)
        h.send(short, expect=False)                                   # a reference joint missing
        pred = h.send(js(3))                                          # history untouched by the bad ones
        np.testing.assert_allclose(np.array(pred.position), Q[4], rtol=0, atol=1e-9)
        # stray estimates far in time (an hour ahead, a replayed stamp alone): dropped, the history goes on
        h.send(js(0, stamp=T0 + 3600 * 10**9), expect=False)
        h.send(js(0, stamp=T0 - 5 * 10**9), expect=False)
        pred = h.send(js(4))
        np.testing.assert_allclose(np.array(pred.position), Q[5], rtol=0, atol=1e-9)
        # a jump back of more than restart_after_s that the next estimate continues: a replayed sequence,
        # history cleared (its first estimate is the jump's witness, not predicted from)
        h.send(js(0, stamp=T0 - 5 * 10**9), expect=False)
        restart = h.send(js(1, stamp=T0 - 5 * 10**9 + PERIOD_NS))
        np.testing.assert_allclose(np.array(restart.position), Q[1], rtol=0, atol=1e-12)
    assert proc.popen.poll() is None, proc.output()
    assert proc.stop() == 0
    out = proc.output()
    dropped = [ln for ln in out.splitlines() if "joint_states dropped" in ln]
    # NaN, out of order (twice: one line), missing joint, far stamps (three: one line)
    assert len(dropped) == 4, out
    assert f"JointState.position of joint {names[9]!r}: expected a finite number, received nan" in dropped[0]
    assert "is not newer than the last one's" in dropped[1] and "out of order by 40.0 ms" in dropped[1]
    assert f"to contain joint {names[-1]!r}" in dropped[2]
    assert "+3599.880 s from the stream" in dropped[3] and "a restart only if the next one follows it" in dropped[3]
    assert "the stream restarted" in out and "a new sequence; history cleared" in out
    assert "6 predictions published, 7 estimates dropped, 1 restarts" in out
