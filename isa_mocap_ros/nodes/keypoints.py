"""Keypoint node: BlazePose landmarks per view, ``cam<i>/image_raw`` + ``cam<i>/mask`` -> ``cam<i>/keypoints``.

Run alone (relative topic names; ``/mocap`` namespace as the rest of the network)::

    keypoints_node --ros-args -r __ns:=/mocap -p views:=4 -p every_k_frames:=3
    python -m isa_mocap_ros.nodes.keypoints --ros-args -r __ns:=/mocap --params-file config/pipeline.yaml

A node of its own, not a stage of the segmentation node: the landmark model costs 10-30 ms per view
(measured under contention, docs/keypoints.md), ten times a mask, and runs every k-th frame only; in
its own process it neither delays the masks the estimator waits for nor shares their thread, and a
network without it (or without the model file) runs as before.

Per view ``i`` it pairs ``cam<i>/image_raw`` and ``cam<i>/mask`` (sensor-data QoS) by stamp (the
segmentation node copies the image header; either may arrive first, the last 8 unpaired of each are
kept). For a pair the schedule picks (:class:`~isa_mocap_ros.vision.keypoint_schedule.KeypointSchedule`:
the view's first ``dense_frames`` frames with a person, then every ``every_k_frames``-th), it crops the
square around the mask's foreground, runs
:class:`~isa_mocap_ros.vision.landmarks.PoseLandmarker` and publishes ``cam<i>/keypoints``
(``geometry_msgs/PolygonStamped``, x=u, y=v, z=confidence, the image's header; an empty polygon when
the pose score is below ``min_score``; msg_adapters/keypoints.py). Every other pair it handled (not
picked, or dropped as bad) gets its header on ``cam<i>/keypoints_skipped`` (``std_msgs/Header``): each
pair gets exactly one message on one of the two topics, so an estimator in lockstep knows, per frame and
view, whether keypoints come, without a second copy of the schedule.

Input checks as the segmentation node's (:mod:`isa_mocap_ros.intake`): an image is taken only when a
``cam<i>/camera_info`` of its stamp agrees with it (or it agrees with the view's camera and its stamp lies
within ``max_stamp_gap_s`` of the view's stream), and a mask only when its frame id and size are the view's
camera's and its stamp is near the stream; so stray images and masks (another size, frame, a far stamp)
neither get detected on nor move the schedule. Bad input (undecodable image, unsupported encoding, a mask
of another size than its image, the checks above) is dropped for that view with one rate-limited log line.
"""
from __future__ import annotations

import sys
import time
from collections import OrderedDict, deque

import numpy as np
from geometry_msgs.msg import PolygonStamped
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

import msg_adapters as ma
from isa_mocap_ros.intake import Setting, ViewGate
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.nodes.common import QOS_OVERRIDES, ProblemLog, camera_info_callback, declare, run_node
from isa_mocap_ros.vision.errors import VisionError
from isa_mocap_ros.vision.landmark_model import ModelUnavailable
from isa_mocap_ros.vision.keypoint_schedule import DENSE_FRAMES, EVERY_K, KeypointSchedule, detect_in_mask
from isa_mocap_ros.vision.landmarks import PoseLandmarker

__all__ = ["KeypointNode", "main"]

ENCODINGS = ("rgb8", "bgr8")
_KEEP = 8                 # unpaired images (or masks) kept per view while the other is on its way


class KeypointNode(Node):
    """Thin node over :class:`PoseLandmarker` (see the module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__("keypoints", **kwargs)
        self.n_views = declare(self, "views", 4, "number of camera views (cam0 .. cam<views-1>)", lo=1, hi=64)
        self.every_k = declare(self, "every_k_frames", EVERY_K, "after the dense start, detect on every k-th frame "
                               "with a person of each view (1 = all)", lo=1, hi=10000)
        self.dense_frames = declare(self, "dense_frames", DENSE_FRAMES, "detect on each view's first frames with "
                                    "a person (the automatic initialization and its heading check)", lo=0, hi=10000)
        self.min_score = declare(self, "min_score", 0.5, "pose presence score below which nobody is reported",
                                 lo=0.0, hi=1.0)
        self.box_scale = declare(self, "box_scale", 1.25, "crop side / longer side of the mask's bounding box",
                                 lo=1.0, hi=4.0)
        model_path = declare(self, "model_path", "", "landmark model file ('' = the cache of `make models`)")
        threads = declare(self, "threads", 1, "interpreter threads", lo=1, hi=64)
        gap_s = declare(self, "max_stamp_gap_s", 5.0, "an image or mask farther than this from the view's stream in "
                        "time is dropped unless its own camera_info comes with it (0 = no check)", lo=0.0, hi=1e9)
        self.gates = [ViewGate(f"cam{v}", max_gap_ns=int(gap_s * 1e9)) for v in range(self.n_views)]
        try:
            self.detector = PoseLandmarker(model_path or None, num_threads=threads)
        except ModelUnavailable as exc:           # run_node prints a ValueError as one line, exit 2
            raise ValueError(str(exc)) from None
        self.problems = ProblemLog(self)
        self.images: list[OrderedDict[int, Image]] = [OrderedDict() for _ in range(self.n_views)]
        self.masks: list[OrderedDict[int, Image]] = [OrderedDict() for _ in range(self.n_views)]
        self.unpaired = [0] * self.n_views
        self.schedules = [KeypointSchedule(self.every_k, dense_frames=self.dense_frames)
                          for _ in range(self.n_views)]
        self.skipped = [0] * self.n_views
        self.published = [0] * self.n_views
        self.latency_s: deque[float] = deque(maxlen=1000)
        self.cpu_s: deque[float] = deque(maxlen=1000)      # thread CPU time per detection
        self.pubs = [self.create_publisher(PolygonStamped, f"cam{i}/keypoints", qos.RELIABLE,
                                           qos_overriding_options=QOS_OVERRIDES) for i in range(self.n_views)]
        self.pubs_skipped = [self.create_publisher(Header, f"cam{i}/keypoints_skipped", qos.RELIABLE)
                             for i in range(self.n_views)]
        for i in range(self.n_views):
            self.create_subscription(Image, f"cam{i}/image_raw", self._pair_cb(i, "image"), qos.SENSOR_DATA,
                                     qos_overriding_options=QOS_OVERRIDES)
            self.create_subscription(Image, f"cam{i}/mask", self._pair_cb(i, "mask"), qos.SENSOR_DATA,
                                     qos_overriding_options=QOS_OVERRIDES)
            self.create_subscription(CameraInfo, f"cam{i}/camera_info", self._info_cb(i), qos.SENSOR_DATA,
                                     qos_overriding_options=QOS_OVERRIDES)
        self.get_logger().info(f"keypoints: {self.n_views} views, every {self.every_k} frame(s) after the first "
                               f"{self.dense_frames} with a person, model "
                               f"{self.detector.model_path}")

    def _pair_cb(self, v: int, kind: str):
        """Callback of ``cam<v>/image_raw`` (kind "image") or ``cam<v>/mask``: the second of the pair of
        one stamp to arrive (either order) runs the detection; an unpaired message waits among the last
        :data:`_KEEP` of its kind, then ages out (counted in :attr:`unpaired`)."""

        def cb(msg: Image) -> None:
            stamp = ma.stamp_to_ns(msg.header)
            gate = self.gates[v]
            if kind == "image":        # through the view's gate: taken when a camera_info agrees (_info_cb)
                self._settle(v, *gate.add_image(stamp, Setting(msg.header.frame_id, msg.width, msg.height,
                                                               msg.encoding), msg))
                return
            known = gate.setting       # None: waits for an image of its stamp like any mask
            why = None if known is None else (
                   gate.window.far(stamp) or (f"frame {msg.header.frame_id!r}, {msg.width}x{msg.height}, is not the "
                                              f"view's camera's ({known.frame_id!r}, {known.width}x{known.height})"
                                              if (msg.header.frame_id, msg.width, msg.height)
                                              != (known.frame_id, known.width, known.height) else None))
            if why is not None:
                self.problems.report(f"mask{v}", f"cam{v}/mask dropped: {why}")
                return
            self._pair(v, kind, stamp, msg)
        return cb

    def _info_cb(self, v: int):
        return camera_info_callback(v, self.problems, lambda exc: f"info{v}:{exc.field}",
                                    lambda *info: self._settle(v, *self.gates[v].add_info(*info)))

    def _settle(self, v: int, accepted, rejected) -> None:
        for r in rejected:
            self.problems.report(f"info{v}:gate" if r.kind == "camera_info" else f"image{v}:{r.kind}", r.text)
        for a in accepted:
            self._pair(v, "image", a.stamp_ns, a.payload)

    def _pair(self, v: int, kind: str, stamp: int, msg: Image) -> None:
        """Pair a taken image or mask with the other of its stamp (either order; see :meth:`_pair_cb`)."""
        mine = (self.images if kind == "image" else self.masks)[v]
        other = (self.masks if kind == "image" else self.images)[v]
        partner = other.pop(stamp, None)
        if partner is None:
            mine[stamp] = msg
            while len(mine) > _KEEP:
                mine.popitem(last=False)
                self.unpaired[v] += 1
            return
        image, mask = (msg, partner) if kind == "image" else (partner, msg)
        self._detect(v, stamp, image, mask)

    def _detect(self, v: int, stamp: int, image: Image, mask_msg: Image) -> None:
        t0 = time.perf_counter()
        t0_cpu = time.thread_time()
        try:
            if image.encoding not in ENCODINGS:
                raise ma.AdapterError("Image.encoding", f"one of {', '.join(ENCODINGS)}", image.encoding)
            mask = ma.image_to_array(mask_msg)
            if (mask.shape[0], mask.shape[1]) != (image.height, image.width):
                raise ma.AdapterError("mask size", f"the image's {image.width}x{image.height}",
                                      f"{mask.shape[1]}x{mask.shape[0]}")
            if not self.schedules[v].due(bool(np.any(mask))):
                self.pubs_skipped[v].publish(image.header)
                self.skipped[v] += 1
                return
            lm = detect_in_mask(self.detector, ma.image_to_array(image), mask, box_scale=self.box_scale,
                                min_score=self.min_score, bgr=image.encoding == "bgr8")
            out = ma.keypoints_to_polygon(None if lm is None else lm.uv, None if lm is None else lm.confidence,
                                          image.header)
        except (ma.AdapterError, VisionError) as exc:
            self.problems.report(f"view{v}:{type(exc).__name__}", f"cam{v} frame at {stamp} ns dropped: {exc}")
            self.pubs_skipped[v].publish(image.header)     # no keypoints for it: a lockstep estimator goes on
            return
        self.published[v] += 1
        self.pubs[v].publish(out)
        self.latency_s.append(time.perf_counter() - t0)
        self.cpu_s.append(time.thread_time() - t0_cpu)

    def close(self) -> None:
        """Log what was published and the per-view detection time."""
        lat = np.array(self.latency_s) * 1e3
        cpu = np.array(self.cpu_s) * 1e3
        text = (f"keypoints: {sum(self.published)} keypoint sets published {self.published}, "
                f"{sum(self.skipped)} frames skipped by the schedule, "
                f"{self.problems.total} frames dropped, {sum(self.unpaired)} images/masks never paired"
                + (f", per view {np.median(lat):.1f} ms median / {np.percentile(lat, 95):.1f} ms p95 wall, "
                   f"{np.mean(cpu):.1f} ms mean CPU" if lat.size else ""))
        if self.context.ok():
            self.get_logger().info(text)
        else:
            print(text, file=sys.stderr, flush=True)


def main(args: list[str] | None = None) -> int:
    """Console script ``keypoints_node``."""
    return run_node(KeypointNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
