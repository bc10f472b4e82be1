"""Temporal smoothness term: chosen joints held near where the frame's prediction puts them (issue 34).

Where the silhouettes are flat along a degree of freedom (the knee on the real recording: docs/real_cameras.md),
the search's end point scatters from frame to frame. This term charges a pose for moving chosen joints away from
their positions in the frame's prediction ``x̂`` (the damped AR prediction, ISA 13.28), robustly, so a real fast
motion is not held back beyond a few ``σ``. It is written as correspondences of the keypoint term's kind (ISA
13.30-13.31: a model joint and a Plücker line), three lines per joint through its predicted position ``p_j`` along
the world axes ``e_a``, so the compiled search evaluates it with the keypoint kernel
(:mod:`.keypoint_kernel`) and a frame with both terms adds them in one kernel call::

    d_ja² = ‖P_j(x) × e_a − p_j × e_a‖²     (the distance of P_j from the line p_j + t e_a; Σ_a d_ja² = 2 ‖P_j − p_j‖²)
    E(x) = Σ_j Σ_a w d_ja² / (d_ja² + σ²),   w = 1 / (3 J)

so ``E`` lies in [0, 1) like the keypoint term. Off by default (``TrackerConfig.objective.temporal_weight`` 0);
measured in docs/history/issue34_real_recording.md (session 34).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from isa_mocap_ros.body import BodyModel
from isa_mocap_ros.body.kinematics import joint_positions, kernel_tables

from ._checks import EnergyError, _check_model, _check_poses
from .keypoint_kernel import KeypointTerm, keypoint_batch

__all__ = ["TemporalTerm", "combined_term"]


class _Correspondences:
    """What a term of the keypoint kernel's kind shares: its correspondence tables (``model``, ``joints``,
    ``directions``, ``moments``, ``weights``, ``sigma_m``) as the compiled search takes them, and its evaluation."""

    @property
    def n_correspondences(self) -> int:
        return len(self.joints)

    def kernel_term(self, scale: float) -> KeypointTerm:
        """This term weighted by ``scale`` as the compiled search takes it."""
        return KeypointTerm(*kernel_tables(self.model), self.joints, self.directions, self.moments, self.weights,
                            self.sigma_m, float(scale))

    def __call__(self, X: Any) -> np.ndarray:
        """Energies ``(n,)`` (the keypoint kernel's function); non-finite rows give ``+inf``."""
        return _evaluate(self, X)


class TemporalTerm(_Correspondences):
    """Robust distance of chosen model joints from their positions in a reference pose (the frame's prediction).

    Parameters
    ----------
    model : BodyModel
    reference : (D,) array_like
        The pose whose joint positions the term holds to (finite).
    joints : sequence of str
        Model joint names (at least one; each a joint of ``model``).
    sigma_m : float
        Scale of the Geman-McClure loss, metres (> 0).

    Attributes
    ----------
    joints, directions, moments, weights : ndarrays
        The correspondences as the keypoint kernel takes them (``(K,)``, ``(K, 3)``, ``(K, 3)``, ``(K,)``,
        ``K = 3 J``; the weights sum to 1).
    sigma_m : float
    n_evals : int
        Poses evaluated through :meth:`__call__` or counted by the compiled search.
    """

    def __init__(self, model: BodyModel, reference: Any, joints: Sequence[str], *, sigma_m: float) -> None:
        self.model = _check_model(model)
        if not np.isfinite(sigma_m) or sigma_m <= 0:
            raise EnergyError(f"sigma_m: expected a positive number of metres, received {sigma_m!r}")
        x = np.asarray(reference, dtype=np.float64)
        if x.shape != (model.dof,) or not np.all(np.isfinite(x)):
            raise EnergyError(f"reference: expected {model.dof} finite numbers, received shape {x.shape}")
        names = list(joints)
        unknown = [n for n in names if n not in model.joint_names]
        if not names or unknown:
            raise EnergyError(f"joints: expected one or more of the model's joints, received {names!r}"
                              + (f" (unknown: {', '.join(unknown)})" if unknown else ""))
        idx = np.array([model.joint_names.index(n) for n in names], dtype=np.int64)
        P = joint_positions(model, x[None])[0][idx]                               # (J, 3)
        E = np.eye(3)
        self.joints = np.repeat(idx, 3)
        self.directions = np.ascontiguousarray(np.tile(E, (len(idx), 1)))
        self.moments = np.ascontiguousarray(np.cross(np.repeat(P, 3, axis=0), self.directions))   # p × e (13.30)
        self.weights = np.full(len(self.joints), 1.0 / len(self.joints))
        self.sigma_m = float(sigma_m)
        self.n_evals = 0

class _Combined(_Correspondences):
    """Two terms of the keypoint kernel's kind with their weights, as one (:func:`combined_term`)."""

    def __init__(self, parts: Sequence[tuple[Any, float]]) -> None:
        self.model = parts[0][0].model
        self.parts = list(parts)
        self.joints = np.concatenate([t.joints for t, _ in parts]).astype(np.int64)
        self.directions = np.ascontiguousarray(np.concatenate([t.directions for t, _ in parts]))
        self.moments = np.ascontiguousarray(np.concatenate([t.moments for t, _ in parts]))
        self.weights = np.ascontiguousarray(np.concatenate([w * t.weights for t, w in parts]))
        self.sigma_m = float(parts[0][0].sigma_m)
        self._n_evals = 0

    @property
    def n_evals(self) -> int:
        return self._n_evals

    @n_evals.setter
    def n_evals(self, value: int) -> None:     # the compiled search counts its evaluations here: each part's too
        for t, _ in self.parts:
            t.n_evals += int(value) - self._n_evals
        self._n_evals = int(value)


def combined_term(parts: Sequence[tuple[Any, float]]):
    """``Σ w_i term_i`` of terms of the keypoint kernel's kind (:class:`~.keypoints.KeypointEnergy`,
    :class:`TemporalTerm`) as one term the compiled search takes with weight 1 (one kernel call). The terms must
    share their loss scale ``sigma_m`` (one σ per kernel call)."""
    parts = [(t, float(w)) for t, w in parts]
    if not parts:
        raise EnergyError("parts: expected at least one (term, weight), received none")
    if len({t.sigma_m for t, _ in parts}) != 1:
        raise EnergyError("parts: expected terms with one sigma_m, received "
                          + ", ".join(f"{t.sigma_m:g}" for t, _ in parts))
    return _Combined(parts)


def _evaluate(term, X: Any) -> np.ndarray:
    X, ok = _check_poses(term.model, X)
    term.n_evals += X.shape[0]
    out = np.where(ok, 0.0, np.inf)
    if not term.n_correspondences or not ok.any():
        return out
    E = np.empty(int(ok.sum()))
    keypoint_batch(np.ascontiguousarray(X[ok]), *term.kernel_term(1.0)[:-1], E)
    out[ok] = E
    return out
