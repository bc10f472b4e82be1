"""Initial pose for the first frame: given, or found automatically from the foreground masks.

Source: issue 5 item 5 (a new user needs no hand-made initial pose); the energy searched is the
tracker's (EA-vs-PF Eq. 4-5, optionally with the ISA 13.33 prior), the standing pose is the body
model's rest pose (DESIGN §3).

Automatic initialization, in three steps:

1. **Root position.** In each view with foreground, the centroid ``(ū, v̄)`` of the mask pixels
   gives a ray ``o_v + s d_v`` (:meth:`Camera.ray`, distortion removed). The point nearest to all
   rays in the least-squares sense solves

       (Σ_v (I − d_v d_vᵀ)) p = Σ_v (I − d_v d_vᵀ) o_v                              (ray triangulation)

   (:func:`triangulate_rays`). A silhouette's centroid is not exactly the projection of one 3D
   point, but for a standing person seen from a few metres it is close to the projection of the
   body's centre (≈ pelvis). Only ``x, y`` are kept; the height is set to ``model.pelvis_height``
   (the person stands on the floor ``z = 0``). With foreground in one view only, the ray is cut
   with the plane ``z = pelvis_height``; with none, :class:`InitError`.
2. **Yaw and posture.** A coarse global search: the energy of ``n_yaw`` headings (evenly spaced
   over 2π) × a few standing variants (:data:`STANDING_VARIANTS`: rest, arms out, left stride,
   right stride) at that root, in one batch.
3. **Refinement** (optional, ``refine_evals > 0``): a short run of a flat optimizer over the 6 root DOF
   only (posture kept), from the best grid candidate of each of four heading sectors (the best heading
   + 0°, 90°, 180°, 270°, each ±45°: a standing silhouette is nearly symmetric front/back, and at low
   resolution side-on and frontal views are confused too), spreads 0.1 m (x, y), 0.05 m (z), 0.1 rad
   (tilt), 0.2 rad (yaw); the lower final energy wins. The optimizer is ``refine_optimizer``: the library
   CMA-ES by default, the tracker's own flat algorithm from the tracker (for h-isa a compiled ISA,
   :func:`~isa_mocap_ros.optim.compiled_search.search`, in whole generations: ~half the CPU time of CMA-ES's
   ~45 Python generations a run, the same accuracy on 5 sequences × 3 seeds, docs/history/issue35_speed.md); the
   tracker runs them whole in its compiled search, the energy inside (``refine_search``: the same numbers).
   Without refinement the four sector candidates are returned as scored. The joint angles are left to the
   tracker's first frame: a few hundred evaluations in all 39 DOF did not improve on the grid candidate
   (measured).

The result keeps the energy and the number of evaluations spent, so the tracker can report them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from isa_mocap_ros.geometry import exp_so3, log_so3

__all__ = ["InitError", "InitResult", "STANDING_VARIANTS", "mask_centroid", "triangulate_rays",
           "root_from_masks", "standing_poses", "yaw_rotvec", "yaw_of", "wrap_angle", "initial_pose"]


class InitError(ValueError):
    """Bad input to the initializer, or no foreground to initialize from."""


#: Standing variants searched with every heading: name -> {dof name: angle (rad)}; DOFs a model
#: lacks are skipped. Signs follow the body model (hip flexion forward is -y, knee flexion +y,
#: left abduction +x).
STANDING_VARIANTS: dict[str, dict[str, float]] = {
    "rest": {},
    "arms_out": {"left_shoulder_x": 0.35, "right_shoulder_x": -0.35},
    "left_stride": {"left_hip_y": -0.35, "left_knee_y": 0.25, "right_hip_y": 0.25, "right_knee_y": 0.15,
                    "left_shoulder_y": 0.25, "right_shoulder_y": -0.25},
    "right_stride": {"right_hip_y": -0.35, "right_knee_y": 0.25, "left_hip_y": 0.25, "left_knee_y": 0.15,
                     "right_shoulder_y": 0.25, "left_shoulder_y": -0.25},
}


@dataclass(frozen=True, eq=False)
class InitResult:
    """Outcome of :func:`initial_pose`.

    Attributes
    ----------
    x : (D,) ndarray
        Initial pose.
    energy : float
        Its energy.
    yaw : float
        Heading of the best grid candidate, radians (about world z; 0 faces +x).
    variant : str
        Name of the best grid candidate's standing variant.
    root : (3,) ndarray
        Root position from the masks (before refinement).
    n_evals : int
        Energy evaluations spent (grid + refinement).
    views_used : int
        Views whose mask centroid entered the triangulation.
    notes : tuple of str
        Views skipped and why.
    candidates : tuple of ((D,) ndarray, float)
        The refined start of every heading sector and its energy, best first (``x`` is the first);
        the tracker optimizes the whole pose from each on the first frame.
    """

    x: np.ndarray
    energy: float
    yaw: float
    variant: str
    root: np.ndarray
    n_evals: int
    views_used: int
    notes: tuple = ()
    candidates: tuple = ()


def mask_centroid(mask) -> tuple[float, float] | None:
    """Centroid ``(u, v)`` (column, row; pixel centres at integers) of the nonzero pixels of a
    ``(H, W)`` mask, or None when it has none."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise InitError(f"mask: expected shape (H, W), received {m.shape}")
    rows, cols = np.nonzero(m)
    if rows.size == 0:
        return None
    return float(cols.mean()), float(rows.mean())


def triangulate_rays(origins, directions) -> np.ndarray:
    """Least-squares intersection ``(3,)`` of rays ``o_v + s d_v``.

    Parameters
    ----------
    origins : (V, 3) array_like
    directions : (V, 3) array_like
        Need not be unit length; at least two non-parallel rays.

    Raises
    ------
    InitError
        Fewer than two rays, or (nearly) parallel rays.
    """
    O = np.asarray(origins, dtype=float)
    Dv = np.asarray(directions, dtype=float)
    if O.ndim != 2 or O.shape[1] != 3 or Dv.shape != O.shape or O.shape[0] < 2:
        raise InitError(f"origins, directions: expected two arrays of shape (V, 3) with V >= 2, received "
                        f"{O.shape} and {Dv.shape}")
    Dv = Dv / np.linalg.norm(Dv, axis=1, keepdims=True)
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for o, d in zip(O, Dv):
        Pm = np.eye(3) - np.outer(d, d)          # projector onto the plane normal to the ray
        A += Pm
        b += Pm @ o
    if np.linalg.cond(A) > 1e8:
        raise InitError("directions: expected non-parallel rays, received (nearly) parallel ones")
    return np.linalg.solve(A, b)


def _usable_masks(cameras, masks) -> tuple[list[tuple[int, np.ndarray]], list[str]]:
    """(view, mask) pairs with foreground of the right size, and notes on the others."""
    notes = []
    out = []
    if masks is None:
        return out, ["masks: none given"]
    if len(masks) != len(cameras):
        notes.append(f"masks: expected {len(cameras)} views, received {len(masks)}; using the first "
                     f"{min(len(masks), len(cameras))}")
    for v, (cam, m) in enumerate(zip(cameras, masks)):
        if m is None:
            notes.append(f"view {v}: no mask")
            continue
        m = np.asarray(m)
        if m.shape != (cam.height, cam.width):
            notes.append(f"view {v}: mask shape {m.shape}, expected ({cam.height}, {cam.width}); skipped")
            continue
        if not m.any():
            notes.append(f"view {v}: empty mask; skipped")
            continue
        out.append((v, m))
    return out, notes


def root_from_masks(model, cameras: Sequence, masks: Sequence) -> tuple[np.ndarray, int, list[str]]:
    """Root position ``(3,)`` from the masks' centroid rays (step 1 of the module docstring).

    Returns
    -------
    root : (3,) ndarray
        ``(x, y, model.pelvis_height)``.
    views_used : int
    notes : list of str

    Raises
    ------
    InitError
        No view with foreground of the right size.
    """
    usable, notes = _usable_masks(cameras, masks)
    if not usable:
        raise InitError("masks: expected foreground in at least one view of the camera's size, received none "
                        f"({'; '.join(notes)})")
    origins, dirs = [], []
    for v, m in usable:
        u, vv = mask_centroid(m)
        o, d = cameras[v].ray(u, vv)
        origins.append(np.asarray(o, float))
        dirs.append(np.asarray(d, float))
    h = float(model.pelvis_height)
    if len(usable) >= 2:
        try:
            p = triangulate_rays(origins, dirs)
        except InitError as exc:
            notes.append(f"triangulation failed ({exc}); using the first view's ray at the pelvis height")
            p = None
    else:
        notes.append("one view with foreground: its centroid ray cut at the pelvis height")
        p = None
    if p is None:
        o, d = origins[0], dirs[0]
        if abs(d[2]) < 1e-9:
            raise InitError("masks: the only usable centroid ray is horizontal; cannot place the root")
        p = o + (h - o[2]) / d[2] * d
    return np.array([p[0], p[1], h]), len(usable), notes


def yaw_rotvec(yaw: float) -> np.ndarray:
    """Root rotation vector ``(3,)`` of a heading ``yaw`` about world z."""
    return np.array([0.0, 0.0, float(yaw)])


def standing_poses(model, root, yaws, *, variants=None) -> tuple[np.ndarray, list[tuple[float, str]]]:
    """Candidate poses ``(len(yaws) * len(variants), D)``: every heading × standing variant at ``root``.

    Parameters
    ----------
    model : BodyModel
    root : (3,) array_like
    yaws : (k,) array_like
        Headings, radians.
    variants : mapping name -> {dof name: angle}, optional
        Default :data:`STANDING_VARIANTS`.

    Returns
    -------
    X : (n, D) ndarray
    labels : list of (yaw, variant name)
    """
    variants = STANDING_VARIANTS if variants is None else variants
    base = model.rest_pose()
    base[:3] = np.asarray(root, dtype=float)
    rows, labels = [], []
    for name, angles in variants.items():
        xv = base.copy()
        for dof, a in angles.items():
            if dof in model.dof_names:
                xv[model.dof_names.index(dof)] = a
        xv = np.clip(xv, model.lower, model.upper)
        for yaw in np.asarray(yaws, dtype=float):
            x = xv.copy()
            x[3:6] = yaw_rotvec(yaw)
            rows.append(x)
            labels.append((float(yaw), name))
    return np.array(rows), labels


def yaw_of(rotvec) -> float:
    """Heading (rad, about world z) of the root rotation vector ``rotvec`` (3,): the angle of its x axis."""
    R = exp_so3(np.asarray(rotvec, float))
    return float(np.arctan2(R[1, 0], R[0, 0]))


def wrap_angle(a):
    """Angles ``a`` (rad) wrapped into [-π, π)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def initial_pose(model, cameras: Sequence, masks: Sequence, energy: Callable, *, rng: np.random.Generator | None = None,
                 n_yaw: int = 24, variants=None, refine_evals: int = 400,
                 refine_optimizer: tuple = ("cmaes", {}), refine_search: Callable | None = None) -> InitResult:
    """Automatic initial pose from foreground masks (see the module docstring).

    Parameters
    ----------
    model : BodyModel
    cameras : sequence of Camera
    masks : sequence of (H, W) array_like or None
        One per camera; nonzero = foreground. Missing, empty or wrongly sized masks are skipped
        (listed in ``notes``).
    energy : callable
        Batch energy ``(n, D) -> (n,)`` (the tracker's, set to these masks).
    rng : numpy.random.Generator, optional
        Needed when ``refine_evals > 0``.
    n_yaw : int
        Headings of the grid (>= 4).
    variants : mapping, optional
        Standing variants (default :data:`STANDING_VARIANTS`).
    refine_evals : int
        Evaluations per refinement run (four runs; 0 = no refinement; other than CMA-ES rounded down to
        whole generations).
    refine_optimizer : (str, mapping)
        The refinement's flat optimizer and its parameters (:func:`~isa_mocap_ros.optim.make_optimizer`;
        default the library CMA-ES).
    refine_search : callable, optional
        ``fn(start (D,), spread (6,), rng, evals) -> Result or None``: a refinement run of ``refine_optimizer``
        (other than CMA-ES) over the root coordinates from ``start`` done by the caller, with the same numbers
        (the tracker's compiled search with the energy inside, :func:`.first_frame.root_search`); ``best_x`` and
        ``x`` of the 6 root coordinates. None from it, or no ``refine_search``: the run here.

    Returns
    -------
    InitResult

    Raises
    ------
    InitError
        Bad arguments, or no usable foreground.
    """
    if isinstance(n_yaw, bool) or not isinstance(n_yaw, (int, np.integer)) or n_yaw < 4:
        raise InitError(f"n_yaw: expected an integer >= 4, received {n_yaw!r}")
    if isinstance(refine_evals, bool) or not isinstance(refine_evals, (int, np.integer)) or refine_evals < 0:
        raise InitError(f"refine_evals: expected an integer >= 0, received {refine_evals!r}")
    if refine_evals > 0 and not isinstance(rng, np.random.Generator):
        raise InitError(f"rng: expected a numpy.random.Generator for the refinement, received {type(rng).__name__}")
    root, n_views, notes = root_from_masks(model, cameras, masks)
    yaws = np.arange(n_yaw) * (2 * np.pi / n_yaw) - np.pi
    X, labels = standing_poses(model, root, yaws, variants=variants)
    E = np.asarray(energy(X), dtype=float)
    if E.shape != (X.shape[0],):
        raise InitError(f"energy: expected an array of shape ({X.shape[0]},), received {E.shape}")
    E = np.where(np.isfinite(E), E, np.inf)
    n_evals = X.shape[0]
    order = np.argsort(E, kind="stable")
    best = int(order[0])
    yaw0, variant = labels[best]
    x_best, e_best = X[best].copy(), float(E[best])
    # one start per heading sector (best yaw + 0, 90, 180, 270 deg, each +-45 deg): the
    # silhouettes of opposite and of side-on headings are easily confused at low resolution
    starts = []
    for sector in range(4):
        centre = yaw0 + sector * np.pi / 2
        for i in order:
            if abs(wrap_angle(labels[i][0] - centre)) <= np.pi / 4 + 1e-9 and np.isfinite(E[i]):
                starts.append(int(i))
                break
    cands = []
    if refine_evals > 0:
        from isa_mocap_ros.optim import compiled_search, make_optimizer, minimize

        spread = np.array([0.1, 0.1, 0.05, 0.1, 0.1, 0.2])
        bounds = (model.lower[:6], model.upper[:6])
        for i in starts:
            base = X[i]

            def root_energy(R6, base=base):
                Xf = np.repeat(base[None], R6.shape[0], axis=0)
                Xf[:, :6] = R6
                return energy(Xf)

            name, params = refine_optimizer
            if name == "cmaes":
                opt = make_optimizer(name, base[:6], spread, rng=rng, bounds=bounds, **dict(params))
                res = minimize(opt, root_energy, max_evals=int(refine_evals))
            else:
                opt = make_optimizer(name, base[:6], spread, rng=rng, bounds=bounds, rotation_blocks=((3, 4, 5),),
                                     **dict(params))
                evals = max(opt.generation_size, int(refine_evals) // opt.generation_size * opt.generation_size)
                # the caller's compiled search first, then the generations compiled, the energy called from Python
                # (the same numbers each way; None: the path does not cover it and has drawn nothing)
                res = refine_search(base, spread, rng, evals) if refine_search is not None else None
                if res is None:
                    res = compiled_search.search(opt, root_energy, evals)
                if res is None:           # not covered by the compiled path (the same numbers)
                    res = minimize(opt, root_energy, max_evals=evals)
            n_evals += res.n_evals
            x_ref = base.copy()
            x_ref[:6] = res.best_x
            e, x = min([(float(res.best_energy), x_ref), (float(E[i]), base)], key=lambda t: t[0])
            x = np.array(x, dtype=float)
            x[3:6] = log_so3(exp_so3(x[3:6]))
            cands.append((x, e))
    else:
        cands = [(np.array(X[i], dtype=float), float(E[i])) for i in starts]
    cands.sort(key=lambda t: t[1])
    if not cands:
        cands = [(x_best, e_best)]
    # keep the rotation vector short (|w| <= pi) so the search around it starts well-conditioned
    x_best = cands[0][0].copy()
    e_best = cands[0][1]
    return InitResult(x=x_best, energy=float(e_best), yaw=yaw0, variant=variant, root=root, n_evals=int(n_evals),
                      views_used=n_views, notes=tuple(notes), candidates=tuple(cands))
