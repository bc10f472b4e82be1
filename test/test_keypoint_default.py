"""The main job's keypoint default (cli/keypoint_options.py, decision 014): on when the landmark model is installed,
off with a note when it is not; an explicit choice wins either way."""
import argparse

from isa_mocap_ros.cli.keypoint_options import DEFAULT_KEYPOINT_WEIGHT, default_keypoint_weight
from isa_mocap_ros.cli.main import build_parser
from isa_mocap_ros.cli.run import _keypoints_on


def test_without_the_model_the_default_is_off_and_says_how_to_get_it(tmp_path, monkeypatch):
    monkeypatch.setenv("ISA_MOCAP_MODEL_DIR", str(tmp_path))
    weight, note = default_keypoint_weight()
    assert weight == 0.0 and "keypoints off (the default is on)" in note and "make models" in note
    assert not _keypoints_on(argparse.Namespace(keypoints=None))
    assert _keypoints_on(argparse.Namespace(keypoints=True))         # asked for: the keypoint node then says why not


def test_with_the_model_the_default_is_on(tmp_path, monkeypatch):
    from isa_mocap_ros.vision import landmark_model

    monkeypatch.setattr(landmark_model, "landmark_model_path", lambda **kw: tmp_path / "model.tflite")
    assert default_keypoint_weight() == (DEFAULT_KEYPOINT_WEIGHT, None) and DEFAULT_KEYPOINT_WEIGHT == 1.0
    assert _keypoints_on(argparse.Namespace(keypoints=None))
    assert not _keypoints_on(argparse.Namespace(keypoints=False))


def test_the_commands_leave_the_choice_to_the_default_unless_told():
    p = build_parser()
    assert p.parse_args(["track", "B", "--out", "o"]).keypoint_weight is None
    assert p.parse_args(["track", "B", "--out", "o", "--keypoint-weight", "0"]).keypoint_weight == 0.0
    assert p.parse_args(["run"]).keypoints is None
    assert p.parse_args(["run", "--no-keypoints"]).keypoints is False
    assert p.parse_args(["bench", "mesh"]).keypoint_weight is None
