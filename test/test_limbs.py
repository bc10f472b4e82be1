"""Limb stage: twist-and-hinge proposals (the upper bone stays put, the hidden twist and the hinge
are redrawn), and the tracker stage that uses them (budget, skip note, and what it is for: a
folded arm whose real counterpart is stretched)."""
import numpy as np
import pytest

from isa_mocap_ros.body import capsule_endpoints, joint_positions, make_model
from isa_mocap_ros.body.motion import generate_motion
from isa_mocap_ros.tracking import Tracker, TrackerConfig, TrackerError
from isa_mocap_ros.tracking.limbs import LIMBS, LimbMove
from isa_mocap_ros.tracking import plan
from isa_mocap_ros.tracking.plan import FrameBudget
from isa_mocap_ros.tracking.tracker import frame_rng


def _limb_stage_of(tr, notes, pred):
    """The limb stage's plan on a full frame budget."""
    return plan.limb_stage(tr, notes, pred, FrameBudget(tr.config.search.evals))
from isa_mocap_ros.vision import default_rig, render_mask


@pytest.mark.parametrize("dof, limbs", [(39, LIMBS), (28, LIMBS), (18, ("left_leg", "right_leg"))])
def test_limbs_of_each_model(dof, limbs):
    lm = LimbMove(make_model(dof))
    assert tuple(v.name for v in lm.limbs) == limbs
    with pytest.raises(ValueError, match="limb: expected one of"):
        lm.limb("tail")


@pytest.mark.parametrize("name, base, hinge, tip", [("right_arm", "right_shoulder", "right_elbow", "right_wrist"),
                                                    ("left_leg", "left_hip", "left_knee", "left_ankle")])
def test_proposals_turn_the_limb_about_its_upper_bone(name, base, hinge, tip):
    model = make_model(39)
    rng = np.random.default_rng(3)
    x = model.rest_pose().copy()
    x[6:] += rng.normal(0.0, 0.15, model.dof - 6)
    x = np.clip(x, model.lower, model.upper)
    lm = LimbMove(model)
    limb = lm.limb(name)
    x[limb.hinge_dof] = 0.5 * (model.lower[limb.hinge_dof] + model.upper[limb.hinge_dof])   # bent, off its limits
    names = list(model.joint_names)
    b, h, t = names.index(base), names.index(hinge), names.index(tip)
    # no twist and the current hinge angle give the pose back
    np.testing.assert_allclose(lm.proposals(x, limb, np.zeros(1), x[[limb.hinge_dof]])[0], x, atol=1e-9)
    phi = np.deg2rad([-40.0, -15.0, 10.0, 25.0, 45.0])
    X = lm.proposals(x, limb, phi, np.full(5, x[limb.hinge_dof]))
    J0, J = joint_positions(model, x[None])[0], joint_positions(model, X)
    unclipped = [k for k in range(5) if np.all(X[k][limb.dofs] > model.lower[limb.dofs] + 1e-9)
                 and np.all(X[k][limb.dofs] < model.upper[limb.dofs] - 1e-9)]
    assert len(unclipped) >= 3                               # proposals the limits did not bend
    for k in unclipped:
        np.testing.assert_allclose(J[k, h], J0[h], atol=1e-9)             # the upper bone did not move
        d0, d = J0[t] - J0[h], J[k, t] - J[k, h]
        assert np.linalg.norm(d) == pytest.approx(np.linalg.norm(d0), abs=1e-9)
        axis = (J0[h] - J0[b]) / np.linalg.norm(J0[h] - J0[b])
        # the lower bone turned about the upper one by the twist (same angle to the axis)
        assert d @ axis == pytest.approx(d0 @ axis, abs=1e-9)
    assert not np.allclose(J[unclipped, t], J0[t], atol=1e-3)
    # every other joint angle is untouched
    others = [k for k in range(model.dof) if k not in limb.dofs]
    np.testing.assert_array_equal(X[:, others], np.repeat(x[None, others], 5, 0))
    # proposals are always inside the model's limits
    X = lm.draw(x, limb, 50, rng)
    assert np.all(X >= model.lower) and np.all(X <= model.upper)
    # hinge proposals only: the base joint is kept, the hinge spans its range
    X = lm.draw(x, limb, 50, rng, twist=False)
    keep = [k for k in range(model.dof) if k != limb.hinge_dof]
    np.testing.assert_array_equal(X[:, keep], np.repeat(x[None, keep], 50, 0))
    lo, hi = model.lower[limb.hinge_dof], model.upper[limb.hinge_dof]
    assert np.all((X[:, limb.hinge_dof] >= lo) & (X[:, limb.hinge_dof] <= hi))
    assert np.ptp(X[:, limb.hinge_dof]) > 0.7 * (hi - lo)
    # within a window about the pose's hinge (and still within the limits)
    for w in (0.3, 5.0):
        X = lm.draw(x, limb, 50, rng, twist=False, window=w)
        np.testing.assert_array_equal(X[:, keep], np.repeat(x[None, keep], 50, 0))
        h = X[:, limb.hinge_dof]
        assert np.all((h >= max(lo, x[limb.hinge_dof] - w)) & (h <= min(hi, x[limb.hinge_dof] + w)))
        assert np.ptp(h) > 0.7 * (min(hi, x[limb.hinge_dof] + w) - max(lo, x[limb.hinge_dof] - w))


@pytest.fixture(scope="module")
def scene():
    model = make_model(39)
    rig = default_rig(width=160, height=120)
    walk = generate_motion("walk", model, duration_s=0.2, fps=30, rng=np.random.default_rng(1))
    truth = walk[3].copy()
    k = model.joint_index("right_elbow")
    truth[model.joint_dofs[k][0]] = np.deg2rad(-20.0)     # a nearly stretched right arm
    masks = [render_mask(c, capsule_endpoints(model, truth)[0], model.capsule_radii) for c in rig.cameras]
    return model, rig.cameras, walk, truth, masks


def test_stage_reopens_a_folded_arm(scene):
    """The trap the stage exists for: the forearm folded onto the upper arm (elbow at its limit) and
    the upper arm twisted 180 deg, where the real arm is nearly straight. The upper bone is right, so
    the proposals only have to find the twist and the hinge."""
    model, cams, walk, truth, masks = scene
    lm = LimbMove(model)
    limb = lm.limb("right_arm")
    trapped = lm.proposals(truth, limb, np.array([np.pi]), model.lower[[limb.hinge_dof]])[0]
    w = model.joint_index("right_wrist")
    wrist_err = lambda x: float(np.linalg.norm(joint_positions(model, x[None])[0, w]
                                               - joint_positions(model, truth[None])[0, w]))
    assert wrist_err(trapped) > 0.2
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1))
    tr.initialize(pose=trapped)
    tr.step(masks, 3)                                       # sets the masks
    e0 = tr.total_energy(trapped[None])[0]
    fixed = 0
    for s in range(3):
        x, e, n, changed = tr.propose_limbs(trapped, n=200, rng=frame_rng(s, 3), limbs=["left_arm", "right_arm"])
        assert n == 2 * 200 + 2 and e == pytest.approx(tr.total_energy(x[None])[0], rel=1e-12)
        assert e <= e0 and np.all(x >= model.lower) and np.all(x <= model.upper)
        fixed += changed == ["right_arm"] and wrist_err(x) < 0.06
    assert fixed == 3
    # the hierarchy's own search, from the trapped pose with the same number of evaluations, stays folded
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, evals=402, pelvis_fraction=0.0, limb_proposals=0))
    tr.initialize(pose=trapped)
    r = tr.step(masks, 4, prediction=trapped)
    assert wrist_err(r.x) > 0.15


def test_stage_budget_skip_note_and_off(scene):
    model, cams, walk, truth, masks = scene
    for cfg, note in [(TrackerConfig.from_flat(evals=700, seed=1), False),        # (14 + 3) x 4 + 2 = 70
                      (TrackerConfig.from_flat(evals=330, seed=1, pelvis_fraction=0.0), False),   # 4 + 3 per limb
                      (TrackerConfig.from_flat(evals=700, seed=1, limb_proposals=0), False)]:
        tr = Tracker(model, cams, cfg)
        tr.initialize(pose=walk[2])
        r = tr.step(masks, 3)
        # whole generations: the limb stage (last) takes the rest as proposals, < 4 left; without it < 30
        slack = 4 if cfg.stages.limb_proposals and not note else 30
        assert cfg.search.evals - slack < r.n_evals <= cfg.search.evals and not r.fell_back
        assert not any(n.startswith("limb stage skipped") for n in r.notes)
    # drawn proposals per limb: limb_proposals, or as many as fit in a tenth of the budget beside the 3
    # extrapolated ones; below 4 no stage
    for evals, limbs, n in [(1500, LIMBS, 16), (700, LIMBS, 14), (500, LIMBS, 9), (330, LIMBS, 4),
                            (330, ("left_arm", "right_arm"), 12), (290, LIMBS, 0), (170, LIMBS, 0)]:
        tr = Tracker(model, cams, TrackerConfig.from_flat(evals=evals, seed=1, limb_proposal_limbs=limbs))
        notes = []
        got = _limb_stage_of(tr, notes, truth)
        assert got == ((list(limbs), [v for v in limbs if v.endswith("_leg")], n) if n else ([], [], 0))
        assert (notes == ["limb stage skipped: fewer than 4 proposals per limb fit in a tenth of the frame "
                          f"budget ({evals}; 4 limbs)"]) == (n == 0)


def test_not_on_the_automatically_initialized_frame(scene, monkeypatch):
    model, cams, walk, truth, masks = scene
    calls = []
    from isa_mocap_ros.tracking import stages

    orig = stages.propose_limbs
    monkeypatch.setattr(stages, "propose_limbs", lambda *a, **k: calls.append(1) or orig(*a, **k))
    # not in the heading candidates' searches; init_polish's search of the winner (and of a heading check's
    # rival) is a tracked frame's, with every stage
    for polish in (False, True):
        calls.clear()
        tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, evals=600, init_refine_evals=50, init_yaw_steps=8,
                                                init_polish=polish))
        r = tr.step(masks, 0)
        polished = 1 + any(n.startswith("heading check started") for n in r.notes)
        assert r.initialized and len(calls) == (polished if polish else 0)


@pytest.mark.parametrize("kw, match", [({"limb_proposals": -1}, "limb_proposals"),
                                       ({"limb_proposals": 2.5}, "limb_proposals"),
                                       ({"limb_proposal_limbs": ("left_arm", "tail")}, "limb_proposal_limbs"),
                                       ({"limb_proposal_limbs": "left_arm"}, "limb_proposal_limbs"),
                                       ({"limb_proposal_limbs": ("left_arm", "left_arm")}, "limb_proposal_limbs"),
                                       ({"limb_hinge_limbs": ("left_leg", "knee")}, "limb_hinge_limbs"),
                                       ({"limb_hinge_limbs": "left_leg"}, "limb_hinge_limbs"),
                                       ({"limb_extrapolations": (1.0, -2.0)}, "limb_extrapolations"),
                                       ({"limb_extrapolations": 2.0}, "limb_extrapolations"),
                                       ({"limb_extrapolations": (float("nan"),)}, "limb_extrapolations"),
                                       ({"limb_hinge_window_deg": -1.0}, "limb_hinge_window_deg"),
                                       ({"limb_hinge_window_deg": float("nan")}, "limb_hinge_window_deg")])
def test_bad_settings(kw, match):
    with pytest.raises(TrackerError, match=match):
        TrackerConfig.from_flat(**kw)


def test_a_leg_folded_in_the_prediction_joins_the_stage(scene):
    """limb_fold_deg: a knee bent beyond it in the prediction (the CMU walk's fast stride left it at its
    155 deg limit for good) gets the leg proposals that bring it back; below it the legs are left out."""
    model, cams, walk, truth, masks = scene
    leg = LimbMove(model).limb("right_leg")
    folded = truth.copy()
    folded[leg.hinge_dof] = np.deg2rad(150.0)
    a = model.joint_index("right_ankle")

    def ankle_err(x):
        return float(np.linalg.norm(joint_positions(model, x[None])[0, a] - joint_positions(model, truth[None])[0, a]))
    assert ankle_err(folded) > 0.3
    out = {}
    for fold in (130.0, 0.0):
        tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, limb_fold_deg=fold, limb_proposal_limbs=("left_arm",
                                                                                                 "right_arm")))
        tr.initialize(pose=folded)
        r = tr.step(masks, 3, prediction=folded)
        notes = [n for n in r.notes if n.startswith("limb stage: right_leg folded in the prediction (150 deg)")]
        assert len(notes) == (1 if fold else 0) and 1500 - 3 < r.n_evals <= 1500 and not r.fell_back
        out[fold] = ankle_err(r.x)
    assert out[130.0] < 0.1 < out[0.0]
    # not folded: with the arms-only stage the legs stay out
    arms = dict(limb_proposal_limbs=("left_arm", "right_arm"))
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, **arms))
    tr.initialize(pose=truth)
    assert _limb_stage_of(tr, [], truth) == (["left_arm", "right_arm"], [], 16)
    notes = []
    assert _limb_stage_of(tr, notes, folded) == (["left_arm", "right_arm", "right_leg"], [], 16) and len(notes) == 1
    # the folded leg joins only while the stage stays within a tenth of the budget (16 x 3 + 2 = 50 > 40)
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, evals=400, **arms))
    notes = []
    assert _limb_stage_of(tr, notes, folded) == (["left_arm", "right_arm"], [], 16) and notes == []
    assert _limb_stage_of(Tracker(model, cams, TrackerConfig.from_flat(seed=1, limb_proposals=0)), notes, folded) == ([], [], 0)
    # the default stage has the legs with hinge proposals; a folded one gets the twist too (no note: it is in)
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1))
    notes = []
    assert _limb_stage_of(tr, notes, truth) == (list(LIMBS), ["left_leg", "right_leg"], 16)
    assert _limb_stage_of(tr, notes, folded) == (list(LIMBS), ["left_leg"], 16) and notes == []


@pytest.mark.parametrize("off_deg, window", [(70.0, 0.0), (70.0, 90.0), (40.0, 45.0)])
def test_knee_proposals_follow_a_knee_beyond_the_search_box(scene, off_deg, window):
    """The legs' hinge proposals (default): the CMU walk's kick straightens a knee by 25-30 deg per
    frame, beyond what the search from the prediction reaches. A knee off in the prediction (not
    folded: < 130 deg) is put back by the stage, the hip untouched by it; without the legs in the stage
    it stays off. The proposals reach as far as their window (``limb_hinge_window_deg``, default 90)."""
    model, cams, walk, truth, masks = scene
    leg = LimbMove(model).limb("right_leg")
    off = truth.copy()
    off[leg.hinge_dof] = truth[leg.hinge_dof] + np.deg2rad(off_deg)
    assert np.rad2deg(off[leg.hinge_dof]) < 130.0
    a = model.joint_index("right_ankle")

    def ankle_err(x):
        return float(np.linalg.norm(joint_positions(model, x[None])[0, a] - joint_positions(model, truth[None])[0, a]))
    out = {}
    for limbs in (LIMBS, ("left_arm", "right_arm")):
        # (the contour and untwist stages off: they would mend the leg too; this is the limb stage's test)
        tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, limb_proposal_limbs=limbs, contour_iterations=0,
                                                limb_hinge_window_deg=window, leg_untwist=False))
        tr.initialize(pose=off)
        r = tr.step(masks, 3, prediction=off)
        assert 1500 - 4 < r.n_evals <= 1500 and not r.fell_back
        out[limbs] = ankle_err(r.x)
    assert out[LIMBS] < 0.06 and out[LIMBS] < 0.7 * out[("left_arm", "right_arm")], out
    assert off_deg < 60 or out[("left_arm", "right_arm")] > 0.15, out    # 70 deg: beyond the search box
    # the stage itself: hinge proposals only change the knee
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, limb_hinge_window_deg=window))
    tr.initialize(pose=off)
    tr.step(masks, 3, prediction=off)
    x, e, n, changed = tr.propose_limbs(off, n=16, rng=frame_rng(1, 3), limbs=["right_leg"], hinge_only=["right_leg"])
    assert changed == ["right_leg"] and n == 18
    keep = [k for k in range(model.dof) if k != leg.hinge_dof]
    np.testing.assert_array_equal(x[keep], off[keep])
    assert abs(x[leg.hinge_dof] - truth[leg.hinge_dof]) < np.deg2rad(12.0)


def test_extrapolated_proposals_carry_a_limb_along_its_motion(scene):
    """limb_extrapolations: a limb the search trails (a kick: the knee 25-30 deg per frame) is offered
    ``x + k (x - last)`` for k in (1, 2, 3); a leg half-way from the last frame's angles to the truth is
    put on the truth by k = 1."""
    model, cams, walk, truth, masks = scene
    lm = LimbMove(model)
    leg = lm.limb("right_leg")
    last = truth.copy()
    last[leg.hinge_dof] += np.deg2rad(40.0)                    # the knee straightening fast
    last[leg.base_dofs[0]] += 0.1                               # the hip moving too
    half = truth.copy()
    half[leg.hinge_dof] += np.deg2rad(20.0)
    half[leg.base_dofs[0]] += 0.05
    X = lm.extrapolate(half, last, leg, (1.0, 2.0, 3.0))
    np.testing.assert_allclose(X[0, leg.dofs], truth[leg.dofs], atol=1e-12)
    np.testing.assert_allclose(X[:, leg.base_dofs[0]], half[leg.base_dofs[0]] - np.array([1, 2, 3]) * 0.05)
    keep = [k for k in range(model.dof) if k not in leg.dofs]
    np.testing.assert_array_equal(X[:, keep], np.repeat(half[None, keep], 3, 0))
    assert np.all(X >= model.lower) and np.all(X <= model.upper)
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1))
    tr.initialize(pose=half)
    tr.step(masks, 3, prediction=half)                          # sets the masks
    # one drawn proposal (a knee alone cannot reach the truth: the hip is off too) and the extrapolations
    x, e, n, changed = tr.propose_limbs(half, n=1, rng=frame_rng(1, 3), limbs=["right_leg"],
                                        hinge_only=["right_leg"], last=last)
    assert n == (1 + 3) + 2 and changed == ["right_leg"]
    assert abs(x[leg.hinge_dof] - truth[leg.hinge_dof]) < np.deg2rad(1.0)
    # without the previous pose there is nothing to extrapolate
    _, _, n, _ = tr.propose_limbs(half, n=1, rng=frame_rng(1, 3), limbs=["right_leg"], hinge_only=["right_leg"])
    assert n == 1 + 2
    # off
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, limb_extrapolations=()))
    assert _limb_stage_of(tr, [], truth) == (list(LIMBS), ["left_leg", "right_leg"], 16)
    assert plan.limb_share(tr, 4, 16) == 66


@pytest.mark.parametrize("energy", ["raster", "fast"])
def test_batch_energies_limb_by_limb_equal_one_call(scene, energy):
    """The limb stage's batch is scored limb by limb on the energy restricted to each limb
    (stages._limb_batch_energies): the same bits as one call of the frame's objective, keypoint-free and with
    twist, hinge-only and extrapolated proposals."""
    from isa_mocap_ros.tracking import stages

    model, cams, walk, truth, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=1, energy=energy))
    tr.initialize(pose=walk[2])
    tr.step(masks, 3)
    ctx = tr.frame_context()
    x = np.clip(walk[3], model.lower, model.upper)
    rng = np.random.default_rng(5)
    chosen = tr.limb_move.limbs
    batches = [np.vstack([tr.limb_move.draw(x, limb, 7, rng, twist=limb.name.endswith("arm")),
                          tr.limb_move.extrapolate(x, walk[1], limb, (0.5, 1.0))]) for limb in chosen]
    n0 = tr.energy.n_evals
    got = stages._limb_batch_energies(ctx, x, chosen, batches)
    assert tr.energy.n_evals - n0 == 1 + sum(len(P) for P in batches)
    want = ctx.objective(np.vstack([x[None, :]] + batches))
    assert got.shape == want.shape and np.array_equal(got, want)


def test_intrinsic_euler_reads_angles_as_scipy_does():
    """limbs.intrinsic_euler: the angles scipy's as_euler gives (to 1e-12) for every Tait-Bryan sequence, including
    rotations at gimbal lock, and the rotation they compose is the input."""
    from scipy.spatial.transform import Rotation

    from isa_mocap_ros.tracking.limbs import intrinsic_euler

    R = Rotation.random(500, random_state=3)
    lock = Rotation.from_euler("XYZ", [[0.3, np.pi / 2, -0.2], [1.0, -np.pi / 2, 0.5]])
    for seq in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"):
        q = intrinsic_euler(R.as_matrix(), seq)
        np.testing.assert_allclose(q, R.as_euler(seq), atol=1e-12)
        np.testing.assert_allclose(Rotation.from_euler(seq, q).as_matrix(), R.as_matrix(), atol=1e-12)
    q = intrinsic_euler(lock.as_matrix(), "XYZ")
    np.testing.assert_allclose(Rotation.from_euler("XYZ", q).as_matrix(), lock.as_matrix(), atol=1e-9)
