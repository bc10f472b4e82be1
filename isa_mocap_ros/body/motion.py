"""Parametric motion generator: walking, jogging, arm waving and boxing for any body model.

Needs no data file (DESIGN §6: the shipped bags are rendered from motion the project generates
itself). :func:`generate_motion` returns pose vectors ``(F, D)`` in the layout of DESIGN §3 (root
translation, root rotation vector, joint angles in ``model.dof_names`` order) for the 39-, 28- and
18-DOF models; a DOF the model lacks is skipped (e.g. no ankles in the 28-DOF model, no arms in the
18-DOF one).

How a motion is made
--------------------
1. **Joint-angle curves.** Gaits (``walk``, ``jog``, ``walk_turns``) use one periodic curve per
   quantity over the gait cycle (heel strike of the left foot at phase 0, the right leg half a cycle
   later), interpolated by periodic cubic splines through key frames shaped like clinical gait data
   (sagittal thigh angle, knee flexion, foot pitch): knee flexion peak ~60° in walking swing and
   ~95° in jogging, loading-response knee flexion, heel strike, foot flat, heel rise and toe-off.
   The ankle angle is derived from the foot-pitch curve (``ankle = flat - pitch - hip - knee``), so
   the sole is flat in mid stance whatever the thigh and knee do. Arms swing against the legs,
   elbows flex (jog ~85°), the pelvis rotates and tilts sideways with the step, the spine
   counter-rotates and the hips compensate the pelvic tilt. ``wave`` stands (slow weight shift) and
   raises the right arm to wave above the head; ``box`` is a boxing stance (feet apart, knees bent,
   bouncing, guard) with jabs (left) and crosses (right) at random intervals, the trunk twisting
   with each punch.
2. **Joint limits.** Every joint angle is clipped to ``[model.lower, model.upper]``.
3. **Foot locking** (the root translation is *derived*, never drawn). Forward kinematics with the
   root at the origin (root rotation applied) gives the four foot spheres (the two ends of each
   foot capsule: heel/ankle ball and toe ball). In each frame the support sphere is the lowest
   sphere of the legs in stance (by gait phase; both legs for standing motions); the root moves
   horizontally so that this sphere's centre keeps its world position from the previous frame
   (a pivot without slip). The root height puts the lowest point of the whole skin (the lowest
   capsule end ball) exactly on the floor ``z = 0``, so nothing goes through the floor and the
   pelvis bob follows from the leg geometry. In a flight phase (jogging: no leg in stance) the
   root keeps its horizontal velocity and rises on a ballistic parabola (g = 9.81 m/s²).
4. **Stride.** For gaits the amplitude of the sagittal thigh curve is scaled (fixed-point
   iteration) until the foot-locked root advances ``stride_m`` per gait cycle; the cycle time is
   ``stride_m / speed_mps``. The path is centred on the world origin (x, y).

Randomness: every draw comes from the ``rng`` argument (a :class:`numpy.random.Generator`): the
starting phase, ±3 % cadence, ±4 % stride, ±10-20 % secondary amplitudes (arm swing, pelvis,
trunk), small left/right asymmetries, wave frequency, punch timing. The same seed gives identical
poses; another seed a slightly different motion of the same kind.

Measured (``test/test_motion.py``, default shape, 30 fps): the centre of a foot ball in contact
with the floor moves less than 2 cm horizontally per step; no capsule goes below the floor.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from ..geometry import log_so3, rot_x, rot_y, rot_z
from .kinematics import joint_positions
from .model import BodyError, BodyModel

__all__ = ["MOTIONS", "MotionError", "generate_motion", "motion_defaults"]

#: names accepted by :func:`generate_motion`
MOTIONS = ("walk", "jog", "walk_turns", "wave", "box")

_G = 9.81
_D = np.deg2rad


class MotionError(BodyError):
    """Bad argument to the motion generator (a :class:`BodyError`, hence a ``ValueError``)."""


@dataclass(frozen=True)
class _Gait:
    speed: float            # m/s
    stride: float           # m per gait cycle (two steps)
    duty: float             # fraction of the cycle a foot is in stance
    thigh: tuple            # key frames (percent, degrees): thigh angle from vertical, + forward
    knee: tuple             # knee flexion, degrees
    foot: tuple             # foot pitch (sole vs floor), + toe up
    shoulder_mean: float    # shoulder flexion mean (+ forward), degrees
    shoulder_gain: float    # arm swing per unit of (opposite) thigh swing
    elbow_mean: float       # elbow flexion, degrees
    elbow_gain: float
    lean: float             # trunk forward lean, degrees
    pelvis_yaw: float       # pelvis rotation amplitude, degrees
    pelvis_roll: float      # pelvic obliquity amplitude, degrees


_WALK = _Gait(
    speed=1.2, stride=1.30, duty=0.62,
    thigh=((0, 22), (10, 20), (30, 5), (50, -14), (57, -15), (65, -8), (75, 8), (87, 24), (100, 22)),
    knee=((0, 3), (8, 14), (15, 17), (30, 8), (40, 5), (50, 10), (60, 36), (70, 60), (76, 58), (85, 35),
          (93, 8), (100, 3)),
    foot=((0, 16), (6, 4), (10, 0), (38, 0), (46, -5), (53, -16), (58, -28), (62, -42), (68, -38), (76, -15),
          (86, 5), (94, 12), (100, 16)),
    shoulder_mean=-3.0, shoulder_gain=0.75, elbow_mean=18.0, elbow_gain=0.25, lean=3.0,
    pelvis_yaw=4.0, pelvis_roll=4.0)

_JOG = _Gait(
    speed=2.6, stride=1.95, duty=0.38,
    thigh=((0, 24), (12, 12), (30, -10), (38, -18), (46, -14), (60, 8), (75, 32), (88, 33), (100, 24)),
    knee=((0, 16), (12, 38), (25, 30), (38, 20), (50, 62), (63, 95), (72, 90), (85, 45), (95, 18), (100, 16)),
    foot=((0, 10), (6, 0), (20, 0), (30, -15), (38, -40), (48, -40), (62, -25), (78, 0), (90, 8), (100, 10)),
    shoulder_mean=-5.0, shoulder_gain=0.9, elbow_mean=85.0, elbow_gain=0.2, lean=8.0,
    pelvis_yaw=6.0, pelvis_roll=4.0)


def motion_defaults(name: str) -> dict:
    """Default parameters of a motion: ``{"speed_mps", "stride_m", "turn_deg_per_s"}`` (gaits) or ``{}``.

    Without ``stride_m`` the stride scales as ``(speed / default speed) ** 0.6``; without
    ``speed_mps`` the speed follows the stride at the default cadence (both ±3-4 % random).
    """
    name = _check_name(name)
    if name == "walk":
        return {"speed_mps": _WALK.speed, "stride_m": _WALK.stride, "turn_deg_per_s": 0.0}
    if name == "walk_turns":
        return {"speed_mps": 1.0, "stride_m": round(_WALK.stride * (1.0 / _WALK.speed) ** 0.6, 3),
                "turn_deg_per_s": 0.0}
    if name == "jog":
        return {"speed_mps": _JOG.speed, "stride_m": _JOG.stride, "turn_deg_per_s": 0.0}
    return {}


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------
def _check_name(name) -> str:
    if not isinstance(name, str) or name not in MOTIONS:
        raise MotionError(f"name: expected one of {', '.join(MOTIONS)}, received {name!r}")
    return name


def _positive(arg: str, value, *, allow_none: bool = False, allow_zero: bool = False):
    if value is None and allow_none:
        return None
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) \
        and np.isfinite(value) and (value >= 0 if allow_zero else value > 0)
    if not ok:
        raise MotionError(f"{arg}: expected a finite number {'>= 0' if allow_zero else '> 0'}, received {value!r}")
    return float(value)


def _periodic(keys, phase: np.ndarray) -> np.ndarray:
    """Periodic cubic spline through ``keys`` ((percent, degrees), first == last) at ``phase`` in cycles."""
    k = np.asarray(keys, dtype=float)
    cs = CubicSpline(k[:, 0] / 100.0, k[:, 1], bc_type="periodic")
    return cs(np.mod(phase, 1.0))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


class _Pose:
    """Joint angles by DOF name; names the model lacks are dropped silently."""

    def __init__(self, model: BodyModel, n: int):
        self.model = model
        self.X = np.zeros((n, model.dof))
        self.index = {name: i for i, name in enumerate(model.dof_names)}

    def has(self, name: str) -> bool:
        return name in self.index

    def set(self, name: str, values) -> None:
        i = self.index.get(name)
        if i is not None:
            self.X[:, i] = values

    def add(self, name: str, values) -> None:
        i = self.index.get(name)
        if i is not None:
            self.X[:, i] += values

    def spine(self, axis: str, total) -> None:
        """Spread a total rotation over the spine joints the model has (lower, upper)."""
        names = [f"spine_{p}_{axis}" for p in ("lower", "upper") if self.has(f"spine_{p}_{axis}")]
        for n in names:
            self.add(n, np.asarray(total) / len(names))


def _flat_foot_angle(model: BodyModel, side: str) -> float:
    """Ankle ``y`` angle (rad) at which the foot capsule's two balls touch a level floor together
    (leg vertical); 0 when the model has no ankle DOF or no foot capsule."""
    name = f"{side}_foot"
    if name not in model.capsule_names:
        return 0.0
    c = model.capsule_names.index(name)
    r0, r1 = model.capsule_radii[c]
    toe = model.offsets[model.capsules[c, 1]]
    ox, oz = float(toe[0]), float(toe[2])
    rho = float(np.hypot(ox, oz))
    # rotating (ox, oz) by a about y gives z' = rho sin(phi - a); want z' = r1 - r0
    phi = np.arctan2(oz, ox)
    return float(phi - np.arcsin(np.clip((r1 - r0) / rho, -1.0, 1.0)))


def _foot_spheres(model: BodyModel):
    """[(joint index, radius, side)] of the two balls of each foot capsule."""
    out = []
    for side in ("left", "right"):
        name = f"{side}_foot"
        if name not in model.capsule_names:
            raise MotionError(f"model: expected foot capsules ('{name}') for foot locking, model {model.name} has "
                              f"{', '.join(model.capsule_names)}")
        c = model.capsule_names.index(name)
        for end in (0, 1):
            out.append((int(model.capsules[c, end]), float(model.capsule_radii[c, end]), side))
    return out


def _root_rotvec(yaw, pitch, roll) -> np.ndarray:
    """Rotation vectors of ``Rz(yaw) Ry(pitch) Rx(roll)``, unwrapped so consecutive frames stay close."""
    R = rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)
    w = log_so3(R)
    for k in range(1, len(w)):
        th = np.linalg.norm(w[k])
        if th > 1e-9:
            alt = w[k] * (1.0 - 2.0 * np.pi / th)
            if np.linalg.norm(alt - w[k - 1]) < np.linalg.norm(w[k] - w[k - 1]):
                w[k] = alt
    return w


# ---------------------------------------------------------------------------------------------
# foot locking
# ---------------------------------------------------------------------------------------------
def _foot_lock(model: BodyModel, X: np.ndarray, stance: np.ndarray, dt: float) -> np.ndarray:
    """Root translation from the support foot (module docstring, step 3).

    Parameters
    ----------
    X : (F, D) poses; the root translation is ignored and replaced.
    stance : (F, 2) bool, left/right leg in stance.
    dt : frame period, s.

    Returns
    -------
    (F, D) poses with root translation set (path not yet centred).
    """
    X = X.copy()
    X[:, :3] = 0.0
    P = joint_positions(model, X)                                    # (F, J, 3), root at origin
    spheres = _foot_spheres(model)
    centres = np.stack([P[:, j] for j, _, _ in spheres], axis=1)     # (F, 4, 3)
    radii = np.array([r for _, r, _ in spheres])
    leg = np.array([0 if s == "left" else 1 for _, _, s in spheres])
    ends = P[:, model.capsules]                                      # (F, C, 2, 3)
    lowest = np.min(ends[..., 2] - model.capsule_radii[None], axis=(1, 2))   # (F,)
    F = X.shape[0]
    T = np.zeros((F, 3))
    flight = ~stance.any(axis=1)
    # ballistic height within each flight run
    bump = np.zeros(F)
    k = 0
    while k < F:
        if flight[k]:
            j = k
            while j < F and flight[j]:
                j += 1
            a, b = (k - 0.5) * dt, (j - 0.5) * dt          # lift-off / touch-down between frames
            t = np.arange(k, j) * dt
            bump[k:j] = 0.5 * _G * (t - a) * (b - t)
            k = j
        else:
            k += 1
    vel = np.zeros(2)
    for k in range(1, F):
        if flight[k]:
            T[k, :2] = T[k - 1, :2] + vel
        else:
            bottoms = centres[k, :, 2] - radii
            cand = np.where(stance[k][leg], bottoms, np.inf)
            s = int(np.argmin(cand))
            T[k, :2] = T[k - 1, :2] - (centres[k, s, :2] - centres[k - 1, s, :2])
            vel = T[k, :2] - T[k - 1, :2]
    T[:, 2] = -lowest + bump
    X[:, :3] = T
    return X


# ---------------------------------------------------------------------------------------------
# the motions
# ---------------------------------------------------------------------------------------------
def _gait(model, t, g: _Gait, *, cycle, thigh_scale, phase0, heading, rng_par) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles (root translation zero) and stance flags ``(F, 2)`` of a gait.

    ``heading`` is a function of time (s, array) -> facing direction (rad). Each foot keeps the
    heading it had at touch-down during its whole stance and turns to the next touch-down heading
    during swing; the hip rotation (``hip_z``) absorbs the difference to the pelvis yaw, so a
    planted foot does not twist on the floor while the body turns or the pelvis rotates.
    """
    F = len(t)
    p = _Pose(model, F)
    ph = {"left": phase0 + t / cycle, "right": phase0 + t / cycle + 0.5}
    amp = rng_par["amp"]
    stance = np.zeros((F, 2), dtype=bool)
    thigh_mean = np.mean(np.asarray(g.thigh)[:-1, 1])
    roll = _D(g.pelvis_roll * amp * rng_par["roll"]) * np.sin(2 * np.pi * (ph["left"] + 0.05))
    yaw_osc = -_D(g.pelvis_yaw * amp * rng_par["yaw"]) * np.cos(2 * np.pi * ph["left"])
    pelvis_yaw = heading(t) + yaw_osc
    for i, side in enumerate(("left", "right")):
        s = rng_par["asym"][i]
        thigh = thigh_mean + thigh_scale * s * (_periodic(g.thigh, ph[side]) - thigh_mean)
        knee = _periodic(g.knee, ph[side]) * (1.0 + 0.5 * (s - 1.0))
        foot = _periodic(g.foot, ph[side])
        hip_y = -_D(thigh)
        knee_y = _D(knee)
        p.set(f"{side}_hip_y", hip_y)
        p.set(f"{side}_knee_y", knee_y)
        p.set(f"{side}_ankle_y", _flat_foot_angle(model, side) - _D(foot) - hip_y - knee_y)
        # frontal plane: legs compensate the pelvic obliquity, feet slightly inside the hips
        sign = 1.0 if side == "left" else -1.0
        p.set(f"{side}_hip_x", -roll - sign * _D(1.5))
        # foot heading: fixed in stance, turning in swing; the hip rotation takes up the rest
        frac = np.mod(ph[side], 1.0)
        h_prev = heading(t - frac * cycle)
        h_next = heading(t + (1.0 - frac) * cycle)
        u = _smoothstep((frac - g.duty) / (1.0 - g.duty))
        p.set(f"{side}_hip_z", h_prev + u * (h_next - h_prev) - pelvis_yaw)
        # arm swings against the same-side leg
        opp = "right" if side == "left" else "left"
        opp_thigh = thigh_mean + thigh_scale * (_periodic(g.thigh, ph[opp]) - thigh_mean)
        swing = amp * rng_par["arm"][i] * g.shoulder_gain * (opp_thigh - thigh_mean)
        p.set(f"{side}_shoulder_y", -_D(g.shoulder_mean + swing))
        p.set(f"{side}_shoulder_x", sign * _D(7.0 + 2.0 * rng_par["arm"][i]))
        p.set(f"{side}_elbow_y", -_D(g.elbow_mean * rng_par["elbow"] + g.elbow_gain * np.maximum(swing, 0.0)))
        stance[:, i] = frac < g.duty
    # trunk: lean forward, counter-rotate the thorax, keep it upright against the obliquity
    p.spine("y", np.full(F, _D(g.lean * rng_par["lean"])))
    p.spine("z", -1.5 * yaw_osc)
    p.spine("x", -0.8 * roll)
    p.set("neck_z", 0.5 * yaw_osc)
    p.set("neck_y", np.full(F, -_D(g.lean * rng_par["lean"]) * 0.5))
    p.X[:, 3:6] = _root_rotvec(pelvis_yaw, np.zeros(F), roll)
    return p.X, stance


def _heading(name: str, turn_rate: float, heading0: float, rng):
    """Heading (rad) as a function of time: ``heading0`` plus a constant turn rate, plus for
    ``walk_turns`` a rounded square (straight ~0.9 s, then 90° left in ~1.6 s)."""
    rate0 = _D(turn_rate)
    if name != "walk_turns":
        return lambda tt: heading0 + rate0 * np.asarray(tt, dtype=float)
    straight = 0.9 * (1.0 + 0.1 * rng.uniform(-1, 1))
    turn_s = 1.6 * (1.0 + 0.1 * rng.uniform(-1, 1))
    rate = np.pi / 2 / turn_s
    period = straight + turn_s
    shift = 0.5 * straight                                   # start half-way along a side

    def f(tt):
        tt = np.asarray(tt, dtype=float) + shift
        n = np.floor(tt / period)
        within = np.clip(tt - n * period - straight, 0.0, turn_s)
        return heading0 + n * np.pi / 2 + rate * within + rate0 * (tt - shift)
    return f


def _gait_motion(name, model, t, dt, *, speed, stride, turn, amplitude, heading0, rng) -> np.ndarray:
    g = _JOG if name == "jog" else _WALK
    base_speed = 1.0 if name == "walk_turns" else g.speed
    if stride is None:
        stride_t = g.stride * ((speed if speed is not None else base_speed) / g.speed) ** 0.6
        stride_t *= 1.0 + 0.04 * rng.uniform(-1, 1)
    else:
        stride_t = stride
    if speed is None:
        speed = base_speed * (stride_t / (g.stride * (base_speed / g.speed) ** 0.6)) * (1.0 + 0.03 * rng.uniform(-1, 1))
    cycle = stride_t / speed
    par = {"amp": amplitude, "roll": rng.uniform(0.8, 1.2), "yaw": rng.uniform(0.8, 1.2),
           "asym": 1.0 + 0.03 * rng.uniform(-1, 1, 2), "arm": rng.uniform(0.85, 1.15, 2),
           "elbow": rng.uniform(0.9, 1.1), "lean": rng.uniform(0.7, 1.3)}
    phase0 = rng.uniform(0.0, 1.0)
    heading = _heading(name, turn, heading0 + _D(rng.uniform(-3, 3)), rng)
    straight = _heading("walk", 0.0, 0.0, rng)
    scale = 1.0
    n_ref = max(int(round(2 * cycle / dt)) + 1, 8)
    tr = np.arange(n_ref) * dt
    for _ in range(8):                      # match the stride on a straight reference (docstring, 4)
        Xr, sr = _gait(model, tr, g, cycle=cycle, thigh_scale=scale, phase0=phase0, heading=straight,
                       rng_par=par)
        Xr = _foot_lock(model, _clip(model, Xr), sr, dt)
        achieved = np.linalg.norm(Xr[-1, :2] - Xr[0, :2]) / (tr[-1] / cycle)
        if achieved <= 0:
            break
        new = float(np.clip(scale * stride_t / achieved, 0.3, 2.0))
        done = abs(new - scale) < 1e-3
        scale = new
        if done:
            break
    X, stance = _gait(model, t, g, cycle=cycle, thigh_scale=scale, phase0=phase0, heading=heading, rng_par=par)
    return _foot_lock(model, _clip(model, X), stance, dt)


def _stance_legs(p: _Pose, model, *, hip_flex, knee, hip_abd, foot_pitch=0.0) -> None:
    """Both legs alike (mirrored abduction), soles flat."""
    for side, sign in (("left", 1.0), ("right", -1.0)):
        hip_y = -hip_flex
        p.set(f"{side}_hip_y", hip_y)
        p.set(f"{side}_knee_y", knee)
        p.set(f"{side}_hip_x", sign * hip_abd)
        p.set(f"{side}_ankle_y", _flat_foot_angle(model, side) - foot_pitch - hip_y - knee)


def _wave(model, t, *, heading, amplitude, rng) -> np.ndarray:
    F = len(t)
    p = _Pose(model, F)
    f_sway = rng.uniform(0.2, 0.3)
    sway = _D(2.0) * amplitude * np.sin(2 * np.pi * f_sway * t + rng.uniform(0, 2 * np.pi))
    _stance_legs(p, model, hip_flex=np.full(F, _D(2.0)), knee=np.full(F, _D(4.0)), hip_abd=np.full(F, _D(3.0)))
    p.add("left_hip_x", sway)
    p.add("right_hip_x", sway)
    p.spine("x", -sway)
    # right arm: raise (0.8 s) then wave side to side above the head
    t_up = rng.uniform(0.6, 1.0)
    up = _smoothstep(t / t_up)
    f_w = rng.uniform(1.6, 2.4)
    osc = np.sin(2 * np.pi * f_w * t)
    a = amplitude * rng.uniform(0.85, 1.15)
    p.set("right_shoulder_y", -up * _D(150.0))
    p.set("right_shoulder_x", -up * _D(20.0 + 20.0 * a * osc))
    p.set("right_elbow_y", -up * _D(35.0 + 15.0 * a * np.sin(2 * np.pi * f_w * t + 0.6)))
    p.set("right_wrist_x", up * _D(10.0 * a) * osc)
    p.set("left_shoulder_x", np.full(F, _D(6.0)))
    p.set("left_elbow_y", np.full(F, -_D(12.0)))
    p.set("neck_y", np.full(F, -_D(5.0)))
    p.set("neck_z", -up * _D(8.0))
    p.X[:, 3:6] = _root_rotvec(np.full(F, heading), np.zeros(F), np.zeros(F))
    return p.X


def _punch_profile(t, starts, *, out_s, hold_s, back_s) -> np.ndarray:
    prof = np.zeros_like(t)
    for s in starts:
        x = t - s
        rise = _smoothstep(x / out_s)
        fall = 1.0 - _smoothstep((x - out_s - hold_s) / back_s)
        prof = np.maximum(prof, np.where(x < 0, 0.0, np.minimum(rise, fall)))
    return prof


def _box(model, t, *, heading, amplitude, rng) -> np.ndarray:
    F = len(t)
    p = _Pose(model, F)
    f_b = rng.uniform(1.6, 2.1)
    bounce = amplitude * _D(6.0) * 0.5 * (1.0 - np.cos(2 * np.pi * f_b * t))
    _stance_legs(p, model, hip_flex=_D(14.0) + 0.5 * bounce, knee=_D(26.0) + bounce, hip_abd=np.zeros(F))
    # punches: alternate mostly, random intervals
    starts = {"left": [], "right": []}
    s, side = rng.uniform(0.3, 0.6), "left"
    while s < t[-1] + 1.0:
        starts[side].append(s)
        if rng.uniform() < 0.75:
            side = "right" if side == "left" else "left"
        s += rng.uniform(0.45, 0.85)
    prof = {k: _punch_profile(t, v, out_s=0.13, hold_s=0.05, back_s=0.22) for k, v in starts.items()}
    stance_twist = _D(-30.0)                 # orthodox stance: left side forward
    twist = -stance_twist * 0.7 + amplitude * (_D(16.0) * prof["right"] - _D(8.0) * prof["left"])
    p.spine("z", twist)
    p.spine("y", np.full(F, _D(8.0)))
    p.set("neck_z", -0.3 * twist - 0.3 * stance_twist)
    p.set("neck_y", np.full(F, -_D(6.0)))
    for side, sign in (("left", 1.0), ("right", -1.0)):
        pr = amplitude * prof[side]
        p.set(f"{side}_shoulder_y", -_D(45.0 + 42.0 * pr))
        p.set(f"{side}_shoulder_x", sign * _D(18.0 - 12.0 * pr))
        p.set(f"{side}_shoulder_z", -sign * _D(20.0 * (1.0 - pr)))
        p.set(f"{side}_elbow_y", -_D(125.0 - 113.0 * pr))
    p.X[:, 3:6] = _root_rotvec(np.full(F, heading + stance_twist), np.zeros(F), np.zeros(F))
    return p.X


def _clip(model: BodyModel, X: np.ndarray) -> np.ndarray:
    X = X.copy()
    X[:, 6:] = np.clip(X[:, 6:], model.lower[6:], model.upper[6:])
    return X


# ---------------------------------------------------------------------------------------------
# public
# ---------------------------------------------------------------------------------------------
def generate_motion(name: str, model: BodyModel, *, duration_s: float, fps: float, rng: np.random.Generator,
                    speed_mps: float | None = None, stride_m: float | None = None, turn_deg_per_s: float = 0.0,
                    amplitude: float = 1.0, heading_deg: float = 0.0) -> np.ndarray:
    """Generate a motion as pose vectors.

    Parameters
    ----------
    name : {"walk", "jog", "walk_turns", "wave", "box"}
        ``walk_turns`` walks a rounded square at 1.0 m/s by default (straight ~0.9 s, then a 90°
        left turn in ~1.6 s), staying within about ±1.6 m of the origin.
    model : BodyModel
        Any model from :func:`make_model` (39, 28 or 18 DOF) or a BVH-sized one.
    duration_s : float, keyword-only
        Length in seconds (> 0); ``F = round(duration_s * fps)`` frames (at least 2).
    fps : float, keyword-only
        Frames per second (> 0).
    rng : numpy.random.Generator, keyword-only
        Source of all random variation (module docstring).
    speed_mps : float, optional
        Gaits: walking speed (default 1.2 m/s walking, 2.6 m/s jogging, ±3 % random).
    stride_m : float, optional
        Gaits: distance per gait cycle (two steps); default 1.30 m walking, 1.95 m jogging (±4 %),
        scaled with ``speed_mps`` when only the speed is given.
    turn_deg_per_s : float
        Gaits: constant turning rate (positive = left); added to the turns of ``walk_turns``.
    amplitude : float
        Scale of the secondary motions (arm swing, pelvis, trunk) of gaits and of the gestures
        (wave, punches, bounce); 1 = natural. Must be in ``[0, 2]``.
    heading_deg : float
        Initial facing direction (0 = +x, positive = towards +y).

    Returns
    -------
    X : (F, D) ndarray
        Poses (DESIGN §3) within the model's joint limits, feet locked to the floor ``z = 0``,
        path centred on the origin in x and y.

    Raises
    ------
    MotionError
        Unknown name, non-positive duration/fps/speed/stride, amplitude outside ``[0, 2]``, a rng
        that is not a Generator, or a path that leaves the root translation limits (±10 m).
    """
    name = _check_name(name)
    if not isinstance(model, BodyModel):
        raise MotionError(f"model: expected a BodyModel, received {type(model).__name__}")
    duration_s = _positive("duration_s", duration_s)
    fps = _positive("fps", fps)
    if not isinstance(rng, np.random.Generator):
        raise MotionError(f"rng: expected a numpy.random.Generator, received {type(rng).__name__}")
    speed_mps = _positive("speed_mps", speed_mps, allow_none=True)
    stride_m = _positive("stride_m", stride_m, allow_none=True)
    for arg, v in (("turn_deg_per_s", turn_deg_per_s), ("heading_deg", heading_deg)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v):
            raise MotionError(f"{arg}: expected a finite number, received {v!r}")
    amplitude = _positive("amplitude", amplitude, allow_zero=True)
    if amplitude > 2.0:
        raise MotionError(f"amplitude: expected a number in [0, 2], received {amplitude!r}")
    F = max(2, int(round(duration_s * fps)))
    dt = 1.0 / fps
    t = np.arange(F) * dt
    heading = _D(float(heading_deg))
    if name in ("walk", "jog", "walk_turns"):
        X = _gait_motion(name, model, t, dt, speed=speed_mps, stride=stride_m, turn=float(turn_deg_per_s),
                         amplitude=amplitude, heading0=heading, rng=rng)
    else:
        make = _wave if name == "wave" else _box
        X = make(model, t, heading=heading, amplitude=amplitude, rng=rng)
        X = _foot_lock(model, _clip(model, X), np.ones((F, 2), dtype=bool), dt)
    # centre the path on the origin
    centre = 0.5 * (X[:, :2].min(axis=0) + X[:, :2].max(axis=0))
    X[:, :2] -= centre
    lo, hi = model.lower[:3], model.upper[:3]
    if np.any(X[:, :3] < lo) or np.any(X[:, :3] > hi):
        ext = np.ptp(X[:, :2], axis=0)
        raise MotionError(f"duration_s: the {name} path spans {ext[0]:.1f} x {ext[1]:.1f} m, expected it within the "
                          f"root translation limits {lo.tolist()}..{hi.tolist()} m; received duration_s={duration_s} "
                          "(shorten it or add turning)")
    return X

