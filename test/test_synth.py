"""`isa-mocap synth`: topics, types, QoS, stamps, images, masks vs ground truth, determinism, bad input."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from isa_mocap_ros.bag import BagReader
from isa_mocap_ros.body import capsule_endpoints, joint_positions, joint_state_to_pose, make_model
from isa_mocap_ros.cli.main import main
from isa_mocap_ros.synth import T0_NS, SceneRenderer, SynthError, make_clip, stamp_ns, synthesize
from isa_mocap_ros.vision import Camera, default_rig, render_mask, save_rig
from isa_mocap_ros.vision.calibration import Rig
from msg_adapters import (camera_info_to_intrinsics, from_cdr, image_to_array, joint_state_to_arrays,
                          stamp_to_ns, transform_to_rt)

TINY = ["--views", "2", "--width", "64", "--height", "48", "--duration-s", "0.1", "--empty-frames", "2",
        "--no-progress"]


def synth(*args) -> int:
    return main(["synth", *[str(a) for a in args]])


def all_messages(path) -> list[tuple[str, int, bytes]]:
    with BagReader(path) as r:
        return [(m.topic, m.log_time_ns, m.data) for m in r.messages()]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synth") / "tiny"
    # the capsule body: these tests check the capsule path exactly (mesh bodies: test_mesh_bodies.py)
    assert synth("walk", out, *TINY, "--masks", "--seed", "5", "--body", "capsules") == 0
    return out


def test_topics_types_counts_qos(tiny):
    with BagReader(tiny) as r:
        topics = r.topics
    expect = {}
    for i in range(2):
        expect[f"/mocap/cam{i}/image_raw"] = ("sensor_msgs/msg/Image", 5)
        expect[f"/mocap/cam{i}/camera_info"] = ("sensor_msgs/msg/CameraInfo", 5)
        expect[f"/mocap/cam{i}/mask"] = ("sensor_msgs/msg/Image", 5)
        expect[f"/mocap/cam{i}/extrinsics"] = ("geometry_msgs/msg/TransformStamped", 1)
    expect["/mocap/ground_truth/joint_states"] = ("sensor_msgs/msg/JointState", 3)
    expect["/mocap/ground_truth/markers"] = ("geometry_msgs/msg/PoseArray", 3)
    expect["/mocap/ground_truth/model"] = ("std_msgs/msg/String", 1)
    assert {n: (t.type, t.message_count) for n, t in topics.items()} == expect
    for name, t in topics.items():
        latched = name.endswith(("/extrinsics", "/model"))
        assert t.latched == latched, name
        assert all(q.reliability == "reliable" for q in t.offered_qos)


def test_stamps_shared_and_images(tiny):
    frames: dict[int, list] = {}
    rig = default_rig(n_views=2, width=64, height=48)
    with BagReader(tiny) as r:
        for m in r.messages():
            msg = from_cdr(m.data, m.type)
            if m.topic.endswith("/model"):
                assert m.log_time_ns == T0_NS
                continue
            stamp = stamp_to_ns(msg.header.stamp)
            assert stamp == m.log_time_ns
            if m.topic.endswith("/extrinsics"):
                i = int(m.topic.split("/")[2][3:])
                R, t = transform_to_rt(msg)
                assert msg.header.frame_id == "world" and msg.child_frame_id == f"cam{i}_optical_frame"
                np.testing.assert_allclose(R, rig[i].R.T, atol=1e-9)          # world <- camera
                np.testing.assert_allclose(t, rig[i].center, atol=1e-9)
                assert stamp == T0_NS
                continue
            frames.setdefault(stamp, []).append((m.topic, msg))
    stamps = sorted(frames)
    assert stamps == [stamp_ns(k, 30.0) for k in range(5)]
    assert stamps[0] == T0_NS and stamps[1] - stamps[0] == 33_333_333
    for k, s in enumerate(stamps):
        topics = sorted(t for t, _ in frames[s])
        n_gt = 0 if k < 2 else 2                                                  # empty frames: no ground truth
        assert len(topics) == 6 + n_gt
        for topic, msg in frames[s]:
            if topic.endswith("/image_raw"):
                assert msg.encoding == "rgb8"
                assert image_to_array(msg).shape == (48, 64, 3)
            elif topic.endswith("/mask"):
                assert msg.encoding == "mono8" and image_to_array(msg).shape == (48, 64)
                assert set(np.unique(image_to_array(msg))) <= {0, 255}
                assert (image_to_array(msg).any()) == (k >= 2)
            elif topic.endswith("/camera_info"):
                i = int(topic.split("/")[2][3:])
                intr = camera_info_to_intrinsics(msg)
                assert (intr.width, intr.height) == (64, 48)
                np.testing.assert_allclose(intr.K, rig[i].K)
                assert msg.header.frame_id == f"cam{i}_optical_frame"


def test_masks_equal_render_of_ground_truth(tiny):
    with BagReader(tiny) as r:
        msgs = [(m.topic, from_cdr(m.data, m.type)) for m in r.messages()]
    text = next(msg.data for t, msg in msgs if t.endswith("/model"))
    desc = yaml.safe_load(text)
    assert desc["model"]["dof"] == 39 and desc["motion"]["name"] == "walk" and desc["sequence"]["seed"] == 5
    model = make_model(39, shape=desc["model"]["shape"])
    assert list(model.dof_names) == desc["model"]["dof_names"]
    rig = default_rig(n_views=2, width=64, height=48)
    masks = {(t, stamp_to_ns(m.header.stamp)): image_to_array(m) for t, m in msgs if t.endswith("/mask")}
    markers = {stamp_to_ns(m.header.stamp): m for t, m in msgs if t.endswith("/markers")}
    n = 0
    for t, js in msgs:
        if not t.endswith("/joint_states"):
            continue
        names, q = joint_state_to_arrays(js)
        assert names == list(model.dof_names)
        X = joint_state_to_pose(model, q)
        s = stamp_to_ns(js.header.stamp)
        E = capsule_endpoints(model, X)[0]
        for i in range(2):
            ref = render_mask(rig[i], E, model.capsule_radii)
            assert ref.any()
            assert np.array_equal(masks[(f"/mocap/cam{i}/mask", s)], ref)
        pa = markers[s]
        assert pa.header.frame_id == "world" and len(pa.poses) == len(model.markers)
        got = np.array([[p.position.x, p.position.y, p.position.z] for p in pa.poses])
        np.testing.assert_allclose(got, joint_positions(model, X)[0, model.markers], atol=1e-9)
        n += 1
    assert n == 3


def test_byte_identical_and_seed_dependent(tiny, tmp_path):
    again = tmp_path / "again"
    assert synth("walk", again, *TINY, "--masks", "--seed", "5", "--body", "capsules") == 0
    assert all_messages(again) == all_messages(tiny)
    other = tmp_path / "other"
    assert synth("walk", other, *TINY, "--masks", "--seed", "6", "--body", "capsules") == 0
    a = {(t, s): d for t, s, d in all_messages(tiny)}
    b = {(t, s): d for t, s, d in all_messages(other)}
    assert a.keys() == b.keys()
    assert a[("/mocap/cam0/image_raw", T0_NS)] != b[("/mocap/cam0/image_raw", T0_NS)]          # background
    s = stamp_ns(4, 30.0)
    assert a[("/mocap/ground_truth/joint_states", s)] != b[("/mocap/ground_truth/joint_states", s)]  # motion


def test_distortions_change_images_not_truth(tmp_path):
    clean, noisy = tmp_path / "clean", tmp_path / "noisy"
    assert synth("box", clean, *TINY, "--masks") == 0
    assert synth("box", noisy, *TINY, "--masks", "--noise", "0.3", "--occluders", "5") == 0
    a = {(t, s): d for t, s, d in all_messages(clean)}
    b = {(t, s): d for t, s, d in all_messages(noisy)}
    for key in a:
        same = a[key] == b[key]
        if key[0].endswith("/image_raw"):
            assert not same
        elif not key[0].endswith("/model"):
            assert same, key
    img = image_to_array(from_cdr(b[("/mocap/cam1/image_raw", T0_NS)], "sensor_msgs/msg/Image"))
    ref = image_to_array(from_cdr(a[("/mocap/cam1/image_raw", T0_NS)], "sensor_msgs/msg/Image"))
    changed = np.any(img != ref, axis=-1).mean()
    assert changed > 0.25            # at least the noise (p = 0.3), plus the rectangles


def test_refuses_to_overwrite(tiny, tmp_path, capsys):
    out = tmp_path / "bag"
    assert synth("wave", out, *TINY) == 0
    before = all_messages(out)
    capsys.readouterr()
    assert synth("wave", out, *TINY, "--seed", "3") == 2
    err = capsys.readouterr().err
    assert "exists" in err and "--overwrite" in err
    assert all_messages(out) == before
    assert synth("wave", out, *TINY, "--seed", "3", "--overwrite") == 0
    assert all_messages(out) != before


def _blind_rig(path: Path) -> None:
    good = default_rig(n_views=2, width=64, height=48)
    c = good[1]
    R = -c.R * np.array([[1], [-1], [1]])          # rows 0 and 2 negated: still a rotation, looking away
    away = Camera(name="cam1", width=c.width, height=c.height, K=c.K, dist=c.dist, R=R, t=-R @ c.center)
    save_rig(Rig((good[0], away), "blind", None), path)


@pytest.mark.parametrize("args,match", [
    (["dance", "OUT"], "motion: expected a BVH file or one of"),
    (["walk", "OUT", "--views", "0"], "--views: expected an integer >= 1"),
    (["walk", "OUT", "--width", "-5"], "--width: expected"),
    (["walk", "OUT", "--noise", "1.5"], "noise: expected a probability"),
    (["walk", "OUT", "--fps", "0"], "fps: expected"),
    (["missing_file.bvh", "OUT"], "no such file"),
    (["walk", "OUT", "--rig", "BLIND"], "sees nothing"),
    (["walk", "OUT", "--rig", "nonexistent_rig.yaml"], "--rig: expected a rig YAML file"),
])
def test_bad_input(tmp_path, capsys, args, match):
    blind = tmp_path / "blind.yaml"
    _blind_rig(blind)
    args = [str(tmp_path / "out") if a == "OUT" else str(blind) if a == "BLIND" else a for a in args]
    assert synth(*args, "--no-progress", "--duration-s", "0.1") == 2
    err = capsys.readouterr().err
    assert match in err
    assert not (tmp_path / "out").exists()


def test_core_frames_and_errors():
    clip = make_clip("wave", duration_s=0.1, seed=1)
    rig = default_rig(n_views=1, width=40, height=30)
    r = SceneRenderer(clip.model, rig, seed=1)
    frames = list(synthesize(clip, r, empty_frames=1))
    assert [f.index for f in frames] == [0, 1, 2, 3] and frames[0].empty and not frames[1].empty
    assert np.array_equal(frames[0].images[0], r.backgrounds[0])          # empty frame = background
    assert frames[2].markers.shape == (len(clip.model.markers), 3)
    for bad, match in ((dict(motion="walk", dof=20), "dof: expected 18, 28 or 39"),
                       (dict(motion="walk", seed=-1), "seed: expected an integer >= 0"),
                       (dict(motion="walk", duration_s=0), "duration_s: expected")):
        with pytest.raises(SynthError, match=match):
            make_clip(**bad)


def test_bvh_input(cmu_walk, tmp_path):
    out = tmp_path / "bvh"
    assert synth(cmu_walk, out, "--views", "2", "--width", "64", "--height", "48", "--start-s", "1.0",
                 "--duration-s", "0.5", "--model", "28", "--no-progress", "--masks") == 0
    with BagReader(out) as r:
        counts = {n: t.message_count for n, t in r.topics.items()}
        desc = yaml.safe_load(from_cdr(next(r.messages(["/mocap/ground_truth/model"])).data,
                                       "std_msgs/msg/String").data)
        js = [from_cdr(m.data, m.type) for m in r.messages(["/mocap/ground_truth/joint_states"])]
        masks = [image_to_array(from_cdr(m.data, m.type)) for m in r.messages(["/mocap/cam0/mask"])]
    assert counts["/mocap/ground_truth/joint_states"] == 15 and counts["/mocap/cam0/image_raw"] == 15
    assert desc["motion"]["source"] == str(cmu_walk) and desc["model"]["dof"] == 28
    assert desc["motion"]["params"]["retarget_mean_mm"] < 30
    assert len(js[0].name) == 28
    model = make_model(28, shape=desc["model"]["shape"])
    X = joint_state_to_pose(model, joint_state_to_arrays(js[7])[1])
    assert abs(X[0] - 0.0) < 3.0 and 0.7 < X[2] < 1.3                        # centred, pelvis at hip height
    assert all(m.any() for m in masks)


BAGS = Path(__file__).resolve().parents[1] / "bags"


def test_shipped_bags(tmp_path):
    """bags/: under 25 MB; the fixture is what its recorded command makes (bags/README.md)."""
    total = sum(f.stat().st_size for f in BAGS.rglob("*") if f.is_file())
    assert total < 25e6
    with BagReader(BAGS / "demo") as r:
        counts = {n: t.message_count for n, t in r.topics.items()}
        desc = yaml.safe_load(from_cdr(next(r.messages(["/mocap/ground_truth/model"])).data,
                                       "std_msgs/msg/String").data)
    assert all(counts[f"/mocap/cam{i}/image_raw"] == 145 for i in range(4))
    assert counts["/mocap/ground_truth/joint_states"] == 135 and desc["motion"]["name"] == "walk_turns"
    assert desc["model"]["dof"] == 39 and desc["sequence"]["empty_frames"] == 10
    assert desc["body"]["kind"] == "mesh" and desc["body"]["subject"]["name"] == "average_man"
    assert counts["/mocap/ground_truth/markers"] == 135
    again = tmp_path / "fixture"
    assert synth("walk", again, "--views", "4", "--width", "160", "--height", "120", "--duration-s", "0.4",
                 "--empty-frames", "3", "--masks", "--seed", "0", "--no-progress", "--body", "capsules") == 0
    a, b = all_messages(BAGS / "fixture"), all_messages(again)
    assert [(t, s) for t, s, _ in a] == [(t, s) for t, s, _ in b]
    for (topic, _, da), (_, _, db) in zip(a, b):
        if topic.endswith(("/image_raw", "/mask")):
            ia = image_to_array(from_cdr(da, "sensor_msgs/msg/Image"))
            ib = image_to_array(from_cdr(db, "sensor_msgs/msg/Image"))
            assert ia.shape == ib.shape and np.mean(ia != ib) < 1e-3      # exact here; tolerant across machines
        elif topic.endswith("/joint_states"):
            qa = joint_state_to_arrays(from_cdr(da, "sensor_msgs/msg/JointState"))[1]
            qb = joint_state_to_arrays(from_cdr(db, "sensor_msgs/msg/JointState"))[1]
            np.testing.assert_allclose(qa, qb, atol=1e-9)
