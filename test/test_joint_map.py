"""Model → rig joint map (eval/joint_map.py): fitted on some runs, applied unchanged to others."""
import numpy as np
import pytest

from isa_mocap_ros.body import joint_positions, make_model
from isa_mocap_ros.body.kinematics import joint_frames
from isa_mocap_ros.body.motion import generate_motion
from isa_mocap_ros.eval import score_markers
from isa_mocap_ros.eval.joint_map import (JointMap, JointMapError, fit_joint_map, load_joint_map, mapped_markers,
                                          mesh_rig_map, save_joint_map, segment_of)

#: a rig that puts some joints elsewhere: offsets in the parent segment's frame (x forward, y left, z up), metres
RIG = {"neck": [0.0, 0.0, 0.066], "left_hip": [-0.05, 0.0, 0.01], "right_hip": [-0.05, 0.0, 0.01],
       "left_knee": [0.0, 0.01, 0.02], "right_knee": [0.0, -0.01, 0.02], "pelvis": [-0.035, 0.0, -0.03]}


def _rig_markers(model, X, offsets):
    """The rig's points for poses X: each marker joint moved by its offset in its parent segment's frame."""
    R, P, _ = joint_frames(model, X)
    names = [model.joint_names[j] for j in model.markers]
    T = P[:, model.markers].copy()
    for m, n in enumerate(names):
        if n in offsets:
            p, _ = segment_of(model, n)
            T[:, m] += R[:, p] @ np.asarray(offsets[n])
    return names, T


def _run(motion, seed, model=None, noise=0.0):
    model = model or make_model(39)
    X = generate_motion(motion, model, duration_s=1.0, fps=15, rng=np.random.default_rng(seed))
    names, T = _rig_markers(model, X, RIG)
    T = T + np.random.default_rng(seed + 100).normal(0, noise, T.shape)
    return model, X, names, T


def test_fit_recovers_body_fixed_offsets_and_maps_a_held_out_motion():
    train = [_run("walk", 1, noise=0.003), _run("jog", 2, noise=0.003)]
    jm = fit_joint_map(train, rig="test rig")
    for n, o in RIG.items():
        np.testing.assert_allclose(jm.offset(n), o, atol=2e-3)
    model, X, names, T = _run("walk_turns", 3)          # not fitted on: a turning body
    sc = score_markers(model, X, names, T, joint_map=jm)
    assert sc["mpjpe_mm"] > 10.0
    assert sc["mapped_mpjpe_mm"] < 1.5
    assert sc["mapped_knee_rmse_deg"] < 0.3 < sc["knee_rmse_deg"]
    assert sc["joint_map"] == "test rig"


def test_a_zero_map_scores_like_the_raw_joints():
    model, X, names, T = _run("walk", 4)
    sc = score_markers(model, X, names, T, joint_map=JointMap(offsets={}))
    assert sc["mapped_mpjpe_mm"] == pytest.approx(sc["mpjpe_mm"], abs=1e-9)
    assert sc["mapped_knee_rmse_deg"] == pytest.approx(sc["knee_rmse_deg"], abs=1e-9)


def test_scaled_map_follows_the_segment_length():
    """Offsets proportional to the segment (a longer thigh moves the knee's point further): a scaled map fitted
    on one body maps another body's points exactly, a metric one does not."""
    small = make_model(39)
    big_shape = {**small.shape, "offsets": {**small.shape["offsets"]}}
    big_shape["offsets"]["left_knee"] = [0.0, 0.0, -0.52]
    big_shape["offsets"]["right_knee"] = [0.0, 0.0, -0.52]
    big = make_model(39, shape=big_shape)
    u = np.array([0.0, 0.0, 0.1])                          # a tenth of the thigh, along it
    Xs = generate_motion("walk", small, duration_s=1.0, fps=15, rng=np.random.default_rng(5))
    Xb = generate_motion("walk", big, duration_s=1.0, fps=15, rng=np.random.default_rng(6))
    rs = {n: u * segment_of(small, n)[1] for n in ("left_knee", "right_knee")}
    rb = {n: u * segment_of(big, n)[1] for n in ("left_knee", "right_knee")}
    ns, Ts = _rig_markers(small, Xs, rs)
    nb, Tb = _rig_markers(big, Xb, rb)
    scaled = fit_joint_map([(small, Xs, ns, Ts)], scaled=True)
    metric = fit_joint_map([(small, Xs, ns, Ts)], scaled=False)
    i = nb.index("left_knee")
    assert np.abs(mapped_markers(scaled, big, Xb, ["left_knee"])[:, 0] - Tb[:, i]).max() < 1e-9
    assert np.abs(mapped_markers(metric, big, Xb, ["left_knee"])[:, 0] - Tb[:, i]).max() > 5e-3


def test_save_load_round_trip_and_bad_files(tmp_path):
    jm = fit_joint_map([_run("walk", 7)], rig="r", source={"runs": ["a"]})
    p = tmp_path / "m.yaml"
    save_joint_map(jm, p)
    back = load_joint_map(p)
    assert back.rig == "r" and back.source == {"runs": ["a"]} and not back.scaled
    for n in RIG:
        np.testing.assert_allclose(back.offset(n), jm.offset(n), atol=1e-5)
    p.write_text("offsets:\n  neck: [0.0, 1.0]\n")
    with pytest.raises(JointMapError, match=r"m.yaml: offsets.neck: expected three finite numbers"):
        load_joint_map(p)
    with pytest.raises(JointMapError, match=r"missing.yaml: cannot read it"):
        load_joint_map(tmp_path / "missing.yaml")
    with pytest.raises(JointMapError, match=r"no joint 'tail'"):
        mapped_markers(jm, make_model(39), np.zeros((1, 39)), ["tail"])


def test_shipped_mesh_rig_map_covers_the_markers():
    jm = mesh_rig_map()
    model = make_model(39)
    names = [model.joint_names[j] for j in model.markers]
    assert set(jm.offsets) == set(names)
    assert jm.source.get("fitted_on"), "the shipped map says what it was fitted on"
    # symmetric: the right side mirrors the left (y negated)
    for n in names:
        if n.startswith("left_"):
            np.testing.assert_allclose(jm.offset("right_" + n[5:]), jm.offset(n) * [1, -1, 1], atol=1e-5)
    P = mapped_markers(jm, model, model.rest_pose()[None], names)
    assert np.all(np.linalg.norm(P[0] - joint_positions(model, model.rest_pose())[0, model.markers], axis=1) < 0.12)
