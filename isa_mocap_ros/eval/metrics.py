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
           "joint_offsets_m", "joint_errors_offset_removed_mm"]


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


def joint_offsets_m(pred_joints, true_joints) -> np.ndarray:
    """Each joint's mean offset ``(M, 3)`` (metres) of the estimate from the reference over the frames:
    ``o_i = mean_f (x̂_fi − x_fi)``, frames where the reference point is missing (NaN) left out (NaN
    for a joint missing in every frame).

    A peer's keypoints (e.g. Pose2Sim's, from 2-D detectors) are not anatomical joint centres: a
    keypoint sits at a roughly constant offset from the joint centre of the same name.
    """
    P = _points("pred_joints", pred_joints)
    T = _points_missing("true_joints", true_joints)
    if P.shape != T.shape:
        raise MetricsError(f"true_joints: expected the shape of pred_joints {P.shape}, received {T.shape}")
    D = P - T
    ok = np.all(np.isfinite(D), axis=-1)
    n = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        o = np.where(ok[..., None], D, 0.0).sum(axis=0) / n[:, None]
    o[n == 0] = np.nan
    return o


def joint_errors_offset_removed_mm(pred_joints, true_joints) -> np.ndarray:
    """Euclidean error ``(F, M)`` in millimetres after removing each joint's mean offset
    (:func:`joint_offsets_m`): ``‖x̂_fi − x_fi − o_i‖``, NaN where the reference point is missing.

    What remains is the error that changes over the frames (the motion), not the constant
    difference between two definitions of a joint (a keypoint vs a joint centre). The shared
    measure for a peer's keypoints and for joints defined differently than the model's.

    Examples
    --------
    >>> T = np.zeros((2, 1, 3)); P = T.copy(); P[:, 0, 2] = 0.05   # constant 50 mm offset
    >>> joint_errors_offset_removed_mm(P, T).tolist()
    [[0.0], [0.0]]
    """
    P = _points("pred_joints", pred_joints)
    T = _points_missing("true_joints", true_joints)
    o = joint_offsets_m(P, T)
    return 1e3 * np.linalg.norm(P - T - o[None], axis=-1)


def _pair(pred_joints, true_joints) -> tuple[np.ndarray, np.ndarray]:
    P = _points("pred_joints", pred_joints)
    T = _points("true_joints", true_joints)
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


def score_markers(model, poses, truth_names, truth_markers) -> dict:
    """Accuracy of pose estimates against ground-truth joint centres (or a peer's keypoints) matched BY NAME.

    Needs no ground-truth model: the estimate's joint centres come from ``model`` (the tracking
    model, with the shape it tracked with) by forward kinematics; every ground-truth marker whose
    name is one of ``model``'s marker joints is compared (Eq. 20 per frame, then the mean). A
    missing reference point (NaN) is left out of its frame's mean. Knee angles are measured in 3-D
    on both sides (:func:`knee_flexion_from_points`: thigh vs shank). The same figures are also
    given with each joint's mean offset removed (:func:`joint_errors_offset_removed_mm`; keys
    ending ``_offset_removed``), the measure for a reference whose points are not joint centres.

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
        with the offsets removed ``mpjpe_offset_removed_mm``, ``max_frame_error_offset_removed_mm``,
        ``worst_frame_offset_removed``, ``frame_errors_offset_removed_mm`` (F,),
        ``per_marker_offset_removed_mm`` (name -> mean) and ``offsets_mm`` (name -> length of the
        joint's mean offset); ``heading_error_deg`` (F,) the angle between the horizontal left-right
        axes (hips, and shoulders when scored) of estimate and reference and ``frames_facing_backwards``
        the frames where it exceeds 90 deg (both None without left and right hips or shoulders).
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
    jr = joint_errors_offset_removed_mm(Pe, Pt)
    off = joint_offsets_m(Pe, Pt)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)       # mean of a frame / joint with nothing to compare
        fe, fr = np.nanmean(je, axis=1), np.nanmean(jr, axis=1)
        pm, pr = np.nanmean(je, axis=0), np.nanmean(jr, axis=0)
    scored = np.isfinite(fe)
    out = {"frames": int(X.shape[0]), "mpjpe_mm": float(fe[scored].mean()),
           "median_frame_error_mm": float(np.median(fe[scored])),
           "max_frame_error_mm": float(fe[scored].max()), "worst_frame": int(np.nanargmax(fe)), "markers": shared,
           "frame_errors_mm": fe, "per_marker_mm": {n: float(v) for n, v in zip(shared, pm)},
           "mpjpe_offset_removed_mm": float(fr[scored].mean()),
           "max_frame_error_offset_removed_mm": float(fr[scored].max()),
           "worst_frame_offset_removed": int(np.nanargmax(fr)), "frame_errors_offset_removed_mm": fr,
           "per_marker_offset_removed_mm": {n: float(v) for n, v in zip(shared, pr)},
           "offsets_mm": {n: float(1e3 * np.linalg.norm(v)) for n, v in zip(shared, off)},
           "knee_rmse_deg": float("nan"), "knee_errors_deg": None}
    # heading: the horizontal left-right axis (hips, plus shoulders when scored) of the estimate against
    # the reference's, world z up (DESIGN §3); more than 90 deg apart = the body faces backwards
    pairs = [(f"left_{j}", f"right_{j}") for j in ("hip", "shoulder") if f"left_{j}" in shared and f"right_{j}" in shared]
    out["heading_error_deg"], out["frames_facing_backwards"] = None, None
    if pairs:
        def lateral(P):
            v = sum(P[:, shared.index(a)] - P[:, shared.index(b)] for a, b in pairs)[:, :2]
            return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
        a, b = lateral(Pe), lateral(Pt)
        hd = np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))
        out["heading_error_deg"] = hd
        out["frames_facing_backwards"] = int(np.sum(hd > 90.0))
    sides = [s for s in ("left", "right") if all(f"{s}_{j}" in shared for j in ("hip", "knee", "ankle"))]
    if sides:
        def ang(P, s):
            return knee_flexion_from_points(*(P[:, shared.index(f"{s}_{j}")] for j in ("hip", "knee", "ankle")))
        ke = np.stack([np.rad2deg(ang(Pe, s) - ang(Pt, s)) for s in sides], axis=1)
        out["knee_rmse_deg"] = float(np.sqrt(np.nanmean(ke ** 2)))
        out["knee_errors_deg"] = ke
    return out
