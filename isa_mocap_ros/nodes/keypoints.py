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
kept), and synchronizes the views' pairs into frame sets as the estimator does (its ``sync``, ``queue_size``,
``slop_s``, ``view_timeout_s``, ``min_views``: keep them equal; ``isa-mocap run --lockstep`` sets
``view_timeout_s`` 0 for both). Only a completed frame set moves the schedule
(:class:`~isa_mocap_ros.vision.keypoint_schedule.KeypointSchedule`: the view's first ``dense_frames`` frames with a
person, then every ``every_k_frames``-th), so the node counts the frames the estimator tracks
(:mod:`isa_mocap_ros.keypoint_intake`). For each view of a set the schedule picks, it crops the
square around the mask's foreground, runs
:class:`~isa_mocap_ros.vision.landmarks.PoseLandmarker` and publishes ``cam<i>/keypoints``
(``geometry_msgs/PolygonStamped``, x=u, y=v, z=confidence, the image's header; an empty polygon when
the pose score is below ``min_score``; msg_adapters/keypoints.py). Every other view of a set (not
picked, or dropped as bad) gets its header on ``cam<i>/keypoints_skipped`` (``std_msgs/Header``): each
view of a frame set gets exactly one message on one of the two topics, so an estimator in lockstep knows, per
frame and view, whether keypoints come, without a second copy of the schedule. The detection starts when the
set is complete (the last view's mask), not at each view's own mask.

Input checks as the segmentation node's (:mod:`isa_mocap_ros.intake`): an image is taken only when a
``cam<i>/camera_info`` of its stamp agrees with it (or it agrees with the view's camera and its stamp lies
within ``max_stamp_gap_s`` of the view's stream), and a mask only when it is mono8 and its frame id and size are
those of the gated image of its stamp, judged when the two meet (at any stamp, so a stream that jumps ahead is
followed, and in either order: the first mask of a camera that changed may come before the camera_info that lets
its image through the gate). A pair that forms no frame set (one view's image
and camera_info that agree at a far stamp, and the segmentation node's mask of it) neither gets published
keypoints the estimator would use nor moves the schedule. Bad input (undecodable image or mask, unsupported
encoding, a mask of another size than its image, a NaN camera_info, the checks above) is dropped for that view
with one rate-limited log line.
"""
from __future__ import annotations

import sys
import time
from collections import deque

import numpy as np
from geometry_msgs.msg import PolygonStamped
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

import msg_adapters as ma
from isa_mocap_ros.intake import Setting
from isa_mocap_ros.keypoint_intake import KeypointIntake
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.nodes.common import (QOS_OVERRIDES, ProblemLog, camera_info_callback, declare,
                                       declare_frame_sync, run_node)
from isa_mocap_ros.vision.errors import VisionError
from isa_mocap_ros.vision.landmark_model import ModelUnavailable
from isa_mocap_ros.vision.keypoint_schedule import DENSE_FRAMES, EVERY_K, detect_in_mask
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
        # the estimator's frame-set matching (keep equal to /mocap/estimator's): only a completed set moves the
        # schedules (isa_mocap_ros.keypoint_intake)
        sync_kw = declare_frame_sync(self, self.n_views)
        self.intake = KeypointIntake(self.n_views, every_k=self.every_k, dense_frames=self.dense_frames,
                                     max_gap_ns=int(gap_s * 1e9), keep=_KEEP, **sync_kw)
        try:
            self.detector = PoseLandmarker(model_path or None, num_threads=threads)
        except ModelUnavailable as exc:           # run_node prints a ValueError as one line, exit 2
            raise ValueError(str(exc)) from None
        self.problems = ProblemLog(self)
        self.skipped = [0] * self.n_views
        self.published = [0] * self.n_views
        self.latency_s: deque[float] = deque(maxlen=1000)
        self.cpu_s: deque[float] = deque(maxlen=1000)      # thread CPU time per detection
        self.pubs = [self.create_publisher(PolygonStamped, f"cam{i}/keypoints", qos.RELIABLE,
                                           qos_overriding_options=QOS_OVERRIDES) for i in range(self.n_views)]
        self.pubs_skipped = [self.create_publisher(Header, f"cam{i}/keypoints_skipped", qos.RELIABLE)
                             for i in range(self.n_views)]
        for i in range(self.n_views):
            self.create_subscription(Image, f"cam{i}/image_raw", self._image_cb(i), qos.SENSOR_DATA,
                                     qos_overriding_options=QOS_OVERRIDES)
            self.create_subscription(Image, f"cam{i}/mask", self._mask_cb(i), qos.SENSOR_DATA,
                                     qos_overriding_options=QOS_OVERRIDES)
            self.create_subscription(CameraInfo, f"cam{i}/camera_info", self._info_cb(i), qos.SENSOR_DATA,
                                     qos_overriding_options=QOS_OVERRIDES)
        if sync_kw["max_wait_s"] > 0:
            self.create_timer(min(0.1, sync_kw["max_wait_s"] / 2), self._poll)
        self.get_logger().info(f"keypoints: {self.n_views} views, every {self.every_k} frame(s) after the first "
                               f"{self.dense_frames} with a person, model "
                               f"{self.detector.model_path}")

    def _image_cb(self, v: int):
        def cb(msg: Image) -> None:      # through the view's gate: taken when a camera_info agrees (_info_cb)
            setting = Setting(msg.header.frame_id, msg.width, msg.height, msg.encoding)
            self._run(*self.intake.add_image(v, ma.stamp_to_ns(msg.header), setting, msg, time.monotonic()))
        return cb

    def _mask_cb(self, v: int):
        def cb(msg: Image) -> None:
            try:
                mask = ma.image_to_array(msg)
                if mask.ndim != 2 or mask.dtype != np.uint8:
                    raise ma.AdapterError(f"cam{v}/mask.encoding", "mono8", msg.encoding)
            except ma.AdapterError as exc:
                self.problems.report(f"mask{v}", f"cam{v}/mask dropped: {exc}")
                return
            setting = Setting(msg.header.frame_id, mask.shape[1], mask.shape[0])
            self._run(*self.intake.add_mask(v, ma.stamp_to_ns(msg.header), setting, mask, bool(np.any(mask)),
                                            time.monotonic()))
        return cb

    def _info_cb(self, v: int):
        return camera_info_callback(v, self.problems, lambda exc: f"info{v}:{exc.field}",
                                    lambda *info: self._run(*self.intake.add_info(v, *info, time.monotonic())))

    def _poll(self) -> None:
        self._run(*self.intake.poll(time.monotonic()))

    def _run(self, jobs, problems) -> None:
        """Report the rejected inputs; detect on (or publish the skip notice of) each view of completed sets."""
        for key, text in problems:
            self.problems.report(key, text)
        for job in jobs:
            if job.detect:
                self._detect(job.view, job.stamp_ns, job.image, job.mask)
            else:
                self.pubs_skipped[job.view].publish(job.image.header)
                self.skipped[job.view] += 1

    def _detect(self, v: int, stamp: int, image: Image, mask: np.ndarray) -> None:
        t0 = time.perf_counter()
        t0_cpu = time.thread_time()
        try:
            if image.encoding not in ENCODINGS:
                raise ma.AdapterError("Image.encoding", f"one of {', '.join(ENCODINGS)}", image.encoding)
            if mask.shape != (image.height, image.width):
                raise ma.AdapterError("mask size", f"the image's {image.width}x{image.height}",
                                      f"{mask.shape[1]}x{mask.shape[0]}")
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
                f"{self.problems.total} frames dropped, {sum(self.intake.unpaired)} images/masks never paired"
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
