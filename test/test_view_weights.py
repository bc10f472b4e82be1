"""Views counted by what they see: ``gate.visible_shares`` and the tracker's ``view_weights``."""
import numpy as np
import pytest

from isa_mocap_ros.body import capsule_endpoints, make_model
from isa_mocap_ros.tracking import Tracker, TrackerConfig, TrackerError
from isa_mocap_ros.tracking.gate import visible_shares
from isa_mocap_ros.vision import Camera, default_rig, render_mask


@pytest.fixture(scope="module")
def rig():
    model = make_model(39)
    cams = list(default_rig().cameras)
    x = model.rest_pose()
    x[model.knee_dofs[0]] = 0.6
    return model, cams, x


def _masks(model, cams, x):
    return [render_mask(c, capsule_endpoints(model, x)[0], model.capsule_radii) for c in cams]


def test_visible_shares_whole_partial_gone_and_behind(rig):
    model, cams, x = rig
    np.testing.assert_array_equal(visible_shares(model, cams, x), np.ones(4))
    side = x.copy()
    side[0] += 2.2                      # out through the border of views 0 and 3
    w = visible_shares(model, cams, side)
    assert np.all(w[[1, 2]] == 1.0) and np.all((w[[0, 3]] > 0.1) & (w[[0, 3]] < 0.5)), w
    # against the exact silhouette at full size on a canvas 3x as wide and high (image in the middle)
    c = cams[0]
    K = c.K.copy()
    K[0, 2] += c.width
    K[1, 2] += c.height
    big = Camera(c.name, 3 * c.width, 3 * c.height, K, c.dist, c.R, c.t)
    m = render_mask(big, capsule_endpoints(model, side)[0], model.capsule_radii) > 0
    exact = m[c.height:2 * c.height, c.width:2 * c.width].sum() / m.sum()
    assert abs(w[0] - exact) < 0.03, (w[0], exact)
    # the canvases are made once per camera and scale: a finer scale is its own canvas, closer still
    fine = visible_shares(model, cams, side, scale=0.5)
    assert abs(fine[0] - exact) < 0.03 and fine[0] != w[0], (fine[0], w[0], exact)
    np.testing.assert_array_equal(visible_shares(model, cams, side), w)
    far = x.copy()
    far[0] += 6.0
    assert np.all(visible_shares(model, cams, far)[[0, 3]] == 0.0)
    behind = x.copy()
    behind[:3] = cams[0].center        # the body around camera 0: nothing bounded in front of it
    assert visible_shares(model, cams[:1], behind)[0] < 0.5


def test_the_tracker_weighs_the_views_by_the_predicted_share(rig):
    """With an estimate, the energy gets ``visible_shares`` of the prediction (a constant-pose
    prediction from one estimate: the pose itself) as Eq. 5's weights; ``view_weights=False``: none."""
    model, cams, x = rig
    side = x.copy()
    side[0] += 2.1
    masks = _masks(model, cams, side)
    cfg = dict(evals=200, contour_iterations=0, contour_extra_iterations=0, limb_proposals=0)
    for on in (True, False):
        tr = Tracker(model, cams, TrackerConfig.from_flat(view_weights=on, **cfg))
        tr.initialize(pose=side)
        res = tr.step(masks, 1)
        assert not res.fell_back
        got = tr.energy._frame["view_w"]
        if on:
            want = visible_shares(model, cams, side)
            assert np.all(want[[0, 3]] < 0.9) and np.all(want[[1, 2]] == 1.0), want
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        else:
            np.testing.assert_array_equal(got, np.ones(4))


def test_an_empty_mask_where_the_body_is_predicted_does_not_drop_the_frame(rig):
    """The only view that sees the predicted body has an empty mask (the others see none of it): the
    views left are counted alike instead of the energy rejecting the weights."""
    model, cams, x = rig
    side = x.copy()
    side[0] += 2.7
    w = visible_shares(model, cams, side)
    assert w[0] == 0.0 and w[3] == 0.0 and w[1] > 0 and w[2] > 0, w
    masks = _masks(model, cams, x)
    masks[1] = np.zeros_like(masks[1])
    masks[2] = np.zeros_like(masks[2])
    tr = Tracker(model, cams, TrackerConfig.from_flat(evals=200, contour_iterations=0, contour_extra_iterations=0,
                                            limb_proposals=0, gate_margin_px=0, hull_filter=False))
    tr.initialize(pose=side)
    res = tr.step(masks, 1)
    assert not res.fell_back and res.views_used == 2, res.notes
    np.testing.assert_array_equal(tr.energy._frame["view_w"], np.ones(2))


def test_views_that_see_the_whole_body_change_nothing(rig):
    """Every view sees the whole person: the weights are all 1 and the estimates equal, bit for bit."""
    model, cams, x = rig
    masks = _masks(model, cams, x)
    cfg = dict(evals=200, contour_iterations=0, contour_extra_iterations=0, limb_proposals=0)
    out = []
    for on in (True, False):
        tr = Tracker(model, cams, TrackerConfig.from_flat(view_weights=on, **cfg))
        tr.initialize(pose=x)
        out.append([tr.step(masks, k).x for k in (1, 2)])
        np.testing.assert_array_equal(tr.energy._frame["view_w"], np.ones(4))
    np.testing.assert_array_equal(np.array(out[0]), np.array(out[1]))


def test_config_checks_view_weights():
    with pytest.raises(TrackerError, match="view_weights: expected true or false"):
        TrackerConfig.from_flat(view_weights="yes")
