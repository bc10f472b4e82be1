"""``isa-mocap bench real``: the real recording's section of the results page (a smoke run on 8 frames at 160 px;
the figures come from the full bench, docs/RESULTS.md). Reads the recording from ../shared, skipped when absent."""
import json

import numpy as np
import pytest

from isa_mocap_ros.bench import BENCHES
from isa_mocap_ros.bench import real as bench_real
from isa_mocap_ros.cli.main import main


def test_real_is_a_bench_and_refuses_unknown_configurations(capsys):
    assert "real" in BENCHES
    assert main(["bench", "real", "--configs", "default,nope", "--lockstep", "none"]) == 2
    assert "expected names of default, keypoints, auto" in capsys.readouterr().err
    assert main(["bench", "real", "--seeds", "a,b", "--lockstep", "none"]) == 2
    assert "--seeds: expected integers" in capsys.readouterr().err


def test_quick_run_scores_every_frame_against_the_peer(tmp_path):
    if not (bench_real.demo_dir() / "calibration" / "Calib_scene_checkerboard.toml").is_file():
        pytest.skip(f"Pose2Sim demo not found at {bench_real.demo_dir()} (set ISA_MOCAP_SHARED to the shared/ folder)")
    out = tmp_path / "json" / "real.json"
    assert main(["bench", "real", "--quick", "--configs", "default", "--lockstep", "none", "--out", str(tmp_path / "w"),
                 "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    r = d["runs"]["default"]
    assert d["quick"] and r["frames_tracked"] == r["frames"] == 8 and len(r["frame_errors_mm"]) == 8
    assert 0 < r["offset_removed_mpjpe_mm"] <= r["mpjpe_mm"] and np.isfinite(r["knee_rmse_deg"])
    assert len(r["offset_removed_per_marker_mm"]) == 14
    md = bench_real.render_markdown(d)
    assert "| default shape | 8 |" in md and "Quick run" in md and "nan" not in md.lower()
    assert d["seeds"] == [0] and r["seeds"][0]["seed"] == 0
    assert r["offset_removed_over_seeds"]["mean"] == r["offset_removed_mpjpe_mm"]
    # per joint in each third of the frames (3 + 3 + 2 of 8): weighted by the spans, the score's per-joint mean
    th = r["joint_thirds_over_seeds"]
    assert set(th) == set(r["offset_removed_per_marker_mm"])
    for n, v in th.items():
        assert np.dot(v, [3, 3, 2]) / 8 == pytest.approx(r["offset_removed_per_marker_mm"][n], abs=1e-9), n
    assert "| last third |" in md
    # the masks per view against the peer's stick figure (shares in [0, 1])
    assert [m["view"] for m in d["masks"]] == [0, 1, 2, 3]
    assert all(0 <= m[k] <= 1 for m in d["masks"] for k in ("beyond", "core_missed", "keypoints_on"))
    assert all(len(m["beyond_thirds"]) == 3 and all(0 <= x <= 1 for x in m["beyond_thirds"]) for m in d["masks"])
    assert "cam0 " in md and "stick figure" in md
    # the peer's points defined on the mesh bodies: 'our joints' is the score itself; the other points placed too
    defs = r["definitions_over_seeds"]
    assert defs["joints"]["raw"]["mean"] == pytest.approx(r["mpjpe_mm"], abs=1e-9)
    assert defs["joints"]["offset_removed"]["mean"] == pytest.approx(r["offset_removed_mpjpe_mm"], abs=1e-9)
    assert defs["head_top"]["per_joint_offset_removed_mm"]["left_knee"] == pytest.approx(
        r["offset_removed_per_marker_mm"]["left_knee"], abs=1e-9)                  # only the head differs
    assert defs["head_top"]["raw"]["mean"] != defs["joints"]["raw"]["mean"]
    assert set(defs["extra"]) == {"Nose", "LHeel", "RHeel", "LBigToe", "RBigToe", "LSmallToe", "RSmallToe"}
    assert "mesh bodies' head top" in md and "outside the score" in md
    # the offline smoothing option, scored apart
    assert np.isfinite(r["smoothed_offset_removed_mpjpe_mm"]) and "`track --smooth-hz 6`" in md
    # the bag is cached in the work directory: a second run does not import again
    assert (tmp_path / "w" / "demo_bag_160_8" / "metadata.yaml").is_file()
    assert bench_real.render_markdown({"skipped": "x"}) == "Not run: x.\n"


def test_filtered_score_removes_jitter_not_motion_and_reads_the_peer_in_its_axes(tmp_path):
    """The like-for-like figure: the estimate's joints filtered as Pose2Sim filters its points. A reference that is a
    slow motion of the model's own joints, with a constant offset per joint, written in TRC (y-up) axes: the estimate
    with that motion scores ~0 mm, with 20 mm white jitter per coordinate far less than its unfiltered score."""
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.eval.metrics import marker_positions
    from isa_mocap_ros.eval.trc import TRC_TO_WORLD, Trc, write_trc

    model = make_model(39)
    names = [model.joint_names[j] for j in model.markers]
    F, rng = 100, np.random.default_rng(0)
    X = np.zeros((F, model.dof))
    X[:, 0] = 0.3 * np.sin(np.linspace(0, np.pi, F))              # a slow walk forward and back, 1.67 s at 60 fps
    X[:, 2] = 1.0
    world = marker_positions(model, X, joints=names) + rng.normal(0, 0.03, (1, len(names), 3))   # per-joint offsets
    ref = tmp_path / "peer.trc"
    write_trc(ref, Trc(tuple(f"p{i}" for i in range(len(names))), np.arange(F) / 60.0,
                       world @ np.linalg.inv(TRC_TO_WORLD).T, 60.0))
    collect = {"model": model, "truth_marker_names": names, "truth_markers": {k: world[k] for k in range(F)},
               "estimates": {k: X[k] for k in range(F)}}
    assert bench_real.filtered_score(collect, 60.0, ref) < 1.0
    J = X.copy()
    J[:, :3] += rng.normal(0, 0.02, (F, 3))                          # the estimate's root jitters 20 mm
    collect["estimates"] = {k: J[k] for k in range(F)}
    jittered = bench_real.filtered_score(collect, 60.0, ref)
    raw = float(np.mean(np.linalg.norm(J[:, :3] - X[:, :3], axis=1))) * 1e3
    assert jittered < 0.5 * raw, (jittered, raw)
    assert bench_real.filtered_score({**collect, "estimates": {k: J[k] for k in range(10)}}, 60.0, ref) is None
