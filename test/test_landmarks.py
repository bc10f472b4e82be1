"""BlazePose landmark detector core: crop geometry, detection on rendered people (upright and turned),
the model fetch's checks, bad input named."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from isa_mocap_ros.body import joint_positions
from isa_mocap_ros.synth import SceneRenderer, make_clip
from isa_mocap_ros.vision import VisionError, default_rig
from isa_mocap_ros.vision import landmark_model as lmm
from isa_mocap_ros.vision.landmarks import (LANDMARK_NAMES, PoseLandmarker, _crop_transform, box_from_mask,
                                            box_from_points, upright_angle)

NAMES = ["left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_hip", "right_hip", "left_knee",
         "right_knee", "left_ankle", "right_ankle"]


@pytest.fixture(scope="module")
def detector(landmark_model):
    return PoseLandmarker(landmark_model)


@pytest.fixture(scope="module")
def person():
    rig = default_rig(n_views=1, width=480, height=360)
    clip = make_clip("walk", dof=39, fps=30.0, duration_s=0.5, seed=3)
    images, masks = SceneRenderer(clip.model, rig, seed=3).render(clip.poses[6], 6)
    J = joint_positions(clip.model, clip.poses[6])[0]
    ref = rig.cameras[0].project(J[[clip.model.joint_names.index(n) for n in NAMES]])
    return images[0], masks[0], ref


def test_regions_and_crop_transform():
    r = box_from_points([[100.0, 50.0], [140.0, 250.0]])
    np.testing.assert_allclose(r, [120.0, 150.0, 250.0, 0.0])
    assert upright_angle([0, 10], [0, 0]) == 0.0
    assert upright_angle([0, 0], [10, 0]) == pytest.approx(np.pi / 2)      # shoulders to the right of hips
    # the turned region maps its centre to the crop centre and the body's up direction to crop up
    roi = np.array([200.0, 100.0, 128.0, np.pi / 2])
    M = _crop_transform(roi)
    np.testing.assert_allclose(M @ [200.0, 100.0, 1.0], [128.0, 128.0], atol=1e-9)
    np.testing.assert_allclose(M @ [210.0, 100.0, 1.0] - M @ [200.0, 100.0, 1.0], [0.0, -20.0], atol=1e-9)
    mask = np.zeros((60, 80), np.uint8)
    assert box_from_mask(mask) is None
    mask[10:30, 20:25] = 255
    np.testing.assert_allclose(box_from_mask(mask, scale=1.0), [22.5, 20.0, 20.0, 0.0])
    with pytest.raises(VisionError, match="uv"):
        box_from_points(np.zeros((0, 2)))


def test_detects_a_rendered_person_upright_and_turned(detector, person):
    img, mask, ref = person
    li = [LANDMARK_NAMES.index(n) for n in NAMES]
    lm = detector.detect(img, box_from_mask(mask))
    assert lm.score > 0.9 and lm.uv.shape == (33, 2)
    err = np.linalg.norm(lm.uv[li] - ref, axis=1)
    assert np.median(err) < 12.0, err
    again = detector.detect(img, box_from_mask(mask))
    np.testing.assert_array_equal(again.uv, lm.uv)                          # deterministic
    # the image turned by 90 degrees: an aligned region finds the same points, turned
    rot = cv2.rotate(img, cv2.ROTATE_90_CLOCKWISE)
    h = img.shape[0]
    ref_r = np.column_stack([h - 1 - ref[:, 1], ref[:, 0]])                 # (u, v) -> (h-1-v, u)
    hips = ref_r[[NAMES.index("left_hip"), NAMES.index("right_hip")]].mean(axis=0)
    sh = ref_r[[NAMES.index("left_shoulder"), NAMES.index("right_shoulder")]].mean(axis=0)
    roi = box_from_points(ref_r, scale=1.5, angle_rad=upright_angle(hips, sh))
    assert abs(abs(roi[3]) - np.pi / 2) < 0.3
    lm_r = detector.detect(rot, roi)
    err_r = np.linalg.norm(lm_r.uv[li] - ref_r, axis=1)
    assert np.median(err_r) < 12.0, err_r
    # a blank image: nobody there
    assert detector.detect(np.zeros_like(img), [240.0, 180.0, 300.0, 0.0]).score < 0.1


def test_bad_input_is_named(detector):
    with pytest.raises(VisionError, match="image"):
        detector.detect(np.zeros((10, 10), np.uint8), [5.0, 5.0, 10.0, 0.0])
    with pytest.raises(VisionError, match="roi"):
        detector.detect(np.zeros((10, 10, 3), np.uint8), [5.0, 5.0, 0.0, 0.0])


def test_missing_or_altered_model_is_reported(tmp_path, monkeypatch):
    monkeypatch.setenv("ISA_MOCAP_MODEL_DIR", str(tmp_path))
    with pytest.raises(lmm.ModelUnavailable, match="make models"):
        lmm.landmark_model_path()
    (tmp_path / lmm.MODEL_FILE).write_bytes(b"not a model")
    with pytest.raises(lmm.ModelUnavailable, match="SHA-256"):
        lmm.landmark_model_path()


def test_fetch_keeps_a_present_model_and_reports_a_failed_download(tmp_path, monkeypatch):
    """Idempotent: a file with the right digest is kept without calling pip; a failed pip download is
    a ModelUnavailable naming the requirement (no network is touched: pip is replaced)."""
    calls = []

    def fake_run(cmd, **kw):
        calls.append(cmd)
        import subprocess
        return subprocess.CompletedProcess(cmd, 1, stdout="", stderr="ERROR: No matching distribution found")

    monkeypatch.setattr(lmm.subprocess, "run", fake_run)
    monkeypatch.setenv("ISA_MOCAP_MODEL_DIR", str(tmp_path))
    with pytest.raises(lmm.ModelUnavailable, match="mediapipe==0.10.21.*No matching distribution"):
        lmm.fetch_landmark_model()
    assert len(calls) == 1 and "--no-deps" in calls[0] and "download" in calls[0]
    monkeypatch.delenv("ISA_MOCAP_MODEL_DIR")
    try:
        real = lmm.landmark_model_path()
    except lmm.ModelUnavailable:
        pytest.skip("landmark model not available (make models)")
    monkeypatch.setenv("ISA_MOCAP_MODEL_DIR", str(tmp_path))
    (tmp_path / lmm.MODEL_FILE).write_bytes(real.read_bytes())
    assert lmm.fetch_landmark_model() == tmp_path / lmm.MODEL_FILE and len(calls) == 1
