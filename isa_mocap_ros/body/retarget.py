"""Retargeting BVH motion onto the body models: skeleton mapping, model sizing, pose fitting.

Sources: the models of EA-vs-PF Table 1 / ISA §13.4.2 (see :mod:`.model`); the fit minimises the
squared distances between the model's joint centres and the BVH joints they stand for — the
marker error of EA-vs-PF Eq. 20 — by projected Levenberg-Marquardt, batched over all frames.

Mapping (:func:`map_skeleton`) is structural, helped by names: the wrists (``LeftWrist``,
``LeftHand``, ``lHand``...) and ankles (``LeftAnkle``, ``LeftFoot``, ``lFoot``...) are found by
name and side (``Left*``/``L*``/``*_l``, ``Right*``/``R*``/``*_r``); elbows, shoulders, knees and
hips are their nearest ancestors at a distinct position; the pelvis is the lowest common
ancestor of the hips, the upper spine that of the left shoulder and the head; the lower spine is
the pelvis's child towards it; the neck is the first joint named ``*neck*`` below the upper spine
at a distinct position; the end sites (head top, hands, toes) follow the first child down to the
first point 2 cm away. This covers CMU (``Hips/LHipJoint/LeftUpLeg/...``), Motion-Builder
(``Hips/Spine/LeftUpLeg/LeftLeg/LeftFoot/...``) and Poser/Daz (``hip/abdomen/chest/lCollar/
lShldr/lForeArm/lHand/lThigh/lShin/lFoot``) layouts.

Fit (:func:`retarget`): the root is initialised per frame from the hip line and the spine, joint
angles at zero; then Levenberg-Marquardt on all frames at once (analytic Jacobian,
:func:`.kinematics.position_jacobian`), clipped to the joint limits. Further passes restart every
frame from its predecessor's solution (warm start) and keep whichever fit is better; root
frames where a shoulder or hip ends at a twist or hinge limit are restarted on the other twist
branch (``z ± π``, hinge negated) and refitted; root rotation vectors are finally made continuous over time (``w`` vs. ``w (1 - 2π/‖w‖)``).
"""
from __future__ import annotations

import re
import time
from dataclasses import dataclass
from types import MappingProxyType
from typing import Callable, Mapping

import numpy as np

from ..geometry import exp_so3, log_so3
from .bvh import BVH_TO_WORLD, BvhMotion
from .kinematics import _position_jacobian_dk, joint_positions
from .model import BodyError, BodyModel, default_shape, make_model

__all__ = ["map_skeleton", "model_from_bvh", "retarget", "fit_positions", "RetargetReport"]

_PREFIXES = ("mixamorig", "bip01", "bip001", "character1", "characters", "skeleton", "armature")
_WRIST_PARTS = ("wrist", "hand")
_ANKLE_PARTS = ("ankle", "foot")
_MIN_SEGMENT_M = 0.02

_UPPER_ROLES = ("spine_lower", "spine_upper", "neck", "head", "left_shoulder", "left_elbow",
                "left_wrist", "right_shoulder", "right_elbow", "right_wrist")
_LOWER_ROLES = ("pelvis", "left_hip", "left_knee", "left_ankle", "right_hip", "right_knee", "right_ankle")


def _normalize(name: str) -> tuple[str | None, str]:
    """(side, part) from a joint name: side 'left'/'right'/None, part lower-case alphanumeric."""
    raw = name.split(":")[-1]
    low = raw.lower()
    side = None
    m = re.search(r"[._ ]([lr])$", low)
    if m:
        side = "left" if m.group(1) == "l" else "right"
        low = low[: m.start()]
    norm = re.sub(r"[^a-z0-9]", "", low)
    for p in _PREFIXES:
        if norm.startswith(p) and len(norm) > len(p):
            norm = norm[len(p):]
    if side is None:
        for s in ("left", "right"):
            if norm.startswith(s):
                return s, norm[len(s):]
            if norm.endswith(s) and len(norm) > len(s):
                return s, norm[: -len(s)]
        if len(raw) > 1 and raw[0] in "lLrR" and (raw[1].isupper() or raw[1] in "_.") or \
                (len(norm) > 1 and norm[0] in "lr" and norm[1:] in _KNOWN_PARTS):
            return ("left" if raw[0] in "lL" else "right"), re.sub(r"[^a-z0-9]", "", raw[1:].lower())
    return side, norm


_KNOWN_PARTS = {"hand", "wrist", "foot", "ankle", "shldr", "shoulder", "forearm", "elbow", "collar",
                "thigh", "shin", "knee", "hip", "uparm", "arm", "leg", "upleg", "toe", "toebase"}


def _find(motion: BvhMotion, side: str, parts) -> int | None:
    info = [_normalize(n) for n in motion.joint_names]
    for part in parts:
        for j, (s, p) in enumerate(info):
            if s == side and p == part and not motion.joint_names[j].endswith("_end"):
                return j
    return None


def _ancestors(motion: BvhMotion, j: int) -> list[int]:
    out = []
    p = motion.parents[j]
    while p >= 0:
        out.append(int(p))
        p = motion.parents[p]
    return out


def _distinct_ancestor(motion: BvhMotion, rest: np.ndarray, j: int) -> int | None:
    for a in _ancestors(motion, j):
        if np.linalg.norm(rest[a] - rest[j]) >= _MIN_SEGMENT_M:
            return a
    return None


def _end_point(motion: BvhMotion, rest: np.ndarray, j: int) -> int | None:
    """Follow the first child until a point at least 2 cm from joint j."""
    k = j
    while True:
        kids = [c for c in range(len(motion.parents)) if motion.parents[c] == k]
        if not kids:
            return None
        k = kids[0]
        if np.linalg.norm(rest[k] - rest[j]) >= _MIN_SEGMENT_M:
            return k


def map_skeleton(motion: BvhMotion, *, lower_body_only: bool = False) -> dict[str, str]:
    """Map our joint names to BVH joint names (see the module docstring for the rules).

    Parameters
    ----------
    motion : BvhMotion
    lower_body_only : bool
        Only require the pelvis and legs (enough for the 18-DOF model).

    Returns
    -------
    mapping : dict
        ``our joint -> BVH joint`` for the joints found; end sites (``head_top``, ``*_hand``,
        ``*_toe``) only where the BVH has them.

    Raises
    ------
    BodyError
        Naming the roles that could not be found and the BVH's joint names.
    """
    rest = motion.rest_positions()
    found: dict[str, int] = {}
    missing: list[str] = []

    def need(role, j):
        if j is None:
            missing.append(role)
        else:
            found[role] = j
        return j

    for side in ("left", "right"):
        ank = need(f"{side}_ankle", _find(motion, side, _ANKLE_PARTS))
        knee = need(f"{side}_knee", None if ank is None else _distinct_ancestor(motion, rest, ank))
        need(f"{side}_hip", None if knee is None else _distinct_ancestor(motion, rest, knee))
    if "left_hip" in found and "right_hip" in found:
        common = [a for a in _ancestors(motion, found["left_hip"]) if a in set(_ancestors(motion, found["right_hip"]))]
        need("pelvis", common[0] if common else None)
    else:
        missing.append("pelvis")
    # the upper body (required unless lower_body_only)
    upper_missing: list[str] = []
    upper: dict[str, int] = {}
    for side in ("left", "right"):
        wr = _find(motion, side, _WRIST_PARTS)
        el = None if wr is None else _distinct_ancestor(motion, rest, wr)
        sh = None if el is None else _distinct_ancestor(motion, rest, el)
        for role, j in ((f"{side}_wrist", wr), (f"{side}_elbow", el), (f"{side}_shoulder", sh)):
            if j is None:
                upper_missing.append(role)
            else:
                upper[role] = j
    heads = [j for j, n in enumerate(motion.joint_names) if _normalize(n)[1] == "head" and not n.endswith("_end")]
    head = heads[0] if heads else None
    if head is None:
        upper_missing.append("head")
    else:
        upper["head"] = head
    if head is not None and "left_shoulder" in upper and "pelvis" in found:
        hs = _ancestors(motion, head)
        common = [a for a in _ancestors(motion, upper["left_shoulder"]) if a in set(hs)]
        su = common[0] if common else None
        if su is None or su == found["pelvis"]:
            upper_missing.append("spine_upper")
        else:
            upper["spine_upper"] = su
            path = [su] + _ancestors(motion, su)
            if found["pelvis"] in path:
                below = path[: path.index(found["pelvis"])]
                upper["spine_lower"] = below[-1]
            else:
                upper_missing.append("spine_lower")
            chain = list(reversed(hs[: hs.index(su)])) if su in hs else []
            necks = [j for j in chain if "neck" in _normalize(motion.joint_names[j])[1]
                     and np.linalg.norm(rest[j] - rest[su]) >= _MIN_SEGMENT_M]
            neck = necks[0] if necks else (chain[0] if chain else None)
            if neck is None:
                upper_missing.append("neck")
            else:
                upper["neck"] = neck
    else:
        upper_missing += [r for r in ("spine_upper", "spine_lower", "neck") if r not in upper]
    found.update(upper)
    if not lower_body_only:
        missing += upper_missing
    if missing:
        raise BodyError(f"unknown joint layout in {motion.source}: could not find {', '.join(sorted(set(missing)))} "
                        f"among the BVH joints ({', '.join(motion.joint_names)}); expected CMU, Motion-Builder "
                        "or Poser-style names (Hips/LeftUpLeg/LeftLeg/LeftFoot/Spine/Neck/Head/LeftArm/"
                        "LeftForeArm/LeftHand ...)")
    for role, src in (("head_top", "head"), ("left_hand", "left_wrist"), ("right_hand", "right_wrist"),
                      ("left_toe", "left_ankle"), ("right_toe", "right_ankle")):
        if src in found:
            e = _end_point(motion, rest, found[src])
            if e is not None:
                found[role] = e
    return {k: motion.joint_names[v] for k, v in found.items()}


# ---------------------------------------------------------------------------------------------
# Model sizing
# ---------------------------------------------------------------------------------------------
_LIMB = {"left_elbow", "left_wrist", "left_hand", "left_knee", "left_ankle",
         "right_elbow", "right_wrist", "right_hand", "right_knee", "right_ankle"}


def _body_frame(P: dict[str, np.ndarray]) -> np.ndarray:
    """Columns (forward, left, up) from the hip line and (if present) the spine."""
    left = P["left_hip"] - P["right_hip"]
    if "neck" in P:
        up = P["neck"] - P["pelvis"]
    else:
        up = np.array([0.0, 0.0, 1.0]) if left.ndim == 1 else np.broadcast_to([0.0, 0.0, 1.0], left.shape)
    left = left / np.linalg.norm(left, axis=-1, keepdims=True)
    up = up - np.sum(up * left, axis=-1, keepdims=True) * left
    up = up / np.linalg.norm(up, axis=-1, keepdims=True)
    fwd = np.cross(left, up)
    return np.stack([fwd, left, up], axis=-1)


def model_from_bvh(motion: BvhMotion, dof: int = 39, *, mapping: Mapping[str, str] | None = None) -> BodyModel:
    """A body model sized from the BVH skeleton.

    Rigid offsets (pelvis → hips, spine, neck, head, shoulders, feet) are the BVH rest vectors
    between the mapped joints expressed in the body frame (forward, left, up); limb segments
    (upper arm, forearm, hand, thigh, shin) keep the BVH length along the canonical straight-down
    direction of our rest pose. Missing end sites and the capsule radii are scaled from the
    default shape by the ratio of hip-to-neck / leg lengths.

    Parameters
    ----------
    motion : BvhMotion
    dof : {39, 28, 18}
    mapping : mapping, optional
        From :func:`map_skeleton` (computed when omitted).

    Returns
    -------
    BodyModel
    """
    if dof not in (18, 28, 39):
        raise BodyError(f"dof: expected 18, 28 or 39, got {dof!r}")
    if mapping is None:
        mapping = map_skeleton(motion, lower_body_only=dof == 18)
    rest = motion.rest_positions() @ BVH_TO_WORLD.T
    P = {k: rest[motion.joint_index(v)] for k, v in mapping.items()}
    B = _body_frame(P)
    Q = {k: B.T @ (p - P["pelvis"]) for k, p in P.items()}
    shape = default_shape()
    d_off = shape["offsets"]
    model_default = make_model(39 if dof != 18 else 18)
    offsets = {}
    for j, name in enumerate(model_default.joint_names[1:], start=1):
        parent = model_default.joint_names[model_default.parents[j]]
        if name in Q and parent in Q:
            vec = Q[name] - Q[parent]
            if name in _LIMB:
                vec = np.array([0.0, 0.0, -np.linalg.norm(vec)])
            offsets[name] = vec
    leg = np.linalg.norm(offsets["left_knee"]) + np.linalg.norm(offsets["left_ankle"])
    leg0 = np.linalg.norm(d_off["left_knee"]) + np.linalg.norm(d_off["left_ankle"])
    ratio = leg / leg0
    for name in model_default.joint_names[1:]:
        if name not in offsets and name in d_off:       # not the end sites of capsules off their joint line
            offsets[name] = np.asarray(d_off[name]) * ratio
    for name in d_off:  # joints of the full tree the 18-DOF model does not use
        offsets.setdefault(name, np.asarray(d_off[name]) * ratio)
    radii = {k: np.asarray(v) * ratio for k, v in shape["radii"].items()}
    stem = str(motion.source).rsplit("/", 1)[-1].rsplit(".", 1)[0] or "bvh"
    return make_model(dof, shape={"name": stem, "offsets": offsets, "radii": radii,
                                  "axis_offsets": shape["axis_offsets"]})


# ---------------------------------------------------------------------------------------------
# Fitting
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RetargetReport:
    """Residual of a retargeting (distances between BVH joints and the model's joints).

    Attributes
    ----------
    mean_mm : float
        Mean over frames and compared joints.
    max_frame_mm : float
        Largest per-frame mean.
    max_mm : float
        Largest single joint distance.
    per_joint_mm : mapping str -> float
        Mean per compared model joint.
    per_frame_mm : (F,) ndarray
    joints : tuple of str
        Compared model joints (with their BVH counterparts in ``mapping``).
    mapping : mapping str -> str
    n_frames : int
    seconds : float
        Wall-clock time of the fit.
    """

    mean_mm: float
    max_frame_mm: float
    max_mm: float
    per_joint_mm: Mapping
    per_frame_mm: np.ndarray
    joints: tuple
    mapping: Mapping
    n_frames: int
    seconds: float

    def __str__(self) -> str:
        worst = max(self.per_joint_mm, key=self.per_joint_mm.get)
        return (f"retarget residual over {self.n_frames} frames, {len(self.joints)} joints: mean "
                f"{self.mean_mm:.1f} mm, worst frame {self.max_frame_mm:.1f} mm, max {self.max_mm:.1f} mm "
                f"(worst joint {worst}: {self.per_joint_mm[worst]:.1f} mm), {self.seconds:.2f} s")


def _init_root(model: BodyModel, targets: dict[str, np.ndarray]) -> np.ndarray:
    rest = joint_positions(model, np.zeros(model.dof))[0]
    Prest = {n: rest[model.joint_index(n)] for n in targets}
    B_rest = _body_frame(Prest)
    B = _body_frame(targets)
    R = B @ B_rest.T
    F = next(iter(targets.values())).shape[0]
    X = np.zeros((F, model.dof))
    X[:, :3] = targets["pelvis"]
    X[:, 3:6] = log_so3(R)
    return X


def _lm(model, X, idx, target, *, iters, reg, lam0=1e-2):
    """Projected Levenberg-Marquardt over the frames of X (each frame independent).

    Cost per frame: ``Σ_k ‖p_k(x) - target_k‖² + reg ‖q‖²`` (q: joint angles; the small Tikhonov
    term keeps DOF the joint positions cannot see, like a twist about a bone, at zero).
    """
    F, D = X.shape
    lower, upper = model.lower, model.upper
    lam = np.full(F, lam0)
    R_reg = np.zeros(D)
    R_reg[6:] = reg

    def cost_of(Xc):
        P = joint_positions(model, Xc)[:, idx]
        return np.sum((P - target) ** 2, axis=(1, 2)) + np.sum(R_reg * Xc ** 2, axis=1)

    def linearize(Xc):
        P, JacDK = _position_jacobian_dk(model, Xc, idx)
        A = JacDK.reshape(F, D, -1)                                          # (F, D, 3K) = Jᵀ
        r = (P - target).reshape(F, -1, 1)
        H = A @ np.swapaxes(A, 1, 2) + np.diag(R_reg)                      # JᵀJ + reg I
        g = (A @ r)[..., 0] + R_reg * Xc                                     # Jᵀr + reg q
        return H, g

    cost = cost_of(X)
    H, g = linearize(X)
    eye = np.eye(D)
    for _ in range(iters):
        diag = np.einsum("fii->fi", H)
        step = -np.linalg.solve(H + (lam[:, None] * (diag + 1e-6))[:, :, None] * eye, g[..., None])[..., 0]
        Xn = X.copy()
        Xn[:, :3] += step[:, :3]
        Xn[:, 3:6] = log_so3(exp_so3(step[:, 3:6]) @ exp_so3(X[:, 3:6]))
        Xn[:, 6:] = np.clip(X[:, 6:] + step[:, 6:], lower[6:], upper[6:])
        new_cost = cost_of(Xn)
        better = new_cost < cost
        X = np.where(better[:, None], Xn, X)
        cost = np.where(better, new_cost, cost)
        lam = np.clip(np.where(better, lam * 0.3, lam * 10.0), 1e-7, 1e7)
        H, g = linearize(X)
    return X, cost


def _flip_limbs(model: BodyModel, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Candidates on the other twist branch for limbs stuck at a limit.

    A 3-axis shoulder/hip (y, x, z) followed by a y hinge reaches the same elbow/wrist (knee/ankle)
    points with ``z ± π`` and the hinge negated; a fit that started on the wrong branch ends at a
    twist or hinge limit. Returns the candidate poses and a mask of frames that changed.
    """
    Xc = X.copy()
    changed = np.zeros(len(X), dtype=bool)
    for side in ("left", "right"):
        for prox, hinge in (("shoulder", "elbow"), ("hip", "knee")):
            try:
                z = model.dof_names.index(f"{side}_{prox}_z")
                h = model.dof_names.index(f"{side}_{hinge}_y")
            except ValueError:
                continue
            at = np.zeros(len(X), dtype=bool)
            for d in (z, h):
                at |= (X[:, d] <= model.lower[d] + 1e-6) | (X[:, d] >= model.upper[d] - 1e-6)
            zf = X[:, z] - np.pi * np.sign(X[:, z] + 1e-12)
            Xc[at, z] = np.clip(zf[at], model.lower[z], model.upper[z])
            Xc[at, h] = np.clip(-X[at, h], model.lower[h], model.upper[h])
            changed |= at
    return Xc, changed


def _refit_flipped(model, X, cost, idx, target, *, iters, reg):
    """Refit frames stuck at a limb limit from the other twist branch; keep what is better."""
    Xf, changed = _flip_limbs(model, X)
    if changed.any():
        Xf, cf = _lm(model, Xf[changed], idx, target[changed], iters=iters, reg=reg)
        better = cf < cost[changed] - 1e-12
        sel = np.flatnonzero(changed)[better]
        X = X.copy()
        cost = cost.copy()
        X[sel] = Xf[better]
        cost[sel] = cf[better]
    return X, cost


def _unwrap_rotvecs(W: np.ndarray) -> np.ndarray:
    """Make a rotation-vector sequence continuous (choose w or its 2π-complement per frame)."""
    W = W.copy()
    for t in range(1, len(W)):
        th = np.linalg.norm(W[t])
        if th < 1e-9:
            continue
        alt = W[t] * (1.0 - 2.0 * np.pi / th)
        if np.linalg.norm(alt - W[t - 1]) < np.linalg.norm(W[t] - W[t - 1]):
            W[t] = alt
    return W


def retarget(motion: BvhMotion, model: BodyModel, *, iters: int = 25, warm_iters: int = 10,
             warm_rounds: int = 4, reg: float = 1e-4,
             progress: Callable[[int, int], None] | None = None) -> tuple[np.ndarray, RetargetReport]:
    """Convert every BVH frame to a pose vector of ``model``.

    Parameters
    ----------
    motion : BvhMotion
    model : BodyModel
        Usually ``model_from_bvh(motion, dof)``; any model with the same joint names works.
    iters : int
        Levenberg-Marquardt iterations of the first (batched) pass.
    reg : float
        Weight of the ``‖q‖²`` regulariser on the joint angles (m² per rad²).
    warm_iters : int
        Iterations of the warm-started pass (every frame from its predecessor's solution;
        0 disables it).
    warm_rounds : int
        Maximum number of warm-started passes (each propagates good fits one frame further;
        stops early when no frame improves by more than 0.1 %).
    progress : callable(done, total), optional
        Called after each stage (initialisation, each pass, report).

    Returns
    -------
    X : (F, D) ndarray
        Poses (root rotation vectors continuous over time).
    report : RetargetReport
    """
    mapping = map_skeleton(motion, lower_body_only=model.dof == 18)
    mapping = {k: v for k, v in mapping.items() if k in model.joint_names}
    W = motion.world_positions()
    targets = {n: W[:, motion.joint_index(b)] for n, b in mapping.items()}
    return fit_positions(model, targets, iters=iters, warm_iters=warm_iters, warm_rounds=warm_rounds, reg=reg,
                         progress=progress, mapping=mapping)


def fit_positions(model: BodyModel, targets: Mapping[str, np.ndarray], *, iters: int = 25, warm_iters: int = 10,
                  warm_rounds: int = 4, reg: float = 1e-4, progress: Callable[[int, int], None] | None = None,
                  mapping: Mapping[str, str] | None = None) -> tuple[np.ndarray, RetargetReport]:
    """Poses of ``model`` whose joint centres meet ``targets`` (the fit of :func:`retarget`).

    Parameters
    ----------
    model : BodyModel
    targets : mapping str -> (F, 3) ndarray
        World positions (metres, z up) per model joint name; names the model lacks are ignored.
        Must contain ``pelvis`` and both hips.
    mapping : mapping str -> str, optional
        Where each target came from (kept in the report; default: the names themselves).

    Other parameters and the returns are :func:`retarget`'s.
    """
    t0 = time.perf_counter()
    names = tuple(n for n in model.joint_names if n in targets)
    if "pelvis" not in names:
        raise BodyError(f"model: no model joint matches the BVH skeleton ({model.joint_names})")
    idx = np.array([model.joint_index(n) for n in names])
    target = np.stack([np.asarray(targets[n], dtype=float) for n in names], axis=1)
    mapping = {n: n for n in names} if mapping is None else {n: mapping[n] for n in names}
    total = 4
    X = _init_root(model, {n: target[:, k] for k, n in enumerate(names)})
    if progress:
        progress(1, total)
    X, cost = _lm(model, X, idx, target, iters=iters, reg=reg)
    if progress:
        progress(2, total)
    X, cost = _refit_flipped(model, X, cost, idx, target, iters=iters, reg=reg)
    if warm_iters > 0 and len(X) > 1:
        for _ in range(warm_rounds):
            Xw = np.vstack([X[:1], X[:-1]])
            Xw[:, :3] += target[:, 0] - target[np.r_[0, np.arange(len(X) - 1)], 0]
            Xw, cw = _lm(model, Xw, idx, target, iters=warm_iters, reg=reg)
            better = cw < cost * (1.0 - 1e-3)
            X = np.where(better[:, None], Xw, X)
            cost = np.where(better, cw, cost)
            if not better.any():
                break
        X, cost = _refit_flipped(model, X, cost, idx, target, iters=iters, reg=reg)
    if progress:
        progress(3, total)
    X[:, 3:6] = _unwrap_rotvecs(X[:, 3:6])
    dist = np.linalg.norm(joint_positions(model, X)[:, idx] - target, axis=-1) * 1000.0
    report = RetargetReport(
        mean_mm=float(dist.mean()), max_frame_mm=float(dist.mean(1).max()), max_mm=float(dist.max()),
        per_joint_mm=MappingProxyType({n: float(dist[:, k].mean()) for k, n in enumerate(names)}),
        per_frame_mm=dist.mean(1), joints=names, mapping=MappingProxyType(dict(mapping)),
        n_frames=len(X), seconds=time.perf_counter() - t0)
    if progress:
        progress(4, total)
    return X, report
