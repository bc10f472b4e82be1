"""PolygonStamped ⇄ per-view keypoints: round trip through CDR bytes, empty = nobody, bad input named."""
from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import Point32, PolygonStamped

import msg_adapters as ma


def test_round_trip_through_cdr_keeps_header_pixels_and_confidences():
    rng = np.random.default_rng(0)
    uv = rng.uniform(-50, 1900, (33, 2))
    c = rng.uniform(0, 1, 33)
    msg = ma.keypoints_to_polygon(uv, c, ma.make_header(1_700_000_000_123_456_789, "cam2_optical_frame"))
    back = ma.from_cdr(ma.to_cdr(msg), "geometry_msgs/msg/PolygonStamped")
    assert ma.stamp_to_ns(back.header) == 1_700_000_000_123_456_789
    assert back.header.frame_id == "cam2_optical_frame"
    got_uv, got_c = ma.polygon_to_keypoints(back)
    np.testing.assert_allclose(got_uv, uv, atol=1e-3)          # float32 on the wire
    np.testing.assert_allclose(got_c, c, atol=1e-7)


def test_empty_polygon_means_nobody():
    msg = ma.keypoints_to_polygon(None, None, ma.make_header(5, "f"))
    assert len(msg.polygon.points) == 0 and ma.polygon_to_keypoints(msg) is None


def test_bad_messages_and_arrays_are_named():
    msg = PolygonStamped()
    msg.polygon.points = [Point32(x=1.0, y=2.0, z=0.5)] * 17
    with pytest.raises(ma.AdapterError, match=r"0 or 33 points.*17 points"):
        ma.polygon_to_keypoints(msg)
    msg.polygon.points = [Point32(x=1.0, y=2.0, z=0.5)] * 32 + [Point32(x=1.0, y=2.0, z=1.5)]
    with pytest.raises(ma.AdapterError, match=r"z of point 32.*\[0, 1\]"):
        ma.polygon_to_keypoints(msg)
    msg.polygon.points = [Point32(x=float("nan"), y=2.0, z=0.5)] + [Point32(x=1.0, y=2.0, z=0.5)] * 32
    with pytest.raises(ma.AdapterError, match=r"points\[0\].*finite"):
        ma.polygon_to_keypoints(msg)
    with pytest.raises(ma.AdapterError, match="PolygonStamped"):
        ma.polygon_to_keypoints("not a message")
    with pytest.raises(ma.AdapterError, match=r"\(N, 2\)"):
        ma.keypoints_to_polygon(np.zeros((33, 3)), np.zeros(33))
    with pytest.raises(ma.AdapterError, match="confidence of point 3"):
        ma.keypoints_to_polygon(np.zeros((33, 2)), np.where(np.arange(33) == 3, -0.1, 0.5))
