"""The real recording (Pose2Sim demo) tracked end to end, on a few frames: offline (`isa-mocap track`,
with overlays and the model-guided mask refinement) and through the node network (`isa-mocap run
--lockstep`), scored against Pose2Sim's keypoints mapped to our joints by the bag's reference topic.

Reads the recording from ../shared (skipped when absent); the full 100-frame figures come from the
commands in docs/real_cameras.md, not from here."""
from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from conftest import SHARED
from isa_mocap_ros.cli.main import main as cli

DEMO = SHARED / "data" / "real" / "pose2sim_demo"
TOML = DEMO / "calibration" / "Calib_scene_checkerboard.toml"
CLI = [sys.executable, "-m", "isa_mocap_ros.cli.main"]
QUICK = ["--shape", "default", "--evals", "200", "--seed", "1"]
FRAMES = 3


@pytest.fixture(scope="module")
def demo_bag(tmp_path_factory):
    if not TOML.is_file():
        pytest.skip(f"Pose2Sim demo not found at {DEMO} (set ISA_MOCAP_SHARED to the shared/ folder)")
    out = tmp_path_factory.mktemp("real") / "bag"
    args = ["import", str(out)] + [str(DEMO / "balancing" / f"cam0{i}.mp4") for i in range(1, 5)] + [
        "--calibration", str(TOML), "--background", str(DEMO / "calibration" / "extrinsics"),
        "--width", "160", "--frames", str(FRAMES), "--background-frames", "3",
        "--reference", str(DEMO / "reference" / "balancing_pose2sim.trc"), "--no-progress"]
    assert cli(args) == 0
    return out


def test_reference_topic_names_the_markers_without_a_model_description():
    """No recording needed: the reference YAML's names, mapped; a bad YAML is a note, not an error."""
    import yaml

    from isa_mocap_ros.sequence import SequenceBuilder

    def build(text):
        b = SequenceBuilder()
        b.add_camera_info(0, K=np.diag([100.0, 100.0, 1.0]), D=np.zeros(5), width=8, height=8)
        b.add_extrinsics(0, np.eye(3), np.zeros(3))
        b.add_image(0, 5, np.zeros((8, 8, 3), np.uint8))
        b.add_truth_markers(5, np.zeros((3, 3)))
        b.set_reference_yaml(text)
        return b.build()

    seq = build(yaml.safe_dump({"marker_names": ["LKnee", "Nose", "RWrist"]}))
    assert seq.truth_marker_names == ("left_knee", "Nose", "right_wrist") and seq.has_marker_truth
    seq = build("marker_names: [a, b")
    assert not seq.has_marker_truth and any("reference: not YAML" in n for n in seq.notes), seq.notes
    seq = build(yaml.safe_dump({"marker_names": "LKnee"}))
    assert any("expected a list of strings 'marker_names'" in n for n in seq.notes), seq.notes


def test_reference_names_are_mapped_to_our_joints(demo_bag):
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.eval.trc import POSE2SIM_TO_JOINTS

    seq = read_sequence(demo_bag, want_images=True, want_masks=False)
    names = seq.truth_marker_names
    assert len(names) == 21 and names[:3] == ("right_hip", "right_knee", "right_ankle")
    assert "Nose" in names and "RBigToe" in names          # no joint of ours: kept, not scored
    assert sum(n in POSE2SIM_TO_JOINTS.values() for n in names) == 14
    assert sum(f.truth_markers is not None for f in seq.frames) == FRAMES


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_track_scores_against_the_peer_and_draws_overlays(demo_bag, tmp_path, capsys):
    out = tmp_path / "track"
    assert cli(["track", str(demo_bag), "--out", str(out), "--no-progress", "--overlays", str(out / "ov"),
                "--refine-masks", *QUICK]) == 0
    printed = capsys.readouterr().out
    assert "each joint's mean offset removed" in printed and "right_knee" in printed, printed
    s = json.loads((out / "summary.json").read_text())
    assert s["scored_by"] == "markers" and s["frames"] == FRAMES == s["frames_estimated"]
    assert len(s["offset_removed_per_marker_mm"]) == 14
    # with the offsets removed the error cannot be larger than raw (the mean offset minimises it per joint)
    assert s["offset_removed_mpjpe_mm"] <= s["mpjpe_mm"] + 1e-9
    assert s["refine_masks"] and 0.0 <= s["mask_reference_coverage"] <= 1.0
    strip = cv2.imread(s["overlays"]["strip"])
    assert strip.shape == (FRAMES * 282, 4 * 160, 3)
    cap = cv2.VideoCapture(s["overlays"]["video"])
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    cap.release()
    assert n == FRAMES


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_run_tracks_the_imported_recording_through_the_network(demo_bag, tmp_path, rosenv):
    out = tmp_path / "run"
    res = subprocess.run(CLI + ["run", str(demo_bag), "--lockstep", "--out", str(out), "--quiet", *QUICK],
                         env=rosenv, capture_output=True, text=True, timeout=350)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert "joint offsets removed" in res.stdout and "left_knee" in res.stdout, res.stdout
    s = json.loads((out / "summary.json").read_text())
    assert s["frames_estimated"] == FRAMES and s["scored_by"] == "markers", s
    assert s["frames_processed"] == s["frame_sets_played"]          # lockstep: none dropped
    assert np.isfinite(s["offset_removed_mpjpe_mm"])
    # lockstep equals the offline tracker with the same settings, frame by frame (a 60 fps recording: the
    # prediction node and the estimator work with the bag's frame period, not the parameter file's 1/30 s)
    assert cli(["track", str(demo_bag), "--out", str(tmp_path / "track"), "--no-progress", *QUICK]) == 0
    t = json.loads((tmp_path / "track" / "summary.json").read_text())
    assert s["frame_errors_mm"] == t["frame_errors_mm"], (s["frame_errors_mm"], t["frame_errors_mm"])
    log = (out / "nodes.log").read_text()
    assert "no prediction" not in log, log[-3000:]


def test_run_gives_the_nodes_the_bags_frame_period(demo_bag):
    import argparse

    from isa_mocap_ros.cli.run import _inspect, _network

    views, learn, period_s = _inspect(demo_bag)
    assert (views, learn) == (4, 3) and period_s == pytest.approx(1 / 60, abs=1e-9)
    ns = argparse.Namespace(lockstep=True, optimizer=None, evals=None, model=None, seed=None, helper_nice=0)
    specs = {s.name: dict(s.params) for s in _network(ns, "p.yaml", demo_bag, views, learn, frame_period_s=period_s)}
    assert float(specs["estimator"]["frame_period_s"]) == float(specs["prediction"]["frame_period_s"]) == period_s
