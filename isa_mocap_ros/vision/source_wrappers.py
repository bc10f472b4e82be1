"""Sources that wrap another frame source (:mod:`.sources`): :class:`DistortedSource` (the ISA
distortions, §13.4.2), :class:`ResizedSource` (images brought to the rig's sizes) and
:class:`AdaptedSource` (real footage adapted to calibrated cameras, :mod:`.adapt`).
"""
from __future__ import annotations

from typing import Any, Callable, Sequence

import cv2
import numpy as np

from .calibration import Rig
from .distort import occluders as _occluders
from .distort import pixel_noise as _pixel_noise
from .errors import VisionError
from .source_base import EndOfSource, FrameSource, SourceError, SourceEvent

__all__ = ["DistortedSource", "ResizedSource", "AdaptedSource"]


# ------------------------------------------------------------------------------------ distortions
class DistortedSource:
    """Any source with the ISA distortions added (pixel noise, then occluders) per frame and view.

    The generator of frame ``k`` (counting :meth:`read` calls from 0) and view ``v`` is
    ``default_rng([seed, 2, k, v])`` as in :func:`isa_mocap_ros.synth.frame_rng`.
    """

    def __init__(self, source: FrameSource, *, seed: int = 0, noise: float = 0.0, occluders: int = 0) -> None:
        if not (0.0 <= float(noise) <= 1.0):
            raise SourceError(f"noise: expected a probability in [0, 1], received {noise!r}")
        if isinstance(occluders, bool) or not isinstance(occluders, (int, np.integer)) or occluders < 0:
            raise SourceError(f"occluders: expected an integer >= 0, received {occluders!r}")
        self.source = source
        self.n_views = source.n_views
        from isa_mocap_ros.synth import frame_rng

        self._frame_rng = frame_rng
        self.seed, self.noise, self.occluders = int(seed), float(noise), int(occluders)
        self.frame = 0

    @property
    def events(self) -> list[SourceEvent]:
        return getattr(self.source, "events", [])

    def drain_events(self) -> list[SourceEvent]:
        drain = getattr(self.source, "drain_events", None)
        return drain() if drain else []

    def read(self) -> list[np.ndarray | None]:
        """The wrapped source's frame set, distorted."""
        images = self.source.read()
        k = self.frame
        self.frame += 1
        out: list[np.ndarray | None] = []
        for v, img in enumerate(images):
            if img is not None and (self.noise > 0 or self.occluders > 0):
                rng = self._frame_rng(self.seed, k, v)
                if self.noise > 0:
                    img = _pixel_noise(img, self.noise, rng=rng)
                if self.occluders > 0:
                    img = _occluders(img, self.occluders, rng=rng)
            out.append(img)
        return out

    def close(self) -> None:
        self.source.close()


# ------------------------------------------------------------------------- wrappers with their own events
class _ReportingWrapper:
    """A wrapper of ``source`` that drops frames with a warning of its own (kept in :attr:`events`, the last
    1000, and passed to ``on_event``), reported by :meth:`drain_events` after the wrapped source's events."""

    def __init__(self, source: FrameSource, on_event: Callable[[SourceEvent], None] | None) -> None:
        self.source = source
        self.n_views = source.n_views
        self._on_event = on_event
        self.events: list[SourceEvent] = []

    def drain_events(self) -> list[SourceEvent]:
        drain = getattr(self.source, "drain_events", None)
        out = (drain() if drain else []) + self.events
        self.events = []
        return out

    def _warn(self, v: int, text: str) -> None:
        ev = SourceEvent("warning", v, text)
        self.events.append(ev)
        del self.events[:-1000]
        if self._on_event is not None:
            self._on_event(ev)

    def close(self) -> None:
        self.source.close()


# ------------------------------------------------------------------------------------- resizing
class ResizedSource(_ReportingWrapper):
    """Any source with its images brought to the rig's sizes.

    An image of another size but the same aspect ratio (within 1 %) is resized (``INTER_AREA``
    shrinking, ``INTER_LINEAR`` enlarging), which is what :meth:`Camera.resized` assumes; one with
    another aspect ratio is replaced by ``None`` and reported (event ``"warning"``), since no
    scaling of the calibration would describe it.

    Parameters
    ----------
    source : FrameSource
    sizes : sequence of (width, height)
        Wanted size per view.
    """

    def __init__(self, source: FrameSource, sizes: Sequence[tuple[int, int]],
                 on_event: Callable[[SourceEvent], None] | None = None) -> None:
        if len(sizes) != source.n_views:
            raise SourceError(f"sizes: expected one (width, height) per view ({source.n_views}), received "
                              f"{len(sizes)}")
        super().__init__(source, on_event)
        self.sizes = [(int(w), int(h)) for w, h in sizes]

    def read(self) -> list[np.ndarray | None]:
        """The wrapped source's frame set at the rig's sizes."""
        out: list[np.ndarray | None] = []
        for v, img in enumerate(self.source.read()):
            w, h = self.sizes[v]
            if img is None or img.shape[:2] == (h, w):
                out.append(img)
                continue
            ih, iw = img.shape[:2]
            if abs(iw * h - ih * w) > 0.01 * iw * h:
                self._warn(v, f"view {v}: image is {iw}x{ih}, the calibration {w}x{h} (another aspect ratio); "
                              "frame dropped")
                out.append(None)
                continue
            interp = cv2.INTER_AREA if iw > w else cv2.INTER_LINEAR
            out.append(cv2.resize(img, (w, h), interpolation=interp))
        return out


# ------------------------------------------------------------------------------- adapted (real) sources
class AdaptedSource(_ReportingWrapper):
    """Video / image-folder frames brought to the calibration: letterbox removed, resized, with the
    matching cameras (:mod:`.adapt`).

    The first frame set is read at construction: each view's frame size and content decide its
    :class:`~.adapt.FrameGeometry` against the calibrated ``sensors`` (same size, scaled, letterboxed,
    or cropped with ``fit="crop"``; another aspect ratio without visible bars raises
    :class:`SourceError`). Output size: ``width x height`` if both are given (the content's aspect
    ratio within 1 %), ``width`` wide or ``max_side`` long keeping the sensor's aspect ratio (so all
    views of one sensor size get one size), else the content's own size. :attr:`rig` holds the cameras of the published images.

    Parameters
    ----------
    source : FrameSource
    sensors : sequence of Camera
        The calibrated cameras, one per view (their sizes are the sensor images').
    """

    def __init__(self, source: FrameSource, sensors: Sequence[Any], *, fit: str = "auto", width: int = 0,
                 height: int = 0, max_side: int = 0, rig_name: str = "rig", capture_volume: Any = None,
                 labels: Sequence[str] | None = None,
                 on_event: Callable[[SourceEvent], None] | None = None) -> None:
        from .adapt import frame_geometry, working_size

        if len(sensors) != source.n_views:
            raise SourceError(f"sensors: expected one calibrated camera per view ({source.n_views}), received "
                              f"{len(sensors)}")
        super().__init__(source, on_event)
        try:
            first = source.read()
        except EndOfSource as exc:
            raise SourceError(f"the source gives no frame ({exc})") from None
        labels = list(labels) if labels else [f"view {v}" for v in range(self.n_views)]
        self.geometries = []
        cams = []
        for v, (cam, img) in enumerate(zip(sensors, first)):
            if img is None:
                raise SourceError(f"{labels[v]}: the first frame cannot be read; its size is needed to adapt "
                                  "the calibration")
            try:
                g = frame_geometry(cam, img.shape[1], img.shape[0], fit=fit, frame=img, source=labels[v])
            except VisionError as exc:
                raise SourceError(str(exc)) from None
            # the sensor's size decides the working size (every view of one sensor size gets one size;
            # a letterbox crop is stretched by < 1 px to it, which fx/fy, cx/cy follow exactly)
            cw, ch = (g.crop[2], g.crop[3]) if g.fit == "crop" or not (width or max_side) else (cam.width, cam.height)
            if width and height:
                if abs(cw * height - ch * width) > 0.01 * ch * width:
                    raise SourceError(f"width, height: {width}x{height} has another aspect ratio than the "
                                      f"{cw}x{ch} image of {labels[v]}; give width only (height 0) to keep it")
                size = (int(width), int(height))
            else:
                size = working_size(cw, ch, out_width=int(width), max_side=int(max_side))
            self.geometries.append(g)
            cams.append(g.camera(*size))
        self.sizes = [(c.width, c.height) for c in cams]
        self.rig = Rig(tuple(cams), rig_name, capture_volume)
        self._pending: list[np.ndarray | None] | None = first

    def describe(self) -> list[str]:
        """One line per view: the geometry found and the published size."""
        return [f"{g.describe()} -> {w}x{h}" for g, (w, h) in zip(self.geometries, self.sizes)]

    def read(self) -> list[np.ndarray | None]:
        """The next frame set, adapted."""
        from .adapt import adapt_frame

        images = self._pending if self._pending is not None else self.source.read()
        self._pending = None
        out: list[np.ndarray | None] = []
        for v, img in enumerate(images):
            g = self.geometries[v]
            if img is not None and img.shape[:2] != (g.frame_h, g.frame_w):
                self._warn(v, f"view {v}: frame is {img.shape[1]}x{img.shape[0]}, the first was "
                              f"{g.frame_w}x{g.frame_h}; frame dropped")
                img = None
            out.append(None if img is None else adapt_frame(img, g, self.sizes[v]))
        return out
