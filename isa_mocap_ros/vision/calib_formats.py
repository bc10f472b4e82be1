"""Calibration files of other tools, to and from a :class:`~isa_mocap_ros.vision.calibration.Rig`.

Formats (``FORMATS``; :func:`detect_format` picks one from the name and the first bytes):

``rig``
    The project's rig YAML (:func:`~.calibration.load_rig`; ``docs/vision.md``).
``toml``
    Pose2Sim / anipose / caliscope TOML: one ``[section]`` per camera with ``name``, ``size = [w, h]``,
    ``matrix`` (3x3 K), ``distortions = [k1, k2, p1, p2]``, ``rotation`` (a Rodrigues vector) and
    ``translation`` (metres), world -> camera (``x_cam = R x_world + t``, OpenCV's camera frame);
    ``fisheye`` must be false; a ``[metadata]`` section is ignored.
``qualisys``
    Qualisys QTM ``.qca.txt`` (XML): per ``<camera serial=...>`` the ``<fov_video>`` rectangle (image
    size), ``<intrinsic>`` in sensor sub-pixel units (64 per pixel: ``sensorMaxU = 64 (width - 1)``), and
    ``<transform>`` (camera position in mm and rotation ``r11..r33``). Measured on the Pose2Sim demo
    (docs/vision.md, "Calibration files of other tools"): the rows of ``r`` are the camera's axes with y
    up and z backwards, so ``R = diag(1, -1, -1) r`` in OpenCV's camera frame; the distortion values
    (``radialDistortion1..3``, ``tangentalDistortion1..2``) are OpenCV's ``k1 k2 k3 p1 p2`` as written,
    *not* divided by 64 (the checkerboard's reprojection error says so, see the docs).
``opencv``
    OpenCV ``FileStorage`` YAML (``%YAML:1.0``) or XML: either one camera at the top level or one
    mapping per camera, each with ``camera_matrix`` (or ``K``), ``distortion_coefficients`` (or ``D``),
    ``R`` (3x3, or a Rodrigues 3-vector ``rvec``), ``T`` (or ``tvec``; metres), ``image_width`` and
    ``image_height`` (or ``image_size = [w, h]``). A camera without ``R``/``T`` sits at the origin.
``camera_info``
    ROS ``camera_calibration`` YAML (``image_width``, ``camera_matrix: {rows, cols, data}``, ...), one
    camera per file; the project's own per-camera file is this plus ``extrinsics``. Without
    ``extrinsics`` the camera sits at the world origin (intrinsics only).

Round trips: the matrix formats (rig, opencv, camera_info) write floats with ``repr``, so
rig -> file -> rig is bit exact; ``toml`` stores a Rodrigues vector and ``qualisys`` a position in mm,
so their rotation / translation come back to within floating-point rounding (~1e-15).

Every error is a :class:`VisionError` whose message starts with the file and names the camera and
field, e.g. ``Calib.toml: [cam01] matrix: expected 3x3 numbers, received [[1, 0], ...]``.
"""
from __future__ import annotations

import math
import re
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np

from .calibration import DEFAULT_VOLUME, Rig, _dump_yaml, camera_from_dict, camera_to_dict, load_rig, save_rig
from .camera import Camera
from .errors import VisionError

__all__ = ["FORMATS", "detect_format", "read_calibration", "write_calibration", "format_rig"]

FORMATS = ("rig", "toml", "qualisys", "opencv", "camera_info")
#: Qualisys sensor sub-pixels per image pixel
QUALISYS_SUBPIXELS = 64.0
#: Qualisys camera axes (x right, y up, z backwards) -> OpenCV's (x right, y down, z forwards)
_QTM_TO_CV = np.diag([1.0, -1.0, -1.0])


class _Err:
    """Builds the ``file: [camera] field: ...`` messages."""

    def __init__(self, path: str | Path) -> None:
        self.file = str(path)

    def __call__(self, msg: str, camera: str | None = None) -> VisionError:
        return VisionError(f"{self.file}: " + (f"[{camera}] " if camera else "") + msg)


# ------------------------------------------------------------------------------------ detection
def detect_format(path: str | Path) -> str:
    """The format of a calibration file (one of :data:`FORMATS`), from its name and first bytes."""
    p = Path(path)
    err = _Err(p)
    try:
        head = p.read_bytes()[:4096].decode("utf-8", errors="replace")
    except OSError as exc:
        raise err(f"cannot read calibration file: {exc.strerror}") from None
    name = p.name.lower()
    if name.endswith(".toml"):
        return "toml"
    if name.endswith(".qca.txt") or "<calibration" in head and "<cameras" in head:
        return "qualisys"
    if head.lstrip().startswith("%YAML") or "<opencv_storage>" in head:
        return "opencv"
    if name.endswith((".yaml", ".yml")):
        return "rig" if "cameras:" in head else "camera_info"
    if name.endswith(".xml"):
        return "opencv"
    raise err(f"unknown calibration format; expected one of {', '.join(FORMATS)} (.toml, .qca.txt, "
              "OpenCV %YAML:1.0 / <opencv_storage> XML, .yaml)")


def read_calibration(paths: str | Path | Sequence[str | Path], *, fmt: str = "auto",
                     capture_volume: Any = "default", name: str | None = None) -> Rig:
    """A rig from one calibration file (any of :data:`FORMATS`) or several single-camera files.

    Parameters
    ----------
    paths : path or sequence of paths
        One file, or one ``camera_info``/``opencv`` file per camera (cameras in the given order).
    fmt : str
        ``"auto"`` (:func:`detect_format`) or one of :data:`FORMATS`.
    capture_volume : (2, 3) array_like, None or "default"
        Box every camera must see (:class:`Rig`); ``"default"`` keeps a rig file's own box, else
        :data:`DEFAULT_VOLUME`; None switches the check off.
    name : str, optional
        Rig name (default: the first file's stem).
    """
    many = [paths] if isinstance(paths, (str, Path)) else list(paths)
    if not many:
        raise VisionError("paths: expected at least one calibration file, received none")
    cams: list[Camera] = []
    vol = DEFAULT_VOLUME
    for p in many:
        p = Path(p)
        if not p.is_file():
            raise VisionError(f"{p}: calibration file does not exist")
        f = detect_format(p) if fmt == "auto" else fmt
        if f not in FORMATS:
            raise VisionError(f"fmt: expected 'auto' or one of {FORMATS}, received {fmt!r}")
        if f == "rig":
            rig = load_rig(p) if capture_volume == "default" else None
            if rig is None:
                rig = _load_rig_unchecked(p)
            elif rig.capture_volume is not None:
                vol = rig.capture_volume
            cams += rig.cameras
        else:
            cams += _READERS[f](p)
    stem = Path(many[0]).name.split(".")[0]
    volume = vol if isinstance(capture_volume, str) and capture_volume == "default" else capture_volume
    names = [c.name for c in cams]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise VisionError(f"{', '.join(map(str, many))}: camera names {dup} appear twice; give each camera "
                          "its own name")
    try:
        return Rig(tuple(cams), name or stem, volume)
    except VisionError as exc:
        raise VisionError(f"{', '.join(map(str, many))}: {exc}") from None


def _load_rig_unchecked(path: Path) -> Rig:
    from .calibration import _get, _load_yaml

    d = _load_yaml(path)
    cams = _get(d, "cameras", str(path))
    return Rig(tuple(camera_from_dict(c, where=f"{path}.cameras[{i}]") for i, c in enumerate(cams)),
               str(d.get("rig_name", path.stem)), None)


def write_calibration(rig: Rig, path: str | Path, *, fmt: str = "auto") -> None:
    """Write ``rig`` in ``fmt`` (``"auto"``: from the file name, ``.yaml`` = the project's rig file).

    ``camera_info`` writes one file per camera: ``path`` must then contain ``{name}`` (replaced by the
    camera name), or the rig must have one camera.
    """
    if not isinstance(rig, Rig):
        raise VisionError(f"rig: expected a Rig, received {type(rig).__name__}")
    p = Path(path)
    if fmt == "auto":
        n = p.name.lower()
        fmt = ("toml" if n.endswith(".toml") else "qualisys" if n.endswith(".qca.txt") else
               "opencv" if n.endswith(".xml") else "rig" if n.endswith((".yaml", ".yml")) else "")
        if not fmt:
            raise VisionError(f"{p}: cannot tell the format from the name; pass one of {FORMATS}")
    if fmt not in FORMATS:
        raise VisionError(f"fmt: expected 'auto' or one of {FORMATS}, received {fmt!r}")
    if fmt == "rig":
        save_rig(rig, p)
    elif fmt == "camera_info":
        if "{name}" not in str(p) and len(rig) != 1:
            raise VisionError(f"{p}: camera_info holds one camera; put '{{name}}' in the path to write "
                              f"{len(rig)} files")
        for c in rig.cameras:
            Path(str(p).replace("{name}", c.name)).write_text(_dump_yaml(camera_to_dict(c)))
    elif fmt == "opencv":
        _write_opencv(rig, p)
    else:
        p.write_text(_WRITERS[fmt](rig))


# ------------------------------------------------------------------------------------ helpers
def _nums(err: _Err, cam: str, field: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        arr = None
    if arr is None or arr.shape != shape:
        want = "x".join(map(str, shape))
        raise err(f"{field}: expected {want} numbers, received {value!r}", cam)
    if not np.all(np.isfinite(arr)):
        raise err(f"{field}: expected finite numbers, received {value!r}", cam)
    return arr


def _size(err: _Err, cam: str, field: str, value: Any) -> tuple[int, int]:
    s = _nums(err, cam, field, value, (2,))
    if np.any(s != np.round(s)) or np.any(s < 1):
        raise err(f"{field}: expected [width, height] as whole numbers >= 1, received {value!r}", cam)
    return int(s[0]), int(s[1])


def _camera(err: _Err, cam: str, width: int, height: int, K, dist, R, t) -> Camera:
    try:
        return Camera(cam, width, height, K, dist, R, t)
    except VisionError as exc:
        field = str(exc).split(":", 1)[0]
        field = {"K": "camera matrix", "R": "rotation", "t": "translation", "dist": "distortion"}.get(field, field)
        raise err(f"{field}: {exc}", cam) from None


def _rodrigues(rvec: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))[0]


def _rvec(R: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0].ravel()


def _f(x: float) -> str:
    """A float as TOML/XML text that reads back to the same double."""
    return repr(float(x))


# ------------------------------------------------------------------------------------ TOML
def _read_toml(path: Path) -> list[Camera]:
    err = _Err(path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise err(f"not valid TOML: {exc}") from None
    cams = []
    for key, sec in data.items():
        if key == "metadata" or not isinstance(sec, dict):
            continue
        name = str(sec.get("name", key))
        for field in ("size", "matrix", "distortions", "rotation", "translation"):
            if field not in sec:
                raise err(f"{field}: missing (keys present: {sorted(sec)})", name)
        if sec.get("fisheye", False):
            raise err("fisheye: expected false (the fisheye model is not supported), received true", name)
        w, h = _size(err, name, "size", sec["size"])
        K = _nums(err, name, "matrix", sec["matrix"], (3, 3))
        dist = np.array(sec["distortions"], dtype=object)
        if dist.ndim != 1 or dist.size not in (4, 5, 8):
            raise err(f"distortions: expected 4, 5 or 8 numbers (k1 k2 p1 p2 [k3 ...]), received "
                      f"{sec['distortions']!r}", name)
        dist = _nums(err, name, "distortions", sec["distortions"], (dist.size,))
        rvec = _nums(err, name, "rotation", sec["rotation"], (3,))
        t = _nums(err, name, "translation", sec["translation"], (3,))
        cams.append(_camera(err, name, w, h, K, dist, _rodrigues(rvec), t))
    if not cams:
        raise err("no camera sections found (expected [name] tables with size, matrix, distortions, "
                  "rotation, translation)")
    return cams


def _toml_str(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _write_toml(rig: Rig) -> str:
    out = []
    for c in rig.cameras:
        K = c.K
        d = c.dist if c.dist.size else np.zeros(4)
        key = c.name if re.fullmatch(r"[A-Za-z0-9_-]+", c.name) else _toml_str(c.name)
        out.append(f"[{key}]\n"
                   f"name = {_toml_str(c.name)}\n"
                   f"size = [ {_f(c.width)}, {_f(c.height)}]\n"
                   "matrix = [ " + ", ".join("[ " + ", ".join(_f(v) for v in row) + "]" for row in K) + "]\n"
                   "distortions = [ " + ", ".join(_f(v) for v in d) + "]\n"
                   "rotation = [ " + ", ".join(_f(v) for v in _rvec(c.R)) + "]\n"
                   "translation = [ " + ", ".join(_f(v) for v in c.t) + "]\n"
                   "fisheye = false\n")
    out.append("[metadata]\nadjusted = false\nerror = 0.0\n")
    return "\n".join(out)


# ------------------------------------------------------------------------------------ Qualisys
def _attrs(err: _Err, el: ET.Element | None, tag: str, names: Sequence[str], cam: str) -> dict[str, float]:
    if el is None:
        raise err(f"<{tag}>: missing", cam)
    out = {}
    for n in names:
        if n not in el.attrib:
            raise err(f"<{tag}> {n}: missing (attributes present: {sorted(el.attrib)})", cam)
        try:
            out[n] = float(el.attrib[n])
        except ValueError:
            raise err(f"<{tag}> {n}: expected a number, received {el.attrib[n]!r}", cam) from None
        if not math.isfinite(out[n]):
            raise err(f"<{tag}> {n}: expected a finite number, received {el.attrib[n]!r}", cam)
    return out


def _read_qualisys(path: Path) -> list[Camera]:
    err = _Err(path)
    try:
        root = ET.fromstring(path.read_bytes())
    except ET.ParseError as exc:
        raise err(f"not valid XML: {exc}") from None
    cams_el = root.find("cameras")
    if cams_el is None or not cams_el.findall("camera"):
        raise err("<cameras>: expected <camera> elements under <calibration><cameras>")
    cams = []
    for i, el in enumerate(cams_el.findall("camera")):
        name = el.attrib.get("serial") or f"cam{i}"
        if el.attrib.get("active", "1") == "0":
            continue
        fov = _attrs(err, el.find("fov_video"), "fov_video", ("left", "top", "right", "bottom"), name)
        w, h = int(fov["right"] - fov["left"] + 1), int(fov["bottom"] - fov["top"] + 1)
        if w < 1 or h < 1:
            raise err(f"<fov_video>: expected right >= left and bottom >= top, received {fov}", name)
        it = _attrs(err, el.find("intrinsic"), "intrinsic",
                    ("focalLengthU", "focalLengthV", "centerPointU", "centerPointV", "radialDistortion1",
                     "radialDistortion2", "radialDistortion3", "tangentalDistortion1", "tangentalDistortion2"),
                    name)
        s = QUALISYS_SUBPIXELS
        K = np.array([[it["focalLengthU"] / s, 0.0, it["centerPointU"] / s - fov["left"]],
                      [0.0, it["focalLengthV"] / s, it["centerPointV"] / s - fov["top"]], [0.0, 0.0, 1.0]])
        dist = np.array([it["radialDistortion1"], it["radialDistortion2"], it["tangentalDistortion1"],
                         it["tangentalDistortion2"], it["radialDistortion3"]])
        tr = _attrs(err, el.find("transform"), "transform",
                    ("x", "y", "z") + tuple(f"r{a}{b}" for a in "123" for b in "123"), name)
        r = np.array([[tr[f"r{a}{b}"] for b in "123"] for a in "123"])
        R = _QTM_TO_CV @ r
        C = np.array([tr["x"], tr["y"], tr["z"]]) / 1000.0
        cams.append(_camera(err, name, w, h, K, dist, R, -R @ C))
    return cams


def _write_qualisys(rig: Rig) -> str:
    s = QUALISYS_SUBPIXELS
    lines = ["<?xml version='1.0' encoding='ASCII'?>",
             f'<calibration created="isa_mocap_ros" source="{rig.name}" type="regular">',
             "  <cameras>"]
    for c in rig.cameras:
        d = np.zeros(5)
        d[:min(5, c.dist.size)] = c.dist[:5]
        if c.dist.size == 8 and np.any(c.dist[5:]):
            raise VisionError(f"[{c.name}] dist: Qualisys holds k1 k2 k3 p1 p2 only; this camera has "
                              f"rational coefficients {c.dist[5:].tolist()}")
        r = _QTM_TO_CV @ c.R
        C = c.center * 1000.0
        rs = " ".join(f'r{a + 1}{b + 1}="{_f(r[a, b])}"' for a in range(3) for b in range(3))
        lines += [f'    <camera active="1" serial="{c.name}" viewrotation="0">',
                  f'      <fov_video left="0" top="0" right="{c.width - 1}" bottom="{c.height - 1}"/>',
                  f'      <transform x="{_f(C[0])}" y="{_f(C[1])}" z="{_f(C[2])}" {rs}/>',
                  f'      <intrinsic focalLengthU="{_f(c.fx * s)}" focalLengthV="{_f(c.fy * s)}" '
                  f'centerPointU="{_f(c.cx * s)}" centerPointV="{_f(c.cy * s)}" '
                  f'sensorMinU="0" sensorMaxU="{_f((c.width - 1) * s)}" sensorMinV="0" '
                  f'sensorMaxV="{_f((c.height - 1) * s)}" skew="0" '
                  f'radialDistortion1="{_f(d[0])}" radialDistortion2="{_f(d[1])}" radialDistortion3="{_f(d[4])}" '
                  f'tangentalDistortion1="{_f(d[2])}" tangentalDistortion2="{_f(d[3])}"/>',
                  "    </camera>"]
    lines += ["  </cameras>", "</calibration>", ""]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------ OpenCV FileStorage
_K_KEYS = ("camera_matrix", "cameraMatrix", "K", "intrinsic_matrix")
_D_KEYS = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "D", "dist")


def _fs_value(node: "cv2.FileNode") -> Any:
    if node.isMap():
        if set(node.keys()) >= {"rows", "cols", "data"}:   # an opencv-matrix
            return node.mat()
        return {k: _fs_value(node.getNode(k)) for k in node.keys()}
    if node.isSeq():
        return [_fs_value(node.at(i)) for i in range(node.size())]
    if node.isInt():
        return int(node.real())
    if node.isReal():
        return float(node.real())
    if node.isString():
        return node.string()
    mat = node.mat()
    return mat if mat is not None else None


def _opencv_camera(err: _Err, name: str, d: dict) -> Camera:
    def first(keys):
        for k in keys:
            if k in d and d[k] is not None:
                return d[k]
        return None

    K = first(_K_KEYS)
    if K is None:
        raise err(f"camera_matrix: missing (keys present: {sorted(d)})", name)
    K = _nums(err, name, "camera_matrix", K, (3, 3))
    D = first(_D_KEYS)
    D = np.zeros(5) if D is None else np.asarray(D, dtype=np.float64).ravel()
    if D.size not in (0, 4, 5, 8):
        raise err(f"distortion_coefficients: expected 4, 5 or 8 numbers, received {D.size}", name)
    if "image_size" in d:
        w, h = _size(err, name, "image_size", np.asarray(d["image_size"], dtype=np.float64).ravel().tolist())
    else:
        for k in ("image_width", "image_height"):
            if k not in d:
                raise err(f"{k}: missing (or give image_size = [w, h])", name)
        w, h = _size(err, name, "image_width/image_height", [d["image_width"], d["image_height"]])
    Rv = first(("R", "rotation", "rvec"))
    T = first(("T", "t", "tvec", "translation"))
    if Rv is None or T is None:
        R, t = np.eye(3), np.zeros(3)
    else:
        Rv = np.asarray(Rv, dtype=np.float64)
        R = _rodrigues(_nums(err, name, "rvec", Rv.ravel(), (3,))) if Rv.size == 3 else _nums(err, name, "R", Rv, (3, 3))
        t = _nums(err, name, "T", np.asarray(T, dtype=np.float64).ravel(), (3,))
    return _camera(err, name, w, h, K, D, R, t)


def _read_opencv(path: Path) -> list[Camera]:
    err = _Err(path)
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_FORMAT_AUTO)
    except cv2.error as exc:
        raise err(f"OpenCV cannot parse the FileStorage file: {str(exc).strip().splitlines()[-1]}") from None
    if not fs.isOpened():
        raise err("OpenCV cannot open it as a FileStorage file")
    try:
        root = _fs_value(fs.root())
    finally:
        fs.release()
    if not isinstance(root, dict):
        raise err("expected a mapping at the top level")
    if any(k in root for k in _K_KEYS):
        return [_opencv_camera(err, str(root.get("camera_name", path.stem.split(".")[0])), root)]
    cams = [_opencv_camera(err, str(v.get("camera_name", k)), v) for k, v in root.items() if isinstance(v, dict)]
    if not cams:
        raise err(f"no camera found (expected camera_matrix at the top level or in per-camera mappings; keys: "
                  f"{sorted(root)})")
    return cams


def _write_opencv(rig: Rig, path: Path) -> None:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    try:
        for c in rig.cameras:
            fs.startWriteStruct(c.name, cv2.FileNode_MAP)
            fs.write("camera_name", c.name)
            fs.write("image_width", c.width)
            fs.write("image_height", c.height)
            fs.write("camera_matrix", np.ascontiguousarray(c.K))
            fs.write("distortion_coefficients", np.ascontiguousarray(c.dist.reshape(1, -1) if c.dist.size
                                                                     else np.zeros((1, 5))))
            fs.write("R", np.ascontiguousarray(c.R))
            fs.write("T", np.ascontiguousarray(c.t.reshape(3, 1)))
            fs.endWriteStruct()
    finally:
        fs.release()


# ------------------------------------------------------------------------------------ camera_info
def _read_camera_info(path: Path) -> list[Camera]:
    from .calibration import _load_yaml

    d = _load_yaml(path)
    if not isinstance(d, dict):
        raise VisionError(f"{path}: expected a camera_calibration mapping, received {type(d).__name__}")
    return [camera_from_dict(d, where=str(path), require_extrinsics=False)]


_READERS = {"toml": _read_toml, "qualisys": _read_qualisys, "opencv": _read_opencv,
            "camera_info": _read_camera_info}
_WRITERS = {"toml": _write_toml, "qualisys": _write_qualisys}


# ------------------------------------------------------------------------------------ summary
def format_rig(rig: Rig) -> str:
    """A human-readable summary: per camera size, fx fy cx cy, distortion, centre (m), viewing direction,
    horizontal field of view."""
    lines = [f"rig {rig.name!r}: {len(rig)} cameras" + (
        f", capture volume {rig.capture_volume.tolist()}" if rig.capture_volume is not None else "")]
    for c in rig.cameras:
        fov = math.degrees(2 * math.atan(c.width / 2 / c.fx))
        lines.append(f"  {c.name}: {c.width}x{c.height}, fx {c.fx:.2f} fy {c.fy:.2f} cx {c.cx:.2f} cy {c.cy:.2f} "
                     f"(hfov {fov:.1f} deg), dist {np.round(c.dist, 5).tolist()}, centre "
                     f"{np.round(c.center, 3).tolist()} m, looks along {np.round(c.R[2], 3).tolist()}")
    return "\n".join(lines)
