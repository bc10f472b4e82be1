"""Camera node: frame sets from devices, video files, image folders or the synthetic rig.

Run alone (relative topic names; the network runs it in ``/mocap``)::

    camera_node --ros-args -r __ns:=/mocap -p source:=synthetic -p motion:=walk -p views:=4
    python -m isa_mocap_ros.nodes.camera --ros-args -r __ns:=/mocap --params-file config/pipeline.yaml

A timer at ``fps`` reads one frame set from the source (:mod:`isa_mocap_ros.vision.sources`) and
publishes, per view ``i``, ``cam<i>/image_raw`` (rgb8) and ``cam<i>/camera_info`` -- every image and
camera info of one set carries the same ``header.stamp`` (the node clock when the set was read).
``cam<i>/extrinsics`` (``geometry_msgs/TransformStamped`` world -> ``cam<i>_optical_frame``, i.e.
``Camera.pose_in_world()``) is published once, latched (transient local, depth 1).

Video files and image folders are adapted to the calibration (:class:`~isa_mocap_ros.vision.sources.
AdaptedSource`): a frame of another size than the calibrated sensor (scaled, letterboxed, or with
``fit:=crop`` a centred cut) gets the matching intrinsics on ``camera_info``, logged once per view;
``rig_file`` may be any calibration format (:mod:`isa_mocap_ros.vision.calib_formats`).

Faults: a view whose image is missing this time (device unplugged, unreadable file, another aspect
ratio) is skipped for that set and reported (rate-limited); a failed device is reopened with
back-off and "reconnected camera <i> (device <n>)" is logged. A video/image source without a rig
file is refused at start-up (extrinsics unknown): exit code 2 with one line saying so.
"""
from __future__ import annotations

import sys
import time

import cv2
from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image

import msg_adapters as ma
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.nodes.common import QOS_OVERRIDES, ProblemLog, declare, run_node
from isa_mocap_ros.vision.sources import AdaptedSource, EndOfSource, SourceConfig, SourceEvent, open_source, resolve_rig

__all__ = ["CameraNode", "main"]


class CameraNode(Node):
    """Thin node over :func:`isa_mocap_ros.vision.sources.open_source` (see the module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__("camera", **kwargs)
        self.config = self._read_parameters()
        self.problems = ProblemLog(self)
        self.rig = resolve_rig(self.config)
        if self.config.source == "device":
            # OpenCV's own multi-line open warnings; the source reports failures itself, once per retry
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
        self.source = open_source(self.config, self.rig, on_event=self._on_source_event)
        adapted = self.source if isinstance(self.source, AdaptedSource) else getattr(self.source, "source", None)
        if isinstance(adapted, AdaptedSource):     # video / images: the cameras of the adapted frames
            self.rig = adapted.rig
            for line in adapted.describe():
                self.get_logger().info(f"camera: {line}")
        n = self.config.views
        self.frames = [f"{self.frame_id_prefix}cam{i}_optical_frame" for i in range(n)]
        self.intrinsics = [ma.Intrinsics(**cam.intrinsics_fields()) for cam in self.rig.cameras]
        self.image_pubs = [self.create_publisher(Image, f"cam{i}/image_raw", qos.RELIABLE,
                                                 qos_overriding_options=QOS_OVERRIDES) for i in range(n)]
        self.info_pubs = [self.create_publisher(CameraInfo, f"cam{i}/camera_info", qos.RELIABLE,
                                                qos_overriding_options=QOS_OVERRIDES) for i in range(n)]
        self.extrinsics_pubs = [self.create_publisher(TransformStamped, f"cam{i}/extrinsics", qos.LATCHED,
                                                      qos_overriding_options=QOS_OVERRIDES) for i in range(n)]
        stamp = self.get_clock().now().nanoseconds
        for i, cam in enumerate(self.rig.cameras):
            R_wc, t_wc = cam.pose_in_world()
            self.extrinsics_pubs[i].publish(ma.rt_to_transform(R_wc, t_wc, parent_frame="world",
                                                               child_frame=self.frames[i], stamp_ns=stamp))
        self.sets_published = 0
        self.views_skipped = 0
        self._t0: float | None = None
        self._t_last = 0.0
        self.timer = self.create_timer(1.0 / self.config.fps, self._tick)
        sizes = sorted({f"{c.width}x{c.height}" for c in self.rig.cameras})
        self.get_logger().info(
            f"camera: {self.config.source} source, {n} views ({', '.join(sizes)}) at {self.config.fps:g} fps, "
            f"rig {self.rig.name!r}")

    def _read_parameters(self) -> SourceConfig:
        d = lambda *a, **k: declare(self, *a, **k)  # noqa: E731
        source = d("source", "synthetic", "frame source: synthetic, device, video or images")
        devices = d("devices", Parameter.Type.INTEGER_ARRAY, "source=device: one device index per view "
                    "(/dev/video<n>)") or []
        videos = d("videos", Parameter.Type.STRING_ARRAY, "source=video: one video file per view") or []
        globs = d("image_globs", Parameter.Type.STRING_ARRAY,
                  "source=images: one glob per view (files sorted by name)") or []
        motion = d("motion", "walk", "source=synthetic: walk, jog, walk_turns, wave, box, or a BVH file")
        duration = d("motion_duration_s", 0.0, "seconds of motion (0 = whole BVH, 5 s generated)", lo=0.0, hi=1e6)
        dof = d("model_dof", 39, "source=synthetic: body model (18, 28 or 39 DOF)", lo=18, hi=39)
        rig_file = d("rig_file", "", "rig or calibration file: rig YAML, Pose2Sim/anipose TOML, Qualisys .qca.txt, "
                     "OpenCV FileStorage, camera_info YAML ('' = default rig, synthetic source only)")
        views = d("views", 4, "number of views (the first cameras of the rig)", lo=1, hi=64)
        width = d("width", 320, "published image width (0 = the rig file's)", lo=0, hi=8192)
        height = d("height", 240, "published image height (0 = the rig file's; video/images: 0 keeps the "
                   "frames' aspect ratio at width)", lo=0, hi=8192)
        fit = d("fit", "auto", "video/images of another size than the calibration: auto, scale, letterbox, crop")
        fps = d("fps", 30.0, "frame sets per second (timer rate; the synthetic motion's rate)", lo=0.1, hi=1000.0)
        seed = d("seed", 0, "seed of the synthetic motion, backgrounds and distortions", lo=0, hi=2**31 - 1)
        noise = d("noise", 0.0, "pixel-noise probability (ISA 13.4.2; 0 = off)", lo=0.0, hi=1.0)
        occ = d("occluders", 0, "occluding rectangles per image (0 = off)", lo=0, hi=1000)
        empty = d("empty_frames", 10, "synthetic: background-only frames first (background learning)",
                  lo=0, hi=100000)
        loop = d("loop", True, "start the video/images/motion again at its end")
        self.frame_id_prefix = d("frame_id_prefix", "", "prefix of the cam<i>_optical_frame frame ids")
        return SourceConfig(source=source, devices=tuple(int(i) for i in devices), videos=tuple(videos),
                            image_globs=tuple(globs), motion=motion, motion_duration_s=duration, model_dof=dof,
                            rig_file=rig_file, views=views, width=width, height=height, fps=fps, seed=seed,
                            noise=noise, occluders=occ, empty_frames=empty, loop=loop, fit=fit)

    def _on_source_event(self, ev: SourceEvent) -> None:
        if ev.kind in ("reconnected", "info"):
            self.get_logger().info(ev.text)
        else:
            self.problems.report(f"source{ev.view}", ev.text)  # one rate-limited line per view

    def _tick(self) -> None:
        try:
            images = self.source.read()
        except EndOfSource as exc:
            self.timer.cancel()
            self.get_logger().info(f"source ended ({exc}); {self.sets_published} frame sets published")
            return
        stamp = self.get_clock().now().nanoseconds
        for i, img in enumerate(images):
            if img is None:  # the source has reported why (an event, logged rate-limited)
                self.views_skipped += 1
                continue
            self.image_pubs[i].publish(ma.array_to_image(img, "rgb8", stamp_ns=stamp, frame_id=self.frames[i]))
            self.info_pubs[i].publish(ma.intrinsics_to_camera_info(self.intrinsics[i], stamp_ns=stamp,
                                                                   frame_id=self.frames[i]))
        if all(img is None for img in images):
            return
        self.sets_published += 1
        now = time.monotonic()
        if self._t0 is None:
            self._t0 = now
        self._t_last = now

    @property
    def rate_hz(self) -> float:
        """Frame sets per second achieved so far (0 before the second set)."""
        if self._t0 is None or self.sets_published < 2 or self._t_last <= self._t0:
            return 0.0
        return (self.sets_published - 1) / (self._t_last - self._t0)

    def close(self) -> None:
        """Release the source; log what was published."""
        text = (f"camera: {self.sets_published} frame sets published at {self.rate_hz:.2f} sets/s, "
                f"{self.views_skipped} views skipped")
        if self.context.ok():
            self.get_logger().info(text)
        else:  # after Ctrl-C the context is gone; /rosout cannot take it
            print(text, file=sys.stderr, flush=True)
        self.source.close()


def main(args: list[str] | None = None) -> int:
    """Console script ``camera_node``."""
    return run_node(CameraNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
