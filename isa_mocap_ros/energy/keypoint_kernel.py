"""Compiled kernel of the keypoint correspondence energy (ISA 13.30-13.31 on learned landmarks).

:class:`~isa_mocap_ros.energy.keypoints.KeypointEnergy` prepares the correspondences (model joint, Plücker
line of the detected pixel's ray, confidence weight) and evaluates poses with :func:`keypoint_batch`; the
compiled h-isa search (:mod:`isa_mocap_ros.optim.compiled_search`) calls the same function inside its
partition loop, so a frame with keypoints gives the protocol's numbers bit for bit there too. Per pose::

    P = FK(x)                                         (body.kinematics.fk_pose_into)
    d_k² = ‖P_{j_k} × n_k − m_k‖²                     (13.30-13.31)
    E(x) = Σ_k w_k d_k² / (d_k² + σ²)                 (Geman-McClure, Σ w_k = 1)

Serial over the poses (a generation is 30 poses of ~14 correspondences per view: a parallel launch would
cost more than the work), no fastmath, so the same bits from Python and from compiled callers.
"""
from __future__ import annotations

from collections import namedtuple

import numba
import numpy as np

from isa_mocap_ros.body import kinematics
from isa_mocap_ros.body.kinematics import fk_pose_into
from isa_mocap_ros.numba_cache import register_dependent_cache

__all__ = ["KeypointTerm", "keypoint_batch", "no_keypoints"]

# numba keys a cached function on its own file only: the kernels here compile kinematics' forward kinematics into
# their machine code, so an edit there must also miss this module's cache
register_dependent_cache(__file__, (kinematics,))

#: The keypoint term as the compiled search takes it: the body's kinematic tables
#: (``body.kinematics.kernel_tables``: ``parents (J,)``, ``offsets (J, 3)``, ``ptr (J + 1,)``, ``dofs``,
#: ``axes``), the correspondences ``joints (K,)`` int64, ``dirs, moms (K, 3)`` (Plücker line), ``weights
#: (K,)`` (sum 1), ``sigma`` (metres), and ``scale``: the term's weight in the objective (0: no term).
KeypointTerm = namedtuple("KeypointTerm", "parents offsets ptr dofs axes joints dirs moms weights sigma scale")


def no_keypoints(tables) -> KeypointTerm:
    """A :class:`KeypointTerm` that adds nothing (scale 0, no correspondence), on the kinematic ``tables``
    (the same array types as a real term, so the compiled search is compiled once for both)."""
    return KeypointTerm(*tables, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), 1.0, 0.0)


@numba.njit(cache=True, fastmath=False)
def keypoint_batch(X, parents, offsets, ptr, dofs, axes, joints, dirs, moms, weights, sigma,
                   out):  # pragma: no cover - compiled
    """Energies ``out (n,)`` of the finite poses ``X (n, D)`` (module docstring)."""
    n = X.shape[0]
    J = parents.shape[0]
    R = np.empty((n, J, 3, 3))
    P = np.empty((n, J, 3))
    s2 = sigma * sigma
    for i in range(n):
        fk_pose_into(X, i, parents, offsets, ptr, dofs, axes, R, P)
        e = 0.0
        for k in range(joints.size):
            j = joints[k]
            ex = P[i, j, 1] * dirs[k, 2] - P[i, j, 2] * dirs[k, 1] - moms[k, 0]      # X × n − m  (13.30)
            ey = P[i, j, 2] * dirs[k, 0] - P[i, j, 0] * dirs[k, 2] - moms[k, 1]
            ez = P[i, j, 0] * dirs[k, 1] - P[i, j, 1] * dirs[k, 0] - moms[k, 2]
            d2 = ex * ex + ey * ey + ez * ez
            e += weights[k] * (d2 / (d2 + s2))
        out[i] = e
