"""Segmentation node: one background model per view, ``cam<i>/image_raw`` -> ``cam<i>/mask``.

Run alone (relative topic names; the network runs it in ``/mocap``)::

    segmentation_node --ros-args -r __ns:=/mocap -p views:=4 -p method:=colour -p learn_frames:=10
    python -m isa_mocap_ros.nodes.segmentation --ros-args -r __ns:=/mocap --params-file config/pipeline.yaml

Per view ``i`` it subscribes to ``cam<i>/image_raw`` (sensor-data QoS) and keeps one
:class:`~isa_mocap_ros.vision.segmentation.BackgroundSegmenter` (EA-vs-PF §3.2: a per-pixel colour
model learnt from the first ``learn_frames`` images or from a clean plate; OpenCV MOG2/KNN as
alternatives; morphological clean-up and small-blob removal; an outlier-robust mode for images with
impulsive pixel noise, ``robust``). Each image gives one
``cam<i>/mask`` (mono8, 0/255, reliable depth 10) with the source image's header (stamp and
frame id), including the all-zero masks of the learning phase, so frame sets stay complete
downstream. The parameters mirror :class:`~isa_mocap_ros.vision.segmentation.SegmentationConfig`.

The learning ends by stamp as well as by count (:class:`~isa_mocap_ros.vision.segmentation_window.LearningWindows`):
a view learns only from images stamped within ``learn_frames`` frame periods (``frame_rate``; 0 = the smallest stamp
gap of a view) of the first image of the frame sets, so images lost in real time never let the frames after the
empty ones into the background; one log line per view gives the stamps learnt (docs/vision.md). The model's build
from the learning (:meth:`BackgroundSegmenter.advance_build`, a band of rows a step) runs from a timer between the
images after a view's last learning image, the views in the order they learnt; the next image of a view finishes what
is left of its build first. The masks are bit for bit those of a build in one go (docs/vision.md). The compiled
kernels run on the callback's thread only (:func:`~isa_mocap_ros.nodes.common.one_numba_thread`): the learning's
``parallel`` kernels spent 2-4x the CPU in spinning workers on a loaded machine (docs/history/issue35_speed.md,
session 34).

Accepted encodings: ``rgb8``, ``bgr8`` (turned into RGB) and ``mono8``.

Input checks (:mod:`isa_mocap_ros.intake`), before anything reaches a background model. The node
also subscribes to ``cam<i>/camera_info`` and takes a view's camera to be what a camera_info and an
image of the same stamp agree on (frame id and size; the image's encoding with it). So:

* nothing is learnt before such a pair: images wait (``input_queue`` of them) for their camera info;
  a stray image arriving first cannot fix the view's size;
* later images are segmented when they agree with that camera (size, frame id, encoding) and their
  stamp lies within ``max_stamp_gap_s`` of the view's last one; others wait for a camera info of
  their stamp and are dropped when none comes;
* a pair that agrees within itself but not with the camera (a real resolution change) restarts
  that view's background learning, with one log line;
* a pair passes the gate at any stamp, so the prediction node's stream rule follows the accepted
  images (:class:`~isa_mocap_ros.intake.StreamForks`): an image more than ``max_stamp_gap_s`` ahead of the
  view's last one, or behind it by more, is *far*; it is segmented at once (a lockstep replay waits for its
  mask) but on a new background model of its own, which the view keeps only if the next image
  continues the far one's stamp (the stream restarted there: a bag replayed or looped, a camera
  restarted; one log line), and forgets when the next image continues the stream. So one view's lone
  pair at a stamp of its own (a stray camera, a fuzzer) changes nothing in the background model of the
  stream it interrupts, and a stream that starts after such a pair learns nothing from it. An image
  behind the view's last one by at most ``max_stamp_gap_s`` is out of order and dropped;
* malformed images (data length disagreeing with ``height * step``, unknown or unsupported
  encoding) and camera infos are dropped at once.

Every dropped message is counted (``close()`` prints the total) and logged, one rate-limited line
per view and kind, and reported on ``/diagnostics`` at 1 Hz. ``use_camera_info: false`` is for a camera without camera_info: then the first
image fixes the view's size and encoding, and a later change needs a restart of the node.

In real time under load, ``late_set_s`` > 0 skips a frame set in every view when its first image here is older than
that (:class:`~isa_mocap_ros.late_sets.LateSetShedder`: the header stamp against the stream's offset), so the node
drops whole sets instead of losing single views in its queues; counted on ``/diagnostics``
(``late_sets_skipped``), one log line per burst. Off by default and in lockstep
(docs/segmentation_prior_prediction.md "Late frame sets, shed whole").
"""
from __future__ import annotations

import dataclasses
import json
import time
from collections import deque

import cv2
import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image

import msg_adapters as ma
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.intake import Setting, StreamForks, ViewGate
from isa_mocap_ros.late_sets import LateSetShedder
from isa_mocap_ros.nodes.common import (QOS_OVERRIDES, ProblemLog, camera_info_callback, declare, log_closing,
                                        one_numba_thread, run_node)
from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig, SegmentationError
from isa_mocap_ros.vision.segmentation_window import LearningWindows

__all__ = ["SegmentationNode", "main", "ENCODINGS"]

#: encodings the node segments
ENCODINGS = ("rgb8", "bgr8", "mono8")
#: period of the timer that steps the background models' builds between images, seconds (only while one is left)
BUILD_TICK_S = 0.001

# parameter name -> (description, lo, hi); names and defaults come from SegmentationConfig
_PARAMS = {
    "method": ("background model: colour (per-pixel Gaussian), mog2 or knn (OpenCV)", None, None),
    "learn_frames": ("first images used only to learn the background (all-zero masks)", 1, 100000),
    "threshold": ("colour: foreground beyond this many per-pixel std; mog2: sqrt(varThreshold)", 0.01, 1000.0),
    "min_std": ("floor of the per-pixel std (intensity levels)", 0.01, 255.0),
    "initial_std": ("per-pixel std assumed when starting from a clean plate", 0.01, 255.0),
    "std_smoothing_px": ("box filter side applied to the learnt variance (0/1 = none)", 0, 101),
    "update_rate": ("running update rate of the background outside the foreground (0 = frozen)", 0.0, 1.0),
    "update_margin_px": ("foreground dilation before it is excluded from the update", 0, 100),
    "max_foreground_fraction": ("above this foreground fraction a frame is a global change (update all)",
                                0.001, 1.0),
    "shadow_suppression": ("return shadows (darker, same chromaticity) as background", None, None),
    "shadow_min_brightness": ("lowest brightness distortion of a shadow", 0.0, 1.0),
    "shadow_max_brightness": ("highest brightness distortion of a shadow", 0.0, 2.0),
    "shadow_chroma_threshold": ("largest chromaticity distortion of a shadow (std units)", 0.01, 1000.0),
    "open_kernel": ("morphological opening size, px (0/1 = skip)", 0, 101),
    "close_kernel": ("morphological closing size, px (0/1 = skip)", 0, 101),
    "min_blob_area_px": ("connected foreground components smaller than this are removed", 0, 10**8),
    "history": ("mog2/knn: OpenCV history", 1, 100000),
    "knn_dist2_threshold": ("knn: OpenCV dist2Threshold", 0.01, 1e6),
    "kernel": ("colour model implementation: numba or numpy", None, None),
    "robust": ("colour: outlier-robust mode for pixel noise (mode background + neighbourhood vote): "
               "auto, on or off", None, None),
    "robust_detect_fraction": ("robust=auto: outlying share of the learning samples that switches it on",
                               0.001, 0.999),
    "robust_radius": ("robust background: samples agree within this many levels per channel", 0.0, 255.0),
    "vote": ("robust mode's per-frame decision: field (pixel evidence + mean-field MRF) or window "
             "(share of differing pixels in a Gaussian window)", None, None),
    "vote_sigma_px": ("robust mode, vote=window: Gaussian vote window sigma, px (0 = from the measured noise level)",
                      0.0, 50.0),
    "field_coupling": ("robust mode, vote=field: coupling of a pixel to its 8 neighbours", 0.0, 10.0),
    "field_iterations": ("robust mode, vote=field: mean-field iterations", 0, 1000),
    "field_memory": ("robust mode, vote=field: weight of the earlier frames' evidence (leaky sum of the "
                     "positive part; 0 = each frame on its own)", 0.0, 0.99),
    "learn_from": ("colour: frames (the learning frames show the empty scene) or stable (the person may be in "
                   "them: per pixel the frames where the background shows, plus the clean plate)", None, None),
    "work_scale": ("working resolution of the model as a share of the image side (1 = the image's; the mask "
                   "is published at the image's size)", 0.05, 1.0),
}


def _read_plate(path: str) -> np.ndarray:
    img = cv2.imread(path, cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"clean_plates: cannot read {path!r} as an image")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


class SegmentationNode(Node):
    """Thin node over :class:`BackgroundSegmenter`, one per view (see the module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__("segmentation", **kwargs)
        self.n_views = declare(self, "views", 4, "number of camera views (cam0 .. cam<views-1>)", lo=1, hi=64)
        values = {}
        for f in dataclasses.fields(SegmentationConfig):
            text, lo, hi = _PARAMS[f.name]
            values[f.name] = declare(self, f.name, f.default, text, lo=lo, hi=hi)
        plates = declare(self, "clean_plates", Parameter.Type.STRING_ARRAY,
                         "optional clean-plate image per view ('' = learn from the first frames)") or []
        self.use_info = declare(self, "use_camera_info", True, "check images against cam<i>/camera_info "
                                "(false: a camera without one; the first image fixes the view's size)")
        gap_s = declare(self, "max_stamp_gap_s", 5.0, "an image farther than this from the view's last one in "
                        "time is dropped unless its own camera_info comes with it, and then segmented on a background "
                        "model of its own that the view keeps only if the next image follows it (0 = no check)", lo=0.0, hi=1e9)
        depth = declare(self, "input_queue", 10, "images waiting for the camera_info of their stamp (and camera "
                        "infos for their image), per view", lo=1, hi=1000)
        late_s = declare(self, "late_set_s", 0.0, "real time: a frame set whose first image here is older than "
                         "this (its stamp against the stream's offset, the smallest arrival - stamp seen) is skipped "
                         "in every view, so a node under load drops whole sets, not single views (0 = off; stamps "
                         "must advance at wall speed: a live camera, a replay at rate 1.0; never in lockstep)",
                         lo=0.0, hi=1e3)
        frame_rate = declare(self, "frame_rate", 0.0, "frames per second of the cameras: a view learns its background "
                             "only from images stamped within learn_frames frame periods of the first (0 = the period "
                             "from the smallest stamp gap seen in a view)", lo=0.0, hi=1e6)
        self.config = SegmentationConfig(**values)
        self.windows = LearningWindows(self.config.learn_frames, frame_rate=frame_rate)
        if plates and len(plates) != self.n_views:
            raise ValueError(f"clean_plates: expected one entry per view ({self.n_views}), received {len(plates)}")
        plates = list(plates) or [""] * self.n_views
        self.plates = [_read_plate(p) if p else None for p in plates]
        self.gates = [ViewGate(f"cam{v}", max_gap_ns=int(gap_s * 1e9), depth=depth, need_info=self.use_info)
                      for v in range(self.n_views)]
        # each view's background model is the state of its stream (forks at far stamps; none: max_stamp_gap_s 0)
        gap_ns = int(gap_s * 1e9) if gap_s > 0 else 2**62
        self.streams = [StreamForks(lambda v=v: self._new_segmenter(v), back_ns=gap_ns, ahead_ns=gap_ns)
                        for v in range(self.n_views)]
        self.shedder = LateSetShedder(int(late_s * 1e9), reset_ns=gap_ns)
        self._pending_bursts: list[int] | None = None      # bursts not logged yet: [bursts, sets, first, last, age]
        self._burst_logged_at = -float("inf")
        self.restarts = [0] * self.n_views
        self.stream_restarts = [0] * self.n_views
        self._warm_up()
        self.problems = ProblemLog(self)
        self.mask_pubs = [self.create_publisher(Image, f"cam{i}/mask", qos.RELIABLE,
                                                qos_overriding_options=QOS_OVERRIDES) for i in range(self.n_views)]
        for i in range(self.n_views):
            self.create_subscription(Image, f"cam{i}/image_raw", self._image_cb(i), qos.SENSOR_DATA,
                                     qos_overriding_options=QOS_OVERRIDES)
            if self.use_info:
                self.create_subscription(CameraInfo, f"cam{i}/camera_info", self._info_cb(i), qos.SENSOR_DATA,
                                         qos_overriding_options=QOS_OVERRIDES)
        self.masks_published = [0] * self.n_views
        self._reported = [False] * self.n_views
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self._building: deque[BackgroundSegmenter] = deque()    # models whose build has steps left, oldest first
        self._build_timer = self.create_timer(BUILD_TICK_S, self._advance_builds)
        self._build_timer.cancel()
        self.create_timer(1.0, self._publish_diagnostics)
        self.latency_s: deque[float] = deque(maxlen=1000)
        self.get_logger().info(
            f"segmentation: {self.n_views} views, method {self.config.method}, "
            + (f"learning from the first {self.config.learn_frames} frames where the background shows"
               + (" and clean plates" if any(plates) else "") if self.config.learn_from == "stable" else
               "clean plates" if any(plates) else f"learning from the first {self.config.learn_frames} frames"))

    def _warm_up(self) -> None:
        """Run the compiled kernels once on a tiny image, so the first real frame is not slow.

        Both a writable and a read-only image: the callback hands the segmenter a read-only view
        on the message's buffer, and numba compiles (or loads from its cache, ~0.2 s) a separate
        specialization for read-only arrays, which would otherwise stall the first frame after the
        background is learnt."""
        for writeable in (True, False):
            seg = BackgroundSegmenter(self.config)
            img = np.zeros((16, 16, 3), np.uint8)
            img.flags.writeable = writeable
            for _ in range(self.config.learn_frames + 2):
                seg.apply(img)

    @property
    def segmenters(self) -> list[BackgroundSegmenter]:
        """Each view's background model (its stream's)."""
        return [st.state for st in self.streams]

    def _plate_for(self, v: int) -> np.ndarray | None:
        """View ``v``'s clean plate when it fits the view's size (or the size is not known yet), else None."""
        plate, setting = self.plates[v], self.gates[v].setting
        if plate is not None and setting is not None and plate.shape[:2] != (setting.height, setting.width):
            return None
        return plate

    def _new_segmenter(self, v: int) -> BackgroundSegmenter:
        """A new background model for view ``v``, from its clean plate when that fits the view's size."""
        return BackgroundSegmenter(self.config, clean_plate=self._plate_for(v))

    def _info_cb(self, v: int):
        return camera_info_callback(v, self.problems, lambda exc: f"info{v}:{exc.field}",
                                    lambda *info: self._settle(v, *self.gates[v].add_info(*info)))

    def _image_cb(self, v: int):
        def cb(msg: Image) -> None:
            t0 = time.perf_counter()
            try:
                if msg.encoding not in ENCODINGS:
                    raise ma.AdapterError("Image.encoding", f"one of {', '.join(ENCODINGS)}", msg.encoding)
                img = ma.image_to_array(msg)
                stamp = ma.stamp_to_ns(msg.header)
            except ma.AdapterError as exc:  # one rate-limited line per view and offending field
                self.problems.report(f"image{v}:{exc.field}", f"cam{v}/image_raw dropped: {exc}")
                return
            setting = Setting(msg.header.frame_id, img.shape[1], img.shape[0], msg.encoding)
            self._settle(v, *self.gates[v].add_image(stamp, setting, (msg, img)), t0=t0)
        return cb

    def _settle(self, v: int, accepted, rejected, *, t0: float | None = None) -> None:
        """Report the view's rejected inputs, segment its accepted images (in stamp order)."""
        for r in rejected:
            self.problems.report(f"info{v}:gate" if r.kind == "camera_info" else f"image{v}:{r.kind}", r.text)
        for a in accepted:
            if a.changed:
                self.restarts[v] += 1
                self.streams[v].state = self._new_segmenter(v)
                self._reported[v] = False
                self.get_logger().warn(
                    f"cam{v}: the camera changed ({a.changed}; its camera_info and image of stamp {a.stamp_ns} "
                    f"agree): background learning restarts"
                    + ("" if self._plate_for(v) is not None else f" from the next {self.config.learn_frames} images"))
            kind, seg, why = self.streams[v].state_for(a.stamp_ns)
            if kind == "drop":
                self.problems.report(f"image{v}:order", f"cam{v}/image_raw dropped: {why}")
                continue
            if kind == "far":
                self.problems.report(f"image{v}:stamp", f"cam{v}/image_raw: {why}: segmented on a background model "
                                     f"of its own, kept only if the next image follows it")
            elif kind == "restart":
                self.stream_restarts[v] += 1
                self._reported[v] = False
                self.get_logger().warn(f"cam{v}: {why}: the background model begun at its first image is the view's")
            elif self._late(a.stamp_ns, learning=seg.learning):
                continue
            self._segment(v, seg, *a.payload, t0=t0)

    def _late(self, stamp_ns: int, *, learning: bool) -> bool:
        """Whether the set of ``stamp_ns`` is shed (:class:`LateSetShedder`; never while learning, where its images
        only teach the stream's offset, never at a far or restarting stamp); one log line per burst of shed sets,
        when it ends."""
        if not self.shedder.enabled:
            return False
        if learning:
            self.shedder.age_ns(stamp_ns, time.time_ns())
            return False
        late = self.shedder.shed(stamp_ns, arrival_ns=time.time_ns())
        self._log_burst(self.shedder.pop_burst())
        return late

    def _log_burst(self, burst, *, final: bool = False) -> None:
        """One log line per burst of skipped sets, at most one every 5 s (bursts in between are summed into it)."""
        if burst is not None:
            p = self._pending_bursts
            self._pending_bursts = [1, burst.sets, burst.first_stamp_ns, burst.last_stamp_ns, burst.max_age_ns] \
                if p is None else [p[0] + 1, p[1] + burst.sets, p[2], burst.last_stamp_ns, max(p[4], burst.max_age_ns)]
        p, now = self._pending_bursts, time.monotonic()
        if p is not None and (final or now - self._burst_logged_at >= 5.0):
            self._pending_bursts, self._burst_logged_at = None, now
            self.get_logger().info(
                f"segmentation: {p[1]} late frame set{'s' if p[1] > 1 else ''} skipped in every view "
                f"({p[0]} burst{'s' if p[0] > 1 else ''}, stamps {p[2]}..{p[3]}, up to {p[4] / 1e6:.0f} ms late; "
                f"late_set_s {self.shedder.max_age_ns / 1e9:g}; {self.shedder.shed_sets} in all)")

    def _segment(self, v: int, seg: BackgroundSegmenter, msg: Image, img: np.ndarray, *, t0: float | None) -> None:
        t0 = time.perf_counter() if t0 is None else t0
        pub = self.mask_pubs[v]
        if msg.encoding == "bgr8":
            img = img[:, :, ::-1]
        if not img.flags.c_contiguous:
            img = np.ascontiguousarray(img)
        learning = seg.learning
        if learning:
            self._learn_window(v, seg, ma.stamp_to_ns(msg.header))
        try:
            with one_numba_thread():
                mask = seg.apply(img)
        except SegmentationError as exc:
            self.problems.report(f"image{v}:segmenter", f"cam{v}/image_raw dropped: {exc}")
            return
        if seg.building and seg not in self._building:
            self._building.append(seg)
            if self._build_timer.is_canceled():
                self._build_timer.reset()
        if learning and not seg.learning:
            learnt = self.windows.learnt(seg)
            self.get_logger().info(
                f"cam{v}: background learnt from {seg.images_learnt} of {self.config.learn_frames} images, stamps "
                f"{learnt[0]}..{learnt[-1]} (window from {self.windows.start_ns(seg)}, period "
                f"{self.windows.period_ns() / 1e6:.2f} ms" + (")" if len(learnt) == self.config.learn_frames
                                                              else "; the others lost)"))
        if not self._reported[v] and not seg.learning and seg.outlier_fraction is not None and \
                seg is self.streams[v].state:
            self._reported[v] = True    # the robust-mode decision is logged once per view (and learning)
            self.get_logger().info(
                f"cam{v}: background learnt, outlying share {seg.outlier_fraction:.3f} -> robust mode "
                + ("on (neighbourhood vote)" if seg.robust_active else "off"))
        out = ma.array_to_image(mask, "mono8")
        out.header = msg.header
        self.masks_published[v] += 1      # before publish(): a Ctrl-C right after it must not lose the count
        pub.publish(out)
        self.latency_s.append(time.perf_counter() - t0)

    def _advance_builds(self) -> None:
        """Timer: one step of the oldest background model's build (none left: the timer stops)."""
        current = self.segmenters
        while self._building and not (self._building[0].building and any(m is self._building[0] for m in current)):
            self._building.popleft()        # finished (by its next image), or a model the view forgot
        if not self._building:
            self._build_timer.cancel()
            return
        with one_numba_thread():
            self._building[0].advance_build()

    def _learn_window(self, v: int, seg: BackgroundSegmenter, stamp_ns: int) -> None:
        """Before a learning model takes the image of ``stamp_ns``: past its learning window
        (:class:`LearningWindows`) its learning ends on the images it got (the image is segmented)."""
        if self.windows.admits(seg, stamp_ns, v):
            return
        if seg.finish_learning() == 0:      # nothing learnt (every image of its window lost): a window of its own
            self.windows.restart(seg, stamp_ns)
            self.get_logger().warn(f"cam{v}: no image within the learning window; learning from stamp {stamp_ns} on")

    def _publish_diagnostics(self) -> None:
        """1 Hz: masks published, inputs dropped (per kind), views still learning, learning restarts."""
        st = DiagnosticStatus(name="isa_mocap_ros: segmentation", hardware_id="segmentation")
        values = {"masks_published": self.masks_published, "bad_inputs": self.problems.total,
                  "problems": json.dumps(self.problems.counts), "learning_restarts": self.restarts,
                  "stream_restarts": self.stream_restarts, "late_sets_skipped": self.shedder.shed_sets,
                  "views_learning": [v for v, seg in enumerate(self.segmenters) if seg.learning],
                  "images_waiting_for_camera_info": [g.waiting() for g in self.gates]}
        st.level = DiagnosticStatus.OK if self.problems.total == 0 else DiagnosticStatus.WARN
        st.message = "segmenting" if any(self.masks_published) else "waiting for images and camera infos"
        st.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        self.pub_diag.publish(DiagnosticArray(header=ma.make_header(self.get_clock().now().nanoseconds),
                                              status=[st]))

    def close(self) -> None:
        """Log the masks published and the per-image processing time."""
        lat = np.array(self.latency_s) * 1e3
        self._log_burst(self.shedder.pop_burst(flush=True), final=True)
        text = (f"segmentation: {sum(self.masks_published)} masks published {self.masks_published}, "
                f"{sum(n for k, n in self.problems.counts.items() if k.startswith('image'))} images dropped"
                + (f", {infos} camera infos dropped" if (infos := sum(n for k, n in self.problems.counts.items()
                                                                      if k.startswith('info'))) else "")
                + (f", learning restarted {self.restarts} (camera changes)" if any(self.restarts) else "")
                + (f", streams restarted {self.stream_restarts}" if any(self.stream_restarts) else "")
                + (f", {self.shedder.shed_sets} late frame sets skipped" if self.shedder.shed_sets else "")
                + (f", per image {np.median(lat):.2f} ms median / {np.percentile(lat, 95):.2f} ms p95 / "
                   f"{lat.max():.1f} ms max" if lat.size else ""))
        log_closing(self, text)


def main(args: list[str] | None = None) -> int:
    """Console script ``segmentation_node``."""
    # Single-threaded: images of every view are segmented in arrival order (a few ms each at
    # 320x240), and the CPU is left to the estimator on small machines.
    return run_node(SegmentationNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
