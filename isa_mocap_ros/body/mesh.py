"""Skinned human meshes: subjects from MakeHuman's macro sliders, posed by linear-blend skinning.

Sources: the CC0 MakeHuman / MPFB2 base mesh, macro targets and ``cmu_mb`` skeleton
(:mod:`.mesh_assets`); MakeHuman's macro-modifier weighting; linear-blend skinning
``v' = sum_s w_s M_s v``. Used by ``isa-mocap synth --body mesh`` (DESIGN §6).

Subject (:func:`make_subject`)
------------------------------
Sliders in [0, 1]: ``gender`` (0 female, 1 male), ``muscle``, ``weight``, ``height``,
``proportions``; age is fixed at MakeHuman's "young" (25 years) and the race mix at 1/3 each. A
target of a slider pair ``(lo, hi)`` around 0.5 gets ``max(0, 1 - 2 s)`` / ``max(0, 2 s - 1)`` and a
three-way one (min / average / max) additionally ``1 - |2 s - 1|`` for the average; the universal,
height and proportion targets multiply the gender, muscle and weight factors (MakeHuman's rule).
The mesh is then scaled uniformly to the subject's ``stature_m`` (floor to the top of the head, in
the rest pose). Joint centres are the means of MakeHuman's joint helper cubes after the targets.
Presets: :data:`PRESETS`; ``random`` draws sliders, stature and clothing from a generator.

Posing (:func:`pose_mesh`)
--------------------------
The mesh's 31 CMU-named bones are grouped into 17 *segments* between our joint names
(:data:`SEGMENTS`: pelvis → spine_lower, ..., left_knee → left_ankle, ...). A *driver*
(:class:`Driver`: per frame world positions and rotations of our joint names, with their rest
values; from a BVH, :func:`driver_from_bvh`, or from a body model's poses,
:func:`driver_from_model`) moves each segment ``s = (a → b)`` with the affine map

    M_s(x) = P_a + R_s S_s (x - m_a),   R_s = Δ R_a R0_aᵀ A_s,   S_s = I + (k_s - 1) u uᵀ

``m_a`` the mesh's rest joint, ``u`` the unit rest direction ``m_b - m_a``, ``A_s`` the smallest
rotation taking ``u`` to the driver's rest direction, ``R_a R0_aᵀ`` the driver joint's rotation
from its rest, ``Δ`` the smallest rotation that then makes the segment point exactly at the
driver's ``P_b``, and ``k_s = |P0_b - P0_a| / |m_b - m_a|`` (the driver's segment length over the
mesh's, clipped to [0.7, 1.4]). So every posed joint centre ``M_s(m_a)`` is the driver's ``P_a``:
the ground-truth markers of a mesh sequence are the mesh skeleton's joint centres, and they
coincide with the driver's joints. The mesh's rest pose is first turned to face the driver's rest
pose (body frame from the hips and the neck). A segment whose joint the driver lacks (the 18-DOF
model has no upper body) moves with its parent segment.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import numpy as np

from ..geometry import exp_so3
from .bvh import BVH_TO_WORLD, BvhMotion, parse_bvh
from .kinematics import forward_kinematics
from .mesh_assets import MACRO_AXES, load_assets
from .model import BodyError, BodyModel

__all__ = ["PRESETS", "SUBJECTS", "SEGMENTS", "MESH_MARKERS", "Subject", "MeshBody", "Driver", "make_subject",
           "mesh_body", "driver_from_bvh", "driver_from_model", "joint_paths", "pose_mesh", "rest_bvh"]

# segment: (head joint, tail joint, parent segment, mesh bones)
_SEGS = [
    ("pelvis", "pelvis", "spine_lower", None, ("Hips", "LHipJoint", "RHipJoint")),
    ("spine_lower", "spine_lower", "spine_upper", "pelvis", ("LowerBack", "Spine")),
    ("spine_upper", "spine_upper", "neck", "spine_lower", ("Spine1", "LeftShoulder", "RightShoulder")),
    ("neck", "neck", "head", "spine_upper", ("Neck", "Neck1")),
    ("head", "head", "head_top", "neck", ("Head",)),
]
for _s, _S in (("left", "Left"), ("right", "Right")):
    _t = _S[0]
    _SEGS += [
        (f"{_s}_upper_arm", f"{_s}_shoulder", f"{_s}_elbow", "spine_upper", (f"{_S}Arm",)),
        (f"{_s}_forearm", f"{_s}_elbow", f"{_s}_wrist", f"{_s}_upper_arm", (f"{_S}ForeArm",)),
        (f"{_s}_hand", f"{_s}_wrist", f"{_s}_hand", f"{_s}_forearm",
         (f"{_S}Hand", f"{_S}FingerBase", f"{_S}HandFinger1", f"{_t}Thumb")),
        (f"{_s}_thigh", f"{_s}_hip", f"{_s}_knee", "pelvis", (f"{_S}UpLeg",)),
        (f"{_s}_shin", f"{_s}_knee", f"{_s}_ankle", f"{_s}_thigh", (f"{_S}Leg",)),
        (f"{_s}_foot", f"{_s}_ankle", f"{_s}_toe", f"{_s}_shin", (f"{_S}Foot", f"{_S}ToeBase")),
    ]
#: segment name -> (head joint, tail joint, parent segment or None)
SEGMENTS = {s[0]: s[1:4] for s in _SEGS}
#: names (our joint names, in this order) of the ground-truth joint centres of a mesh sequence
MESH_MARKERS = ("pelvis", "neck", "head", "left_shoulder", "left_elbow", "left_wrist", "left_hip", "left_knee",
                "left_ankle", "right_shoulder", "right_elbow", "right_wrist", "right_hip", "right_knee",
                "right_ankle")

# clothing colours (RGB)
_SKIN = {"light": (225, 180, 150), "medium": (190, 140, 105), "dark": (120, 80, 55)}
_HAIR = (60, 40, 28)


@dataclass(frozen=True)
class Subject:
    """A person to render: macro sliders, stature and clothing.

    Attributes
    ----------
    name : str
    sliders : dict
        ``gender, muscle, weight, height, proportions`` in [0, 1].
    stature_m : float
        Rest-pose height, floor to the top of the head.
    shirt, trousers, shoes, skin : tuple of int
        Clothing and skin colours (RGB).
    skirt : bool
        Render MakeHuman's (CC0) helper skirt over the legs (a loose-clothing case).
    """

    name: str
    sliders: dict
    stature_m: float
    shirt: tuple = (200, 45, 40)
    trousers: tuple = (40, 70, 160)
    shoes: tuple = (50, 35, 25)
    skin: tuple = _SKIN["light"]
    skirt: bool = False

    def describe(self) -> dict:
        return {"name": self.name, "sliders": {k: round(float(v), 4) for k, v in self.sliders.items()},
                "stature_m": round(float(self.stature_m), 4), "shirt": list(self.shirt),
                "trousers": list(self.trousers), "shoes": list(self.shoes), "skin": list(self.skin),
                "skirt": bool(self.skirt)}


#: the named subjects (``--subject``)
PRESETS = {
    "slim_woman": Subject("slim_woman", {"gender": 0.0, "muscle": 0.45, "weight": 0.25, "height": 0.4,
                                         "proportions": 0.8}, 1.60,
                          shirt=(70, 150, 95), trousers=(45, 45, 55), shoes=(200, 200, 205), skin=_SKIN["light"]),
    "average_man": Subject("average_man", {"gender": 1.0, "muscle": 0.5, "weight": 0.5, "height": 0.5,
                                           "proportions": 0.6}, 1.78,
                           shirt=(200, 45, 40), trousers=(40, 70, 160), shoes=(50, 35, 25), skin=_SKIN["medium"]),
    "heavy_man": Subject("heavy_man", {"gender": 1.0, "muscle": 0.55, "weight": 1.0, "height": 0.75,
                                       "proportions": 0.5}, 1.88,
                         shirt=(235, 190, 60), trousers=(70, 60, 50), shoes=(30, 30, 30), skin=_SKIN["dark"]),
}
#: accepted ``--subject`` values
SUBJECTS = tuple(PRESETS) + ("random",)
_PALETTE = [(200, 45, 40), (40, 70, 160), (70, 150, 95), (235, 190, 60), (120, 60, 150), (230, 120, 40),
            (45, 45, 55), (150, 150, 160), (90, 60, 40), (30, 120, 140), (220, 220, 225), (160, 30, 80)]


def make_subject(name: str, *, rng: np.random.Generator | None = None, skirt: bool = False) -> Subject:
    """A preset (:data:`PRESETS`) or ``"random"`` (sliders, stature and colours drawn from ``rng``).

    Raises
    ------
    BodyError
        Unknown name, or ``random`` without a generator.
    """
    if name in PRESETS:
        s = PRESETS[name]
    elif name == "random":
        if rng is None:
            raise BodyError("subject 'random': expected a numpy Generator (rng=), received None")
        g = float(rng.uniform())
        sl = {"gender": g, "muscle": float(rng.uniform(0.2, 0.8)), "weight": float(rng.uniform(0.1, 0.95)),
              "height": float(rng.uniform(0.2, 0.8)), "proportions": float(rng.uniform(0.3, 1.0))}
        stature = float(np.clip(rng.normal(1.62 + 0.14 * g, 0.06), 1.48, 1.98))
        cols = rng.choice(len(_PALETTE), size=3, replace=False)
        skin = list(_SKIN.values())[int(rng.integers(3))]
        s = Subject("random", sl, stature, shirt=_PALETTE[cols[0]], trousers=_PALETTE[cols[1]],
                    shoes=_PALETTE[cols[2]], skin=skin)
    else:
        raise BodyError(f"subject: expected one of {', '.join(SUBJECTS)}, received {name!r}")
    if skirt:
        s = Subject(s.name, s.sliders, s.stature_m, s.shirt, s.trousers, s.shoes, s.skin, True)
    return s


def _pair(s: float) -> tuple[float, float]:
    return max(0.0, 1.0 - 2.0 * s), max(0.0, 2.0 * s - 1.0)


def _three(s: float) -> dict:
    lo, hi = _pair(s)
    return {"min": lo, "average": 1.0 - abs(2.0 * s - 1.0), "max": hi}


def macro_weights(sliders: dict) -> dict:
    """Weight of each macro target key (see :mod:`.mesh_assets`) for the sliders."""
    for k in MACRO_AXES:
        v = sliders.get(k)
        if v is None or not 0.0 <= float(v) <= 1.0:
            raise BodyError(f"subject slider {k}: expected a number in [0, 1], received {v!r}")
    g = float(sliders["gender"])
    gw = {"female": 1.0 - g, "male": g}
    mw, ww = _three(float(sliders["muscle"])), _three(float(sliders["weight"]))
    hlo, hhi = _pair(float(sliders["height"]))
    plo, phi = _pair(float(sliders["proportions"]))
    out = {}
    for gk, a in gw.items():
        for r in ("african", "asian", "caucasian"):
            out[f"race/{gk}/{r}"] = a / 3.0
        for mk, b in mw.items():
            for wk, c in ww.items():
                base = a * b * c
                stem = f"{gk}/{mk}muscle/{wk}weight"
                out[f"universal/{stem}"] = base
                out[f"height/{stem}/minheight"] = base * hlo
                out[f"height/{stem}/maxheight"] = base * hhi
                out[f"proportions/{stem}/uncommonproportions"] = base * plo
                out[f"proportions/{stem}/idealproportions"] = base * phi
    return {k: v for k, v in out.items() if v > 1e-9}


@dataclass(frozen=True, eq=False)
class MeshBody:
    """A subject's mesh in its rest pose, ready to pose and render.

    Attributes
    ----------
    subject : Subject
    verts : (N, 3) ndarray
        Rest vertices (world metres, facing +x, feet on z = 0) of the rendered triangles only.
    tris : (T, 3) int ndarray
    colors : (T, 3) uint8 ndarray
        Clothing colour per triangle.
    joints : dict
        Rest joint centre (3,) per joint name (:data:`SEGMENTS` ends).
    seg_weights : (N, S) ndarray
        Skin weight of each vertex per segment (rows sum to 1), segments in :data:`SEGMENTS` order.
    rest_bvh_text : str
        The mesh skeleton's rest pose as BVH text (CMU names), to size a body model from it.
    """

    subject: Subject
    verts: np.ndarray
    tris: np.ndarray
    colors: np.ndarray
    joints: dict
    seg_weights: np.ndarray
    rest_bvh_text: str = field(repr=False)

    def rest_bvh(self) -> BvhMotion:
        return parse_bvh(self.rest_bvh_text, scale=1.0, source=f"mesh:{self.subject.name}")


def _bvh_text(names, parents, heads, tails, children) -> str:
    """A one-frame BVH (rest pose, metres, BVH axes) of the mesh skeleton."""
    inv = BVH_TO_WORLD.T                      # world -> BVH axes
    lines = []

    def emit(b, depth):
        ind = "  " * depth
        off = inv @ (heads[b] - (heads[parents[b]] if parents[b] >= 0 else 0.0))
        kind = "ROOT" if parents[b] < 0 else "JOINT"
        lines.append(f"{ind}{kind} {names[b]}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        ch = "6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" if parents[b] < 0 \
            else "3 Zrotation Xrotation Yrotation"
        lines.append(f"{ind}  CHANNELS {ch}")
        if children[b]:
            for c in children[b]:
                emit(c, depth + 1)
        else:
            e = inv @ (tails[b] - heads[b])
            lines.extend([f"{ind}  End Site", f"{ind}  {{", f"{ind}    OFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}",
                          f"{ind}  }}"])
        lines.append(f"{ind}}}")

    root = int(np.flatnonzero(parents < 0)[0])
    lines.append("HIERARCHY")
    emit(root, 0)
    n_ch = 6 + 3 * (len(names) - 1)
    lines += ["MOTION", "Frames: 1", "Frame Time: 0.033333", " ".join(["0"] * n_ch)]
    return "\n".join(lines) + "\n"


_BODIES: dict = {}


def _mesh_body_cached(subject: Subject) -> MeshBody:
    A = load_assets()
    V = A["verts"].astype(np.float64).copy()
    for key, w in macro_weights(subject.sliders).items():
        idx, d = A["targets"][key]
        np.add.at(V, idx, w * d.astype(np.float64))
    tris = A["tris_body"]
    if subject.skirt:
        tris = np.concatenate([tris, A["tris_skirt"]])
    used = np.unique(tris)
    zmin, zmax = V[A["tris_body"]].reshape(-1, 3)[:, 2].min(), V[A["tris_body"]].reshape(-1, 3)[:, 2].max()
    scale = subject.stature_m / (zmax - zmin)
    V = (V - np.array([0.0, 0.0, zmin])) * scale
    ptr, pidx = A["point_ptr"], A["point_idx"]
    points = np.array([V[pidx[a:b]].mean(axis=0) for a, b in zip(ptr[:-1], ptr[1:])])
    names = A["bone_names"]
    parents = A["bone_parents"]
    heads, tails = points[A["bone_heads"]], points[A["bone_tails"]]
    children = [[c for c in range(len(names)) if parents[c] == b] for b in range(len(names))]
    text = _bvh_text(names, parents, heads, tails, children)
    # our joint names on the mesh skeleton (the BVH mapping rules of .retarget)
    from .retarget import map_skeleton

    mot = parse_bvh(text, scale=1.0, source="mesh")
    mapping = map_skeleton(mot)
    rest = mot.rest_positions() @ BVH_TO_WORLD.T
    joints = {k: rest[mot.joint_index(v)] for k, v in mapping.items()}
    missing = [j for s in SEGMENTS.values() for j in s[:2] if j not in joints]
    if missing:
        raise BodyError(f"mesh skeleton: joints {sorted(set(missing))} not found (assets changed?)")
    # segment weights
    seg_names = list(SEGMENTS)
    bone_seg = np.full(len(names), -1)
    for sname, *_rest, bones in _SEGS:
        for b in bones:
            bone_seg[names.index(b)] = seg_names.index(sname)
    if (bone_seg < 0).any():
        raise BodyError(f"mesh skeleton: bones without a segment: {[n for n, s in zip(names, bone_seg) if s < 0]}")
    Wseg = np.zeros((len(V), len(seg_names)))
    sb, sw = A["skin_bones"], A["skin_weights"].astype(np.float64)
    for k in range(sb.shape[1]):
        np.add.at(Wseg, (np.arange(len(V)), bone_seg[sb[:, k]]), sw[:, k])
    tot = Wseg.sum(axis=1, keepdims=True)
    Wseg = np.where(tot > 0, Wseg / np.where(tot > 0, tot, 1.0), 0.0)
    Wseg[tot[:, 0] == 0, seg_names.index("pelvis")] = 1.0
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    T = remap[tris].astype(np.int32)
    colors = _clothing(subject, V, tris, Wseg, seg_names, joints, n_body=len(A["tris_body"]))
    return MeshBody(subject, V[used], T, colors, joints, Wseg[used], text)


def _clothing(subject, V, tris, Wseg, seg_names, joints, *, n_body) -> np.ndarray:
    dom = Wseg[tris].sum(axis=1).argmax(axis=1)
    kind = {"pelvis": "trousers", "spine_lower": "shirt", "spine_upper": "shirt", "neck": "skin", "head": "skin"}
    for side in ("left", "right"):
        kind.update({f"{side}_upper_arm": "shirt", f"{side}_forearm": "skin", f"{side}_hand": "skin",
                     f"{side}_thigh": "trousers", f"{side}_shin": "trousers", f"{side}_foot": "shoes"})
    pal = {"shirt": subject.shirt, "trousers": subject.trousers, "shoes": subject.shoes, "skin": subject.skin}
    col = np.array([pal[kind[seg_names[d]]] for d in dom], dtype=np.uint8)
    # hair: the top and back of the head
    c = V[tris].mean(axis=1)
    head = joints["head"]
    top = joints["head_top"]
    is_head = np.array([seg_names[d] == "head" for d in dom])
    hair = is_head & ((c[:, 2] > head[2] + 0.55 * (top[2] - head[2])) | ((c[:, 0] < head[0] - 0.02) &
                                                                      (c[:, 2] > head[2] - 0.02)))
    col[hair] = _HAIR
    if len(tris) > n_body:          # the skirt takes the trousers' colour
        col[n_body:] = subject.trousers
    return col


def mesh_body(subject: Subject) -> MeshBody:
    """The subject's mesh (cached per subject)."""
    import json

    key = json.dumps(subject.describe(), sort_keys=True)
    if key not in _BODIES:
        if len(_BODIES) > 8:
            _BODIES.clear()
        _BODIES[key] = _mesh_body_cached(subject)
    return _BODIES[key]


@dataclass(frozen=True, eq=False)
class Driver:
    """What moves a mesh: world positions and rotations of our joint names.

    Attributes
    ----------
    P : dict
        Joint name -> (F, 3) world positions.
    R : dict
        Joint name -> (F, 3, 3) world rotations of the frame that moves the joint's children.
    P0, R0 : dict
        The same in the driver's rest pose ((3,), (3, 3)).
    """

    P: dict
    R: dict
    P0: dict
    R0: dict

    @property
    def n_frames(self) -> int:
        return len(next(iter(self.P.values())))


def driver_from_bvh(motion: BvhMotion, mapping: dict, *, shift=(0.0, 0.0, 0.0)) -> Driver:
    """A driver from BVH joints (``mapping``: our name -> BVH joint, :func:`.retarget.map_skeleton`).

    Positions in our world (z up), plus ``shift`` (metres).
    """
    B = BVH_TO_WORLD
    Rw, Pw = motion.world_transforms()
    rest = motion.rest_positions()
    shift = np.asarray(shift, dtype=float)
    P, R, P0, R0 = {}, {}, {}, {}
    for name, bname in mapping.items():
        j = motion.joint_index(bname)
        P[name] = Pw[:, j] @ B.T + shift
        R[name] = B @ Rw[:, j] @ B.T
        P0[name] = B @ rest[j]
        R0[name] = np.eye(3)
    return Driver(P, R, P0, R0)


def driver_from_model(model: BodyModel, X: np.ndarray) -> Driver:
    """A driver from a body model's poses ``X`` (F, D) (its joint frames, :func:`forward_kinematics`)."""
    T = forward_kinematics(model, np.atleast_2d(X))
    T0 = forward_kinematics(model, model.rest_pose())[0]
    P, R, P0, R0 = {}, {}, {}, {}
    for j, name in enumerate(model.joint_names):
        P[name], R[name] = T[:, j, :3, 3], T[:, j, :3, :3]
        P0[name], R0[name] = T0[j, :3, 3], T0[j, :3, :3]
    return Driver(P, R, P0, R0)


def _minrot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations taking directions ``a`` to ``b`` (..., 3) -> (..., 3, 3) (identity where
    either is shorter than 1e-9)."""
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    degenerate = (na < 1e-9) | (nb < 1e-9)
    a = np.where(degenerate, [1.0, 0.0, 0.0], a / np.maximum(na, 1e-12))
    b = np.where(degenerate, [1.0, 0.0, 0.0], b / np.maximum(nb, 1e-12))
    ax = np.cross(a, b)
    s = np.linalg.norm(ax, axis=-1, keepdims=True)
    c = np.sum(a * b, axis=-1, keepdims=True)
    ang = np.arctan2(s, c)
    # antiparallel: any perpendicular axis
    perp = np.cross(a, np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]))
    axis = np.where(s > 1e-9, ax / np.maximum(s, 1e-12), perp / np.linalg.norm(perp, axis=-1, keepdims=True))
    return exp_so3((axis * ang).reshape(-1, 3)).reshape(a.shape[:-1] + (3, 3))


def _frame(P: dict) -> np.ndarray:
    from .retarget import _body_frame

    return _body_frame({k: P[k] for k in ("left_hip", "right_hip", "pelvis", "neck") if k in P})


@dataclass(frozen=True, eq=False)
class _Plan:
    rest: np.ndarray           # (N, 3) mesh rest, turned to the driver's facing
    joints: dict               # turned rest joints
    A: dict                    # segment -> (3, 3) rest alignment
    k: dict                    # segment -> stretch
    u: dict                    # segment -> unit rest direction (turned mesh)
    seg_of: dict               # segment -> the segment whose motion it takes (itself or an ancestor)


def _plan(body: MeshBody, drv: Driver) -> _Plan:
    G = _frame(drv.P0) @ _frame(body.joints).T
    pel = body.joints["pelvis"]
    rest = (body.verts - pel) @ G.T + pel
    J = {k: G @ (v - pel) + pel for k, v in body.joints.items()}
    A, kk, u, seg_of = {}, {}, {}, {}
    for s, (a, b, parent) in SEGMENTS.items():
        d = J[b] - J[a]
        u[s] = d / np.linalg.norm(d)
        if a in drv.P and b in drv.P0:
            dd = drv.P0[b] - drv.P0[a]
            A[s] = _minrot(u[s], dd)
            kk[s] = float(np.clip(np.linalg.norm(dd) / np.linalg.norm(d), 0.7, 1.4)) \
                if np.linalg.norm(dd) > 1e-6 else 1.0
        else:
            A[s] = np.eye(3)
            kk[s] = 1.0
        t = s
        while SEGMENTS[t][0] not in drv.P and SEGMENTS[t][2] is not None:
            t = SEGMENTS[t][2]
        if SEGMENTS[t][0] not in drv.P:
            raise BodyError(f"driver: expected at least the pelvis, received joints {sorted(drv.P)}")
        seg_of[s] = t
    return _Plan(rest, J, A, kk, u, seg_of)


def segment_maps(body: MeshBody, drv: Driver, frame: int, plan: _Plan | None = None):
    """Affine maps ``(L (S, 3, 3), t (S, 3))`` of every segment at ``frame``: ``x -> L x + t``
    (in the coordinates of the turned rest mesh, see :func:`pose_mesh`)."""
    plan = plan or _plan(body, drv)
    S = len(SEGMENTS)
    L = np.empty((S, 3, 3))
    t = np.empty((S, 3))
    own = {}
    for i, (s, (a, b, _p)) in enumerate(SEGMENTS.items()):
        if plan.seg_of[s] != s:
            continue
        Rr = drv.R[a][frame] @ drv.R0[a].T @ plan.A[s]
        if b in drv.P:
            Rr = _minrot(Rr @ plan.u[s], drv.P[b][frame] - drv.P[a][frame]) @ Rr
        Sm = np.eye(3) + (plan.k[s] - 1.0) * np.outer(plan.u[s], plan.u[s])
        Li = Rr @ Sm
        own[s] = (Li, drv.P[a][frame] - Li @ plan.joints[a])
    for i, s in enumerate(SEGMENTS):
        L[i], t[i] = own[plan.seg_of[s]]
    return L, t


def pose_mesh(body: MeshBody, drv: Driver, frame: int, *, plan: _Plan | None = None):
    """Posed vertices and joint centres of one frame (linear-blend skinning, see the module docstring).

    Returns
    -------
    verts : (N, 3) ndarray
        World metres, ``body.tris`` index them.
    markers : (M, 3) ndarray
        Joint centres of :data:`MESH_MARKERS`: each the rest joint mapped by its segment.
    """
    plan = plan or _plan(body, drv)
    L, t = segment_maps(body, drv, frame, plan)
    X = plan.rest
    out = np.zeros_like(X)
    W = body.seg_weights
    for i in range(L.shape[0]):
        w = W[:, i]
        nz = w > 0
        if nz.any():
            out[nz] += w[nz, None] * (X[nz] @ L[i].T + t[i])
    head_seg = {a: i for i, (a, _b, _p) in enumerate(SEGMENTS.values())}
    seg_names = list(SEGMENTS)
    markers = np.empty((len(MESH_MARKERS), 3))
    for m, name in enumerate(MESH_MARKERS):
        i = seg_names.index(plan.seg_of[seg_names[head_seg[name]]])
        markers[m] = L[i] @ plan.joints[name] + t[i]
    return out, markers


def joint_paths(body: MeshBody, drv: Driver) -> dict:
    """The driver's motion on the mesh's own skeleton: world positions ``(F, 3)`` of every joint of
    :data:`SEGMENTS` with each segment turned as :func:`segment_maps` turns it (towards the driver's next joint,
    twisted as the driver's joint) but keeping the mesh's own rest offsets, not the driver's lengths.

    The chain starts at the mid-hip point: the mesh pelvis is placed so its hips' midpoint is the driver's, so the
    legs stand where the driver's stand whatever the two skeletons call the pelvis (CMU's ``Hips`` joint sits about
    11 cm above its hip joints, the mesh's at their height). Joints the driver lacks follow their parent segment.
    """
    pl = _plan(body, drv)
    J = pl.joints
    rot, out = {}, {}
    for s, (a, b, parent) in SEGMENTS.items():              # parents come before their children
        if pl.seg_of[s] != s:
            rot[s] = rot[pl.seg_of[s]]
        else:
            Rr = drv.R[a] @ drv.R0[a].T @ pl.A[s]
            if b in drv.P:
                Rr = _minrot(Rr @ pl.u[s], drv.P[b] - drv.P[a]) @ Rr
            rot[s] = Rr
        if parent is None:
            hips = 0.5 * (drv.P["left_hip"] + drv.P["right_hip"])
            out[a] = hips - rot[s] @ (0.5 * (J["left_hip"] + J["right_hip"]) - J[a])
        else:
            pa = SEGMENTS[parent][0]
            out[a] = out[pa] + rot[parent] @ (J[a] - J[pa])
    for s, (a, b, _parent) in SEGMENTS.items():
        if b not in out:
            out[b] = out[a] + rot[s] @ (J[b] - J[a])
    return out


def plan(body: MeshBody, drv: Driver) -> _Plan:
    """The per-sequence part of :func:`pose_mesh` (mesh turned to the driver, rest alignments)."""
    return _plan(body, drv)


def rest_bvh(body: MeshBody) -> BvhMotion:
    """The mesh skeleton's rest pose as a one-frame BVH (CMU joint names)."""
    return body.rest_bvh()
