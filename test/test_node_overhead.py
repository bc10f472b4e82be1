"""The network's CPU savings outside the tracker keep results identical (docs/nodes.md, "Where the CPU goes")."""
from __future__ import annotations

import array

import cv2
import numba
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo

from isa_mocap_ros.body import joint_positions, make_model
from isa_mocap_ros.nodes.common import one_numba_thread
from msg_adapters.camera_info import camera_info_key as _camera_info_key
from isa_mocap_ros.vision.segmentation import clean_mask


def _clean_mask_reference(mask, *, open_kernel, close_kernel, min_blob_area_px):
    """clean_mask as it was: always relabel."""
    el = lambda k: cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))  # noqa: E731
    out = cv2.threshold(mask, 0, 255, cv2.THRESH_BINARY)[1]
    out = cv2.morphologyEx(out, cv2.MORPH_OPEN, el(open_kernel))
    out = cv2.morphologyEx(out, cv2.MORPH_CLOSE, el(close_kernel))
    n, labels = cv2.connectedComponents(out, connectivity=8)
    if n > 1:
        keep = np.bincount(labels.ravel(), minlength=n) >= min_blob_area_px
        keep[0] = False
        out = np.take(np.where(keep, np.uint8(255), np.uint8(0)), labels)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_clean_mask_equals_the_always_relabelling_version(seed):
    rng = np.random.default_rng(seed)
    mask = np.zeros((120, 160), np.uint8)
    cv2.ellipse(mask, (80, 60), (20, 45), 0, 0, 360, 255, -1)            # a person: always kept
    for _ in range(seed):                                                # 0..5 blobs, some too small
        x, y, r = rng.integers(5, 150), rng.integers(5, 110), rng.integers(1, 8)
        cv2.circle(mask, (int(x), int(y)), int(r), 255, -1)
    mask[rng.random(mask.shape) < 0.01 * seed] = 255                     # speckle
    for area in (1, 50, 400):
        kw = dict(open_kernel=3, close_kernel=3, min_blob_area_px=area)
        assert np.array_equal(clean_mask(mask, **kw), _clean_mask_reference(mask, **kw))


def test_one_numba_thread_gives_identical_positions_and_restores_the_thread_count():
    model = make_model(39)
    rng = np.random.default_rng(0)
    X = model.rest_pose()[None] + rng.normal(0, 0.2, (8, model.dof))
    ref = [joint_positions(model, x[None]) for x in X]
    n = numba.get_num_threads()
    with one_numba_thread():
        assert numba.get_num_threads() == 1
        got = [joint_positions(model, x[None]) for x in X]
    assert numba.get_num_threads() == n
    assert all(np.array_equal(a, b) for a, b in zip(ref, got))


def _info() -> CameraInfo:
    msg = CameraInfo(width=320, height=240, distortion_model="plumb_bob")
    msg.k = np.array([300.0, 0, 160, 0, 300, 120, 0, 0, 1])
    msg.d = array.array("d", [0.0] * 5)
    msg.r = np.eye(3).ravel()
    msg.p = np.array([300.0, 0, 160, 0, 0, 300, 120, 0, 0, 0, 1, 0])
    return msg


def test_camera_info_key_changes_with_every_field_the_conversion_reads():
    a, b = _info(), _info()
    assert _camera_info_key(a) == _camera_info_key(b)
    changes = [("width", 321), ("height", 241), ("distortion_model", "equidistant")]
    for field, value in changes:
        c = _info()
        setattr(c, field, value)
        assert _camera_info_key(c) != _camera_info_key(a), field
    for field in ("k", "r", "p"):
        c = _info()
        v = np.array(getattr(c, field))
        v[0] += 1e-12
        setattr(c, field, v)
        assert _camera_info_key(c) != _camera_info_key(a), field
    c = _info()
    c.d = array.array("d", [0.0] * 4 + [1e-9])
    assert _camera_info_key(c) != _camera_info_key(a)
