"""The nodes' input gate (isa_mocap_ros.intake): a view's camera is what camera_info and image agree on."""
import pytest

from isa_mocap_ros.intake import Setting, StampWindow, ViewGate

S = 1_700_000_000_000_000_000
P = 33_333_333
CAM = Setting("cam0_optical_frame", 320, 240, "rgb8")
INFO = Setting("cam0_optical_frame", 320, 240)


def gate(**kw):
    return ViewGate("cam0", max_gap_ns=5_000_000_000, **kw)


def test_nothing_is_learnt_before_a_camera_info_vouches_for_an_image():
    g = gate()
    # the stray image: a valid 7x3 bgr8 image arriving first
    acc, rej = g.add_image(S - 10 * P, Setting("cam0_optical_frame", 7, 3, "bgr8"), "stray")
    assert acc == [] and rej == [] and g.setting is None and g.waiting() == 1
    acc, rej = g.add_image(S, CAM, "img0")                   # the real first image waits for its info
    assert acc == [] and g.waiting() == 2
    acc, rej = g.add_info(S, INFO, "info0")
    assert [a.payload for a in acc] == ["img0"] and acc[0].first and acc[0].info == "info0"
    assert g.setting == CAM
    # the stray one is older than what got in: its camera_info is not coming
    assert len(rej) == 1 and rej[0].kind == "size" and "7x3" in rej[0].text and g.waiting() == 0


def test_images_that_disagree_with_the_camera_are_rejected_and_never_change_it():
    g = gate()
    g.add_info(S, INFO, "info0")
    assert g.add_image(S, CAM, "img0")[0][0].first
    # later images without their camera_info (yet): the confirmed setting decides
    acc, _ = g.add_image(S + P, CAM, "img1")
    assert [a.payload for a in acc] == ["img1"] and acc[0].info == "info0"
    bad = [Setting("cam0_optical_frame", 7, 3, "rgb8"), Setting("cam0_optical_frame", 320, 240, "bgr8"),
           Setting("cam5_optical_frame", 320, 240, "rgb8")]
    for k, st in enumerate(bad):
        assert g.add_image(S + (2 + k) * P + 1, st, "bad") == ([], [])    # waits for a camera_info of its stamp
    acc, rej = g.add_image(S + 10 * P, CAM, "img10")                      # a newer good image gets in first
    assert [a.payload for a in acc] == ["img10"]
    assert sorted(r.kind for r in rej) == ["encoding", "frame_id", "size"], rej
    assert g.setting == CAM


def test_far_stamps_are_rejected():
    g = gate()
    g.add_info(S, INFO, "i")
    g.add_image(S, CAM, "img0")
    for far in (S + 3600 * 10**9, S - 100 * 10**9, 0):
        assert g.add_image(far, CAM, "far")[0] == []
    acc, rej = g.add_image(S + P, CAM, "img1")
    assert len(acc) == 1
    # 0 and the one an hour back are older than img1: rejected now; the future one waits until it drops out
    assert [r.kind for r in rej] == ["stamp", "stamp"] and "s from the stream" in rej[0].text
    assert g.waiting() == 1


def test_a_camera_info_pair_that_disagrees_within_itself_is_rejected():
    g = gate()
    acc, rej = g.add_image(S, Setting("cam0_optical_frame", 7, 3, "bgr8"), "stray")
    acc, rej = g.add_info(S, INFO, "info")                   # same stamp, other size
    assert acc == [] and rej[0].kind == "pair" and "its camera_info says 320x240" in rej[0].text
    g.add_info(S + P, Setting("other_frame", 320, 240), "info")
    acc, rej = g.add_image(S + P, CAM, "img")
    assert acc == [] and rej[0].kind == "pair" and "frame_id 'cam0_optical_frame', its camera_info's is" in rej[0].text
    assert g.setting is None


def test_a_real_resolution_change_restarts_the_view():
    g = gate()
    g.add_info(S, INFO, "i0")
    g.add_image(S, CAM, "a")
    big = Setting("cam0_optical_frame", 640, 480, "rgb8")
    assert g.add_image(S + P, big, "b") == ([], [])          # before its camera_info: waits
    acc, rej = g.add_info(S + P, Setting("cam0_optical_frame", 640, 480), "i1")
    assert rej == [] and acc[0].payload == "b" and acc[0].changed == (
        "320x240 rgb8 in 'cam0_optical_frame' -> 640x480 rgb8 in 'cam0_optical_frame'")
    assert g.setting == big and g.info == "i1"
    acc, _ = g.add_image(S + 2 * P, big, "c")                # and the next ones are the new size
    assert acc[0].payload == "c" and acc[0].changed is None
    # a lone camera_info of the old size changes nothing; it is counted once it drops out unmatched
    rej = []
    for k in range(11):
        rej += g.add_info(S + (3 + k) * P + 7, INFO, "old")[1]
    assert len(rej) == 1 and rej[0].kind == "camera_info" and g.setting == big


def test_a_stream_that_jumps_is_followed_through_a_pair():
    g = gate()
    g.add_info(S, INFO, "i0")
    g.add_image(S, CAM, "a")
    later = S + 100 * 10**9                                  # a camera paused for 100 s, or a bag looped
    assert g.add_image(later, CAM, "b") == ([], [])
    acc, _ = g.add_info(later, INFO, "i1")
    assert acc[0].payload == "b"
    assert g.add_image(later + P, CAM, "c")[0][0].payload == "c"


def test_waiting_images_are_bounded():
    g = gate(depth=3)
    rej = []
    for k in range(5):
        rej += g.add_image(S + k * P, CAM, k)[1]
    assert g.waiting() == 3 and [r.kind for r in rej] == ["no_camera_info"] * 2
    assert "no camera_info of its stamp arrived" in rej[0].text


def test_without_camera_info_the_first_image_fixes_the_setting():
    g = gate(need_info=False)
    assert g.add_image(S, CAM, "a")[0][0].first
    acc, rej = g.add_image(S + P, Setting("cam0_optical_frame", 7, 3, "rgb8"), "b")
    assert acc == [] and rej[0].kind == "size"
    assert g.add_image(S + 2 * P, CAM, "c")[0][0].payload == "c"


def test_stamp_window():
    w = StampWindow(10)
    assert w.far(12345) is None          # nothing accepted yet
    w.accept(100)
    assert w.far(110) is None and w.far(90) is None
    assert "s from the stream" in w.far(111)
    assert StampWindow(0).far(10**18) is None
    with pytest.raises(ValueError, match="depth"):
        ViewGate("cam0", max_gap_ns=1, depth=0)


def test_expected_tracker_notes_are_events_not_problems():
    from isa_mocap_ros.nodes.estimator import note_is_expected

    for note in ("view 2: empty mask (nobody in view); skipped",
                 "initialized automatically (4 heading candidates, 3 searched to the end)",
                 "heading check started: a run heading the other way ended 0.05",
                 "heading check decided: kept the initial heading (energy sums ...)",
                 "no usable view and no estimate yet: nothing to track",
                 "pelvis stage skipped: its share (12 evaluations) is below one generation",
                 "keypoints screened: 1 off the foreground, 5 outside the views' consensus, 46 of 52 kept"):
        assert note_is_expected(note), note
    for note in ("view 1: mask shape (7, 3), expected (240, 320); skipped",
                 "no usable view: falling back to the last estimate",
                 "optimizer failed: boom; falling back to the last estimate",
                 "view 0: empty mask after the gate (all 12 foreground pixels farther than 40 px); skipped",
                 "energy: 3 non-finite evaluations"):
        assert not note_is_expected(note), note


def test_stream_jumps_one_stray_stamp_changes_nothing_a_real_restart_is_followed():
    from isa_mocap_ros.intake import StreamJumps

    j = StreamJumps(back_ns=10**9, ahead_ns=5 * 10**9)
    assert j.decide(S) == ("take", None) and j.decide(S + P)[0] == "take"
    kind, why = j.decide(S)                                         # older, within back_ns
    assert kind == "order" and "out of order" in why
    for stray in (S + 3600 * 10**9, S - 3600 * 10**9, 7):           # far, alone: dropped, the stream goes on
        assert j.decide(stray)[0] == "far"
        assert j.decide(j.last_ns + P)[0] == "take"
    start = S - 100 * 10**9                                         # a replayed bag: two stamps in sequence
    assert j.decide(start)[0] == "far"
    kind, why = j.decide(start + P)
    assert kind == "restart" and "restarted" in why and j.last_ns == start + P
    assert j.decide(start + 2 * P)[0] == "take"


def test_stream_forks_a_far_stamp_gets_a_state_of_its_own_kept_only_when_the_stream_follows_it():
    from isa_mocap_ros.intake import StreamForks

    made = []
    f = StreamForks(lambda: made.append(len(made)) or made[-1], back_ns=10**9, ahead_ns=5 * 10**9)
    first = f.state
    assert f.state_for(S) == ("take", first, None) and f.state_for(S + P)[:2] == ("take", first)
    kind, state, why = f.state_for(S)                                 # older, within back_ns
    assert kind == "drop" and state is None and "out of order" in why
    for stray in (S + 3600 * 10**9, S - 3600 * 10**9, 7):            # far, alone: its own state, the stream's untouched
        kind, state, why = f.state_for(stray)
        assert kind == "far" and state is not first and "from the stream" in why and "taken as" not in why
        assert f.state_for(f.jumps.last_ns + P)[:2] == ("take", first)
    start = S - 100 * 10**9                                           # a replayed bag: two stamps in sequence
    kind, candidate, _ = f.state_for(start)
    assert kind == "far"
    kind, state, why = f.state_for(start + P)
    assert kind == "restart" and state is candidate and f.state is candidate and "restarted" in why
    assert f.state_for(start + 2 * P)[:2] == ("take", candidate)


def test_a_restart_survives_a_message_between_its_first_two_stamps():
    """test_network_fuzz: the segmentation node's stream of a view had begun at the fuzzer's stamps (its agreeing
    pairs before the bag); the bag's first frame was far (a candidate), and one message between it and the second
    frame -- the old stream's next stamp, or a far pair -- made the rule forget it: the background was learnt from
    the second frame on, and the first frames with a person were taken for background (no estimate, or keypoints
    on other frames than ``track``'s)."""
    from isa_mocap_ros.intake import StreamForks, StreamJumps

    start = S + 3600 * 10**9
    for between in (S + 2 * P, 7, S - 100 * 10**9):       # the old stream goes on; a far stamp; another far one
        j = StreamJumps(back_ns=10**9, ahead_ns=5 * 10**9)
        assert j.decide(S)[0] == "take" and j.decide(S + P)[0] == "take"
        assert j.decide(start)[0] == "far"
        assert j.decide(between)[0] in ("take", "far")
        assert j.decide(start + P)[0] == "restart" and j.restarted_from == start and j.last_ns == start + P
        assert j.decide(between + P)[0] != "restart"         # the restart forgot the others
    made = []
    f = StreamForks(lambda: made.append(len(made)) or made[-1], back_ns=10**9, ahead_ns=5 * 10**9)
    f.state_for(S)
    _, first_state, _ = f.state_for(start)                  # the restart's first frame, on a state of its own
    assert f.state_for(7)[0] == "far" and f.state_for(S + P)[:2] == ("take", f.state)
    kind, state, _ = f.state_for(start + P)
    assert kind == "restart" and state is first_state and f.state is first_state


def test_stream_jumps_remembers_its_last_candidates_only():
    from isa_mocap_ros.intake import StreamJumps

    j = StreamJumps(back_ns=10**9, ahead_ns=5 * 10**9, candidates=2)
    j.decide(S)
    for k in range(3):
        assert j.decide(S + (k + 1) * 100 * 10**9)[0] == "far"
    assert j.candidates == (S + 200 * 10**9, S + 300 * 10**9)
    assert j.decide(S + 100 * 10**9 + P)[0] == "far"        # the oldest was forgotten
    with pytest.raises(ValueError, match="candidates"):
        StreamJumps(back_ns=0, ahead_ns=0, candidates=0)
