"""Parzen-Rosenblatt pose prior (ISA Eq. 13.32) and its energy term (13.33).

Source: Gall et al., ISA §13.4.2, "Prior Knowledge": the probability of a pose is learnt from
``N`` training samples with a Gaussian-kernel Parzen-Rosenblatt estimator

    p_pose(x) = 1 / ((2π σ²)^{d/2} N) · Σ_i exp(-‖x_i - x‖² / (2σ²))          (13.32)

"where we chose the window size σ as the maximum second nearest neighbor distance between all
training samples", and the energy adds ``-η ln p_pose(x)`` with ``η = 8`` (13.33).

Choices made here (see ``docs/segmentation_prior_prediction.md``):

* **σ.** For each training sample ``x_j`` we take the distance to its *second nearest other*
  training sample (the sample itself, at distance 0, is not counted; an exact duplicate is a
  neighbour at distance 0), and σ is the maximum of these over ``j``. Computed with
  :class:`scipy.spatial.cKDTree` (``k = 3`` query: self, nearest, second nearest).
* **Coordinates.** The prior covers the joint angles only (``dims``; by default every coordinate
  after the 6-D root, DESIGN §3): the absolute position and heading of a person carry no
  information about how plausible a posture is.
* **Energy offset.** ``p_pose(x) ≤ (2π σ²)^{-d/2}`` for every ``x``, so
  :meth:`ParzenPrior.energy` returns ``-η (ln p_pose(x) + (d/2) ln(2π σ²))
  = -η ln( (1/N) Σ_i exp(-‖x_i - x‖² / (2σ²)) ) ≥ 0``. Adding a constant changes no minimiser
  (nor any difference of energies, which is all an optimizer or a Boltzmann weight sees).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["PriorError", "ParzenPrior", "second_nearest_neighbour_sigma"]

_CHUNK_ELEMENTS = 4_000_000   # query rows × training samples per block (32 MB of float64)
_ROOT_DOF = 6


class PriorError(ValueError):
    """Bad training data or a bad query given to the pose prior."""


def _as_matrix(X, name: str, n_cols: int | None = None) -> np.ndarray:
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or (n_cols is not None and X.shape[1] != n_cols):
        want = "(n, D)" if n_cols is None else f"(n, {n_cols})"
        raise PriorError(f"{name}: expected shape {want}, got {X.shape}")
    if not np.all(np.isfinite(X)):
        bad = np.argwhere(~np.isfinite(X))[0]
        raise PriorError(f"{name}: expected finite values, got {X[tuple(bad)]} at row {bad[0]}, "
                         f"column {bad[1]}")
    return X


def second_nearest_neighbour_sigma(samples: np.ndarray) -> float:
    """Window size of 13.32: the maximum over samples of the second-nearest-other distance.

    Parameters
    ----------
    samples : (N, d) ndarray
        Training samples (the selected coordinates), ``N >= 3``.

    Returns
    -------
    float
        ``max_j d_2(x_j)`` where ``d_2(x_j)`` is the distance from ``x_j`` to its second nearest
        sample among the others.
    """
    samples = _as_matrix(samples, "samples")
    if samples.shape[0] < 3:
        raise PriorError(f"samples: expected at least 3 training poses for a second-nearest-"
                         f"neighbour distance, got {samples.shape[0]}")
    dist, _ = cKDTree(samples).query(samples, k=3)
    # Columns: the sample itself (0), its nearest other, its second nearest other. With exact
    # duplicates the zero distances tie, but the sorted third column is still the right one.
    return float(dist[:, 2].max())


class ParzenPrior:
    """Gaussian-kernel Parzen-Rosenblatt density of poses (13.32) and the energy ``-η ln p`` (13.33).

    Parameters
    ----------
    training_poses : (N, D) array_like
        Full pose vectors (DESIGN §3 layout); only the columns ``dims`` are used. ``N >= 3``
        unless ``sigma`` is given.
    dims : (d,) array_like of int, optional
        Columns the prior covers. Default: every column after the 6 root coordinates
        (translation, rotation vector), i.e. the joint angles.
    sigma : float, optional
        Kernel width; default: the maximum second-nearest-neighbour distance of the training
        poses (13.32 text).

    Attributes
    ----------
    sigma : float
    n_train : int
        ``N``.
    dims : (d,) ndarray of int
    n_dof : int
        ``D``, the length of the pose vectors the prior accepts.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> poses = np.hstack([np.zeros((50, 6)), rng.normal(0.0, 0.3, (50, 4))])
    >>> prior = ParzenPrior(poses)
    >>> prior.n_train, prior.dims.tolist()
    (50, [6, 7, 8, 9])
    >>> e = prior.energy(np.vstack([poses[:1], poses[:1] + 3.0]))
    >>> bool(e[0] < e[1])
    True
    """

    def __init__(self, training_poses, *, dims=None, sigma: float | None = None) -> None:
        P = _as_matrix(training_poses, "training_poses")
        self.n_dof = int(P.shape[1])
        self.dims = self._check_dims(dims, self.n_dof)
        samples = P[:, self.dims]
        if samples.shape[0] < 1:
            raise PriorError("training_poses: expected at least one pose, got 0")
        if sigma is None:
            sigma = second_nearest_neighbour_sigma(samples)
            if not sigma > 0:
                raise PriorError("training_poses: expected poses that are not all identical "
                                 "(the second-nearest-neighbour distance is 0, so sigma would be 0)")
        elif not (np.isfinite(sigma) and sigma > 0):
            raise PriorError(f"sigma: expected a finite number > 0, got {sigma!r}")
        self._set(samples, float(sigma))

    def _set(self, samples: np.ndarray, sigma: float) -> None:
        self.sigma = sigma
        self.n_train = int(samples.shape[0])
        self._samples = np.ascontiguousarray(samples, dtype=float)
        # Centre on the training mean so ‖x_i - x‖² = ‖x_i‖² + ‖x‖² - 2 x_i·x loses no precision.
        self._centre = self._samples.mean(axis=0)
        self._Y = self._samples - self._centre
        self._Y2 = np.einsum("ij,ij->i", self._Y, self._Y)
        d = self._samples.shape[1]
        # ln of the constant 1 / ((2π σ²)^{d/2} N) of 13.32
        self._log_norm = -0.5 * d * np.log(2.0 * np.pi * sigma * sigma) - np.log(self.n_train)

    @staticmethod
    def _check_dims(dims, n_dof: int) -> np.ndarray:
        if dims is None:
            if n_dof <= _ROOT_DOF:
                raise PriorError(f"dims: the default (joint angles after the {_ROOT_DOF} root "
                                 f"coordinates) needs D > {_ROOT_DOF}, got D = {n_dof}; pass dims")
            return np.arange(_ROOT_DOF, n_dof)
        d = np.asarray(dims)
        if d.ndim != 1 or d.size == 0 or not np.issubdtype(d.dtype, np.integer):
            raise PriorError(f"dims: expected a non-empty 1-D integer index array, got {dims!r}")
        if d.min() < 0 or d.max() >= n_dof or np.unique(d).size != d.size:
            raise PriorError(f"dims: expected distinct indices in [0, {n_dof}), got {d.tolist()}")
        return d.astype(np.intp)

    @property
    def training_samples(self) -> np.ndarray:
        """(N, d) ndarray: the training poses restricted to ``dims`` (a copy)."""
        return self._samples.copy()

    # ------------------------------------------------------------------ evaluation
    def _log_kernel_mean(self, X) -> np.ndarray:
        """``ln((1/N) Σ_i exp(-‖x_i - x‖² / 2σ²))`` per row, by a stable log-sum-exp in blocks."""
        X = _as_matrix(X, "X", self.n_dof)
        Q = X[:, self.dims] - self._centre
        Q2 = np.einsum("ij,ij->i", Q, Q)
        out = np.empty(Q.shape[0])
        inv2s2 = 0.5 / (self.sigma * self.sigma)
        step = max(1, _CHUNK_ELEMENTS // self.n_train)
        for a in range(0, Q.shape[0], step):
            q = Q[a:a + step]
            r2 = Q2[a:a + step, None] + self._Y2[None, :] - 2.0 * (q @ self._Y.T)   # ‖x - x_i‖²
            np.maximum(r2, 0.0, out=r2)
            z = -inv2s2 * r2
            zmax = z.max(axis=1)
            out[a:a + step] = zmax + np.log(np.exp(z - zmax[:, None]).sum(axis=1))
        return out - np.log(self.n_train)

    def log_density(self, X) -> np.ndarray:
        """``ln p_pose(x)`` of 13.32 for a batch of poses.

        Parameters
        ----------
        X : (n, D) array_like
            Full pose vectors; rows are evaluated independently.

        Returns
        -------
        (n,) ndarray
        """
        return self._log_kernel_mean(X) + self._log_norm + np.log(self.n_train)

    def energy(self, X, *, eta: float = 8.0) -> np.ndarray:
        """Prior energy ``-η ln p_pose(x)`` (13.33) shifted so that its infimum is 0.

        ``E(x) = -η ln((1/N) Σ_i exp(-‖x_i - x‖² / 2σ²)) = -η (ln p_pose(x) + (d/2) ln 2πσ²)``.
        The shift ``η (d/2) ln 2πσ²`` is the same for every ``x``, so minimisers and energy
        differences are those of 13.33. ``E ≥ 0``; ``E ≈ η ln N`` at an isolated training pose and
        grows like ``η ‖x - x_near‖² / 2σ²`` away from the data.

        Parameters
        ----------
        X : (n, D) array_like
        eta : float
            Weight ``η`` (13.33 uses 8 with its correspondence energy's scale).

        Returns
        -------
        (n,) ndarray
        """
        if not (np.isfinite(eta) and eta >= 0):
            raise PriorError(f"eta: expected a finite number >= 0, got {eta!r}")
        return -eta * self._log_kernel_mean(X)

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike) -> None:
        """Write the prior to a small ``.npz`` (training samples, dims, D, sigma)."""
        np.savez_compressed(Path(path), samples=self._samples, dims=self.dims,
                            n_dof=np.int64(self.n_dof), sigma=np.float64(self.sigma),
                            format=np.str_("isa_mocap_ros.ParzenPrior/1"))

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ParzenPrior":
        """Read a prior written by :meth:`save`."""
        try:
            with np.load(Path(path), allow_pickle=False) as f:
                fmt = str(f["format"]) if "format" in f else None
                if fmt != "isa_mocap_ros.ParzenPrior/1":
                    raise PriorError(f"path: expected a ParzenPrior file (format "
                                     f"'isa_mocap_ros.ParzenPrior/1'), got format {fmt!r} in {path}")
                samples, dims = f["samples"], f["dims"]
                n_dof, sigma = int(f["n_dof"]), float(f["sigma"])
        except (OSError, KeyError, ValueError) as exc:
            if isinstance(exc, PriorError):
                raise
            raise PriorError(f"path: cannot read a ParzenPrior from {path}: {exc}") from exc
        obj = cls.__new__(cls)
        obj.n_dof = n_dof
        obj.dims = cls._check_dims(dims, n_dof)
        samples = _as_matrix(samples, "samples", obj.dims.size)
        obj._set(samples, sigma)
        return obj

    @classmethod
    def from_motion(cls, poses, *, stride: int = 4, max_poses: int | None = None, dims=None,
                    sigma: float | None = None) -> "ParzenPrior":
        """Prior from a motion (a sequence of pose vectors), subsampled.

        Parameters
        ----------
        poses : (F, D) array_like
            Frames of a motion, e.g. a BVH converted to the body model's pose vectors.
        stride : int
            Keep every ``stride``-th frame (consecutive frames of a 120 Hz capture are nearly
            equal and only cost evaluation time).
        max_poses : int, optional
            After striding, keep at most this many poses, evenly spread over the motion.
        dims, sigma
            As in :class:`ParzenPrior`.
        """
        P = _as_matrix(poses, "poses")
        if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or stride < 1:
            raise PriorError(f"stride: expected an integer >= 1, got {stride!r}")
        P = P[::stride]
        if max_poses is not None:
            if isinstance(max_poses, bool) or not isinstance(max_poses, (int, np.integer)) or max_poses < 3:
                raise PriorError(f"max_poses: expected an integer >= 3, got {max_poses!r}")
            if P.shape[0] > max_poses:
                P = P[np.unique(np.linspace(0, P.shape[0] - 1, max_poses).round().astype(int))]
        return cls(P, dims=dims, sigma=sigma)
