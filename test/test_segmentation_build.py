"""vision/segmentation_build.py: the background model built a band of rows at a time is bit for bit the model
built in one go, whatever ran before the first image to segment (no step, some, all)."""
import cv2
import numpy as np
import pytest

from isa_mocap_ros.vision.robust_mode import _robust_background_numba
from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig
from isa_mocap_ros.vision.segmentation_build import ModelBuild
from isa_mocap_ros.vision._segmentation_kernels import _fill_from_reliable

H, W, LEARN = 37, 44, 6


def _frames(noise: float, n: int, seed: int = 0):
    """``n`` images of a textured background with camera noise and, with ``noise`` > 0, that share of pixels
    replaced by random colours (the robust mode's case); from frame LEARN on a person-like block."""
    rng = np.random.default_rng(seed)
    bg = rng.integers(30, 220, size=(H, W, 3))
    out = []
    for k in range(n):
        img = np.clip(bg + rng.normal(0, 3, bg.shape), 0, 255).astype(np.uint8)
        if k >= LEARN:
            img[8:30, 12 + k:24 + k] = (240, 30, 200)
        hit = rng.random((H, W)) < noise
        img[hit] = rng.integers(0, 256, size=(int(hit.sum()), 3))
        out.append(img)
    return out


def _one_go(config: SegmentationConfig, images):
    """The model as the segmenter built it in one go before the build was banded: (mu, var, reliable, share)."""
    x = np.stack(images)
    k = len(images)
    total, total_sq = x.sum(axis=0, dtype=np.int64), (x.astype(np.int64) ** 2).sum(axis=0)
    mu = total / k
    var = np.maximum(total_sq / k - mu * mu, 0.0) * (k / max(k - 1, 1))
    var = cv2.blur(var.astype(np.float32), (config.std_smoothing_px,) * 2, borderType=cv2.BORDER_REFLECT)
    rmu, rvar, count = _robust_background_numba(x, float(config.robust_radius))
    reliable = (count >= 2).astype(np.uint8)
    rvar = _fill_from_reliable(rvar, reliable, max(5, config.std_smoothing_px), smooth=True)
    seg = BackgroundSegmenter(config, clean_plate=images[0])       # only for its foreground test on rmu, rvar
    seg._mu, seg._var = rmu, rvar
    hits = sum(int(np.count_nonzero(seg._foreground(s) & reliable)) for s in x)
    share = hits / (k * int(np.count_nonzero(reliable)))
    if share > config.robust_detect_fraction:
        return _fill_from_reliable(rmu, reliable, 5), rvar, reliable, share
    return mu.astype(np.float32), var.astype(np.float32), None, share


@pytest.mark.parametrize("noise", [0.0, 0.5])
def test_the_banded_build_is_the_one_go_build_whatever_ran_before_the_first_mask(noise):
    config = SegmentationConfig(learn_frames=LEARN, min_blob_area_px=5)
    frames = _frames(noise, LEARN + 3)
    mu, var, reliable, share = _one_go(config, frames[:LEARN])
    assert (reliable is not None) == (noise > 0)     # both decisions are exercised
    runs = {}
    for steps in (0, 1, 3, 1000):         # steps of the build between the last learning image and the next
        seg = BackgroundSegmenter(config)
        for img in frames[:LEARN]:
            assert not seg.apply(img).any()
        assert seg.building and not seg.learning
        left = [seg.advance_build() for _ in range(steps)]
        assert seg.building == (steps < 1000) and (steps == 0 or left[0])
        if not seg.building:              # the model itself (before the masks' running update changes it)
            assert np.array_equal(seg._mu, mu) and np.array_equal(seg._var, var)
            assert (seg._reliable is None) == (reliable is None) and seg.outlier_fraction == share
            if reliable is not None:
                assert np.array_equal(seg._reliable, reliable)
        runs[steps] = [seg.apply(img) for img in frames[LEARN:]]
        assert not seg.building
    assert runs[0][0].any()                      # the person is found
    for steps in (1, 3, 1000):
        assert all(np.array_equal(a, b) for a, b in zip(runs[0], runs[steps]))


def test_bands_of_any_height_give_the_same_model():
    config = SegmentationConfig(learn_frames=LEARN)
    x = np.stack(_frames(0.5, LEARN))
    built = []
    for band_rows in (1, 7, H):
        seg = BackgroundSegmenter(config)
        for img in x[:-1]:
            seg.apply(img)
        b = seg._samples, seg._pairs         # the learning so far; the last sample's agreements left to the build
        total = seg._sum + x[-1]
        total_sq = seg._sumsq + x[-1].astype(np.int64) ** 2
        samples = b[0].copy()
        samples[LEARN - 1] = x[-1]
        build = ModelBuild(config, total, total_sq, LEARN, samples=samples,
                           pairs=(b[1][0].copy(), b[1][1].copy()), pending=LEARN - 1, band_rows=band_rows)
        steps = 1
        while build.step():
            steps += 1
        built.append((build.mu, build.var, build.reliable, build.outlier_fraction))
        assert steps >= 2 * -(-H // band_rows)         # a step per band, twice over
    for other in built[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(built[0][:3], other[:3])) and built[0][3] == other[3]
    with pytest.raises(ValueError, match="band_rows: expected an integer >= 1"):
        ModelBuild(config, total, total_sq, LEARN, band_rows=0)
