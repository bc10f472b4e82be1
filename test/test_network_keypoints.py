"""The estimator node with learned keypoints: `isa-mocap run --lockstep --keypoints` on the fixture bag (real
node processes over DDS, the keypoint node among them) while a fuzzer publishes malformed and far keypoint
messages and skip notices (``test/fuzzer.py keypoints``; its other kinds are test_network_fuzz's), against the offline `isa-mocap track --keypoint-weight`
with the same settings: the estimates are identical bit for bit, so the estimator took each frame set's
keypoints (the keypoint node's schedule: the dense start, then every 8th frame) and nothing the fuzzer sent.
"""
from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import msg_adapters as ma
from isa_mocap_ros.bag import BagReader
from conftest import joint_states_by_stamp

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.timeout(600)]
HERE = Path(__file__).parent
FIXTURE = HERE.parent / "bags" / "fixture"
CLI = [sys.executable, "-m", "isa_mocap_ros.cli.main"]
SETTINGS = ["--optimizer", "isa", "--evals", "300", "--seed", "3", "--shape", "default"]


def test_lockstep_run_with_keypoints_equals_offline_track_under_a_fuzzer(landmark_model, spawn, rosenv, tmp_path,
                                                                         fixture_track):
    fuzzer = spawn("fuzzer", str(HERE / "fuzzer.py"), "4", "20", "1", "keypoints")
    assert fuzzer.wait_for_output("sent ", 30), fuzzer.output()
    run = subprocess.run(CLI + ["run", str(FIXTURE), "--lockstep", "--keypoints", "--out", str(tmp_path / "run"),
                                "--quiet", *SETTINGS], env=rosenv, capture_output=True, text=True, timeout=400)
    fuzzer.stop(signal.SIGINT)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    total = next(ln for ln in fuzzer.output().splitlines() if ln.startswith("total "))
    sent = {k: int(n) for k, n in (kv.split("=") for kv in total.split()[1:])}
    assert min(n for k, n in sent.items() if k.startswith("keypoints")) >= 2, sent

    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    with BagReader(FIXTURE) as r:
        n_sets = r.topics["/mocap/cam0/image_raw"].message_count
    assert s["frames_processed"] == n_sets and s["dropped_frames"] == 0
    from conftest import FIXTURE_TRACK_SETTINGS
    assert FIXTURE_TRACK_SETTINGS == tuple(SETTINGS)
    (tmp_path / "track").symlink_to(fixture_track("1"))      # `track --keypoint-weight 1`, shared (conftest)
    offline = json.loads((tmp_path / "track" / "summary.json").read_text())
    # 12 frames with a person: the first 4 and every 8th after (frame 8 of them), 4 views each
    assert offline["keypoint_frames"] == 5 and offline["keypoint_detections"] == 20, offline

    # the keypoint node's messages were recorded (beside the fuzzer's: malformed, or far from the frames):
    # 5 frames x 4 views, the schedule's frames
    with BagReader(FIXTURE) as r:
        frames = {ma.header_stamp_ns_from_cdr(m.data) for m in r.messages(["/mocap/cam0/image_raw"])}
    kp = []
    with BagReader(tmp_path / "run" / "estimates") as r:
        for m in r.messages([f"/mocap/cam{v}/keypoints" for v in range(4)]):
            msg = ma.from_cdr(m.data, m.type)
            try:
                ma.polygon_to_keypoints(msg)
            except ma.AdapterError:
                continue
            if ma.stamp_to_ns(msg.header) in frames:
                kp.append(msg)
    assert len({ma.stamp_to_ns(m.header) for m in kp}) == 5 and len(kp) == 20
    node, ref = joint_states_by_stamp(tmp_path / "run" / "estimates"), joint_states_by_stamp(tmp_path / "track" / "estimates")
    assert node.keys() == ref.keys() and len(node) == 12
    for stamp in node:
        assert np.array_equal(node[stamp], ref[stamp]), (stamp, np.abs(node[stamp] - ref[stamp]).max())
    # the term was on: without it the same settings give other estimates
    off = joint_states_by_stamp(fixture_track("0") / "estimates")
    assert any(not np.array_equal(off[st], node[st]) for st in node)

    log = (tmp_path / "run" / "nodes.log").read_text()
    assert "Traceback" not in log and "[ERROR]" not in log, log[-3000:]
    log0 = log.replace("cam1/", "cam0/").replace("cam2/", "cam0/").replace("cam3/", "cam0/")
    for text in ("cam0/keypoints dropped: PolygonStamped.polygon.points", "z of point"):
        assert text in log0, text
    # a far keypoint message or skip notice is dropped with one line: at once once the stream has started, or when
    # the first frame set forms if it came before (which of the two the fuzzer hits first depends on timing; the
    # problem log says each kind once)
    held = "cam0/keypoints (or skip notice) of stamp"
    for text in ("keypoints dropped: stamp", "keypoints_skipped dropped: stamp"):
        assert text in log0 or held in log0, text
    assert "no keypoints or skip notice" not in log       # every frame set had its views' messages
