"""Body shape calibrated from the silhouettes (tracking/shape_calibration.py, cli/calibrate.py; issue 33)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from isa_mocap_ros.body import capsule_endpoints, default_shape, load_shape, make_model
from isa_mocap_ros.cli.main import main
from isa_mocap_ros.tracking.shape_calibration import (SHAPE_PARAMS, ShapeCalibrationConfig, ShapeCalibrationError,
                                                      bone_errors, bone_lengths, calibrate_shape,
                                                      marker_bone_lengths, shape_from_params)



def test_shape_from_params_identity_symmetry_and_bad_input():
    base = default_shape()
    same = shape_from_params(base, {})
    for j, o in base["offsets"].items():
        assert np.allclose(same["offsets"][j], o)
    for c, r in base["radii"].items():
        assert np.allclose(same["radii"][c], r)
    s = shape_from_params(base, {"thigh": 1.1, "r_legs": 1.3, "hip_width": 0.8})
    assert np.allclose(s["offsets"]["left_knee"], 1.1 * base["offsets"]["left_knee"])
    assert np.allclose(s["offsets"]["right_knee"], s["offsets"]["left_knee"])          # symmetric
    assert np.allclose(s["offsets"]["right_hip"], s["offsets"]["left_hip"] * [1, -1, 1])
    assert np.isclose(s["offsets"]["left_hip"][1], 0.8 * base["offsets"]["left_hip"][1])
    assert np.allclose(s["radii"]["right_thigh"], 1.3 * base["radii"]["left_thigh"])
    b = bone_lengths(make_model(39, shape=s))
    assert np.isclose(b["left_thigh"], 1.1 * bone_lengths(make_model(39))["left_thigh"])
    with pytest.raises(ShapeCalibrationError, match="unknown names"):
        shape_from_params(base, {"tail": 1.0})
    with pytest.raises(ShapeCalibrationError, match="positive finite"):
        shape_from_params(base, {"scale": -1.0})
    with pytest.raises(ShapeCalibrationError, match=f"expected {len(SHAPE_PARAMS)} numbers"):
        shape_from_params(base, [1.0, 2.0])
    with pytest.raises(ShapeCalibrationError, match="window_frames: expected an integer >= 1"):
        ShapeCalibrationConfig(window_frames=0)
    with pytest.raises(ShapeCalibrationError, match="energy: expected 'raster' or 'fast', received 'exact'"):
        ShapeCalibrationConfig(energy="exact")
    with pytest.raises(ShapeCalibrationError, match="combine: expected 'lowest' or 'median', received 'mean'"):
        ShapeCalibrationConfig(combine="mean")


def test_marker_bone_lengths_are_the_median_distance_and_errors_compare_by_name():
    names = ["left_hip", "left_knee", "left_ankle"]
    T = np.zeros((3, 3, 3))
    T[:, 1, 2] = [-0.40, -0.42, -0.44]
    T[:, 2, 2] = T[:, 1, 2] - 0.40
    got = marker_bone_lengths(names, T)
    assert got == pytest.approx({"left_thigh": 0.42, "left_shin": 0.40})
    err = bone_errors({"left_thigh": 0.43, "left_shin": 0.40, "right_thigh": 1.0}, got)
    assert err["per_bone_mm"] == {"left_thigh": 10.0, "left_shin": 0.0} and err["mean_mm"] == pytest.approx(5.0)
    err = bone_errors({"left_thigh": 0.43, "hip_width": 0.25}, {"left_thigh": 0.42, "hip_width": 0.20})
    assert err["mean_mm"] == pytest.approx(30.0) and err["limbs_mean_mm"] == pytest.approx(10.0)
    with pytest.raises(ShapeCalibrationError, match=r"markers: expected shape \(F, 3, 3\)"):
        marker_bone_lengths(names, np.zeros((2, 4, 3)))


def _rendered_frames(model, n, seed=0):
    """Exact masks of ``model`` walking (the project's motion generator) in the default rig."""
    from isa_mocap_ros.body.motion import generate_motion
    from isa_mocap_ros.vision import default_rig, render_mask

    rig = default_rig()
    X = generate_motion("walk", model, duration_s=n / 15.0, fps=15.0, rng=np.random.default_rng(seed))[:n]
    frames = []
    for k, x in enumerate(X):
        E = capsule_endpoints(model, x[None, :])[0]
        frames.append((k, [render_mask(c, E, model.capsule_radii) for c in rig]))
    return list(rig), frames


#: the known shape of the calibration tests' renders: a subject unlike the default shape (taller, long shins,
#: short upper arms, heavier legs)
KNOWN_SHAPE = {"scale": 1.07, "thigh": 0.95, "shin": 1.08, "upper_arm": 0.92, "forearm": 1.0,
               "hip_width": 1.15, "r_legs": 1.25, "r_trunk": 1.1}


@pytest.mark.timeout(300)
def test_calibration_recovers_a_known_capsule_shape():
    # exact renders of a subject unlike the default shape (KNOWN_SHAPE)
    model = make_model(39, shape=shape_from_params(default_shape(), KNOWN_SHAPE))
    cams, frames = _rendered_frames(model, 8)
    cfg = ShapeCalibrationConfig(window_frames=8, n_frames=4, rounds=3, pose_steps=2, shape_evals=1500, seed=0)
    res = calibrate_shape(39, cams, frames, config=cfg)
    want = bone_lengths(model)
    before = bone_errors(bone_lengths(make_model(39)), want)
    after = bone_errors(bone_lengths(make_model(39, shape=res.shape)), want)
    assert res.energy < 0.5 * res.energy_default
    assert res.notes[-1].startswith("restart ") and " of 3 kept" in res.notes[-1]
    # the defaults (raster shape fit, 3 restarts, the lowest judged energy kept), seeds 0-5
    # (docs/history/issue33_shape_calibration.md, session 27): 14.2, 11.8, 11.2, 15.2, 11.1, 15.1 mm (mean 13.1); single
    # raster calibrations 11.1-19.5 (mean 15.1 over 18); session 25's sampled single fit 20.1, 11.1, 13.4, 11.7, 13.0, 24.7
    assert after["mean_mm"] < 18.0 and after["limbs_mean_mm"] < 18.0, (after, before)


@pytest.mark.timeout(300)
def test_occluders_one_view_reports_stay_out_of_the_shape_fit():
    # the known shape's renders with 35 rectangles drawn into every mask (ISA §13.4.2's occluders, as a segmenter
    # that takes them for foreground reports them): the calibration frames' masks are cut to the visual hull's
    # person blob before the pose and shape fits. Seeds 0 / 1 (session 26, /tmp/h33b26/occ_test.py): 26.2 / 17.6 mm
    # mean bone error with the cut, 36.4 / 42.8 mm with masks="raw" (this bound fails there); the same renders
    # without occluders: 20.1 mm (seed 0)
    from isa_mocap_ros.vision.distort import occluders

    model = make_model(39, shape=shape_from_params(default_shape(), KNOWN_SHAPE))
    cams, frames = _rendered_frames(model, 8)
    rng = np.random.default_rng(7)
    occluded = [(k, [occluders(m, 35, rng=rng) for m in ms]) for k, ms in frames]
    cfg = ShapeCalibrationConfig(window_frames=8, n_frames=4, rounds=3, pose_steps=2, shape_evals=1500, seed=0)
    assert cfg.masks == "hull"
    res = calibrate_shape(39, cams, occluded, config=cfg)
    note = next(n for n in res.notes if n.startswith("calibration masks: the visual hull's person blob kept"))
    assert 50.0 < float(note.split("(")[1].split(" %")[0]) < 95.0       # the share of foreground removed
    err = bone_errors(bone_lengths(make_model(39, shape=res.shape)), bone_lengths(model))["mean_mm"]
    assert err < 30.0, err
    with pytest.raises(ShapeCalibrationError, match="masks: expected .hull. or .raw."):
        ShapeCalibrationConfig(masks="gate")


def test_calibration_is_deterministic():
    model = make_model(39, shape=shape_from_params(default_shape(), {"scale": 0.95}))
    cams, frames = _rendered_frames(model, 3)
    cfg = ShapeCalibrationConfig(window_frames=3, n_frames=2, rounds=2, pose_steps=1, shape_evals=40, seed=4)
    a, b = calibrate_shape(39, cams, frames, config=cfg), calibrate_shape(39, cams, frames, config=cfg)
    assert a.params == b.params and np.array_equal(a.poses, b.poses) and a.frame_keys == b.frame_keys == (0, 2)


def test_restarts_keep_the_lowest_judged_energy_and_the_prior_holds_the_arm_split():
    import dataclasses

    from isa_mocap_ros.tracking.shape_calibration import prior

    model = make_model(39, shape=shape_from_params(default_shape(), {"scale": 1.04}))
    cams, frames = _rendered_frames(model, 3)
    cfg = ShapeCalibrationConfig(window_frames=3, n_frames=2, rounds=1, pose_steps=1, shape_evals=40, seed=2, restarts=2)
    res = calibrate_shape(39, cams, frames, config=cfg)
    kept = int(res.notes[-1].split()[1])                          # "restart K of 2 kept (judged energies a, b)"
    assert res.notes[-1].startswith(f"restart {kept} of 2 kept")
    e = [float(v) for v in res.notes[-1].split("energies ")[1].rstrip(")").split(", ")]
    assert len(e) == 2 and e[kept - 1] == min(e)
    # restart K is the calibration with seed + 7919 (K - 1), tracker included
    one = calibrate_shape(39, cams, frames, config=dataclasses.replace(cfg, restarts=1, seed=2 + 7919 * (kept - 1)))
    assert one.params == res.params
    # the prior: a weak pull of every log factor, a stronger one on the upper arm / forearm split only
    z = np.zeros(len(SHAPE_PARAMS))
    names = [n for n, _, _ in SHAPE_PARAMS]
    z[names.index("upper_arm")], z[names.index("forearm")] = 0.1, -0.1
    assert prior(cfg, z) == pytest.approx(cfg.regularization * 0.02 + cfg.arm_split_prior * 0.04)
    z[names.index("forearm")] = 0.1
    assert prior(cfg, z) == pytest.approx(cfg.regularization * 0.02)


def test_the_track_judge_keeps_the_restart_whose_shape_tracks_the_judge_frames_with_the_lowest_energy():
    import dataclasses

    from isa_mocap_ros.tracking.shape_judge import tracked_energy
    from isa_mocap_ros.tracking.tracker import TrackerConfig

    model = make_model(39, shape=shape_from_params(default_shape(), KNOWN_SHAPE))
    cams, frames = _rendered_frames(model, 4)
    cfg = ShapeCalibrationConfig(window_frames=3, n_frames=2, rounds=1, pose_steps=1, shape_evals=150, seed=2,
                                 restarts=2, judge="track", judge_frames=4)
    res = calibrate_shape(39, cams, frames, config=cfg)
    assert res.notes[-1].startswith("restart ") and "(track judge; judged energies " in res.notes[-1]
    kept = int(res.notes[-1].split()[1])
    # each restart's shape tracked over all four frames (one past the window) with the first restart's tracker seed
    tcfg = TrackerConfig.from_flat(seed=2)
    judge = [(f[0], f[1], None) for f in frames]
    e = [tracked_energy(39, cams, judge, calibrate_shape(39, cams, frames[:3], config=dataclasses.replace(
        cfg, restarts=1, seed=2 + 7919 * r), tracker_config=tcfg.replace(seed=2 + 7919 * r)).shape, tcfg)
         for r in range(2)]
    listed = [float(v) for v in res.notes[-1].split("energies ")[1].rstrip(")").split(", ")]
    assert listed == pytest.approx(e, abs=5e-5) and e[kept - 1] == min(e) and e[0] != e[1]
    with pytest.raises(ShapeCalibrationError, match="judge: expected 'fit' or 'track'"):
        ShapeCalibrationConfig(judge="tracked")


def test_radius_prior_is_off_by_default_and_pulls_only_the_radius_factors_towards_their_centre():
    import argparse
    import dataclasses

    from isa_mocap_ros.cli.shape_options import calibration_config
    from isa_mocap_ros.tracking.shape_calibration import prior

    cfg = ShapeCalibrationConfig()
    names = [n for n, _, _ in SHAPE_PARAMS]
    z = np.zeros(len(SHAPE_PARAMS))
    z[names.index("r_arms")], z[names.index("thigh")] = np.log(1.3), 0.1
    assert cfg.radius_prior == 0 and prior(cfg, z) == pytest.approx(cfg.regularization * float(z @ z))
    on = dataclasses.replace(cfg, radius_prior=0.1)
    c = np.log(on.radius_centre)
    want = cfg.regularization * float(z @ z) + 0.1 * ((np.log(1.3) - c) ** 2 + 2 * c ** 2)   # r_arms, r_trunk, r_legs
    assert prior(on, z) == pytest.approx(want)
    assert calibration_config(argparse.Namespace(calib_radius_prior=0.1), 0).radius_prior == 0.1
    with pytest.raises(ShapeCalibrationError, match="radius_prior"):
        ShapeCalibrationConfig(radius_prior=-1.0)
    with pytest.raises(ShapeCalibrationError, match="radius_centre"):
        ShapeCalibrationConfig(radius_centre=0.0)


def test_median_of_restarts_is_each_factors_median_over_the_single_calibrations():
    import dataclasses

    model = make_model(39, shape=shape_from_params(default_shape(), {"scale": 0.96, "thigh": 1.05}))
    cams, frames = _rendered_frames(model, 3)
    cfg = ShapeCalibrationConfig(window_frames=3, n_frames=2, rounds=1, pose_steps=1, shape_evals=40, seed=3, restarts=3,
                                 combine="median")
    res = calibrate_shape(39, cams, frames, config=cfg)
    singles = [calibrate_shape(39, cams, frames, config=dataclasses.replace(cfg, restarts=1, seed=3 + 7919 * k))
               for k in range(3)]
    for n, _, _ in SHAPE_PARAMS:
        want = np.exp(np.median([np.log(r.params[n]) for r in singles]))
        assert res.params[n] == pytest.approx(want, rel=1e-12), n
    assert res.notes[-1].startswith("median factors of 3 restarts")
    assert bone_lengths(make_model(39, shape=res.shape)) == pytest.approx(
        bone_lengths(make_model(39, shape=shape_from_params(default_shape(), res.params))))


def test_raster_shape_fit_gives_the_raster_energys_bits_also_with_lens_distortion():
    # the shape fit's raster route (kernel inputs set once, offsets and radii scaled per candidate) against a
    # SilhouetteEnergy(method='raster') of the candidate's model, on pinhole and on distorted cameras
    import dataclasses

    from isa_mocap_ros.energy import SilhouetteEnergy
    from isa_mocap_ros.tracking import shape_calibration as sc

    model = make_model(39, shape=shape_from_params(default_shape(), {"scale": 1.02}))
    cams, frames = _rendered_frames(model, 2)
    bent = [dataclasses.replace(c, dist=np.array([-0.04, 0.0, 0.0, 0.0, 0.0])) for c in cams]
    cfg = ShapeCalibrationConfig(energy="raster")
    X = np.array([model.rest_pose(), model.rest_pose()])
    X[1, 2] += 0.03
    rng = np.random.default_rng(0)
    for rig in (cams, bent):
        fe = sc._ShapeEnergy(39, default_shape(), rig, sc._prepared_masks(39, rig, [m for _, m in frames], cfg), X,
                             cfg, [0, 33, 1])
        for _ in range(3):
            z = np.concatenate([rng.normal(0.0, 0.1, len(SHAPE_PARAMS)), rng.normal(0.0, 0.02, 2)])
            m = make_model(39, shape=shape_from_params(default_shape(), np.exp(z[:len(SHAPE_PARAMS)])))
            want = 0.0
            for k, (_, masks) in enumerate(frames):
                f = SilhouetteEnergy(m, rig, masks, method="raster")
                want += float(f(fe.poses(z)[k][None, :])[0]) / 2
            assert fe(z[None, :])[0] == want + sc.prior(cfg, z[:len(SHAPE_PARAMS)])


def test_calibration_needs_a_person():
    from isa_mocap_ros.vision import default_rig

    rig = list(default_rig())
    empty = [(k, [np.zeros((c.height, c.width), np.uint8) for c in rig]) for k in range(3)]
    with pytest.raises(ShapeCalibrationError, match="found no person"):
        calibrate_shape(39, rig, empty, config=ShapeCalibrationConfig(window_frames=3, rounds=1, shape_evals=10))
    with pytest.raises(ShapeCalibrationError, match="at least one frame"):
        calibrate_shape(39, rig, [])


REPO = Path(__file__).resolve().parents[1]
FIXTURE = REPO / "bags" / "fixture"
QUICK = ["--calib-frames", "5", "--calib-rounds", "1", "--calib-evals", "40"]


@pytest.mark.skipif(not FIXTURE.is_dir(), reason="bags/fixture not present")
def test_calibrate_cli_writes_a_shape_that_track_uses(tmp_path, capsys):
    from isa_mocap_ros.bag import BagReader
    from isa_mocap_ros.sequence import model_from_yaml
    from msg_adapters import from_cdr

    body = tmp_path / "body.yaml"
    assert main(["calibrate", str(FIXTURE), "--out", str(body), "--use-masks", "--report", str(tmp_path / "r.json"),
                 *QUICK]) == 0
    assert "mean bone-length error" in capsys.readouterr().out
    shape = load_shape(body)
    rep = json.loads((tmp_path / "r.json").read_text())
    assert set(rep["params"]) == {n for n, _, _ in SHAPE_PARAMS} and rep["energy"] <= rep["energy_default_shape"]
    assert rep["bone_error"]["mean_mm"] >= 0 and rep["bones_m"] == pytest.approx(
        bone_lengths(make_model(39, shape=shape)), abs=1e-3)
    # an existing file needs --overwrite
    assert main(["calibrate", str(FIXTURE), "--out", str(body), *QUICK]) == 2
    assert "pass --overwrite" in capsys.readouterr().err
    # track --shape FILE tracks with it and publishes it in its estimates
    out = tmp_path / "tr"
    assert main(["track", str(FIXTURE), "--out", str(out), "--frames", "2", "--evals", "200", "--use-masks",
                 "--no-progress", "--shape", str(body)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["shape"] == str(body) and "shape_calibration" not in s
    with BagReader(out / "estimates") as bag:
        model = model_from_yaml(from_cdr(*next((m.data, m.type) for m in bag.messages(["/mocap/model"]))).data)[0]
    for j, o in shape["offsets"].items():
        assert np.allclose(model.shape["offsets"][j], o, atol=1e-6)
    capsys.readouterr()
    assert main(["track", str(FIXTURE), "--out", str(tmp_path / "t2"), "--shape", str(tmp_path / "nope.yaml")]) == 2
    assert "--shape: expected auto, default, truth or a body-shape YAML file" in capsys.readouterr().err


class _NoShape:
    """A ground-truth model whose shape must not be read (delegates everything else)."""

    def __init__(self, model):
        self._model = model

    def __getattr__(self, name):
        if name == "shape":
            raise AssertionError("the default path read the ground-truth body shape")
        return getattr(self._model, name)


@pytest.mark.skipif(not FIXTURE.is_dir(), reason="bags/fixture not present")
def test_track_default_path_reads_no_ground_truth_shape(tmp_path, monkeypatch):
    import dataclasses

    import isa_mocap_ros.cli.track as track
    import isa_mocap_ros.eval.report as report

    real = track.read_sequence

    def guarded(*a, **kw):
        seq = real(*a, **kw)
        assert seq.truth_model is not None
        return dataclasses.replace(seq, truth_model=_NoShape(seq.truth_model))

    monkeypatch.setattr(track, "read_sequence", guarded)
    monkeypatch.setattr(report, "score", lambda *a, **kw: None)     # scoring may read the truth; tracking not
    out = tmp_path / "tr"
    assert main(["track", str(FIXTURE), "--out", str(out), "--frames", "2", "--evals", "200", "--use-masks",
                 "--no-progress", *QUICK]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["shape"] == "auto" and set(s["shape_calibration"]["params"]) == {n for n, _, _ in SHAPE_PARAMS}
    # the guard works: the diagnostic --shape truth does read it
    with pytest.raises(AssertionError, match="read the ground-truth body shape"):
        main(["track", str(FIXTURE), "--out", str(tmp_path / "t2"), "--frames", "1", "--evals", "100",
              "--use-masks", "--no-progress", "--shape", "truth"])


def test_run_and_track_default_to_the_calibrated_shape():
    from isa_mocap_ros.cli.main import build_parser

    p = build_parser()
    assert p.parse_args(["track", "B", "--out", "o"]).shape == "auto"
    assert p.parse_args(["run", "B"]).shape == "auto"


@pytest.mark.skipif(not FIXTURE.is_dir(), reason="bags/fixture not present")
def test_run_shape_option_gives_the_estimator_a_body_file(tmp_path):
    from isa_mocap_ros.cli.main import build_parser
    from isa_mocap_ros.cli.run import _body_shape, _network

    p = build_parser()
    args = p.parse_args(["run", str(FIXTURE), "--out", str(tmp_path), *QUICK])
    path = _body_shape(args, FIXTURE, tmp_path, 3)
    assert path == str((tmp_path / "body.yaml").resolve()) and load_shape(path)["name"] == "calibrated:fixture"
    assert json.loads((tmp_path / "shape_calibration.json").read_text())["frames"] >= 1
    est = next(s for s in _network(args, "p.yaml", tmp_path, 4, 3, path) if s.name == "estimator")
    assert ("body_shape", path) in est.params
    assert _body_shape(p.parse_args(["run", "--shape", "default"]), FIXTURE, tmp_path, 3) is None
    truth = _body_shape(p.parse_args(["run", "--shape", "truth"]), FIXTURE, tmp_path, 3)
    assert load_shape(truth)["offsets"].keys() == default_shape()["offsets"].keys()
    with pytest.raises(ValueError, match="--shape: expected auto, default, truth or a body-shape YAML"):
        _body_shape(p.parse_args(["run", "--shape", str(tmp_path / "nope.yaml")]), FIXTURE, tmp_path, 3)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_run_on_a_mesh_bag_reports_what_track_reports(tmp_path, rosenv):
    # the main job with its defaults (automatic shape and initialization; a short calibration and budget to
    # stay small) through the node network in lockstep, against the offline tracker on the same bag: the same
    # calibrated shape and the same per-frame errors against the mesh skeleton's joint centres
    import subprocess
    import sys

    bag = tmp_path / "mesh"
    assert main(["synth", "walk", str(bag), "--width", "160", "--height", "120", "--duration-s", "0.2",
                 "--empty-frames", "10", "--subject", "average_man", "--no-progress"]) == 0
    opts = ["--evals", "200", "--calib-frames", "4", "--calib-rounds", "1", "--calib-evals", "40"]
    res = subprocess.run([sys.executable, "-m", "isa_mocap_ros.cli.main", "run", str(bag), "--lockstep", "--out",
                          str(tmp_path / "run"), "--quiet", *opts], env=rosenv, capture_output=True, text=True,
                         timeout=500)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert main(["track", str(bag), "--out", str(tmp_path / "track"), "--no-progress", *opts]) == 0
    r = json.loads((tmp_path / "run" / "summary.json").read_text())
    t = json.loads((tmp_path / "track" / "summary.json").read_text())
    assert t["shape"] == "auto" and t["scored_by"] == r["scored_by"] == "markers"
    assert json.loads((tmp_path / "run" / "shape_calibration.json").read_text())["params"] \
        == t["shape_calibration"]["params"]
    assert r["frames_processed"] == r["frame_sets_played"] and r["frames_estimated"] == t["frames"] == 6
    assert r["frame_errors_mm"] == t["frame_errors_mm"]
    for k in ("mpjpe_mm", "mapped_mpjpe_mm", "knee_rmse_deg"):
        assert r[k] == pytest.approx(t[k], rel=1e-9, abs=1e-9), k
