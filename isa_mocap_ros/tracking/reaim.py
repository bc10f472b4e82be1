"""Re-aimed moves: new values for some joints with the limbs below them kept where they were.

Why: the hip joint centres are the worst-estimated joints of a tracked walk, and they set the knee
angle; they hang on the pelvis, whose orientation the silhouette barely sees. The hierarchy's root
partition turns the whole body, and a pelvis move that keeps the children's world *rotations* carries
each thigh with its hip centre, so the knee moves as far as the hip. The move that corrects a hip
centre turns the thigh about the knee (the figures: ``docs/decisions/005-pelvis-stage.md``).

For candidate values of the *moved* joints' DOFs (the root, or the torso partition) the pose is
rebuilt in kinematic order, and every joint hanging directly below them (an *attached* joint: a
joint with DOFs whose parent is moved, or carried rigidly by a moved joint) is **re-aimed**:

    attached three-axis joint ``a`` with a single child ``g`` (thigh → knee, upper arm → elbow,
    lower spine → upper spine): its world rotation becomes ``Q R_a`` with ``Q`` the smallest
    rotation taking the old direction ``g − a`` onto the direction from the *new* centre of ``a``
    to the old centre of ``g`` — the bone swings about ``g``, which stays on its ray (exactly in
    place when the bone length allows), and keeps its twist as far as a swing can;
    then ``g``: a one-DOF hinge (knee, elbow) with a single child ``e`` takes the angle whose
    ``g → e`` direction is closest to the old one in the world (the shank keeps its direction as far
    as the hinge allows); a three-axis ``g`` (the 39-DOF upper spine) keeps its world rotation;
    a ``g`` without DOFs (the 28-DOF chest) passes that on to its three-axis children (neck,
    shoulders).

Other attached three-axis joints keep their world rotations (as in the pelvis move); everything
else keeps its angles. With the root moved this is the pelvis stage's move: the pelvis turns and shifts,
the thighs swing about the knees, the lower spine about the chest, and the legs below the knees, the chest, arms and head stay in the world. With the torso
moved (the **torso stage**) the spine and neck bend and twist while the upper arms swing about the
elbows: the hierarchy fits the torso with the arms held at their angles, so a torso move drags the
arms with it, and the arms (fitted first) hold the torso where they fit.

Angles are read back in each joint's own axis order (intrinsic Tait-Bryan), choosing of the two
equivalent triples the one nearest to the joint's old angles, each angle taken within π of its old
value; nothing is clipped here (the tracker clips to the limits). A compiled kernel (numba) builds
all candidates of a generation in one call.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from isa_mocap_ros.body.reaim_kernel import euler, pose_fk, rebuild

__all__ = ["ReaimMove", "euler_angles"]

#: Operations of the kernel, per joint.
_NONE, _KEEP, _AIM, _HINGE = 0, 1, 2, 3


class ReaimMove:
    """Poses for new values of the moved joints' DOFs with the limbs below re-aimed (module docstring).

    Parameters
    ----------
    model : BodyModel
    joints : sequence of int or str
        The moved joints (indices or names); their DOFs, in DOF order, are :attr:`coords`, the
        columns of the candidates. The root (joint 0) moves its 6 DOFs.

    Raises
    ------
    ValueError
        An unknown joint, or a moved joint without DOFs.
    """

    def __init__(self, model, joints: Sequence) -> None:
        from isa_mocap_ros.body.kinematics import kernel_tables

        self.model = model
        names = list(model.joint_names)
        moved = []
        for j in joints:
            if isinstance(j, str):
                if j not in names:
                    raise ValueError(f"joints: {j!r} is not a joint of model {model.name} ({', '.join(names)})")
                j = names.index(j)
            j = int(j)
            if not 0 <= j < len(names):
                raise ValueError(f"joints: index {j} outside 0..{len(names) - 1}")
            if j and not len(model.joint_dofs[j]):
                raise ValueError(f"joints: {names[j]} has no DOFs to move")
            moved.append(j)
        if not moved:
            raise ValueError("joints: expected at least one joint")
        self.joints = tuple(sorted(set(moved)))
        self.coords = np.array(sorted(d for j in self.joints for d in (range(6) if j == 0 else model.joint_dofs[j])),
                               dtype=np.int64)
        self._tables = kernel_tables(model)
        self.ops = self._plan()
        J = len(names)
        self._op = np.zeros(J, dtype=np.int64)
        self._target = np.full(J, -1, dtype=np.int64)
        for j, (kind, t) in self.ops.items():
            self._op[j] = {"keep": _KEEP, "aim": _AIM, "hinge": _HINGE}[kind]
            self._target[j] = t

    def _plan(self) -> dict:
        """``{joint: (kind, target)}``: ``("keep", -1)``, ``("aim", child)``, ``("hinge", child)``."""
        m = self.model
        J = len(m.joint_names)
        parents = [int(p) for p in m.parents]
        children = [[c for c in range(J) if parents[c] == j] for j in range(J)]
        ndof = [6 if j == 0 else len(m.joint_dofs[j]) for j in range(J)]

        def three_axis(j):
            axes = [int(m.dof_axis[d]) for d in m.joint_dofs[j]] if j else []
            return len(axes) == 3 and len(set(axes)) == 3 and min(axes) >= 0

        def bone(j):            # the single child with a non-zero offset, or None
            kids = [c for c in children[j] if np.linalg.norm(m.offsets[c]) > 1e-9]
            return kids[0] if len(kids) == 1 and len(children[j]) == 1 else None

        carried = [False] * J    # moved, or rigidly on a moved joint
        for j in range(J):       # parents come first (kinematic order)
            carried[j] = j in self.joints or (ndof[j] == 0 and j > 0 and carried[parents[j]])
        ops: dict = {}
        for a in range(1, J):
            if a in self.joints or ndof[a] == 0 or not carried[parents[a]]:
                continue
            if not three_axis(a):
                continue                                # keeps its angles
            g = bone(a)
            if g is None:
                ops[a] = ("keep", -1)
                continue
            ops[a] = ("aim", g)
            if ndof[g] == 1:
                e = bone(g)
                if e is not None:
                    ops[g] = ("hinge", e)
            elif three_axis(g):
                ops[g] = ("keep", -1)
            elif ndof[g] == 0:
                for c in children[g]:
                    if three_axis(c):
                        ops[c] = ("keep", -1)
        return ops

    def kernel_args(self, x: np.ndarray) -> tuple:
        """The arguments of :func:`~isa_mocap_ros.body.reaim_kernel.rebuild` after the poses, for the base pose ``x``
        (its forward kinematics computed here): ``(x, Rb, Pb, parents, offsets, ptr, dofs, axes, op, target)``."""
        x = np.array(x, dtype=float)
        tables, target = self._tables, self._target
        J = len(self.model.joint_names)
        Rb, Pb = np.empty((J, 3, 3)), np.empty((J, 3))
        pose_fk(x.copy(), *tables, np.zeros(J, dtype=np.int64), target, x, Rb, Pb, Rb, Pb,   # no operation
                np.empty((2, 3, 3)), np.empty((2, 3)))
        return (x, Rb, Pb, *tables, self._op, target)

    def around(self, x: np.ndarray):
        """``C (n, len(coords)) -> X (n, D)`` for a fixed pose ``x`` (its forward kinematics computed once)."""
        args = self.kernel_args(x)
        x, coords = args[0], self.coords

        def poses(C: np.ndarray) -> np.ndarray:
            C = np.atleast_2d(np.asarray(C, dtype=float))
            if C.shape[1] != coords.size:
                raise ValueError(f"candidates: expected {coords.size} columns (the moved DOFs), got {C.shape[1]}")
            X = np.repeat(x[None, :], len(C), axis=0)
            X[:, coords] = C
            rebuild(X, *args)
            return X
        return poses

    def __call__(self, x: np.ndarray, C: np.ndarray) -> np.ndarray:
        """Poses ``(n, D)``: ``x`` with the moved DOFs set to each row of ``C`` and the attached joints re-aimed."""
        return self.around(x)(C)


def euler_angles(L: np.ndarray, axes: Sequence[int], near: Sequence[float] | None = None) -> np.ndarray:
    """Angles ``(q1, q2, q3)`` with ``L = R_a1(q1) R_a2(q2) R_a3(q3)`` for distinct axes ``a1 a2 a3``
    (0 = x, 1 = y, 2 = z); of the two triples the one nearest to ``near`` (default zeros), each
    angle within π of ``near``'s."""
    out = np.empty(3)
    ref = np.zeros(3) if near is None else np.asarray(near, dtype=float)
    euler(np.ascontiguousarray(L, dtype=float), int(axes[0]), int(axes[1]), int(axes[2]), ref, out)
    return out
