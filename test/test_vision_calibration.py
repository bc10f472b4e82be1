"""Calibration files (camera_calibration YAML + extrinsics), rigs and the default rig."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from isa_mocap_ros.vision import (Camera, Rig, VisionError, default_rig, load_camera, load_rig, look_at, ring_rig,
                                  save_camera, save_rig)
from isa_mocap_ros.vision.calibration import camera_to_dict, rig_dir

from test_vision_camera import random_camera

# A monocular file as camera_calibration's ost.yaml writes it (ROS 2 Jazzy, image_pipeline).
OST_YAML = """\
image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [430.15433, 0.0, 311.71434, 0.0, 430.0, 221.0, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.337568, 0.098646, 0.000000, 0.000000, 0.000000]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
projection_matrix:
  rows: 3
  cols: 4
  data: [329.7, 0.0, 308.6, 0.0, 0.0, 379.1, 219.6, 0.0, 0.0, 0.0, 1.0, 0.0]
"""


@pytest.mark.parametrize("n_dist", [0, 5, 8])
def test_camera_file_round_trip(tmp_path, n_dist):
    rng = np.random.default_rng(20 + n_dist)
    cam = random_camera(rng, n_dist=n_dist, name="cam7")
    # small numbers whose repr has no '.', which YAML 1.1 would read back as strings
    cam = Camera(cam.name, cam.width, cam.height, cam.K, np.full(n_dist, 1e-5) if n_dist else [], cam.R, cam.t)
    path = tmp_path / "cam7.yaml"
    save_camera(cam, path)
    back = load_camera(path)
    assert back == cam
    assert np.array_equal(back.dist, cam.dist if n_dist else np.zeros(5))


def test_camera_file_is_camera_calibration_yaml(tmp_path):
    cam = look_at([3, 2, 2.5], [0, 0, 1], width=640, height=480, name="cam0", dist=[-0.2, 0.05, 0.001, -0.001, 0.0])
    path = tmp_path / "cam0.yaml"
    save_camera(cam, path)
    d = yaml.safe_load(path.read_text())
    ost = yaml.safe_load(OST_YAML)
    assert set(ost) <= set(d)  # every key of the stock file, plus extrinsics
    assert set(d) - set(ost) == {"extrinsics"}
    for key in ost:
        assert type(d[key]) is type(ost[key]), key
        if isinstance(ost[key], dict):
            assert set(d[key]) == {"rows", "cols", "data"}
            assert len(d[key]["data"]) == d[key]["rows"] * d[key]["cols"]
            assert all(isinstance(x, float) for x in d[key]["data"])
    assert (d["image_width"], d["image_height"], d["camera_name"]) == (640, 480, "cam0")
    assert d["distortion_model"] == "plumb_bob"
    np.testing.assert_array_equal(np.reshape(d["camera_matrix"]["data"], (3, 3)), cam.K)
    np.testing.assert_array_equal(np.reshape(d["projection_matrix"]["data"], (3, 4))[:, :3], cam.K)
    np.testing.assert_array_equal(np.reshape(d["extrinsics"]["R"], (3, 3)), cam.R)
    assert d["extrinsics"]["parent_frame"] == "world"


def test_load_stock_camera_calibration_file(tmp_path):
    path = tmp_path / "ost.yaml"
    path.write_text(OST_YAML)
    with pytest.raises(VisionError, match="extrinsics: missing"):
        load_camera(path)
    cam = load_camera(path, require_extrinsics=False)
    assert (cam.name, cam.width, cam.height) == ("narrow_stereo", 640, 480)
    assert cam.fx == pytest.approx(430.15433) and cam.cy == pytest.approx(221.0)
    np.testing.assert_allclose(cam.dist, [-0.337568, 0.098646, 0, 0, 0])
    np.testing.assert_array_equal(cam.R, np.eye(3))


@pytest.mark.parametrize("edit,match", [
    (lambda d: d.pop("camera_matrix"), "camera_matrix: missing"),
    (lambda d: d["camera_matrix"].update(rows=2), "camera_matrix: expected rows"),
    (lambda d: d["camera_matrix"].update(data=[0.0] * 9), "K: expected fx"),
    (lambda d: d.update(distortion_model="equidistant"), "distortion_model: expected 'plumb_bob'"),
    (lambda d: d["extrinsics"].update(R=[0.0] * 9), "R: expected an orthonormal rotation"),
    (lambda d: d["extrinsics"].update(R=[1.0, 0, 0]), r"extrinsics.R: expected 9 numbers"),
    (lambda d: d["extrinsics"].update(t=["a", 0, 0]), r"extrinsics.t: expected a list of numbers"),
    (lambda d: d["extrinsics"].update(parent_frame="map"), "parent_frame: expected 'world'"),
    (lambda d: d.update(image_width=-3), "width: expected a positive integer"),
])
def test_bad_camera_file(tmp_path, edit, match):
    d = camera_to_dict(look_at([3, 0, 2], [0, 0, 1]))
    edit(d)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(d))
    with pytest.raises(VisionError, match=match) as info:
        load_camera(path)
    assert "bad.yaml" in str(info.value)


def test_missing_or_broken_file(tmp_path):
    with pytest.raises(VisionError, match="cannot read"):
        load_camera(tmp_path / "nope.yaml")
    (tmp_path / "x.yaml").write_text("a: [1, 2\n")
    with pytest.raises(VisionError, match="not valid YAML"):
        load_camera(tmp_path / "x.yaml")


def test_rig_round_trip(tmp_path):
    rng = np.random.default_rng(4)
    rig = ring_rig(3, radius_m=4.0, height_m=2.2, width=200, height=150)
    cams = list(rig.cameras)
    c = cams[1]
    cams[1] = Camera(c.name, c.width, c.height, c.K, rng.normal(size=5) * 0.01, c.R, c.t)
    rig = Rig(tuple(cams), "lab")
    save_rig(rig, tmp_path / "lab.yaml")
    back = load_rig(tmp_path / "lab.yaml")
    assert back == rig
    assert back.name == "lab" and len(back) == 3


def test_default_rig_sanity():
    rig = default_rig()
    assert len(rig) == 4 and rig.name == "default_4cam"
    centre = np.array([0.0, 0.0, 1.0])
    for cam in rig:
        assert (cam.width, cam.height) == (320, 240)
        assert cam.center[2] == pytest.approx(2.5, abs=0.3)
        horiz = np.hypot(*cam.center[:2])
        assert 2.0 < horiz < 5.0  # around a ~4 m capture area
        uv = cam.project(centre)
        assert cam.depth(centre) > 0
        np.testing.assert_allclose(uv, [(cam.width - 1) / 2, (cam.height - 1) / 2], atol=2.0)
        # a 1.8 m person standing at the centre is fully in view
        assert np.all(cam.in_image([[0, 0, 0], [0, 0, 1.8]], margin=-5))
    # views from different directions (not all from one side)
    dirs = np.array([c.R[2][:2] / np.linalg.norm(c.R[2][:2]) for c in rig])
    assert np.linalg.norm(dirs.sum(axis=0)) < 0.5
    assert (rig_dir() / "default_4cam.yaml").exists()


def test_default_rig_sizes_and_counts():
    big = default_rig(width=640, height=480)
    small = default_rig()
    P = np.array([[0.3, -0.2, 1.4], [0.0, 0.0, 0.1]])
    for a, b in zip(big, small):
        np.testing.assert_allclose(a.project(P), 2 * (b.project(P) + 0.5) - 0.5, atol=1e-9)
    two = default_rig(n_views=2)
    assert [c.name for c in two] == ["cam0", "cam1"]
    assert two[0] == small[0]
    six = default_rig(n_views=6)
    assert len(six) == 6 and len({c.name for c in six}) == 6
    for cam in six:
        np.testing.assert_allclose(cam.center[2], small[0].center[2])
    with pytest.raises(VisionError, match="n_views"):
        default_rig(n_views=0)
    with pytest.raises(VisionError, match="width"):
        default_rig(width=0)


def test_rig_rejects_camera_that_sees_nothing(tmp_path):
    good = ring_rig(2)
    away = look_at([3, 0, 2.5], [10, 0, 2.5], name="away")  # looking out of the room
    with pytest.raises(VisionError, match=r"cameras\[away\]: sees nothing of the capture volume"):
        Rig((good[0], away), "bad")
    # the same through a rig file, with the file named in the message
    d = {"rig_name": "bad", "cameras": [camera_to_dict(good[0]), camera_to_dict(away)]}
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(d))
    with pytest.raises(VisionError, match="bad.yaml.*sees nothing"):
        load_rig(tmp_path / "bad.yaml")
    # with no capture volume the check is off
    assert len(Rig((good[0], away), "free", None)) == 2


def test_rig_file_with_singular_rotation(tmp_path):
    d = {"rig_name": "bad", "cameras": [camera_to_dict(c) for c in ring_rig(2)]}
    d["cameras"][1]["extrinsics"]["R"] = [1.0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(d))
    with pytest.raises(VisionError, match=r"cameras\[1\] \(cam1\): R: expected an orthonormal rotation"):
        load_rig(tmp_path / "bad.yaml")


def test_rig_bad_input(tmp_path):
    cam = ring_rig(1)[0]
    with pytest.raises(VisionError, match="distinct camera names"):
        Rig((cam, cam))
    with pytest.raises(VisionError, match="cameras: expected a non-empty"):
        Rig(())
    with pytest.raises(VisionError, match=r"cameras\[0\]: expected a Camera"):
        Rig(("cam0",))
    with pytest.raises(VisionError, match="capture_volume"):
        Rig((cam,), "r", [[1, 1, 1], [0, 0, 0]])
    (tmp_path / "r.yaml").write_text("rig_name: x\ncameras: []\n")
    with pytest.raises(VisionError, match="cameras: expected a non-empty list"):
        load_rig(tmp_path / "r.yaml")
    with pytest.raises(VisionError, match="rig: expected a Rig"):
        save_rig([cam], tmp_path / "s.yaml")
