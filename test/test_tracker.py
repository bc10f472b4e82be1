"""Tracker: a tiny synthetic walk, determinism, fallbacks on bad input, configuration errors."""
import numpy as np
import pytest

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.body.motion import generate_motion
from isa_mocap_ros.eval import frame_errors_mm, marker_positions
from isa_mocap_ros.tracking import FrameResult, Tracker, TrackerConfig, TrackerError, make_tracker
from isa_mocap_ros.tracking import first_frame, heading
from isa_mocap_ros.tracking.config import JOINT_SPREAD_RAD, ROOT_TRANSLATION_SPREAD_M
from isa_mocap_ros.tracking.contour import ContourFitInfo
from isa_mocap_ros.vision import default_rig, render_mask

from walk_scene import walk_scene

N_FRAMES = 5


@pytest.fixture(scope="module")
def scene():
    return walk_scene(width=160, height=120, frames=N_FRAMES, duration_s=0.3, seed=0)


def _track(scene, config, *, init="truth"):
    model, cams, walk, masks = scene
    tr = Tracker(model, cams, config)
    if init == "truth":
        tr.initialize(pose=walk[0])
    out = [tr.step(masks[k], k) for k in range(1, N_FRAMES)]
    return tr, out


def test_tracks_a_tiny_walk(scene):
    """Bound measured: ~15-25 mm mean per frame at 160x120 / 800 evaluations (ISA, default settings);
    checked against 45 mm, and against the error of simply keeping the first pose."""
    model, cams, walk, masks = scene
    _, out = _track(scene, TrackerConfig.from_flat(evals=800, seed=3))  # default optimizer: h-isa
    est = np.array([r.x for r in out])
    err = frame_errors_mm(marker_positions(model, est), marker_positions(model, walk[1:]))
    still = frame_errors_mm(marker_positions(model, np.repeat(walk[:1], N_FRAMES - 1, 0)),
                            marker_positions(model, walk[1:]))
    assert err.mean() < 45.0
    assert err.mean() < 0.5 * still.mean()
    for r in out:
        assert isinstance(r, FrameResult) and not r.fell_back and r.views_used == 4
        assert 800 - 4 < r.n_evals <= 800 and np.isfinite(r.energy) and r.time_s > 0
        assert np.all(r.x >= model.lower) and np.all(r.x <= model.upper)


def test_same_seed_same_estimates(scene):
    cfg = TrackerConfig.from_flat(evals=300, seed=7)
    _, a = _track(scene, cfg)
    _, b = _track(scene, cfg)
    for ra, rb in zip(a, b):
        np.testing.assert_array_equal(ra.x, rb.x)
        assert ra.energy == rb.energy
    _, c = _track(scene, TrackerConfig.from_flat(evals=300, seed=8))
    assert any(not np.array_equal(ra.x, rc.x) for ra, rc in zip(a, c))


def test_automatic_initialization_on_first_step(scene):
    model, cams, walk, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, init_refine_evals=200, seed=1))
    assert not tr.initialized
    r = tr.step(masks[0], 0)
    assert r.initialized and r.x is not None and tr.initialized
    assert any(n.startswith("initialized automatically") for n in r.notes)
    assert np.linalg.norm(r.x[:2] - walk[0][:2]) < 0.15


def test_initialization_prunes_candidate_runs_part_way(scene):
    # init_keep: every heading candidate's search runs to the first partition's end, then only the
    # init_keep lowest go on. The runs kept end as unpruned runs (own streams): the frame's energy is
    # never below the unpruned frame's, equal only with the same estimate; fewer evaluations.
    model, cams, walk, masks = scene

    def first(keep):
        # the sampled energy (decision 017): with the scanline count a pruned run's polish ended lower here
        tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, init_refine_evals=100, seed=2, init_keep=keep,
                                                          energy="fast"))
        r = tr.step(masks[0], 0)
        assert r.initialized
        return r

    full = first(0)
    assert any("4 heading candidates, 4 searched to the end" in n for n in full.notes)
    same = first(4)
    np.testing.assert_array_equal(same.x, full.x)
    assert same.n_evals == full.n_evals
    evals = []
    for keep in (1, 2, 3):
        r = first(keep)
        assert any(f"4 heading candidates, {keep} searched to the end" in n for n in r.notes)
        assert r.energy >= full.energy
        if r.energy == full.energy:
            np.testing.assert_array_equal(r.x, full.x)
        evals.append(r.n_evals)
    assert evals[0] < evals[1] < evals[2] < full.n_evals


def test_initialization_polish_searches_the_winner_once_more(scene):
    """init_polish: the automatically initialized frame's winner is searched once more as a tracked frame
    (one more frame budget), kept when its energy is lower: never a higher energy than without."""
    model, cams, walk, masks = scene

    def first(polish):
        # the sampled energy (decision 017): with the scanline count this scene's polish lowered the energy but
        # switched to a pose 256 mm off (seed 2)
        tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, init_refine_evals=100, seed=2,
                                                init_polish=polish, energy="fast"))
        r = tr.step(masks[0], 0)
        assert r.initialized and not r.fell_back
        return r

    off, on = first(False), first(True)
    polished = 2 if any(n.startswith("heading check started") for n in on.notes) else 1    # the rival's too
    assert polished * 0.9 * 300 < on.n_evals - off.n_evals <= polished * 300     # whole generations of the hierarchy
    assert on.energy < off.energy
    err = [frame_errors_mm(marker_positions(model, r.x[None]), marker_positions(model, walk[:1]))[0] for r in (off, on)]
    assert err[1] < err[0]


def test_a_frame_without_the_contour_stage(scene):
    """step(contour_stage=False), what the estimator does in real time with a set that waited too long: that frame
    is tracked as with contour_iterations=0 (the share goes to the main search), bit for bit; the next with it."""
    model, cams, walk, masks = scene

    def tracker(**kw):
        tr = Tracker(model, cams, TrackerConfig.from_flat(evals=1000, seed=4, **kw))
        tr.initialize(pose=walk[0])
        return tr

    light, off = tracker(), tracker(contour_iterations=0)
    a, b = light.step(masks[1], 1, contour_stage=False), off.step(masks[1], 1)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.energy == b.energy and a.n_evals == b.n_evals
    assert light.config.stages.contour_iterations == 3
    stage = []
    light.contour_fit.fit = lambda x, **kw: stage.append(1) or (x, ContourFitInfo(0, (), ()))
    light.step(masks[2], 2)
    assert stage


@pytest.fixture(scope="module")
def scene320():
    """Six frames of a generated walk at 320x240 (the heading check needs the default resolution: at
    160x120 and 300 evaluations both headings fit alike)."""
    return walk_scene(width=320, height=240, frames=6, duration_s=0.5, seed=0)


def _heading_runs(scene, monkeypatch, *, wrong_first: bool, external=None, **cfg):
    """Track scene320 from an automatic initialization; with ``wrong_first`` the initialized frame's
    runs heading like the truth get 1.4x their energy, so a run facing the other way wins."""
    import dataclasses

    from isa_mocap_ros.tracking.init import wrap_angle, yaw_of

    model, cams, walk, masks = scene
    if wrong_first:
        orig = first_frame.initial_runs
        yaw = yaw_of(walk[0][3:6])

        def runs(tr, ctx, starts, notes, budget, stream=()):
            out, n = orig(tr, ctx, starts, notes, budget, stream)
            if stream:                                  # the heading re-check's runs are left alone
                return out, n
            return [(j, dataclasses.replace(r, energy=1.4 * r.energy, best_energy=1.4 * r.best_energy)
                     if abs(wrap_angle(yaw_of(r.x[3:6]) - yaw)) < np.pi / 2 else r, p) for j, r, p in out], n
        monkeypatch.setattr(first_frame, "initial_runs", runs)
    # init_confirm_ratio 1.5: here the right and the wrong heading end 29 % apart on the first frame
    tr = Tracker(model, cams, TrackerConfig.from_flat(**{"seed": 0, "init_confirm_ratio": 1.5, **cfg}))
    out = [tr.step(masks[0], 0)]
    out += [tr.step(masks[k], k, prediction=(external or {}).get(k)) for k in range(1, len(masks))]
    monkeypatch.undo()
    err = frame_errors_mm(marker_positions(model, np.array([r.x for r in out])), marker_positions(model, walk))
    return tr, out, err


def _heading_notes(out):
    return [n for r in out for n in r.notes if n.startswith("heading check")]


def test_heading_check_keeps_a_right_first_heading_bit_for_bit(scene320, monkeypatch):
    # the rival (the best run facing the other way, within init_confirm_ratio) is tracked beside the
    # winner on the next frames: the winner's estimates do not change, the frames of the check count both
    _, off, err_off = _heading_runs(scene320, monkeypatch, wrong_first=False, init_confirm_frames=0)
    _, on, err_on = _heading_runs(scene320, monkeypatch, wrong_first=False)
    assert err_off.max() < 60.0
    for a, b in zip(off, on):
        np.testing.assert_array_equal(a.x, b.x)
    notes = _heading_notes(on)
    assert notes[0].startswith("heading check started: a run heading the other way ended") and \
        notes[1].startswith("heading check decided: kept the initial heading")
    checked = [k for k, r in enumerate(on) if any("kept the initial heading" in n for n in r.notes)][0]
    # each hypothesis' limb stage takes the rest as proposals: fewer unspent than its 4 limbs
    assert all(2 * 1500 - 8 < r.n_evals <= 2 * 1500 for r in on[1:checked + 1]) and checked >= 1
    assert all(1500 - 4 < r.n_evals <= 1500 for r in on[checked + 1:])


@pytest.fixture(scope="module")
def scene320_long():
    return walk_scene(width=320, height=240, frames=9, duration_s=0.5, seed=0)


def test_heading_recheck_when_views_join(scene320_long, monkeypatch):
    """The generated walk starts seen by two cameras only (the person walks into the others' view):
    the automatic initialization can face backwards and the heading check on those frames cannot
    tell. When more views see the person, a search from a standing pose heading the other way runs
    on that frame and, as close in energy, is checked beside the track: the check switches."""
    model, cams, walk, masks = scene320_long
    two = [[m if v in (0, 2) else None for v, m in enumerate(ms)] if k < 3 else ms for k, ms in enumerate(masks)]
    scene = (model, cams, walk, two)
    # init_confirm_ratio 1.0: the first frame's rival (the right heading, 1.4x) is not checked at all. The sampled
    # energy (decision 017): with the scanline count the track turned round without the re-check (6.5 mm at the end)
    _, off, err_off = _heading_runs(scene, monkeypatch, wrong_first=True, init_confirm_ratio=1.0,
                                    init_confirm_frames=0, energy="fast")
    tr, on, err_on = _heading_runs(scene, monkeypatch, wrong_first=True, init_confirm_ratio=1.0,
                                   init_confirm_frames=2, energy="fast")
    assert [r.views_used for r in on] == [2, 2, 2] + [4] * 6
    # what the estimator node asks before a frame, to keep the frames after it in sequence
    probe = Tracker(model, cams, TrackerConfig.from_flat(seed=0, init_confirm_ratio=1.0, energy="fast"))   # no check after the first frame
    assert not probe.heading_recheck_pending(masks[3])          # nothing tracked yet
    probe.step(two[0], 0)
    assert not probe.heading_recheck_pending(two[1]) and probe.heading_recheck_pending(masks[3])
    assert err_off[-3:].min() > 150.0                         # facing backwards to the end
    notes = [(k, n) for k, r in enumerate(on) for n in r.notes if n.startswith("heading")]
    assert notes[0][0] == 3 and notes[0][1].startswith("heading re-check: 4 views see the person (2 when the "
                                                       "heading was checked): a run heading the other way ended")
    assert notes[1][0] == 5 and notes[1][1].startswith("heading check decided: switched to the other heading")
    assert len(notes) == 2                                    # no views join after: no second re-check
    assert err_on[5:].max() < 60.0
    assert on[3].n_evals > 3 * 1500 and 2 * 1500 - 8 < on[4].n_evals <= 2 * 1500
    # the frames before the re-check are as without it
    for a, b in zip(off[:3], on[:3]):
        np.testing.assert_array_equal(a.x, b.x)
    # a given pose's heading is not re-checked
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=0))
    tr.initialize(pose=walk[2])
    assert not any(n.startswith("heading") for n in tr.step(masks[3], 3).notes)


def test_an_undecided_heading_check_is_rechecked_once(scene320_long, monkeypatch):
    """A check that keeps the winner only for want of evidence (sums within init_confirm_margin: the
    rival may still have been converging, the generated box seed 2) is re-checked once, a few frames
    later, from standing poses heading the other way."""

    monkeypatch.setattr(heading, "UNDECIDED_RECHECK_FRAMES", 2)
    _, on, _ = _heading_runs(scene320_long, monkeypatch, wrong_first=False, init_confirm_margin=10.0)
    notes = [(k, n) for k, r in enumerate(on) for n in r.notes if n.startswith("heading")]
    assert notes[0][0] == 0 and notes[0][1].startswith("heading check started")
    assert notes[1][0] == 3 and notes[1][1].startswith("heading check decided: kept the initial heading") \
        and notes[1][1].endswith("; undecided, re-checked in 2 frames)")
    assert notes[2][0] == 5 and notes[2][1].startswith("heading re-check: the last check was undecided: a run "
                                                       "heading the other way ended")
    assert on[5].n_evals > 3 * 1500
    # once only: a second undecided check is not re-checked again
    assert not any("re-checked in" in n for _, n in notes[2:])
    assert sum(n.startswith("heading re-check") for _, n in notes) == 1


@pytest.fixture(scope="module")
def scene320_two_views():
    """Twelve frames of the generated walk seen by two cameras only (views 0 and 2): from the front and
    from the back the person casts nearly the same silhouettes."""
    model, cams, walk, masks = walk_scene(width=320, height=240, frames=12, duration_s=0.5, seed=0)
    return model, cams, walk, [[m if v in (0, 2) else None for v, m in enumerate(ms)] for ms in masks]


def test_travel_cue_rechecks_a_track_that_moves_backwards(scene320_two_views, monkeypatch):
    """A track facing backwards (the first frame forced so, its heading check suppressed) whose root
    travels against its heading is re-checked once it has moved for TRAVEL_FRAMES frames, and the
    check switches; without the cue it faces backwards to the end."""
    from isa_mocap_ros.tracking import config as T

    def runs(**cfg):
        monkeypatch.setattr(first_frame, "pick_rival", lambda tr, *a, **k: None)   # no check after the first frame
        # the contour stage off: with it the backwards track fits the two views so closely that the re-check
        # can keep it on its energies (seen with the test workers' thread count; session 16)
        # seed 2: with seed 0 the switched track stayed at 130-155 mm on these two views once the root refinement
        # was the compiled ISA (session 26; see test_travel_cue_decides_a_close_heading_check)
        return _heading_runs(scene320_two_views, monkeypatch, wrong_first=True, init_confirm_frames=2,
                             contour_iterations=0, seed=2, **cfg)
    _, off, err_off = runs(heading_travel_cue=False)
    assert not any(n.startswith("heading") for r in off for n in r.notes)
    assert err_off[-3:].min() > 150.0
    _, on, err_on = runs()
    notes = [(k, n) for k, r in enumerate(on) for n in r.notes if n.startswith("heading")]
    assert notes[0][0] == T.TRAVEL_FRAMES and notes[0][1].startswith("heading re-check: the person moves backwards (")
    assert notes[1][0] == T.TRAVEL_FRAMES + 2 and notes[1][1].startswith(
        "heading check decided: switched to the other heading") and "this heading moves backwards" in notes[1][1]
    assert len(notes) == 2
    assert err_on[T.TRAVEL_FRAMES + 2:].max() < 80.0
    for a, b in zip(off[:T.TRAVEL_FRAMES], on[:T.TRAVEL_FRAMES]):      # the frames before are as without the cue
        np.testing.assert_array_equal(a.x, b.x)


def test_travel_cue_decides_a_close_heading_check(scene320_two_views, monkeypatch):
    """A heading check the energies leave undecided (init_confirm_margin 10) switches to the hypothesis
    that moves forwards; without the cue it keeps the initial heading for want of evidence."""
    # the contour stage and the initialization's polish off (as above: this scene's forced backwards first frame,
    # polished, travels too little in its two frames for the cue; session 17). Seed 2: with seed 0 the switched
    # track drifted to 150 mm on these two views once the root refinement was the compiled ISA (session 26; with
    # seeds 1 and 2 it tracked better than before: what follows a switch on two views is chaotic)
    # The sampled energy (decision 017): with the scanline count this undecided check kept the initial heading here
    _, off, err_off = _heading_runs(scene320_two_views, monkeypatch, wrong_first=True, init_confirm_frames=2,
                                    init_confirm_margin=10.0, heading_travel_cue=False, contour_iterations=0,
                                    init_polish=False, seed=2, energy="fast")
    assert any(n.startswith("heading check decided: kept the initial heading") for n in off[2].notes)
    assert err_off[2:6].min() > 150.0
    _, on, err_on = _heading_runs(scene320_two_views, monkeypatch, wrong_first=True, init_confirm_frames=2,
                                  init_confirm_margin=10.0, contour_iterations=0, init_polish=False, seed=2,
                                  energy="fast")
    decided = [n for n in on[2].notes if n.startswith("heading check decided")]
    assert len(decided) == 1 and decided[0].startswith("heading check decided: switched to the other heading") \
        and "this heading moves backwards" in decided[0]
    assert err_on[2:].max() < 80.0


def test_travel_reads_the_root_motion(scene320_two_views):
    from isa_mocap_ros.tracking import config as T

    model, cams, walk, _ = scene320_two_views
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=0))
    assert tr.travel() is None                                  # nothing tracked yet
    tr.initialize(pose=walk[0])
    assert tr.travel() is None                                  # one estimate: no travel
    for x in walk[1:T.TRAVEL_FRAMES + 1]:
        tr.accept(x)
    direction, dist, span = tr.travel()
    assert span == T.TRAVEL_FRAMES and dist == pytest.approx(np.hypot(*(walk[T.TRAVEL_FRAMES][:2] - walk[0][:2])))
    assert heading.off_travel(direction, walk[T.TRAVEL_FRAMES]) < 20.0            # the generated walk moves forwards
    assert tr.travel(min_periods=T.TRAVEL_FRAMES + 1) is None
    assert heading.travel_recheck_due(tr) is None                                   # forwards: no re-check
    assert not tr.heading_recheck_pending([None] * len(cams))
    from isa_mocap_ros.geometry.so3 import exp_so3, log_so3, rot_z

    turned = tr.track.last.copy()
    turned[3:6] = log_so3(rot_z(np.pi) @ exp_so3(turned[3:6]))              # heading the other way
    tr.track.last = turned
    assert heading.travel_recheck_due(tr)[0] > 160.0
    assert tr.heading_recheck_pending([None] * len(cams))                    # the estimator holds the frames after
    tr.reset()
    assert tr.travel() is None
    still = Tracker(model, cams, TrackerConfig.from_flat(seed=0))
    still.initialize(pose=walk[0])
    for _ in range(T.TRAVEL_FRAMES):
        still.accept(walk[0])                                   # standing: no travel
    assert still.travel() is None
    with pytest.raises(TrackerError, match="heading_travel_cue"):
        TrackerConfig.from_flat(heading_travel_cue=1)


def test_heading_check_ends_at_a_gap(scene320):
    # after a gap (real time: the sets that came during the initialization were dropped) both
    # hypotheses are still catching up: the check ends there without stepping the rival
    model, cams, walk, masks = scene320
    tr = Tracker(model, cams, TrackerConfig.from_flat(seed=0, init_confirm_ratio=1.5))
    assert not tr.checking_heading
    assert any("both tracked" in n for n in tr.step(masks[0], 0).notes)
    assert tr.checking_heading          # the estimator node keeps the next sets in sequence meanwhile
    r = tr.step(masks[2], 2, frames_elapsed=2)
    assert 1500 - 4 < r.n_evals <= 1500
    assert any("heading check ended: no decision (2 frame periods" in n and "re-checked on the next frame" in n
               for n in r.notes)
    assert not tr.checking_heading
    # the check is re-checked once on the next frame that follows its previous one (the estimator node holds
    # the sets in sequence for it when heading_recheck_pending says so): not after another gap, but then
    assert tr.heading_recheck_pending(masks[4])
    r = tr.step(masks[4], 4, frames_elapsed=2)
    assert not any("heading" in n for n in r.notes) and tr.heading_recheck_pending(masks[5])
    r = tr.step(masks[5], 5)
    assert any(n.startswith("heading re-check: the last check ended at a gap") for n in r.notes)
    if not tr.checking_heading:           # the re-check kept this heading: check against the other one anyway
        tr.heading_check.rival_start = (walk[5], r.energy, r.energy)
        heading.start_rival(tr, 5)
    r = tr.step(masks[5], 7, frames_elapsed=2)           # that check ended by a gap too: not re-checked again
    assert any(n.startswith("heading check ended: no decision") and "re-checked" not in n for n in r.notes)
    assert not tr.checking_heading and not tr.heading_recheck_pending(masks[5])


def test_a_polished_rival_mends_a_wrong_first_heading(scene320, monkeypatch):
    """init_polish: the heading check's rival is polished with the winner, and the heading that fits better
    after it wins on the initialized frame itself (bags/demo seed 0, the generated box seed 6)."""
    _, off, err_off = _heading_runs(scene320, monkeypatch, wrong_first=True, init_polish=False)
    assert err_off[0] > 200.0                         # facing backwards until the check switches
    tr, on, err = _heading_runs(scene320, monkeypatch, wrong_first=True)
    assert any(n.startswith("heading check started") for n in on[0].notes)
    assert any(n.startswith("initialization polish: the heading check's rival fits better") for n in on[0].notes)
    assert err.max() < 60.0
    assert not any("switched to the other heading" in n for r in on for n in r.notes)


def test_heading_check_switches_from_a_wrong_first_heading(scene320, monkeypatch):
    # init_polish off: with it the polished rival wins on the first frame already (above)
    _, off, err_off = _heading_runs(scene320, monkeypatch, wrong_first=True, init_confirm_frames=0, init_polish=False)
    assert err_off.min() > 200.0                      # facing backwards: lost for good without the check
    tr, on, err = _heading_runs(scene320, monkeypatch, wrong_first=True, init_polish=False)
    switched = [k for k, r in enumerate(on) if any("switched to the other heading" in n for n in r.notes)]
    assert len(switched) == 1 and 1 <= switched[0] <= 3 and not tr.checking_heading
    k = switched[0]
    assert err[:k].min() > 200.0 and err[k:].max() < 60.0
    np.testing.assert_array_equal(tr.last_estimate, on[-1].x)
    # an external prediction (made from the estimates before the switch) is ignored on the frame
    # after it (AR order 1 looks back on two estimates), used again on the next
    model, _, walk, _ = scene320
    _, ext, _ = _heading_runs(scene320, monkeypatch, wrong_first=True, init_polish=False,
                              external={k + 1: walk[k + 1], k + 2: walk[k + 2]})
    for j in range(k + 2):
        np.testing.assert_array_equal(ext[j].x, on[j].x)
    assert any("the external one follows the estimates from before" in n for n in ext[k + 1].notes)
    assert not any("external" in n for n in ext[k + 2].notes) and not np.array_equal(ext[k + 2].x, on[k + 2].x)


def test_fallbacks_never_raise_and_say_why(scene):
    model, cams, walk, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=200, seed=0))
    r = tr.step([None] * 4, 0)                           # nothing yet: no estimate
    assert r.x is None and r.fell_back and any("no estimate yet" in n for n in r.notes)
    tr.initialize(pose=walk[0])
    empty = [np.zeros_like(m) for m in masks[1]]
    r = tr.step(empty, 1)                                # nobody in view
    assert r.fell_back and r.n_evals == 0 and r.views_used == 0
    np.testing.assert_array_equal(r.x, walk[0])
    assert any("empty mask" in n for n in r.notes) and any("falling back" in n for n in r.notes)
    bad = list(masks[1])
    bad[1] = np.zeros((7, 9), np.uint8)                  # wrong size
    bad[2] = None                                        # missing view
    r = tr.step(bad, 2)
    assert not r.fell_back and r.views_used == 2
    assert any("view 1: mask shape (7, 9)" in n for n in r.notes)
    assert any("view 2: no mask" in n for n in r.notes)
    r = tr.step(masks[2][:3], 3)                         # a view short
    assert not r.fell_back and r.views_used == 3 and any("expected 4 views, received 3" in n for n in r.notes)
    nan = np.full(model.dof, np.nan)
    r = tr.step(masks[3], 4, prediction=nan)             # NaN external prediction
    assert not r.fell_back and any("prediction: non-finite" in n for n in r.notes)
    assert np.all(np.isfinite(r.x))
    r = tr.step(masks[3], 5, prediction=np.zeros(3))     # wrong length
    assert any("prediction: expected shape (39,)" in n for n in r.notes)
    r = tr.step("not masks", 6)
    assert r.fell_back and r.x is not None


def test_nan_from_own_predictor_falls_back_to_last_estimate(scene):
    model, cams, walk, masks = scene

    class NanPredictor:
        def update(self, x):
            pass

        def predict(self):
            return np.full(model.dof, np.nan)

        def reset(self):
            pass

    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=200), predictor=NanPredictor())
    tr.initialize(pose=walk[0])
    r = tr.step(masks[1], 1)
    assert not r.fell_back and any("using the last estimate" in n for n in r.notes)
    np.testing.assert_array_equal(r.prediction, walk[0])


def test_search_box_respects_radius_and_limits(scene):
    model, cams, walk, _ = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(search_radius_rad=0.5, root_translation_radius_m=0.2))
    x = walk[0].copy()
    k = model.knee_dofs[0]
    x[k] = model.lower[k]                                # a prediction on a limit
    lo, hi, spread = tr.search_box(x)
    assert np.all(lo < hi) and np.all(lo >= model.lower) and np.all(hi <= model.upper)
    j = 10
    assert hi[j] - lo[j] <= 1.0 + 1e-12
    np.testing.assert_allclose(hi[:3] - lo[:3], 0.4)
    assert lo[k] == model.lower[k]


@pytest.mark.parametrize("kw, match", [
    ({"optimizer": "nope"}, "optimizer: expected one of"),
    ({"evals": 0}, "evals: expected an integer >= 1"),
    ({"search_radius_rad": -1.0}, "search_radius_rad: expected a finite number > 0"),
    ({"predictor": "kalman"}, "predictor: expected one of ar, constant_pose, constant_velocity"),
    ({"optimizer_params": {"bounds": 1}}, r"optimizer_params: expected algorithm parameters only"),
    ({"energy": "slow"}, "energy: expected one of fast, exact, raster, received 'slow'"),
    ({"seed": -1}, "seed: expected an integer >= 0"),
    ({"n_model_points": 0}, "n_model_points: expected an integer >= 1"),
    ({"n_mask_points": -1}, "n_mask_points: expected an integer >= 0"),
    ({"spread_velocity_gain": -0.5}, "spread_velocity_gain: expected a finite number >= 0"),
    ({"init_keep": 1.5}, "init_keep: expected an integer >= 0"),
    ({"init_confirm_frames": -1}, "init_confirm_frames: expected an integer >= 0"),
    ({"init_confirm_ratio": 0.9}, "init_confirm_ratio: expected a finite number >= 1.0"),
    ({"init_confirm_margin": float("nan")}, "init_confirm_margin: expected a finite number >= 1.0"),
    ({"init_polish": "yes"}, "init_polish: expected true or false, received 'yes'"),
    ({"contour_extra_iterations": -1}, "contour_extra_iterations: expected an integer >= 0"),
    ({"contour_extra_partitions": "left_leg"}, "contour_extra_partitions: expected distinct partition names"),
])
def test_config_errors(kw, match):
    with pytest.raises(TrackerError, match=match):
        TrackerConfig.from_flat(**kw)


def test_tracker_argument_errors(scene):
    model, cams, walk, masks = scene
    with pytest.raises(TrackerError, match="prior: expected a ParzenPrior"):
        Tracker(model, cams, TrackerConfig.from_flat(prior_eta=1.0))
    tr = Tracker(model, cams)
    with pytest.raises(TrackerError, match="frame_index: expected an integer >= 0"):
        tr.step(masks[0], -1)
    with pytest.raises(TrackerError, match="pose: expected a pose of length 39"):
        tr.initialize(pose=np.zeros(5))
    with pytest.raises(TrackerError, match="expected masks= or pose="):
        tr.initialize()


def test_optimizer_rejecting_budget_is_reported_not_raised(scene):
    model, cams, walk, masks = scene
    tr = make_tracker(model, cams, optimizer="isa", evals=10, optimizer_params={"n_particles": 50})
    tr.initialize(pose=walk[0])
    r = tr.step(masks[1], 1)
    assert r.fell_back and any("optimizer failed" in n for n in r.notes)


def test_hierarchical_and_prior(scene):
    from isa_mocap_ros.energy.prior import ParzenPrior

    model, cams, walk, masks = scene
    prior = ParzenPrior(generate_motion("walk", model, duration_s=1.0, fps=30, rng=np.random.default_rng(5)))
    tr = Tracker(model, cams, TrackerConfig.from_flat(optimizer="h-cmaes", evals=600, prior_eta=0.01), prior=prior)
    tr.initialize(pose=walk[0])
    r = tr.step(masks[1], 1)
    assert not r.fell_back and 600 - 4 < r.n_evals <= 600       # < 4 limbs left unspent
    np.testing.assert_allclose(tr.total_energy(r.x[None]) - tr.energy(r.x[None]),
                               prior.energy(r.x[None], eta=0.01))


def test_energy_sample_sizes_reach_the_default_energy(scene):
    """The config's fast-energy sample sizes and downsampling are those of the energy it builds."""
    model, cams, _, _ = scene
    cfg = TrackerConfig.from_flat(n_model_points=200, n_mask_points=50, downsample=1)
    en = Tracker(model, cams, cfg).energy
    assert en.downsample == 1
    assert en.n_mask_points == 50
    assert en.n_template >= 200          # the template holds at least the requested model points


def test_tracks_through_a_half_turn():
    """A walker whose heading crosses 180° while the prediction travels through JointState
    messages (roll/pitch/yaw: |r| <= pi, as in the network). The prediction is re-expressed next to
    the last estimate before the damped extrapolation; before, 174° and −179° averaged to −72° and
    the track was lost (bags/demo, 3 of 4 seeds)."""
    from isa_mocap_ros.geometry import exp_so3, log_so3, rot_z
    from isa_mocap_ros.tracking.published import PublishedPredictor

    model = make_model(39)
    rig = default_rig(width=160, height=120)
    walk = generate_motion("walk", model, duration_s=0.3, fps=30, rng=np.random.default_rng(0))[:8]
    truth = walk.copy()
    for k, x in enumerate(walk):
        R = exp_so3(x[3:6])
        yaw = np.arctan2(R[1, 0], R[0, 0])
        turn = rot_z(np.deg2rad(168.0 + 3.0 * k) - yaw)          # heading 168° → 189°
        truth[k, :3] = turn @ x[:3]
        truth[k, 3:6] = log_so3(turn @ R)
    masks = [[render_mask(c, capsule_endpoints(model, x)[0], model.capsule_radii) for c in rig.cameras]
             for x in truth]
    tr = Tracker(model, rig.cameras, TrackerConfig.from_flat(evals=800, seed=3))
    tr.predictor = PublishedPredictor(model, tr.predictor)
    tr.initialize(pose=truth[0])
    out = [tr.step(masks[k], k) for k in range(1, len(truth))]
    est = np.array([r.x for r in out])
    err = frame_errors_mm(marker_positions(model, est), marker_positions(model, truth[1:]))
    assert err.max() < 45.0
    assert np.all(np.linalg.norm(est[:, 3:6], axis=1) <= np.pi + 1e-12)       # published canonical
    # the truth does cross |r| = pi (else this test would not test the crossing)
    assert np.linalg.norm(truth[3, 3:6]) > 3.0 and np.sign(truth[3, 5]) != np.sign(truth[-1, 5])


@pytest.mark.parametrize("gain", [0.0, 1.5])
def test_spreads_grow_with_the_predicted_motion(scene, monkeypatch, gain):
    """Joints the (damped) prediction moves start with sqrt(s0^2 + (k |p - x|)^2); the others, the
    root, and every joint with gain 0 keep JOINT_SPREAD_RAD."""
    import isa_mocap_ros.optim as optim

    model, cams, walk, masks = scene
    seen = []
    real = optim.make_optimizer

    def spy(name, x0, spread, **kw):
        seen.append(np.array(spread, dtype=float))
        return real(name, x0, spread, **kw)

    monkeypatch.setattr(optim, "make_optimizer", spy)
    cfg = TrackerConfig.from_flat(evals=300, seed=1, spread_velocity_gain=gain, pelvis_fraction=0.0,
                        limb_proposals=0, joint_velocity_gain=0.5)
    tr = Tracker(model, cams, cfg)
    tr.initialize(pose=walk[0])
    k = model.knee_dofs[0]
    p = walk[0].copy()
    p[k] += 0.4                                       # the external prediction bends one knee
    tr.step(masks[1], 1, prediction=p)
    spread = seen[0]
    want = np.full(model.dof, JOINT_SPREAD_RAD)
    want[k] = np.hypot(JOINT_SPREAD_RAD, gain * 0.5 * 0.4)   # damped: half of the predicted motion
    np.testing.assert_allclose(spread[6:], want[6:], rtol=1e-12)
    np.testing.assert_allclose(spread[:3], ROOT_TRANSLATION_SPREAD_M)


class _SpyPredictor:
    """An ArPredictor that records the frame counts the tracker passes (None = the default 1)."""

    def __init__(self):
        from isa_mocap_ros.tracking.predict import ArPredictor
        self.inner, self.updates, self.predicts = ArPredictor(order=1), [], []

    def update(self, x, **kw):
        self.updates.append(kw.get("frames"))
        self.inner.update(x, **kw)

    def predict(self, **kw):
        self.predicts.append(kw.get("frames"))
        return self.inner.predict(**kw)

    def reset(self):
        self.inner.reset()


def test_own_prediction_looks_as_many_frames_ahead_as_have_passed(scene):
    """Frames the tracker did not see (frames_elapsed, or a frame that fell back) make its own
    prediction look further ahead (at most max_frames_ahead); the predictor learns per period."""
    model, cams, walk, masks = scene
    spy = _SpyPredictor()
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, seed=1, max_frames_ahead=4), predictor=spy)
    tr.initialize(pose=walk[0])
    assert tr.step(masks[1], 1).fell_back is False                   # consecutive: the plain calls
    assert tr.step([None] * len(cams), 2).fell_back is True          # nothing seen: no update
    tr.step(masks[3], 3)                                             # 2 periods since the last estimate
    tr.step(masks[4], 4, frames_elapsed=3)
    tr.step(masks[4], 5, frames_elapsed=7)                           # capped at 4 ahead, learnt as 7
    assert spy.updates == [None, None, 2.0, 3.0, 7.0]
    assert spy.predicts == [None, 2.0, 3.0, 4.0]                      # one prediction per tracked frame
    with pytest.raises(TrackerError, match="frames_elapsed: expected a number of frame periods > 0"):
        tr.step(masks[4], 6, frames_elapsed=0)
    with pytest.raises(TrackerError, match="frames_elapsed"):
        tr.step(masks[4], 6, frames_elapsed="2")
    with pytest.raises(TrackerError, match="max_frames_ahead"):
        TrackerConfig.from_flat(max_frames_ahead=0.5)


def test_consecutive_frames_give_the_same_estimates_with_frames_elapsed_one(scene):
    cfg = TrackerConfig.from_flat(evals=300, seed=4)
    _, a = _track(scene, cfg)
    model, cams, walk, masks = scene
    tr = Tracker(model, cams, cfg)
    tr.initialize(pose=walk[0])
    b = [tr.step(masks[k], k, frames_elapsed=1.0) for k in range(1, N_FRAMES)]
    for ra, rb in zip(a, b):
        np.testing.assert_array_equal(ra.x, rb.x)


def test_after_a_long_gap_the_root_follows_the_foreground(scene):
    """More than max_frames_ahead periods unseen (e.g. the automatic initialization in real time):
    the predicted root position moves with the triangulated foreground centroid, not the motion."""
    model, cams, walk, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, seed=2))
    tr.initialize(pose=walk[0])
    tr.step(masks[1], 1)
    far = walk[2].copy()
    far[0] += 0.6                                                    # the person walked on 60 cm
    far_masks = [render_mask(c, capsule_endpoints(model, far)[0], model.capsule_radii) for c in cams]
    r = tr.step(far_masks, 30, frames_elapsed=28)
    moved = [n for n in r.notes if "root moved with the foreground" in n]
    assert len(moved) == 1 and "28 frame periods" in moved[0]
    assert abs(r.prediction[0] - walk[1][0] - 0.6) < 0.1, r.prediction[0]
    assert abs(r.x[0] - far[0]) < 0.05                               # tracked there, not lost
    # a short gap extrapolates the motion instead
    r = tr.step(masks[4], 31, frames_elapsed=2)
    assert not any("root moved" in n for n in r.notes)


def test_after_a_gap_from_the_first_estimate_the_root_follows_the_foreground(scene):
    """A single estimate holds no motion (real time: the first set tracked after the automatic
    initialization comes a few periods later): even a short gap moves the predicted root with the
    foreground; once the motion is known a short gap extrapolates it."""
    model, cams, walk, masks = scene
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=300, init_refine_evals=100, seed=2, init_confirm_frames=0))
    assert tr.step(masks[0], 0).initialized                           # automatic: the masks say where it was
    far = walk[2].copy()
    far[0] += 0.15                                                   # 15 cm further than the walk's frame 2
    far_masks = [render_mask(c, capsule_endpoints(model, far)[0], model.capsule_radii) for c in cams]
    r = tr.step(far_masks, 2, frames_elapsed=2)
    moved = [n for n in r.notes if "root moved with the foreground" in n]
    assert len(moved) == 1 and "2 frame periods" in moved[0]
    assert abs(r.prediction[0] - far[0]) < 0.05, (r.prediction[0], far[0])
    r = tr.step(masks[4], 4, frames_elapsed=2)
    assert not any("root moved" in n for n in r.notes)


def test_a_side_on_rival_is_searched_again_from_the_winners_opposite(scene320, monkeypatch):
    """heading.init_rival: when the heading check's rival (the best run heading > 90 deg away) ended side-on, the
    frame is searched again from the winner's opposite and the better rival is checked (the 35-occluder mesh bag:
    a backwards winner over a rival 46-48 deg off, docs/history/issue33_mesh_accuracy_s29.md). Here the runs heading
    like the truth are turned 60 deg and scored 1.4x, so a backwards run wins over a side-on rival."""
    import dataclasses

    from isa_mocap_ros.geometry import exp_so3, log_so3
    from isa_mocap_ros.tracking.init import wrap_angle, yaw_of, yaw_rotvec

    model, cams, walk, masks = scene320
    yaw = yaw_of(walk[0][3:6])
    orig = first_frame.initial_runs
    turn = exp_so3(yaw_rotvec(np.radians(60.0)))

    def side_on(r):
        x = np.array(r.x, dtype=float)
        x[3:6] = log_so3(turn @ exp_so3(x[3:6]))
        return dataclasses.replace(r, x=x, best_x=x, energy=1.4 * r.energy, best_energy=1.4 * r.best_energy)

    def runs(tr, ctx, starts, notes, budget, stream=()):
        out, n = orig(tr, ctx, starts, notes, budget, stream)
        if stream:                                  # the searches from the opposite are left alone
            return out, n
        return [(j, side_on(r) if abs(wrap_angle(yaw_of(r.x[3:6]) - yaw)) < np.pi / 2 else r, p)
                for j, r, p in out], n

    def track(opposite_deg):
        monkeypatch.setattr(first_frame, "initial_runs", runs)
        monkeypatch.setattr(heading, "RIVAL_OPPOSITE_DEG", opposite_deg)
        tr = Tracker(model, cams, TrackerConfig.from_flat(seed=0, init_confirm_ratio=1.5))
        out = [tr.step(m, k) for k, m in enumerate(masks)]
        monkeypatch.undo()
        return out, frame_errors_mm(marker_positions(model, np.array([r.x for r in out])),
                                    marker_positions(model, walk))

    out, err = track(heading.RIVAL_OPPOSITE_DEG)
    assert any("off the winner's opposite" in n and "and is the rival" in n for n in out[0].notes), out[0].notes
    assert err.max() < 60.0
    off, err_off = track(180.0)                     # the side-on rival checked as it is
    assert not any("off the winner's opposite" in n for r in off for n in r.notes)
    assert err_off[0] > 200.0
