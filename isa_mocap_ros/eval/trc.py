"""TRC marker files (OpenSim / Pose2Sim 3-D results): read, write, and map their axes to our world.

A TRC file is tab-separated text: a ``PathFileType`` line, a header of ``DataRate CameraRate
NumFrames NumMarkers Units OrigDataRate OrigDataStartFrame OrigNumFrames`` and its values, a line
``Frame# Time <marker> \\t\\t <marker> ...``, a line ``X1 Y1 Z1 X2 ...``, then one row per frame
(frame number, time in s, x y z per marker; an empty field is a missing value, NaN here).

OpenSim's (and so Pose2Sim's) TRC axes are y-up. Pose2Sim writes its triangulation, done in the
calibration's z-up world, with ``zup2yup``: TRC ``(X, Y, Z) = (y, z, x)`` of the world point, so
``world = (Z, X, Y)`` of the TRC point (:data:`TRC_TO_WORLD`). Checked on the Pose2Sim demo by
projecting the points into the four calibrated views (``docs/real_cameras.md``).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["TrcError", "Trc", "read_trc", "write_trc", "TRC_TO_WORLD", "UNITS_TO_M", "POSE2SIM_TO_JOINTS",
           "joint_names_of"]

#: world = TRC_TO_WORLD @ trc for Pose2Sim's y-up TRC files (world x = TRC Z, y = TRC X, z = TRC Y)
TRC_TO_WORLD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
#: metres per TRC unit
UNITS_TO_M = {"m": 1.0, "mm": 1e-3, "cm": 1e-2}

#: Pose2Sim keypoint name (its HALPE_26 / BODY_25 skeletons' names, as in its TRC files) -> the joint of our
#: body models (``BodyModel.joint_names``) the keypoint is scored against. Keypoints are 2-D detector
#: outputs triangulated, not joint centres: a keypoint sits at a roughly constant offset from the joint
#: (the scorer reports the error with each joint's mean offset removed as well). ``Neck`` is the
#: detector's point between the shoulders (our ``neck``: the base of the neck); ``Head`` its point on
#: the head (our ``head``: the centre of the head). Toes, heels, the nose and the
#: mid-hip ``Hip`` have no marker joint in our models and are not scored.
POSE2SIM_TO_JOINTS = {
    "RHip": "right_hip", "RKnee": "right_knee", "RAnkle": "right_ankle",
    "LHip": "left_hip", "LKnee": "left_knee", "LAnkle": "left_ankle",
    "RShoulder": "right_shoulder", "RElbow": "right_elbow", "RWrist": "right_wrist",
    "LShoulder": "left_shoulder", "LElbow": "left_elbow", "LWrist": "left_wrist",
    "Neck": "neck", "Head": "head",
}


def joint_names_of(marker_names, name_map: dict | None = None) -> tuple[str, ...]:
    """The reference's marker names mapped to our joint names (:data:`POSE2SIM_TO_JOINTS` by default);
    a name the map does not know is kept as it is (and so matches no joint of ours unless it is one)."""
    m = POSE2SIM_TO_JOINTS if name_map is None else name_map
    return tuple(m.get(str(n), str(n)) for n in marker_names)


class TrcError(ValueError):
    """A malformed TRC file (the message names the file, the line and the field)."""


@dataclass(frozen=True, eq=False)
class Trc:
    """Markers of a TRC file.

    Attributes
    ----------
    names : tuple of str
        Marker names, in file order.
    times_s : (F,) ndarray
    points : (F, M, 3) ndarray
        Positions in **metres**, the file's axes (NaN = missing).
    rate_hz : float
        ``DataRate``.
    """

    names: tuple[str, ...]
    times_s: np.ndarray
    points: np.ndarray
    rate_hz: float

    def in_world(self, axes: np.ndarray = TRC_TO_WORLD) -> np.ndarray:
        """``(F, M, 3)`` points in the calibration's world (``axes @ p``; default Pose2Sim's y-up map)."""
        return self.points @ np.asarray(axes, dtype=np.float64).T


def read_trc(path: str | Path) -> Trc:
    """Read a TRC file; coordinates are converted to metres from its ``Units`` (m, cm, mm)."""
    p = Path(path)
    try:
        lines = p.read_text(errors="replace").splitlines()
    except OSError as exc:
        raise TrcError(f"{p}: cannot read: {exc.strerror}") from None
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise TrcError(f"{p}: line 1: expected 'PathFileType ...' (a TRC file), received {lines[0][:40]!r}"
                       if lines else f"{p}: empty file")
    keys, vals = lines[1].split("\t"), lines[2].split("\t")
    head = dict(zip([k.strip() for k in keys], [v.strip() for v in vals]))
    for k in ("DataRate", "NumFrames", "NumMarkers", "Units"):
        if k not in head:
            raise TrcError(f"{p}: line 2-3: {k} missing from the header (fields: {sorted(head)})")
    try:
        rate, n_markers = float(head["DataRate"]), int(head["NumMarkers"])
    except ValueError:
        raise TrcError(f"{p}: line 3: DataRate / NumMarkers: expected numbers, received "
                       f"{head['DataRate']!r}, {head['NumMarkers']!r}") from None
    units = head["Units"]
    if units not in UNITS_TO_M:
        raise TrcError(f"{p}: line 3: Units: expected one of {sorted(UNITS_TO_M)}, received {units!r}")
    names = tuple(n.strip() for n in lines[3].split("\t")[2:] if n.strip())
    if len(names) != n_markers:
        raise TrcError(f"{p}: line 4: expected NumMarkers = {n_markers} marker names, received {len(names)}")
    rows = []
    for i, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        f = line.split("\t")
        if len(f) < 2 + 3 * n_markers:
            f = f + [""] * (2 + 3 * n_markers - len(f))
        try:
            rows.append([float(x) if x.strip() else np.nan for x in f[1:2 + 3 * n_markers]])
        except ValueError:
            raise TrcError(f"{p}: line {i}: expected numbers, received {line[:60]!r}") from None
    if not rows:
        raise TrcError(f"{p}: no data rows")
    a = np.array(rows, dtype=np.float64)
    pts = a[:, 1:].reshape(len(a), n_markers, 3) * UNITS_TO_M[units]
    return Trc(names, a[:, 0], pts, rate)


def write_trc(path: str | Path, trc: Trc, *, units: str = "m") -> None:
    """Write ``trc`` (points in metres) as a TRC file in ``units``; :func:`read_trc` reads it back."""
    if units not in UNITS_TO_M:
        raise TrcError(f"units: expected one of {sorted(UNITS_TO_M)}, received {units!r}")
    F, M, _ = trc.points.shape
    out = [f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
           "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
           f"{trc.rate_hz!r}\t{trc.rate_hz!r}\t{F}\t{M}\t{units}\t{trc.rate_hz!r}\t0\t{F}",
           "Frame#\tTime\t" + "\t\t\t".join(trc.names) + "\t\t",
           "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, M + 1))]
    scale = 1.0 / UNITS_TO_M[units]
    for k in range(F):
        vals = [("" if np.isnan(v) else repr(float(v * scale))) for v in trc.points[k].ravel()]
        out.append(f"{k + 1}\t{float(trc.times_s[k])!r}\t" + "\t".join(vals))
    Path(path).write_text("\n".join(out) + "\n")
