"""The keypoint node's intake (isa_mocap_ros.keypoint_intake): only the estimator's frame sets move the schedule."""
from isa_mocap_ros.intake import Setting
from isa_mocap_ros.keypoint_intake import KeypointIntake

S = 1_700_000_000_000_000_000
P = 33_333_333
HOUR = 3600 * 10**9


def cam(v, w=160, h=120):
    return Setting(f"cam{v}_optical_frame", w, h, "rgb8")


def info(v, w=160, h=120):
    return Setting(f"cam{v}_optical_frame", w, h)


def mask_setting(v, w=160, h=120):
    return Setting(f"cam{v}_optical_frame", w, h)


def intake(n=2, **kw):
    return KeypointIntake(n, every_k=kw.pop("every_k", 2), dense_frames=kw.pop("dense_frames", 1),
                          max_gap_ns=5 * 10**9, **kw)


def frame(ki, v, stamp, person=True, *, image="img", w=160, h=120):
    """One view's camera_info, image and mask of ``stamp`` (the camera and the segmentation node)."""
    jobs, problems = [], []
    for j, p in (ki.add_info(v, stamp, info(v, w, h), "K", 0.0),
                 ki.add_image(v, stamp, cam(v, w, h), (image, v, stamp), 0.0),
                 ki.add_mask(v, stamp, mask_setting(v, w, h), "mask", person, 0.0)):
        jobs += j
        problems += p
    return jobs, problems


def run(ki, stamps, n=2, person=True):
    """Frames of every view at ``stamps``; the (view, stamp, detect) of each job, in order."""
    out = []
    for s in stamps:
        for v in range(n):
            jobs, _ = frame(ki, v, s, person)
            out += [(j.view, j.stamp_ns, j.detect) for j in jobs]
    return out


def test_a_view_set_is_scheduled_once_complete_each_view_once():
    ki = intake()
    jobs, _ = frame(ki, 0, S)
    assert jobs == []                                # view 1 not yet: no decision
    jobs, _ = frame(ki, 1, S)
    assert [(j.view, j.stamp_ns, j.detect) for j in jobs] == [(0, S, True), (1, S, True)]
    assert jobs[0].image == ("img", 0, S) and jobs[0].mask == "mask"
    # dense 1, then every 2nd person frame: frames 0, 2, 4
    got = run(ki, [S + k * P for k in range(1, 5)])
    assert [d for v, s, d in got if v == 0] == [False, True, False, True]


def test_image_and_mask_pair_in_either_order():
    ki = intake(n=1)
    assert ki.add_mask(0, S, mask_setting(0), "m", True, 0.0) == ([], [])
    ki.add_info(0, S, info(0), "K", 0.0)
    jobs, _ = ki.add_image(0, S, cam(0), "i", 0.0)
    assert [(j.image, j.mask, j.detect) for j in jobs] == [("i", "m", True)]


def test_one_views_agreeing_pair_at_a_far_stamp_moves_no_schedule():
    """The fuzzer's image + camera_info of one stamp (7, or an hour off), with the segmentation node's mask of
    it, before and inside the stream: no frame set, so the schedule is that of the clean stream."""
    clean = run(intake(), [S + k * P for k in range(8)])
    ki = intake()
    stray = []
    for s in (7, S + HOUR):                                          # before the stream
        stray += frame(ki, 1, s, image="noise", w=320, h=240)[0]
    got = run(ki, [S + k * P for k in range(3)])
    for s in (7, S + 2 * P - HOUR, S + 2 * P + HOUR):                # inside it
        stray += frame(ki, 0, s, image="noise")[0]
    got += run(ki, [S + k * P for k in range(3, 8)])
    assert stray == [] and got == clean
    # and the view's camera, set by the first stray pair (320x240), is the real one again
    assert ki.gates[1].setting == cam(1)


def test_frames_without_a_person_are_skipped_and_not_counted():
    ki = intake(n=1, every_k=2, dense_frames=0)
    got = run(ki, [S], n=1, person=False) + run(ki, [S + P, S + 2 * P, S + 3 * P], n=1)
    assert got == [(0, S, False), (0, S + P, True), (0, S + 2 * P, False), (0, S + 3 * P, True)]


def test_masks_far_from_the_sets_or_of_another_camera_are_dropped():
    ki = intake(n=1)
    run(ki, [S], n=1)
    jobs, problems = ki.add_mask(0, S + HOUR, mask_setting(0), "m", True, 0.0)
    assert jobs == [] and problems[0][0] == "mask0" and "from the stream" in problems[0][1]
    jobs, problems = ki.add_mask(0, S + P + 3_000_007, Setting("fuzz_optical_frame", 160, 120), "m", True, 0.0)
    assert jobs == [] and "is not the view's camera's" in problems[0][1]
    jobs, problems = ki.add_mask(0, S + P + 3_000_008, mask_setting(0, 7, 3), "m", True, 0.0)
    assert jobs == [] and "7x3" in problems[0][1]
    assert run(ki, [S + P], n=1) == [(0, S + P, False)]             # the stream goes on (every 2nd after 1)


def test_an_old_pair_is_dropped_as_out_of_order():
    ki = intake(n=1)
    run(ki, [S, S + P], n=1)
    jobs, problems = frame(ki, 0, S - P)
    assert jobs == [] and any(k == "order0" for k, _ in problems)


def test_a_partial_set_after_the_wait_counts_only_its_views():
    ki = intake(n=3, max_wait_s=1.0, min_views=2, every_k=1, dense_frames=0)
    for v in (0, 1):
        assert frame(ki, v, S)[0] == []
    assert ki.poll(0.5) == ([], [])
    jobs, _ = ki.poll(1.5)
    assert [(j.view, j.detect) for j in jobs] == [(0, True), (1, True)]
    assert ki.schedules[2].person_frames == 0 and ki.schedules[0].person_frames == 1
