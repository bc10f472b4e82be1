"""Fuzzing msg_adapters with hypothesis: random field values raise AdapterError or nothing.

Where an input is valid, the result is also checked against an independent reference (a
row-by-row decoding of images, struct-unpacking of CDR stamps, orthonormality of rotations).
"""
from __future__ import annotations

import array
import math
import struct
from types import SimpleNamespace

import numpy as np
import pytest
from geometry_msgs.msg import TransformStamped
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from sensor_msgs.msg import CameraInfo, Image, JointState

import msg_adapters as ma
from msg_adapters import AdapterError

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FEW = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

encodings = st.one_of(st.sampled_from(sorted(ma.ENCODINGS)),
                      st.sampled_from(["yuv422", "bayer_rggb8", "16SC1", "", "MONO8", "rgb16"]),
                      st.text(max_size=8))
any_value = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(), st.text(max_size=4),
                      st.binary(max_size=8), st.lists(st.integers(-5, 300), max_size=4))
floats_all = st.floats(allow_nan=True, allow_infinity=True, width=64)


def reference_decode(msg: Image) -> np.ndarray:
    """Row-by-row decoding, independent of the adapter's strided view."""
    dtype, c = ma.ENCODINGS[msg.encoding]
    dt = dtype.newbyteorder(">" if msg.is_bigendian else "<")
    raw = bytes(msg.data)
    rows = [np.frombuffer(raw[r * msg.step: r * msg.step + msg.width * dtype.itemsize * c], dtype=dt)
            for r in range(msg.height)]
    out = np.array(rows).astype(dtype)
    return out.reshape((msg.height, msg.width) if c == 1 else (msg.height, msg.width, c))


@st.composite
def images(draw):
    encoding = draw(st.one_of(st.sampled_from(sorted(ma.ENCODINGS)), encodings))
    height = draw(st.integers(0, 9))
    width = draw(st.integers(0, 9))
    bpp = (ma.ENCODINGS[encoding][0].itemsize * ma.ENCODINGS[encoding][1]) if encoding in ma.ENCODINGS else 3
    step = draw(st.one_of(st.just(width * bpp), st.integers(width * bpp, width * bpp + 9),
                          st.integers(0, width * bpp + 9), st.integers(0, 2**32 - 1)))
    exact = height * step if height * step < 4096 else 0
    n = draw(st.one_of(st.just(exact), st.just(exact), st.just(exact), st.integers(0, 600)))
    data = draw(st.binary(min_size=n, max_size=n))
    big = draw(st.one_of(st.integers(0, 1), st.integers(0, 255)))
    msg = Image(height=height, width=width, encoding=encoding, is_bigendian=big, step=step)
    msg.data = array.array("B", data)
    return msg


@FUZZ
@given(images(), st.booleans())
def test_fuzz_image_to_array(msg, copy):
    try:
        out = ma.image_to_array(msg, copy=copy)
    except AdapterError:
        return
    ref = reference_decode(msg)
    assert out.shape == ref.shape and out.dtype == ref.dtype and out.dtype.isnative
    np.testing.assert_array_equal(out, ref)


@FEW
@given(st.fixed_dictionaries({k: any_value for k in ("height", "width", "encoding", "is_bigendian", "step", "data")}))
def test_fuzz_image_to_array_any_field_types(fields):
    try:
        ma.image_to_array(SimpleNamespace(**fields))
    except AdapterError:
        pass


dtypes = st.sampled_from([np.uint8, np.uint16, np.float32, np.float64, np.int8, np.int16, np.int32, np.bool_,
                          np.dtype(">u2"), np.dtype(">f4"), np.complex64])


@FUZZ
@given(st.data())
def test_fuzz_array_to_image(data):
    dtype = data.draw(dtypes)
    shape = data.draw(hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=6))
    arr = data.draw(hnp.arrays(dtype, shape))
    encoding = data.draw(encodings)
    if data.draw(st.booleans()) and arr.ndim >= 2:
        arr = arr[::-1, ::2]
    try:
        msg = ma.array_to_image(arr, encoding, stamp_ns=data.draw(st.integers(-5, 2**64)))
    except AdapterError:
        return
    back = ma.image_to_array(ma.from_cdr(ma.to_cdr(msg), Image))
    np.testing.assert_array_equal(back, arr.reshape(back.shape))


@st.composite
def camera_infos(draw):
    good_k = [draw(st.floats(1, 2000)), 0.0, draw(st.floats(-1e4, 1e4)), 0.0, draw(st.floats(1, 2000)),
              draw(st.floats(-1e4, 1e4)), 0.0, 0.0, 1.0]
    k = draw(st.one_of(st.just(good_k), st.just(good_k), st.lists(floats_all, min_size=9, max_size=9),
                       st.just([0.0] * 9)))
    model = draw(st.one_of(st.sampled_from(["plumb_bob", "rational_polynomial", "equidistant", ""]) , st.text(max_size=6)))
    n_d = draw(st.one_of(st.just(ma.DISTORTION_MODELS.get(model, 5)), st.integers(0, 10)))
    d = draw(st.lists(st.one_of(st.floats(-1, 1), st.floats(-1, 1), floats_all), min_size=n_d, max_size=n_d))
    r = draw(st.one_of(st.just([0.0] * 9), st.just(np.eye(3).reshape(-1).tolist()),
                       st.lists(st.floats(-1, 1), min_size=9, max_size=9),
                       st.lists(floats_all, min_size=9, max_size=9)))
    p = draw(st.one_of(st.just([0.0] * 12), st.lists(st.floats(-1e4, 1e4), min_size=12, max_size=12),
                       st.lists(floats_all, min_size=12, max_size=12)))
    if draw(st.booleans()):  # a plausible calibration, so valid inputs are well explored too
        model = draw(st.sampled_from(["plumb_bob", "rational_polynomial", "equidistant"]))
        k = good_k
        d = draw(st.lists(st.floats(-1, 1), min_size=ma.DISTORTION_MODELS[model], max_size=ma.DISTORTION_MODELS[model]))
        r = draw(st.sampled_from([[0.0] * 9, np.eye(3).reshape(-1).tolist()]))
        p = draw(st.one_of(st.just([0.0] * 12), st.lists(st.floats(-1e4, 1e4), min_size=12, max_size=12)))
    msg = CameraInfo(width=draw(st.integers(0, 5000)), height=draw(st.integers(0, 5000)), distortion_model=model)
    msg.k, msg.r, msg.p = np.array(k), np.array(r), np.array(p)
    msg.d = array.array("d", d)
    return msg


@FUZZ
@given(camera_infos())
def test_fuzz_camera_info(msg):
    try:
        intr = ma.camera_info_to_intrinsics(msg)
    except AdapterError:
        return
    assert np.isfinite(intr.K).all() and intr.K.any() and intr.fx > 0 and intr.fy > 0
    assert intr.D.shape == (ma.DISTORTION_MODELS[intr.distortion_model],)
    again = ma.camera_info_to_intrinsics(ma.from_cdr(ma.to_cdr(ma.intrinsics_to_camera_info(intr)), CameraInfo))
    assert again == intr


@FEW
@given(st.fixed_dictionaries({k: any_value for k in ("width", "height", "distortion_model", "k", "d", "r", "p")}))
def test_fuzz_camera_info_any_field_types(fields):
    try:
        ma.camera_info_to_intrinsics(SimpleNamespace(**fields))
    except AdapterError:
        pass


quat_component = st.one_of(st.floats(-1, 1), floats_all, st.sampled_from([0.0, -0.0, 1e-300, 5e-324, 1e300]))


@FUZZ
@given(st.lists(quat_component, min_size=4, max_size=4), st.lists(floats_all, min_size=3, max_size=3))
def test_fuzz_transform_to_rt(q, t):
    msg = TransformStamped()
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = q
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = t
    try:
        R, tt = ma.transform_to_rt(msg)
    except AdapterError:
        assert not (all(map(math.isfinite, q)) and any(q) and all(map(math.isfinite, t)))
        return
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_array_equal(tt, t)
    R2, _ = ma.transform_to_rt(ma.rt_to_transform(R, tt, parent_frame="a", child_frame="b"))
    np.testing.assert_allclose(R2, R, atol=1e-12)


@FUZZ
@given(hnp.arrays(np.float64, st.sampled_from([(3, 3), (3, 3), (3, 3), (2, 3), (9,), (3, 4)]),
                  elements=st.one_of(st.floats(-10, 10), st.floats(-10, 10), st.floats(-10, 10), floats_all)),
       st.one_of(st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3), st.lists(st.floats(-1e3, 1e3), min_size=3,
                 max_size=3), st.lists(floats_all, min_size=0, max_size=4)),
       st.sampled_from([True, True, False]))
def test_fuzz_rt_to_transform(M, t, make_rotation):
    if make_rotation and M.shape == (3, 3) and np.isfinite(M).all():
        u, _, vt = np.linalg.svd(M)
        M = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt)) or 1.0]) @ vt  # the nearest rotation
    try:
        msg = ma.rt_to_transform(M, t, parent_frame="a", child_frame="b")
    except AdapterError:
        return
    R, tt = ma.transform_to_rt(msg)
    np.testing.assert_allclose(R, M, atol=1e-5)
    np.testing.assert_array_equal(tt, t)


@st.composite
def joint_states(draw):
    names = draw(st.one_of(st.lists(st.sampled_from(["a", "b", "c", "knee", "hip", ""]) | st.text(max_size=3),
                                    max_size=6),
                           st.lists(st.sampled_from(["a", "b", "c", "knee", "hip"]), max_size=5, unique=True)))
    n = draw(st.one_of(st.just(len(names)), st.integers(0, 7)))
    positions = draw(st.lists(st.one_of(st.floats(-4, 4), st.floats(-4, 4), floats_all), min_size=n, max_size=n))
    wanted = draw(st.one_of(st.none(), st.lists(st.sampled_from(names or ["zz"]), max_size=4),
                            st.lists(st.sampled_from(["a", "b", "c", "knee", "hip", "zz"]), max_size=4)))
    return names, positions, wanted


@FUZZ
@given(joint_states())
def test_fuzz_joint_state(case):
    names, positions, wanted = case
    msg = JointState(name=names, position=positions)
    try:
        got_names, got = ma.joint_state_to_arrays(msg, wanted)
    except AdapterError:
        return
    assert np.isfinite(got).all() and len(got_names) == got.size
    table = dict(zip(names, positions))
    assert got.tolist() == [table[n] for n in got_names]
    if len(set(got_names)) == len(got_names):
        msg2 = ma.from_cdr(ma.to_cdr(ma.arrays_to_joint_state(got_names, got)), JointState)
        assert ma.joint_state_to_arrays(msg2)[1].tolist() == got.tolist()


@FEW
@given(any_value, any_value, st.one_of(st.none(), any_value))
def test_fuzz_arrays_to_joint_state(names, positions, velocities):
    try:
        msg = ma.arrays_to_joint_state(names, positions, velocities=velocities)
    except AdapterError:
        return
    assert len(msg.name) == len(msg.position)


@FUZZ
@given(st.one_of(st.integers(0, (2**31 - 1) * 10**9 + 999_999_999), st.integers(-2**70, 2**70), st.floats(),
                 st.booleans(), st.none(), st.text(max_size=3)))
def test_fuzz_stamps(ns):
    try:
        t = ma.ns_to_stamp(ns)
    except AdapterError:
        return
    assert ma.stamp_to_ns(t) == ns


@FEW
@given(st.one_of(st.integers(-2**31, 2**31 - 1), st.integers(-2**40, 2**40)),
       st.one_of(st.integers(0, 10**9 - 1), st.integers(-2**40, 2**40)))
def test_fuzz_stamp_to_ns(sec, nanosec):
    try:
        ns = ma.stamp_to_ns(SimpleNamespace(sec=sec, nanosec=nanosec))
    except AdapterError:
        assert not (-2**31 <= sec < 2**31 and 0 <= nanosec < 10**9)
        return
    assert ns == sec * 10**9 + nanosec


MSG_TYPES = [Image, CameraInfo, JointState, TransformStamped]
cdr_prefix = st.sampled_from([b"", b"\x00\x01\x00\x00", b"\x00\x00\x00\x00", b"\x00\x01"])


@FUZZ
@given(cdr_prefix, st.binary(max_size=200), st.sampled_from(MSG_TYPES))
def test_fuzz_from_cdr_random_bytes(prefix, body, msg_type):
    try:
        msg = ma.from_cdr(prefix + body, msg_type)
    except AdapterError:
        return
    assert isinstance(msg, msg_type)


def _valid_cdr() -> list[bytes]:
    """One serialized message per entry of MSG_TYPES, in that order."""
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    intr = ma.Intrinsics(K=K, D=np.zeros(5), P=np.hstack([K, np.zeros((3, 1))]), R=np.eye(3), width=640, height=480)
    return [
        ma.to_cdr(ma.array_to_image(np.arange(12, dtype=np.uint8).reshape(3, 4), "mono8", stamp_ns=5, frame_id="c")),
        ma.to_cdr(ma.intrinsics_to_camera_info(intr, stamp_ns=3)),
        ma.to_cdr(ma.arrays_to_joint_state(["a", "b"], [1.0, 2.0], stamp_ns=7)),
        ma.to_cdr(ma.rt_to_transform(np.eye(3), np.ones(3), parent_frame="w", child_frame="c", stamp_ns=9)),
    ]


VALID_CDR = _valid_cdr()


@FUZZ
@given(st.sampled_from(range(4)), st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), max_size=4),
       st.one_of(st.just(10_000), st.integers(0, 10_000)), st.one_of(st.none(), st.sampled_from(MSG_TYPES)))
def test_fuzz_from_cdr_mutated_messages(which, edits, cut, msg_type):
    msg_type = msg_type or MSG_TYPES[which]  # often the blob's own type, so mutations get past the parser
    blob = bytearray(VALID_CDR[which])
    for pos, val in edits:
        blob[pos % len(blob)] = val
    blob = bytes(blob[: min(cut, len(blob))])
    try:
        msg = ma.from_cdr(blob, msg_type)
    except AdapterError:
        return
    assert isinstance(msg, msg_type)
    # whatever came out must go through the matching adapter cleanly or with an AdapterError
    adapter = {Image: ma.image_to_array, CameraInfo: ma.camera_info_to_intrinsics,
               JointState: ma.joint_state_to_arrays, TransformStamped: ma.transform_to_rt}[msg_type]
    try:
        adapter(msg)
    except AdapterError:
        pass


@FUZZ
@given(cdr_prefix, st.one_of(st.binary(min_size=8, max_size=20), st.binary(max_size=20),
                             st.builds(lambda s, n, rest: struct.pack("<iI", s, n) + rest,
                                       st.integers(-2**31, 2**31 - 1), st.integers(0, 10**9 - 1), st.binary(max_size=8))))
def test_fuzz_header_stamp_ns_from_cdr(prefix, body):
    data = prefix + body
    try:
        ns = ma.header_stamp_ns_from_cdr(data)
    except AdapterError:
        return
    sec, nanosec = struct.unpack_from("<iI" if data[1] == 1 else ">iI", data, 4)
    assert ns == sec * 10**9 + nanosec and 0 <= nanosec < 10**9


@FEW
@given(st.one_of(any_value, st.text(max_size=30), st.from_regex(r"[a-z_]{1,8}/(msg/)?[A-Z][a-z]{0,8}", fullmatch=True)))
def test_fuzz_message_type(name):
    try:
        cls = ma.message_type(name)
    except AdapterError:
        return
    assert ma.type_name_of(cls).split("/")[-1] == name.split("/")[-1]

