"""Silhouette overlap energy (EA-vs-PF Eq. 4-5): exact raster reference and a fast compiled estimate.

Source: Yeguas et al., EA-vs-PF §3.2. For view ``v`` with foreground mask ``F_v`` and the model's
silhouette ``M_v(x)``, over pixels (``D(.)`` = the pixels with value 1)::

    f_v(x) = 1/(2|D(M_v(x))|) Σ_{p ∈ D(M_v(x))} (M_v(x,p) − F_v(p))
           + 1/(2|D(F_v)|)    Σ_{p ∈ D(F_v)}    (F_v(p) − M_v(x,p))                  (4)
    f(x)   = 1/V Σ_v f_v(x)                                                        (5)

i.e. half the fraction of model pixels off the foreground plus half the fraction of foreground
pixels the model misses; ``f`` is minimised and lies in ``[0, 1]``.

* :func:`exact_view_energy` is Eq. 4 literally: the silhouette is rasterized with
  :func:`isa_mocap_ros.vision.render_mask` (pixel-centre rays against the exact capsule solids,
  docs/vision.md) and pixels are counted. A model with no pixel in the view gets ``f_v = 1``
  (the first term is 0/0 there; we take its worst value 1/2).
* :class:`SilhouetteEnergy` evaluates Eq. 5 over the usable views with either the exact
  reference (``method="exact"``) or the compiled estimate of :mod:`.silhouette_kernel`
  (``method="fast"``, the default): the same two terms from a fixed stratified template of points
  in each capsule's projected area (overlaps counted once) looked up in a downsampled foreground
  coverage image, and from a fixed sample of foreground pixels tested against the projected
  capsules. See ``docs/energy.md`` for the approximations and the measured agreement.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import cv2
import numba
import numpy as np

from ..body import BodyModel, capsule_endpoints
from ..vision import Camera
from ..vision.camera import PixelAreas
from . import raster_kernel as _rk
from . import silhouette_kernel as _k
from .coarse import coarse_views, raster_rows_subset, view_subset
from ._checks import EnergyError, _check_cameras, _check_model, _check_poses
from .restricted import RestrictedSilhouetteEnergy
from .silhouette_exact import _foreground, _view_terms, core_weights, exact_view_energy, mask_problem
from .undistort import pinhole, undistort_mask

__all__ = ["EnergyError", "PreparedMasks", "SilhouetteEnergy", "RestrictedSilhouetteEnergy", "exact_view_energy",
           "kinematic_tables"]

#: default size of the model-point template per view (split over the capsules by area)
N_MODEL_POINTS = 160
#: default number of foreground pixels sampled per view and frame
N_MASK_POINTS = 96
_N_BINS = 32
#: vertical strips (x quantiles) of the foreground sample: a capsule tests only the strips its box meets
#: (1: measured fastest for one person at 384 points; 2 and 4 cost more in run overhead than they save)
_N_STRIPS = 1


# ---------------------------------------------------------------------- helpers
def kinematic_tables(model: BodyModel) -> tuple[np.ndarray, ...]:
    """``(parents, offsets, ptr, dofs, axes)`` for the compiled forward kinematics of ``model``.

    ``ptr (J+1,)`` indexes ``dofs``/``axes``: joint ``j`` rotates by ``R_axes[k](x[dofs[k]])`` for
    ``k`` in ``ptr[j]:ptr[j+1]`` in chain order (the same tables as ``body.kinematics``).
    """
    J = len(model.joint_names)
    ptr = np.zeros(J + 1, dtype=np.int64)
    dofs: list[int] = []
    axes: list[int] = []
    for j in range(J):
        ids = model.joint_dofs[j] if j else ()
        dofs += list(ids)
        axes += [int(model.dof_axis[d]) for d in ids]
        ptr[j + 1] = len(dofs)
    return (np.asarray(model.parents, dtype=np.int64), np.ascontiguousarray(model.offsets, dtype=np.float64), ptr,
            np.array(dofs, dtype=np.int64), np.array(axes, dtype=np.int64))


def _view_weights(weights: Any, n_views: int) -> np.ndarray:
    """``(n_views,)`` float64 view weights of :meth:`SilhouetteEnergy.set_masks` (None: ones)."""
    if weights is None:
        return np.ones(n_views)
    try:
        w = np.array(weights, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EnergyError(f"weights: expected {n_views} numbers (one per camera), received {weights!r}") from exc
    if w.shape != (n_views,):
        raise EnergyError(f"weights: expected {n_views} numbers (one per camera), received shape {w.shape}")
    if not (np.isfinite(w).all() and (w >= 0).all()):
        raise EnergyError(f"weights: expected finite numbers >= 0, received {w.tolist()}")
    return w


def _normalized_area(camera: Camera, u: np.ndarray, v: np.ndarray, areas: PixelAreas | None = None) -> float:
    """Area of the pixels ``(u, v)`` in the normalized undistorted image plane of ``camera``.

    ``1 / (fx fy)`` per pixel for a pinhole camera; with lens distortion the determinant of the
    Jacobian of the undistortion at each pixel centre (central differences of ±0.5 px), from ``areas``
    (the camera's :class:`~isa_mocap_ros.vision.camera.PixelAreas`, kept between frames) when given."""
    if not camera.has_distortion:
        return u.size / (camera.fx * camera.fy)
    return float((areas if areas is not None else PixelAreas(camera)).of(u, v).sum())


def _template(model: BodyModel, n_points: int,
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stratified (jittered-grid) points in ``[0, 1]^2`` per capsule, ``k_c`` proportional to its
    rest silhouette area ``2 r L + π r^2`` (at least 4); returns ``(T, 2)`` points (first coordinate
    along the capsule's axis), ``(C+1,)`` offsets and ``(C,)`` numbers of strata along the axis
    (each capsule's points are its strata in increasing order, equally many points each)."""
    rest = np.zeros((len(model.joint_names), 3))
    for j in range(1, len(model.joint_names)):
        rest[j] = rest[model.parents[j]] + model.offsets[j]
    caps = np.asarray(model.capsules)
    L = np.linalg.norm(rest[caps[:, 1]] - rest[caps[:, 0]], axis=1)
    r = np.asarray(model.capsule_radii, dtype=float).max(axis=1)
    area = 2.0 * r * L + np.pi * r * r
    share = np.maximum(4, np.round(n_points * area / area.sum())).astype(int)
    pts, ptr, strata = [], [0], []
    for c in range(len(caps)):
        length, width = L[c] + 2.0 * r[c], 2.0 * r[c]
        nb = max(1, int(round(np.sqrt(share[c] * width / length))))
        na = max(1, int(np.ceil(share[c] / nb)))
        ia, ib = np.meshgrid(np.arange(na), np.arange(nb), indexing="ij")
        u = rng.random((na * nb, 2))
        p = np.stack([(ia.ravel() + u[:, 0]) / na, (ib.ravel() + u[:, 1]) / nb], axis=1)
        pts.append(p)
        ptr.append(ptr[-1] + len(p))
        strata.append(na)
    return (np.ascontiguousarray(np.concatenate(pts)), np.array(ptr, dtype=np.int64),
            np.array(strata, dtype=np.int64))


@dataclass(frozen=True, eq=False)
class PreparedMasks:
    """One frame's masks as :meth:`SilhouetteEnergy.prepare_masks` prepared them for the energies with
    ``cameras``, ``method``, ``downsample`` and ``core_px``: the usable views ``used`` (and ``skipped``, as
    :attr:`SilhouetteEnergy.skipped_views`), per used view the foreground ``F``, its pixel count ``n_fg``
    and term-2 weights ``core``, and (fast method) the kernel inputs no model or random draw changes
    (``static``). Read-only: energies share its arrays."""

    cameras: tuple
    method: str
    downsample: int
    core_px: float
    used: tuple
    skipped: tuple
    F: dict
    n_fg: dict
    core: dict
    static: dict | None


# ---------------------------------------------------------------------- the batch energy
class SilhouetteEnergy:
    """Batch silhouette energy ``f(x)`` of Eq. 5 (mean over usable views of Eq. 4), minimised, in [0, 1].

    Parameters
    ----------
    model : BodyModel
    cameras : sequence of Camera (or a Rig)
        ``V`` calibrated views, full image size.
    masks : sequence of (H, W) uint8 (or bool) or None, optional
        One foreground mask per camera (nonzero = foreground); see :meth:`set_masks`. May be given
        later; evaluating before any masks are set raises :class:`EnergyError`.
    method : {"fast", "exact", "raster"}
        ``"fast"``: the compiled sampled estimate (numba, parallel over poses). ``"exact"``: Eq. 4
        per view by rasterizing with ``render_mask`` and counting pixels (slow; the reference).
        ``"raster"``: Eq. 4 counted on the pixel grid from the projected hulls rasterized by scanlines
        (compiled, no sample; :mod:`.raster_kernel`), every ``downsample``-th pixel row; ``core_px <= 1`` only.
        A distorted camera's masks are resampled once per frame onto its pinhole image (:mod:`.undistort`).
    downsample : int
        Fast method only: term 1 reads the foreground **coverage** of the mask resized by
        ``1 / downsample`` with area averaging (``cv2.INTER_AREA``; the fraction of foreground in
        each block), through the camera ``scaled(1 / downsample)``. ``1`` (default) reads the
        full-size mask: as fast as 2 (one memory read per point either way) and closer to the
        exact energy near the optimum (docs/energy.md). Term 2 always samples full-resolution
        foreground pixels.
    n_model_points : int
        Fast method only: size of the per-view template of model points (split over the capsules
        by rest silhouette area, at least 4 each; the actual total is ``self.n_template``).
    n_mask_points : int
        Fast method only: foreground pixels sampled per view and frame (systematic sample in raster
        order with a random start; all pixels when the mask has fewer).
    core_px : float
        Term 2 of Eq. 4 (foreground the model misses) counts a foreground pixel by ``min(1, d / core_px)``,
        ``d`` its distance to the background in pixels (:func:`core_weights`): the silhouette's rim, where
        clothes and soft tissue lie outside any capsule body, asks less to be covered, while term 1 still
        charges every model pixel off the foreground. ``<= 1`` (default 0): Eq. 4 as printed. The fast
        method draws its foreground sample in proportion to the weights (needs ``n_mask_points > 0``).
    rng : numpy.random.Generator, optional
        Source of the template jitter (drawn once here) and of the foreground samples (drawn at
        each :meth:`set_masks`). Same generator state ⇒ same values. ``None``: ``default_rng(0)``.

    Attributes
    ----------
    skipped_views : list of (int, str)
        Views left out of the current frame and why (missing mask, empty mask, wrong size).
    n_views_used : int
        ``V`` minus the skipped views.
    n_evals : int
        Poses evaluated so far (every row of every call, including non-finite rows).

    Notes
    -----
    ``energy(X)`` with ``X (n, D)`` (or ``(D,)``, read as one row) returns ``(n,)``; rows with NaN or
    inf give ``+inf`` (the optimizers treat non-finite energies as the worst); a wrong width raises
    :class:`EnergyError`.

    Examples
    --------
    >>> import numpy as np
    >>> from isa_mocap_ros.body import make_model, capsule_endpoints
    >>> from isa_mocap_ros.vision import default_rig, render_mask
    >>> model, rig = make_model(39), default_rig()
    >>> x = model.rest_pose()
    >>> masks = [render_mask(c, capsule_endpoints(model, x)[0], model.capsule_radii) for c in rig]
    >>> f = SilhouetteEnergy(model, rig, masks, method="exact")
    >>> float(f(x[None])[0])
    0.0
    """

    def __init__(self, model: BodyModel, cameras: Sequence[Camera], masks: Sequence[Any] | None = None, *,
                 method: str = "fast", downsample: int = 1, n_model_points: int = N_MODEL_POINTS,
                 n_mask_points: int = N_MASK_POINTS, core_px: float = 0.0,
                 rng: np.random.Generator | None = None) -> None:
        self.model = _check_model(model)
        self.cameras = _check_cameras(cameras)
        if method not in ("fast", "exact", "raster"):
            raise EnergyError(f"method: expected 'fast', 'exact' or 'raster', received {method!r}")
        self.method = method
        for name, value, least in (("downsample", downsample, 1), ("n_model_points", n_model_points, 1),
                                   ("n_mask_points", n_mask_points, 0)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
                raise EnergyError(f"{name}: expected an integer >= {least}, received {value!r}")
        if rng is None:
            rng = np.random.default_rng(0)
        if not isinstance(rng, np.random.Generator):
            raise EnergyError(f"rng: expected a numpy.random.Generator, received {type(rng).__name__}")
        if isinstance(core_px, bool) or not isinstance(core_px, (int, float, np.integer, np.floating)) \
                or not np.isfinite(core_px) or core_px < 0:
            raise EnergyError(f"core_px: expected a finite number >= 0 (pixels), received {core_px!r}")
        if core_px > 1 and method == "fast" and n_mask_points == 0:
            raise EnergyError("core_px: expected n_mask_points > 0 with core_px > 1 (the fast method weighs the "
                              "sampled foreground pixels), received n_mask_points=0")
        if method == "raster" and core_px > 1:
            raise EnergyError(f"method: 'raster' needs core_px <= 1, received core_px={core_px!r}; use 'fast'")
        self.downsample = int(downsample)
        self.n_mask_points = int(n_mask_points)
        self.core_px = float(core_px)
        self.rng = rng
        self._radii = np.ascontiguousarray(model.capsule_radii, dtype=np.float64)
        self._caps = np.ascontiguousarray(model.capsules, dtype=np.int64)
        self._kin = kinematic_tables(model)
        self._tmpl, self._tmpl_ptr, self._tmpl_na = _template(model, int(n_model_points), rng)
        # the kernel's layout: along the axis in [0, 1], across it in [-1, 1]
        # (padded by 8: the kernel runs over whole 8-lane vectors and drops the extra points)
        self._tmpl_a = np.zeros((len(self._tmpl) + 8), np.float32)
        self._tmpl_s = np.zeros((len(self._tmpl) + 8), np.float32)
        self._tmpl_a[:len(self._tmpl)] = self._tmpl[:, 0]
        self._tmpl_s[:len(self._tmpl)] = 2.0 * self._tmpl[:, 1] - 1.0
        # bigger capsules first: their points need no overlap test, and they own the shared area
        self._order = np.argsort(-np.diff(self._tmpl_ptr), kind="stable").astype(np.int64)
        self.n_template = int(self._tmpl_ptr[-1])
        # the kernels' argument bundles that do not change with the masks
        self._body = _k.Body(*self._kin, self._caps, self._radii)
        self._template_args = _k.Template(self._order, self._tmpl_a, self._tmpl_s, self._tmpl_ptr, self._tmpl_na)
        self._small = tuple(c.scaled(1.0 / self.downsample) for c in self.cameras)
        self._areas = tuple(PixelAreas(c) for c in self.cameras)   # per pixel, filled as frames need them
        self._pinhole = tuple(pinhole(c) for c in self.cameras)     # raster: distorted masks resampled onto these
        self.skipped_views: list[tuple[int, str]] = []
        self.n_views_used = 0
        self.n_evals = 0
        self._used: list[int] = []
        self._frame: dict | None = None
        # RestrictedSilhouetteEnergy's cache (coords -> what a restriction needs besides pose and masks; a coords
        # array's dtype, shape, bytes -> (sorted coords, that)); it marks an energy restricted.py can restrict
        self.restriction_cache: dict = {}
        if masks is not None:
            self.set_masks(masks)

    # ------------------------------------------------------------------ frames
    @property
    def has_masks(self) -> bool:
        """Whether masks with at least one usable view are set (the energy can be evaluated)."""
        return self._frame is not None

    def prepare_masks(self, masks: Sequence[Any]) -> "PreparedMasks":
        """One frame's masks checked and reduced to what depends neither on the body model nor on the
        random foreground sample: the usable views, foreground images, their pixels and normalized area
        (with lens distortion the costly part: every foreground pixel undistorted four times), the
        coverage images and camera tables.

        :meth:`set_masks` of this energy, or of any other with the same cameras, ``method``,
        ``downsample`` and ``core_px`` (whatever its model), takes the result in place of the masks and
        gives the same bits as from the masks themselves. For a caller that scores the same frames with
        many models (the shape calibration).

        Raises
        ------
        EnergyError
            ``masks`` is not a sequence of one entry per camera.
        """
        try:
            masks = list(masks)
        except TypeError as exc:
            raise EnergyError(f"masks: expected a sequence of {len(self.cameras)} masks, received "
                              f"{type(masks).__name__}") from exc
        if len(masks) != len(self.cameras):
            raise EnergyError(f"masks: expected {len(self.cameras)} masks (one per camera, None for a missing "
                              f"view), received {len(masks)}")
        skipped, used = [], []
        for v, (m, cam) in enumerate(zip(masks, self.cameras)):
            problem = mask_problem(m, cam)
            if problem is None:
                used.append(v)
            else:
                skipped.append((v, problem))
        F = {v: _foreground(masks[v]) for v in used}
        core = {v: core_weights(F[v], self.core_px) for v in used}
        static = None
        if self.method == "fast" and used:
            static = self._fast_static(used, F)
        elif self.method == "raster" and used:
            static = _rk.raster_static([self._pinhole[v] for v in used],
                                       [undistort_mask(self.cameras[v], F[v]) for v in used], self.downsample)
        return PreparedMasks(cameras=tuple(self.cameras), method=self.method, downsample=self.downsample,
                             core_px=self.core_px, used=tuple(used), skipped=tuple(skipped), F=F,
                             n_fg={v: int(np.count_nonzero(F[v])) for v in used}, core=core, static=static)

    def set_masks(self, masks: Sequence[Any] | "PreparedMasks", weights: Sequence[float] | None = None) -> None:
        """Take the foreground masks of a new frame, one per camera (``None`` allowed).

        A view whose mask is ``None``, empty, not a numeric 2-D array or not of its camera's size
        is skipped and listed in :attr:`skipped_views` as ``(view index, reason)``. ``masks`` may also be
        what :meth:`prepare_masks` returned for them (same result, without preparing them again).

        ``weights`` (one finite number >= 0 per camera, optional) turn Eq. 5's mean over the views
        into ``sum_v w_v f_v / sum_v w_v``; None (all ones) is Eq. 5 itself, to the bit. The tracker
        uses them to count a view by the share of the body it sees (``TrackerConfig.objective.view_weights``).

        Raises
        ------
        EnergyError
            ``masks`` is not a sequence of one entry per camera, no view is usable, ``weights``
            is not one finite number >= 0 per camera with a positive sum over the usable views, or
            prepared masks were prepared for other cameras or settings.
        """
        w = _view_weights(weights, len(self.cameras))
        if isinstance(masks, PreparedMasks):
            pre = masks
            self._check_prepared(pre)
        else:
            pre = self.prepare_masks(masks)
        skipped, used = list(pre.skipped), list(pre.used)
        if not used:
            self._frame = None
            self.skipped_views, self._used, self.n_views_used = skipped, [], 0
            raise EnergyError("masks: expected at least one usable view, received none: "
                              + "; ".join(f"view {v}: {why}" for v, why in skipped))
        view_w = np.ascontiguousarray(w[used])
        if not view_w.sum() > 0:
            raise EnergyError(f"weights: expected a positive sum over the usable views {used}, received "
                              f"{view_w.tolist()}")
        frame: dict = {"F": pre.F, "n_fg": pre.n_fg, "view_w": view_w, "core": pre.core}
        if self.method == "fast":
            frame.update(pre.static)
            frame.update(self._fast_sample(used, pre))
            # the kernels' argument bundles of these masks (_k.Views, _k.Foreground)
            frame["views"] = _k.Views(*(frame[k] for k in _k.Views._fields))
            frame["fg"] = _k.Foreground(*(frame[k] for k in _k.Foreground._fields))
        elif self.method == "raster":
            frame.update(pre.static)
            frame["views"] = _k.Views(*(frame[k] for k in _k.Views._fields))
            frame["raster"] = _rk.Raster(*(frame[k] for k in _rk.Raster._fields))
        self._frame = frame
        self._threads = numba.get_num_threads()      # per set_masks: the call costs ~20 µs
        self.skipped_views, self._used, self.n_views_used = skipped, used, len(used)

    def _check_prepared(self, pre: "PreparedMasks") -> None:
        mine = (self.method, self.downsample, self.core_px)
        theirs = (pre.method, pre.downsample, pre.core_px)
        if theirs != mine:
            raise EnergyError(f"masks: prepared for method, downsample, core_px = {theirs}, this energy has {mine}")
        if len(pre.cameras) != len(self.cameras) or not all(
                a is b or a == b for a, b in zip(pre.cameras, self.cameras)):
            raise EnergyError("masks: prepared for other cameras ("
                              + ", ".join(c.name for c in pre.cameras) + ") than this energy's ("
                              + ", ".join(c.name for c in self.cameras) + ")")

    def _fast_static(self, used: list[int], F: dict) -> dict:
        """The fast kernel's inputs of these masks that no random draw changes: camera tables, coverage
        images, and per view the foreground pixels ``(v, u)`` in raster order and their normalized area."""
        V = len(used)
        small = [self._small[v] for v in used]
        Hmax = max(c.height for c in small)
        Wmax = max(c.width for c in small)
        # full resolution: the mask itself as uint8 0/1 (4x less memory to read than float32)
        cov = np.zeros((V, Hmax, Wmax), np.uint8 if self.downsample == 1 else np.float32)
        fg_area = np.zeros(V)
        pixels = []
        for k, v in enumerate(used):
            cam, sc = self.cameras[v], small[k]
            if self.downsample == 1:
                cov[k, :sc.height, :sc.width] = F[v]
            else:
                cov[k, :sc.height, :sc.width] = cv2.resize(F[v].astype(np.float32), (sc.width, sc.height),
                                                           interpolation=cv2.INTER_AREA)
            vv, uu = np.divmod(np.flatnonzero(F[v]), F[v].shape[1])   # np.nonzero(F[v]) (raster order), 10x faster
            fg_area[k] = _normalized_area(cam, uu, vv, self._areas[v])
            pixels.append((vv, uu))
        return {"cam_R": np.ascontiguousarray([self.cameras[v].R for v in used]),
                "cam_t": np.ascontiguousarray([self.cameras[v].t for v in used]),
                "cam_K": np.ascontiguousarray([[c.fx, c.fy, c.cx, c.cy, 1.0] for c in small]),
                "cam_D": np.ascontiguousarray([np.pad(c.dist, (0, 8 - c.dist.size)) for c in small]),
                "cam_hasd": np.array([c.has_distortion for c in small]),
                # 8 zeros after the pixels: the kernel reads the last one for the points it does not count
                "cov": np.concatenate([cov.reshape(V, Hmax * Wmax), np.zeros((V, 8), cov.dtype)], axis=1),
                "cov_wh": np.array([[c.width, c.height, Wmax] for c in small], np.int64),
                "fg_area": fg_area, "pixels": tuple(pixels)}

    def _fast_sample(self, used: list[int], pre: "PreparedMasks") -> dict:
        """The fast kernel's foreground sample of these masks (drawn from :attr:`rng`): per view ``S`` strips
        of points sorted by y and binned."""
        V = len(used)
        M = self.n_mask_points
        S = _N_STRIPS
        # foreground sample: per view S strips of Ms points (whole 8-lane vectors; the padding lies
        # far outside the image), each strip sorted by y and binned
        Ms = max(8, (-(-M // S) + 7) // 8 * 8)
        fg_x = np.full((V * S, Ms), 1e6, np.float32)
        fg_y = np.full((V * S, Ms), 1e6, np.float32)
        fg_n = np.zeros(V, np.int64)
        fg_tab = np.zeros((V * S, _N_BINS + 1), np.int64)
        fg_bins = np.zeros((V * S, 2))
        fg_xr = np.tile([np.inf, -np.inf], (V * S, 1))
        for k, v in enumerate(used):
            if M == 0:
                continue
            cam = self.cameras[v]
            vv, uu = pre.static["pixels"][k]
            n = vv.size
            if pre.core[v] is not None:                     # systematic sample in proportion to the weights
                cum = np.cumsum(pre.core[v][vv, uu])
                pos = (self.rng.random() + np.arange(M)) * (cum[-1] / M)
                idx = np.minimum(np.searchsorted(cum, pos, side="right"), n - 1)
                vv, uu = vv[idx], uu[idx]
            elif n > M:                                     # systematic sample, random start
                idx = np.floor(self.rng.random() * (n / M) + np.arange(M) * (n / M)).astype(np.int64)
                idx = np.minimum(idx, n - 1)
                vv, uu = vv[idx], uu[idx]
            x, y = cam.undistort_pixels(uu.astype(float), vv.astype(float))
            fg_n[k] = x.size
            by_x = np.argsort(x, kind="stable")
            for s_, part in enumerate(np.array_split(by_x, S)):
                if part.size == 0:
                    continue
                r = k * S + s_
                xs, ys = x[part], y[part]
                order = np.argsort(ys, kind="stable")
                xs, ys = xs[order], ys[order]
                fg_x[r, :xs.size], fg_y[r, :xs.size] = xs, ys
                fg_xr[r] = xs.min(), xs.max()
                # y bins: a capsule's box meets the run fg_tab[r, b0]:fg_tab[r, b1 + 1] of the strip
                dy = max(float(ys[-1] - ys[0]), 1e-9) / _N_BINS
                fg_bins[r] = ys[0], 1.0 / dy
                fg_tab[r] = np.searchsorted(ys, ys[0] + dy * np.arange(_N_BINS + 1), side="left")
                fg_tab[r, -1] = ys.size
        return {"fg_x": fg_x.ravel(), "fg_y": fg_y.ravel(), "fg_n": fg_n, "fg_tab": fg_tab, "fg_bins": fg_bins,
                "fg_xr": fg_xr}

    # ------------------------------------------------------------------ evaluation
    def __call__(self, X: Any) -> np.ndarray:
        """Energies ``(n,)`` of poses ``X (n, D)``; non-finite rows give ``+inf``."""
        X, ok = _check_poses(self.model, X)
        if self._frame is None:
            raise EnergyError("masks: expected masks to be set (constructor or set_masks) before evaluating, "
                              "received none")
        n = X.shape[0]
        self.n_evals += n
        if ok.all():
            return self._exact(X) if self.method == "exact" else self._fast(X)
        out = np.full(n, np.inf)
        if ok.any():
            Xg = np.ascontiguousarray(X[ok])
            out[ok] = self._exact(Xg) if self.method == "exact" else self._fast(Xg)
        return out

    def _exact(self, X: np.ndarray) -> np.ndarray:
        E = capsule_endpoints(self.model, X)
        fr = self._frame
        total = np.zeros(X.shape[0])
        for v, w in zip(self._used, fr["view_w"]):
            total += w * _view_terms(self.cameras[v], fr["F"][v], fr["n_fg"][v], E, self._radii, fr["core"][v])
        return total / fr["view_w"].sum()

    @property
    def frame_data(self) -> dict | None:
        """The current frame's kernel inputs (a new object at each :meth:`set_masks`; None without masks):
        what a restriction made for this frame checks it still scores."""
        return self._frame

    @property
    def kin_tables(self) -> tuple:
        """The model's kinematic tables (:func:`kinematic_tables`)."""
        return self._kin

    @property
    def capsule_joints(self) -> np.ndarray:
        """``(C, 2)`` int64: the two joints of each capsule."""
        return self._caps

    @property
    def capsule_order(self) -> np.ndarray:
        """``(C,)`` int64: the capsules in the kernel's processing order (bigger capsules first)."""
        return self._order

    @property
    def threads(self) -> int:
        """numba threads of the kernels, read by the last :meth:`set_masks`."""
        return self._threads

    def kernel_args(self) -> tuple:
        """See :meth:`_kernel_args` (the public name, for the tracker's compiled search)."""
        return self._kernel_args()

    def _kernel_args(self) -> tuple:
        """The arguments of :func:`~.silhouette_kernel.silhouette_batch` between the poses and
        ``n_chunks`` for the current masks, its bundles ``(Body, Views, Template, Foreground)`` (also
        what the tracker's compiled search passes it)."""
        fr = self._frame
        if self.method == "raster":
            return self._body, fr["views"], fr["raster"]
        return self._body, fr["views"], self._template_args, fr["fg"]

    def coarse_kernel_args(self, second: bool = False) -> tuple:
        """:meth:`kernel_args` of the coarse level: the two usable views whose optical axes are closest to
        perpendicular (:func:`.coarse.coarse_views`; ``second``: the other pair, among the remaining views) with
        their foreground samples; the kernel then returns their weighted mean of Eq. 4, the same quantity from
        fewer views at about half the cost (all the views' bundles with fewer than three usable); ``"raster"``: every
        view on every second counted pixel row (:func:`.coarse.raster_rows_subset`, ``second`` alike). Built once per
        frame. For the compiled search's early generations (``SearchConfig.coarse_fraction``, docs/energy.md)."""
        fr = self._frame
        if self.method == "raster":
            return fr["coarse"] if "coarse" in fr else fr.setdefault("coarse", (self._body, fr["views"],
                                                                                raster_rows_subset(fr["raster"])))
        if self.method != "fast":
            raise EnergyError(f"coarse level: expected method 'fast' or 'raster', received {self.method!r}")
        key = "coarse2" if second else "coarse"
        if key not in fr:
            k = self.coarse_views(second)
            fr[key] = self._kernel_args() if len(k) == len(self._used) else view_subset(self._kernel_args(), k)
        return fr[key]

    def coarse_views(self, second: bool = False) -> np.ndarray:
        """Positions (among the used views) of :meth:`coarse_kernel_args`' views."""
        return coarse_views([self.cameras[v] for v in self._used], self._frame["view_w"], second)

    def _fast(self, X: np.ndarray) -> np.ndarray:
        out = np.empty(X.shape[0])
        # one work unit per thread: numba splits a parallel loop statically (equal blocks per thread), so more
        # chunks only repeat each chunk's scratch set-up (docs/energy.md)
        n_chunks = max(1, min(X.shape[0], self._threads))
        # a few poses (a stage's final pose, the contour stage's pair) on this thread: a parallel launch
        # costs more than they do (the same bits either way)
        serial = X.shape[0] < _k.SERIAL_BELOW
        if self.method == "raster":
            (_rk.raster_batch_serial if serial else _rk.raster_batch)(X, *self._kernel_args(), n_chunks, out)
            return out
        kernel = _k.silhouette_batch_serial if serial else _k.silhouette_batch
        kernel(X, *self._kernel_args(), n_chunks, out)
        return out

    def restrict(self, x_base: Any, coords: Any) -> "RestrictedSilhouetteEnergy":
        """The energy of the poses that equal ``x_base`` outside the coordinates ``coords``, computed
        faster: what depends only on the capsules those coordinates do not move is computed once here.

        The values are the same bits as ``self(X)`` (same points counted, same summation order). Meant
        for one stage of a hierarchical optimizer (every particle differs from the current estimate in
        the stage's coordinates only): :class:`~isa_mocap_ros.optim.Hierarchical` asks for it when a
        partition starts. Valid for the current masks only (a later :meth:`set_masks` makes calling it
        raise). See :class:`RestrictedSilhouetteEnergy` and docs/energy.md.

        Parameters
        ----------
        x_base : (D,) array_like
            Finite base pose.
        coords : sequence of int
            The coordinates that may differ from ``x_base`` (indices in ``[0, D)``, no repeats).

        Raises
        ------
        EnergyError
            Bad ``x_base`` or ``coords``, or no masks set.
        """
        return RestrictedSilhouetteEnergy(self, x_base, coords)

    def __repr__(self) -> str:
        return (f"SilhouetteEnergy(model={self.model.name!r}, views={len(self.cameras)}, method={self.method!r}, "
                f"used={self.n_views_used}, downsample={self.downsample}, n_template={self.n_template}, "
                f"n_mask_points={self.n_mask_points}, core_px={self.core_px})")

