"""Unit tests of msg_adapters: round trips for every adapter and every rejection's message."""
from __future__ import annotations

import array
import math
import struct
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Header

import msg_adapters as ma
from msg_adapters import AdapterError

ALL_ENCODINGS = sorted(ma.ENCODINGS)


def random_pixels(encoding: str, h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    dtype, c = ma.ENCODINGS[encoding]
    shape = (h, w) if c == 1 else (h, w, c)
    if dtype.kind == "f":
        return rng.normal(size=shape).astype(dtype)
    return rng.integers(0, np.iinfo(dtype).max, size=shape, endpoint=True).astype(dtype)


def padded_image(arr: np.ndarray, encoding: str, *, pad: int, big: bool) -> Image:
    """An Image built by hand (independently of array_to_image): rows padded with 0xAB bytes."""
    dtype, _ = ma.ENCODINGS[encoding]
    h, w = arr.shape[:2]
    raw = arr.astype(dtype.newbyteorder(">" if big else "<")).reshape(h, -1).view(np.uint8)
    rows = np.concatenate([raw, np.full((h, pad), 0xAB, np.uint8)], axis=1)
    msg = Image(height=h, width=w, encoding=encoding, is_bigendian=int(big), step=rows.shape[1])
    msg.data = array.array("B", rows.tobytes())
    return msg


# ------------------------------------------------------------------------------------ images

@pytest.mark.parametrize("encoding", ALL_ENCODINGS)
def test_image_round_trip_every_encoding(encoding):
    rng = np.random.default_rng(1)
    arr = random_pixels(encoding, 7, 5, rng)
    msg = ma.array_to_image(arr, encoding, stamp_ns=1_500_000_123, frame_id="cam0")
    dtype, c = ma.ENCODINGS[encoding]
    assert (msg.height, msg.width, msg.encoding) == (7, 5, encoding)
    assert msg.step == 5 * dtype.itemsize * c
    assert len(msg.data) == msg.height * msg.step
    assert msg.is_bigendian == int(sys.byteorder == "big")
    assert ma.stamp_to_ns(msg.header) == 1_500_000_123 and msg.header.frame_id == "cam0"
    out = ma.image_to_array(msg)
    assert out.dtype == dtype and out.shape == arr.shape
    np.testing.assert_array_equal(out, arr)


@pytest.mark.parametrize("encoding", ALL_ENCODINGS)
def test_image_to_array_is_a_read_only_view(encoding):
    arr = random_pixels(encoding, 4, 6, np.random.default_rng(2))
    msg = ma.array_to_image(arr, encoding)
    view = ma.image_to_array(msg)
    assert not view.flags.writeable
    assert np.shares_memory(view, np.frombuffer(msg.data, np.uint8))
    with pytest.raises(ValueError):
        view[0, 0] = 0
    copy = ma.image_to_array(msg, copy=True)
    assert copy.flags.writeable and copy.flags.c_contiguous
    assert not np.shares_memory(copy, np.frombuffer(msg.data, np.uint8))
    np.testing.assert_array_equal(copy, arr)


@pytest.mark.parametrize("encoding", ALL_ENCODINGS)
@pytest.mark.parametrize("pad", [1, 3, 64])
def test_image_padded_step_is_a_view_without_padding(encoding, pad):
    arr = random_pixels(encoding, 5, 3, np.random.default_rng(3))
    msg = padded_image(arr, encoding, pad=pad, big=sys.byteorder == "big")
    out = ma.image_to_array(msg)
    np.testing.assert_array_equal(out, arr)
    assert np.shares_memory(out, np.frombuffer(msg.data, np.uint8))
    assert out.strides[0] == msg.step


@pytest.mark.parametrize("encoding", ["mono16", "16UC1", "32FC1"])
@pytest.mark.parametrize("pad", [0, 2, 5])
def test_image_big_and_little_endian_data_decode_to_native(encoding, pad):
    arr = random_pixels(encoding, 6, 4, np.random.default_rng(4))
    for big in (True, False):
        msg = padded_image(arr, encoding, pad=pad, big=big)
        out = ma.image_to_array(msg)
        assert out.dtype == ma.ENCODINGS[encoding][0] and out.dtype.isnative
        np.testing.assert_array_equal(out, arr)
    # the swapped data really differs from a native reading: is_bigendian is what made it right
    msg = padded_image(arr, encoding, pad=pad, big=sys.byteorder != "big")
    msg.is_bigendian = int(sys.byteorder == "big")
    assert not np.array_equal(ma.image_to_array(msg), arr, equal_nan=True)


def test_image_big_endian_32fc1_known_value():
    msg = Image(height=1, width=2, encoding="32FC1", is_bigendian=1, step=8)
    msg.data = array.array("B", struct.pack(">ff", 1.5, -2.25))
    np.testing.assert_array_equal(ma.image_to_array(msg), np.array([[1.5, -2.25]], np.float32))
    msg.is_bigendian = 0
    msg.data = array.array("B", struct.pack("<ff", 1.5, -2.25))
    np.testing.assert_array_equal(ma.image_to_array(msg), np.array([[1.5, -2.25]], np.float32))


def test_image_big_endian_mono16_known_value():
    msg = Image(height=1, width=2, encoding="mono16", is_bigendian=1, step=4)
    msg.data = array.array("B", [0x01, 0x02, 0xFF, 0x00])
    np.testing.assert_array_equal(ma.image_to_array(msg), [[0x0102, 0xFF00]])


def test_image_channel_order_is_the_encoding_order():
    msg = Image(height=1, width=1, encoding="bgr8", step=3)
    msg.data = array.array("B", [10, 20, 30])
    np.testing.assert_array_equal(ma.image_to_array(msg)[0, 0], [10, 20, 30])


def test_array_to_image_accepts_single_channel_3d_and_strided_and_swapped_input():
    rng = np.random.default_rng(5)
    a = random_pixels("mono8", 4, 5, rng)
    np.testing.assert_array_equal(ma.image_to_array(ma.array_to_image(a[:, :, None], "mono8")), a)
    big = random_pixels("rgb8", 6, 8, rng)
    strided = big[::2, ::2]
    assert not strided.flags.c_contiguous
    np.testing.assert_array_equal(ma.image_to_array(ma.array_to_image(strided, "rgb8")), strided)
    f = random_pixels("32FC1", 3, 3, rng)
    swapped = f.astype(f.dtype.newbyteorder())
    np.testing.assert_array_equal(ma.image_to_array(ma.array_to_image(swapped, "32FC1")), f)


def test_empty_image_round_trips():
    for h, w in [(0, 0), (0, 4), (3, 0)]:
        msg = ma.array_to_image(np.zeros((h, w, 3), np.uint8), "rgb8")
        out = ma.image_to_array(msg)
        assert out.shape == (h, w, 3)


def test_image_survives_cdr_round_trip():
    arr = random_pixels("mono16", 9, 11, np.random.default_rng(6))
    msg = ma.array_to_image(arr, "mono16", stamp_ns=42, frame_id="f")
    back = ma.from_cdr(ma.to_cdr(msg), Image)
    np.testing.assert_array_equal(ma.image_to_array(back), arr)


def test_image_accepts_rosbags_style_numpy_data():
    arr = random_pixels("rgb8", 2, 3, np.random.default_rng(7))
    msg = SimpleNamespace(height=2, width=3, encoding="rgb8", is_bigendian=0, step=9, data=arr.reshape(-1))
    np.testing.assert_array_equal(ma.image_to_array(msg), arr)


def _image(**kw):
    fields = dict(height=2, width=3, encoding="mono8", is_bigendian=0, step=3)
    fields.update(kw)
    data = fields.pop("data", bytes(fields["height"] * fields["step"]))
    msg = Image(**fields)
    msg.data = array.array("B", data)
    return msg


@pytest.mark.parametrize("kw, pattern", [
    (dict(encoding="yuv422"), r"Image\.encoding: expected one of mono8.*received 'yuv422'"),
    (dict(encoding=""), r"Image\.encoding: expected one of .*received ''"),
    (dict(data=bytes(5)), r"Image\.data: expected height \* step = 2 \* 3 = 6 bytes, received 5 bytes"),
    (dict(data=bytes(7)), r"Image\.data: expected .* = 6 bytes, received 7 bytes"),
    (dict(step=2, data=bytes(4)), r"Image\.step: expected >= width \* bytes_per_pixel = 3 \* 1 = 3, received 2"),
    (dict(encoding="rgb8", step=8, data=bytes(16)), r"Image\.step: expected >= .* = 3 \* 3 = 9, received 8"),
    (dict(encoding="32FC1", step=11, data=bytes(22)), r"Image\.step: expected >= .* = 3 \* 4 = 12, received 11"),
    (dict(height=0, data=bytes(3)), r"Image\.data: expected height \* step = 0 \* 3 = 0 bytes, received 3"),
    (dict(width=0, step=3), r"Image\.width: expected > 0 for non-empty data, received 0"),
])
def test_image_to_array_rejections_name_the_field(kw, pattern):
    with pytest.raises(AdapterError, match=pattern):
        ma.image_to_array(_image(**kw))


@pytest.mark.parametrize("field, value, pattern", [
    ("height", -1, r"Image\.height: expected an integer in \[0, 4294967295\], received -1"),
    ("width", 2.0, r"Image\.width: expected an integer, received 2\.0"),
    ("step", "3", r"Image\.step: expected an integer, received '3'"),
    ("is_bigendian", None, r"Image\.is_bigendian: expected an integer, received None"),
    ("data", 5, r"Image\.data: expected a bytes-like sequence of uint8, received 'int'"),
    ("data", [1, 2, 300, 4, 5, 6], r"Image\.data: expected a bytes-like sequence of uint8, received 'list'"),
    ("encoding", 8, r"Image\.encoding: expected one of .*received 8"),
])
def test_image_to_array_rejects_wrong_field_types(field, value, pattern):
    fields = dict(height=2, width=3, encoding="mono8", is_bigendian=0, step=3, data=bytes(6))
    fields[field] = value
    with pytest.raises(AdapterError, match=pattern):
        ma.image_to_array(SimpleNamespace(**fields))


def test_image_to_array_accepts_a_list_of_ints_as_data():
    msg = SimpleNamespace(height=1, width=3, encoding="mono8", is_bigendian=0, step=3, data=[1, 2, 3])
    np.testing.assert_array_equal(ma.image_to_array(msg), [[1, 2, 3]])


@pytest.mark.parametrize("arr, encoding, pattern", [
    (np.zeros((2, 2), np.uint8), "jpeg", r"encoding: expected one of .*received 'jpeg'"),
    (np.zeros((2, 2), np.uint16), "mono8", r"arr\.dtype: expected uint8 for encoding 'mono8', received uint16"),
    (np.zeros((2, 2), np.float64), "32FC1", r"arr\.dtype: expected float32 .*received float64"),
    (np.zeros((2, 2), np.int16), "mono16", r"arr\.dtype: expected uint16 .*received int16"),
    (np.zeros((2, 2, 3), np.uint8), "mono8", r"arr\.shape: expected \(H, W\) or \(H, W, 1\) .*received \(2, 2, 3\)"),
    (np.zeros((2, 2), np.uint8), "rgb8", r"arr\.shape: expected \(H, W, 3\) for encoding 'rgb8', received \(2, 2\)"),
    (np.zeros((2, 2, 3), np.uint8), "rgba8", r"arr\.shape: expected \(H, W, 4\) .*received \(2, 2, 3\)"),
    (np.zeros(4, np.uint8), "mono8", r"arr\.shape: expected .*received \(4,\)"),
    ([[1, 2]], "mono8", r"arr: expected a numpy\.ndarray, received 'list'"),
])
def test_array_to_image_rejections(arr, encoding, pattern):
    with pytest.raises(AdapterError, match=pattern):
        ma.array_to_image(arr, encoding)


def test_array_to_image_rejects_bad_header_arguments():
    with pytest.raises(AdapterError, match=r"stamp_ns: expected an integer in \[0, .*received -1"):
        ma.array_to_image(np.zeros((1, 1), np.uint8), "mono8", stamp_ns=-1)
    with pytest.raises(AdapterError, match=r"frame_id: expected a str, received 3"):
        ma.array_to_image(np.zeros((1, 1), np.uint8), "mono8", frame_id=3)


# ------------------------------------------------------------------------------ camera info

def make_intrinsics(model="plumb_bob", rng=None):
    rng = rng or np.random.default_rng(8)
    K = np.array([[rng.uniform(300, 900), 0.0, rng.uniform(300, 340)],
                  [0.0, rng.uniform(300, 900), rng.uniform(220, 260)], [0.0, 0.0, 1.0]])
    D = rng.normal(scale=0.1, size=ma.DISTORTION_MODELS[model])
    P = np.hstack([K, rng.normal(size=(3, 1))])
    R = ma.quaternion_to_matrix(rng.normal(size=4))
    return ma.Intrinsics(K=K, D=D, P=P, R=R, width=640, height=480, distortion_model=model)


@pytest.mark.parametrize("model", ["plumb_bob", "rational_polynomial", "equidistant"])
def test_camera_info_round_trip(model):
    intr = make_intrinsics(model)
    msg = ma.intrinsics_to_camera_info(intr, stamp_ns=7_000_000_001, frame_id="cam1_optical_frame")
    assert msg.distortion_model == model and (msg.width, msg.height) == (640, 480)
    assert list(msg.k) == intr.K.reshape(-1).tolist() and list(msg.d) == intr.D.tolist()
    assert ma.stamp_to_ns(msg.header) == 7_000_000_001
    back = ma.camera_info_to_intrinsics(ma.from_cdr(ma.to_cdr(msg), CameraInfo))
    assert back == intr
    assert back != make_intrinsics(model, np.random.default_rng(99))
    assert (back.fx, back.fy, back.cx, back.cy) == (intr.K[0, 0], intr.K[1, 1], intr.K[0, 2], intr.K[1, 2])


def test_intrinsics_arrays_are_read_only_copies():
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    intr = ma.Intrinsics(K=K, D=[0, 0, 0, 0, 0], P=np.hstack([K, np.zeros((3, 1))]), R=np.eye(3),
                         width=640, height=480)
    K[0, 0] = 1.0
    assert intr.K[0, 0] == 500.0 and intr.D.dtype == np.float64 and intr.distortion_model == "plumb_bob"
    with pytest.raises(ValueError):
        intr.K[0, 0] = 2.0


def test_camera_info_defaults_for_uncalibrated_fields():
    msg = CameraInfo(width=10, height=8, distortion_model="")
    msg.k = np.array([100.0, 0, 5, 0, 100, 4, 0, 0, 1])
    intr = ma.camera_info_to_intrinsics(msg)
    assert intr.distortion_model == "plumb_bob"
    np.testing.assert_array_equal(intr.D, np.zeros(5))
    np.testing.assert_array_equal(intr.R, np.eye(3))
    np.testing.assert_array_equal(intr.P, np.hstack([intr.K, np.zeros((3, 1))]))


def _camera_info(**kw):
    msg = CameraInfo(width=640, height=480, distortion_model="plumb_bob")
    msg.k = np.array([500.0, 0, 320, 0, 500, 240, 0, 0, 1])
    msg.d = array.array("d", [0.1, 0.0, 0.0, 0.0, 0.0])
    msg.r = np.eye(3).reshape(-1)
    msg.p = np.array([500.0, 0, 320, 0, 0, 500, 240, 0, 0, 0, 1, 0])
    for k, v in kw.items():
        setattr(msg, k, v)
    return msg


def _nan_at(values, i):
    v = np.array(values, dtype=float)
    v[i] = np.nan
    return v


@pytest.mark.parametrize("kw, pattern", [
    (dict(k=np.zeros(9)), r"CameraInfo\.k: expected a calibrated camera matrix \(not all zero\), received all zeros"),
    (dict(k=_nan_at([500.0, 0, 320, 0, 500, 240, 0, 0, 1], 2)),
     r"CameraInfo\.k: expected finite numbers, received nan at flat index 2"),
    (dict(k=np.array([-500.0, 0, 320, 0, 500, 240, 0, 0, 1])), r"CameraInfo\.k: expected fx = K\[0,0\] > 0"),
    (dict(k=np.array([500.0, 0, 320, 0, 500, 240, 0, 0, 2])), r"CameraInfo\.k: expected K = \[\[fx, s, cx\]"),
    (dict(d=array.array("d", [0.1, math.inf, 0, 0, 0])), r"CameraInfo\.d: expected finite numbers, received inf"),
    (dict(d=array.array("d", [0.1, 0.2, 0.3])),
     r"CameraInfo\.d: expected 5 coefficients for distortion_model 'plumb_bob', received 3 coefficients"),
    (dict(distortion_model="fisheye"), r"CameraInfo\.distortion_model: expected one of plumb_bob, .*received 'fisheye'"),
    (dict(p=_nan_at(np.zeros(12), 11)), r"CameraInfo\.p: expected finite numbers, received nan at flat index 11"),
    (dict(r=_nan_at(np.eye(3).reshape(-1), 0)), r"CameraInfo\.r: expected finite numbers"),
])
def test_camera_info_rejections(kw, pattern):
    with pytest.raises(AdapterError, match=pattern):
        ma.camera_info_to_intrinsics(_camera_info(**kw))


def test_camera_info_rejects_wrong_sizes_and_types():
    base = dict(width=640, height=480, distortion_model="plumb_bob", k=np.eye(3).reshape(-1),
                d=[0.0] * 5, r=np.eye(3).reshape(-1), p=np.zeros(12))
    with pytest.raises(AdapterError, match=r"CameraInfo\.k: expected 9 numbers, received 8 numbers"):
        ma.camera_info_to_intrinsics(SimpleNamespace(**{**base, "k": np.ones(8)}))
    with pytest.raises(AdapterError, match=r"CameraInfo\.width: expected an integer in \[0, .*received -5"):
        ma.camera_info_to_intrinsics(SimpleNamespace(**{**base, "width": -5}))
    with pytest.raises(AdapterError, match=r"CameraInfo\.p: expected an array of real numbers, received 'abc'"):
        ma.camera_info_to_intrinsics(SimpleNamespace(**{**base, "p": "abc"}))


def test_intrinsics_constructor_rejections():
    good = dict(K=np.diag([5.0, 5.0, 1.0]), D=np.zeros(5), P=np.zeros((3, 4)), R=np.eye(3), width=1, height=1)
    for kw, pattern in [
        (dict(K=np.zeros((3, 3))), r"K: expected a calibrated camera matrix"),
        (dict(K=np.eye(4)), r"K: expected shape \(3, 3\), received shape \(4, 4\)"),
        (dict(D=np.zeros(4)), r"D: expected shape \(5,\) for distortion_model 'plumb_bob', received shape \(4,\)"),
        (dict(P=np.zeros((3, 3))), r"P: expected shape \(3, 4\)"),
        (dict(R=np.full((3, 3), np.inf)), r"R: expected finite numbers"),
        (dict(width=1.5), r"width: expected an integer"),
        (dict(distortion_model="pinhole"), r"distortion_model: expected one of plumb_bob"),
    ]:
        with pytest.raises(AdapterError, match=pattern):
            ma.Intrinsics(**{**good, **kw})
    with pytest.raises(AdapterError, match=r"intr: expected an Intrinsics, received 'dict'"):
        ma.intrinsics_to_camera_info(good)


# -------------------------------------------------------------------------------- transforms

def random_rotation(rng):
    q = rng.normal(size=4)
    return ma.quaternion_to_matrix(q), q


def test_quaternion_to_matrix_is_a_rotation_and_normalises():
    rng = np.random.default_rng(9)
    for _ in range(50):
        R, q = random_rotation(rng)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(ma.quaternion_to_matrix(q * 1e-200), R, atol=1e-12)
        np.testing.assert_allclose(ma.quaternion_to_matrix(q * 1e200), R, atol=1e-12)
        np.testing.assert_allclose(ma.quaternion_to_matrix(-q), R, atol=1e-12)


def test_quaternion_known_value():
    # 90 degrees about z: x -> y
    s = math.sqrt(0.5)
    R = ma.quaternion_to_matrix([0.0, 0.0, s, s])
    np.testing.assert_allclose(R @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)


def test_transform_round_trip_random_and_branch_cases():
    rng = np.random.default_rng(10)
    rotations = [random_rotation(rng)[0] for _ in range(50)]
    rotations += [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]), np.eye(3)]
    rotations += [ma.quaternion_to_matrix([1.0, 1.0, 1e-9, 1e-9])]  # 180 degrees about (1,1,0)
    for R in rotations:
        t = rng.normal(size=3)
        msg = ma.rt_to_transform(R, t, parent_frame="world", child_frame="cam0", stamp_ns=123)
        assert msg.header.frame_id == "world" and msg.child_frame_id == "cam0"
        q = msg.transform.rotation
        assert q.w >= 0 and math.isclose(q.x**2 + q.y**2 + q.z**2 + q.w**2, 1.0, rel_tol=1e-12)
        back = ma.from_cdr(ma.to_cdr(msg), TransformStamped)
        R2, t2 = ma.transform_to_rt(back)
        np.testing.assert_allclose(R2, R, atol=1e-12)
        np.testing.assert_array_equal(t2, t)
        assert ma.stamp_to_ns(back.header) == 123


def test_transform_to_rt_normalises_a_scaled_quaternion():
    R, q = random_rotation(np.random.default_rng(11))
    msg = TransformStamped()
    msg.transform.rotation.x, msg.transform.rotation.y, msg.transform.rotation.z, msg.transform.rotation.w = (
        float(v) for v in 7.0 * q)
    np.testing.assert_allclose(ma.transform_to_rt(msg)[0], R, atol=1e-12)


def test_rt_to_transform_accepts_orthonormal_within_tolerance():
    R = ma.quaternion_to_matrix([0.1, 0.2, 0.3, 0.9])
    ma.rt_to_transform(R * (1 + 2e-7), np.zeros(3), parent_frame="a", child_frame="b")
    with pytest.raises(AdapterError, match=r"R: expected an orthonormal matrix \(max \|R\^T R - I\| <= 1e-06\)"):
        ma.rt_to_transform(R * (1 + 1e-5), np.zeros(3), parent_frame="a", child_frame="b")


@pytest.mark.parametrize("xyzw, pattern", [
    ((0.0, 0.0, 0.0, 0.0), r"TransformStamped\.transform\.rotation: expected a non-zero quaternion"),
    ((0.0, math.nan, 0.0, 1.0), r"TransformStamped\.transform\.rotation: expected finite numbers, received nan"),
    ((0.0, 0.0, math.inf, 1.0), r"TransformStamped\.transform\.rotation: expected finite numbers, received inf"),
])
def test_transform_to_rt_rejects_bad_quaternions(xyzw, pattern):
    msg = TransformStamped()
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = xyzw
    with pytest.raises(AdapterError, match=pattern):
        ma.transform_to_rt(msg)


def test_transform_to_rt_rejects_bad_translation_and_non_transforms():
    msg = TransformStamped()
    msg.transform.translation.y = math.nan
    with pytest.raises(AdapterError, match=r"TransformStamped\.transform\.translation\.y: expected a finite number"):
        ma.transform_to_rt(msg)
    with pytest.raises(AdapterError, match=r"Transform: expected a geometry_msgs/msg/Transform\(Stamped\), received 'Image'"):
        ma.transform_to_rt(Image())


@pytest.mark.parametrize("R, t, pattern", [
    (np.diag([1.0, 1.0, -1.0]), np.zeros(3), r"R: expected a rotation \(det R = \+1\), received det R = -1"),
    (np.ones((3, 3)), np.zeros(3), r"R: expected an orthonormal matrix"),
    (np.eye(2), np.zeros(3), r"R: expected shape \(3, 3\), received shape \(2, 2\)"),
    (np.full((3, 3), np.nan), np.zeros(3), r"R: expected finite numbers"),
    (np.eye(3), np.zeros(4), r"t: expected 3 numbers, received 4 numbers"),
    (np.eye(3), [0.0, np.inf, 0.0], r"t: expected finite numbers, received inf at flat index 1"),
])
def test_rt_to_transform_rejections(R, t, pattern):
    with pytest.raises(AdapterError, match=pattern):
        ma.rt_to_transform(R, t, parent_frame="world", child_frame="cam")


def test_rt_to_transform_rejects_non_str_frames():
    with pytest.raises(AdapterError, match=r"child_frame: expected a str, received None"):
        ma.rt_to_transform(np.eye(3), np.zeros(3), parent_frame="world", child_frame=None)


# ------------------------------------------------------------------------------ joint states

def test_joint_state_round_trip_and_reorder():
    names = ["hip_l", "knee_l", "hip_r", "knee_r"]
    pos = np.array([0.1, -0.2, 0.3, -0.4])
    msg = ma.arrays_to_joint_state(names, pos, stamp_ns=5, frame_id="base", velocities=[1.0, 2.0, 3.0, 4.0])
    assert list(msg.velocity) == [1.0, 2.0, 3.0, 4.0] and len(msg.effort) == 0
    back = ma.from_cdr(ma.to_cdr(msg), JointState)
    got_names, got = ma.joint_state_to_arrays(back)
    assert got_names == names and got.dtype == np.float64
    np.testing.assert_array_equal(got, pos)
    order = ["knee_r", "hip_l", "knee_l"]
    got_names, got = ma.joint_state_to_arrays(back, order)
    assert got_names == order
    np.testing.assert_array_equal(got, [-0.4, 0.1, -0.2])
    got[0] = 99.0  # a new array, not a view of the message
    assert back.position[3] == -0.4


def test_joint_state_without_velocities_and_empty():
    msg = ma.arrays_to_joint_state([], [])
    assert ma.joint_state_to_arrays(msg)[0] == [] and ma.joint_state_to_arrays(msg)[1].shape == (0,)
    assert len(ma.arrays_to_joint_state(["a"], [1.0]).velocity) == 0


def test_joint_state_nan_in_unrequested_joint_is_ignored():
    msg = JointState(name=["a", "b"], position=[1.0, math.nan])
    assert ma.joint_state_to_arrays(msg, ["a"])[1].tolist() == [1.0]
    with pytest.raises(AdapterError, match=r"JointState\.position of joint 'b': expected a finite number, received nan"):
        ma.joint_state_to_arrays(msg)


@pytest.mark.parametrize("name, position, wanted, pattern", [
    (["a", "b"], [1.0], None, r"JointState\.position: expected one value per name \(2\), received 1 values"),
    (["a", "b"], [1.0, math.inf], None, r"JointState\.position of joint 'b': expected a finite number, received inf"),
    (["a", "b"], [1.0, 2.0], ["b", "c"], r"JointState\.name: expected to contain joint 'c'"),
    (["a", "b"], [1.0, 2.0], ["x", "y"], r"JointState\.name: expected to contain joint 'x', .*\(2 wanted joints missing\)"),
    (["a", "a"], [1.0, 2.0], None, r"JointState\.name: expected unique joint names, received 'a' more than once"),
    (["a", "b"], [math.nan, 2.0], ["b", "a"], r"JointState\.position of joint 'a': expected a finite number, received nan"),
])
def test_joint_state_rejections(name, position, wanted, pattern):
    msg = JointState(name=name, position=position)
    with pytest.raises(AdapterError, match=pattern):
        ma.joint_state_to_arrays(msg, wanted)


def test_joint_state_rejects_bad_types():
    with pytest.raises(AdapterError, match=r"JointState\.name\[1\]: expected a str, received 3"):
        ma.joint_state_to_arrays(SimpleNamespace(name=["a", 3], position=[1.0, 2.0]))
    with pytest.raises(AdapterError, match=r"names: expected a sequence of str, received 'ab'"):
        ma.joint_state_to_arrays(JointState(name=["a"], position=[1.0]), "ab")


@pytest.mark.parametrize("names, positions, kw, pattern", [
    (["a", "b"], [1.0], {}, r"positions: expected shape \(2,\) \(one per name\), received shape \(1,\)"),
    (["a", "b"], [1.0, math.nan], {}, r"positions of joint 'b': expected a finite number, received nan"),
    (["a", "a"], [1.0, 2.0], {}, r"names: expected unique joint names, received 'a' more than once"),
    (["a", 5], [1.0, 2.0], {}, r"names\[1\]: expected a str, received 5"),
    (["a"], [1.0], dict(velocities=[1.0, 2.0]), r"velocities: expected shape \(1,\)"),
    (["a"], [1.0], dict(velocities=[math.inf]), r"velocities of joint 'a': expected a finite number, received inf"),
    (["a"], [[1.0]], {}, r"positions: expected shape \(1,\) \(one per name\), received shape \(1, 1\)"),
])
def test_arrays_to_joint_state_rejections(names, positions, kw, pattern):
    with pytest.raises(AdapterError, match=pattern):
        ma.arrays_to_joint_state(names, positions, **kw)


# ----------------------------------------------------------------------------------- stamps

@pytest.mark.parametrize("ns", [0, 1, 999_999_999, 1_000_000_000, 1_700_000_000_123_456_789, (2**31 - 1) * 10**9 + 999_999_999])
def test_stamp_round_trip(ns):
    t = ma.ns_to_stamp(ns)
    assert isinstance(t, Time) and 0 <= t.nanosec < 10**9
    assert ma.stamp_to_ns(t) == ns
    header = ma.make_header(ns, "world")
    assert isinstance(header, Header) and header.frame_id == "world"
    assert ma.stamp_to_ns(header) == ns
    assert ma.stamp_to_ns(ma.from_cdr(ma.to_cdr(header), Header)) == ns


def test_stamp_to_ns_accepts_negative_seconds_of_int32():
    assert ma.stamp_to_ns(Time(sec=-2, nanosec=5)) == -2 * 10**9 + 5


@pytest.mark.parametrize("ns, pattern", [
    (-1, r"stamp_ns: expected an integer in \[0, 2147483647999999999\], received -1"),
    (2**31 * 10**9, r"stamp_ns: expected an integer in \[0, .*received 2147483648000000000"),
    (1.5, r"stamp_ns: expected an integer, received 1\.5"),
    (True, r"stamp_ns: expected an integer, received True"),
])
def test_ns_to_stamp_rejections(ns, pattern):
    with pytest.raises(AdapterError, match=pattern):
        ma.ns_to_stamp(ns)


def test_stamp_to_ns_rejections():
    with pytest.raises(AdapterError, match=r"header\.stamp\.nanosec: expected an integer in \[0, 999999999\], received 1000000000"):
        ma.stamp_to_ns(SimpleNamespace(stamp=SimpleNamespace(sec=1, nanosec=10**9)))
    with pytest.raises(AdapterError, match=r"stamp\.sec: expected an integer in \[-2147483648, 2147483647\]"):
        ma.stamp_to_ns(SimpleNamespace(sec=2**31, nanosec=0))
    with pytest.raises(AdapterError, match=r"stamp: expected a builtin_interfaces/msg/Time or std_msgs/msg/Header, received 'int'"):
        ma.stamp_to_ns(5)


# -------------------------------------------------------------------------------------- CDR

def test_message_type_by_name():
    assert ma.message_type("sensor_msgs/msg/Image") is Image
    assert ma.message_type("sensor_msgs/Image") is Image
    assert ma.message_type("geometry_msgs/msg/PoseStamped") is PoseStamped
    assert ma.type_name_of(Image()) == "sensor_msgs/msg/Image" and ma.type_name_of(JointState) == "sensor_msgs/msg/JointState"
    event = ma.message_type("std_srvs/srv/Trigger_Event")  # Jazzy service introspection topics
    assert ma.type_name_of(event) == "std_srvs/srv/Trigger_Event"
    assert type(ma.from_cdr(ma.to_cdr(event()), "std_srvs/srv/Trigger_Event")) is event


@pytest.mark.parametrize("name, pattern", [
    ("sensor_msgs/msg/NoSuchThing", r"type_name: expected an installed ROS 2 message type, received 'sensor_msgs/msg/NoSuchThing'"),
    ("no_such_pkg/msg/Image", r"type_name: expected an installed ROS 2 message type, received 'no_such_pkg/msg/Image'"),
    ("sensor_msgs/srv/Image", r"type_name: expected an installed ROS 2 message type, received 'sensor_msgs/srv/Image'"),
    ("sensor_msgs/foo/Image", r"type_name: expected 'pkg/msg/Name' or 'pkg/Name', received 'sensor_msgs/foo/Image'"),
    ("std_srvs/srv/Trigger", r"type_name: expected an installed ROS 2 message type, .*\(not a message class\)"),
    ("Image", r"type_name: expected 'pkg/msg/Name'"),
    ("../etc/Passwd", r"type_name: expected 'pkg/msg/Name'"),
    ("sensor_msgs/msg/image_encodings", r"type_name: expected 'pkg/msg/Name'"),
    (None, r"type_name: expected a str"),
])
def test_message_type_rejections(name, pattern):
    with pytest.raises(AdapterError, match=pattern):
        ma.message_type(name)


def test_message_type_rejects_non_message_attributes(monkeypatch):
    monkeypatch.setitem(sys.modules, "fake_adapters_pkg.msg", SimpleNamespace(NotAMessage=int))
    with pytest.raises(AdapterError, match=r"type_name: expected an installed ROS 2 message type, "
                                           r"received 'fake_adapters_pkg/msg/NotAMessage' \(not a message class\)"):
        ma.message_type("fake_adapters_pkg/msg/NotAMessage")


def test_cdr_round_trip_and_input_kinds():
    msg = ma.arrays_to_joint_state(["a", "b"], [1.0, 2.0], stamp_ns=3_000_000_004, frame_id="x")
    data = ma.to_cdr(msg)
    assert isinstance(data, bytes) and data[:2] == b"\x00\x01"
    for blob in (data, bytearray(data), memoryview(data)):
        for t in (JointState, "sensor_msgs/msg/JointState", "sensor_msgs/JointState"):
            assert ma.from_cdr(blob, t) == msg


@pytest.mark.parametrize("data, msg_type, pattern", [
    (b"", Image, r"data: expected at least 4 bytes \(CDR encapsulation header\), received 0 bytes"),
    (b"\x00\x01\x00\x00", Image, r"data: expected a serialized sensor_msgs/msg/Image, received 4 bytes that fail to deserialize"),
    (b"\x07\x01\x00\x00" + bytes(40), Image, r"data encapsulation: expected 00 00 \(CDR_BE\) or 00 01 \(CDR_LE\), received 07 01"),
    (b"\x00\x01\x00\x00" + b"\xff" * 40, CameraInfo, r"data: expected a serialized sensor_msgs/msg/CameraInfo"),
    ("text", Image, r"data: expected bytes, received 'str'"),
    (b"\x00\x01\x00\x00", "nope/msg/Nope", r"type_name: expected an installed ROS 2 message type"),
    (b"\x00\x01\x00\x00", int, r"msg_type: expected an rclpy message class or 'pkg/msg/Name', received <class 'int'>"),
])
def test_from_cdr_rejections(data, msg_type, pattern):
    with pytest.raises(AdapterError, match=pattern):
        ma.from_cdr(data, msg_type)


def test_from_cdr_rejects_truncated_messages():
    data = ma.to_cdr(ma.array_to_image(np.zeros((4, 4), np.uint8), "mono8"))
    for n in (8, 20, len(data) - 1):
        with pytest.raises(AdapterError, match=r"data: expected a serialized sensor_msgs/msg/Image"):
            ma.from_cdr(data[:n], Image)


def test_to_cdr_rejections():
    with pytest.raises(AdapterError, match=r"msg: expected an rclpy message instance, received 'dict'"):
        ma.to_cdr({})
    bad = Image(check_fields=False)
    bad.encoding = 5  # without field checks (the default) rclpy lets this through
    with pytest.raises(AdapterError, match=r"sensor_msgs/msg/Image fields: expected values matching the message definition"):
        ma.to_cdr(bad)


def _header_messages(ns: int):
    yield ma.array_to_image(np.zeros((2, 3), np.uint8), "mono8", stamp_ns=ns, frame_id="cam0")
    yield ma.intrinsics_to_camera_info(make_intrinsics(), stamp_ns=ns, frame_id="cam0_optical_frame")
    yield ma.arrays_to_joint_state(["a", "b"], [0.5, 0.25], stamp_ns=ns)
    yield ma.rt_to_transform(np.eye(3), np.ones(3), parent_frame="world", child_frame="c", stamp_ns=ns)
    yield PoseStamped(header=ma.make_header(ns, "w"))


@pytest.mark.parametrize("ns", [0, 1, 1_700_000_000_123_456_789, (2**31 - 1) * 10**9 + 999_999_999])
def test_header_stamp_fast_path_agrees_with_deserialization(ns):
    for msg in _header_messages(ns):
        data = ma.to_cdr(msg)
        full = deserialize_message(data, type(msg))
        assert ma.header_stamp_ns_from_cdr(data) == ma.stamp_to_ns(full.header) == ns
        assert ma.header_stamp_ns_from_cdr(memoryview(data)) == ns
        assert ma.header_stamp_ns_from_cdr(bytearray(data)) == ns


def test_header_stamp_fast_path_big_endian_and_rejections():
    assert ma.header_stamp_ns_from_cdr(b"\x00\x00\x00\x00" + struct.pack(">iI", 12, 34)) == 12 * 10**9 + 34
    assert ma.header_stamp_ns_from_cdr(b"\x00\x01\x00\x00" + struct.pack("<iI", -1, 5) + b"rest") == -10**9 + 5
    with pytest.raises(AdapterError, match=r"data: expected at least 12 bytes \(encapsulation \+ header\.stamp\), received 11 bytes"):
        ma.header_stamp_ns_from_cdr(b"\x00\x01\x00\x00" + bytes(7))
    with pytest.raises(AdapterError, match=r"data: expected at least 4 bytes .*received 2 bytes"):
        ma.header_stamp_ns_from_cdr(b"\x00\x01")
    with pytest.raises(AdapterError, match=r"data encapsulation: expected 00 00 \(CDR_BE\) or 00 01 \(CDR_LE\), received 00 03"):
        ma.header_stamp_ns_from_cdr(b"\x00\x03\x00\x00" + bytes(8))
    with pytest.raises(AdapterError, match=r"header\.stamp\.nanosec: expected < 1000000000, received 1000000000"):
        ma.header_stamp_ns_from_cdr(b"\x00\x01\x00\x00" + struct.pack("<iI", 0, 10**9))
    with pytest.raises(AdapterError, match=r"data: expected bytes, received 'int'"):
        ma.header_stamp_ns_from_cdr(5)


# ---------------------------------------------------------------------------- house rules

def test_adapter_error_is_a_value_error_with_its_parts():
    err = AdapterError("Image.step", ">= 3", 2)
    assert isinstance(err, ValueError)
    assert (err.field, err.expected, err.received) == ("Image.step", ">= 3", 2)
    assert str(err) == "Image.step: expected >= 3, received 2"
    assert len(str(AdapterError("data", "x", b"\x00" * 10_000))) < 60  # big blobs are summarised


def test_msg_adapters_imports_nothing_from_isa_mocap_ros():
    code = ("import sys, msg_adapters; bad = [m for m in sys.modules if m.startswith('isa_mocap_ros')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def test_joint_names_with_nul_rejected():
    # a NUL ends a ROS string on the wire, so ['', '\x00'] would arrive as two '' (found by the fuzz test)
    with pytest.raises(ma.AdapterError, match=r"names\[1\].*without NUL"):
        ma.arrays_to_joint_state(["", "\x00"], [0.0, 1.0])
    with pytest.raises(ma.AdapterError, match="without NUL"):
        ma.joint_state_to_arrays(JointState(name=["a\x00b"], position=[0.0]))


def test_camera_info_key_tells_equal_camera_infos_apart_from_changed_ones():
    import numpy as np

    import msg_adapters as ma

    intr = ma.Intrinsics(K=np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]]), D=np.zeros(5),
                         P=np.array([[300.0, 0, 160, 0], [0, 300.0, 120, 0], [0, 0, 1, 0]]), R=np.eye(3),
                         width=320, height=240)
    a = ma.intrinsics_to_camera_info(intr, stamp_ns=1, frame_id="cam0_optical_frame")
    b = ma.intrinsics_to_camera_info(intr, stamp_ns=2, frame_id="cam0_optical_frame")   # another stamp only
    assert ma.camera_info_key(a) == ma.camera_info_key(b) is not None
    b.k[0] = 301.0
    assert ma.camera_info_key(a) != ma.camera_info_key(b)
    b = ma.intrinsics_to_camera_info(intr, stamp_ns=2)
    b.width = 640
    assert ma.camera_info_key(a) != ma.camera_info_key(b)
    assert ma.camera_info_key(object()) is None
