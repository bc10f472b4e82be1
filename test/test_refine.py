"""Refinement stage: the hierarchical algorithm once more over the torso and both arms merged into one
partition (budget, never worse, skip note, flat algorithms, settings). What it is for (a waving arm,
which the partition-by-partition search follows with the spine leaning after it): test_wave_hierarchy.py."""
import numpy as np
import pytest

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.body.motion import generate_motion
from isa_mocap_ros.tracking import Tracker, TrackerConfig, TrackerError
from isa_mocap_ros.tracking import plan
from isa_mocap_ros.tracking.plan import FrameBudget
from isa_mocap_ros.tracking.tracker import frame_rng
from isa_mocap_ros.vision import default_rig, render_mask

from walk_scene import walk_scene


@pytest.fixture(scope="module")
def wave():
    """A waving subject (39 DOF) in the default rig at 160x120: the truth of one frame and its masks."""
    model = make_model(39)
    rig = default_rig(width=160, height=120)
    truth = generate_motion("wave", model, duration_s=1.0, fps=30, rng=np.random.default_rng(2))[20]
    masks = [render_mask(c, capsule_endpoints(model, truth)[0], model.capsule_radii) for c in rig.cameras]
    return model, rig.cameras, truth, masks


def test_never_worse_and_exact_counts(wave):
    model, cams, truth, masks = wave
    tr = Tracker(model, cams, TrackerConfig(seed=0))
    tr.initialize(pose=truth)
    tr.step(masks, 20)
    e_truth = float(tr.total_energy(truth[None])[0])
    # from the truth itself the search rarely finds lower: whatever it returns is not worse
    for s in range(3):
        # energy unknown: one more; whole generations: 1 + 90 + 1 of 100
        x, e, n, replaced = tr.refine(truth, evals=100, rng=frame_rng(s, 20))
        assert n == 92 and e <= e_truth
        assert e == pytest.approx(float(tr.total_energy(x[None])[0]), rel=1e-12)
        if not replaced:
            np.testing.assert_array_equal(x, truth)


def test_frames_spend_exactly_their_budget_and_the_stage_runs():
    model, cams, walk, masks = walk_scene(width=160, height=120, frames=4, duration_s=0.2, seed=1)
    calls = []
    # the stage as it was the default (before the torso stage took its job)
    old = dict(refine_fraction=0.1, torso_fraction=0.0)
    for cfg in (TrackerConfig(seed=1, evals_per_frame=1300, **old),
                TrackerConfig(seed=1, evals_per_frame=1300, pelvis_fraction=0, limb_proposals=0, **old)):
        tr = Tracker(model, cams, cfg)
        orig = tr.refine
        tr.refine = lambda *a, **k: calls.append(k) or orig(*a, **k)
        tr.initialize(pose=walk[0])
        for f in range(1, 4):
            r = tr.step(masks[f], f)
            # whole generations: the stage, last, gets what the searches before left, and leaves < 30
            assert 1300 - 30 < r.n_evals <= 1300 and not r.fell_back
    assert len(calls) == 6 and all(130 <= k["evals"] < 130 + 3 * 30 for k in calls)
    # without an earlier stage the result's energy may be a particle's: the stage evaluates the start
    assert [k["energy"] is None for k in calls] == [False] * 3 + [True] * 3


def test_off_flat_algorithms_skip_note_and_models():
    model, cams, walk, masks = walk_scene(width=160, height=120, frames=3, duration_s=0.2, seed=1)
    old = dict(refine_fraction=0.1, torso_fraction=0.0)
    for cfg, note in [(TrackerConfig(seed=1, evals_per_frame=1219, **old), True),           # 121 < 4 x 30 + 2
                      (TrackerConfig(seed=1, evals_per_frame=1220, **old), False),
                      (TrackerConfig(seed=1, evals_per_frame=600, refine_fraction=0.21, pelvis_fraction=0.0,
                                     torso_fraction=0.0), False),
                      (TrackerConfig(seed=1, evals_per_frame=1219, refine_fraction=0.0, torso_fraction=0.0), False),
                      (TrackerConfig(seed=1, evals_per_frame=300, optimizer="pso"), False)]:
        tr = Tracker(model, cams, cfg)
        tr.initialize(pose=walk[0])
        r = tr.step(masks[1], 1)
        assert cfg.evals_per_frame - 30 < r.n_evals <= cfg.evals_per_frame       # whole generations
        assert any(n.startswith("refinement stage skipped: its share (121 evaluations) is below 4 generations of "
                                "isa (4 x 30) + 2") for n in r.notes) == note
    tr = Tracker(model, cams, TrackerConfig(seed=1, optimizer="pso"))
    with pytest.raises(TrackerError, match="not hierarchical"):
        tr.refine(walk[0], evals=100, rng=frame_rng(0, 0))
    low = make_model(18)           # no torso or arms: no stage, and refine says why
    tr = Tracker(low, cams, TrackerConfig(seed=1, refine_fraction=0.1))
    assert plan.refine_share(tr, None, FrameBudget(tr.config.evals_per_frame)) is None
    with pytest.raises(TrackerError, match="none of refine_partitions"):
        tr.refine(low.rest_pose(), evals=100, rng=frame_rng(0, 0))


def test_partitions_with_the_root(wave):
    """Any partitions can be merged; the root's rotation vector stays one rotation block."""
    model, cams, truth, masks = wave
    tr = Tracker(model, cams, TrackerConfig(seed=0, refine_partitions=("root", "torso", "tail")))
    tr.initialize(pose=truth)
    tr.step(masks, 20)
    start = truth.copy()
    start[[0, 4, 6]] += [0.03, 0.1, 0.1]
    e0 = float(tr.total_energy(start[None])[0])
    x, e, n, replaced = tr.refine(start, evals=121, rng=frame_rng(0, 20), energy=e0)     # 4 generations + 1
    moved = np.concatenate([model.partitions["root"], model.partitions["torso"]])
    assert n == 121 and replaced and e < e0
    np.testing.assert_array_equal(np.delete(x, moved), np.delete(start, moved))


@pytest.mark.parametrize("kw, match", [({"refine_fraction": -0.1}, "refine_fraction"),
                                       ({"refine_fraction": 1.0}, "refine_fraction"),
                                       ({"refine_fraction": 0.5, "pelvis_fraction": 0.5},
                                        "pelvis_fraction \\+ torso_fraction \\+ refine"),
                                       ({"refine_partitions": "torso"}, "refine_partitions"),
                                       ({"refine_partitions": ("torso", "torso")}, "refine_partitions"),
                                       ({"refine_partitions": ("torso", 3)}, "refine_partitions")])
def test_bad_settings(kw, match):
    with pytest.raises(TrackerError, match=match):
        TrackerConfig(**kw)
