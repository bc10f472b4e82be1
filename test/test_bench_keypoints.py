"""bench keypoints: the minimal Pose2Sim readers on the real files, and a smoke run of the detector
against the projected peer keypoints (skips without ../shared data or the model)."""
from __future__ import annotations

import argparse

import cv2
import numpy as np
import pytest

from conftest import SHARED
from isa_mocap_ros.bench import BENCHES
from isa_mocap_ros.bench import keypoints as bk

REAL = SHARED / "data" / "real" / "pose2sim_demo"


@pytest.fixture(scope="module")
def real():
    if not (REAL / "balancing").is_dir():
        pytest.skip(f"real recording not found at {REAL} (set ISA_MOCAP_SHARED to the shared/ folder)")
    return REAL


def test_registered():
    assert "keypoints" in BENCHES


def test_readers_project_the_peer_keypoints_into_every_view(real):
    cams = bk.read_pose2sim_toml(real / "calibration" / "Calib_scene_checkerboard.toml")
    names, P = bk.read_trc(real / "reference" / "balancing_pose2sim.trc")
    assert [c["name"] for c in cams] == [f"int_cam0{i}_img" for i in range(1, 5)]
    assert P.shape == (100, 21, 3) and names[:2] == ["RHip", "RKnee"]
    W = P[0][:, [2, 0, 1]]
    for i, cam in enumerate(cams):
        cap = cv2.VideoCapture(str(real / "balancing" / f"cam0{i + 1}.mp4"))
        w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        cap.release()
        uv = cv2.projectPoints(W, cam["rvec"], cam["tvec"], bk._video_K(cam, w, h), cam["dist"])[0].reshape(-1, 2)
        assert np.all((uv > 0) & (uv < [w, h])), (i, uv)
        assert uv[names.index("Head"), 1] < uv[names.index("RAnkle"), 1]       # head above the feet


def test_detector_on_the_real_recording_smoke(real, landmark_model):
    from isa_mocap_ros.vision.landmarks import PoseLandmarker
    det = PoseLandmarker(landmark_model)
    res = bk.bench_real(det, real, 50, aligned=True)           # frames 0 and 50 of each view
    assert set(res) == {"cam01", "cam02", "cam03", "cam04"}
    for cam, r in res.items():
        assert r["views"] == 2 and r["median_score"] > 0.5
        assert r["median_px"] < 60, (cam, r["median_px"])     # measured 18-29 px over 20 frames (docs/keypoints.md)


def test_bad_arguments_exit_2(capsys):
    ns = argparse.Namespace(kinds="real,nope", step=5, json=False)
    assert bk.run(ns) == 2 and "nope" in capsys.readouterr().err
