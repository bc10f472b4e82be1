"""Tracking accuracy: joint-centre error (EA-vs-PF Eq. 20) and joint-angle errors (ISA §13.4.2).

Sources: yeguas_ea_vs_pf_mocap Eq. 20, the HumanEva error of a pose estimate ``X̂`` against the
ground truth ``X``, both given as ``n`` marker (joint-centre) positions::

    d(X, X̂) = (1/n) Σ_i ‖x_i − x̂_i‖                                             (20)

computed here per frame (:func:`frame_errors_mm`) and averaged over the frames of a sequence
(:func:`mpjpe_mm`); and gall_isa_introduction §13.4.2, which reports the root-mean-square error of
the two knee angles against a marker-based system (:func:`knee_rmse_deg`: over all frames and both
knees, ``sqrt(mean((q̂ − q)²))``, in degrees).

All functions take positions in metres and return millimetres, take angles in radians and return
degrees, and raise :class:`MetricsError` (a ``ValueError``) naming the argument, the expected and
the received shape for bad input.
"""
from __future__ import annotations

import warnings
from typing import Mapping

import numpy as np

__all__ = ["MetricsError", "joint_errors_mm", "frame_errors_mm", "mpjpe_mm", "max_frame_error_mm",
           "knee_rmse_deg", "knee_errors_deg", "per_joint_angle_rmse_deg", "angle_difference",
           "shared_markers", "marker_positions", "score_markers", "knee_flexion_from_points",
           "body_frames", "offset_removed_errors_mm", "heading_errors_deg"]


class MetricsError(ValueError):
    """Bad input to a metric (names the argument, the expected and the received value)."""


def _points(name: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.ndim != 3 or a.shape[-1] != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise MetricsError(f"{name}: expected joint positions of shape (F, M, 3) with F, M >= 1, "
                           f"received shape {a.shape}")
    if not np.all(np.isfinite(a)):
        f, m, _ = np.argwhere(~np.isfinite(a))[0]
        raise MetricsError(f"{name}: expected finite positions, received {a[f, m].tolist()} at frame {f}, "
                           f"marker {m}")
    return a


def _points_missing(name: str, value) -> np.ndarray:
    """As :func:`_points`, but NaN marks a missing point (a peer's marker file); inf is still refused."""
    a = np.asarray(value, dtype=float)
    if a.ndim != 3 or a.shape[-1] != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise MetricsError(f"{name}: expected joint positions of shape (F, M, 3) with F, M >= 1, "
                           f"received shape {a.shape}")
    if np.any(np.isinf(a)):
        f, m, _ = np.argwhere(np.isinf(a))[0]
        raise MetricsError(f"{name}: expected finite positions or NaN (missing), received {a[f, m].tolist()} at "
                           f"frame {f}, marker {m}")
    return a


def _pair(pred_joints, true_joints, *, missing: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The two point arrays, checked (``missing``: NaN marks a missing reference point)."""
    P = _points("pred_joints", pred_joints)
    T = (_points_missing if missing else _points)("true_joints", true_joints)
    if P.shape != T.shape:
        raise MetricsError(f"true_joints: expected the shape of pred_joints {P.shape}, received {T.shape}")
    return P, T


def joint_errors_mm(pred_joints, true_joints) -> np.ndarray:
    """Euclidean error of every marker in every frame.

    Parameters
    ----------
    pred_joints, true_joints : (F, M, 3) array_like
        Estimated and true joint centres, metres, same markers in the same order.

    Returns
    -------
    (F, M) ndarray
        ``‖x_i − x̂_i‖`` in millimetres.
    """
    P, T = _pair(pred_joints, true_joints)
    return 1e3 * np.linalg.norm(P - T, axis=-1)


def body_frames(true_joints, left_hip: int, right_hip: int) -> np.ndarray:
    """Per-frame body axes ``(F, 3, 3)`` from the true hips, world z up: columns ``lateral`` (the
    horizontal direction from the right hip to the left), ``forward`` (``lateral × up``: the way a body whose
    left is ``lateral`` faces) and ``up``.

    A frame whose hips are vertically aligned (no horizontal hip axis) or missing (NaN) takes the previous frame's axes
    (the world axes if it is the first). Used to express a joint's offset in the body, so that an offset of
    definition (the same joint placed differently by two skeletons) stays one vector while the body turns.
    """
    T = _points_missing("true_joints", true_joints)
    a = T[:, left_hip] - T[:, right_hip]
    a[:, 2] = 0.0
    n = np.linalg.norm(a, axis=-1)
    R = np.empty((T.shape[0], 3, 3))
    last = np.eye(3)
    for f in range(T.shape[0]):
        if n[f] > 1e-6:                         # False for NaN (a missing hip)
            x = a[f] / n[f]
            last = np.column_stack([x, np.cross(x, [0.0, 0.0, 1.0]), [0.0, 0.0, 1.0]])
        R[f] = last
    return R


def heading_errors_deg(pred_joints, true_joints, left_hip: int, right_hip: int) -> np.ndarray:
    """Per frame, the angle ``(F,)`` in degrees (0-180) between the estimated and the true horizontal hip
    axes (right hip to left hip): near 180° the body is tracked facing backwards (a silhouette seen from the
    front looks nearly like one seen from the back); NaN where a reference hip is missing."""
    P, T = _pair(pred_joints, true_joints, missing=True)
    a = (P[:, left_hip] - P[:, right_hip])[:, :2]
    b = (T[:, left_hip] - T[:, right_hip])[:, :2]
    c = np.sum(a * b, axis=1) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-12)
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def offset_removed_errors_mm(pred_joints, true_joints, frames=None) -> tuple[np.ndarray, np.ndarray]:
    """Joint errors with each joint's mean offset removed: the error of the motion, not of where a
    skeleton puts its joint centres.

    Two skeletons may define a joint at different places in the body (a mesh rig's hip joint 1-2 cm below
    its pelvis, a capsule model's 5 cm; a peer system's keypoints): a constant offset in the body then adds
    to every frame's Eq. 20 error. Here each joint's error vector ``x̂_i − x_i`` is expressed in the body
    frame ``frames`` (:func:`body_frames`; None = the world axes), averaged over the frames, and that mean
    offset ``o_i`` is removed: ``‖x̂_i − x_i − R o_i‖``.

    Parameters
    ----------
    pred_joints, true_joints : (F, M, 3) array_like
        Estimated and true joint centres, metres, same markers in the same order.
    frames : (F, 3, 3) array_like, optional
        Body axes (columns) per frame.

    Returns
    -------
    errors : (F, M) ndarray
        Millimetres, after removing the offsets.
    offsets : (M, 3) ndarray
        The mean offsets ``o_i`` in the body frame (lateral, forward, up), millimetres.

    A missing reference point (NaN, a peer's file) is left out of its joint's mean offset, and its error is
    NaN; a joint missing in every frame has a NaN offset.

    Examples
    --------
    >>> T = np.zeros((2, 1, 3)); P = T.copy(); P[:, 0, 2] = 0.05   # constant 50 mm offset
    >>> offset_removed_errors_mm(P, T)[0].tolist()
    [[0.0], [0.0]]
    """
    P, T = _pair(pred_joints, true_joints, missing=True)
    D = P - T
    if frames is None:
        R = np.broadcast_to(np.eye(3), (P.shape[0], 3, 3))
    else:
        R = np.asarray(frames, dtype=float)
        if R.shape != (P.shape[0], 3, 3):
            raise MetricsError(f"frames: expected shape ({P.shape[0]}, 3, 3), received {R.shape}")
    local = np.einsum("fji,fmj->fmi", R, D)        # R^T d
    ok = np.all(np.isfinite(local), axis=-1)
    n = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        o = np.where(ok[..., None], local, 0.0).sum(axis=0) / n[:, None]
    o[n == 0] = np.nan
    rest = D - np.einsum("fij,mj->fmi", R, o)
    return 1e3 * np.linalg.norm(rest, axis=-1), 1e3 * o


def frame_errors_mm(pred_joints, true_joints) -> np.ndarray:
    """Eq. 20 per frame: the mean joint-centre error ``(F,)`` in millimetres."""
    return joint_errors_mm(pred_joints, true_joints).mean(axis=1)


def mpjpe_mm(pred_joints, true_joints) -> float:
    """Mean joint-centre error of a sequence: Eq. 20 averaged over the ``F`` frames, millimetres.

    Examples
    --------
    >>> T = np.zeros((2, 2, 3)); P = T.copy(); P[1, :, 0] = 0.01   # frame 1 off by 10 mm
    >>> mpjpe_mm(P, T)
    5.0
    """
    return float(frame_errors_mm(pred_joints, true_joints).mean())


def max_frame_error_mm(pred_joints, true_joints) -> float:
    """Largest per-frame Eq. 20 error of a sequence, millimetres."""
    return float(frame_errors_mm(pred_joints, true_joints).max())


def angle_difference(a, b) -> np.ndarray:
    """``a − b`` wrapped into ``[−π, π)`` (radians), elementwise."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    return (d + np.pi) % (2.0 * np.pi) - np.pi


def _poses(name: str, value, dof: int | None) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.ndim != 2 or a.shape[0] < 1 or (dof is not None and a.shape[1] != dof):
        want = f"(F, {dof})" if dof is not None else "(F, D)"
        raise MetricsError(f"{name}: expected pose vectors of shape {want} with F >= 1, received shape {a.shape}")
    if not np.all(np.isfinite(a)):
        f, d = np.argwhere(~np.isfinite(a))[0]
        raise MetricsError(f"{name}: expected finite values, received {a[f, d]} at frame {f}, DOF {d}")
    return a


def _dof_index(model, name: str, arg: str) -> int:
    names = tuple(getattr(model, "dof_names", ()))
    if name not in names:
        raise MetricsError(f"{arg}: expected a model with DOF {name!r}, received model "
                           f"{getattr(model, 'name', model)!r} without it")
    return names.index(name)


def _angle_pairs(pred_poses, true_poses, model, true_model, names) -> tuple[np.ndarray, np.ndarray]:
    """Columns ``names`` of both pose arrays (``(F, k)`` each, radians), matched by DOF name."""
    tm = model if true_model is None else true_model
    P = _poses("pred_poses", pred_poses, model.dof)
    T = _poses("true_poses", true_poses, tm.dof)
    if P.shape[0] != T.shape[0]:
        raise MetricsError(f"true_poses: expected {P.shape[0]} frames (as pred_poses), received {T.shape[0]}")
    ip = [_dof_index(model, n, "model") for n in names]
    it = [_dof_index(tm, n, "true_model") for n in names]
    return P[:, ip], T[:, it]


def knee_errors_deg(pred_poses, true_poses, model, *, true_model=None) -> np.ndarray:
    """Signed knee-flexion errors ``(F, 2)`` (left, right), degrees.

    Parameters
    ----------
    pred_poses : (F, D) array_like
        Estimated pose vectors of ``model`` (DESIGN §3 layout, radians).
    true_poses : (F, D') array_like
        True pose vectors of ``true_model`` (default: ``model``); knees are matched by name
        (``left_knee_y``, ``right_knee_y``), so models of different DOF can be compared.
    model, true_model : BodyModel
    """
    P, T = _angle_pairs(pred_poses, true_poses, model, true_model, ("left_knee_y", "right_knee_y"))
    return np.rad2deg(angle_difference(P, T))


def knee_rmse_deg(pred_poses, true_poses, model, *, true_model=None) -> float:
    """Knee-angle RMSE (ISA §13.4.2): ``sqrt(mean over frames and both knees of (q̂ − q)²)``, degrees.

    See :func:`knee_errors_deg` for the arguments.

    Examples
    --------
    >>> from isa_mocap_ros.body import make_model
    >>> m = make_model(18)
    >>> T = np.zeros((4, 18)); P = T.copy(); P[:, m.knee_dofs] = np.deg2rad(2.0)
    >>> round(knee_rmse_deg(P, T, m), 9)
    2.0
    """
    e = knee_errors_deg(pred_poses, true_poses, model, true_model=true_model)
    return float(np.sqrt(np.mean(e * e)))


def per_joint_angle_rmse_deg(pred_poses, true_poses, model, *, true_model=None) -> Mapping[str, float]:
    """RMSE over frames of every joint-angle DOF both models share, degrees.

    Parameters
    ----------
    pred_poses, true_poses, model, true_model
        As in :func:`knee_errors_deg`.

    Returns
    -------
    dict
        ``{dof_name: rmse_deg}`` for the joint-angle DOFs (not the 6 root DOFs) of ``model`` that
        ``true_model`` also has, in ``model`` order. Differences are wrapped into ``[−π, π)``.
    """
    tm = model if true_model is None else true_model
    names = [n for n in model.dof_names[6:] if n in tm.dof_names]
    P, T = _angle_pairs(pred_poses, true_poses, model, true_model, names)
    e = np.rad2deg(angle_difference(P, T))
    rmse = np.sqrt(np.mean(e * e, axis=0))
    return {n: float(v) for n, v in zip(names, rmse)}


def shared_markers(model, other) -> tuple[str, ...]:
    """Names of the marker joints (``model.markers``) that ``other`` also has as markers, in
    ``model`` order (e.g. the lower-body markers when one model is the 18-DOF one)."""
    mine = [model.joint_names[j] for j in model.markers]
    theirs = {other.joint_names[j] for j in other.markers}
    return tuple(n for n in mine if n in theirs)


def marker_positions(model, poses, *, joints=None) -> np.ndarray:
    """Joint centres ``(F, M, 3)`` (metres) of pose vectors ``(F, D)`` by forward kinematics.

    Parameters
    ----------
    model : BodyModel
    poses : (F, D) array_like
    joints : sequence of str, optional
        Joint names to return (default: the model's markers).
    """
    from isa_mocap_ros.body import joint_positions

    X = _poses("poses", poses, model.dof)
    names = [model.joint_names[j] for j in model.markers] if joints is None else list(joints)
    idx = []
    for n in names:
        if n not in model.joint_names:
            raise MetricsError(f"joints: expected joints of model {model.name!r}, received unknown {n!r}")
        idx.append(model.joint_names.index(n))
    return joint_positions(model, X)[:, idx]


def knee_flexion_from_points(hip, knee, ankle) -> np.ndarray:
    """Knee flexion (radians) from 3-D joint centres ``(..., 3)``: the angle between the thigh
    ``knee - hip`` and the shank ``ankle - knee`` (0 = straight leg)."""
    a = np.asarray(knee, float) - np.asarray(hip, float)
    b = np.asarray(ankle, float) - np.asarray(knee, float)
    c = np.sum(a * b, axis=-1) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-12)
    return np.arccos(np.clip(c, -1.0, 1.0))


def score_markers(model, poses, truth_names, truth_markers, *, joint_map=None) -> dict:
    """Accuracy of pose estimates against ground-truth joint centres (or a peer's keypoints) matched BY NAME.

    Needs no ground-truth model: the estimate's joint centres come from ``model`` (the tracking
    model, with the shape it tracked with) by forward kinematics; every ground-truth marker whose
    name is one of ``model``'s marker joints is compared (Eq. 20 per frame, then the mean). A
    missing reference point (NaN) is left out of its frame's mean. Knee angles are measured in 3-D
    on both sides (:func:`knee_flexion_from_points`: thigh vs shank). The same figures are also
    given with each joint's mean offset removed (:func:`offset_removed_errors_mm`; keys starting
    ``offset_removed_``), the measure for a reference whose points are not joint centres.

    Parameters
    ----------
    model : BodyModel
    poses : (F, D) array_like
        Estimates.
    truth_names : sequence of str
        Names of the ground-truth markers (the bag's ``model.marker_joints``, or a reference's names
        mapped to the model's joints).
    truth_markers : (F, M, 3) array_like
        Ground-truth joint centres, metres, in ``truth_names`` order (NaN = missing).

    Returns
    -------
    dict
        ``frames``, ``mpjpe_mm``, ``median_frame_error_mm``, ``max_frame_error_mm``,
        ``worst_frame`` (index into the F frames), ``knee_rmse_deg`` (NaN without hips, knees and
        ankles on both sides), ``markers`` (names compared), ``frame_errors_mm`` (F,),
        ``per_marker_mm`` (name -> mean), ``knee_errors_deg`` ((F, 2) estimate - truth, left/right);
        and the same error with each joint's mean offset in the body removed
        (:func:`offset_removed_errors_mm`, body axes from the true hips, else the world axes):
        ``offset_removed_mpjpe_mm``, ``offset_removed_max_frame_error_mm``, ``offset_removed_worst_frame``,
        ``offset_removed_frame_errors_mm`` (F,), ``offset_removed_per_marker_mm`` (name -> mean),
        ``per_marker_offset_mm`` (name -> [lateral, forward, up] mean offset, mm); with both hips,
        ``heading_errors_deg`` (F,) (:func:`heading_errors_deg`), ``backwards_share`` and
        ``frames_facing_backwards`` (the share and the number of frames whose heading is more than 90° off);
        with both legs, ``offset_removed_knee_rmse_deg`` (the knee angles from the estimate's joints moved by
        their mean offsets). With ``joint_map`` (:class:`.joint_map.JointMap`, fitted on other runs): the
        estimate's virtual markers of that map scored alike, ``mapped_mpjpe_mm``, ``mapped_median_frame_error_mm``,
        ``mapped_max_frame_error_mm``, ``mapped_frame_errors_mm`` (F,), ``mapped_per_marker_mm``,
        ``mapped_knee_rmse_deg``, ``mapped_knee_errors_deg`` and ``joint_map`` (its rig name).
    """
    X = _poses("poses", poses, model.dof)
    T = _points_missing("truth_markers", truth_markers)
    names = list(truth_names)
    if T.ndim != 3 or T.shape[0] != X.shape[0] or T.shape[1] != len(names):
        raise MetricsError(f"truth_markers: expected shape ({X.shape[0]}, {len(names)}, 3), received {T.shape}")
    mine = [model.joint_names[j] for j in model.markers]
    shared = [n for n in mine if n in names]
    if not shared:
        raise MetricsError(f"truth_names: expected some of the model's markers {mine}, received {names}")
    Pe = marker_positions(model, X, joints=shared)
    Pt = T[:, [names.index(n) for n in shared]]
    if np.all(np.isnan(Pt).any(axis=-1).all(axis=1)):
        raise MetricsError("truth_markers: expected some reference points, received NaN (missing) in every frame")
    je = 1e3 * np.linalg.norm(Pe - Pt, axis=-1)
    hips = [shared.index(n) for n in ("left_hip", "right_hip") if n in shared]
    B = body_frames(Pt, *hips) if len(hips) == 2 else None
    jr, off = offset_removed_errors_mm(Pe, Pt, B)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)       # mean of a frame / joint with nothing to compare
        fe, fr = np.nanmean(je, axis=1), np.nanmean(jr, axis=1)
        pm, pr = np.nanmean(je, axis=0), np.nanmean(jr, axis=0)
    scored = np.isfinite(fe)
    out = {"frames": int(X.shape[0]), "mpjpe_mm": float(fe[scored].mean()),
           "median_frame_error_mm": float(np.median(fe[scored])),
           "max_frame_error_mm": float(fe[scored].max()), "worst_frame": int(np.nanargmax(fe)), "markers": shared,
           "frame_errors_mm": fe, "per_marker_mm": {n: float(v) for n, v in zip(shared, pm)},
           "offset_removed_mpjpe_mm": float(fr[scored].mean()),
           "offset_removed_max_frame_error_mm": float(fr[scored].max()),
           "offset_removed_worst_frame": int(np.nanargmax(fr)), "offset_removed_frame_errors_mm": fr,
           "offset_removed_per_marker_mm": {n: float(v) for n, v in zip(shared, pr)},
           "per_marker_offset_mm": {n: [round(float(c), 1) for c in v] for n, v in zip(shared, off)},
           "knee_rmse_deg": float("nan"), "knee_errors_deg": None}
    if len(hips) == 2:
        he = heading_errors_deg(Pe, Pt, *hips)
        back = he > 90.0                                      # False where a hip is missing (NaN)
        out.update(heading_errors_deg=he, backwards_share=float(np.mean(back[np.isfinite(he)])),
                   frames_facing_backwards=int(back.sum()))
    sides = [s for s in ("left", "right") if all(f"{s}_{j}" in shared for j in ("hip", "knee", "ankle"))]
    if sides:
        def ang(P, s):
            return knee_flexion_from_points(*(P[:, shared.index(f"{s}_{j}")] for j in ("hip", "knee", "ankle")))
        ke = np.stack([np.rad2deg(ang(Pe, s) - ang(Pt, s)) for s in sides], axis=1)
        out["knee_rmse_deg"] = float(np.sqrt(np.nanmean(ke ** 2)))
        out["knee_errors_deg"] = ke
        # the same angles from the estimate's joints moved by their mean offsets (a hip defined 5 cm further
        # forward tilts the thigh by ~6°, a bias of definition in every frame's knee angle)
        R = np.broadcast_to(np.eye(3), (Pe.shape[0], 3, 3)) if B is None else B
        Pc = Pe - np.einsum("fij,mj->fmi", R, off / 1e3)
        kc = np.stack([np.rad2deg(ang(Pc, s) - ang(Pt, s)) for s in sides], axis=1)
        out["offset_removed_knee_rmse_deg"] = float(np.sqrt(np.nanmean(kc ** 2)))
    if joint_map is not None:
        from .joint_map import mapped_markers

        Pm = mapped_markers(joint_map, model, X, shared)
        jm = 1e3 * np.linalg.norm(Pm - Pt, axis=-1)
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            fm, pmm = np.nanmean(jm, axis=1), np.nanmean(jm, axis=0)
        out.update(joint_map=joint_map.rig, mapped_mpjpe_mm=float(fm[scored].mean()),
                   mapped_median_frame_error_mm=float(np.median(fm[scored])),
                   mapped_max_frame_error_mm=float(fm[scored].max()), mapped_frame_errors_mm=fm,
                   mapped_per_marker_mm={n: float(v) for n, v in zip(shared, pmm)})
        if sides:
            km = np.stack([np.rad2deg(ang(Pm, s) - ang(Pt, s)) for s in sides], axis=1)
            out.update(mapped_knee_rmse_deg=float(np.sqrt(np.nanmean(km ** 2))), mapped_knee_errors_deg=km)
    return out
