"""BVH motion files: parsing (any channel order and hierarchy), unit detection, world positions,
resampling.

Source format: Biovision Hierarchy (HIERARCHY with ROOT/JOINT/End Site, OFFSET, CHANNELS; MOTION
with ``Frames:``, ``Frame Time:`` and one line of channel values per frame). Conventions used here:

* A joint's local transform is ``Trans(t) · R_c1 R_c2 R_c3`` with the rotation channels in the
  order listed (degrees, intrinsic), and ``t = OFFSET`` unless the joint has position channels, in
  which case ``t`` is the channel values (they replace the offset, as exporters that write 6
  channels per joint assume). End sites become joints named ``<parent>_end`` without channels.
* Lengths are scaled to metres: ``scale`` given, or detected from the rest skeleton's height
  ``h`` (largest extent of the rest joint positions): ``h < 3`` metres, ``30 ≤ h < 110`` inches,
  ``110 ≤ h < 300`` centimetres, ``300 ≤ h < 3000`` millimetres; anything else is refused.
* World frame: BVH is y up. :meth:`BvhMotion.world_positions` returns positions in our world frame
  (z up, DESIGN §3) by the axis permutation ``(x, y, z)_ours = (z, x, y)_bvh``, a proper rotation
  that takes a BVH character facing +z (left = +x) to one facing +x (left = +y).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..geometry import exp_so3, log_so3
from .model import BodyError

__all__ = ["BvhMotion", "load_bvh", "parse_bvh", "BVH_TO_WORLD"]

# (x, y, z)_ours = BVH_TO_WORLD @ (x, y, z)_bvh
BVH_TO_WORLD = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

_CHANNELS = {"xposition": ("pos", 0), "yposition": ("pos", 1), "zposition": ("pos", 2),
             "xrotation": ("rot", 0), "yrotation": ("rot", 1), "zrotation": ("rot", 2)}


@dataclass(frozen=True, eq=False)
class BvhMotion:
    """A parsed BVH motion (lengths in metres, BVH axes; angles in degrees as in the file).

    Attributes
    ----------
    joint_names : tuple of str
        ``Jb`` joints in file order (parents first), end sites as ``<parent>_end``.
    parents : (Jb,) int ndarray
        ``-1`` for the root.
    offsets : (Jb, 3) ndarray
        Rest offsets from the parent, metres, BVH axes.
    channels : tuple of tuple
        ``(joint index, channel name)`` for each column of ``frames``, e.g. ``(0, "Xposition")``.
    frame_time : float
        Seconds per frame.
    frames : (F, channels) ndarray
        Channel values (positions scaled to metres, rotations in degrees).
    scale : float
        Metres per file unit that was applied.
    source : str
        Where it came from (path or ``"<string>"``).
    """

    joint_names: tuple
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple
    frame_time: float
    frames: np.ndarray
    scale: float = 1.0
    source: str = "<string>"
    _joint_channels: tuple = field(default=(), repr=False)

    @property
    def n_frames(self) -> int:
        return int(self.frames.shape[0])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    def joint_index(self, name: str) -> int:
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise BodyError(f"joint: '{name}' not in the BVH skeleton "
                            f"({', '.join(self.joint_names)})") from None

    def rest_positions(self) -> np.ndarray:
        """Rest-pose joint positions ``(Jb, 3)`` (all rotations zero, offsets only), BVH axes, m."""
        P = np.zeros((len(self.joint_names), 3))
        for j, p in enumerate(self.parents):
            P[j] = self.offsets[j] + (P[p] if p >= 0 else 0.0)
        return P

    def local_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-frame local rotations ``(F, Jb, 3, 3)`` and translations ``(F, Jb, 3)`` (BVH axes)."""
        F, Jb = self.n_frames, len(self.joint_names)
        R = np.broadcast_to(np.eye(3), (F, Jb, 3, 3)).copy()
        t = np.broadcast_to(self.offsets, (F, Jb, 3)).copy()
        for j, chans in enumerate(self._joint_channels):
            for col, kind, axis in chans:
                if kind == "pos":
                    t[:, j, axis] = self.frames[:, col]
            rot = [(col, axis) for col, kind, axis in chans if kind == "rot"]
            if rot:
                Rj = np.broadcast_to(np.eye(3), (F, 3, 3))
                for col, axis in rot:
                    v = np.zeros((F, 3))
                    v[:, axis] = np.deg2rad(self.frames[:, col])
                    Rj = Rj @ exp_so3(v)
                R[:, j] = Rj
        return R, t

    def world_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """World rotations ``(F, Jb, 3, 3)`` and positions ``(F, Jb, 3)`` in BVH axes."""
        Rl, tl = self.local_transforms()
        Rw = np.empty_like(Rl)
        Pw = np.empty_like(tl)
        for j, p in enumerate(self.parents):
            if p < 0:
                Rw[:, j], Pw[:, j] = Rl[:, j], tl[:, j]
            else:
                Rw[:, j] = Rw[:, p] @ Rl[:, j]
                Pw[:, j] = Pw[:, p] + np.einsum("fij,fj->fi", Rw[:, p], tl[:, j])
        return Rw, Pw

    def world_positions(self) -> np.ndarray:
        """Joint positions per frame in OUR world frame (z up, metres): ``(F, Jb, 3)``."""
        return self.world_transforms()[1] @ BVH_TO_WORLD.T

    def slice(self, start: int = 0, stop: int | None = None) -> "BvhMotion":
        """Frames ``start:stop`` as a new motion."""
        return replace(self, frames=_ro(self.frames[start:stop]))

    def resample(self, fps: float) -> "BvhMotion":
        """Resample to ``fps`` frames per second over the same duration.

        Position channels are interpolated linearly, each joint's rotation by slerp (the result is
        written back in the joint's own channel order).

        Parameters
        ----------
        fps : float
            Target rate (> 0).

        Returns
        -------
        BvhMotion
        """
        if not np.isfinite(fps) or fps <= 0:
            raise BodyError(f"fps: expected a positive number, got {fps!r}")
        F = self.n_frames
        duration = (F - 1) * self.frame_time
        n_new = int(np.floor(duration * fps + 1e-3)) + 1   # tolerate rounded frame times
        s = np.minimum(np.arange(n_new) / fps / self.frame_time, F - 1)   # fractional source frame
        i0 = np.clip(np.floor(s).astype(int), 0, F - 1)
        i1 = np.minimum(i0 + 1, F - 1)
        a = (s - i0)[:, None]
        out = (1 - a) * self.frames[i0] + a * self.frames[i1]
        Rl, _ = self.local_transforms()
        for chans in self._joint_channels:
            rot = [(col, axis) for col, kind, axis in chans if kind == "rot"]
            if not rot:
                continue
            j = self._joint_of_column(rot[0][0])
            R0, R1 = Rl[i0, j], Rl[i1, j]
            d = log_so3(np.swapaxes(R0, -1, -2) @ R1)
            Rs = R0 @ exp_so3(d * a)
            out[:, [c for c, _ in rot]] = _to_euler(Rs, [ax for _, ax in rot], out[:, [c for c, _ in rot]])
        return replace(self, frames=_ro(out), frame_time=1.0 / fps)

    def _joint_of_column(self, col: int) -> int:
        return self.channels[col][0]


def _to_euler(R: np.ndarray, axes: list[int], hint: np.ndarray) -> np.ndarray:
    """Decompose ``R = R_a1 R_a2 R_a3`` (intrinsic, degrees); ``hint`` (degrees) keeps the branch
    near the linearly interpolated angles where the decomposition is ambiguous."""
    from scipy.spatial.transform import Rotation

    if len(axes) == 3 and len(set(axes)) == 3:
        seq = "".join("XYZ"[a] for a in axes)
        ang = Rotation.from_matrix(R).as_euler(seq, degrees=True)
        # the other branch (a1 + 180, 180 - a2, a3 + 180) when it is closer to the hint
        alt = np.stack([ang[:, 0] + 180, 180 - ang[:, 1], ang[:, 2] + 180], axis=1)
        def wrap(v, ref):
            return ref + (v - ref + 180) % 360 - 180
        ang = wrap(ang, hint)
        alt = wrap(alt, hint)
        use_alt = np.abs(alt - hint).sum(1) < np.abs(ang - hint).sum(1)
        return np.where(use_alt[:, None], alt, ang)
    # one or two rotation channels: the interpolation stays on their subgroup; use the hint.
    return hint


def _ro_int(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=int)
    a.flags.writeable = False
    return a


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


# ---------------------------------------------------------------------------------------------
# Parsing
# ---------------------------------------------------------------------------------------------
def load_bvh(path, *, scale: float | None = None) -> BvhMotion:
    """Read a BVH file.

    Parameters
    ----------
    path : str or Path
    scale : float, optional
        Metres per file unit (e.g. 0.01 for centimetres); detected from the skeleton height when
        omitted (see module docstring).

    Returns
    -------
    BvhMotion
    """
    path = Path(path)
    if not path.is_file():
        raise BodyError(f"path: BVH file not found: {path}")
    return parse_bvh(path.read_text(errors="replace"), scale=scale, source=str(path))


def parse_bvh(text: str, *, scale: float | None = None, source: str = "<string>") -> BvhMotion:
    """Parse BVH text (see :func:`load_bvh`)."""
    lines = text.splitlines()
    tokens: list[tuple[str, int]] = []
    motion_line = None
    for ln, line in enumerate(lines, start=1):
        if line.strip().upper() == "MOTION":
            motion_line = ln
            break
        tokens += [(tok, ln) for tok in line.replace("{", " { ").replace("}", " } ").split()]
    if motion_line is None:
        raise BodyError(f"{source}: no MOTION section")
    pos = 0

    def take(expected: str | None = None) -> tuple[str, int]:
        nonlocal pos
        if pos >= len(tokens):
            raise BodyError(f"{source}: unexpected end of HIERARCHY"
                            + (f", expected '{expected}'" if expected else ""))
        tok, ln = tokens[pos]
        pos += 1
        if expected is not None and tok.upper() != expected.upper():
            raise BodyError(f"{source}: line {ln}: expected '{expected}', got '{tok}'")
        return tok, ln

    def take_floats(k: int, what: str) -> np.ndarray:
        vals = []
        for _ in range(k):
            tok, ln = take()
            try:
                vals.append(float(tok))
            except ValueError:
                raise BodyError(f"{source}: line {ln}: {what}: expected {k} numbers, got '{tok}'") from None
        return np.array(vals)

    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[tuple[int, str]] = []

    take("HIERARCHY")

    def parse_joint(kind: str, parent: int) -> None:
        tok, ln = take()
        if kind == "End":
            if tok.upper() != "SITE":
                raise BodyError(f"{source}: line {ln}: expected 'Site' after 'End', got '{tok}'")
            name = f"{names[parent]}_end"
        else:
            name = tok
            if name in names:
                raise BodyError(f"{source}: line {ln}: duplicate joint name '{name}'")
        j = len(names)
        names.append(name)
        parents.append(parent)
        take("{")
        take("OFFSET")
        offsets.append(take_floats(3, f"OFFSET of '{name}'"))
        has_channels = False
        while True:
            tok, ln = take()
            up = tok.upper()
            if up == "}":
                break
            if up == "CHANNELS":
                if kind == "End":
                    raise BodyError(f"{source}: line {ln}: End Site of '{names[parent]}' cannot have CHANNELS")
                ctok, cln = take()
                try:
                    k = int(ctok)
                except ValueError:
                    raise BodyError(f"{source}: line {cln}: CHANNELS of '{name}': expected a count, "
                                    f"got '{ctok}'") from None
                for _ in range(k):
                    ch, chln = take()
                    if ch.lower() not in _CHANNELS:
                        raise BodyError(f"{source}: line {chln}: CHANNELS of '{name}': expected {k} channel "
                                        f"names (X/Y/Z position/rotation), got '{ch}'")
                    channels.append((j, ch[0].upper() + ch[1:].lower()))
                has_channels = True
            elif up in ("JOINT", "END"):
                if kind != "End" and not has_channels:
                    raise BodyError(f"{source}: line {ln}: joint '{name}' has no CHANNELS line before its children")
                parse_joint("End" if up == "END" else "JOINT", j)
            else:
                raise BodyError(f"{source}: line {ln}: unexpected token '{tok}' in joint '{name}'")
        if kind != "End" and not has_channels:
            raise BodyError(f"{source}: joint '{name}' has no CHANNELS line (missing channels)")

    take("ROOT")
    parse_joint("ROOT", -1)
    if pos != len(tokens):
        tok, ln = tokens[pos]
        raise BodyError(f"{source}: line {ln}: expected MOTION after the root joint, got '{tok}' "
                        "(only one ROOT is supported)")

    # MOTION header
    header = {}
    ln = motion_line
    for key in ("frames", "frame time"):
        while ln < len(lines) and not lines[ln].strip():
            ln += 1
        if ln >= len(lines):
            raise BodyError(f"{source}: MOTION: missing '{key.title()}:' line")
        m = re.match(r"\s*" + key.replace(" ", r"\s+") + r"\s*:\s*(\S+)\s*$", lines[ln], re.IGNORECASE)
        if not m:
            raise BodyError(f"{source}: line {ln + 1}: expected '{key.title()}: <number>', got '{lines[ln].strip()}'")
        header[key] = m.group(1)
        ln += 1
    try:
        n_frames = int(header["frames"])
        frame_time = float(header["frame time"])
    except ValueError:
        raise BodyError(f"{source}: MOTION header: expected an integer frame count and a number for the "
                        f"frame time, got {header}") from None
    if n_frames < 1 or not frame_time > 0:
        raise BodyError(f"{source}: MOTION header: expected Frames >= 1 and Frame Time > 0, "
                        f"got Frames {n_frames}, Frame Time {frame_time}")
    C = len(channels)
    data = np.empty((n_frames, C))
    k = 0
    for i in range(ln, len(lines)):
        if not lines[i].strip():
            continue
        if k >= n_frames:
            raise BodyError(f"{source}: line {i + 1}: more frame lines than 'Frames: {n_frames}'")
        parts = lines[i].split()
        if len(parts) != C:
            raise BodyError(f"{source}: line {i + 1} (frame {k}): expected {C} channel values, got {len(parts)}")
        try:
            data[k] = np.array(parts, dtype=float)
        except ValueError:
            raise BodyError(f"{source}: line {i + 1} (frame {k}): expected numbers, got "
                            f"'{lines[i].strip()[:60]}'") from None
        k += 1
    if k != n_frames:
        raise BodyError(f"{source}: expected {n_frames} frame lines ('Frames: {n_frames}'), got {k}")
    if not np.all(np.isfinite(data)):
        bad = np.argwhere(~np.isfinite(data))[0]
        raise BodyError(f"{source}: frame {bad[0]}: expected finite values, got {data[tuple(bad)]} "
                        f"in channel {bad[1]} ({names[channels[bad[1]][0]]} {channels[bad[1]][1]})")

    offsets_arr = np.array(offsets)
    parents_arr = np.array(parents, dtype=int)
    if scale is None:
        scale = _detect_scale(offsets_arr, parents_arr, source)
    elif not (np.isfinite(scale) and scale > 0):
        raise BodyError(f"scale: expected a positive number (metres per file unit), got {scale!r}")
    pos_cols = [c for c, (_, ch) in enumerate(channels) if ch.endswith("position")]
    data[:, pos_cols] *= scale
    joint_channels = [[] for _ in names]
    for col, (j, ch) in enumerate(channels):
        kind, axis = _CHANNELS[ch.lower()]
        joint_channels[j].append((col, kind, axis))
    return BvhMotion(joint_names=tuple(names), parents=_ro_int(parents_arr),
                     offsets=_ro(offsets_arr * scale), channels=tuple(channels), frame_time=frame_time,
                     frames=_ro(data), scale=float(scale), source=source,
                     _joint_channels=tuple(tuple(c) for c in joint_channels))


def _detect_scale(offsets: np.ndarray, parents: np.ndarray, source: str) -> float:
    P = np.zeros_like(offsets)
    for j, p in enumerate(parents):
        P[j] = offsets[j] + (P[p] if p >= 0 else 0.0)
    h = float(np.max(P.max(0) - P.min(0)))
    if 0.3 <= h < 3.0:
        return 1.0
    if 30.0 <= h < 110.0:
        return 0.0254
    if 110.0 <= h < 300.0:
        return 0.01
    if 300.0 <= h < 3000.0:
        return 0.001
    raise BodyError(f"{source}: cannot detect the length unit from the skeleton height {h:.4g} "
                    "(expected 0.3-3 m, 30-110 in, 110-300 cm or 300-3000 mm); pass scale= "
                    "(--bvh-scale) in metres per file unit")
