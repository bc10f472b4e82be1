"""Camera node as a real process: frame sets with one stamp, latched extrinsics, file sources, faults."""
from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from geometry_msgs.msg import TransformStamped
from sensor_msgs.msg import CameraInfo, Image

import msg_adapters as ma
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.vision import default_rig, save_rig
from isa_mocap_ros.vision.sources import SyntheticSource
from rosnode import ros_node, spin_until

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]
NODE = ["-m", "isa_mocap_ros.nodes.camera", "--ros-args", "-r", "__ns:=/mocap"]


def write_params(path: Path, **params) -> Path:
    path.write_text(yaml.safe_dump({"/mocap/camera": {"ros__parameters": params}}))
    return path


def test_synthetic_frame_sets_share_one_stamp_and_extrinsics_are_latched(spawn, rosenv, tmp_path):
    p = dict(source="synthetic", motion="walk", motion_duration_s=1.0, model_dof=18, views=2, width=160,
             height=120, fps=20.0, seed=4, empty_frames=2, loop=True)
    cam = spawn("camera", *NODE, "--params-file", str(write_params(tmp_path / "p.yaml", **p)))
    assert cam.wait_for_output("camera: synthetic source", 60), cam.output()
    rig = default_rig(n_views=2, width=160, height=120)
    # The same frames rendered here: every received image must be one of them, both views the same frame.
    ref = SyntheticSource(rig, "walk", fps=20.0, model_dof=18, seed=4, empty_frames=2, duration_s=1.0, loop=False)
    n_ref = ref.empty_frames + ref.clip.n_frames
    index = [{}, {}]
    for k in range(n_ref):
        for v, img in enumerate(ref.read()):
            index[v].setdefault(img.tobytes(), k)
    images: dict[int, dict[int, int]] = {0: {}, 1: {}}
    infos: dict[int, dict[int, CameraInfo]] = {0: {}, 1: {}}
    arrivals = []
    with ros_node(rosenv, "camera_test") as (node, ex):
        def on_image(v):
            def cb(msg):
                img = ma.image_to_array(msg)
                assert msg.encoding == "rgb8" and msg.header.frame_id == f"cam{v}_optical_frame"
                images[v][ma.stamp_to_ns(msg.header)] = index[v].get(img.tobytes(), -1)
                if v == 0:
                    arrivals.append(time.monotonic())
            return cb

        def on_info(v):
            return lambda msg: infos[v].__setitem__(ma.stamp_to_ns(msg.header), msg)

        for v in range(2):
            node.create_subscription(Image, f"/mocap/cam{v}/image_raw", on_image(v), qos.SENSOR_DATA)
            node.create_subscription(CameraInfo, f"/mocap/cam{v}/camera_info", on_info(v), qos.RELIABLE)
        assert spin_until(ex, lambda: len(images[0]) >= 30 and len(images[1]) >= 30, 30), cam.output()
        # A late subscriber still gets the extrinsics published once at start-up.
        ext: dict[str, TransformStamped] = {}
        for v in range(2):
            node.create_subscription(TransformStamped, f"/mocap/cam{v}/extrinsics",
                                     lambda m: ext.__setitem__(m.child_frame_id, m), qos.LATCHED)
        assert spin_until(ex, lambda: len(ext) == 2, 10), ext
    assert cam.popen.poll() is None, cam.output()
    common = sorted(set(images[0]) & set(images[1]))
    assert len(common) >= 25
    for s in common:
        k0, k1 = images[0][s], images[1][s]
        assert k0 >= 0 and k0 == k1, (s, k0, k1)  # one stamp = one rendered frame in every view
    for v in range(2):
        for s in common:
            if s in infos[v]:
                intr = ma.camera_info_to_intrinsics(infos[v][s])
                np.testing.assert_allclose(intr.K, rig.cameras[v].K)
        assert len(set(infos[v]) & set(images[v])) >= 20  # camera_info carries the image's stamp
    for v in range(2):
        R, t = ma.transform_to_rt(ext[f"cam{v}_optical_frame"])
        R_wc, t_wc = rig.cameras[v].pose_in_world()
        np.testing.assert_allclose(R, R_wc, atol=1e-9)
        np.testing.assert_allclose(t, t_wc, atol=1e-9)
        assert ext[f"cam{v}_optical_frame"].header.frame_id == "world"
    rate = (len(arrivals) - 1) / (arrivals[-1] - arrivals[0])
    print(f"camera node: {rate:.1f} frame sets/s received (fps parameter 20)")
    assert cam.stop() == 0
    assert "frame sets published" in cam.output()


def test_image_folder_source_with_rig_file_publishes_the_files(spawn, rosenv, tmp_path):
    rng = np.random.default_rng(11)
    frames = [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8) for _ in range(6)]
    for k, f in enumerate(frames):
        cv2.imwrite(str(tmp_path / f"img_{k:02d}.png"), cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    save_rig(default_rig(n_views=1, width=64, height=48), tmp_path / "rig.yaml")
    params = write_params(tmp_path / "p.yaml", source="images", image_globs=[str(tmp_path / "img_*.png")],
                          rig_file=str(tmp_path / "rig.yaml"), views=1, width=0, height=0, fps=10.0, loop=True)
    cam = spawn("camera", *NODE, "--params-file", str(params))
    assert cam.wait_for_output("camera: images source", 60), cam.output()
    got = []
    with ros_node(rosenv, "camera_test") as (node, ex):
        node.create_subscription(Image, "/mocap/cam0/image_raw",
                                 lambda m: got.append(ma.image_to_array(m, copy=True)), qos.SENSOR_DATA)
        assert spin_until(ex, lambda: len(got) >= 8, 20), cam.output()
    keys = [f.tobytes() for f in frames]
    order = [keys.index(g.tobytes()) for g in got]  # ValueError if an image is not one of the files
    for a, b in zip(order, order[1:]):
        assert b == (a + 1) % len(frames)  # sorted order, looping
    assert cam.stop() == 0


def test_video_source_without_rig_file_is_refused(spawn, tmp_path):
    params = write_params(tmp_path / "p.yaml", source="video", videos=[str(tmp_path / "a.avi")], views=1)
    cam = spawn("camera", *NODE, "--params-file", str(params))
    assert cam.popen.wait(60) == 2
    assert "extrinsics are unknown" in cam.output(), cam.output()


def test_missing_device_is_reported_and_the_node_keeps_running(spawn, rosenv, tmp_path):
    save_rig(default_rig(n_views=2, width=64, height=48), tmp_path / "rig.yaml")
    params = write_params(tmp_path / "p.yaml", source="device", devices=[97, 98], rig_file=str(tmp_path / "rig.yaml"),
                          views=2, width=0, height=0, fps=10.0)
    cam = spawn("camera", *NODE, "--params-file", str(params))
    assert cam.wait_for_output("camera 1 (device 98) cannot open; retrying in", 60), cam.output()
    with ros_node(rosenv, "camera_test") as (node, ex):
        ext = {}
        node.create_subscription(TransformStamped, "/mocap/cam1/extrinsics",
                                 lambda m: ext.__setitem__(m.child_frame_id, m), qos.LATCHED)
        assert spin_until(ex, lambda: ext, 15)  # still serving its calibration
    assert cam.popen.poll() is None
    assert cam.stop() == 0
    out = cam.output()
    assert out.count("camera 0 (device 97) cannot open") <= 3, out  # rate-limited, not one per frame
