"""Bag player node: replays an MCAP rosbag2 bag's CDR bytes on their topics.

Run alone::

    player_node --ros-args -p bag:=bags/demo -p rate:=1.0 -p lockstep_topic:=/mocap/joint_states

or through ``isa-mocap play BAG``. Messages are published as recorded bytes (never deserialized),
with the recorded QoS re-offered (latched topics stay latched). In lockstep mode frame k+1 goes out
only after a message on ``lockstep_topic`` carries frame k's ``header.stamp`` (see
:mod:`isa_mocap_ros.bag.playback`), so downstream results do not depend on machine speed.
"""
from __future__ import annotations

import sys
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

import msg_adapters as ma
from isa_mocap_ros.bag import BagError, BagMessage, BagReader
from isa_mocap_ros.bag.playback import (PlaybackOptions, first_field_is_header, frames,
                                        parse_remaps, select_topics)
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.nodes.common import declare, declare_executor, make_executor, spin_until_shutdown


class BagPlayer(Node):
    """Publishes a bag's messages; ``run()`` plays it (call it beside a spinning executor)."""

    def __init__(self, **kwargs) -> None:
        super().__init__("player", **kwargs)
        self.bag_path = declare(self, "bag", "", "rosbag2 directory or .mcap file to replay")
        rate = declare(self, "rate", 1.0, "playback rate (1.0 = recorded speed)", lo=0.001, hi=1000.0)
        loop = declare(self, "loop", False, "start again at the end")
        start = declare(self, "start_offset_s", 0.0, "skip this many seconds of the bag", lo=0.0, hi=1e9)
        topics = declare(self, "topics", [""], "topics (or globs) to replay; empty = all")
        exclude = declare(self, "exclude_topics", [""], "topics (or globs) not to replay")
        remap = declare(self, "remap", [""], "topic remaps 'old:=new'")
        self.clock = declare(self, "clock", False, "publish /clock from the bag's time")
        self.clock_hz = declare(self, "clock_hz", 40.0, "/clock rate between messages", lo=0.1, hi=1000.0)
        self.lockstep_topic = declare(self, "lockstep_topic", "", "wait for this topic to echo each frame's stamp before the next frame ('' = real time)")
        self.lockstep_type = declare(self, "lockstep_type", "sensor_msgs/msg/JointState", "message type on lockstep_topic (its first field must be a std_msgs/Header)")
        self.lockstep_timeout_s = declare(self, "lockstep_timeout_s", 10.0, "give up waiting for a lockstep echo after this long; replay continues", lo=0.0, hi=1e6)
        self.wait_for_subscribers_s = declare(self, "wait_for_subscribers_s", 0.0, "before playing, wait up to this long until every topic (and /clock with clock) has a subscriber", lo=0.0, hi=1e6)
        self.delay_s = declare(self, "delay_s", 0.0, "sleep before playing (discovery)", lo=0.0, hi=1e6)
        self.wait_for_acked_s = declare(self, "wait_for_all_acked_s", 10.0, "at the end, wait up to this long until reliable subscribers acknowledged every message "
            "(like ros2 bag play --wait-for-all-acked)", lo=0.0, hi=1e6)
        if not self.bag_path:
            raise BagError("parameter 'bag' is empty: give the bag to replay (-p bag:=PATH)")
        self.options = PlaybackOptions(
            rate=rate, loop=loop, start_offset_s=start,
            topics=tuple(t for t in topics if t), exclude_topics=tuple(t for t in exclude if t),
            remap=parse_remaps(r for r in remap if r))
        self.reader = BagReader(self.bag_path)
        self.topics = select_topics(self.reader.topics, self.options)
        self.publishers_by_topic = {}
        self.stamped: list[str] = []
        self.latched: list[str] = []
        for name in self.topics:
            info = self.reader.topics[name]
            try:
                msg_type = ma.message_type(info.type)
            except ma.AdapterError as exc:
                self.get_logger().error(f"skipping topic {name}: {exc}")
                continue
            profile = qos.playback_qos(info.offered_qos)
            out_name = self.options.remap.get(name, name)
            self.publishers_by_topic[name] = self.create_publisher(msg_type, out_name, profile)
            if profile.durability == qos.LATCHED.durability:
                self.latched.append(name)
            elif first_field_is_header(self.reader.msgdef(info.type)):
                self.stamped.append(name)
        self.clock_pub = self.create_publisher(Clock, "/clock", 10) if self.clock else None
        self._acked: set[int] = set()
        self._ack_cv = threading.Condition()
        if self.lockstep_topic:
            self.create_subscription(ma.message_type(self.lockstep_type), self.lockstep_topic,
                                     self._on_ack, qos.RELIABLE, raw=True)
        self.published = 0
        self.acks = 0
        self.timeouts = 0
        self._bad_stamp_logged: set[str] = set()
        self.summary: dict | None = None
        self.done = threading.Event()
        self._halt = threading.Event()
        self._thread: threading.Thread | None = None
        # Playback runs in its own thread, started once an executor spins this node, so the
        # player works alone (``play()``) and inside a shared executor (``launch --single-process``).
        self._kickoff_timer = self.create_timer(0.01, self._kickoff)

    def _kickoff(self) -> None:
        self._kickoff_timer.cancel()
        if self._thread is None:
            self._thread = threading.Thread(target=self._play_thread, name="player", daemon=True)
            self._thread.start()

    def _play_thread(self) -> None:
        try:
            self.summary = self.run()
        except BagError as exc:
            self.get_logger().error(f"replay stopped: {exc}")
        finally:
            self.done.set()

    def _running(self) -> bool:
        return not self._halt.is_set() and rclpy.ok(context=self.context)

    # -- lockstep ------------------------------------------------------------------------------
    def _on_ack(self, data: bytes) -> None:
        try:
            stamp = ma.header_stamp_ns_from_cdr(data)
        except ma.AdapterError as exc:
            self.get_logger().warn(f"lockstep: unreadable message on {self.lockstep_topic}: {exc}")
            return
        with self._ack_cv:
            self._acked.add(stamp)
            self._ack_cv.notify_all()

    def _wait_ack(self, stamp_ns: int) -> bool:
        deadline = time.monotonic() + self.lockstep_timeout_s
        with self._ack_cv:
            while stamp_ns not in self._acked:
                left = deadline - time.monotonic()
                if left <= 0 or not self._running():
                    return False
                self._ack_cv.wait(min(left, 0.1))
            self._acked.discard(stamp_ns)
        return True

    # -- playback ------------------------------------------------------------------------------
    def _stamp_of(self, msg: BagMessage) -> int | None:
        try:
            return ma.header_stamp_ns_from_cdr(msg.data)
        except ma.AdapterError as exc:
            if msg.topic not in self._bad_stamp_logged:
                self._bad_stamp_logged.add(msg.topic)
                self.get_logger().warn(f"cannot read header stamp on {msg.topic}: {exc}")
            return None

    def _wait_for_subscribers(self) -> None:
        if self.wait_for_subscribers_s <= 0:
            return
        deadline = time.monotonic() + self.wait_for_subscribers_s
        while time.monotonic() < deadline and self._running():
            missing = [t for t, pub in self.publishers_by_topic.items() if pub.get_subscription_count() == 0]
            if self.clock_pub is not None and self.clock_pub.get_subscription_count() == 0:
                missing.append("/clock")      # published too: a sim-time subscriber would miss the first stamps
            if not missing:
                return
            time.sleep(0.05)
        self.get_logger().warn(f"no subscriber after {self.wait_for_subscribers_s:.1f} s on: {missing}")

    def _wait_for_all_acked(self) -> None:
        """Keep the writers alive until reliable readers acknowledged everything (bounded)."""
        from rclpy.duration import Duration
        deadline = time.monotonic() + self.wait_for_acked_s
        for topic, pub in self.publishers_by_topic.items():
            left = deadline - time.monotonic()
            if left <= 0 or not self._running():
                break
            try:
                if not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                    self.get_logger().warn(f"{topic}: not every message was acknowledged "
                                           f"within {self.wait_for_acked_s:.1f} s")
            except Exception as exc:  # noqa: BLE001 - best effort (e.g. best-effort writers)
                self.get_logger().debug(f"{topic}: wait_for_all_acked failed: {exc}")

    def _sleep_until(self, t: float) -> bool:
        while self._running():
            left = t - time.monotonic()
            if left <= 0:
                return True
            time.sleep(min(left, 0.05))
        return False

    def _publish(self, msg: BagMessage) -> None:
        pub = self.publishers_by_topic.get(msg.topic)
        if pub is None:
            return
        pub.publish(msg.data)
        self.published += 1
        if self.clock_pub is not None:
            self.clock_pub.publish(Clock(clock=ma.ns_to_stamp(msg.log_time_ns)))

    def run(self) -> dict:
        """Play the bag (blocking); returns a summary dict."""
        self._wait_for_subscribers()
        if self.delay_s > 0:
            self._sleep_until(time.monotonic() + self.delay_s)
        t_start = time.monotonic()
        start_ns = self.reader.start_ns + int(self.options.start_offset_s * 1e9)
        n_frames = 0
        passes = 1
        while self._running():
            # real time: the clock starts once the first frame set is out. The first message on each
            # topic costs the publisher tens of ms (DDS writer set-up): timed from before it, the
            # next frame sets fell due meanwhile and went out in a burst (sets 0-2 within 7 ms,
            # and the estimator dropped one or two of them)
            wall0 = time.monotonic()
            shifted = False
            for frame in frames(self.reader.messages(list(self.publishers_by_topic), start_ns=start_ns),
                                stamped_topics=self.stamped, latched_topics=self.latched,
                                stamp_of=self._stamp_of):
                if not self._running():
                    break
                for msg in frame.messages:
                    if not self.lockstep_topic:
                        due = wall0 + (msg.log_time_ns - start_ns) / 1e9 / self.options.rate
                        if not self._sleep_until(due):
                            break
                    self._publish(msg)
                if not shifted and frame.stamp_ns is not None and frame.messages:
                    # the time the first frame set took to go out moves the whole timeline
                    shifted = True
                    due = wall0 + (frame.messages[-1].log_time_ns - start_ns) / 1e9 / self.options.rate
                    wall0 += max(0.0, time.monotonic() - due)
                if frame.stamp_ns is not None:
                    n_frames += 1
                    if self.lockstep_topic:
                        if self._wait_ack(frame.stamp_ns):
                            self.acks += 1
                        elif self._running():
                            self.timeouts += 1
                            self.get_logger().warn(
                                f"lockstep: no {self.lockstep_topic} with stamp {frame.stamp_ns} within "
                                f"{self.lockstep_timeout_s:.1f} s; continuing")
            if not self.options.loop:
                break
            if passes == 1:
                self.get_logger().info("loop: the bag played once; replaying it from the start until stopped")
            passes += 1
        self._wait_for_all_acked()
        summary = {"messages": self.published, "frames": n_frames, "topics": len(self.publishers_by_topic),
                   "seconds": round(time.monotonic() - t_start, 3),
                   "lockstep_acks": self.acks, "lockstep_timeouts": self.timeouts}
        self.get_logger().info(
            f"played {self.published} messages ({n_frames} frames) on {len(self.publishers_by_topic)} topics "
            f"in {summary['seconds']:.2f} s" + (f"; lockstep acks {self.acks}, timeouts {self.timeouts}"
                                                if self.lockstep_topic else ""))
        return summary

    def close(self) -> None:
        """Stop playback (if running) and release the bag."""
        self._halt.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self.reader.close()


def play(args: list[str] | None = None, *, parameter_overrides=None) -> dict | None:
    """Init rclpy, spin the player until the bag is played, shut down; returns the summary."""
    rclpy.init(args=args)
    node = None
    executor = None
    try:
        node = BagPlayer(parameter_overrides=parameter_overrides or [])
        executor = make_executor(declare_executor(node))
        executor.add_node(node)
        spin_until_shutdown(executor, node.context, until=node.done.is_set, step_s=0.05)
        return node.summary
    except (KeyboardInterrupt, ExternalShutdownException):
        return None
    except BagError as exc:
        print(f"player: {exc}", file=sys.stderr)
        raise SystemExit(2)
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()


def main(args: list[str] | None = None) -> None:
    play(args)


if __name__ == "__main__":
    main()
