"""Video frames whose size differs from the calibrated sensor image: the matching intrinsics.

A calibration describes the sensor image (``cam.width x cam.height``). A video of the same camera may
be that image scaled (same aspect ratio), scaled and *letterboxed* (black bars filling a container of
another aspect ratio, e.g. the Pose2Sim demo's 1080x1920 files of a 1088x1920 sensor), or a centred
*crop*. Each is an affine map of pixel edges ``x' = s x + o`` (pixel centres at integer coordinates,
so a centre ``u`` goes to ``s (u + 0.5) + o - 0.5``, as ``cv2.resize`` maps them), hence

    fx' = s_x fx,   cx' = s_x (cx + 0.5) + o_x - 0.5        (likewise y)

with distortion and extrinsics unchanged (the distortion acts on normalised coordinates).

:func:`frame_geometry` decides the map: the same size, or the same aspect ratio (within 0.5 %):
``"scale"``; otherwise ``"letterbox"`` when the frame shows the black bars where a fitted image
would leave them, and an error naming the video and both sizes when it does not (``fit="crop"`` or
``fit="letterbox"`` can be given explicitly) -- never silently wrong intrinsics. A letterboxed
frame is cut to the rows/columns the image fully covers (:attr:`FrameGeometry.crop`), so every view
of a rig ends up with the geometry of its sensor. :func:`adapt_frame` applies crop and resizing to a
frame, :func:`FrameGeometry.camera` gives the camera of the result.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .camera import Camera
from .errors import VisionError

__all__ = ["FITS", "FrameGeometry", "frame_geometry", "adapt_frame", "working_size"]

#: ``fit`` values of :func:`frame_geometry`
FITS = ("auto", "scale", "letterbox", "crop")
#: aspect ratios this close (relative) count as equal
ASPECT_TOL = 0.005
#: a letterbox bar is darker than this (mean of 0..255) ...
BAR_MAX_MEAN = 25.0
#: ... and the image next to it brighter than the bar by this much
BAR_CONTRAST = 15.0


@dataclass(frozen=True)
class FrameGeometry:
    """How a ``frame_w x frame_h`` frame shows the calibrated image of ``sensor``.

    Attributes
    ----------
    fit : {"same", "scale", "letterbox", "crop"}
    scale_x, scale_y : float
        Sensor pixels -> frame pixels.
    offset_x, offset_y : float
        Frame position of the sensor image's top-left pixel edge.
    crop : (x0, y0, w, h)
        The part of the frame to keep (the whole frame unless letterboxed).
    """

    sensor: Camera
    frame_w: int
    frame_h: int
    fit: str
    scale_x: float
    scale_y: float
    offset_x: float
    offset_y: float
    crop: tuple[int, int, int, int]

    def camera(self, width: int | None = None, height: int | None = None) -> Camera:
        """The camera of the cropped frame, resized to ``width x height`` (default: the crop's size)."""
        c = self.sensor
        x0, y0, w, h = self.crop
        K = c.K.copy()
        K[0, 0] = self.scale_x * c.fx
        K[1, 1] = self.scale_y * c.fy
        K[0, 2] = self.scale_x * (c.cx + 0.5) + self.offset_x - 0.5 - x0
        K[1, 2] = self.scale_y * (c.cy + 0.5) + self.offset_y - 0.5 - y0
        cam = Camera(c.name, w, h, K, c.dist, c.R, c.t)
        if width is None:
            return cam
        return cam.resized(int(width), int(height))

    def describe(self) -> str:
        """One line: what was found and done."""
        x0, y0, w, h = self.crop
        s = f"{self.frame_w}x{self.frame_h} frame of the {self.sensor.width}x{self.sensor.height} calibration"
        if self.fit == "same":
            return s + ": same size"
        out = s + f": {self.fit}, scale {self.scale_x:.5f} x {self.scale_y:.5f}, offset ({self.offset_x:.2f}, " \
                  f"{self.offset_y:.2f}) px"
        if (w, h) != (self.frame_w, self.frame_h):
            out += f", kept {w}x{h} at ({x0}, {y0})"
        return out


def _bars_dark(frame: np.ndarray, axis: int, pad_lo: float, pad_hi: float) -> bool:
    """Does ``frame`` show black bars of ``pad_lo`` / ``pad_hi`` pixels along ``axis`` (0 rows, 1 columns)?"""
    g = frame.astype(np.float32).mean(axis=2) if frame.ndim == 3 else frame.astype(np.float32)
    prof = g.mean(axis=1 - axis)
    n = prof.size
    lo, hi = int(math.floor(pad_lo)), int(math.floor(pad_hi))
    if lo < 1 and hi < 1:
        return False
    bars = np.concatenate([prof[:max(lo, 0)], prof[n - max(hi, 0):]])
    inner = prof[int(math.ceil(pad_lo)) + 1:n - int(math.ceil(pad_hi)) - 1]
    return bool(bars.size and bars.mean() < BAR_MAX_MEAN and inner.mean() > bars.mean() + BAR_CONTRAST)


def frame_geometry(sensor: Camera, frame_w: int, frame_h: int, *, fit: str = "auto",
                   frame: np.ndarray | None = None, source: str = "video") -> FrameGeometry:
    """The map from the calibrated image of ``sensor`` to a ``frame_w x frame_h`` frame.

    Parameters
    ----------
    sensor : Camera
        The calibrated camera (its size is the sensor image's).
    frame_w, frame_h : int
        Size of the video's frames.
    fit : {"auto", "scale", "letterbox", "crop"}
        ``"auto"``: same size / same aspect ratio -> scale; another aspect ratio -> letterbox if
        ``frame`` shows the bars, else :class:`VisionError`.
    frame : (H, W[, 3]) uint8 ndarray, optional
        A frame of the video, to look for letterbox bars (required by ``"auto"`` for another aspect
        ratio).
    source : str
        Name of the video / folder, for the messages.
    """
    if fit not in FITS:
        raise VisionError(f"fit: expected one of {FITS}, received {fit!r}")
    W, H = sensor.width, sensor.height
    fw, fh = int(frame_w), int(frame_h)
    if fw < 1 or fh < 1:
        raise VisionError(f"{source}: frame size {fw}x{fh} is empty")
    whole = (0, 0, fw, fh)
    if (fw, fh) == (W, H) and fit in ("auto", "scale"):
        return FrameGeometry(sensor, fw, fh, "same", 1.0, 1.0, 0.0, 0.0, whole)
    same_aspect = abs(fw * H - fh * W) <= ASPECT_TOL * fh * W
    if fit == "scale" or (fit == "auto" and same_aspect):
        if not same_aspect:
            raise VisionError(f"{source} ({sensor.name}): fit 'scale' needs the calibration's aspect ratio; the "
                              f"frames are {fw}x{fh}, the calibration {W}x{H}")
        return FrameGeometry(sensor, fw, fh, "scale", fw / W, fh / H, 0.0, 0.0, whole)
    s_fit, s_fill = min(fw / W, fh / H), max(fw / W, fh / H)
    if fit == "crop":
        s = s_fill
        return FrameGeometry(sensor, fw, fh, "crop", s, s, (fw - s * W) / 2, (fh - s * H) / 2, whole)
    s = s_fit
    ox, oy = (fw - s * W) / 2, (fh - s * H) / 2
    if fit == "auto":
        if frame is None:
            raise VisionError(f"{source} ({sensor.name}): frames are {fw}x{fh}, the calibration {W}x{H} (another "
                              "aspect ratio); give a frame to look for letterbox bars, or fit='letterbox'/'crop'")
        axis = 0 if oy > ox else 1
        if frame.shape[:2] != (fh, fw) or not _bars_dark(frame, axis, oy if axis == 0 else ox, oy if axis == 0 else ox):
            raise VisionError(f"{source} ({sensor.name}): frames are {fw}x{fh}, the calibration {W}x{H} (another "
                              "aspect ratio) and show no black letterbox bars; say how the video was made with "
                              "fit 'crop' (a centred cut) or 'letterbox' (scaled to fit, padded)")
    x0, y0 = int(math.ceil(ox - 1e-9)), int(math.ceil(oy - 1e-9))
    x1, y1 = int(math.floor(ox + s * W + 1e-9)), int(math.floor(oy + s * H + 1e-9))
    return FrameGeometry(sensor, fw, fh, "letterbox", s, s, ox, oy, (x0, y0, x1 - x0, y1 - y0))


def working_size(width: int, height: int, *, out_width: int = 0, max_side: int = 0) -> tuple[int, int]:
    """The size an image of ``width x height`` is resized to: ``out_width`` wide, or its longer side
    ``max_side`` (0 and 0: unchanged); the aspect ratio is kept (rounded)."""
    if out_width and max_side:
        raise VisionError("width, max_side: give one of them, not both")
    if out_width:
        f = out_width / width
    elif max_side:
        f = max_side / max(width, height)
    else:
        return width, height
    return max(1, int(round(width * f))), max(1, int(round(height * f)))


def adapt_frame(frame: np.ndarray, geom: FrameGeometry, size: tuple[int, int] | None = None) -> np.ndarray:
    """``frame`` cut to ``geom.crop`` and resized to ``size = (w, h)`` (``INTER_AREA`` shrinking)."""
    if frame.shape[:2] != (geom.frame_h, geom.frame_w):
        raise VisionError(f"frame: expected {geom.frame_w}x{geom.frame_h} (the video's size), received "
                          f"{frame.shape[1]}x{frame.shape[0]}")
    x0, y0, w, h = geom.crop
    out = frame[y0:y0 + h, x0:x0 + w]
    if size is not None and tuple(size) != (w, h):
        interp = cv2.INTER_AREA if size[0] < w else cv2.INTER_LINEAR
        out = cv2.resize(out, tuple(int(v) for v in size), interpolation=interp)
    return np.ascontiguousarray(out)
