"""Keypoint node as a real process: BlazePose landmarks of a rendered person on cam<i>/keypoints on the
frames its schedule picks (the dense start, then every k-th), image and mask paired in either order,
source headers, once both views' pairs of a stamp are in (the estimator's frame set); every other view of a
set (not picked, empty mask) on cam<i>/keypoints_skipped, so each gets exactly one message; a bad mask is dropped
with a line."""
from __future__ import annotations

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PolygonStamped
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

import msg_adapters as ma
from isa_mocap_ros.body import joint_positions
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.synth import SceneRenderer, make_clip
from isa_mocap_ros.vision import default_rig
from isa_mocap_ros.vision.landmarks import LANDMARK_NAMES
from rosnode import ros_node, spin_until

pytestmark = [pytest.mark.ros, pytest.mark.timeout(180)]
NODE = ["-m", "isa_mocap_ros.nodes.keypoints", "--ros-args", "-r", "__ns:=/mocap"]


def test_node_publishes_landmarks_every_k_frames(landmark_model, rosenv, spawn, tmp_path):
    # reliable inputs, as `isa-mocap run --lockstep` sets them (sensor-data QoS drops messages on a loaded machine)
    params = {"views": 2, "every_k_frames": 2, "dense_frames": 1,
              "qos_overrides": {f"/mocap/cam{v}/{t}": {"subscription": {"reliability": "reliable"}}
                                for v in range(2) for t in ("image_raw", "mask", "camera_info")}}
    path = tmp_path / "kp.yaml"
    path.write_text(yaml.safe_dump({"/mocap/keypoints": {"ros__parameters": params}}))
    proc = spawn("keypoints", *NODE, "--params-file", str(path))
    assert proc.wait_for_output("keypoints: 2 views, every 2 frame(s) after the first 1", 90), proc.output()

    rig = default_rig(n_views=2, width=480, height=360)
    clip = make_clip("walk", dof=39, fps=30.0, duration_s=0.2, seed=1)
    renderer = SceneRenderer(clip.model, rig, seed=1)
    J = joint_positions(clip.model, clip.poses)
    names = ["left_shoulder", "right_shoulder", "left_hip", "right_hip", "left_knee", "right_knee"]
    ji = [clip.model.joint_names.index(n) for n in names]
    li = [LANDMARK_NAMES.index(n) for n in names]
    with ros_node(rosenv, "kp_test") as (node, ex):
        img_pubs = [node.create_publisher(Image, f"/mocap/cam{v}/image_raw", qos.RELIABLE) for v in range(2)]
        mask_pubs = [node.create_publisher(Image, f"/mocap/cam{v}/mask", qos.RELIABLE) for v in range(2)]
        info_pubs = [node.create_publisher(CameraInfo, f"/mocap/cam{v}/camera_info", qos.RELIABLE) for v in range(2)]
        K = np.array([[250.0, 0, 240], [0, 250.0, 180], [0, 0, 1]])
        intr = ma.Intrinsics(K=K, D=np.zeros(5), P=np.hstack([K, np.zeros((3, 1))]), R=np.eye(3), width=480, height=360)

        def info(v, stamp):       # the camera's: an image is taken when a camera_info of its stamp agrees
            info_pubs[v].publish(ma.intrinsics_to_camera_info(intr, stamp_ns=stamp, frame_id=f"cam{v}_optical_frame"))
        got: list[dict[int, PolygonStamped]] = [{}, {}]
        skipped: list[list[int]] = [[], []]
        for v in range(2):
            node.create_subscription(PolygonStamped, f"/mocap/cam{v}/keypoints",
                                     lambda m, v=v: got[v].__setitem__(ma.stamp_to_ns(m.header), m), qos.RELIABLE)
            node.create_subscription(Header, f"/mocap/cam{v}/keypoints_skipped",
                                     lambda m, v=v: skipped[v].append(ma.stamp_to_ns(m)), qos.RELIABLE)
        assert spin_until(ex, lambda: all(p.get_subscription_count() > 0 for p in img_pubs + mask_pubs + info_pubs)
                          and all(node.count_publishers(f"/mocap/cam{v}/keypoints") for v in range(2)), 30)
        stamps = []
        for f in range(4):
            images, masks = renderer.render(clip.poses[f], f)
            stamp = 1_700_000_000 * 10**9 + f * 33_333_333
            stamps.append(stamp)
            for v in range(2):
                im = ma.array_to_image(images[v], "rgb8")
                im.header = ma.make_header(stamp, f"cam{v}_optical_frame")
                mk = ma.array_to_image(masks[v], "mono8")
                mk.header = im.header
                first, second = (mask_pubs, img_pubs) if f == 2 else (img_pubs, mask_pubs)   # either order pairs
                info(v, stamp)
                first[v].publish(mk if f == 2 else im)
                spin_until(ex, lambda: False, 0.05)
                second[v].publish(im if f == 2 else mk)
            spin_until(ex, lambda: False, 0.05)
        assert spin_until(ex, lambda: all(len(g) >= 2 for g in got), 120), (got, proc.output())
        # empty masks: "looked, nobody"; then a mask of the wrong size: dropped with a log line
        stamp = stamps[-1] + 10 * 33_333_333
        for v, mask, t in ((0, np.zeros((360, 480), np.uint8), stamp), (1, np.zeros((360, 480), np.uint8), stamp),
                           (1, np.zeros((10, 10), np.uint8), stamp + 33_333_333)):
            im = ma.array_to_image(images[v], "rgb8")
            im.header = ma.make_header(t, f"cam{v}_optical_frame")
            mk = ma.array_to_image(mask, "mono8")
            mk.header = im.header
            info(v, t)
            img_pubs[v].publish(im)
            spin_until(ex, lambda: False, 0.05)
            mask_pubs[v].publish(mk)
        assert spin_until(ex, lambda: stamp in skipped[0] and stamp in skipped[1], 30), proc.output()
        assert proc.wait_for_output("cam1/mask dropped: frame 'cam1_optical_frame', 10x10, is not the view's", 30), \
            proc.output()
        # a NaN camera_info and an image of another encoding: one line each, and the node goes on
        bad = ma.intrinsics_to_camera_info(intr, stamp_ns=stamp + 2 * 33_333_333, frame_id="cam0_optical_frame")
        bad.d = [float("nan")] * 5
        info_pubs[0].publish(bad)
        mono = ma.array_to_image(images[0][:, :, 0].copy(), "mono8", stamp_ns=stamp + 3 * 33_333_333,
                                 frame_id="cam0_optical_frame")
        img_pubs[0].publish(mono)
        assert proc.wait_for_output("cam0/camera_info dropped: CameraInfo.d: expected finite numbers", 30), proc.output()
        last = stamp + 4 * 33_333_333
        for v in range(2):
            im = ma.array_to_image(images[v], "rgb8", stamp_ns=last, frame_id=f"cam{v}_optical_frame")
            mk = ma.array_to_image(masks[v], "mono8", stamp_ns=last, frame_id=f"cam{v}_optical_frame")
            info(v, last)
            img_pubs[v].publish(im)
            spin_until(ex, lambda: False, 0.05)
            mask_pubs[v].publish(mk)
        assert spin_until(ex, lambda: all(last in g for g in got), 60), proc.output()
        assert proc.wait_for_output("encoding 'mono8', the camera's is 'rgb8'", 30), proc.output()
    # the first frame and every 2nd after (0 and 2) per view, with the image's header; 1 and 3 skipped
    for v in range(2):
        assert sorted(got[v]) == [stamps[0], stamps[2], last]      # view 1's 10x10 mask counted nothing
        assert skipped[v] == [stamps[1], stamps[3], stamp]
        assert got[v][stamps[0]].header.frame_id == f"cam{v}_optical_frame"
        for f in (0, 2):
            uv, conf = ma.polygon_to_keypoints(got[v][stamps[f]])
            ref = rig.cameras[v].project(J[f, ji])
            err = np.linalg.norm(uv[li] - ref, axis=1)
            assert np.median(err) < 15.0, err              # pixels, at 480x360
            assert conf.min() >= 0 and conf.max() <= 1 and np.median(conf[li]) > 0.5
    assert all(stamp not in g for g in got)


def test_run_starts_the_keypoint_node_only_when_asked_and_records_its_topic():
    import argparse
    from pathlib import Path

    from isa_mocap_ros.cli.run import RECORDED, _network

    def names(**kw):
        ns = argparse.Namespace(lockstep=True, optimizer=None, evals=None, model=None, seed=None, helper_nice=0, **kw)
        return {s.name: s for s in _network(ns, "p.yaml", Path("out"), 2, None)}

    assert "keypoints" not in names() and "keypoints" not in names(keypoints=False)
    spec = names(keypoints=True)["keypoints"]
    params = dict(spec.params)
    assert spec.exec == "keypoints_node" and params["views"] == "2"
    # lockstep: image and mask subscriptions reliable, as the segmentation's and the estimator's
    assert params["qos_overrides./mocap/cam1/mask.subscription.reliability"] == "reliable"
    assert params["qos_overrides./mocap/cam1/camera_info.subscription.reliability"] == "reliable"
    assert "/mocap/cam*/keypoints" in RECORDED
