"""Learned 2-D body keypoints: the BlazePose landmark model on a crop around the person.

Pure (no ROS): numpy + OpenCV + the LiteRT interpreter (``ai-edge-litert``, the ``keypoints`` extra).
The model file comes from :mod:`~isa_mocap_ros.vision.landmark_model`.

Model layout (read from the interpreter's input/output details of ``pose_landmark_full.tflite``,
and MediaPipe's ``pose_landmark_by_roi_cpu`` graph, which feeds it):

* input ``(1, 256, 256, 3)`` float32: an RGB crop of the region of interest scaled to 256x256
  keeping its aspect ratio (letterboxed), values in ``[0, 1]``;
* output ``(1, 195)``: 39 landmarks x ``(x, y, z, visibility, presence)``, x and y in pixels of the
  256x256 input, visibility and presence as logits (a sigmoid gives the probabilities). The first 33
  are the BlazePose topology (:data:`LANDMARK_NAMES`); 33-38 are auxiliary points MediaPipe uses to
  place the next frame's region (not used here);
* output ``(1, 1)``: the pose presence score (a probability that a person is in the crop);
* output ``(1, 256, 256, 1)``: the person segmentation of the crop as logits (:meth:`PoseLandmarker.person_probability`
  turns it into a per-pixel probability in the full image; used to find the person when estimating a background,
  :mod:`.person_masks`);
* outputs ``(1, 64, 64, 39)`` heatmaps and ``(1, 117)`` world landmarks are not used (MediaPipe refines x, y
  with the heatmap; we do not, see ``docs/keypoints.md``).

The region of interest ``(cu, cv, side, angle_rad)`` is a square around the person: the bounding box of
the foreground mask (:func:`box_from_mask`, upright) or of a predicted pose's projected joints
(:func:`box_from_points`), grown by ``scale`` (MediaPipe grows its detector box by 1.25), optionally
turned so the hip-to-shoulder direction points up in the crop (:func:`upright_angle`; MediaPipe aligns
its region the same way, and the model misses a strongly leaning body in an upright crop). Parts of
the square outside the image are black.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from .errors import VisionError
from .landmark_model import landmark_model_path

__all__ = ["LANDMARK_NAMES", "N_LANDMARKS", "INPUT_SIZE", "Landmarks2D", "PoseLandmarker", "box_from_mask",
           "box_from_points", "square_box", "upright_angle"]

INPUT_SIZE = 256
N_LANDMARKS = 33
#: The 33 BlazePose landmarks, in the model's order (MediaPipe ``pose_landmark_topology``).
LANDMARK_NAMES = (
    "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye", "right_eye_outer",
    "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder", "right_shoulder", "left_elbow",
    "right_elbow", "left_wrist", "right_wrist", "left_pinky", "right_pinky", "left_index", "right_index",
    "left_thumb", "right_thumb", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
    "left_heel", "right_heel", "left_foot_index", "right_foot_index",
)


@dataclass(frozen=True)
class Landmarks2D:
    """The 33 landmarks of one view.

    Attributes
    ----------
    uv : (33, 2) ndarray
        Pixel coordinates ``(u, v)`` in the full image (may lie outside it).
    visibility : (33,) ndarray
        Probability that the landmark is visible (not occluded), in ``[0, 1]``.
    presence : (33,) ndarray
        Probability that the landmark is inside the crop, in ``[0, 1]``.
    score : float
        Pose presence score of the crop, in ``[0, 1]``.
    roi : (4,) ndarray
        The square region ``(cu, cv, side, angle_rad)``: centre and side in pixels, rotation from upright.
    """

    uv: np.ndarray
    visibility: np.ndarray
    presence: np.ndarray
    score: float
    roi: np.ndarray

    @property
    def confidence(self) -> np.ndarray:
        """``(33,)`` ``score * visibility * presence``: the weight the keypoint energy gives each landmark."""
        return self.score * self.visibility * self.presence


def square_box(u0: float, v0: float, u1: float, v1: float, *, scale: float = 1.25) -> np.ndarray:
    """The upright square region ``(cu, cv, side, 0)`` centred on the box ``[u0, u1] x [v0, v1]``,
    side = scale x its longer edge."""
    if not all(np.isfinite([u0, v0, u1, v1])) or u1 < u0 or v1 < v0:
        raise VisionError(f"box: expected finite corners with u1 >= u0 and v1 >= v0, received {(u0, v0, u1, v1)}")
    if not np.isfinite(scale) or scale <= 0:
        raise VisionError(f"scale: expected a positive number, received {scale!r}")
    side = max(u1 - u0, v1 - v0, 1.0) * scale
    return np.array([(u0 + u1) / 2.0, (v0 + v1) / 2.0, side, 0.0])


def box_from_mask(mask: Any, *, scale: float = 1.25, min_pixels: int = 20) -> np.ndarray | None:
    """Upright square region ``(cu, cv, side, 0)`` around the foreground of ``mask`` ((H, W), nonzero =
    person); ``None`` when it has fewer than ``min_pixels`` foreground pixels."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise VisionError(f"mask: expected a 2-D array, received shape {m.shape}")
    fg = (m > 0).view(np.uint8)
    if cv2.countNonZero(fg) < min_pixels:
        return None
    # the bounding rectangle of the non-zero pixels of a one-channel 8-bit image (what findNonZero's point
    # list gives, without the list: 0.03 ms instead of 0.5-0.7 ms on a 640x480 mask)
    x, y, w, h = cv2.boundingRect(fg)
    return square_box(x, y, x + w, y + h, scale=scale)


def upright_angle(hips_uv: Any, shoulders_uv: Any) -> float:
    """Angle (radians) of the body's hip-to-shoulder direction from image up, positive when the upper
    body leans to the image's right: the rotation of the region that shows the person upright
    (as MediaPipe aligns its region of interest)."""
    d = np.asarray(shoulders_uv, dtype=np.float64) - np.asarray(hips_uv, dtype=np.float64)
    if d.shape != (2,) or not np.all(np.isfinite(d)):
        raise VisionError(f"hips_uv, shoulders_uv: expected two finite pixels, received difference {d!r}")
    return float(np.arctan2(d[0], -d[1]))


def box_from_points(uv: Any, *, scale: float = 1.25, angle_rad: float = 0.0) -> np.ndarray:
    """Square region ``(cu, cv, side, angle_rad)`` around projected points ``uv`` ((m, 2), e.g. a
    predicted pose's joints), measured in the frame turned by ``angle_rad`` (:func:`upright_angle`)."""
    p = np.asarray(uv, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) == 0:
        raise VisionError(f"uv: expected shape (m, 2) with m >= 1, received shape {p.shape}")
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) == 0:
        raise VisionError("uv: no finite point")
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    R = np.array([[c, s], [-s, c]])                 # image -> region frame: turns by -angle
    q = p @ R.T
    lo, hi = q.min(axis=0), q.max(axis=0)
    side = max(hi[0] - lo[0], hi[1] - lo[1], 1.0) * scale
    centre = R.T @ ((lo + hi) / 2.0)
    return np.array([centre[0], centre[1], side, float(angle_rad)])


def _crop_transform(roi: np.ndarray) -> np.ndarray:
    """2x3 affine image -> model input for the region ``(cu, cv, side, angle)``: q = k R(-angle)(p - c) + 128."""
    cu, cv, side, a = roi
    k = INPUT_SIZE / side
    c, s = np.cos(a), np.sin(a)
    A = k * np.array([[c, s], [-s, c]])
    return np.column_stack([A, np.array([INPUT_SIZE / 2.0, INPUT_SIZE / 2.0]) - A @ [cu, cv]])


def _check_roi(roi: Any) -> np.ndarray:
    b = np.asarray(roi, dtype=np.float64)
    if b.shape != (4,) or not np.all(np.isfinite(b)) or b[2] <= 0:
        raise VisionError(f"roi: expected (cu, cv, side, angle_rad) with a positive side, received {b.tolist()}")
    return b


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.clip(x, -60.0, 60.0)))


class PoseLandmarker:
    """Runs the BlazePose landmark model on a square crop of an image.

    Parameters
    ----------
    model_path : path, optional
        The ``.tflite`` file; default: the cached model (:func:`landmark_model_path`, which raises
        :class:`~isa_mocap_ros.vision.landmark_model.ModelUnavailable` if it is absent).
    num_threads : int
        Interpreter threads (1 keeps one core free for the energy).

    Notes
    -----
    Deterministic: the same image and region give the same landmarks. Not thread-safe (one interpreter).
    """

    def __init__(self, model_path: str | Path | None = None, *, num_threads: int = 1) -> None:
        try:
            from ai_edge_litert.interpreter import Interpreter
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise VisionError("ai-edge-litert is not installed: pip install -e '.[keypoints]'") from exc
        path = Path(model_path) if model_path is not None else landmark_model_path(check=False)
        if not path.is_file():
            raise VisionError(f"model_path: {path} is not a file")
        self.model_path = path
        self._it = Interpreter(model_path=str(path), num_threads=int(num_threads))
        self._it.allocate_tensors()
        inp = self._it.get_input_details()
        if len(inp) != 1 or tuple(inp[0]["shape"]) != (1, INPUT_SIZE, INPUT_SIZE, 3):
            raise VisionError(f"{path}: expected one (1, {INPUT_SIZE}, {INPUT_SIZE}, 3) input, received "
                              f"{[tuple(d['shape']) for d in inp]}")
        self._in = inp[0]["index"]
        by_shape = {tuple(d["shape"]): d["index"] for d in self._it.get_output_details()}
        try:
            self._out_landmarks = by_shape[(1, 195)]
            self._out_flag = by_shape[(1, 1)]
        except KeyError as exc:
            raise VisionError(f"{path}: expected outputs of shapes (1, 195) and (1, 1), received "
                              f"{sorted(by_shape)}") from exc
        self._out_segmentation = by_shape.get((1, INPUT_SIZE, INPUT_SIZE, 1))

    def crop(self, image: Any, roi: Any, *, bgr: bool = False) -> np.ndarray:
        """The model input ``(256, 256, 3)`` float32 RGB in ``[0, 1]`` for the region ``roi``."""
        img = np.asarray(image)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise VisionError(f"image: expected (H, W, 3) uint8, received shape {img.shape} dtype {img.dtype}")
        M = _crop_transform(_check_roi(roi))
        out = cv2.warpAffine(img, M, (INPUT_SIZE, INPUT_SIZE), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))
        if bgr:
            out = cv2.cvtColor(out, cv2.COLOR_BGR2RGB)
        return out.astype(np.float32) * np.float32(1.0 / 255.0)

    def run_model(self, x: np.ndarray) -> None:
        """Run the network once on a prepared input ``x`` (what :meth:`crop` returns), outputs not decoded (for
        timing the model alone)."""
        self._it.set_tensor(self._in, x[None])
        self._it.invoke()

    def detect(self, image: Any, roi: Any, *, bgr: bool = False) -> Landmarks2D:
        """Landmarks of the person in the region ``roi`` = ``(cu, cv, side, angle_rad)`` of ``image``
        ((H, W, 3) uint8, RGB unless ``bgr``)."""
        b = _check_roi(roi)
        x = self.crop(image, b, bgr=bgr)
        self._it.set_tensor(self._in, x[None])
        self._it.invoke()
        raw = self._it.get_tensor(self._out_landmarks).reshape(39, 5)[:N_LANDMARKS].astype(np.float64)
        flag = float(self._it.get_tensor(self._out_flag).ravel()[0])
        M = _crop_transform(b)
        A_inv = np.linalg.inv(M[:, :2])
        uv = (raw[:, :2] - M[:, 2]) @ A_inv.T                # back to image pixels
        return Landmarks2D(uv=uv, visibility=_sigmoid(raw[:, 3]), presence=_sigmoid(raw[:, 4]),
                           score=float(np.clip(flag, 0.0, 1.0)), roi=b)

    @property
    def has_segmentation(self) -> bool:
        """Whether the model has the person segmentation output (:meth:`person_probability`)."""
        return self._out_segmentation is not None

    def person_probability(self, image: Any, roi: Any, *, bgr: bool = False) -> tuple[np.ndarray, Landmarks2D]:
        """``(prob, landmarks)``: the model's person segmentation of the region ``roi`` as a per-pixel
        probability ``(H, W)`` float32 of the full image (0 outside the region), and :meth:`detect`'s landmarks."""
        if self._out_segmentation is None:
            raise VisionError(f"{self.model_path}: the model has no (1, {INPUT_SIZE}, {INPUT_SIZE}, 1) segmentation output")
        img = np.asarray(image)
        lm = self.detect(img, roi, bgr=bgr)
        logits = self._it.get_tensor(self._out_segmentation)[0, :, :, 0].astype(np.float32)
        full = cv2.warpAffine(logits, _crop_transform(lm.roi), (img.shape[1], img.shape[0]),
                              flags=cv2.WARP_INVERSE_MAP | cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=-60.0)
        return _sigmoid(full).astype(np.float32), lm

    def __repr__(self) -> str:
        return f"PoseLandmarker(model_path='{self.model_path}')"
