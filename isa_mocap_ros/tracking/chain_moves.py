"""Whole-leg moves for the clean walks' knee (issue 33): the untwist stage, an option.

Why: on the clean mesh walks a run restarted at the truth every frame ends at a lower energy than the free run
and with a better knee; the free run's pelvis orientation, lower spine and thighs' twists wander along directions
the silhouettes barely see (``docs/history/issue33_knee_s31.md``, ``docs/history/issue33_knee_s32.md``; a chain
stage searching root, lower spine, hips and knees together was measured worse there and removed).

:func:`untwist_legs` (the untwist stage, ``StageConfig.leg_untwist``): per leg, the thigh's twist about its own
axis halved and undone, the ankle turned back by as much; a leg takes its best proposal when its energy is below
the pose's times ``1 + leg_untwist_tolerance`` plus ``leg_untwist_margin``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["untwist_legs", "untwist_share", "parse_untwist_tolerance", "UNTWIST_SCALES"]


#: The untwist stage's proposals: each leg's hip twist scaled by these factors, the ankle's twist taking the rest.
UNTWIST_SCALES = (0.0, 0.5)


def untwist_legs(tr, ctx, x, *, energy: float | None = None, tolerance: float = 0.0, margin: float = 0.0,
                 scales=UNTWIST_SCALES) -> tuple[np.ndarray, float, int, list[str]]:
    """The untwist stage on pose ``x``: per leg, proposals with the hip's twist (``<side>_hip_z``, the thigh's turn
    about its own axis, which the silhouettes barely see) scaled by each of ``scales`` and the ankle's twist
    (``<side>_ankle_z``) turned the other way by as much (the foot keeps its heading); a leg takes its
    lowest-energy proposal when that energy is below ``x``'s times ``1 + tolerance`` plus ``margin`` (an absolute
    price, which the clutter of occluders or noise does not inflate as it inflates ``x``'s energy; measured:
    ``docs/history/issue33_knee_s32.md``, ``docs/history/issue33_untwist_s33.md``). Each leg's proposals are scored with ``x`` itself on the energy
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
        if E[i] < E[0] + tolerance * abs(E[0]) + margin:
            out = P[i]
            changed.append(leg)
    if changed or energy is None:
        energy = float(ctx.objective(out[None, :])[0])
        used += 1
    return out, float(energy), used, changed


def untwist_share(tr) -> int:
    """Evaluations of the untwist stage (``chain_moves.untwist_legs``): ``1 + len(UNTWIST_SCALES)`` per leg with
    a hip and an ankle twist, + 1; 0 when off."""
    if not tr.config.stages.leg_untwist:
        return 0
    names = set(tr.model.dof_names)
    legs = sum(f"{s}_hip_z" in names and f"{s}_ankle_z" in names for s in ("left", "right"))
    return (1 + len(UNTWIST_SCALES)) * legs + 1 if legs else 0


def parse_untwist_tolerance(text: str):
    """A command line's untwist tolerance (``track``/``bench mesh --leg-untwist``): a number >= 0, or ``"off"``
    (the stage off); ValueError otherwise."""
    if text.strip().lower() == "off":
        return "off"
    try:
        tol = float(text)
    except ValueError:
        tol = float("nan")
    if not tol >= 0.0:
        raise ValueError(f"expected a tolerance >= 0 or 'off', received {text!r}")
    return tol
