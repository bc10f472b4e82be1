"""The contour stage: a damped Gauss-Newton fit of the pose to the silhouette contours.

Source: the 3-D-2-D correspondences of ISA §13.4.2 ("Silhouette", Eq. 13.30-13.31): model points on
the contour of a pose, each paired with its closest point on the extracted image contour, whose
projection ray is a Plücker line ``(n_i, m_i)``; the pose error of a pair is the distance
``‖x_i(x) × n_i − m_i‖`` of the moved model point from that line. Gall, Rosenhahn and Seidel
minimise that energy with ISA; the authors' own earlier pose estimation (Rosenhahn's, cited there)
solves it by linearizing the kinematic chain, which is what this stage does after the tracker's
global search: a few **iterated closest point** steps, each

1. drawing the current pose's silhouette per usable view, taking its outer contour and back-projecting its
   pixels onto the visible capsules (the nearest hit of each pixel's ray, as
   :func:`~isa_mocap_ros.vision.render_labels_at`; at most ``n_points`` per view; subsampling, labels and
   back-projection in one compiled call per view: :func:`.contour_kernel.contour_points`). The silhouette is the
   scanline energy's: each capsule's two projected end discs and their hull, filled by scanlines
   (:func:`~isa_mocap_ros.vision.outline.fill_capsules`, one compiled call per view); in a view with lens
   distortion the exact one, ray-cast (:func:`~isa_mocap_ros.vision.render_mask`). The discs lie inside the
   balls' exact projections, so every outline contour pixel's ray hits a capsule; the outline is within a
   pixel of the exact silhouette's contour at the tracker's image sizes (``test_contour_fit``);
2. pairing each model contour pixel with the closest pixel of the mask's outer contour (kept when
   within ``max_px`` pixels: a farther match is more often another limb's edge than this one's);
3. one Levenberg-Marquardt step on the stacked residuals ``e_i = x_i × n_i − m_i``:
   ``(JᵀJ + λ diag(JᵀJ)) δ = −Jᵀe`` with the analytic Jacobian ``∂e_i/∂q = (∂x_i/∂q) × n_i``:
   a joint angle about world axis ``a`` at joint centre ``c`` moves the points below it by
   ``a × (x − c)``; the root translation by the identity; the root rotation is perturbed on the left,
   ``R₀ ← exp(δ̂) R₀`` about the root position (as :func:`~isa_mocap_ros.body.position_jacobian`), and
   written back as a rotation vector continuous with the old one;
4. the new pose clipped to the model's limits.

New here (neither paper has it): the papers' searches are global; this local step after the global
search removes the residual error a population's weighted mean leaves (fast knees trail their motion;
``docs/decisions/008-contour-stage.md``). It needs no silhouette-energy
evaluation; the tracker charges each iteration ``D + 1`` evaluations of its budget — the cost of
the same Jacobian by finite differences of the correspondence energy — and evaluates the silhouette
energy of the poses before and after (``Tracker.fit_contours`` keeps the fit unless its energy is more
than ``CONTOUR_KEEP_TOLERANCE`` above the pose's).

Pure numpy (no ROS); :class:`ContourFit` is usable on its own.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import cv2
import numba
import numpy as np
from scipy.spatial import cKDTree

from ..body import BodyModel
from ..body import capsule_endpoints, forward_kinematics
from ..body.kinematics import descendant_mask, frames_and_axes, joint_frames
from ..energy.correspondence import mask_contour_pixels, capsule_contour_points, capsule_frames, pixel_plucker_lines
from ..vision import capsule_data, render_mask
from ..vision.outline import camera_arrays, fill_capsules
from ..vision.render import ray_tiles
from . import contour_kernel

__all__ = ["ContourFit", "ContourFitError", "ContourFitInfo"]

#: Fewest correspondences (over all views) for a step: fewer leave the 39 coordinates underdetermined.
MIN_CORRESPONDENCES = 60


def _padded_distortion(dist) -> np.ndarray:
    """A camera's distortion as the 8 numbers ``(k1, k2, p1, p2, k3, k4, k5, k6)`` (zeros after its own)."""
    out = np.zeros(8)
    out[: np.size(dist)] = np.ravel(dist)
    return out


def _outer_contour(img: np.ndarray, box) -> np.ndarray:
    """``(k, 2)`` int32 outer contour pixels ``(u, v)`` of the nonzero pixels of the uint8 image ``img``: OpenCV's
    ``findContours`` (external, every pixel) in ``box`` = ``(y0, y1, x0, x1)``, which holds those pixels with a row
    and column of background around them or the image's border (OpenCV pads with background as it does for the whole
    image): the same contours, point for point and in the same order, without scanning the empty rest of the image
    (``box``: :func:`.contour_kernel.outline_box`, or the whole image ``(0, H, 0, W)``)."""
    y0, y1, x0, x1 = box
    if y1 <= y0:
        return np.zeros((0, 2), dtype=np.int32)
    contours, _ = cv2.findContours(img[y0:y1, x0:x1], cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE, offset=(x0, y0))
    if not contours:
        return np.zeros((0, 2), dtype=np.int32)
    return np.concatenate(contours).reshape(-1, 2)


class ContourFitError(ValueError):
    """A bad setting or input of :class:`ContourFit`."""


@dataclass(frozen=True)
class ContourFitInfo:
    """What :meth:`ContourFit.fit` did: ``iterations`` steps taken, ``correspondences`` per step,
    ``rms_px``: root mean square pixel distance of the matched pairs per step (before the step),
    ``stopped``: why it ended early (empty when it ran all its iterations)."""
    iterations: int
    correspondences: tuple
    rms_px: tuple
    stopped: str = ""


def _check_positive(name: str, value, *, integer: bool = False, zero: bool = False):
    bad = isinstance(value, bool) or not isinstance(value, (int, np.integer) if integer else (int, float, np.number))
    if bad or not np.isfinite(value) or value < 0 or (value == 0 and not zero):
        kind = "an integer" if integer else "a number"
        raise ContourFitError(f"{name}: expected {kind} {'>= 0' if zero else '> 0'}, received {value!r}")
    return int(value) if integer else float(value)


@numba.njit(cache=True)
def _normal_equations(R, P, axes, frames, local, n, m, dof_joint, below, use):  # pragma: no cover - compiled
    """``JᵀJ (D, D)`` and ``Jᵀe (D,)`` of the residuals ``e_k = x_k × n_k − m_k`` (13.30) with the
    analytic Jacobian (root translation: identity; root rotation: left perturbation about the root;
    a joint angle: ``a_d × (x − c_d)`` for the points below its joint), rows with zero columns skipped; only the
    coordinates with ``use[d]`` (the others' rows and columns stay zero; those computed are the same numbers)."""
    D = axes.shape[0]
    A = np.zeros((D, D))
    g = np.zeros(D)
    G = np.zeros((D, 3))
    act = np.zeros(D, dtype=np.int64)
    for k in range(frames.shape[0]):
        f = frames[k]
        X = np.empty(3)
        for r in range(3):
            X[r] = P[f, r] + R[f, r, 0] * local[k, 0] + R[f, r, 1] * local[k, 1] + R[f, r, 2] * local[k, 2]
        nx, ny, nz = n[k, 0], n[k, 1], n[k, 2]
        e0 = X[1] * nz - X[2] * ny - m[k, 0]
        e1 = X[2] * nx - X[0] * nz - m[k, 1]
        e2 = X[0] * ny - X[1] * nx - m[k, 2]
        na = 0
        for d in range(D):
            if not use[d]:
                continue
            if d < 3:                               # root translation: the unit vector e_d
                dx, dy, dz = 1.0 if d == 0 else 0.0, 1.0 if d == 1 else 0.0, 1.0 if d == 2 else 0.0
            else:
                if d < 6:                           # root rotation about e_(d-3) through the root
                    c = P[0]
                    ax, ay, az = 1.0 if d == 3 else 0.0, 1.0 if d == 4 else 0.0, 1.0 if d == 5 else 0.0
                else:
                    j = dof_joint[d]
                    if not below[j, f]:
                        continue
                    c = P[j]
                    ax, ay, az = axes[d, 0], axes[d, 1], axes[d, 2]
                ux, uy, uz = X[0] - c[0], X[1] - c[1], X[2] - c[2]
                dx = ay * uz - az * uy
                dy = az * ux - ax * uz
                dz = ax * uy - ay * ux
            G[d, 0] = dy * nz - dz * ny            # (∂x/∂q) × n
            G[d, 1] = dz * nx - dx * nz
            G[d, 2] = dx * ny - dy * nx
            act[na] = d
            na += 1
        for a in range(na):
            da = act[a]
            g0, g1, g2 = G[da, 0], G[da, 1], G[da, 2]
            g[da] += g0 * e0 + g1 * e1 + g2 * e2
            for b in range(a, na):              # the upper triangle (act ascends); mirrored below
                db = act[b]
                A[da, db] += g0 * G[db, 0] + g1 * G[db, 1] + g2 * G[db, 2]
    for a in range(D):                          # the lower triangle took the same sums in the same order
        for b in range(a + 1, D):
            A[b, a] = A[a, b]
    return A, g


class ContourFit:
    """Levenberg-Marquardt on Plücker-line contour correspondences, re-matched every iteration.

    Parameters
    ----------
    model : BodyModel
    cameras : sequence of Camera
    n_points : int
        At most this many model contour points per view and iteration (evenly spaced).
    max_px : float
        Pairs whose image contour point is farther than this (pixels) from the model's are dropped.
    damping : float
        Levenberg-Marquardt ``λ`` (relative to the diagonal of ``JᵀJ``; ``0``: Gauss-Newton).

    Examples
    --------
    >>> fit = ContourFit(model, cameras)                  # doctest: +SKIP
    >>> fit.set_masks(masks)                              # doctest: +SKIP
    >>> x, info = fit.fit(x0, iterations=3)               # doctest: +SKIP
    """

    def __init__(self, model: BodyModel, cameras: Sequence, *, n_points: int = 200, max_px: float = 8.0,
                 damping: float = 1e-3) -> None:
        self.model = model
        self.cameras = list(cameras)
        self.n_points = _check_positive("n_points", n_points, integer=True)
        self.max_px = _check_positive("max_px", max_px)
        self.damping = _check_positive("damping", damping, zero=True)
        self._below = descendant_mask(model)                 # (J, J): [j, f] frame f at or below joint j
        self._dof_joint = np.asarray(model.dof_joint)
        self._all = np.ones(model.dof, np.bool_)              # _normal_equations over every coordinate
        self._diag = np.diag_indices(model.dof)
        self._lower = np.ascontiguousarray(model.lower, dtype=np.float64)
        self._upper = np.ascontiguousarray(model.upper, dtype=np.float64)
        self._Rc = np.empty((3, 3))                           # step's scratch: the composed root rotation
        self._cap_frames = capsule_frames(model)
        self._radii = np.ascontiguousarray(model.capsule_radii, dtype=np.float64)
        self._images: list = [None] * len(self.cameras)
        # per camera, built once: the index image of the contour pixels (-1 elsewhere; cleared pixel by
        # pixel each frame) and the projection's numbers for the compiled matching
        self._index = [np.full((c.height, c.width), -1, np.int32) for c in self.cameras]
        # the scanline silhouette's image and camera numbers per view (.vision.outline), and the per-view scratch of
        # contour_kernel.contour_points (pixels, labels, depths)
        self._sil = [np.zeros((c.height, c.width), np.uint8) for c in self.cameras]
        self._outline_cams = [camera_arrays(c) for c in self.cameras]
        self._scratch = (np.empty(self.n_points, np.int64), np.empty(self.n_points, np.int64),
                         np.empty(self.n_points, np.int32), np.empty(self.n_points, np.float32))
        # own writable C-order copies: one kernel signature for every camera (a read-only or Fortran-order R from a
        # calibration file would load a second compiled version on the first real frame, after the warm-up)
        self._proj = [(np.array(c.R, dtype=np.float64, order="C"), np.array(c.t, dtype=np.float64, order="C"),
                       np.array([c.fx, c.fy, c.cx, c.cy]), _padded_distortion(c.dist), c.has_distortion) for c in self.cameras]

    def set_masks(self, masks: Sequence[Any]) -> int:
        """Take this frame's foreground masks (one per camera; None for a view to leave out); return the
        number of views with an image contour."""
        masks = list(masks)
        if len(masks) != len(self.cameras):
            raise ContourFitError(f"masks: expected {len(self.cameras)} (one per camera), received {len(masks)}")
        for m, cam in zip(masks, self.cameras):
            if m is not None and np.shape(m) != (cam.height, cam.width):
                raise ContourFitError(f"masks: expected ({cam.height}, {cam.width}) for this camera, received "
                                      f"shape {np.shape(m)}")
        for img, index in zip(self._images, self._index):
            if img is not None:
                contour_kernel.mark_pixels(index, img[4], False)
        self._images = []
        for m, index, cam in zip(masks, self._index, self.cameras):
            pix = mask_contour_pixels(np.asarray(m)) if m is not None else np.zeros((0, 2), np.int64)
            if not len(pix):
                self._images.append(None)
                continue
            c = pix.astype(np.float64)
            contour_kernel.mark_pixels(index, pix, True)
            # the contour pixels, their KD-tree (the reference matching; built when first asked for), the
            # Plücker line of each (13.30) and the integer pixels, once per frame
            self._images.append([c, None, *pixel_plucker_lines(cam, pix), pix])
        return sum(c is not None for c in self._images)

    def _tree(self, v: int):
        img = self._images[v]
        if img[1] is None:
            img[1] = cKDTree(img[0])
        return img[1]

    def model_points(self, x: np.ndarray) -> list:
        """The model contour points of pose ``x`` in every view with an image contour: a list of
        ``(view, frames (k,), local (k, 3))`` (:func:`~isa_mocap_ros.energy.correspondence.model_contour_points`:
        one rendering per view)."""
        out = []
        if not any(img is not None for img in self._images):
            return out
        E = capsule_endpoints(self.model, x)[0]
        T = forward_kinematics(self.model, x)[0]
        capsules = capsule_data(E, self.model.capsule_radii)
        for v, (img, cam) in enumerate(zip(self._images, self.cameras)):
            if img is None:
                continue
            pix, fr, loc = capsule_contour_points(cam, E, self.model.capsule_radii, T, self._cap_frames,
                                                  self.n_points, capsules)
            if len(pix):
                out.append((v, fr, loc))
        return out

    def _points(self, R: np.ndarray, P: np.ndarray) -> list:
        """:meth:`model_points` of the pose with joint rotations ``R`` and positions ``P``
        (:func:`~isa_mocap_ros.body.kinematics.frames_and_axes`), the back-projection compiled
        (:func:`.contour_kernel.back_project`)."""
        out = []
        if not any(img is not None for img in self._images):
            return out
        E = np.ascontiguousarray(P[np.asarray(self.model.capsules)])
        radii = self._radii
        capsules = capsule_data(E, radii)
        for v, (img, cam) in enumerate(zip(self._images, self.cameras)):
            if img is None:
                continue
            contour = self._silhouette_contour(v, E, radii, capsules)
            if not len(contour):
                continue
            n = min(len(contour), self.n_points)
            fr, loc = np.empty(n, np.int64), np.empty((n, 3))
            k = contour_kernel.contour_points(contour, self.n_points, *ray_tiles(cam), cam.width, *capsules,
                                              self._cap_frames, R, P, *self._scratch, fr, loc)
            if k:
                out.append((v, fr[:k], loc[:k]))
        return out

    def _silhouette_contour(self, v: int, E: np.ndarray, radii: np.ndarray, capsules: tuple) -> np.ndarray:
        """``(k, 2)`` int32 outer contour pixels ``(u, v)`` of the model's silhouette in view ``v`` (capsule end points
        ``E``): in a view without lens distortion the capsules' outlines drawn by scanlines
        (:func:`~isa_mocap_ros.vision.outline.fill_capsules`: the scanline energy's silhouette), else the exact
        silhouette ray-cast (:func:`~isa_mocap_ros.vision.render_mask`)."""
        cam = self.cameras[v]
        if not cam.has_distortion:
            sil = self._sil[v]
            sil.fill(0)
            fill_capsules(E, radii, *self._outline_cams[v], 0.0, sil, np.uint8(255))
            return _outer_contour(sil, contour_kernel.outline_box(E, radii, *self._outline_cams[v], *sil.shape))
        sil = render_mask(cam, E, radii, capsules=capsules)
        return _outer_contour(sil, (0, sil.shape[0], 0, sil.shape[1]))

    def _pairs(self, points: list, R: np.ndarray, P: np.ndarray):
        """:meth:`correspondences` of the pose with joint rotations ``R`` and positions ``P``, the matching
        compiled (:func:`.contour_kernel.match`: the same nearest contour pixel within ``max_px``)."""
        n = sum(len(fr) for _, fr, _ in points)
        F, L, N, M, Dst = np.empty(n, np.int64), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
        k = 0
        for v, fr, loc in points:
            img = self._images[v]
            if img is None:             # no image contour in this view (this frame)
                continue
            k = contour_kernel.match(fr, loc, R, P, *self._proj[v], self._index[v], self.max_px, img[2], img[3],
                                     F, L, N, M, Dst, k)
        return F[:k], L[:k], N[:k], M[:k], Dst[:k]

    def correspondences(self, x: np.ndarray, points: list | None = None, fk=None):
        """Pairs of pose ``x`` under the current masks: ``(frames (K,), local (K, 3), n (K, 3), m (K, 3),
        pixel distances (K,))`` — joint frame and position in it of each model point, the Plücker line
        of its matched image contour pixel, and how far apart the two are in the image.

        ``points``: model contour points from :meth:`model_points` (default: those of ``x``), moved with
        their joints to pose ``x`` and projected; ``fk``: ``(R, P)`` of ``x`` if known."""
        if points is None:
            points = self.model_points(x)
        if fk is None:
            R, P, _ = joint_frames(self.model, x[None])
            fk = R[0], P[0]
        R, P = fk
        F, L, N, M, Dst = [], [], [], [], []
        for v, fr, loc in points:
            img = self._images[v]
            X = P[fr] + np.einsum("kij,kj->ki", R[fr], loc)
            dist, idx = self._tree(v).query(self.cameras[v].project(X))
            ok = dist <= self.max_px
            if not ok.any():
                continue
            F.append(fr[ok])
            L.append(loc[ok])
            N.append(img[2][idx[ok]])
            M.append(img[3][idx[ok]])
            Dst.append(dist[ok])
        if not F:
            z = np.zeros((0, 3))
            return np.zeros(0, dtype=np.int64), z, z, z, np.zeros(0)
        return (np.concatenate(F), np.concatenate(L), np.concatenate(N), np.concatenate(M),
                np.concatenate(Dst))

    def step(self, x: np.ndarray, frames, local, n, m, *, coords=None, fk=None) -> np.ndarray:
        """One damped Gauss-Newton step of pose ``x`` on the given pairs (clipped to the limits), over the
        coordinates ``coords`` (default all; the others held); ``fk``: ``joint_frames(model, x, want_axes=True)``
        if known."""
        model = self.model
        x = np.ascontiguousarray(x, dtype=np.float64)
        R, P, axes = joint_frames(model, x[None], want_axes=True) if fk is None else fk
        f64 = [np.ascontiguousarray(a, dtype=np.float64) for a in (local, n, m)]
        use = self._all
        if coords is not None:
            use = np.zeros(model.dof, np.bool_)
            use[coords] = True
        A, g = _normal_equations(R[0], P[0], axes[0], np.ascontiguousarray(frames, dtype=np.int64), *f64,
                                 self._dof_joint, self._below, use)
        D = model.dof
        A[self._diag] *= 1.0 + self.damping
        A[self._diag] += 1e-9
        if coords is None:
            delta = -np.linalg.solve(A, g)
        else:
            delta = np.zeros(D)
            delta[coords] = -np.linalg.solve(A[np.ix_(coords, coords)], g[coords])
        out = x + delta
        # the root rotation perturbed on the left, log(exp(δ_r) exp(r)) nearest the old one, then the limits
        # (geometry.so3's numbers, compiled; the logarithm's angle by numpy's arctan2)
        s, c = contour_kernel.compose_root(x, delta, self._Rc)
        contour_kernel.finish_step(out, x, self._Rc, float(np.arctan2(s, c)), self._lower, self._upper)
        return out

    def fit(self, x: Any, *, iterations: int, coords: Any = None,
            render_each: bool = True) -> tuple[np.ndarray, ContourFitInfo]:
        """``iterations`` closest-point steps from pose ``x`` over the coordinates ``coords`` (default all;
        the others held); returns the new pose and what happened (the pose unchanged when the masks
        give too few pairs).

        ``render_each``: the model contour points are those of the current pose at every step (one
        rendering per view and step); False: those of ``x``, moved with their joints at each step —
        a third of the cost, but the contour generator of a capsule slides over its surface as the
        pose turns, and fast arms fitted worse (``docs/decisions/008-contour-stage.md``)."""
        iterations = _check_positive("iterations", iterations, integer=True, zero=True)
        x = np.array(x, dtype=np.float64)
        if x.shape != (self.model.dof,) or not np.all(np.isfinite(x)):
            raise ContourFitError(f"x: expected a finite pose of shape ({self.model.dof},), received "
                                  f"{'shape ' + str(x.shape) if x.shape != (self.model.dof,) else 'non-finite values'}")
        if coords is not None:
            coords = np.asarray(coords, dtype=np.int64)
            if coords.ndim != 1 or not len(coords) or coords.min() < 0 or coords.max() >= self.model.dof \
                    or len(np.unique(coords)) != len(coords):
                raise ContourFitError(f"coords: expected distinct coordinate indices in [0, {self.model.dof}), "
                                      f"received {coords.tolist()}")
        counts, rms = [], []
        points = None
        for _ in range(iterations):
            R, P, A = frames_and_axes(self.model, x)        # the pose's kinematics, once per step
            if points is None or render_each:
                points = self._points(R, P)
            frames, local, n, m, dist = self._pairs(points, R, P)
            fk = (R[None], P[None], A[None])
            counts.append(len(frames))
            rms.append(float(np.sqrt(np.mean(dist ** 2))) if len(dist) else float("nan"))
            if len(frames) < MIN_CORRESPONDENCES:
                return x, ContourFitInfo(len(counts) - 1, tuple(counts), tuple(rms),
                                         f"{len(frames)} contour pairs, fewer than {MIN_CORRESPONDENCES}")
            x = self.step(x, frames, local, n, m, coords=coords, fk=fk)
        return x, ContourFitInfo(len(counts), tuple(counts), tuple(rms))
