"""Draw an estimated body on a camera image (for ``/mocap/cam<i>/overlay`` and run reports).

Pure OpenCV: the model's capsules are projected with the camera and drawn as thick bones with
joint dots; the silhouette mask, when given, is tinted underneath so fit errors are visible.
"""
from __future__ import annotations

import cv2
import numpy as np

from .camera import Camera


def draw_overlay(image: np.ndarray, camera: Camera, endpoints: np.ndarray, radii: np.ndarray, *,
                 mask: np.ndarray | None = None, color=(40, 255, 40)) -> np.ndarray:
    """Return a copy of ``image`` (H, W, 3) RGB with the capsules ``endpoints (C, 2, 3)`` drawn.

    Bone thickness follows the projected mean radius; points behind the camera are skipped.
    """
    img = np.ascontiguousarray(image[..., :3] if image.ndim == 3 else np.repeat(image[..., None], 3, 2)).copy()
    if mask is not None and mask.shape[:2] == img.shape[:2]:
        fg = mask > 0
        img[fg] = (0.6 * img[fg] + 0.4 * np.array([255, 60, 200])).astype(np.uint8)
    E = np.asarray(endpoints, dtype=float).reshape(-1, 2, 3)
    depth = camera.depth(E.reshape(-1, 3)).reshape(-1, 2)
    uv = camera.project(E.reshape(-1, 3)).reshape(-1, 2, 2)
    r = np.asarray(radii, dtype=float).reshape(-1, 2).mean(axis=1)
    for c in range(E.shape[0]):
        if np.any(depth[c] <= 0.05) or not np.all(np.isfinite(uv[c])):
            continue
        thick = int(np.clip(camera.fx * r[c] / depth[c].mean(), 1, 40))
        p0 = tuple(int(round(v)) for v in uv[c, 0])
        p1 = tuple(int(round(v)) for v in uv[c, 1])
        cv2.line(img, p0, p1, color, max(1, thick // 2), cv2.LINE_AA)
        cv2.circle(img, p0, max(2, thick // 3), (255, 255, 0), -1, cv2.LINE_AA)
        cv2.circle(img, p1, max(2, thick // 3), (255, 255, 0), -1, cv2.LINE_AA)
    return img


def overlay_row(images, cameras, endpoints: np.ndarray, radii: np.ndarray, *, masks=None,
                label: str = "") -> np.ndarray:
    """All views of one frame side by side (RGB), the model drawn on each (:func:`draw_overlay`), the
    mask tinted underneath; ``label`` (and the view's name) written in each tile's corner. Views
    without an image are black tiles of the first image's size."""
    tiles = []
    ref = next((im for im in images if im is not None), None)
    if ref is None:
        raise ValueError("images: expected at least one view with an image, received none")
    H = ref.shape[0]
    for v, (img, cam) in enumerate(zip(images, cameras)):
        if img is None:
            t = np.zeros((H, ref.shape[1], 3), np.uint8)
        else:
            m = None if masks is None else masks[v]
            t = draw_overlay(img, cam, endpoints, radii, mask=m)
            if t.shape[0] != H:
                t = cv2.resize(t, (int(round(t.shape[1] * H / t.shape[0])), H), interpolation=cv2.INTER_AREA)
        txt = f"{cam.name} {label}".strip()
        cv2.putText(t, txt, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(t, txt, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(t)
    return np.concatenate(tiles, axis=1)


def write_strip(path, rows) -> None:
    """Rows of :func:`overlay_row` stacked into one PNG (rows of unequal width are padded)."""
    from pathlib import Path

    W = max(r.shape[1] for r in rows)
    padded = [r if r.shape[1] == W else np.pad(r, ((0, 0), (0, W - r.shape[1]), (0, 0))) for r in rows]
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(np.concatenate(padded, axis=0), cv2.COLOR_RGB2BGR)):
        raise OSError(f"{path}: cannot write the PNG")


class VideoStrip:
    """Write :func:`overlay_row` images as the frames of an MP4 (OpenCV's ``mp4v``), size set by the first row."""

    def __init__(self, path, fps: float) -> None:
        from pathlib import Path

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fps = float(fps)
        self._w = None
        self.frames = 0

    def add(self, row: np.ndarray) -> None:
        if self._w is None:
            h, w = row.shape[:2]
            self._size = (w - w % 2, h - h % 2)
            self._w = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, self._size)
            if not self._w.isOpened():
                raise OSError(f"{self.path}: OpenCV cannot open an mp4v video writer")
        self._w.write(cv2.cvtColor(np.ascontiguousarray(row[:self._size[1], :self._size[0]]), cv2.COLOR_RGB2BGR))
        self.frames += 1

    def close(self) -> None:
        if self._w is not None:
            self._w.release()
            self._w = None
