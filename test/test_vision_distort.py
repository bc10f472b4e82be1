"""The ISA paper's distortions (§13.4.2): pixel noise p and K occluding rectangles."""
from __future__ import annotations

import numpy as np
import pytest

from isa_mocap_ros.vision import VisionError, make_background, occluders, pixel_noise


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return make_background(320, 240, rng=np.random.default_rng(0))


@pytest.mark.parametrize("p", [0.0, 0.1, 0.5, 0.7, 1.0])
def test_pixel_noise_fraction(image, p):
    out = pixel_noise(image, p, rng=np.random.default_rng(1))
    assert out.shape == image.shape and out.dtype == np.uint8
    changed = np.any(out != image, axis=-1)
    n = changed.size
    # binomial: within 5 standard deviations (a replaced pixel keeps its value with prob. 256^-3)
    assert abs(changed.mean() - p) <= 5 * np.sqrt(p * (1 - p) / n) + 1e-9
    if 0 < p:
        vals = out[changed].astype(float)
        assert vals.mean() == pytest.approx(127.5, abs=2.0)  # uniform on [0, 255]
        assert vals.min() <= 2 and vals.max() >= 253


def test_pixel_noise_per_channel_and_grey(image):
    p = 0.4
    out = pixel_noise(image, p, rng=np.random.default_rng(2), per_channel=True)
    per_chan = (out != image).mean(axis=(0, 1))
    np.testing.assert_allclose(per_chan, p * (1 - 1 / 256), atol=0.01)
    whole = np.all(out != image, axis=-1).mean()
    assert whole < 0.2  # channels decided independently: all three rarely together (0.4^3)
    grey = image[..., 0].copy()
    g = pixel_noise(grey, p, rng=np.random.default_rng(3))
    assert g.shape == grey.shape
    assert (g != grey).mean() == pytest.approx(p * (1 - 1 / 256), abs=0.01)


def test_pixel_noise_deterministic_and_pure(image):
    before = image.copy()
    a = pixel_noise(image, 0.7, rng=np.random.default_rng(9))
    b = pixel_noise(image, 0.7, rng=np.random.default_rng(9))
    c = pixel_noise(image, 0.7, rng=np.random.default_rng(10))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    np.testing.assert_array_equal(image, before)


def test_occluders_rectangles(image):
    out, rects = occluders(image, 35, rng=np.random.default_rng(4), return_rects=True)
    assert rects.shape == (35, 5)
    x, y, w, h, g = rects.T
    assert np.all((w >= 1) & (w <= 40) & (h >= 1) & (h <= 40))
    assert np.all((x >= 0) & (y >= 0) & (x + w <= 320) & (y + h <= 240))
    assert np.all((g >= 0) & (g <= 255))
    assert len(set(w.tolist())) > 10  # random sizes across the range
    # the last rectangle is on top: all its pixels have its grey value on every channel
    xl, yl, wl, hl, gl = rects[-1]
    assert np.all(out[yl:yl + hl, xl:xl + wl] == gl)
    # outside every rectangle nothing changed
    covered = np.zeros((240, 320), bool)
    for xi, yi, wi, hi, _ in rects:
        covered[yi:yi + hi, xi:xi + wi] = True
    np.testing.assert_array_equal(out[~covered], image[~covered])
    assert np.any(out[covered] != image[covered])


def test_occluders_deterministic_and_edge_cases(image):
    a = occluders(image, 35, rng=np.random.default_rng(5))
    b = occluders(image, 35, rng=np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(occluders(image, 0, rng=np.random.default_rng(5)), image)
    tiny = np.zeros((5, 7), np.uint8)
    out, rects = occluders(tiny, 20, rng=np.random.default_rng(6), min_size=1, max_size=40, return_rects=True)
    assert np.all(rects[:, 2] <= 7) and np.all(rects[:, 3] <= 5)
    _, rects = occluders(image, 50, rng=np.random.default_rng(7), min_size=10, max_size=12, return_rects=True)
    assert rects[:, 2:4].min() >= 10 and rects[:, 2:4].max() <= 12


@pytest.mark.parametrize("call,match", [
    (lambda im: pixel_noise(im, 1.5, rng=np.random.default_rng(0)), r"p: expected a probability in \[0, 1\]"),
    (lambda im: pixel_noise(im, -0.1, rng=np.random.default_rng(0)), "p: expected a probability"),
    (lambda im: pixel_noise(im, 0.5, rng=None), "rng: expected a numpy.random.Generator"),
    (lambda im: pixel_noise(im.astype(np.float32), 0.5, rng=np.random.default_rng(0)),
     "img: expected a non-empty uint8"),
    (lambda im: occluders(im, -1, rng=np.random.default_rng(0)), "k: expected an integer >= 0"),
    (lambda im: occluders(im, 3, rng=np.random.default_rng(0), min_size=0), "min_size: expected an integer >= 1"),
    (lambda im: occluders(im, 3, rng=np.random.default_rng(0), min_size=5, max_size=4),
     "max_size: expected >= min_size"),
    (lambda im: occluders(im[0, 0], 3, rng=np.random.default_rng(0)), "img: expected"),
])
def test_distort_bad_input(image, call, match):
    with pytest.raises(VisionError, match=match):
        call(image)
