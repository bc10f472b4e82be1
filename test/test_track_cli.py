"""``isa-mocap track`` on the shipped fixture bag: estimates bag + summary.json; the pure sequence layer."""
import json
from pathlib import Path

import numpy as np
import pytest

from isa_mocap_ros.cli.main import main
from isa_mocap_ros.sequence import SequenceBuilder, SequenceError, view_of_topic

FIXTURE = Path(__file__).resolve().parents[1] / "bags" / "fixture"
KEYS = {"knee_rmse_deg", "mpjpe_mm", "max_frame_error_mm", "frames", "optimizer", "evals_per_frame", "model_dof",
        "fps", "seed"}


@pytest.mark.skipif(not FIXTURE.is_dir(), reason="bags/fixture not present")
@pytest.mark.parametrize("masks", [True, False])
def test_track_fixture_writes_estimates_and_summary(tmp_path, capsys, masks):
    from isa_mocap_ros.bag import BagReader
    from msg_adapters import from_cdr, joint_state_to_arrays

    out = tmp_path / "out"
    argv = ["track", str(FIXTURE), "--out", str(out), "--evals", "300", "--frames", "5", "--seed", "1",
            "--no-progress", "--init", "truth", "--shape", "truth"]
    if masks:
        argv.append("--use-masks")
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "mean joint error" in text and "knee-angle RMSE" in text
    s = json.loads((out / "summary.json").read_text())
    assert KEYS <= set(s)
    assert s["optimizer"] == "h-isa" and s["evals_per_frame"] == 300 and s["model_dof"] == 39 and s["seed"] == 1
    assert s["frames"] == 5 and np.isfinite(s["mpjpe_mm"]) and s["max_frame_error_mm"] >= s["mpjpe_mm"]
    with BagReader(out / "estimates") as bag:
        msgs = list(bag.messages(["/mocap/joint_states"]))
    assert len(msgs) == 5
    # per-frame energies (ISA Fig. 13.14) by stamp; the ground-truth first frame has none
    assert s["frame_stamps_ns"] == [m.log_time_ns for m in msgs]
    assert s["frame_energies"][0] is None and all(np.isfinite(e) for e in s["frame_energies"][1:])
    names, pos = joint_state_to_arrays(from_cdr(msgs[0].data, msgs[0].type))
    assert len(names) == 39 and names[0] == "root_tx" and np.all(np.isfinite(pos))
    assert msgs[0].log_time_ns == from_cdr(msgs[0].data, msgs[0].type).header.stamp.sec * 10**9 + \
        from_cdr(msgs[0].data, msgs[0].type).header.stamp.nanosec


@pytest.mark.skipif(not FIXTURE.is_dir(), reason="bags/fixture not present")
def test_track_stride_tracks_every_kth_frame(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["track", str(FIXTURE), "--out", str(out), "--evals", "300", "--frames", "7", "--stride", "3",
                 "--no-progress", "--init", "truth", "--shape", "truth", "--use-masks"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["stride"] == 3 and s["frames_tracked"] == 3 and s["frames"] == 3       # frames k, k + 3, k + 6
    d = np.diff(s["frame_stamps_ns"])
    assert len(d) == 2 and d[0] == d[1] and d[0] > 0
    assert main(["track", str(FIXTURE), "--out", str(tmp_path / "o2"), "--stride", "0"]) == 2
    assert "--stride: expected an integer >= 1" in capsys.readouterr().err


@pytest.mark.skipif(not FIXTURE.is_dir(), reason="bags/fixture not present")
def test_track_partition_order(tmp_path, capsys):
    paper = "root,torso,left_arm,right_arm,left_leg,right_leg"
    out = tmp_path / "out"
    assert main(["track", str(FIXTURE), "--out", str(out), "--evals", "300", "--frames", "3", "--no-progress",
                 "--init", "truth", "--shape", "truth", "--use-masks", "--partition-order", paper]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["partition_order"] == paper.split(",") and s["frames"] == 3
    capsys.readouterr()
    assert main(["track", str(FIXTURE), "--out", str(tmp_path / "o2"), "--partition-order", "root,torso", "--shape", "default"]) == 2
    assert "partition_order: expected every partition of model" in capsys.readouterr().err


def test_track_bad_input(tmp_path, capsys):
    assert main(["track", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "no such path" in capsys.readouterr().err
    if FIXTURE.is_dir():
        assert main(["track", str(FIXTURE), "--out", str(tmp_path / "o"), "--params", "[1]"]) == 2
        assert "--params: expected a JSON object" in capsys.readouterr().err


def test_sequence_builder():
    assert view_of_topic("/mocap/cam3/mask") == (3, "mask")
    assert view_of_topic("/mocap/ground_truth/model") is None
    b = SequenceBuilder()
    K = np.array([[100.0, 0, 40], [0, 100, 30], [0, 0, 1]])
    for v in range(2):
        b.add_camera_info(v, K=K, D=np.zeros(5), width=80, height=60)
        b.add_extrinsics(v, np.eye(3), [0, 0, -3.0 - v])
    b.add_image(0, 20, np.zeros((60, 80, 3), np.uint8))
    b.add_image(1, 10, np.zeros((60, 80, 3), np.uint8))
    b.add_mask(1, 20, np.zeros((60, 80), np.uint8))
    seq = b.build()
    assert seq.n_views == 2 and [f.stamp_ns for f in seq.frames] == [10, 20]
    assert seq.frames[0].images[0] is None and seq.frames[0].images[1] is not None
    assert seq.frames[1].masks[1] is not None and not seq.has_truth
    np.testing.assert_allclose(seq.cameras[1].center, [0, 0, -4.0])
    b2 = SequenceBuilder()
    b2.add_camera_info(0, K=K, D=np.zeros(5), width=80, height=60)
    with pytest.raises(SequenceError, match="view 0: expected camera_info and extrinsics, missing extrinsics"):
        b2.build()
    with pytest.raises(SequenceError, match="stamp_ns: expected an integer >= 0"):
        b2.add_image(0, -5, np.zeros((2, 2)))
