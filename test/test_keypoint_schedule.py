"""The keypoint schedule shared by the keypoint node and `isa-mocap track`: which frames of a view are detected on."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from isa_mocap_ros.vision.errors import VisionError
from isa_mocap_ros.vision.camera import look_at
from isa_mocap_ros.vision.keypoint_schedule import (AGREE_IOU, ARM_TRUNK_JOINTS, CROP, DENSE_FRAMES, KeypointSchedule,
                                                     body_axis_angle, crop_box, detect_in_mask, forearms_over_trunk,
                                                     person_pixels, segmentation_iou)


def _due(schedule, persons):
    return [i for i, p in enumerate(persons) if schedule.due(p)]


def test_dense_start_then_every_k_frames_with_a_person():
    # 3 empty frames, then a person: frames 3-6 (the dense start), then every 4th person frame (7, 11, 15)
    persons = [False] * 3 + [True] * 14
    assert _due(KeypointSchedule(4), persons) == [3, 4, 5, 6, 7, 11, 15]
    assert DENSE_FRAMES == 4
    # frames without a person are never due and do not count
    persons = [True, False, True, True, False, False, True, True, True]
    assert _due(KeypointSchedule(2, dense_frames=1), persons) == [0, 3, 7]


def test_every_1_is_every_person_frame_and_0_the_dense_start_only():
    persons = [True] * 10
    assert _due(KeypointSchedule(1, dense_frames=0), persons) == list(range(10))
    assert _due(KeypointSchedule(0, dense_frames=3), persons) == [0, 1, 2]


def test_two_schedules_fed_the_same_frames_agree():
    rng = np.random.default_rng(0)
    persons = list(rng.random(200) < 0.8)
    assert _due(KeypointSchedule(3), persons) == _due(KeypointSchedule(3), persons)


def test_wanted_frames_are_added_at_most_every_gap_and_leave_the_regular_ones():
    persons = [True] * 20
    wanted = [False] * 6 + [True] * 9 + [False] * 5
    regular = _due(KeypointSchedule(8, dense_frames=2), persons)
    s = KeypointSchedule(8, dense_frames=2, extra_gap=3)
    due = [i for i, (p, w) in enumerate(zip(persons, wanted)) if s.due(p, wanted=w)]
    assert regular == [0, 1, 8, 16]
    # wanted from 6: 6 (5 after the last, 1), then 8 is regular, 11, 14; nothing wanted after 14
    assert due == [0, 1, 6, 8, 11, 14, 16] and s.extra == 3
    # off (the default), a wanted frame changes nothing
    s = KeypointSchedule(8, dense_frames=2)
    assert [i for i, (p, w) in enumerate(zip(persons, wanted)) if s.due(p, wanted=w)] == regular and s.extra == 0
    # a frame without a person is never due
    assert not KeypointSchedule(8, extra_gap=1).due(False, wanted=True)


def _standing(hand_forward_m: float) -> np.ndarray:
    """:data:`ARM_TRUNK_JOINTS` of a person facing +x at the origin: the left arm down at the side, the right
    forearm held ``hand_forward_m`` in front of the belly."""
    P = {"left_shoulder": (0, 0.2, 1.45), "right_shoulder": (0, -0.2, 1.45), "right_hip": (0, -0.1, 0.95),
         "left_hip": (0, 0.1, 0.95), "left_elbow": (0, 0.3, 1.15), "left_wrist": (0, 0.32, 0.9),
         "left_hand": (0, 0.33, 0.82), "right_elbow": (0.05, -0.25, 1.15),
         "right_wrist": (hand_forward_m, -0.05, 1.1), "right_hand": (hand_forward_m + 0.05, 0.02, 1.1)}
    return np.array([P[n] for n in ARM_TRUNK_JOINTS], float)


def test_forearm_over_the_trunk_in_the_views_that_see_it_there():
    front = look_at((4, 0, 1.2), (0, 0, 1.1), width=320, height=240, fov_deg=50)
    side = look_at((0, 4, 1.2), (0, 0, 1.1), width=320, height=240, fov_deg=50)
    back = look_at((-4, 0.3, 1.2), (0, 0, 1.1), width=320, height=240, fov_deg=50)
    cams = [front, side, back]
    assert forearms_over_trunk(cams, _standing(0.25)).tolist() == [True, False, True]
    hanging = _standing(0.25)
    hanging[list(ARM_TRUNK_JOINTS).index("right_wrist")] = (0, -0.32, 0.9)
    hanging[list(ARM_TRUNK_JOINTS).index("right_hand")] = (0, -0.33, 0.82)
    hanging[list(ARM_TRUNK_JOINTS).index("right_elbow")] = (0, -0.3, 1.15)
    assert not forearms_over_trunk(cams, hanging).any()
    with pytest.raises(VisionError, match="points: expected shape"):
        forearms_over_trunk(cams, np.zeros((4, 3)))


@pytest.mark.parametrize("kw", [dict(every_k=-1), dict(every_k=1.5), dict(every_k=True),
                                dict(every_k=2, dense_frames=-1), dict(every_k=2, extra_gap=-1)])
def test_bad_settings_raise(kw):
    every_k = kw.pop("every_k")
    with pytest.raises(VisionError, match="expected an integer"):
        KeypointSchedule(every_k, **kw)


def test_detect_in_mask_refuses_a_mask_of_another_size_and_finds_nobody_in_an_empty_one():
    img = np.zeros((60, 80, 3), np.uint8)
    with pytest.raises(VisionError, match="mask: expected the image's size 80x60"):
        detect_in_mask(None, img, np.zeros((10, 10), np.uint8))
    assert detect_in_mask(None, img, np.zeros((60, 80), np.uint8)) is None     # no crop, no model call


def test_person_crop_leaves_out_small_blobs_and_keeps_large_parts():
    m = np.zeros((200, 160), np.uint8)
    m[40:160, 70:90] = 255            # the person: 2400 px
    m[180:190, 0:20] = 255            # a reflection far off: 200 px (< 20 % of the person)
    m[20:40, 120:150] = 255           # an arm cut off by a mask hole: 600 px (>= 20 %), kept
    whole = crop_box(m, crop="mask", box_scale=1.0)
    person = crop_box(m, crop="person", box_scale=1.0)
    np.testing.assert_allclose(whole, [75.0, 105.0, 170.0, 0.0])          # bounding box 0..150 x 20..190
    np.testing.assert_allclose(person, [110.0, 90.0, 140.0, 0.0])         # 70..150 x 20..160
    assert np.array_equal(person_pixels(m)[180:190, 0:20], np.zeros((10, 20), np.uint8))
    assert crop_box(np.zeros_like(m), crop="person") is None


def test_person_crop_is_the_mask_crop_when_the_mask_is_one_component():
    # the renders' masks (bags/demo, the fixture, the mesh bags) are one blob: their keypoints, and so their tracks,
    # are those of the crop around the whole mask, bit for bit
    m = np.zeros((240, 320), np.uint8)
    cv2.ellipse(m, (150, 120), (30, 90), 10, 0, 360, 255, -1)
    cv2.line(m, (150, 60), (230, 30), 255, 5)
    assert np.array_equal(crop_box(m, crop="person"), crop_box(m, crop="mask"))
    assert CROP == "mask"


def test_turned_crop_follows_a_leaning_body_and_stays_upright_for_a_wide_one():
    lean = np.zeros((200, 200), np.uint8)
    cv2.line(lean, (60, 180), (120, 40), 255, 12)       # leaning to the image's right, 23.2° from up
    box = crop_box(lean, crop="person_turned")
    assert box[3] == pytest.approx(np.arctan2(60, 140), abs=np.radians(1.0))
    # the turned square holds the body: its side is the body's length and width (x 1.25)
    assert box[2] == pytest.approx(1.25 * np.hypot(60, 140) + 1.25 * 12, rel=0.1)
    flat = np.zeros((200, 200), np.uint8)
    flat[90:110, 20:180] = 255                            # arms spread: the long axis is horizontal
    assert crop_box(flat, crop="person_turned")[3] == 0.0
    assert body_axis_angle(np.zeros((10, 10), np.uint8)) == 0.0


def test_crop_names_are_checked():
    with pytest.raises(VisionError, match="crop: expected one of mask, person, person_turned, received 'x'"):
        crop_box(np.ones((10, 10), np.uint8), crop="x")


def test_segmentation_iou():
    a = np.zeros((10, 10), np.float32)
    b = np.zeros((10, 10), np.uint8)
    assert segmentation_iou(a, b) == 0.0
    a[0:4, 0:5] = 0.9                  # 20 px
    b[2:6, 0:5] = 255                  # 20 px, 10 shared
    assert segmentation_iou(a, b) == pytest.approx(10 / 30)


@pytest.fixture(scope="module")
def rendered_person():
    from isa_mocap_ros.synth import SceneRenderer, make_clip
    from isa_mocap_ros.vision import default_rig

    rig = default_rig(n_views=1, width=480, height=360)
    clip = make_clip("walk", dof=39, fps=30.0, duration_s=0.5, seed=3)
    images, masks = SceneRenderer(clip.model, rig, seed=3).render(clip.poses[6], 6)
    return images[0], (np.asarray(masks[0]) > 0).astype(np.uint8) * 255


def _same(a, b):
    return a is not None and b is not None and np.array_equal(a.uv, b.uv) and a.score == b.score \
        and np.array_equal(a.roi, b.roi)


def test_checked_person_crop_is_taken_where_the_model_sees_the_person_and_not_where_it_does_not(
        landmark_model, rendered_person):
    from isa_mocap_ros.vision.landmarks import LANDMARK_NAMES, PoseLandmarker, box_from_points, upright_angle

    det = PoseLandmarker(landmark_model)
    img, person = rendered_person
    # one component: one detection, the mask crop's
    assert _same(detect_in_mask(det, img, person, crop="person_checked"), detect_in_mask(det, img, person))
    # a small blob far off (a reflection): the person square differs, the model finds the person there and its
    # segmentation agrees with the person component, so the person square's landmarks are accepted and refined by
    # a second detection in the square around them, turned by their hips and shoulders
    m = person.copy()
    m[340:350, 0:12] = 255
    assert not np.array_equal(crop_box(m, crop="person"), crop_box(m, crop="mask"))
    refined = detect_in_mask(det, img, m, crop="person_checked")
    first = detect_in_mask(det, img, m, crop="person")
    prob, _ = det.person_probability(img, crop_box(m, crop="person"))
    assert first.score >= 0.5 and segmentation_iou(prob, person_pixels(m)) >= AGREE_IOU
    L = LANDMARK_NAMES.index
    turn = upright_angle(0.5 * (first.uv[L("left_hip")] + first.uv[L("right_hip")]),
                         0.5 * (first.uv[L("left_shoulder")] + first.uv[L("right_shoulder")]))
    assert _same(refined, det.detect(img, box_from_points(first.uv, angle_rad=turn)))
    # a large grey block with nobody in it, in the image and the mask, beside the person: the person components are
    # the block, the model finds nobody there (its segmentation alone would take the block for a person), and the
    # mask square is detected on as well
    img2, m2 = img.copy(), person.copy()
    img2[10:350, 360:475] = 128
    m2[10:350, 360:475] = 255
    assert person_pixels(m2)[200, 400] == 1 and person_pixels(m2)[200, 240] == 0
    asked = []

    class Spy:
        has_segmentation = True

        def detect(self, image, roi, bgr=False):
            asked.append(("detect", tuple(roi)))
            return det.detect(image, roi, bgr=bgr)

        def person_probability(self, image, roi, bgr=False):
            asked.append(("person_probability", tuple(roi)))
            return det.person_probability(image, roi, bgr=bgr)

    lm = detect_in_mask(Spy(), img2, m2, crop="person_checked", min_score=0.5)
    person_box, mask_box = tuple(crop_box(m2, crop="person")), tuple(crop_box(m2, crop="mask"))
    assert asked == [("person_probability", person_box), ("detect", mask_box)]
    assert det.detect(img2, np.array(person_box)).score < 0.5
    assert lm is None or np.array_equal(lm.roi, mask_box)
    prob, _ = det.person_probability(img2, np.array(person_box))
    assert segmentation_iou(prob, person_pixels(m2)) >= AGREE_IOU          # why the score is asked too
    # the reflection case asks the person square, then the square around its landmarks
    asked.clear()
    detect_in_mask(Spy(), img, m, crop="person_checked")
    assert [a[0] for a in asked] == ["person_probability", "detect"] and asked[0][1] == tuple(crop_box(m, crop="person"))
    assert asked[1][1] == tuple(refined.roi)
    with pytest.raises(VisionError, match="crop: expected one of mask, person, person_turned, person_checked"):
        detect_in_mask(det, img, m, crop="x")
