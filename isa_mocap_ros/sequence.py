"""A recorded multi-view sequence as per-frame arrays (pure: no ROS types).

Source: the bag layout of ``isa-mocap synth`` (``docs/synthetic_sequences.md``, DESIGN §1): per view
``/mocap/cam<i>/image_raw``, ``camera_info``, latched ``extrinsics`` (world → ``cam<i>_optical_frame``),
optionally ``/mocap/cam<i>/mask``; ground truth ``/mocap/ground_truth/joint_states`` (root as
x, y, z, roll, pitch, yaw) and the latched ``/mocap/ground_truth/model`` YAML.

The command-line tools convert the messages (``msg_adapters``) and hand the arrays to a
:class:`SequenceBuilder`; :meth:`SequenceBuilder.build` returns a :class:`Sequence`: cameras,
frames keyed by stamp in time order (images and masks per view, ``None`` where a view has none),
and, when present, the ground-truth model and poses (pose vectors, DESIGN §3).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml

__all__ = ["SequenceError", "Frame", "Sequence", "SequenceBuilder", "view_of_topic", "model_from_yaml",
           "model_to_yaml"]

_TOPIC = re.compile(r"^/?(?:.*/)?cam(\d+)/(image_raw|camera_info|extrinsics|mask)$")


class SequenceError(ValueError):
    """Bad or inconsistent sequence contents (names the item, the expected and the received value)."""


def view_of_topic(topic: str) -> tuple[int, str] | None:
    """``(view, kind)`` of a per-view topic like ``/mocap/cam2/mask`` (kind: image_raw, camera_info,
    extrinsics, mask), None for any other topic."""
    m = _TOPIC.match(topic)
    return (int(m.group(1)), m.group(2)) if m else None


def model_from_yaml(text: str):
    """The ground-truth body model of a ``/mocap/ground_truth/model`` YAML (``model.dof`` and
    ``model.shape``; see :func:`isa_mocap_ros.synth.model_yaml`), and the parsed mapping."""
    from isa_mocap_ros.body import make_model

    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise SequenceError(f"model: expected YAML, received unparsable text ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("model"), dict):
        raise SequenceError("model: expected a mapping with a 'model' entry, received "
                            f"{type(data).__name__}")
    m = data["model"]
    dof = m.get("dof")
    if dof not in (18, 28, 39):
        raise SequenceError(f"model.dof: expected 18, 28 or 39, received {dof!r}")
    model = make_model(int(dof), shape=m.get("shape"))
    names = m.get("dof_names")
    if names is not None and list(names) != list(model.dof_names):
        raise SequenceError(f"model.dof_names: expected the {dof}-DOF model's names, received {names!r}")
    return model, data


def model_to_yaml(model, *, role: str = "estimator", **extra) -> str:
    """A body model as the YAML of ``/mocap/ground_truth/model`` (``format``, ``model``: name, dof,
    dof_names, marker_joints, shape; ``root``): what the estimator publishes latched on
    ``/mocap/model`` and ``isa-mocap track`` writes into its estimates bag, so a recorded result
    names the model (and the shape) its joint states belong to. ``model_from_yaml`` reads it back.
    ``extra`` entries are added at the top level (plain values)."""
    def plain(v):
        if isinstance(v, np.ndarray):
            return [plain(x) for x in v.tolist()]
        if isinstance(v, (np.floating, float)):
            return round(float(v), 9)
        if isinstance(v, np.integer):
            return int(v)
        if isinstance(v, dict) or hasattr(v, "items"):
            return {str(k): plain(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [plain(x) for x in v]
        return v

    data = {"format": 1, "role": role,
            "model": {"name": model.name, "dof": model.dof, "dof_names": list(model.dof_names),
                      "marker_joints": [model.joint_names[j] for j in model.markers],
                      "shape": plain({"name": model.shape["name"], "offsets": dict(model.shape["offsets"]),
                                      "radii": dict(model.shape["radii"]),
                                      **({"axis_offsets": dict(model.shape["axis_offsets"])}
                                         if model.shape.get("axis_offsets") else {})})},
            "root": ("root_tx, root_ty, root_tz: pelvis position in world (m); root_rx, root_ry, root_rz: roll, "
                     "pitch, yaw (rad) with R = Rz(yaw) Ry(pitch) Rx(roll) (isa_mocap_ros.body.joint_state_to_pose)")}
    data.update(plain(extra))
    return yaml.safe_dump(data, sort_keys=False, width=120)


@dataclass(frozen=True, eq=False)
class Frame:
    """One frame set: what every view recorded at one stamp.

    Attributes
    ----------
    index : int
        Position in the sequence (0 = first stamp).
    stamp_ns : int
    images : tuple of ((H, W, 3) uint8 ndarray or None)
        Per view.
    masks : tuple of ((H, W) uint8 ndarray or None)
        Per view (recorded masks only).
    truth : (D,) ndarray or None
        Ground-truth pose vector (of :attr:`Sequence.truth_model`).
    truth_markers : (M, 3) ndarray or None
        Ground-truth joint centres (``/mocap/ground_truth/markers``), named by
        :attr:`Sequence.truth_marker_names`.
    """

    index: int
    stamp_ns: int
    images: tuple
    masks: tuple
    truth: np.ndarray | None = None
    truth_markers: np.ndarray | None = None

    @property
    def has_images(self) -> bool:
        return any(i is not None for i in self.images)

    @property
    def has_masks(self) -> bool:
        return any(m is not None for m in self.masks)


@dataclass(frozen=True, eq=False)
class Sequence:
    """A multi-view sequence (see the module docstring).

    Attributes
    ----------
    cameras : tuple of Camera
        One per view, view order.
    frames : tuple of Frame
        In stamp order.
    truth_model : BodyModel or None
        From the ground-truth model YAML.
    truth_info : dict
        The parsed YAML (empty without one).
    notes : tuple of str
        What was dropped or filled in.
    truth_marker_names : tuple of str
        Names of the ground-truth markers in order (the model YAML's ``model.marker_joints``).
    """

    cameras: tuple
    frames: tuple
    truth_model: Any = None
    truth_info: dict = field(default_factory=dict)
    notes: tuple = ()
    truth_marker_names: tuple = ()

    @property
    def has_marker_truth(self) -> bool:
        """Named ground-truth joint centres on some frame (scoring needs no ground-truth model then)."""
        return bool(self.truth_marker_names) and any(f.truth_markers is not None for f in self.frames)

    @property
    def body_kind(self) -> str:
        """``"mesh"`` or ``"capsules"`` (the model YAML's ``body.kind``; capsules when absent)."""
        b = self.truth_info.get("body") if isinstance(self.truth_info, dict) else None
        return str(b.get("kind", "capsules")) if isinstance(b, dict) else "capsules"

    @property
    def n_views(self) -> int:
        return len(self.cameras)

    @property
    def has_masks(self) -> bool:
        return any(f.has_masks for f in self.frames)

    @property
    def has_truth(self) -> bool:
        return self.truth_model is not None and any(f.truth is not None for f in self.frames)

    @property
    def empty_frames(self) -> int:
        """Empty (background-only) frames at the start as the model YAML states (0 if unknown)."""
        seq = self.truth_info.get("sequence", {}) if isinstance(self.truth_info, dict) else {}
        v = seq.get("empty_frames", 0) if isinstance(seq, dict) else 0
        return int(v) if isinstance(v, int) and v >= 0 else 0


class SequenceBuilder:
    """Collect converted bag contents, then :meth:`build` a :class:`Sequence`.

    Every ``add_*`` takes plain arrays; views are indexed from 0. Later messages of the latched
    calibration replace earlier ones; a second image/mask of one view and stamp replaces the first
    (noted).
    """

    def __init__(self) -> None:
        self._intr: dict[int, dict] = {}
        self._extr: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._images: dict[int, dict[int, np.ndarray]] = {}
        self._masks: dict[int, dict[int, np.ndarray]] = {}
        self._truth: dict[int, tuple[list, np.ndarray]] = {}
        self._truth_markers: dict[int, np.ndarray] = {}
        self._model_text: str | None = None
        self._reference_names: tuple | None = None
        self._notes: list[str] = []

    @staticmethod
    def _view(view) -> int:
        if isinstance(view, bool) or not isinstance(view, (int, np.integer)) or view < 0:
            raise SequenceError(f"view: expected an integer >= 0, received {view!r}")
        return int(view)

    @staticmethod
    def _stamp(stamp_ns) -> int:
        if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, (int, np.integer)) or stamp_ns < 0:
            raise SequenceError(f"stamp_ns: expected an integer >= 0, received {stamp_ns!r}")
        return int(stamp_ns)

    def add_camera_info(self, view: int, *, K, D, width: int, height: int) -> None:
        """Intrinsics of a view (from CameraInfo)."""
        self._intr[self._view(view)] = {"K": np.asarray(K, float), "D": np.asarray(D, float),
                                        "width": int(width), "height": int(height)}

    def add_extrinsics(self, view: int, R_wc, t_wc) -> None:
        """The camera optical frame in the world (``x_world = R_wc x_cam + t_wc``; the TransformStamped
        world → cam<i>_optical_frame)."""
        self._extr[self._view(view)] = (np.asarray(R_wc, float), np.asarray(t_wc, float))

    def _put(self, store: dict, what: str, view: int, stamp_ns: int, arr: np.ndarray) -> None:
        v, s = self._view(view), self._stamp(stamp_ns)
        d = store.setdefault(v, {})
        if s in d:
            self._notes.append(f"view {v}: second {what} at stamp {s}; the later one kept")
        d[s] = arr

    def add_image(self, view: int, stamp_ns: int, image) -> None:
        """An ``(H, W, 3)`` uint8 RGB image (or ``(H, W)`` mono)."""
        self._put(self._images, "image", view, stamp_ns, np.asarray(image))

    def add_mask(self, view: int, stamp_ns: int, mask) -> None:
        """An ``(H, W)`` foreground mask (nonzero = foreground)."""
        self._put(self._masks, "mask", view, stamp_ns, np.asarray(mask))

    def add_truth(self, stamp_ns: int, names, positions) -> None:
        """Ground-truth JointState (names, positions; root as x, y, z, roll, pitch, yaw)."""
        self._truth[self._stamp(stamp_ns)] = (list(names), np.asarray(positions, float))

    def add_truth_markers(self, stamp_ns: int, positions) -> None:
        """Ground-truth joint centres ``(M, 3)`` (a ``/mocap/ground_truth/markers`` PoseArray)."""
        P = np.asarray(positions, float).reshape(-1, 3)
        self._truth_markers[self._stamp(stamp_ns)] = P

    def set_model_yaml(self, text: str) -> None:
        """The ``/mocap/ground_truth/model`` String."""
        self._model_text = str(text)

    def set_reference_yaml(self, text: str) -> None:
        """The ``/mocap/ground_truth/reference`` String (``isa-mocap import --reference``): names the
        ground-truth markers when the bag has no model description naming them. The reference's names
        (e.g. Pose2Sim's ``RKnee``) are mapped to our joints by
        :data:`isa_mocap_ros.eval.trc.POSE2SIM_TO_JOINTS`."""
        import yaml

        from isa_mocap_ros.eval.trc import joint_names_of

        try:
            info = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            self._notes.append(f"/mocap/ground_truth/reference: not YAML ({str(exc).splitlines()[0]}); ignored")
            return
        names = info.get("marker_names") if isinstance(info, dict) else None
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            self._notes.append("/mocap/ground_truth/reference: expected a list of strings 'marker_names'; ignored")
            return
        self._reference_names = joint_names_of(names)

    def cameras(self) -> tuple:
        """The calibrated cameras so far (raises :class:`SequenceError` for an incomplete view)."""
        from isa_mocap_ros.vision import Camera

        views = sorted(set(self._intr) | set(self._extr) | set(self._images) | set(self._masks))
        if not views:
            raise SequenceError("cameras: expected camera_info and extrinsics of at least one view, received none")
        if views != list(range(len(views))):
            raise SequenceError(f"views: expected views 0..{max(views)} without gaps, received {views}")
        cams = []
        for v in views:
            if v not in self._intr or v not in self._extr:
                miss = [n for n, d in (("camera_info", self._intr), ("extrinsics", self._extr)) if v not in d]
                raise SequenceError(f"view {v}: expected camera_info and extrinsics, missing {', '.join(miss)}")
            i = self._intr[v]
            R_wc, t_wc = self._extr[v]
            D = i["D"]
            if D.size not in (0, 4, 5, 8):
                D = np.concatenate([D, np.zeros(8)])[:8] if D.size < 8 else D[:8]
            cams.append(Camera.from_intrinsics_and_pose(f"cam{v}", K=i["K"], D=D, width=i["width"],
                                                        height=i["height"], R_wc=R_wc, t_wc=t_wc))
        return tuple(cams)

    def build(self) -> Sequence:
        """The :class:`Sequence` (frames at every stamp any view has an image or mask)."""
        cams = self.cameras()
        V = len(cams)
        notes = list(self._notes)
        truth_model, info = None, {}
        if self._model_text is not None:
            truth_model, info = model_from_yaml(self._model_text)
        stamps = sorted(set().union(*[set(d) for d in self._images.values()],
                                    *[set(d) for d in self._masks.values()]))
        frames = []
        for k, s in enumerate(stamps):
            truth = None
            if s in self._truth:
                names, q = self._truth[s]
                if truth_model is None:
                    notes.append("ground truth without a model description: ignored")
                    self._truth.clear()
                else:
                    truth = self._truth_pose(truth_model, names, q, s)
            frames.append(Frame(k, s, tuple(self._images.get(v, {}).get(s) for v in range(V)),
                                tuple(self._masks.get(v, {}).get(s) for v in range(V)), truth,
                                self._truth_markers.get(s)))
        for v in range(V):
            n = len(self._images.get(v, {})) + len(self._masks.get(v, {}))
            if n == 0:
                notes.append(f"view {v}: no images or masks")
        mnames: tuple = ()
        if self._truth_markers:
            m = info.get("model") if isinstance(info, dict) else None
            names = m.get("marker_joints") if isinstance(m, dict) else None
            if not isinstance(names, list) and self._reference_names is not None:
                names = list(self._reference_names)
            sizes = {len(p) for p in self._truth_markers.values()}
            if not isinstance(names, list) or sizes != {len(names)}:
                notes.append("ground-truth markers without names matching them in the model description "
                             f"(model.marker_joints): ignored")
                frames = [Frame(f.index, f.stamp_ns, f.images, f.masks, f.truth, None) for f in frames]
            else:
                mnames = tuple(str(n) for n in names)
        return Sequence(cams, tuple(frames), truth_model, info, tuple(notes), mnames)

    @staticmethod
    def _truth_pose(model, names, q, stamp) -> np.ndarray:
        from isa_mocap_ros.body import joint_state_to_pose

        if len(names) != q.size:
            raise SequenceError(f"ground truth at {stamp}: expected one position per name, received "
                                f"{len(names)} names and {q.size} positions")
        pos = dict(zip(names, q))
        missing = [n for n in model.dof_names if n not in pos]
        if missing:
            raise SequenceError(f"ground truth at {stamp}: expected the model's joints, missing {missing[:5]}")
        return joint_state_to_pose(model, np.array([pos[n] for n in model.dof_names]))
