"""Recorder node: writes topics to an MCAP rosbag2 bag as they arrive.

Run alone::

    recorder_node --ros-args -p output:=out/run1 -p topics:="['/mocap/joint_states']"

or through ``isa-mocap record OUT --topics ...`` / ``--all``. Subscriptions are raw (CDR bytes
written untouched); publishers that appear later are discovered every ``discovery_period_s``;
the bag is flushed at least every ``flush_period_s`` so a SIGKILL loses at most that much
(``isa-mocap bag repair`` restores the index); SIGINT/SIGTERM close it cleanly with metadata.
"""
from __future__ import annotations

import fnmatch
import queue
import sys
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

import msg_adapters as ma
from isa_mocap_ros.bag import BagError, BagWriter
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.nodes.common import declare, declare_executor, log_closing, make_executor, spin_until_shutdown

# Topics every ROS graph has; recording them with --all only adds noise (ros2 bag skips them too).
_ALWAYS_EXCLUDED = ("/rosout", "/parameter_events")


class BagRecorder(Node):
    """Subscribes (raw) to the selected topics and appends every message to a bag."""

    def __init__(self, **kwargs) -> None:
        super().__init__("recorder", **kwargs)
        output = declare(self, "output", "", "rosbag2 directory to create")
        self.patterns = [t for t in declare(self, "topics", [""], "topics (or globs) to record") if t]
        self.record_all = declare(self, "all", False, "record every topic (except /rosout, /parameter_events)")
        self.exclude = [t for t in declare(self, "exclude_topics", [""], "topics (or globs) not to record") if t]
        version = declare(self, "version", 9, "rosbag2 metadata version (8 or 9)", lo=8, hi=9)
        compression = declare(self, "compression", "zstd", "chunk compression: zstd, lz4 or none")
        overwrite = declare(self, "overwrite", False, "replace an existing output bag")
        flush_s = declare(self, "flush_period_s", 1.0, "flush to disk at least this often", lo=0.05, hi=60.0)
        discovery_s = declare(self, "discovery_period_s", 0.5, "look for new publishers this often", lo=0.05, hi=60.0)
        if not output:
            raise BagError("parameter 'output' is empty: give the bag directory to write (-p output:=DIR)")
        if not self.patterns and not self.record_all:
            raise BagError("nothing to record: set 'topics' or 'all'")
        self.writer = BagWriter(output, version=version, compression=compression, overwrite=overwrite)
        self.output = output
        self.subscribed: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self._unsupported: set[str] = set()
        self._wanted_cache: dict[str, bool] = {}
        # Callbacks only enqueue; one writer thread owns the BagWriter (chunk compression never
        # blocks the executor, so publishers' histories are drained while a chunk is written).
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._writer_lock = threading.Lock()
        self._flush_s = flush_s
        self._writer_thread = threading.Thread(target=self._write_loop, name="recorder-writer", daemon=True)
        self._writer_thread.start()
        self.create_timer(discovery_s, self._discover)
        self.get_logger().info(f"recording to {output}")
        self._discover()

    def _wanted(self, topic: str) -> bool:
        """Whether ``topic`` is recorded (memoized: the patterns never change, discovery runs at 2 Hz)."""
        wanted = self._wanted_cache.get(topic)
        if wanted is None:
            wanted = self._wanted_cache[topic] = self._match(topic)
        return wanted

    def _match(self, topic: str) -> bool:
        if any(fnmatch.fnmatchcase(topic, e) for e in self.exclude):
            return False
        if self.record_all:
            return topic not in _ALWAYS_EXCLUDED
        return any(fnmatch.fnmatchcase(topic, t) for t in self.patterns)

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self.subscribed or topic in self._unsupported or not self._wanted(topic):
                continue
            type_name = types[0]
            try:
                msg_type = ma.message_type(type_name)
            except ma.AdapterError as exc:
                self._unsupported.add(topic)
                self.get_logger().error(f"not recording {topic}: {exc}")
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if not infos and topic not in self.patterns:
                continue  # a glob match with only subscribers so far: wait for a publisher's QoS
            # An explicitly named topic is subscribed as soon as it exists in the graph, so the first
            # messages of a publisher that appears later are not missed (reliable, default QoS recorded).
            offered = [i.qos_profile for i in infos]
            try:
                with self._writer_lock:
                    self.writer.add_topic(topic, type_name,
                                          qos=[qos.from_rclpy(o) for o in offered] if offered else None)
            except BagError as exc:
                self._unsupported.add(topic)
                self.get_logger().error(f"not recording {topic}: {exc}")
                continue
            self.create_subscription(msg_type, topic, self._callback(topic), qos.subscription_qos_for(offered),
                                     raw=True)
            self.subscribed[topic] = type_name
            self.counts[topic] = 0
            self.get_logger().info(f"subscribed to {topic} [{type_name}]")

    def _callback(self, topic: str):
        def on_message(data: bytes) -> None:
            self._queue.put((topic, data, self.get_clock().now().nanoseconds))
            self.counts[topic] += 1
        return on_message

    def _write_loop(self) -> None:
        """Drain the queue into the bag; flush at least every ``flush_period_s``; stop on None."""
        last_flush = time.monotonic()
        while True:
            try:
                item = self._queue.get(timeout=min(0.1, self._flush_s))
            except queue.Empty:
                item = ()
            if item is None:
                return
            with self._writer_lock:
                if item:
                    self.writer.write(*item)
                if time.monotonic() - last_flush >= self._flush_s:
                    self.writer.flush()
                    last_flush = time.monotonic()

    def close(self) -> None:
        self._queue.put(None)
        self._writer_thread.join(timeout=60.0)
        with self._writer_lock:
            self.writer.close()
        total = sum(self.counts.values())
        # after Ctrl-C the context is already shut down: no /rosout any more (log_closing)
        log_closing(self, f"closed {self.output}: {total} messages on {len(self.counts)} topics")


def main(args: list[str] | None = None, *, parameter_overrides=None) -> None:
    rclpy.init(args=args)
    node = None
    try:
        node = BagRecorder(parameter_overrides=parameter_overrides or [])
        executor = make_executor(declare_executor(node))
        executor.add_node(node)
        spin_until_shutdown(executor, node.context)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except BagError as exc:
        print(f"recorder: {exc}", file=sys.stderr)
        raise SystemExit(2)
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
