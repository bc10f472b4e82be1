"""Multi-view frame sources for the camera node (pure: OpenCV and numpy, no ROS).

Source: issue 6 item 1 and DESIGN §1 ("``camera`` (live devices, video files, image folders, or a
synthetic rig driven by BVH motion)"). Every source delivers *frame sets*: one RGB image per view
per :meth:`FrameSource.read`, in view order, so the camera node can stamp them all alike.

Sources
-------
:class:`DeviceSource`
    Live cameras through ``cv2.VideoCapture(index)`` (V4L2 on Linux). A device that fails to open
    or to deliver a frame gives ``None`` for its view and is reopened with exponential back-off
    (``retry_s``, doubling up to ``max_retry_s``); failures and reconnections are reported as
    :class:`SourceEvent` objects (``events`` list and optional ``on_event`` callback), e.g.
    ``"reconnected camera 2 (device 5)"``. It never raises because a device is missing.
:class:`VideoFileSource`
    One video file per view (anything OpenCV decodes), advanced together; ``loop`` rewinds a file
    that ended, otherwise the first view to end ends the source.
:class:`ImageFolderSource`
    One glob per view; the matches of each glob are sorted by name and read in that order. The
    source has as many frames as the shortest list.
:class:`SyntheticSource`
    The synthetic rig of :mod:`isa_mocap_ros.synth` rendered live: a generated motion or a BVH file
    on a body model, ``empty_frames`` background-only frames first, pixel noise and occluders drawn
    from ``default_rng([seed, 2, frame, view])`` (:func:`isa_mocap_ros.synth.frame_rng`), so frame
    ``k`` is identical whether rendered live, into a bag, or alone.
:class:`DistortedSource`
    Wraps any source and adds the ISA distortions (§13.4.2: pixel noise ``p``, ``k`` occluding
    rectangles) with the same per-frame generators.

End of stream: :meth:`FrameSource.read` raises :class:`EndOfSource` (a finite file or folder
source without ``loop``, or a synthetic clip without ``loop``).
"""
from __future__ import annotations

import glob as globlib
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import cv2
import numpy as np

from .calib_formats import read_calibration
from .calibration import Rig, default_rig
from .source_base import EndOfSource, FrameSource, SourceError, SourceEvent, _bgr_to_rgb, _EventMixin
from .source_wrappers import AdaptedSource, DistortedSource, ResizedSource

__all__ = ["FrameSource", "EndOfSource", "SourceError", "SourceEvent", "DeviceSource", "VideoFileSource",
           "ImageFolderSource", "SyntheticSource", "DistortedSource", "ResizedSource", "AdaptedSource", "SourceConfig",
           "SOURCE_KINDS", "resolve_rig", "open_source"]

#: the ``source`` values of :class:`SourceConfig`
SOURCE_KINDS = ("synthetic", "device", "video", "images")


# --------------------------------------------------------------------------------------- devices
def _open_device(index: int):
    """``cv2.VideoCapture`` of a device index (the V4L2 back end on Linux)."""
    api = cv2.CAP_V4L2 if sys.platform.startswith("linux") else cv2.CAP_ANY
    return cv2.VideoCapture(int(index), api)


class DeviceSource(_EventMixin):
    """Live cameras by device index (``/dev/video<index>`` on Linux), BGR converted to RGB.

    Parameters
    ----------
    indices : sequence of int
        One device index per view.
    retry_s : float, keyword-only
        First wait before reopening a failed device; doubles after each failed attempt.
    max_retry_s : float, keyword-only
        Longest wait between attempts.
    width, height, fps : int, int, float, keyword-only
        Requested capture size and rate (0 = the device's default; a device may ignore them).
    on_event : callable(SourceEvent), optional
        Called for every failure / reconnection (also kept in :attr:`events`).
    opener : callable(int) -> capture, optional
        Opens a device (default ``cv2.VideoCapture``); a capture needs ``isOpened()``, ``read()``
        and ``release()``. For tests and other capture back ends.
    clock : callable() -> float, optional
        Monotonic seconds (default ``time.monotonic``).

    Notes
    -----
    A failed device costs nothing until its retry time: :meth:`read` returns ``None`` for it
    without touching the device.
    """

    def __init__(self, indices: Sequence[int], *, retry_s: float = 0.5, max_retry_s: float = 5.0,
                 width: int = 0, height: int = 0, fps: float = 0.0,
                 on_event: Callable[[SourceEvent], None] | None = None,
                 opener: Callable[[int], Any] | None = None, clock: Callable[[], float] | None = None) -> None:
        idx = list(indices) if isinstance(indices, (list, tuple)) else None
        if not idx or any(isinstance(i, bool) or not isinstance(i, (int, np.integer)) or i < 0 for i in idx):
            raise SourceError(f"indices: expected a non-empty list of device indices >= 0, received {indices!r}")
        if not (retry_s > 0 and max_retry_s >= retry_s):
            raise SourceError(f"retry_s, max_retry_s: expected 0 < retry_s <= max_retry_s, received "
                              f"{retry_s!r}, {max_retry_s!r}")
        self._init_events(on_event)
        self.indices = [int(i) for i in idx]
        self.n_views = len(self.indices)
        self.retry_s, self.max_retry_s = float(retry_s), float(max_retry_s)
        self._size = (int(width), int(height), float(fps))
        self._opener = opener or _open_device
        self._clock = clock or time.monotonic
        self._caps: list[Any] = [None] * self.n_views
        self._next_try = [0.0] * self.n_views
        self._wait = [self.retry_s] * self.n_views
        self._was_open = [False] * self.n_views
        self._failed_reported = [False] * self.n_views
        for v in range(self.n_views):
            self._try_open(v)

    def _name(self, v: int) -> str:
        return f"camera {v} (device {self.indices[v]})"

    def _try_open(self, v: int) -> bool:
        cap = None
        try:
            cap = self._opener(self.indices[v])
            ok = bool(cap is not None and cap.isOpened())
        except Exception as exc:  # noqa: BLE001 - a back end may raise anything; the node must go on
            ok, err = False, exc
        else:
            err = None
        if ok:
            w, h, fps = self._size
            if w > 0 and h > 0 and hasattr(cap, "set"):
                cap.set(cv2.CAP_PROP_FRAME_WIDTH, w)
                cap.set(cv2.CAP_PROP_FRAME_HEIGHT, h)
            if fps > 0 and hasattr(cap, "set"):
                cap.set(cv2.CAP_PROP_FPS, fps)
            self._caps[v] = cap
            self._wait[v] = self.retry_s
            if self._was_open[v] or self._failed_reported[v]:
                self._emit("reconnected", v, f"reconnected {self._name(v)}")
            self._was_open[v] = True
            self._failed_reported[v] = False
            return True
        if cap is not None:
            try:
                cap.release()
            except Exception:  # noqa: BLE001
                pass
        self._schedule_retry(v, "cannot open" + (f": {err}" if err else ""))
        return False

    def _schedule_retry(self, v: int, why: str) -> None:
        wait = self._wait[v]
        self._next_try[v] = self._clock() + wait
        self._wait[v] = min(self.max_retry_s, 2.0 * wait)
        kind = "retry" if self._failed_reported[v] else "failed"
        self._failed_reported[v] = True
        self._emit(kind, v, f"{self._name(v)} {why}; retrying in {wait:.1f} s")

    def read(self) -> list[np.ndarray | None]:
        """One frame per device; ``None`` (and a reconnect attempt later) for a failed one."""
        out: list[np.ndarray | None] = []
        now = self._clock()
        for v in range(self.n_views):
            cap = self._caps[v]
            if cap is None:
                if now < self._next_try[v] or not self._try_open(v):
                    out.append(None)
                    continue
                cap = self._caps[v]
            try:
                ok, frame = cap.read()
            except Exception as exc:  # noqa: BLE001
                ok, frame = False, None
                why = f"read failed: {exc}"
            else:
                why = "delivered no frame"
            if not ok or frame is None or frame.size == 0:
                try:
                    cap.release()
                except Exception:  # noqa: BLE001
                    pass
                self._caps[v] = None
                self._schedule_retry(v, why)
                out.append(None)
                continue
            out.append(_bgr_to_rgb(frame))
        return out

    def close(self) -> None:
        """Release every device."""
        for v, cap in enumerate(self._caps):
            if cap is not None:
                cap.release()
            self._caps[v] = None


# ------------------------------------------------------------------------------------ video files
class VideoFileSource(_EventMixin):
    """One video file per view, read in lockstep (BGR converted to RGB).

    Parameters
    ----------
    paths : sequence of str or Path
        One file per view; each must open with OpenCV.
    loop : bool, keyword-only
        Rewind a file that ended (each view independently); otherwise :meth:`read` raises
        :class:`EndOfSource` as soon as one view has no frame left.
    """

    def __init__(self, paths: Sequence[str | Path], *, loop: bool = False,
                 on_event: Callable[[SourceEvent], None] | None = None) -> None:
        if not isinstance(paths, (list, tuple)) or not paths:
            raise SourceError(f"paths: expected a non-empty list of video files, received {paths!r}")
        self._init_events(on_event)
        self.paths = [Path(p) for p in paths]
        self.n_views = len(self.paths)
        self.loop = bool(loop)
        self._caps = []
        for p in self.paths:
            if not p.is_file():
                self.close()
                raise SourceError(f"paths: video file {str(p)!r} does not exist")
            cap = cv2.VideoCapture(str(p))
            if not cap.isOpened():
                self.close()
                raise SourceError(f"paths: OpenCV cannot open video {str(p)!r}")
            self._caps.append(cap)
        self.frames_read = 0

    @property
    def fps(self) -> list[float]:
        """Frame rate stored in each file (0 when unknown)."""
        return [float(c.get(cv2.CAP_PROP_FPS) or 0.0) for c in self._caps]

    def read(self) -> list[np.ndarray | None]:
        """Next frame of every file; see ``loop``."""
        out: list[np.ndarray | None] = []
        for v, cap in enumerate(self._caps):
            ok, frame = cap.read()
            if not ok and self.loop:
                cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
                ok, frame = cap.read()
                if ok:
                    self._emit("info", v, f"video {self.paths[v].name} (view {v}) looped to its start")
            if not ok:
                if self.loop:
                    self._emit("failed", v, f"video {self.paths[v].name} (view {v}) gives no frame even "
                                            "after rewinding")
                    out.append(None)
                    continue
                raise EndOfSource(f"video {self.paths[v]} (view {v}) ended after {self.frames_read} frames")
            out.append(_bgr_to_rgb(frame))
        self.frames_read += 1
        return out

    def close(self) -> None:
        """Release the files."""
        for cap in self._caps:
            cap.release()
        self._caps = []


# ---------------------------------------------------------------------------------- image folders
class ImageFolderSource(_EventMixin):
    """One glob per view (e.g. ``"seq/cam0/*.png"``); files sorted by name, read in order.

    Parameters
    ----------
    globs : sequence of str
        One pattern per view (``**`` allowed); each must match at least one file.
    loop : bool, keyword-only
        Start again after the last frame set instead of raising :class:`EndOfSource`.

    Attributes
    ----------
    files : list of list of Path
        The matched files per view, cut to the shortest list.
    n_frames : int
    """

    def __init__(self, globs: Sequence[str], *, loop: bool = False,
                 on_event: Callable[[SourceEvent], None] | None = None) -> None:
        if not isinstance(globs, (list, tuple)) or not globs or not all(isinstance(g, str) and g for g in globs):
            raise SourceError(f"globs: expected a non-empty list of non-empty glob patterns, received {globs!r}")
        self._init_events(on_event)
        self.globs = list(globs)
        self.n_views = len(self.globs)
        self.loop = bool(loop)
        files = []
        for v, g in enumerate(self.globs):
            found = sorted((Path(p) for p in globlib.glob(g, recursive=True) if Path(p).is_file()), key=str)
            if not found:
                raise SourceError(f"globs[{v}]: pattern {g!r} matches no file")
            files.append(found)
        self.n_frames = min(len(f) for f in files)
        if any(len(f) != self.n_frames for f in files):
            self._emit("warning", -1, f"image globs match {[len(f) for f in files]} files; using the first "
                                      f"{self.n_frames} of each view")
        self.files = [f[:self.n_frames] for f in files]
        self.index = 0

    def read(self) -> list[np.ndarray | None]:
        """The next file of every view (``None`` for a file OpenCV cannot read)."""
        if self.index >= self.n_frames:
            if not self.loop:
                raise EndOfSource(f"image folders ended after {self.n_frames} frames")
            self.index = 0
        out: list[np.ndarray | None] = []
        for v in range(self.n_views):
            path = self.files[v][self.index]
            img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if img is None or img.dtype != np.uint8:
                self._emit("failed", v, f"cannot read {path} (view {v}) as an 8-bit image; view skipped")
                out.append(None)
            else:
                out.append(_bgr_to_rgb(img))
        self.index += 1
        return out

    def close(self) -> None:
        """Nothing to release."""


# ------------------------------------------------------------------------------------- synthetic
class SyntheticSource(_EventMixin):
    """The synthetic rig rendering a motion live (:mod:`isa_mocap_ros.synth`).

    Parameters
    ----------
    rig : Rig
        Cameras to render (their sizes are the image sizes).
    motion : str or Path
        A generated motion name (``walk``, ``jog``, ``walk_turns``, ``wave``, ``box``) or a BVH file.
    fps : float, keyword-only
        Frame rate of the motion (a BVH is resampled to it).
    model_dof : {39, 28, 18}, keyword-only
    seed : int, keyword-only
        Seeds the motion, the backgrounds and the per-frame distortions.
    noise : float, keyword-only
        Pixel-noise probability in [0, 1].
    occluders : int, keyword-only
        Occluding rectangles per image.
    empty_frames : int, keyword-only
        Background-only frames before the motion (for background learning); not repeated on a loop.
    duration_s : float, optional, keyword-only
        Seconds of motion (default: the whole BVH, or 5 s of a generated motion).
    start_s : float, keyword-only
        Skip this many seconds of the motion.
    loop : bool, keyword-only
        Play the motion again after its end (frame numbers, hence distortions, keep counting);
        otherwise :meth:`read` raises :class:`EndOfSource`.

    Attributes
    ----------
    frame : int
        Index of the next frame (empty frames count), the ``frame`` of :func:`synth.frame_rng`.
    last_pose : (D,) ndarray or None
        Ground-truth pose of the frame read last (``None`` for an empty frame).
    last_masks : list of (H, W) uint8
        Exact silhouettes of the frame read last (before distortions).
    """

    def __init__(self, rig: Rig, motion: str | Path, *, fps: float = 30.0, model_dof: int = 39, seed: int = 0,
                 noise: float = 0.0, occluders: int = 0, empty_frames: int = 0, duration_s: float | None = None,
                 start_s: float = 0.0, loop: bool = True,
                 on_event: Callable[[SourceEvent], None] | None = None) -> None:
        from isa_mocap_ros.synth import SceneRenderer, make_clip

        if not isinstance(rig, Rig):
            raise SourceError(f"rig: expected a Rig, received {type(rig).__name__}")
        if isinstance(empty_frames, bool) or not isinstance(empty_frames, (int, np.integer)) or empty_frames < 0:
            raise SourceError(f"empty_frames: expected an integer >= 0, received {empty_frames!r}")
        self._init_events(on_event)
        self.rig = rig
        self.n_views = len(rig)
        self.clip = make_clip(motion, dof=model_dof, fps=fps, seed=seed, duration_s=duration_s, start_s=start_s)
        self.renderer = SceneRenderer(self.clip.model, rig, seed=seed, noise=noise, occluders=occluders)
        self.empty_frames = int(empty_frames)
        self.loop = bool(loop)
        self.frame = 0
        self.last_pose: np.ndarray | None = None
        self.last_masks: list[np.ndarray] = []

    @property
    def model(self):
        """The body model being rendered."""
        return self.clip.model

    def pose_at(self, frame: int) -> np.ndarray | None:
        """Ground-truth pose of frame ``frame`` (``None`` for an empty frame)."""
        if frame < self.empty_frames:
            return None
        j = frame - self.empty_frames
        if j >= self.clip.n_frames and not self.loop:
            raise EndOfSource(f"synthetic motion ended after {self.empty_frames + self.clip.n_frames} frames")
        return self.clip.poses[j % self.clip.n_frames]

    def read(self) -> list[np.ndarray | None]:
        """Render the next frame in every view."""
        pose = self.pose_at(self.frame)
        if pose is not None and self.frame - self.empty_frames == self.clip.n_frames:
            self._emit("info", -1, f"synthetic motion looped after {self.clip.n_frames} frames")
        images, masks = self.renderer.render(pose, self.frame)
        self.last_pose = None if pose is None else pose.copy()
        self.last_masks = masks
        self.frame += 1
        return list(images)

    def close(self) -> None:
        """Nothing to release."""


# ------------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class SourceConfig:
    """Everything the camera node needs to build its source (its ROS parameters, read once).

    Attributes
    ----------
    source : {"synthetic", "device", "video", "images"}
    devices : tuple of int
        ``source="device"``: one device index per view.
    videos, image_globs : tuple of str
        ``source="video"`` / ``"images"``: one file / glob per view.
    motion : str
        ``source="synthetic"``: generated motion name or BVH path.
    motion_duration_s : float
        Seconds of motion (0 = the whole BVH / 5 s generated).
    model_dof : int
        Body model of the synthetic person (18, 28, 39).
    rig_file : str
        Rig file ('' = the default rig; only allowed for ``synthetic``).
    views : int
        Number of views (the first ``views`` cameras of the rig).
    width, height : int
        Image size published (0 = the rig file's own sizes). ``video``/``images``: ``height`` 0 keeps
        the frames' aspect ratio at ``width`` (see :class:`AdaptedSource`).
    fit : {"auto", "scale", "letterbox", "crop"}
        ``video``/``images``: how frames of another size relate to the calibration (:mod:`.adapt`).
    fps : float
    seed : int
    noise : float
    occluders : int
    empty_frames : int
    loop : bool
    """

    source: str = "synthetic"
    devices: tuple[int, ...] = ()
    videos: tuple[str, ...] = ()
    image_globs: tuple[str, ...] = ()
    motion: str = "walk"
    motion_duration_s: float = 0.0
    model_dof: int = 39
    rig_file: str = ""
    views: int = 4
    width: int = 320
    height: int = 240
    fps: float = 30.0
    seed: int = 0
    noise: float = 0.0
    occluders: int = 0
    empty_frames: int = 10
    loop: bool = True
    fit: str = "auto"

    def __post_init__(self) -> None:
        if self.source not in SOURCE_KINDS:
            raise SourceError(f"source: expected one of {', '.join(SOURCE_KINDS)}, received {self.source!r}")
        if self.views < 1:
            raise SourceError(f"views: expected an integer >= 1, received {self.views!r}")
        from .adapt import FITS

        if self.fit not in FITS:
            raise SourceError(f"fit: expected one of {', '.join(FITS)}, received {self.fit!r}")
        keep_aspect = self.source in ("video", "images") and self.width > 0 and self.height == 0
        if ((self.width == 0) != (self.height == 0) and not keep_aspect) or self.width < 0 or self.height < 0:
            raise SourceError(f"width, height: expected both > 0, or both 0 (the rig's sizes), received "
                              f"{self.width}x{self.height}")
        if not self.fps > 0:
            raise SourceError(f"fps: expected a number > 0, received {self.fps!r}")
        inputs = {"device": ("devices", self.devices), "video": ("videos", self.videos),
                  "images": ("image_globs", self.image_globs)}
        if self.source in inputs:
            name, values = inputs[self.source]
            if len(values) != self.views:
                raise SourceError(f"{name}: expected one entry per view (views={self.views}) for source "
                                  f"{self.source!r}, received {len(values)}: {list(values)}")
            if not self.rig_file:
                raise SourceError(f"rig_file: source {self.source!r} needs a rig/calibration file; without one "
                                  "the cameras' extrinsics are unknown (only the synthetic source has a "
                                  "default rig)")


def resolve_rig(cfg: SourceConfig) -> Rig:
    """The rig whose first ``cfg.views`` cameras the node publishes, at ``cfg.width x cfg.height``.

    Raises
    ------
    SourceError
        A rig file with fewer cameras than ``views``; :class:`VisionError` for an unreadable file.
    """
    if not cfg.rig_file:
        return default_rig(n_views=cfg.views, width=cfg.width or 320, height=cfg.height or 240)
    path = Path(cfg.rig_file)
    if not path.is_file():
        raise SourceError(f"rig_file: {cfg.rig_file!r} does not exist")
    rig = read_calibration(path)          # a rig YAML or any other tool's calibration file
    if len(rig) < cfg.views:
        raise SourceError(f"views: the rig file {cfg.rig_file!r} has {len(rig)} cameras, views={cfg.views}")
    rig = Rig(rig.cameras[:cfg.views], rig.name, rig.capture_volume)
    if cfg.source in ("video", "images"):   # sizes follow the frames: AdaptedSource.rig
        return rig
    if cfg.width and any((c.width, c.height) != (cfg.width, cfg.height) for c in rig.cameras):
        rig = rig.resized(cfg.width, cfg.height)
    return rig


def open_source(cfg: SourceConfig, rig: Rig, *,
                on_event: Callable[[SourceEvent], None] | None = None) -> FrameSource:
    """Build the frame source of ``cfg`` for ``rig`` (distortions and resizing included).

    The synthetic source renders at the rig's sizes and draws its own distortions; devices are
    wrapped in :class:`ResizedSource` (to the rig's sizes), video files and image folders in
    :class:`AdaptedSource` (letterbox / scale / crop against the calibration; its ``rig`` has the
    published cameras); then, when ``noise`` or ``occluders`` is set, :class:`DistortedSource`.
    """
    if cfg.source == "synthetic":
        return SyntheticSource(rig, cfg.motion, fps=cfg.fps, model_dof=cfg.model_dof, seed=cfg.seed,
                               noise=cfg.noise, occluders=cfg.occluders, empty_frames=cfg.empty_frames,
                               duration_s=cfg.motion_duration_s or None, loop=cfg.loop, on_event=on_event)
    if cfg.source == "device":
        src: Any = DeviceSource(list(cfg.devices), width=rig.cameras[0].width, height=rig.cameras[0].height,
                                fps=cfg.fps, on_event=on_event)
    else:
        if cfg.source == "video":
            src, labels = VideoFileSource(list(cfg.videos), loop=cfg.loop, on_event=on_event), list(cfg.videos)
        else:
            src = ImageFolderSource(list(cfg.image_globs), loop=cfg.loop, on_event=on_event)
            labels = list(cfg.image_globs)
        src = AdaptedSource(src, rig.cameras, fit=cfg.fit, width=cfg.width, height=cfg.height, rig_name=rig.name,
                            capture_volume=rig.capture_volume, labels=labels, on_event=on_event)
    if cfg.source == "device":
        src = ResizedSource(src, [(c.width, c.height) for c in rig.cameras], on_event=on_event)
    if cfg.noise > 0 or cfg.occluders > 0:
        src = DistortedSource(src, seed=cfg.seed, noise=cfg.noise, occluders=cfg.occluders)
    return src
