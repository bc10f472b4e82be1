"""Intrinsic calibration from checkerboard or ChArUco images (OpenCV; Zhang's method).

Source: issue 34 item 2. :func:`find_checkerboard` detects the inner corners on a copy downscaled
to at most ``detect_max_side`` pixels (fast on phone-size images; ``cv2.findChessboardCorners``,
then the sector-based ``cv2.findChessboardCornersSB`` when the first fails) and refines them with
``cv2.cornerSubPix`` on the full-resolution image. :func:`calibrate_intrinsics` runs
``cv2.calibrateCamera`` on every image where the board was found, with the OpenCV model
``k1 k2 p1 p2`` (``k3`` fixed at 0 unless ``k3=True``: a few board views cannot pin it down), and
reports the RMS reprojection error and the error per image. ``board = (a, b)`` counts *inner*
corners (Pose2Sim's ``intrinsics_corners_nb = [4, 7]``); the square size only scales the board
poses, not the intrinsics.

ChArUco boards (:func:`find_charuco`) use ``cv2.aruco.CharucoDetector``; ``board`` then counts
squares, and the marker side is ``marker_ratio`` times the square.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from .camera import Camera
from .errors import VisionError

__all__ = ["BoardView", "IntrinsicsResult", "find_checkerboard", "find_charuco", "calibrate_intrinsics",
           "board_points"]


@dataclass(frozen=True)
class BoardView:
    """Board corners found in one image: ``image_points (n, 2)`` pixels, ``object_points (n, 3)`` mm."""

    path: str
    image_points: np.ndarray
    object_points: np.ndarray


@dataclass(frozen=True)
class IntrinsicsResult:
    """Outcome of :func:`calibrate_intrinsics`.

    Attributes
    ----------
    camera : Camera
        ``K`` and ``dist`` (``k1 k2 p1 p2 k3``) at ``width x height``, at the world origin.
    rms_px : float
        RMS reprojection error over all corners (OpenCV's return value).
    per_image_px : dict[str, float]
        RMS error per used image.
    used, rejected : tuple of str
        Images where the board was / was not found.
    """

    camera: Camera
    rms_px: float
    per_image_px: dict[str, float] = field(default_factory=dict)
    used: tuple[str, ...] = ()
    rejected: tuple[str, ...] = ()


def board_points(board: tuple[int, int], square_mm: float) -> np.ndarray:
    """``(a*b, 3)`` inner-corner positions of a checkerboard in its plane (mm), OpenCV's corner order."""
    a, b = board
    g = np.zeros((a * b, 3), np.float32)
    g[:, :2] = np.mgrid[0:a, 0:b].T.reshape(-1, 2) * float(square_mm)
    return g


def _read_grey(path: str | Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise VisionError(f"{path}: OpenCV cannot read this image")
    return img


def _check_board(board) -> tuple[int, int]:
    try:
        a, b = (int(v) for v in board)
    except (TypeError, ValueError):
        raise VisionError(f"board: expected two integers (inner corners, e.g. 4x7), received {board!r}") from None
    if a < 2 or b < 2:
        raise VisionError(f"board: expected at least 2x2 inner corners, received {a}x{b}")
    return a, b


def find_checkerboard(image: np.ndarray, board: tuple[int, int], *, detect_max_side: int = 1000) -> np.ndarray | None:
    """Inner corners ``(a*b, 2)`` of a checkerboard in a grey image (full-resolution pixels), or None."""
    a, b = _check_board(board)
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    s = min(1.0, detect_max_side / max(grey.shape))
    small = grey if s == 1.0 else cv2.resize(grey, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, c = cv2.findChessboardCorners(small, (a, b), flags)
    if not ok:
        ok, c = cv2.findChessboardCornersSB(small, (a, b), cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok:
        return None
    c = ((c.reshape(-1, 2) + 0.5) / s - 0.5).astype(np.float32).reshape(-1, 1, 2)
    win = max(3, int(round(3 / s)))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    c = cv2.cornerSubPix(grey, c, (win, win), (-1, -1), crit)
    return c.reshape(-1, 2)


def find_charuco(image: np.ndarray, board: tuple[int, int], square_mm: float, *, marker_ratio: float = 0.75,
                 dictionary: str = "DICT_4X4_50") -> tuple[np.ndarray, np.ndarray] | None:
    """ChArUco corners ``(n, 2)`` and their board positions ``(n, 3)`` mm (``board`` = squares), or None."""
    a, b = _check_board(board)
    if not hasattr(cv2, "aruco"):
        raise VisionError("charuco: this OpenCV build has no aruco module")
    if not hasattr(cv2.aruco, dictionary):
        raise VisionError(f"dictionary: expected an OpenCV aruco dictionary name (e.g. DICT_4X4_50), "
                          f"received {dictionary!r}")
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    cb = cv2.aruco.CharucoBoard((a, b), float(square_mm), float(square_mm) * marker_ratio, d)
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(cb).detectBoard(grey)
    if ids is None or len(ids) < 6:
        return None
    obj = cb.getChessboardCorners()[ids.ravel()]
    return corners.reshape(-1, 2).astype(np.float32), np.asarray(obj, np.float32).reshape(-1, 3)


def calibrate_intrinsics(images: Sequence[str | Path], *, board: tuple[int, int], square_mm: float,
                         charuco: str | None = None, k3: bool = False, detect_max_side: int = 1000,
                         name: str = "cam0") -> IntrinsicsResult:
    """Calibrate one camera from images of a board.

    Parameters
    ----------
    images : sequence of paths
        Board images of one camera, all the same size.
    board : (int, int)
        Inner corners of a checkerboard (ChArUco: squares).
    square_mm : float
        Side of a square.
    charuco : str, optional
        An aruco dictionary name (e.g. ``"DICT_4X4_50"``) for a ChArUco board.
    k3 : bool
        Also estimate the radial ``k3``.

    Raises
    ------
    VisionError
        Unreadable image, images of different sizes, or fewer than 3 images with the board.
    """
    if not square_mm > 0:
        raise VisionError(f"square_mm: expected a size > 0, received {square_mm!r}")
    board = _check_board(board)
    views: list[BoardView] = []
    rejected: list[str] = []
    size = None
    for p in images:
        grey = _read_grey(p)
        if size is None:
            size = grey.shape[::-1]
        elif grey.shape[::-1] != size:
            raise VisionError(f"{p}: image is {grey.shape[1]}x{grey.shape[0]}, the first was {size[0]}x{size[1]}; "
                              "calibrate one camera (one image size) at a time")
        if charuco:
            found = find_charuco(grey, board, square_mm, dictionary=charuco)
            if found is None:
                rejected.append(str(p))
                continue
            views.append(BoardView(str(p), *found))
        else:
            c = find_checkerboard(grey, board, detect_max_side=detect_max_side)
            if c is None:
                rejected.append(str(p))
                continue
            views.append(BoardView(str(p), c, board_points(board, square_mm)))
    if len(views) < 3:
        raise VisionError(f"images: the board ({board[0]}x{board[1]}) was found in {len(views)} of {len(images)} "
                          f"images; at least 3 are needed (not found in: {rejected[:5]})")
    flags = 0 if k3 else cv2.CALIB_FIX_K3
    obj = [v.object_points for v in views]
    img = [v.image_points.reshape(-1, 1, 2) for v in views]
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, size, None, None, flags=flags)
    per = {}
    for v, rv, tv in zip(views, rvecs, tvecs):
        proj, _ = cv2.projectPoints(v.object_points, rv, tv, K, dist)
        per[v.path] = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - v.image_points) ** 2, axis=1))))
    K = np.array(K, dtype=np.float64)
    K[0, 1] = 0.0
    cam = Camera(name, int(size[0]), int(size[1]), K, np.asarray(dist, np.float64).ravel()[:5])
    return IntrinsicsResult(cam, float(rms), per, tuple(v.path for v in views), tuple(rejected))
