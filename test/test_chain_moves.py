"""The chain stage (tracking/chain_moves.py): root, lower spine, hips and knees searched together."""
import numpy as np
import pytest

from isa_mocap_ros.body import make_model
from isa_mocap_ros.tracking import Tracker, TrackerConfig, TrackerError
from isa_mocap_ros.tracking.chain_moves import ChainMove, refit_chain
from isa_mocap_ros.tracking.reaim import ReaimMove
from isa_mocap_ros.tracking.tracker import frame_rng

from walk_scene import walk_scene


@pytest.fixture(scope="module")
def scene():
    """A generated walk, 0.2 s at 160x120 (every frame of it)."""
    return walk_scene(width=160, height=120, frames=100, duration_s=0.2, seed=1)


@pytest.mark.parametrize("dof", [28, 39])
def test_the_start_gives_the_pose_back_and_offsets_add(dof):
    m = make_model(dof)
    rng = np.random.default_rng(3)
    x = np.clip(m.rest_pose() + 0.2 * rng.standard_normal(m.dof) * (np.arange(m.dof) >= 3), m.lower, m.upper)
    chain = ChainMove(m, ReaimMove(m, [0]))
    names = [m.dof_names[d] for d in chain.joint_coords]
    assert sorted(names[:3]) == ["spine_lower_x", "spine_lower_y", "spine_lower_z"] or dof == 28
    assert {n.rsplit("_", 1)[0] for n in names} <= {"spine_lower", "left_hip", "right_hip", "left_knee", "right_knee"}
    assert "left_knee_y" in names and "right_hip_x" in names
    poses = chain.around(x)
    c0 = chain.start(x)
    assert np.allclose(poses(c0[None])[0], x, atol=1e-9)
    C = np.tile(c0, (2, 1))
    k = list(chain.coords).index(m.dof_names.index("left_knee_y"))
    C[1, k] = 0.1
    X = poses(C)
    d = m.dof_names.index("left_knee_y")
    assert X[1, d] == pytest.approx(min(X[0, d] + 0.1, m.upper[d]))
    assert np.allclose(np.delete(X[1], d), np.delete(X[0], d))


def test_the_stage_never_raises_the_energy_and_finds_a_bent_chain(scene):
    model, cams, walk, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, evals=900))
    tr.initialize(pose=walk[0])
    tr.step(masks[1], 1)                        # sets the masks of frame 1
    ctx = tr.frame_context(1)
    x = walk[1]
    e = float(tr.total_energy(x[None])[0])
    for known in (e, None):     # 90 + 2 (+ 1): three generations of 30, the estimate and best particle (and the start)
        y, ey, n, replaced = refit_chain(tr, ctx, x, evals=100, rng=frame_rng(1, 2), energy=known)
        assert n == 92 + (known is None)
        assert (ey < e) if replaced else (ey == e and np.array_equal(y, np.clip(x, model.lower, model.upper)))
    # the pelvis pitched 8 deg with the hips and the lower spine compensating, a knee and a hip 0.25 rad off:
    # the stage lowers the energy
    chain = ChainMove(model, tr.pelvis_reaim)
    c = chain.start(x)
    c[4] += np.deg2rad(8.0)
    names = [model.dof_names[d] for d in chain.coords]
    c[names.index("left_knee_y")] += 0.25
    c[names.index("right_hip_y")] += 0.25
    bent = chain.around(x)(c[None])[0]
    eb = float(tr.total_energy(bent[None])[0])
    y, ey, n, replaced = refit_chain(tr, ctx, bent, evals=400, rng=frame_rng(1, 2), energy=eb)
    assert replaced and ey < eb
    # the same seed gives the same pose
    y2, ey2, _, _ = refit_chain(tr, ctx, bent, evals=400, rng=frame_rng(1, 2), energy=eb)
    assert np.array_equal(y, y2) and ey == ey2


def test_the_stage_in_a_frame_spends_the_budget_and_is_off_by_default(scene, monkeypatch):
    from isa_mocap_ros.tracking import chain_moves

    model, cams, walk, masks = scene
    calls = []
    orig = chain_moves.refit_chain
    monkeypatch.setattr(chain_moves, "refit_chain", lambda *a, **k: calls.append(k["evals"]) or orig(*a, **k))
    for fraction in (0.0, 0.1):
        tr = Tracker(model, cams, TrackerConfig.from_flat(evals=1500, seed=1, chain_fraction=fraction))
        tr.initialize(pose=walk[0])
        r = tr.step(masks[1], 1)
        assert 1500 - 4 < r.n_evals <= 1500 and not r.fell_back
    assert len(calls) == 1 and calls[0] >= 150
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, seed=1, chain_fraction=0.05))   # 15 < 30 + 2
    tr.initialize(pose=walk[0])
    r = tr.step(masks[1], 1)
    assert any(n.startswith("chain stage skipped: its share (15 evaluations)") for n in r.notes)


@pytest.mark.parametrize("kw, match", [({"chain_fraction": -0.1}, "chain_fraction"),
                                       ({"chain_fraction": 1.0}, "chain_fraction"),
                                       ({"pelvis_fraction": 0.4, "torso_fraction": 0.3, "chain_fraction": 0.3},
                                        "chain_fraction: expected below 1"),
                                       ({"leg_untwist": 1}, "leg_untwist"),
                                       ({"leg_untwist_tolerance": -0.1}, "leg_untwist_tolerance")])
def test_bad_config(kw, match):
    with pytest.raises(TrackerError, match=match):
        TrackerConfig.from_flat(**kw)


def test_a_model_without_a_root_move_is_named():
    m = make_model(39)
    with pytest.raises(TrackerError, match="no re-aimed root move"):
        ChainMove(m, None)


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


def test_untwist_in_a_frame_is_charged_and_off_by_default(scene, monkeypatch):
    from isa_mocap_ros.tracking import chain_moves

    model, cams, walk, masks = scene
    calls = []
    orig = chain_moves.untwist_legs
    monkeypatch.setattr(chain_moves, "untwist_legs", lambda *a, **k: calls.append(k["tolerance"]) or orig(*a, **k))
    for on in (False, True):
        tr = Tracker(model, cams, TrackerConfig.from_flat(evals=1500, seed=1, leg_untwist=on,
                                                          leg_untwist_tolerance=0.01))
        tr.initialize(pose=walk[0])
        r = tr.step(masks[1], 1)
        assert 1500 - 4 < r.n_evals <= 1500 and not r.fell_back
    assert calls == [0.01]
