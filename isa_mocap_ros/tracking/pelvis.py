"""Pelvis stage: re-fit the root with the root's child joints held still in the world.

Why (measured on the CMU walk, ``docs/tracking.md``): the pelvis is a small part of the silhouette,
so its orientation is weakly observed. Along a sequence the estimated root rotation drifts (20-50°
of pitch within 150 frames) while the spine and hips bend the opposite way, so the torso and the
thighs still fit the masks. That compensated pose is a trap for the §3.3 hierarchy: moving the root
alone turns the whole (well fitted) body and raises the energy 5×, moving any one partition to the
truth raises it as well, although the straight line from the estimate to the truth descends all
the way. The coordinated move that leaves the trap is "turn the pelvis, keep the children":

    for a root candidate ``(t', r')``: every child joint ``c`` of the root with three distinct
    rotation axes gets the local rotation ``L_c' = R(r')^T R(r) L_c``, so its world rotation
    ``R(r) L_c`` is unchanged; its Euler angles are re-read in the joint's own axis order.

Only the pelvis and the joint *centres* at its ends (hips, spine base) move; everything below the
children turns with them rigidly. This is a change of coordinates of the root partition, not a new
energy: the stage minimises the same total energy with the configured algorithm.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["PelvisMove"]


class PelvisMove:
    """Poses for root candidates with the root's children kept in the world (see module docstring).

    Parameters
    ----------
    model : BodyModel
        Children of the root (joint 0) whose DOFs are three rotations about distinct axes are
        compensated (the spine base and both hips of the 28/39-DOF models; the hips of the 18-DOF
        model); others keep their angles.
    """

    def __init__(self, model) -> None:
        from isa_mocap_ros.body.kinematics import euler_sequence

        self.model = model
        self.children: list[tuple[list[int], str]] = []
        for j in range(1, len(model.parents)):
            seq = euler_sequence(model, j) if int(model.parents[j]) == 0 else None
            if seq is not None:
                self.children.append(([int(k) for k in model.joint_dofs[j]], seq))

    def __call__(self, x: np.ndarray, roots: np.ndarray) -> np.ndarray:
        """Poses ``(n, D)``: ``x`` with its root replaced by each row of ``roots (n, 6)`` and the
        compensated child angles (not clipped to the limits)."""
        return self.around(x)(roots)

    def around(self, x: np.ndarray):
        """``roots -> poses`` for a fixed ``x`` (what :meth:`__call__` computes, with the parts that
        depend on ``x`` only — its root rotation and the children's local rotations — computed once;
        the pelvis stage calls it once per generation)."""
        x = np.array(x, dtype=float)
        root = Rotation.from_rotvec(x[3:6])                                              # R(r)
        local = [(dofs, seq, Rotation.from_euler(seq, x[dofs])) for dofs, seq in self.children]   # L_c

        def poses(roots: np.ndarray) -> np.ndarray:
            roots = np.atleast_2d(np.asarray(roots, dtype=float))
            X = np.repeat(x[None, :], len(roots), axis=0)
            X[:, :6] = roots
            if local:
                turn = Rotation.from_rotvec(roots[:, 3:6]).inv() * root                 # R(r')^T R(r)
                for dofs, seq, L in local:
                    X[:, dofs] = (turn * L).as_euler(seq)
            return X
        return poses
