"""Motion generator: physical plausibility (foot sliding, floor), limits, determinism, bad input."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.body import BodyError, joint_positions, make_model
from isa_mocap_ros.body.motion import MOTIONS, MotionError, generate_motion

FPS = 30.0
CONTACT_M = 0.001      # a foot ball touches the floor when its bottom is within 1 mm of z = 0


@pytest.fixture(scope="module")
def models():
    return {d: make_model(d) for d in (39, 28, 18)}


def _foot_balls(model):
    """(joint index, radius) of the two end balls of each foot capsule."""
    out = []
    for side in ("left", "right"):
        c = model.capsule_names.index(f"{side}_foot")
        for end in (0, 1):
            out.append((int(model.capsules[c, end]), float(model.capsule_radii[c, end])))
    return out


def sliding_per_contact(model, X):
    """Horizontal path (m) of each foot ball's centre over each run of consecutive frames in
    which the ball touches the floor (an independent measure: no generator internals)."""
    P = joint_positions(model, X)
    runs = []
    for j, r in _foot_balls(model):
        c = P[:, j]
        touch = (c[:, 2] - r) < CONTACT_M
        acc = None
        for k in range(1, len(X)):
            if touch[k] and touch[k - 1]:
                acc = (acc or 0.0) + float(np.linalg.norm(c[k, :2] - c[k - 1, :2]))
            elif acc is not None:
                runs.append(acc)
                acc = None
        if acc is not None:
            runs.append(acc)
    return np.array(runs)


@pytest.mark.parametrize("dof", [39, 28, 18])
@pytest.mark.parametrize("name", MOTIONS)
def test_plausible(models, name, dof):
    model = models[dof]
    for seed in (0, 1):
        X = generate_motion(name, model, duration_s=3.0, fps=FPS, rng=np.random.default_rng(seed))
        assert X.shape == (90, model.dof)
        assert np.all(np.isfinite(X))
        # joint limits
        assert np.all(X[:, 6:] >= model.lower[6:] - 1e-12) and np.all(X[:, 6:] <= model.upper[6:] + 1e-12)
        assert np.all(X[:, :3] >= model.lower[:3]) and np.all(X[:, :3] <= model.upper[:3])
        # nothing below the floor by more than 1 cm, and the body stands on it (not floating)
        P = joint_positions(model, X)
        lowest = np.min(P[:, model.capsules][..., 2] - model.capsule_radii, axis=(1, 2))
        assert lowest.min() > -0.01
        if name != "jog":
            assert np.abs(lowest).max() < 0.005
        else:
            assert np.median(lowest) < 0.005 and lowest.max() < 0.05      # short flight phases
        # a foot touching the floor does not slide along it
        runs = sliding_per_contact(model, X)
        assert len(runs) > 0
        # the 28-DOF model has no ankle: its foot cannot roll, the toe may drag a little at toe-off
        bound = 0.025 if "left_ankle_y" in model.dof_names else 0.035
        assert runs.max() < bound, f"sliding {runs.max() * 100:.2f} cm"
        assert runs.mean() < 0.01


@pytest.mark.parametrize("name,speed", [("walk", 1.2), ("jog", 2.6), ("walk_turns", 1.0)])
def test_gait_speed_and_progress(models, name, speed):
    model = models[39]
    X = generate_motion(name, model, duration_s=4.0, fps=FPS, rng=np.random.default_rng(3))
    path = np.linalg.norm(np.diff(X[:, :2], axis=0), axis=1).sum() / (len(X) / FPS)
    assert abs(path - speed) < 0.2 * speed
    if name == "walk_turns":
        span = np.ptp(X[:, :2], axis=0)
        assert np.all(span > 1.0) and np.all(np.abs(X[:, :2]) < 2.0)   # turns, stays in the capture area
        yaw = np.unwrap(np.arctan2(*np.diff(X[::6, :2], axis=0)[:, ::-1].T))
        assert np.ptp(yaw) > np.pi / 2
    else:
        d = X[-1, :2] - X[0, :2]
        assert abs(d[1]) < 0.15 * abs(d[0])                             # straight along +x


def test_stride_and_speed_parameters(models):
    model = models[39]
    for stride, speed in ((1.0, 0.9), (1.5, 1.5)):
        X = generate_motion("walk", model, duration_s=4.0, fps=FPS, rng=np.random.default_rng(0),
                            stride_m=stride, speed_mps=speed)
        v = np.linalg.norm(X[-1, :2] - X[0, :2]) / ((len(X) - 1) / FPS)
        assert abs(v - speed) < 0.1 * speed


def test_knee_curve_shape(models):
    """Walking knee flexion: two peaks per cycle, swing peak 50-70 degrees, near-straight at heel strike."""
    model = models[39]
    X = generate_motion("walk", model, duration_s=3.0, fps=FPS, rng=np.random.default_rng(0))
    knee = np.rad2deg(X[:, model.knee_dofs[0]])
    assert 50 < knee.max() < 70 and knee.min() < 8


def test_turning_parameter(models):
    model = models[39]
    X = generate_motion("walk", model, duration_s=3.0, fps=FPS, rng=np.random.default_rng(0), turn_deg_per_s=30.0)
    d = np.diff(X[:, :2], axis=0)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    turned = np.rad2deg(heading[-15:].mean() - heading[:15].mean())
    assert 50 < turned < 110          # ~30 deg/s over ~2.5 s between the two windows


def test_wave_raises_right_arm_box_punches(models):
    model = models[39]
    X = generate_motion("wave", model, duration_s=3.0, fps=FPS, rng=np.random.default_rng(0))
    P = joint_positions(model, X)
    head = P[:, model.joint_index("head_top"), 2]
    rhand = P[:, model.joint_index("right_hand"), 2]
    lhand = P[:, model.joint_index("left_hand"), 2]
    assert np.all(rhand[45:] > head[45:]) and np.all(lhand < head)
    Xb = generate_motion("box", model, duration_s=3.0, fps=FPS, rng=np.random.default_rng(0))
    el = np.rad2deg(Xb[:, [model.dof_names.index("left_elbow_y"), model.dof_names.index("right_elbow_y")]])
    assert el.min() < -100 and el.max() > -30          # guard (flexed) and punches (extended), both arms
    assert np.all((el > -30).any(axis=0))


@pytest.mark.parametrize("name", MOTIONS)
def test_seed_determinism(models, name):
    model = models[39]
    a = generate_motion(name, model, duration_s=1.5, fps=FPS, rng=np.random.default_rng(7))
    b = generate_motion(name, model, duration_s=1.5, fps=FPS, rng=np.random.default_rng(7))
    c = generate_motion(name, model, duration_s=1.5, fps=FPS, rng=np.random.default_rng(8))
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)


@pytest.mark.parametrize("kwargs,match", [
    ({"name": "dance"}, "name: expected one of"),
    ({"duration_s": 0}, "duration_s: expected"),
    ({"fps": -1}, "fps: expected"),
    ({"rng": 3}, "rng: expected a numpy.random.Generator"),
    ({"speed_mps": 0.0}, "speed_mps: expected"),
    ({"stride_m": float("nan")}, "stride_m: expected"),
    ({"amplitude": 3.0}, "amplitude: expected a number in"),
    ({"turn_deg_per_s": float("inf")}, "turn_deg_per_s: expected"),
    ({"duration_s": 30.0}, "root translation limits"),
])
def test_bad_input(models, kwargs, match):
    args = {"name": "walk", "duration_s": 1.0, "fps": FPS, "rng": np.random.default_rng(0)}
    args.update(kwargs)
    name = args.pop("name")
    with pytest.raises(MotionError, match=match) as err:
        generate_motion(name, models[39], **args)
    assert isinstance(err.value, BodyError) and isinstance(err.value, ValueError)
