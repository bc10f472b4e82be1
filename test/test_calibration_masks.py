"""The shape calibration's masks (tracking/calibration_masks.py): foreground the neighbouring frames confirm."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.tracking.calibration_masks import neighbour_keys, persistent_masks
from isa_mocap_ros.tracking.shape_calibration import ShapeCalibrationConfig, ShapeCalibrationError


def test_neighbours_are_the_frames_before_and_after_or_the_two_nearest_at_the_window_ends():
    keys = [40, 10, 30, 20]                                   # any order: the window sorted by key
    assert neighbour_keys(keys, 20) == (10, 30)
    assert neighbour_keys(keys, 30) == (20, 40)
    assert neighbour_keys(keys, 10) == (20, 30)               # the first frame: the two after it
    assert neighbour_keys(keys, 40) == (20, 30)               # the last: the two before it
    assert neighbour_keys([1, 2], 1) is None                  # fewer than three frames: no evidence


def _frames(n=5, step_px=2, seed=0):
    """A 12x30 px 'person' moving step_px to the right per frame, and in every frame one 10x10 rectangle drawn
    anew at a random place (ISA §13.4.2's occluders are drawn independently per frame)."""
    rng = np.random.default_rng(seed)
    out, person = {}, {}
    for k in range(n):
        m = np.zeros((60, 80), np.uint8)
        m[15:45, 20 + step_px * k:32 + step_px * k] = 255
        person[k] = m.copy()
        y, x = rng.integers(0, 50), rng.integers(45, 70)
        m[y:y + 10, x:x + 10] = 255
        out[k] = [m, None]                                    # a second, missing view
    return out, person


def test_persistent_masks_drop_what_one_frame_alone_shows_and_keep_a_person_moving_less_than_the_radius():
    masks, person = _frames()
    got, note = persistent_masks(masks, [1, 2, 3], 3)
    for (k, ms) in zip([1, 2, 3], got):
        assert ms[1] is None                                  # a missing view stays missing
        m = ms[0]
        assert m.dtype == np.uint8 and set(np.unique(m)) <= {0, 255}
        # the person (2 px per frame, radius 3) is whole; the frame's own rectangle is gone (another frame's
        # rectangle in the same place would be kept: these seeds place them apart)
        assert np.array_equal(m, person[k]), k
    assert "removed over 3 frames" in note and "within 3 px" in note
    # at the window's end the neighbours are the two next frames, 2 and 4 px away: the first column goes
    first = persistent_masks(masks, [0], 3)[0][0][0]
    assert np.array_equal(first[:, 21:], person[0][:, 21:]) and not first[:, 20].any() and person[0][:, 20].any()
    # a person moving faster than the radius loses its leading and trailing edges, not more
    fast, person = _frames(step_px=5)
    m = persistent_masks(fast, [2], 3)[0][0][0]
    lost = np.count_nonzero(person[2]) - np.count_nonzero(m & person[2])
    assert 0 < lost <= 2 * 2 * 30                             # (5 - 3) px columns on both sides, 30 rows


def test_persistent_masks_bad_input_and_the_config_option():
    masks, _ = _frames()
    with pytest.raises(ValueError, match="radius_px: expected an integer >= 1, received 0"):
        persistent_masks(masks, [0], 0)
    assert ShapeCalibrationConfig().persist_px == 0           # off unless asked (docs/shape_calibration.md)
    with pytest.raises(ShapeCalibrationError, match="persist_px: expected an integer >= 0, received -1"):
        ShapeCalibrationConfig(persist_px=-1)
    with pytest.raises(ShapeCalibrationError, match="persist_px: expected an integer >= 0, received 1.5"):
        ShapeCalibrationConfig(persist_px=1.5)


def test_the_option_reaches_the_calibration_and_its_notes():
    import argparse

    from isa_mocap_ros.body import capsule_endpoints, make_model
    from isa_mocap_ros.body.motion import generate_motion
    from isa_mocap_ros.cli.shape_options import calibration_config
    from isa_mocap_ros.tracking.shape_calibration import calibrate_shape
    from isa_mocap_ros.vision import default_rig, render_mask

    assert calibration_config(argparse.Namespace(calib_persist_px=4), 0).persist_px == 4
    assert calibration_config(argparse.Namespace(), 0).persist_px == 0
    model = make_model(39)
    rig = list(default_rig())
    X = generate_motion("walk", model, duration_s=0.2, fps=30.0, rng=np.random.default_rng(0))[:3]
    frames = [(k, [render_mask(c, capsule_endpoints(model, x[None, :])[0], model.capsule_radii) for c in rig])
              for k, x in enumerate(X)]
    cfg = ShapeCalibrationConfig(window_frames=3, n_frames=2, rounds=1, pose_steps=1, shape_evals=40, seed=4,
                                 restarts=1, persist_px=3)
    res = calibrate_shape(39, rig, frames, config=cfg)
    note = next(n for n in res.notes if "of the neighbouring frames' kept" in n)
    assert "within 3 px" in note and "over 2 frames" in note
    # both calibration frames are the window's ends (neighbours 1 and 2 frames away): the fast limbs' edges go
    assert 0.0 < float(note.split("(")[1].split(" %")[0]) < 50.0
    assert not any("neighbouring frames" in n for n in calibrate_shape(39, rig, frames, config=ShapeCalibrationConfig(
        window_frames=3, n_frames=2, rounds=1, pose_steps=1, shape_evals=40, seed=4, restarts=1)).notes)
