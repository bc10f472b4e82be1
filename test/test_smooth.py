"""Offline zero-phase smoothing of a track (tracking/smooth.py, `isa-mocap track --smooth-hz`)."""
import json

import numpy as np
import pytest

from isa_mocap_ros.body import make_model
from isa_mocap_ros.geometry import exp_so3
from isa_mocap_ros.tracking.smooth import SmoothError, continuous_rotation_vectors, smooth_poses


def _motion(model, F=120, fps=60.0):
    t = np.arange(F) / fps
    X = np.tile(model.rest_pose().astype(float), (F, 1))
    X[:, 0] = 0.5 * np.sin(2 * np.pi * 0.8 * t)                      # 0.8 Hz: well below the cut-off
    X[:, 2] = 1.0
    k = model.dof_names.index("left_knee_y")
    X[:, k] = 0.6 + 0.5 * np.sin(2 * np.pi * 1.2 * t)
    return X


def test_removes_jitter_without_delay():
    model, rng = make_model(39), np.random.default_rng(0)
    X = _motion(model)
    noisy = X + np.concatenate([rng.normal(0, 0.01, (len(X), 6)), rng.normal(0, 0.05, (len(X), model.dof - 6))], 1)
    noisy[:, 6:] = np.clip(noisy[:, 6:], model.lower[6:], model.upper[6:])
    Y = smooth_poses(model, noisy, 60.0, 6.0)
    inner = slice(10, -10)
    # white noise keeps about sqrt(6 / 30) of its size through a 6 Hz low-pass at 60 fps
    assert np.abs(Y - X)[inner].mean() < 0.55 * np.abs(noisy - X)[inner].mean()
    # zero phase: a clean motion comes back in place (a one-way filter would lag it by several frames)
    clean = smooth_poses(model, X, 60.0, 6.0)
    k = model.dof_names.index("left_knee_y")
    assert np.abs(clean[inner, k] - X[inner, k]).max() < 0.01
    lags = [np.mean((np.roll(clean[:, k], s) - X[:, k])[inner] ** 2) for s in range(-3, 4)]
    assert int(np.argmin(lags)) == 3
    assert np.all(Y[:, 6:] >= model.lower[6:]) and np.all(Y[:, 6:] <= model.upper[6:])
    np.testing.assert_array_equal(smooth_poses(model, X[:3], 60.0, 6.0), X[:3])    # too short: unchanged


def test_root_rotation_made_continuous_through_pi():
    """A body turning steadily through 180°: its rotation vectors jump from +π to −π; the filter must not see it."""
    model = make_model(39)
    F = 60
    ang = np.linspace(np.pi - 0.6, np.pi + 0.6, F)
    ang = np.where(ang > np.pi, ang - 2 * np.pi, ang)                 # as a tracker reports them: |r| <= π
    X = np.tile(model.rest_pose().astype(float), (F, 1))
    X[:, 5] = ang
    c = continuous_rotation_vectors(X[:, 3:6])
    assert np.abs(np.diff(c[:, 2])).max() < 0.05
    np.testing.assert_allclose(exp_so3(c), exp_so3(X[:, 3:6]), atol=1e-12)      # the same rotations
    Y = smooth_poses(model, X, 60.0, 6.0)
    np.testing.assert_allclose(exp_so3(Y[:, 3:6]), exp_so3(X[:, 3:6]), atol=1e-3)


def test_bad_arguments_are_named():
    model = make_model(39)
    X = _motion(model, F=10)
    with pytest.raises(SmoothError, match="cut-off: expected 0 < Hz < half the frame rate"):
        smooth_poses(model, X, 60.0, 30.0)
    with pytest.raises(SmoothError, match=r"poses: expected shape \(F, 39\)"):
        smooth_poses(model, X[:, :10], 60.0, 6.0)
    with pytest.raises(SmoothError, match="fps: expected a frame rate > 0"):
        smooth_poses(model, X, 0.0, 6.0)


def test_track_writes_and_scores_the_smoothed_track_apart(tmp_path, capsys):
    """`isa-mocap track --smooth-hz` on the shipped demo bag (a few frames): the per-frame estimates and their score
    unchanged, the smoothed ones written beside them and scored apart."""
    from conftest import joint_states_by_stamp
    from isa_mocap_ros.cli.main import main
    from isa_mocap_ros.resources import default_bag

    args = ["track", str(default_bag()), "--no-progress", "--frames", "8", "--evals", "200", "--shape", "truth",
            "--init", "truth", "--keypoint-weight", "0"]
    assert main(args + ["--out", str(tmp_path / "a")]) == 0
    assert main(args + ["--out", str(tmp_path / "b"), "--smooth-hz", "4"]) == 0
    assert "smoothed offline (4 Hz, zero phase)" in capsys.readouterr().out
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in "ab")
    assert a["mpjpe_mm"] == b["mpjpe_mm"] and "smoothed" not in a
    sm = b["smoothed"]
    assert sm["cutoff_hz"] == 4.0 and np.isfinite(sm["mpjpe_mm"]) and sm["mpjpe_mm"] != b["mpjpe_mm"]
    est, smo = (joint_states_by_stamp(tmp_path / "b" / d) for d in ("estimates", "estimates_smoothed"))
    assert sorted(est) == sorted(smo) and len(est) == 8
    assert any(not np.allclose(est[s], smo[s]) for s in est)
    assert main(args + ["--out", str(tmp_path / "c"), "--smooth-hz", "-1"]) == 2
    assert "--smooth-hz: expected a cut-off in Hz >= 0" in capsys.readouterr().err
