"""nodes.common.spin_until_shutdown at Ctrl-C: rclpy's signal handler shuts the context down on a thread of its
own, so a callback running at that moment fails to publish ("publisher's context is invalid"). That ended a node
stopped by SIGINT with exit code 1 (a segmentation node's diagnostics timer, 1 of 25 tries); the spin must end
as the shutdown does. An error while the context is up still propagates."""
from __future__ import annotations

import threading

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

from isa_mocap_ros.nodes import qos
from isa_mocap_ros.nodes.common import spin_until_shutdown

pytestmark = [pytest.mark.ros, pytest.mark.timeout(60)]


def _node_whose_timer_publishes_after(ctx: Context, shutdown: bool):
    """A node whose timer callback has the context shut down from another thread (as rclpy's signal thread
    does) before it publishes (``shutdown``), or raises while the context is up."""
    node = rclpy.create_node("shutdown_probe", context=ctx)
    pub = node.create_publisher(String, "probe", qos.RELIABLE)
    calls = []

    def tick():
        calls.append(1)
        if not shutdown:
            raise RuntimeError("a callback's own error")
        t = threading.Thread(target=ctx.try_shutdown)
        t.start()
        t.join()
        pub.publish(String(data="late"))            # RCLError: publisher's context is invalid
    node.create_timer(0.01, tick)
    return node, calls


@pytest.fixture
def ctx(rosenv, monkeypatch):
    """An rclpy context of the test's private ROS domain."""
    for k, v in rosenv.items():
        if k.startswith("ROS_"):
            monkeypatch.setenv(k, v)
    context = Context()
    rclpy.init(context=context)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.mark.parametrize("kind", ["events", "single_threaded"])
def test_a_callback_failing_because_the_context_shut_down_ends_the_spin_quietly(ctx, kind):
    from rclpy.experimental import EventsExecutor

    node, calls = _node_whose_timer_publishes_after(ctx, shutdown=True)
    executor = (EventsExecutor if kind == "events" else SingleThreadedExecutor)(context=ctx)
    executor.add_node(node)
    try:
        spin_until_shutdown(executor, ctx)    # returns: no RCLError
        assert calls and not ctx.ok()
    finally:
        node.destroy_node()


def test_an_error_while_the_context_is_up_propagates(ctx):
    node, _ = _node_whose_timer_publishes_after(ctx, shutdown=False)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        with pytest.raises(RuntimeError, match="a callback's own error"):
            spin_until_shutdown(executor, ctx)
    finally:
        node.destroy_node()


def test_the_estimators_worker_asking_the_graph_after_the_shutdown_gets_an_answer(ctx):
    """The estimator's worker asks the graph from its own thread while it waits in lockstep (is a keypoint node, a
    prediction node there?); at Ctrl-C the context is shut down under it and rcl raised "rcl node's context is
    invalid" in that thread (seen once at shutdown). Once the context is down the answer is: none there."""
    from rclpy.node import Node

    from isa_mocap_ros.nodes.common import publishers_on
    from isa_mocap_ros.nodes.estimator_intake import EstimatorIntake

    class Probe(EstimatorIntake, Node):
        n_views = 2

    node = Probe("graph_probe", context=ctx)
    pub = node.create_publisher(String, "cam0/keypoints_skipped", qos.RELIABLE)
    try:
        assert publishers_on(node, "cam0/keypoints_skipped") == 1 and not node._keypoint_node_present()
        ctx.try_shutdown()
        assert publishers_on(node, "cam0/keypoints_skipped") == 0 and not node._keypoint_node_present()
    finally:
        node.destroy_publisher(pub)
        node.destroy_node()
