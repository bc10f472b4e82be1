"""Whole-chain moves for the clean walks' knee (issue 33): the chain stage and the untwist stage, both options.

Why: on the clean mesh walks a run restarted at the truth every frame ends at a lower energy than the free run
and with a better knee; the free run's pelvis orientation, lower spine and thighs' twists wander along directions
the silhouettes barely see (``docs/history/issue33_knee_s31.md``, ``docs/history/issue33_knee_s32.md``).

:func:`refit_chain` (the chain stage, ``StageConfig.chain_fraction``): a candidate is the root's 6 DOF, applied by
the pelvis stage's re-aimed move (:mod:`.reaim`: the thighs swung about the knees, the lower spine about the chest),
plus offsets added to the re-aimed pose's lower spine, hips and knees (:class:`ChainMove`); a flat ISA (the
configured algorithm's flat form) searches them around the pose on the frame's objective, and the result replaces
the pose when it lowers the energy.

:func:`untwist_legs` (the untwist stage, ``StageConfig.leg_untwist``): per leg, the thigh's twist about its own
axis halved and undone, the ankle turned back by as much; a leg takes its best proposal when its energy is below
the pose's times ``1 + leg_untwist_tolerance``.
"""
from __future__ import annotations

import numpy as np

from isa_mocap_ros.optim import compiled_search

from . import plan
from .config import TrackerError, whole_generations

__all__ = ["ChainMove", "CHAIN_JOINTS", "refit_chain", "untwist_legs", "UNTWIST_SCALES"]

#: The joints whose DOFs the chain stage moves besides the root, when the model has them.
CHAIN_JOINTS = ("spine_lower", "left_hip", "right_hip", "left_knee", "right_knee")
#: Initial spread of the root rotation-vector components and of the joint offsets (rad): wider than the main
#: search's (0.025 / 0.05) so that the pelvis's poorly seen turns are tried at the size the free runs wander.
ROOT_ROTATION_SPREAD_RAD = 0.06
JOINT_OFFSET_SPREAD_RAD = 0.06
#: Initial spread of the root translation (m).
ROOT_TRANSLATION_SPREAD_M = 0.01


class ChainMove:
    """Poses from chain candidates ``C (n, 6 + k)``: the root's 6 DOF through the pelvis stage's re-aimed move
    (``reaim``, a :class:`~.reaim.ReaimMove` of the root), then ``C[:, 6:]`` added as offsets to the re-aimed
    poses' :attr:`joint_coords` (the lower spine's, hips' and knees' DOFs).

    Parameters
    ----------
    model : BodyModel
    reaim : ReaimMove
        The root's re-aimed move (the tracker's ``pelvis_reaim``).
    """

    def __init__(self, model, reaim) -> None:
        if reaim is None or list(reaim.coords) != list(range(6)):
            raise TrackerError(f"chain stage: model {model.name} has no re-aimed root move")
        names = list(model.joint_names)
        self.model = model
        self.reaim = reaim
        self.joint_coords = np.array([d for j in CHAIN_JOINTS if j in names for d in model.joint_dofs[names.index(j)]],
                                     dtype=np.int64)
        self.coords = np.concatenate([np.arange(6, dtype=np.int64), self.joint_coords])

    def around(self, x: np.ndarray):
        """``C (n, 6 + k) -> X (n, D)`` around the fixed pose ``x`` (clipped to the model's limits)."""
        x = np.asarray(x, dtype=float)
        move = self.reaim.around(x)
        jc, lo, hi = self.joint_coords, self.model.lower, self.model.upper

        def poses(C: np.ndarray) -> np.ndarray:
            C = np.atleast_2d(np.asarray(C, dtype=float))
            X = move(C[:, :6])
            X[:, jc] += C[:, 6:]
            return np.clip(X, lo, hi)
        return poses

    def start(self, x: np.ndarray) -> np.ndarray:
        """The candidate of ``x`` itself: its root, zero offsets."""
        return np.concatenate([np.asarray(x, dtype=float)[:6], np.zeros(self.joint_coords.size)])

    def spreads(self) -> np.ndarray:
        """Initial spreads of the candidates' coordinates."""
        s = np.full(self.coords.size, JOINT_OFFSET_SPREAD_RAD)
        s[:3] = ROOT_TRANSLATION_SPREAD_M
        s[3:6] = ROOT_ROTATION_SPREAD_RAD
        return s


def refit_chain(tr, ctx, x, *, evals: int, rng: np.random.Generator, energy: float | None = None,
                bounds=None) -> tuple[np.ndarray, float, int, bool]:
    """The chain stage on pose ``x`` on the frame's objective ``ctx.objective``: the configured algorithm's flat
    form searches :class:`ChainMove`'s coordinates around ``x`` (root within ``bounds``, default
    :meth:`search_box` around ``x``, widened to hold it; offsets within ± the search radius); the result replaces
    ``x`` when it lowers the energy.

    ``energy``: ``x``'s energy if known (else one evaluation computes it); the search gets whole generations of the
    rest of ``evals`` but two (the energies of the search's estimate and of its best particle, the lower kept). Returns ``(pose, its energy, evaluations, replaced)``.
    """
    from isa_mocap_ros.optim import make_optimizer, minimize

    m = tr.model
    chain = ChainMove(m, tr.pelvis_reaim)
    x = np.clip(np.asarray(x, dtype=float), m.lower, m.upper)
    lo, hi = bounds if bounds is not None else tr.search_box(x)[:2]
    c0 = chain.start(x)
    r = tr.config.search.search_radius_rad
    k = chain.joint_coords.size
    lo_c = np.concatenate([np.minimum(lo[:6], x[:6]), np.full(k, -r)])
    hi_c = np.concatenate([np.maximum(hi[:6], x[:6]), np.full(k, r)])
    used = 0
    if energy is None:
        energy, used = float(ctx.objective(x[None, :])[0]), 1
    poses = chain.around(x)

    def energy_of(C):
        return ctx.objective(poses(C))

    name, params = plan.flat_algorithm(tr)
    opt = make_optimizer(name, c0, chain.spreads(), rng=rng, bounds=(lo_c, hi_c), rotation_blocks=((3, 4, 5),),
                         **params)
    evals_search = whole_generations(int(evals) - used - 2, opt.generation_size)
    if evals_search < opt.generation_size:
        return x, float(energy), used, False
    res = compiled_search.search(opt, energy_of, evals_search) if tr.use_compiled_search else None
    if res is None:
        res = minimize(opt, energy_of, max_evals=evals_search)
    # the search's estimate and its best particle: the lower of the two (one batch)
    Y = poses(np.stack([res.x, res.best_x]))
    E = ctx.objective(Y)
    i = int(np.argmin(E))
    used += res.n_evals + 2
    if E[i] < energy:
        return Y[i], float(E[i]), used, True
    return x, float(energy), used, False


#: The untwist stage's proposals: each leg's hip twist scaled by these factors, the ankle's twist taking the rest.
UNTWIST_SCALES = (0.0, 0.5)


def untwist_legs(tr, ctx, x, *, energy: float | None = None, tolerance: float = 0.0,
                 scales=UNTWIST_SCALES) -> tuple[np.ndarray, float, int, list[str]]:
    """The untwist stage on pose ``x``: per leg, proposals with the hip's twist (``<side>_hip_z``, the thigh's turn
    about its own axis, which the silhouettes barely see) scaled by each of ``scales`` and the ankle's twist
    (``<side>_ankle_z``) turned the other way by as much (the foot keeps its heading); a leg takes its
    lowest-energy proposal when that energy is below ``x``'s times ``1 + tolerance`` (measured:
    ``docs/history/issue33_knee_s32.md``). Each leg's proposals are scored with ``x`` itself on the energy
    restricted to that leg (the same values); returns ``(pose, its energy, evaluations, legs changed)``, the
    evaluations ``(1 + len(scales))`` per leg + 1 (the returned pose's energy when a leg changed, else ``energy``
    or one evaluation of it)."""
    m = tr.model
    names = list(m.dof_names)
    out = np.clip(np.asarray(x, dtype=float), m.lower, m.upper)
    used, changed = 0, []
    for side in ("left", "right"):
        hip, ankle, leg = f"{side}_hip_z", f"{side}_ankle_z", f"{side}_leg"
        if hip not in names or ankle not in names or leg not in m.partitions:
            continue
        h, a = names.index(hip), names.index(ankle)
        P = np.repeat(out[None, :], len(scales) + 1, axis=0)
        for i, s in enumerate(scales, start=1):
            P[i, h] = s * out[h]
            P[i, a] = out[a] + (1.0 - s) * out[h]
        P = np.clip(P, m.lower, m.upper)
        f = ctx.objective.restrict(out, m.partitions[leg]) or ctx.objective
        E = np.asarray(f(P), dtype=float)
        used += len(P)
        i = 1 + int(np.argmin(E[1:]))
        if E[i] < E[0] + tolerance * abs(E[0]):
            out = P[i]
            changed.append(leg)
    if changed or energy is None:
        energy = float(ctx.objective(out[None, :])[0])
        used += 1
    return out, float(energy), used, changed


def chain_share(tr, notes, budget) -> int | None:
    """Evaluations of the chain stage (:func:`refit_chain`), or None (off, no re-aimed root move, or below one
    generation + 2)."""
    cfg = tr.config
    if cfg.stages.chain_fraction <= 0 or tr.pelvis_reaim is None or not tr.pelvis_reaim.ops:
        return None
    share = int(budget.evals * cfg.stages.chain_fraction)
    n = plan.flat_generation(tr, ChainMove(tr.model, tr.pelvis_reaim).coords.size)
    if share - 2 < n:       # the energies of the search's estimate and of its best particle
        if notes is not None:
            notes.append(f"chain stage skipped: its share ({share} evaluations) is below one generation "
                         f"of {plan.flat_algorithm(tr)[0]} ({n}) + 2")
        return None
    return share


def untwist_share(tr) -> int:
    """Evaluations of the untwist stage (``chain_moves.untwist_legs``): ``1 + len(UNTWIST_SCALES)`` per leg with
    a hip and an ankle twist, + 1; 0 when off."""
    if not tr.config.stages.leg_untwist:
        return 0
    names = set(tr.model.dof_names)
    legs = sum(f"{s}_hip_z" in names and f"{s}_ankle_z" in names for s in ("left", "right"))
    return (1 + len(UNTWIST_SCALES)) * legs + 1 if legs else 0
