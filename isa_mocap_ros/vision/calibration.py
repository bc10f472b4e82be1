"""Calibration files and camera rigs (YAML).

Source: the monocular calibration file of ROS ``camera_calibration`` / ``camera_info_manager``
(``image_width``, ``image_height``, ``camera_name``, ``camera_matrix``, ``distortion_model``,
``distortion_coefficients``, ``rectification_matrix``, ``projection_matrix``; matrices as
``{rows, cols, data}`` row-major), extended by the world -> camera pose of DESIGN §3::

    extrinsics:
      parent_frame: world
      child_frame: cam0_optical_frame
      R: [r11, r12, r13, r21, ..., r33]   # x_cam = R x_world + t (row-major)
      t: [t1, t2, t3]

A file written here is a valid ``camera_calibration`` YAML (readers ignore the extra key).
``rectification_matrix`` and ``projection_matrix`` are written as identity and ``[K | 0]`` (a
monocular camera) and ignored on reading: the raw image geometry is ``K`` + distortion.

A rig file lists cameras with the same per-camera schema, plus an optional capture volume (an
axis-aligned box in world metres; default ``[-2, -2, 0] .. [2, 2, 2]``, the ~4 m area of both
papers' four-camera set-ups, ISA §13.4.2, EA-vs-PF §5.1)::

    rig_name: default_4cam
    capture_volume: {min: [-2, -2, 0], max: [2, 2, 2]}
    cameras:
      - image_width: 320
        ...
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .camera import Camera, look_at
from .errors import VisionError

__all__ = ["Rig", "load_camera", "save_camera", "camera_to_dict", "camera_from_dict", "load_rig", "save_rig",
           "default_rig", "ring_rig", "rig_dir", "DEFAULT_VOLUME"]

#: default capture volume (min corner, max corner), world metres
DEFAULT_VOLUME = np.array([[-2.0, -2.0, 0.0], [2.0, 2.0, 2.0]])
#: the default rig file name in ``config/rigs/``
DEFAULT_RIG_FILE = "default_4cam.yaml"


# ---------------------------------------------------------------------- per-camera dict <-> Camera
def _matrix(rows: int, cols: int, values: np.ndarray) -> dict[str, Any]:
    return {"rows": rows, "cols": cols, "data": [float(x) for x in np.asarray(values, dtype=np.float64).ravel()]}


def camera_to_dict(cam: Camera) -> dict[str, Any]:
    """The calibration-file mapping of ``cam`` (camera_calibration keys + ``extrinsics``)."""
    if not isinstance(cam, Camera):
        raise VisionError(f"cam: expected a Camera, received {type(cam).__name__}")
    P = np.hstack([cam.K, np.zeros((3, 1))])
    dist = cam.dist if cam.dist.size else np.zeros(5)
    return {
        "image_width": cam.width,
        "image_height": cam.height,
        "camera_name": cam.name,
        "camera_matrix": _matrix(3, 3, cam.K),
        "distortion_model": cam.distortion_model,
        "distortion_coefficients": _matrix(1, dist.size, dist),
        "rectification_matrix": _matrix(3, 3, np.eye(3)),
        "projection_matrix": _matrix(3, 4, P),
        "extrinsics": {
            "parent_frame": "world",
            "child_frame": f"{cam.name}_optical_frame",
            "R": [float(x) for x in cam.R.ravel()],
            "t": [float(x) for x in cam.t],
        },
    }


def _get(d: Any, key: str, where: str) -> Any:
    if not isinstance(d, dict):
        raise VisionError(f"{where}: expected a mapping, received {type(d).__name__}")
    if key not in d:
        raise VisionError(f"{where}.{key}: missing (keys present: {sorted(map(str, d))})")
    return d[key]


def _numbers(name: str, values: Any, n: int | None) -> np.ndarray:
    if not isinstance(values, (list, tuple)):
        raise VisionError(f"{name}: expected a list of numbers, received {values!r}")
    try:
        arr = np.array([float(v) for v in values], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise VisionError(f"{name}: expected a list of numbers, received {values!r}") from exc
    if n is not None and arr.size != n:
        raise VisionError(f"{name}: expected {n} numbers, received {arr.size}")
    return arr


def _read_matrix(d: dict, key: str, where: str, shape: tuple[int, int] | None) -> np.ndarray:
    m = _get(d, key, where)
    rows, cols = _get(m, "rows", f"{where}.{key}"), _get(m, "cols", f"{where}.{key}")
    data = _numbers(f"{where}.{key}.data", _get(m, "data", f"{where}.{key}"), None)
    if not isinstance(rows, int) or not isinstance(cols, int) or rows * cols != data.size:
        raise VisionError(f"{where}.{key}: expected rows*cols = len(data), received rows={rows!r}, cols={cols!r}, "
                          f"{data.size} numbers")
    if shape is not None and (rows, cols) != shape:
        raise VisionError(f"{where}.{key}: expected {shape[0]}x{shape[1]}, received {rows}x{cols}")
    return data.reshape(rows, cols)


def camera_from_dict(d: Any, *, where: str = "camera", require_extrinsics: bool = True) -> Camera:
    """A :class:`Camera` from a calibration-file mapping (see :func:`camera_to_dict`).

    With ``require_extrinsics=False`` a plain ``camera_calibration`` file (no ``extrinsics``) gives a
    camera at the world origin (``R = I``, ``t = 0``).
    """
    width = _get(d, "image_width", where)
    height = _get(d, "image_height", where)
    name = str(_get(d, "camera_name", where))
    K = _read_matrix(d, "camera_matrix", where, (3, 3))
    model = d.get("distortion_model", "plumb_bob") or "plumb_bob"
    if model not in ("plumb_bob", "rational_polynomial"):
        raise VisionError(f"{where}.distortion_model: expected 'plumb_bob' or 'rational_polynomial', "
                          f"received {model!r}")
    dist = _read_matrix(d, "distortion_coefficients", where, None).ravel() if "distortion_coefficients" in d \
        else np.zeros(5)
    if model == "rational_polynomial" and dist.size != 8:
        raise VisionError(f"{where}.distortion_coefficients: expected 8 numbers for rational_polynomial, "
                          f"received {dist.size}")
    if model == "plumb_bob" and dist.size not in (0, 4, 5):
        raise VisionError(f"{where}.distortion_coefficients: expected 0, 4 or 5 numbers for plumb_bob, "
                          f"received {dist.size}")
    if "extrinsics" in d:
        ex = d["extrinsics"]
        parent = ex.get("parent_frame", "world") if isinstance(ex, dict) else None
        if parent != "world":
            raise VisionError(f"{where}.extrinsics.parent_frame: expected 'world', received {parent!r}")
        R = _numbers(f"{where}.extrinsics.R", _get(ex, "R", f"{where}.extrinsics"), 9).reshape(3, 3)
        t = _numbers(f"{where}.extrinsics.t", _get(ex, "t", f"{where}.extrinsics"), 3)
    elif require_extrinsics:
        raise VisionError(f"{where}.extrinsics: missing (world -> camera R, t); pass require_extrinsics=False "
                          "to load a plain camera_calibration file at the origin")
    else:
        R, t = np.eye(3), np.zeros(3)
    if isinstance(width, bool) or not isinstance(width, int) or isinstance(height, bool) or not isinstance(height, int):
        raise VisionError(f"{where}.image_width/image_height: expected integers, received {width!r}, {height!r}")
    try:
        return Camera(name, width, height, K, dist, R, t)
    except VisionError as exc:
        raise VisionError(f"{where} ({name}): {exc}") from None


def _dump_yaml(data: Any) -> str:
    """YAML with flow-style number lists and floats that YAML 1.1 readers parse as floats."""

    class _Dumper(yaml.SafeDumper):
        pass

    def _list(dumper, value):
        flow = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        return dumper.represent_sequence("tag:yaml.org,2002:seq", value, flow_style=flow)

    def _float(dumper, value):
        s = repr(float(value))
        if "e" in s and "." not in s:  # '1e-05' is a string in YAML 1.1; '1.0e-05' is a float
            s = s.replace("e", ".0e")
        return dumper.represent_scalar("tag:yaml.org,2002:float", s)

    _Dumper.add_representer(list, _list)
    _Dumper.add_representer(float, _float)
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=False, width=120)


def _load_yaml(path: str | Path) -> Any:
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise VisionError(f"path: cannot read calibration file {str(p)!r}: {exc.strerror}") from exc
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise VisionError(f"path: {str(p)!r} is not valid YAML: {exc}") from exc


def load_camera(path: str | Path, *, require_extrinsics: bool = True) -> Camera:
    """Read a calibration file (camera_calibration YAML + ``extrinsics``)."""
    return camera_from_dict(_load_yaml(path), where=str(path), require_extrinsics=require_extrinsics)


def save_camera(cam: Camera, path: str | Path) -> None:
    """Write ``cam`` as a calibration file; floats are written exactly (``repr``), so loading round-trips."""
    Path(path).write_text(_dump_yaml(camera_to_dict(cam)))


# ---------------------------------------------------------------------- rigs
def _volume_points(volume: np.ndarray, n: int = 9) -> np.ndarray:
    lo, hi = volume
    g = [np.linspace(lo[i], hi[i], n if i < 2 else max(3, n // 2)) for i in range(3)]
    pts = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.vstack([(lo + hi) / 2.0, pts])


@dataclass(frozen=True, eq=False)
class Rig:
    """A set of calibrated cameras sharing the world frame.

    Parameters
    ----------
    cameras : tuple of Camera
        ``V >= 1`` cameras with distinct names.
    name : str
        Rig name.
    capture_volume : (2, 3) array_like or None
        Min and max corner of the box the cameras must look at (default :data:`DEFAULT_VOLUME`);
        a camera that sees none of it (checked on a 9x9x5 grid of the box plus its centre) raises
        :class:`VisionError`. ``None`` skips the check.
    """

    cameras: tuple[Camera, ...]
    name: str = "rig"
    capture_volume: np.ndarray | None = field(default_factory=lambda: DEFAULT_VOLUME.copy())

    def __post_init__(self) -> None:
        cams = tuple(self.cameras) if isinstance(self.cameras, (list, tuple)) else None
        if not cams:
            raise VisionError(f"cameras: expected a non-empty sequence of Camera, received {self.cameras!r}")
        for i, c in enumerate(cams):
            if not isinstance(c, Camera):
                raise VisionError(f"cameras[{i}]: expected a Camera, received {type(c).__name__}")
        names = [c.name for c in cams]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise VisionError(f"cameras: expected distinct camera names, received duplicates {dup}")
        object.__setattr__(self, "cameras", cams)
        if self.capture_volume is not None:
            vol = np.array(self.capture_volume, dtype=np.float64)
            if vol.shape != (2, 3) or not np.all(np.isfinite(vol)) or np.any(vol[1] < vol[0]):
                raise VisionError(f"capture_volume: expected [[xmin, ymin, zmin], [xmax, ymax, zmax]] with min <= max, "
                                  f"received {self.capture_volume!r}")
            vol.setflags(write=False)
            object.__setattr__(self, "capture_volume", vol)
            pts = _volume_points(vol)
            for c in cams:
                if not np.any(c.in_image(pts)):
                    raise VisionError(f"cameras[{c.name}]: sees nothing of the capture volume {vol.tolist()} "
                                      f"(centre {c.center.round(3).tolist()}, viewing direction "
                                      f"{c.R[2].round(3).tolist()})")

    def __len__(self) -> int:
        return len(self.cameras)

    def __iter__(self):
        return iter(self.cameras)

    def __getitem__(self, i: int) -> Camera:
        return self.cameras[i]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Rig):
            return NotImplemented
        va, vb = self.capture_volume, other.capture_volume
        same_vol = (va is None and vb is None) or (va is not None and vb is not None and np.array_equal(va, vb))
        return self.name == other.name and self.cameras == other.cameras and same_vol

    __hash__ = None  # type: ignore[assignment]

    def scaled(self, factor: float) -> "Rig":
        """Every camera :meth:`Camera.scaled` by ``factor``."""
        return Rig(tuple(c.scaled(factor) for c in self.cameras), self.name, self.capture_volume)

    def resized(self, width: int, height: int) -> "Rig":
        """Every camera :meth:`Camera.resized` to ``width x height``."""
        return Rig(tuple(c.resized(width, height) for c in self.cameras), self.name, self.capture_volume)


def load_rig(path: str | Path) -> Rig:
    """Read a rig file (see the module docstring). Calibration files of other tools:
    :func:`~.calib_formats.read_calibration`, which reads these too."""
    d = _load_yaml(path)
    where = str(path)
    cams_d = _get(d, "cameras", where)
    if not isinstance(cams_d, list) or not cams_d:
        raise VisionError(f"{where}.cameras: expected a non-empty list of cameras, received {cams_d!r}")
    cams = tuple(camera_from_dict(c, where=f"{where}.cameras[{i}]") for i, c in enumerate(cams_d))
    vol = DEFAULT_VOLUME
    if d.get("capture_volume") is not None:
        cv = d["capture_volume"]
        vol = np.stack([_numbers(f"{where}.capture_volume.min", _get(cv, "min", f"{where}.capture_volume"), 3),
                        _numbers(f"{where}.capture_volume.max", _get(cv, "max", f"{where}.capture_volume"), 3)])
    try:
        return Rig(cams, str(d.get("rig_name", Path(path).stem)), vol)
    except VisionError as exc:
        raise VisionError(f"{where}: {exc}") from None


def save_rig(rig: Rig, path: str | Path) -> None:
    """Write ``rig`` as a rig file."""
    if not isinstance(rig, Rig):
        raise VisionError(f"rig: expected a Rig, received {type(rig).__name__}")
    data: dict[str, Any] = {"rig_name": rig.name}
    if rig.capture_volume is not None:
        data["capture_volume"] = {"min": [float(x) for x in rig.capture_volume[0]],
                                  "max": [float(x) for x in rig.capture_volume[1]]}
    data["cameras"] = [camera_to_dict(c) for c in rig.cameras]
    Path(path).write_text(_dump_yaml(data))


def ring_rig(n_views: int, *, radius_m: float = 3.5, height_m: float = 2.5, target: Any = (0.0, 0.0, 1.0),
             fov_deg: float = 65.0, width: int = 320, height: int = 240, azimuth0_deg: float = 45.0,
             name: str | None = None) -> Rig:
    """``n_views`` cameras evenly spaced on a horizontal circle, all looking at ``target``.

    Camera ``i`` stands at azimuth ``azimuth0_deg + 360 i / n_views`` around ``target``, at horizontal
    distance ``radius_m`` and height ``height_m``; horizontal field of view ``fov_deg``.
    """
    if isinstance(n_views, bool) or not isinstance(n_views, (int, np.integer)) or n_views < 1:
        raise VisionError(f"n_views: expected a positive integer, received {n_views!r}")
    tgt = np.asarray(target, dtype=np.float64)
    cams = []
    for i in range(int(n_views)):
        a = math.radians(azimuth0_deg + 360.0 * i / n_views)
        eye = np.array([tgt[0] + radius_m * math.cos(a), tgt[1] + radius_m * math.sin(a), height_m])
        cams.append(look_at(eye, tgt, fov_deg=fov_deg, width=width, height=height, name=f"cam{i}"))
    return Rig(tuple(cams), name or f"ring_{n_views}cam")


def rig_dir() -> Path:
    """The ``config/rigs`` directory (source tree, else the installed ``share/isa_mocap_ros``)."""
    candidates = [Path(__file__).resolve().parents[2] / "config" / "rigs",
                  Path(sys.prefix) / "share" / "isa_mocap_ros" / "config" / "rigs"]
    for c in candidates:
        if (c / DEFAULT_RIG_FILE).exists():
            return c
    raise VisionError(f"rig directory: {DEFAULT_RIG_FILE} not found in {[str(c) for c in candidates]}")


def default_rig(*, n_views: int = 4, width: int = 320, height: int = 240) -> Rig:
    """The default rig of ``config/rigs/default_4cam.yaml``, resized to ``width x height``.

    Four cameras at the corners of a square around a ~4 m capture area, 2.5 m high, looking at
    ``(0, 0, 1)``. ``n_views <= 4`` takes the first ``n_views`` cameras of the file (cam0 and cam1
    are 90 degrees apart); ``n_views > 4`` builds :func:`ring_rig` with the same radius, height and
    field of view. A size with another aspect ratio than the file's scales x and y independently
    (see :meth:`Camera.resized`).
    """
    if isinstance(n_views, bool) or not isinstance(n_views, (int, np.integer)) or n_views < 1:
        raise VisionError(f"n_views: expected a positive integer, received {n_views!r}")
    for f, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise VisionError(f"{f}: expected a positive integer, received {v!r}")
    rig = load_rig(rig_dir() / DEFAULT_RIG_FILE)
    if n_views > len(rig):
        c0 = rig.cameras[0]
        target = np.array([0.0, 0.0, 1.0])
        eye = c0.center
        fov = math.degrees(2.0 * math.atan((c0.width / 2.0) / c0.fx))
        return ring_rig(n_views, radius_m=float(np.hypot(*(eye - target)[:2])), height_m=float(eye[2]),
                        target=target, fov_deg=fov, width=width, height=height, name=f"default_{n_views}cam")
    cams = tuple(c.resized(width, height) for c in rig.cameras[:n_views])
    return Rig(cams, rig.name if n_views == len(rig) else f"{rig.name}[:{n_views}]", rig.capture_volume)
