"""The keypoint schedule shared by the keypoint node and `isa-mocap track`: which frames of a view are detected on."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.vision.errors import VisionError
from isa_mocap_ros.vision.keypoint_schedule import DENSE_FRAMES, KeypointSchedule, detect_in_mask


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


@pytest.mark.parametrize("kw", [dict(every_k=-1), dict(every_k=1.5), dict(every_k=True), dict(every_k=2, dense_frames=-1)])
def test_bad_settings_raise(kw):
    every_k = kw.pop("every_k")
    with pytest.raises(VisionError, match="expected an integer"):
        KeypointSchedule(every_k, **kw)


def test_detect_in_mask_refuses_a_mask_of_another_size_and_finds_nobody_in_an_empty_one():
    img = np.zeros((60, 80, 3), np.uint8)
    with pytest.raises(VisionError, match="mask: expected the image's size 80x60"):
        detect_in_mask(None, img, np.zeros((10, 10), np.uint8))
    assert detect_in_mask(None, img, np.zeros((60, 80), np.uint8)) is None     # no crop, no model call
