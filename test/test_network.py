"""The node network end to end: `isa-mocap run` on the fixture bag through separate node processes.

Deterministic lockstep replay: two runs give identical joint states, and they equal the offline
tracker (`isa-mocap track`) on the same bag with the same seed, optimizer and budget.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import msg_adapters as ma
from isa_mocap_ros.bag import BagReader
from conftest import joint_states_by_stamp

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.timeout(600)]
REPO = Path(__file__).resolve().parents[1]
FIXTURE = REPO / "bags" / "fixture"
CLI = [sys.executable, "-m", "isa_mocap_ros.cli.main"]
SETTINGS = ["--optimizer", "isa", "--evals", "300", "--seed", "3"]




def _run(out: Path, rosenv: dict, *extra: str) -> dict:
    res = subprocess.run(CLI + ["run", str(FIXTURE), "--lockstep", "--out", str(out), "--quiet", "--shape", "default",
                                *SETTINGS, *extra],
                         env=rosenv, capture_output=True, text=True, timeout=400)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def runs(tmp_path_factory, fixture_track):
    from conftest import FIXTURE_TRACK_SETTINGS, next_domain
    from isa_mocap_ros.rosenv import ros_env
    base = tmp_path_factory.mktemp("network")
    summaries = []
    for k in range(2):
        env = ros_env(next_domain())
        summaries.append(_run(base / f"run{k}", env))
    # segmentation, prediction and estimator in one process on one executor (isa_mocap_ros.cli.compose)
    summaries.append(_run(base / "single", ros_env(next_domain()), "--single-process"))
    # the offline tracker with the same settings and its default keypoint weight (shared with the other network tests)
    assert FIXTURE_TRACK_SETTINGS == (*SETTINGS, "--shape", "default")
    (base / "track").symlink_to(fixture_track(None))
    return base, summaries


def test_run_processes_every_frame_set_and_writes_the_summary(runs):
    base, (s0, *_) = runs
    for key in ("frames", "knee_rmse_deg", "mpjpe_mm", "max_frame_error_mm", "fps", "latency_ms_p50",
                "latency_ms_p95", "dropped_frames", "optimizer", "evals_per_frame", "model_dof"):
        assert key in s0, key
    with BagReader(FIXTURE) as r:
        n_sets = r.topics["/mocap/cam0/image_raw"].message_count
        n_truth = r.topics["/mocap/ground_truth/joint_states"].message_count
    assert s0["frames_processed"] == n_sets          # lockstep: every frame set, none dropped
    assert s0["dropped_frames"] == 0
    assert s0["dropped_while_initializing"] == 0      # lockstep: the next set waits for the first estimate
    assert s0["frames"] == n_truth                     # an estimate for every frame with a person
    assert s0["optimizer"] == "isa" and s0["evals_per_frame"] == 300 and s0["model_dof"] == 39
    assert s0["tracker_threads"] == 1          # reported by the estimator (pipeline.yaml: 1)
    assert 0 < s0["tracker_ms_p50"] <= s0["tracker_ms_p95"]   # Tracker.step per tracked set, from /diagnostics
    assert s0["init_ms"] > 0                   # the automatic initialization's set, from /diagnostics
    assert np.isfinite(s0["mpjpe_mm"]) and (base / "run0" / "knees_and_error.png").stat().st_size > 1000
    assert s0["ground_truth"] is True
    # the empty masks of the background-learning frames, the initialization, the heading check: expected
    # events (INFO), not bad inputs
    assert s0["bad_inputs"] == 0, s0
    log = (base / "run0" / "nodes.log").read_text()
    assert "initialized automatically" in log and "[ERROR]" not in log
    # a clean shutdown prints no error (the recorder logged after the context was shut down)
    assert "Failed to publish log message" not in log and "Traceback" not in log
    assert list((base / "run0" / "overlays").glob("*.png"))


def test_two_lockstep_runs_give_identical_joint_states(runs):
    base, _ = runs
    a, b = joint_states_by_stamp(base / "run0" / "estimates"), joint_states_by_stamp(base / "run1" / "estimates")
    assert a.keys() == b.keys() and len(a) > 0
    for s in a:
        assert np.array_equal(a[s], b[s]), s


def test_single_process_run_equals_the_multi_process_run(runs):
    base, (s0, _, single) = runs
    log = (base / "single" / "nodes.log").read_text()
    for name in ("segmentation", "prediction", "estimator"):     # three nodes, one process
        assert f"[compose] {name} in-process" in log
    assert log.count("[launch] started") == 2                     # that process and the recorder
    assert single["frames_processed"] == s0["frames_processed"] and single["dropped_frames"] == 0
    a, b = joint_states_by_stamp(base / "run0" / "estimates"), joint_states_by_stamp(base / "single" / "estimates")
    assert a.keys() == b.keys() and len(a) > 0
    for s in a:
        assert np.array_equal(a[s], b[s]), (s, np.abs(a[s] - b[s]).max())


def test_network_equals_the_offline_tracker(runs):
    base, _ = runs
    node, offline = joint_states_by_stamp(base / "run0" / "estimates"), joint_states_by_stamp(base / "track" / "estimates")
    assert node.keys() == offline.keys()
    for s in node:
        assert np.array_equal(node[s], offline[s]), (s, np.abs(node[s] - offline[s]).max())


def test_rep155_view_and_markers_are_published(runs):
    base, _ = runs
    with BagReader(base / "run0" / "estimates") as r:
        topics = r.topics
        assert topics["/humans/bodies/mocap/joint_states"].message_count == topics["/mocap/joint_states"].message_count
        assert topics["/mocap/root_pose"].message_count == topics["/mocap/joint_states"].message_count
        assert topics["/mocap/markers"].message_count == topics["/mocap/joint_states"].message_count
        msg = next(ma.from_cdr(m.data, m.type) for m in r.messages(["/humans/bodies/mocap/joint_states"]))
        urdf = next(ma.from_cdr(m.data, m.type).data for m in r.messages(["/humans/bodies/mocap/urdf"]))
        assert topics["/humans/bodies/mocap/urdf"].latched
    assert "l_knee_mocap" in msg.name and "waist_mocap" in msg.name
    assert 'name="l_knee_mocap"' in urdf and 'name="human_mocap"' in urdf
