"""Pinhole cameras with lens distortion, ``look_at`` and batch projection.

Source: the pinhole model with the Brown-Conrady ("plumb_bob") and rational lens distortion as
implemented by OpenCV ``cv2.projectPoints`` and described by REP-104 / ``sensor_msgs/CameraInfo``;
the extrinsic convention of DESIGN §3: a world point ``X`` maps to the camera optical frame
(z forward, x right, y down) by ``x_cam = R X + t``. The ISA paper (§13.4.2) and the EA-vs-PF
paper (§3.1) both use four calibrated views of this kind.

Projection of ``x_cam = (X, Y, Z)`` (OpenCV, pixel centres at integer coordinates)::

    x, y   = X / Z, Y / Z,                 r2 = x^2 + y^2
    radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
    x'     = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
    y'     = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
    u, v   = fx x' + cx,  fy y' + cy

``dist`` holds ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])`` (lengths 0, 4, 5 or 8; missing
coefficients are zero). Points with ``Z <= 0`` are projected by the same formula (as OpenCV does);
use :meth:`Camera.depth` to discard them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

from .errors import VisionError

__all__ = ["Camera", "PixelAreas", "look_at", "project_batch", "as_points", "DIST_LENGTHS"]

#: accepted lengths of the distortion vector (0 = none, plumb_bob 4/5, rational_polynomial 8)
DIST_LENGTHS = (0, 4, 5, 8)
_ORTHO_TOL = 1e-6


def as_points(P: Any, *, name: str = "P") -> np.ndarray:
    """``P`` as a float64 array of shape ``(..., 3)``; VisionError naming ``name`` otherwise."""
    try:
        arr = np.asarray(P, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise VisionError(f"{name}: expected a numeric array of shape (..., 3), received {P!r}") from exc
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise VisionError(f"{name}: expected shape (..., 3), received shape {arr.shape}")
    return arr


def _array(name: str, value: Any, shape: tuple[int, ...] | None) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise VisionError(f"{name}: expected a numeric array, received {value!r}") from exc
    if shape is not None and arr.shape != shape:
        raise VisionError(f"{name}: expected shape {shape}, received shape {arr.shape}")
    arr.setflags(write=False)
    return arr


def _dist8(dist: np.ndarray) -> np.ndarray:
    """The distortion vector padded to ``(k1, k2, p1, p2, k3, k4, k5, k6)``."""
    out = np.zeros(8)
    out[: dist.size] = dist
    return out


def _distort(x: np.ndarray, y: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalized undistorted ``(x, y)`` -> distorted normalized coordinates (OpenCV model)."""
    k1, k2, p1, p2, k3, k4, k5, k6 = d
    r2 = x * x + y * y
    radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def _undistort(xd: np.ndarray, yd: np.ndarray, d: np.ndarray, *, n_iter: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Invert :func:`_distort` by Newton's method (finite-difference 2x2 Jacobian), vectorized.

    Each point stops on its own, at the first iterate whose residual ``|rx| + |ry|`` is below 1e-14 (or
    after ``n_iter`` steps): a point's result does not depend on the other points of its batch, so a
    per-pixel table built once gives the same bits as undistorting the pixels a frame needs."""
    x, y = np.array(xd, dtype=np.float64), np.array(yd, dtype=np.float64)     # copies (0-d for a scalar)
    xf, yf = x.reshape(-1), y.reshape(-1)          # views of the copies: updated in place
    xdf, ydf = x.reshape(-1).copy(), y.reshape(-1).copy()
    idx = np.arange(xf.size)                       # the points still iterating
    h = 1e-7
    for _ in range(n_iter):
        xa, ya = xf[idx], yf[idx]
        fx, fy = _distort(xa, ya, d)
        rx, ry = fx - xdf[idx], fy - ydf[idx]
        go = ~(np.abs(rx) + np.abs(ry) < 1e-14)    # not converged (NaN: never converges, as before)
        if not go.any():
            break
        if not go.all():
            idx, xa, ya, fx, fy, rx, ry = idx[go], xa[go], ya[go], fx[go], fy[go], rx[go], ry[go]
        ax, ay = _distort(xa + h, ya, d)
        bx, by = _distort(xa, ya + h, d)
        j11, j21 = (ax - fx) / h, (ay - fy) / h
        j12, j22 = (bx - fx) / h, (by - fy) / h
        det = j11 * j22 - j12 * j21
        det = np.where(np.abs(det) < 1e-12, 1e-12, det)
        xf[idx] = xa - (j22 * rx - j12 * ry) / det
        yf[idx] = ya - (-j21 * rx + j11 * ry) / det
    return (x[()], y[()]) if x.ndim == 0 else (x, y)


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated pinhole camera with lens distortion and world->camera extrinsics.

    Parameters
    ----------
    name : str
        Camera name (``camera_name`` in the calibration file, e.g. ``"cam0"``).
    width, height : int
        Image size in pixels (> 0).
    K : (3, 3) array_like
        ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` with fx, fy > 0 (no skew: OpenCV's projection
        ignores it, so it is rejected rather than silently dropped).
    dist : (n,) array_like
        ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])``, n in {0, 4, 5, 8}; zeros = no distortion.
    R : (3, 3) array_like
        World -> camera rotation (orthonormal, det +1).
    t : (3,) array_like
        World -> camera translation: ``x_cam = R @ x_world + t``.

    All arrays are stored as read-only float64 copies; :meth:`validate` runs on construction and
    raises :class:`VisionError` naming the bad field. Cameras compare equal when all fields are equal.
    """

    name: str
    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise VisionError(f"name: expected a non-empty string, received {self.name!r}")
        for f in ("width", "height"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
                raise VisionError(f"{f}: expected a positive integer, received {v!r}")
            object.__setattr__(self, f, int(v))
        object.__setattr__(self, "K", _array("K", self.K, (3, 3)))
        dist = _array("dist", self.dist, None).ravel()
        if dist.size not in DIST_LENGTHS:
            raise VisionError(f"dist: expected {DIST_LENGTHS} coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6]]), "
                              f"received {dist.size}")
        dist.setflags(write=False)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "R", _array("R", self.R, (3, 3)))
        object.__setattr__(self, "t", _array("t", self.t, (3,)))
        self.validate()

    # ------------------------------------------------------------------ checks, equality
    def validate(self) -> None:
        """Check the numbers; raise :class:`VisionError` naming the field otherwise."""
        K, R = self.K, self.R
        if not np.all(np.isfinite(K)):
            raise VisionError(f"K: expected finite numbers, received {K.tolist()}")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise VisionError(f"K: expected fx = K[0,0] > 0 and fy = K[1,1] > 0, received fx={K[0, 0]}, fy={K[1, 1]}")
        if K[0, 1] != 0 or K[1, 0] != 0 or not np.array_equal(K[2], [0.0, 0.0, 1.0]):
            raise VisionError(f"K: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], received {K.tolist()}")
        if not np.all(np.isfinite(self.dist)):
            raise VisionError(f"dist: expected finite numbers, received {self.dist.tolist()}")
        if not np.all(np.isfinite(R)):
            raise VisionError(f"R: expected finite numbers, received {R.tolist()}")
        err = float(np.abs(R.T @ R - np.eye(3)).max())
        if err > _ORTHO_TOL:
            raise VisionError(f"R: expected an orthonormal rotation (|R^T R - I| <= {_ORTHO_TOL}), "
                              f"received max deviation {err:.3g} (det {np.linalg.det(R):.3g})")
        if np.linalg.det(R) < 0:
            raise VisionError(f"R: expected det(R) = +1 (a rotation), received det {np.linalg.det(R):.3g} "
                              "(a reflection)")
        if not np.all(np.isfinite(self.t)):
            raise VisionError(f"t: expected finite numbers, received {self.t.tolist()}")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Camera):
            return NotImplemented
        return (self.name == other.name and self.width == other.width and self.height == other.height
                and np.array_equal(self.K, other.K) and np.array_equal(_dist8(self.dist), _dist8(other.dist))
                and np.array_equal(self.R, other.R) and np.array_equal(self.t, other.t))

    __hash__ = None  # type: ignore[assignment]

    def key(self) -> bytes:
        """Bytes identifying the geometry (size, K, dist, R, t): a cache key for per-camera data (made once: the
        camera is frozen and its arrays read-only; the renderer, gate and hull ask for it ~50 times a frame)."""
        k = self.__dict__.get("_key")
        if k is None:
            k = (np.array([self.width, self.height], dtype=np.int64).tobytes() + self.K.tobytes()
                 + _dist8(self.dist).tobytes() + self.R.tobytes() + self.t.tobytes())
            object.__setattr__(self, "_key", k)
        return k

    # ------------------------------------------------------------------ properties
    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates, ``-R^T t``."""
        return -self.R.T @ self.t

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def distortion_model(self) -> str:
        """``"plumb_bob"`` (0, 4 or 5 coefficients) or ``"rational_polynomial"`` (8)."""
        return "rational_polynomial" if self.dist.size == 8 else "plumb_bob"

    @property
    def has_distortion(self) -> bool:
        """Whether any distortion coefficient is non-zero (made once: the camera is frozen and its arrays
        read-only; the contour stage, hull filter and mask undistortion ask ~25 times a frame)."""
        d = self.__dict__.get("_has_distortion")
        if d is None:
            d = bool(np.any(self.dist != 0))
            object.__setattr__(self, "_has_distortion", d)
        return d

    # ------------------------------------------------------------------ ROS views (CameraInfo, TF)
    def intrinsics_fields(self) -> dict[str, Any]:
        """The numbers of a ``sensor_msgs/CameraInfo``: keys ``K, D, P, R, width, height, distortion_model``.

        ``msg_adapters.camera_info.Intrinsics(**cam.intrinsics_fields())`` builds the adapter's value
        (the core does not import ``msg_adapters``). ``D`` has 5 entries for ``plumb_bob``, 8 for
        ``rational_polynomial``; ``R`` is the identity and ``P = [K | 0]`` (a monocular camera).
        """
        D = _dist8(self.dist)[: 8 if self.dist.size == 8 else 5].copy()
        return {"K": self.K.copy(), "D": D, "P": np.hstack([self.K, np.zeros((3, 1))]), "R": np.eye(3),
                "width": self.width, "height": self.height, "distortion_model": self.distortion_model}

    def pose_in_world(self) -> tuple[np.ndarray, np.ndarray]:
        """``(R_wc, t_wc)``: the camera optical frame in the world, ``x_world = R_wc x_cam + t_wc``.

        This is the ``TransformStamped`` with ``header.frame_id = world`` and ``child_frame_id =
        <name>_optical_frame`` (tf convention: the child's pose in the parent): ``R_wc = R^T``,
        ``t_wc = -R^T t`` (the camera centre).
        """
        return self.R.T.copy(), self.center

    @classmethod
    def from_intrinsics_and_pose(cls, name: str, *, K: Any, D: Any, width: int, height: int, R_wc: Any,
                                 t_wc: Any) -> "Camera":
        """Inverse of :meth:`intrinsics_fields` + :meth:`pose_in_world` (e.g. from CameraInfo + TF)."""
        R_wc = _array("R_wc", R_wc, (3, 3))
        t_wc = _array("t_wc", t_wc, (3,))
        return cls(name, width, height, K, D, R_wc.T, -R_wc.T @ t_wc)

    # ------------------------------------------------------------------ geometry
    def to_camera(self, P: Any) -> np.ndarray:
        """World points ``(..., 3)`` -> camera optical frame ``(..., 3)``: ``R P + t``."""
        P = as_points(P)
        return P @ self.R.T + self.t

    def depth(self, P: Any) -> np.ndarray:
        """``(...,)`` z of world points ``(..., 3)`` in the camera frame (> 0 in front)."""
        P = as_points(P)
        return P @ self.R[2] + self.t[2]

    def project(self, P: Any) -> np.ndarray:
        """Pixels ``(..., 2)`` of world points ``(..., 3)``, with lens distortion (= ``cv2.projectPoints``)."""
        Xc = self.to_camera(P)
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = Xc[..., 0] / z, Xc[..., 1] / z
        if self.has_distortion:
            x, y = _distort(x, y, _dist8(self.dist))
        return np.stack([self.fx * x + self.cx, self.fy * y + self.cy], axis=-1)

    def undistort_pixels(self, u: Any, v: Any) -> tuple[np.ndarray, np.ndarray]:
        """Normalized undistorted image coordinates ``(x, y)`` of pixels ``(u, v)`` (Newton inverse)."""
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        xd, yd = (u - self.cx) / self.fx, (v - self.cy) / self.fy
        if not self.has_distortion:
            return xd, yd
        return _undistort(xd, yd, _dist8(self.dist))

    def ray(self, u: Any, v: Any) -> tuple[np.ndarray, np.ndarray]:
        """World ray through pixel ``(u, v)`` (scalars or arrays of one shape ``S``).

        Returns
        -------
        origin : (3,) ndarray
            The camera centre.
        direction : (*S, 3) ndarray
            Unit direction in world coordinates, lens distortion removed: the ray through
            ``(u, v)`` contains every world point that :meth:`project` maps to ``(u, v)``.
        """
        x, y = self.undistort_pixels(u, v)
        d_cam = np.stack([x, y, np.ones_like(x)], axis=-1)
        d = d_cam @ self.R  # R^T d_cam, row vectors
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return self.center, d

    def scaled(self, factor: float) -> "Camera":
        """The same camera for an image resized by ``factor`` (e.g. 0.5 for a 2x downsampled mask).

        The new size is ``round(width * factor) x round(height * factor)``; with the actual ratios
        ``sx, sy`` the intrinsics become ``fx' = sx fx``, ``cx' = sx (cx + 0.5) - 0.5`` (pixel centres
        at integer coordinates, as ``cv2.resize`` maps them), likewise for y. Distortion and
        extrinsics are unchanged.
        """
        try:
            f = float(factor)
        except (TypeError, ValueError) as exc:
            raise VisionError(f"factor: expected a positive number, received {factor!r}") from exc
        if not np.isfinite(f) or f <= 0:
            raise VisionError(f"factor: expected a positive finite number, received {factor!r}")
        w, h = int(round(self.width * f)), int(round(self.height * f))
        if w < 1 or h < 1:
            raise VisionError(f"factor: {f} makes a {self.width}x{self.height} image empty ({w}x{h})")
        return self.resized(w, h)

    def resized(self, width: int, height: int) -> "Camera":
        """The same camera for the image resized to ``width x height`` (see :meth:`scaled`)."""
        if (width, height) == (self.width, self.height):
            return self
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0, 0] *= sx
        K[1, 1] *= sy
        K[0, 2] = sx * (self.cx + 0.5) - 0.5
        K[1, 2] = sy * (self.cy + 0.5) - 0.5
        return Camera(self.name, int(width), int(height), K, self.dist, self.R, self.t)

    def in_image(self, P: Any, *, margin: float = 0.0) -> np.ndarray:
        """``(...,)`` bool: world points in front of the camera that project into the image."""
        uv = self.project(P)
        z = self.depth(P)
        with np.errstate(invalid="ignore"):
            return ((z > 0) & (uv[..., 0] >= -0.5 - margin) & (uv[..., 0] <= self.width - 0.5 + margin)
                    & (uv[..., 1] >= -0.5 - margin) & (uv[..., 1] <= self.height - 0.5 + margin))

    def __repr__(self) -> str:
        c = self.center
        return (f"Camera({self.name!r}, {self.width}x{self.height}, fx={self.fx:.1f}, fy={self.fy:.1f}, "
                f"centre=({c[0]:.2f}, {c[1]:.2f}, {c[2]:.2f}))")


class PixelAreas:
    """The area of each pixel of ``camera`` in its normalized undistorted image plane, kept once computed.

    A pixel's area is ``|det J|`` of the undistortion at its centre, by central differences of ±0.5 px (its
    four neighbouring half-pixel points undistorted, :meth:`Camera.undistort_pixels`). The silhouette energy
    needs the summed area of every foreground pixel on every frame; with lens distortion that undistorted each
    pixel four times per frame (~0.66 s per 4-view set at the real recording's size). Here each pixel is
    computed the first time a frame asks for it and kept in a ``(height, width)`` table (NaN = not yet), so a
    frame pays only for pixels no frame before it had. The same bits as computing them every time (each
    point's Newton iteration stops on its own, :func:`_undistort`).

    Examples
    --------
    >>> cam = look_at([3.0, 0.0, 1.0], [0.0, 0.0, 1.0], fov_deg=60, width=64, height=48)
    >>> areas = PixelAreas(cam)
    >>> a = areas.of(np.array([10, 11]), np.array([5, 5]))
    >>> bool(np.allclose(a, 1.0 / (cam.fx * cam.fy)))
    True
    """

    def __init__(self, camera: "Camera") -> None:
        self.camera = camera
        self._table: np.ndarray | None = None

    def of(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``(n,)`` areas of the pixels ``(u[i], v[i])`` (integer columns and rows inside the image)."""
        u, v = np.asarray(u), np.asarray(v)
        if self._table is None:
            self._table = np.full((self.camera.height, self.camera.width), np.nan)
        a = self._table[v, u]
        miss = np.flatnonzero(np.isnan(a))
        if miss.size:
            uf, vf = u[miss].astype(float), v[miss].astype(float)
            cam = self.camera
            xu0, yu0 = cam.undistort_pixels(uf - 0.5, vf)
            xu1, yu1 = cam.undistort_pixels(uf + 0.5, vf)
            xv0, yv0 = cam.undistort_pixels(uf, vf - 0.5)
            xv1, yv1 = cam.undistort_pixels(uf, vf + 0.5)
            a[miss] = np.abs((xu1 - xu0) * (yv1 - yv0) - (xv1 - xv0) * (yu1 - yu0))
            self._table[v[miss], u[miss]] = a[miss]
        return a


def look_at(eye: Any, target: Any, *, up: Any = (0.0, 0.0, 1.0), K: Any = None, fov_deg: float | None = None,
            width: int = 320, height: int = 240, name: str = "cam", dist: Any = None) -> Camera:
    """A camera at ``eye`` looking at ``target`` with the image's "up" towards ``up``.

    Parameters
    ----------
    eye, target : (3,) array_like
        Camera centre and the world point that projects to the principal point.
    up : (3,) array_like, optional
        World up direction (default +z, REP-103); must not be parallel to ``target - eye``.
    K : (3, 3) array_like, optional
        Intrinsics; exclusive with ``fov_deg``.
    fov_deg : float, optional
        Horizontal field of view in degrees (default 60 when ``K`` is not given): ``fx = fy =
        (width / 2) / tan(fov / 2)``, principal point at the image centre ``((w-1)/2, (h-1)/2)``.
    width, height : int
        Image size in pixels.
    name : str
        Camera name.
    dist : (n,) array_like, optional
        Distortion coefficients (default none).

    Returns
    -------
    Camera
        Optical frame rows ``R = [right; down; forward]``, ``t = -R eye``.
    """
    eye = _array("eye", eye, (3,))
    target = _array("target", target, (3,))
    up = _array("up", up, (3,))
    fwd = target - eye
    n = np.linalg.norm(fwd)
    if not np.isfinite(n) or n < 1e-9:
        raise VisionError(f"target: expected a point distinct from eye {eye.tolist()}, received {target.tolist()}")
    fwd = fwd / n
    right = np.cross(fwd, up)
    nr = np.linalg.norm(right)
    if nr < 1e-9 * max(1.0, np.linalg.norm(up)):
        raise VisionError(f"up: expected a direction not parallel to the viewing direction {fwd.tolist()}, "
                          f"received {up.tolist()}")
    right /= nr
    down = np.cross(fwd, right)
    R = np.stack([right, down, fwd])
    if K is not None and fov_deg is not None:
        raise VisionError("K, fov_deg: expected at most one of them, received both")
    if K is None:
        fov = 60.0 if fov_deg is None else float(fov_deg)
        if not 0.0 < fov < 180.0:
            raise VisionError(f"fov_deg: expected 0 < fov_deg < 180, received {fov_deg!r}")
        f = (width / 2.0) / np.tan(np.radians(fov) / 2.0)
        K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    return Camera(name, width, height, K, np.zeros(5) if dist is None else dist, R, -R @ eye)


# ---------------------------------------------------------------------- batch projection
@numba.njit(parallel=True, cache=True, fastmath=False)
def _project_batch_kernel(Rs, ts, Ks, Ds, P, out):  # pragma: no cover - compiled
    V = Rs.shape[0]
    n, m = P.shape[0], P.shape[1]
    for i in numba.prange(n):
        for v in range(V):
            R, t, d = Rs[v], ts[v], Ds[v]
            fx, fy, cx, cy = Ks[v, 0, 0], Ks[v, 1, 1], Ks[v, 0, 2], Ks[v, 1, 2]
            has_d = False
            for q in range(8):
                if d[q] != 0.0:
                    has_d = True
            for k in range(m):
                X, Y, Z = P[i, k, 0], P[i, k, 1], P[i, k, 2]
                xc = R[0, 0] * X + R[0, 1] * Y + R[0, 2] * Z + t[0]
                yc = R[1, 0] * X + R[1, 1] * Y + R[1, 2] * Z + t[1]
                zc = R[2, 0] * X + R[2, 1] * Y + R[2, 2] * Z + t[2]
                x = xc / zc
                y = yc / zc
                if has_d:
                    r2 = x * x + y * y
                    radial = ((1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4])))
                              / (1.0 + r2 * (d[5] + r2 * (d[6] + r2 * d[7]))))
                    xd = x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x)
                    yd = y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y
                    x, y = xd, yd
                out[v, i, k, 0] = fx * x + cx
                out[v, i, k, 1] = fy * y + cy


def project_batch(cams: Any, P: Any) -> np.ndarray:
    """Project a batch of point sets into several cameras at once (numba, parallel over sets).

    Parameters
    ----------
    cams : sequence of Camera, or a Rig
        ``V`` cameras.
    P : (n, K, 3) array_like
        ``n`` sets (e.g. one per particle) of ``K`` world points.

    Returns
    -------
    uv : (V, n, K, 2) float64
        Pixels, identical (to rounding) to ``cams[v].project(P)``.
    """
    cams = tuple(getattr(cams, "cameras", cams))
    if not cams or not all(isinstance(c, Camera) for c in cams):
        raise VisionError(f"cams: expected a non-empty sequence of Camera, received {cams!r}")
    P = np.ascontiguousarray(as_points(P), dtype=np.float64)
    if P.ndim != 3:
        raise VisionError(f"P: expected shape (n, K, 3), received shape {P.shape}")
    # C order throughout: one compiled signature whatever the cameras' own layout (a calibration file's R may be
    # Fortran-ordered: a second version loaded on the first real frame, after the estimator's warm-up)
    Rs, ts, Ks, Ds = (np.ascontiguousarray(np.stack(a), dtype=np.float64) for a in (
        [c.R for c in cams], [c.t for c in cams], [c.K for c in cams], [_dist8(c.dist) for c in cams]))
    out = np.empty((len(cams), P.shape[0], P.shape[1], 2))
    if P.size:
        _project_batch_kernel(Rs, ts, Ks, Ds, P, out)
    return out
