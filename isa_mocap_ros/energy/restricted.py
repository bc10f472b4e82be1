"""The silhouette energy restricted to poses that differ from a base pose in a few coordinates
(:meth:`.silhouette.SilhouetteEnergy.restrict`, docs/energy.md "Restricted evaluation for hierarchical
stages"): :class:`RestrictedSilhouetteEnergy`.

This module does not import :mod:`.silhouette` (which imports it for ``restrict``): the parent energy
is recognised by the state it carries for restrictions.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from . import raster_kernel as _rk
from . import silhouette_kernel as _k
from ._checks import EnergyError, _check_poses

__all__ = ["RestrictedSilhouetteEnergy"]

_NO_ROWS = np.zeros(0, np.int64)


class RestrictedSilhouetteEnergy:
    """:class:`SilhouetteEnergy` restricted to poses equal to a base pose outside some coordinates
    (:meth:`SilhouetteEnergy.restrict`); ``f(X (n, D)) -> (n,)``, the same values as the full energy.

    The *moving* capsules are those with an end joint whose position depends on one of ``coords``
    through the kinematic tree; the others are *fixed*. Computed once here, per view: the fixed
    capsules' projections and boxes, their term-1 template points that lie in their own hull, in no
    earlier fixed capsule's hull and in the image (count, foreground sum, the points themselves), and
    the foreground sample points no fixed capsule covers. Per pose: forward kinematics and projection
    of the moving joints and capsules only; term 1 in full for the moving capsules, and for a fixed one
    only its stored points against the *earlier moving* capsules whose boxes meet its own (usually none:
    its stored sums); term 2 from the stored count plus the uncovered points the moving capsules cover.

    Falls back to the full kernel (still checking the contract) when it would not pay or is not
    implemented: ``method="exact"``, a root coordinate (0-5) in ``coords``, or every capsule moving
    (:attr:`full` is then True). With ``method="raster"`` the fixed capsules' union bitmap is made once and
    each pose ORs its moving capsules into a copy (:func:`.raster_kernel.raster_restricted`; the same bits).

    Contract: every finite row of ``X`` must equal ``x_base`` (exactly) outside ``coords``; a row that
    does not raises :class:`EnergyError` (checked per row in the kernel, cheaply, never skipped). Rows
    with NaN or inf give ``+inf``, as the full energy. Evaluations count in the parent's ``n_evals``.
    Calling it after the parent's :meth:`~SilhouetteEnergy.set_masks` raises :class:`EnergyError`.

    Attributes
    ----------
    energy : SilhouetteEnergy
        The parent.
    x_base : (D,) ndarray
    coords : (k,) int ndarray
        Sorted.
    moving_capsules : (m,) int ndarray
        Capsule indices that move (processing order).
    full : bool
        True when evaluating with the full kernel (see above).
    """

    def __init__(self, energy: SilhouetteEnergy, x_base: Any, coords: Any) -> None:
        if not isinstance(getattr(energy, "restriction_cache", None), dict):   # SilhouetteEnergy's public marker
            raise EnergyError(f"energy: expected a SilhouetteEnergy, received {type(energy).__name__}")
        model = energy.model
        D = model.dof
        if not energy.has_masks:
            raise EnergyError("masks: expected masks to be set (constructor or set_masks) before restricting, "
                              "received none")
        try:
            x = np.array(x_base, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise EnergyError(f"x_base: expected a numeric array of shape ({D},), received {x_base!r}") from exc
        if x.shape != (D,) or not np.isfinite(x).all():
            raise EnergyError(f"x_base: expected a finite array of shape ({D},), received shape {x.shape}"
                              + ("" if x.shape != (D,) else " with non-finite values"))
        try:
            idx = np.asarray(coords)
        except (TypeError, ValueError) as exc:
            raise EnergyError(f"coords: expected integer indices in [0, {D}), received {coords!r}") from exc
        # the coordinates' checks and structure once per distinct coords array (the tracker restricts ~11 times a
        # frame, to the same few coordinate sets)
        raw = (idx.dtype.str, idx.shape, idx.tobytes()) if idx.dtype.kind in "iu" else None
        hit = energy.restriction_cache.get(raw) if raw is not None else None
        if hit is None:
            if idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
                raise EnergyError(f"coords: expected a 1-D sequence of integer indices in [0, {D}), received {coords!r}")
            idx = idx.astype(np.int64)
            if idx.size and (idx.min() < 0 or idx.max() >= D):
                raise EnergyError(f"coords: expected indices in [0, {D}), received {idx.tolist()}")
            if np.unique(idx).size != idx.size:
                raise EnergyError(f"coords: expected no repeated index, received {idx.tolist()}")
            srt = np.sort(idx)
            key = tuple(srt.tolist())
            st = energy.restriction_cache.get(key)
            if st is None:
                st = energy.restriction_cache[key] = _restriction_structure(energy, srt)
            hit = (srt, st)
            if raw is not None:
                energy.restriction_cache[raw] = hit
        self.energy = energy
        self.x_base = x
        self.coords = hit[0].copy()
        self._frame = energy.frame_data
        st = hit[1]
        (self._fixed, self._fixed_mask, self._fk_joints, self._cam_joints, self.moving_capsules, self._mov_ci,
         self._moving_ci, moving, structural_full) = st
        self.full = energy.method == "exact" or structural_full
        self._raster = energy.method == "raster"
        if self.full:
            return
        if self._raster:        # the scanline kernel: the fixed capsules' bitmap once (raster_kernel)
            body, views, raster = energy.kernel_args()
            stage = _rk.RasterStage(*_rk.raster_restrict_prepare(x, body, views, raster, moving))
            self._args = (_k.Restriction(x, self._fixed, self._fk_joints, self._cam_joints, self.moving_capsules,
                                         self._mov_ci, self._moving_ci), body, views, raster, stage)
            self._moving = moving
            self._coarse = [None, None]
            return
        body, views, tmpl, fg = energy.kernel_args()
        stage = _k.Stage(*_k.restrict_prepare(x, body, views, tmpl, fg, moving))
        # the kernel's arguments between X and (n_chunks, out)
        self._moving = moving
        self._args = (_k.Restriction(x, self._fixed, self._fk_joints, self._cam_joints, self.moving_capsules,
                                     self._mov_ci, self._moving_ci), body, views, tmpl, fg, stage)
        self._coarse = [None, None]     # the two pairs of views

    def kernel_args(self) -> tuple:
        """The arguments of the restricted kernel between the poses and ``(n_chunks, out)`` (for the
        tracker's compiled search)."""
        return self._args

    def coarse_kernel_args(self, second: bool = False) -> tuple:
        """:meth:`kernel_args` on the parent's coarse level (:meth:`SilhouetteEnergy.coarse_kernel_args`: two views;
        with ``method="raster"`` every second pixel row, ``second`` alike)."""
        if self._raster:            # every second pixel row: the fixed capsules' bitmap on those rows once
            if self._coarse[0] is None:
                body, views, raster = self.energy.coarse_kernel_args()
                stage = _rk.RasterStage(*_rk.raster_restrict_prepare(self.x_base, body, views, raster, self._moving))
                self._coarse[0] = (self._args[0], body, views, raster, stage)
            return self._coarse[0]
        if self._coarse[second] is None:
            body, views, tmpl, fg = self.energy.coarse_kernel_args(second)
            if views is self._args[2]:
                self._coarse[second] = self._args
            else:
                stage = _k.Stage(*_k.restrict_prepare(self.x_base, body, views, tmpl, fg, self._moving))
                self._coarse[second] = (self._args[0], body, views, tmpl, fg, stage)
        return self._coarse[second]

    def violation(self, X: np.ndarray, rows: np.ndarray) -> EnergyError:
        """The error for rows ``rows`` of ``X`` that move coordinates outside :attr:`coords`."""
        return self._violation(X, rows)

    def _violation(self, X: np.ndarray, rows: np.ndarray) -> EnergyError:
        i = int(rows[0])
        d = int(np.flatnonzero((X[i] != self.x_base) & self._fixed_mask)[0])
        return EnergyError(f"X: expected rows equal to x_base outside coords {self.coords.tolist()}, received row "
                           f"{i} with coordinate {d} = {X[i, d]!r} (x_base: {self.x_base[d]!r}); "
                           f"{rows.size} such row(s)")

    def __call__(self, X: Any) -> np.ndarray:
        """Energies ``(n,)`` of poses ``X (n, D)`` equal to ``x_base`` outside ``coords``."""
        en = self.energy
        X, ok = _check_poses(en.model, X)
        if en.frame_data is not self._frame:
            raise EnergyError("masks: expected the masks this restriction was made for, received new ones "
                              "(set_masks was called since): restrict again")
        if self.full:       # the full kernel is right for any pose: nothing to check
            return en(X)
        n = X.shape[0]
        en.n_evals += n
        if ok.all():
            out = self._fast(X)
            bad = np.flatnonzero(out < 0.0) if out.min(initial=0.0) < 0.0 else _NO_ROWS
        else:
            out = np.full(n, np.inf)
            rows = np.flatnonzero(ok)
            bad = _NO_ROWS
            if rows.size:
                sub = self._fast(np.ascontiguousarray(X[rows]))
                out[rows] = sub
                bad = rows[sub < 0.0]
        if bad.size:
            raise self._violation(X, bad)
        return out

    def _fast(self, X: np.ndarray) -> np.ndarray:
        out = np.empty(X.shape[0])
        kernel = _rk.raster_restricted if self._raster else _k.silhouette_restricted
        kernel(X, *self._args, max(1, min(X.shape[0], self.energy.threads)), out)
        return out

    def __repr__(self) -> str:
        return (f"RestrictedSilhouetteEnergy(coords={self.coords.tolist()}, moving_capsules="
                f"{self.moving_capsules.tolist()}, full={self.full})")


def _restriction_structure(energy: SilhouetteEnergy, coords: np.ndarray) -> tuple:
    """What a restriction to ``coords`` (sorted) depends on besides the base pose and the masks (cached
    per energy): fixed coordinates (indices, mask), joints to recompute (rotating or moving), joints
    to project (moving), moving capsules (processing order) and their processing positions, the
    processing positions' moving flags, the capsules' moving flags, and whether only the full kernel
    applies (a root coordinate, or every capsule moving)."""
    D = energy.model.dof
    fixed = np.ones(D, bool)
    fixed[coords] = False
    parents, _, ptr, dofs, _ = energy.kin_tables
    J = parents.size
    rot = np.zeros(J, bool)         # a coordinate of the joint or of an ancestor
    moved = np.zeros(J, bool)       # an ancestor rotates
    for j in range(1, J):
        rot[j] = rot[parents[j]] or not fixed[dofs[ptr[j]:ptr[j + 1]]].all()
        moved[j] = rot[parents[j]] or moved[parents[j]]
    caps, order = energy.capsule_joints, energy.capsule_order
    moving = np.ascontiguousarray(moved[caps[:, 0]] | moved[caps[:, 1]])
    pos = np.empty(len(order), np.int64)
    pos[order] = np.arange(len(order))
    mov_caps = np.array([c for c in order if moving[c]], dtype=np.int64)
    full = bool(np.any(coords < 6)) or bool(moving.all())
    return (np.flatnonzero(fixed).astype(np.int64), fixed, np.flatnonzero(rot | moved).astype(np.int64),
            np.flatnonzero(moved).astype(np.int64), mov_caps, np.ascontiguousarray(pos[mov_caps]),
            np.ascontiguousarray(moving[order]), moving, full)
