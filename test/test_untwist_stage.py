"""The untwist stage (tracking/chain_moves.py): each thigh's twist halved or undone, the ankle turned back."""
import numpy as np
import pytest

from isa_mocap_ros.tracking import Tracker, TrackerConfig, TrackerError

from walk_scene import walk_scene


@pytest.fixture(scope="module")
def scene():
    """A generated walk, 0.2 s at 160x120 (every frame of it)."""
    return walk_scene(width=160, height=120, frames=100, duration_s=0.2, seed=1)


@pytest.mark.parametrize("kw, match", [({"leg_untwist": 1}, "leg_untwist"),
                                       ({"leg_untwist_tolerance": -0.1}, "leg_untwist_tolerance"),
                                       ({"leg_untwist_margin": -1e-4}, "leg_untwist_margin")])
def test_bad_config(kw, match):
    with pytest.raises(TrackerError, match=match):
        TrackerConfig.from_flat(**kw)


def test_untwist_puts_a_twisted_thigh_back_and_counts_its_evaluations(scene):
    from isa_mocap_ros.tracking.chain_moves import untwist_legs

    model, cams, walk, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, evals=900))
    tr.initialize(pose=walk[0])
    tr.step(masks[1], 1)                        # sets the masks of frame 1
    ctx = tr.frame_context(1)
    names = list(model.dof_names)
    x = walk[1].copy()
    x[names.index("left_knee_y")] = max(x[names.index("left_knee_y")], 0.6)    # a bent knee shows the twist
    h, a = names.index("left_hip_z"), names.index("left_ankle_z")
    twisted = x.copy()
    twisted[h] += 0.4
    twisted[a] -= 0.4
    e = float(tr.total_energy(twisted[None])[0])
    y, ey, n, legs = untwist_legs(tr, ctx, twisted, energy=e)
    assert "left_leg" in legs and ey < e and n == 3 * 2 + 1
    assert abs(y[h] - x[h]) < abs(twisted[h] - x[h])
    assert ey == pytest.approx(float(tr.total_energy(y[None])[0]), rel=0, abs=0)
    # nothing taken: the pose and its energy back, one evaluation when the energy was not given
    y, ey, n, legs = untwist_legs(tr, ctx, x, energy=None, scales=(1.0,))
    assert legs == [] and np.array_equal(y, np.clip(x, model.lower, model.upper)) and n == 2 * 2 + 1
    # a proposal as dear as the pose: refused without a price, taken with an absolute margin (both legs)
    y, ey, n, legs = untwist_legs(tr, ctx, x, energy=None, scales=(1.0,), margin=1e-9)
    assert legs == ["left_leg", "right_leg"] and np.array_equal(y, np.clip(x, model.lower, model.upper))


def test_untwist_on_by_default_and_its_command_line_value():
    """Decision 019: on at TOL 0.01 (docs/decisions/019-untwist-by-default.md); ``--leg-untwist off`` turns it off."""
    from isa_mocap_ros.tracking.chain_moves import parse_untwist_tolerance

    st = TrackerConfig().stages
    assert st.leg_untwist is True and st.leg_untwist_tolerance == 0.01 and st.leg_untwist_margin == 0.0
    assert parse_untwist_tolerance("off") == "off" and parse_untwist_tolerance(" OFF ") == "off"
    assert parse_untwist_tolerance("0.02") == 0.02 and parse_untwist_tolerance("0") == 0.0
    for bad in ("-0.01", "nan", "on", ""):
        with pytest.raises(ValueError):
            parse_untwist_tolerance(bad)


def test_untwist_in_a_frame_is_charged_only_when_on(scene, monkeypatch):
    from isa_mocap_ros.tracking import chain_moves

    model, cams, walk, masks = scene
    calls = []
    orig = chain_moves.untwist_legs
    monkeypatch.setattr(chain_moves, "untwist_legs", lambda *a, **k: calls.append((k["tolerance"], k["margin"])) or orig(*a, **k))
    for on in (False, True):
        tr = Tracker(model, cams, TrackerConfig.from_flat(evals=1500, seed=1, leg_untwist=on,
                                                          leg_untwist_tolerance=0.01, leg_untwist_margin=0.002))
        tr.initialize(pose=walk[0])
        r = tr.step(masks[1], 1)
        assert 1500 - 4 < r.n_evals <= 1500 and not r.fell_back
    assert calls == [(0.01, 0.002)]
