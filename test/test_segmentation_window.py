"""Learning windows by stamp (vision.segmentation_window) and a segmenter's learning ended early
(BackgroundSegmenter.finish_learning): lost images never let the person into the background."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig
from isa_mocap_ros.vision.segmentation_window import LearningWindows

T = 33_333_333          # frame period, ns
T0 = 1_000_000_000
EMPTY = 10              # empty frames before the person, = learn_frames (as bags/demo)


def _frames(n: int, *, noise: float = 0.0, seed: int = 0) -> list[np.ndarray]:
    """A textured scene with camera noise; from frame EMPTY on a moving 'person' (a bright block);
    ``noise``: the ISA paper's pixel noise (that share of pixels a random colour)."""
    rng = np.random.default_rng(seed)
    bg = rng.integers(20, 200, size=(60, 80, 3)).astype(np.int16)
    out = []
    for k in range(n):
        img = np.clip(bg + rng.integers(-3, 4, size=bg.shape), 0, 255).astype(np.uint8)
        if k >= EMPTY:
            x = 10 + 2 * (k - EMPTY)
            img[15:45, x:x + 14] = (240, 40, 220)
        if noise:
            hit = rng.random(img.shape[:2]) < noise
            img[hit] = rng.integers(0, 256, size=(int(hit.sum()), 3))
        out.append(img)
    return out


def _config(**kw) -> SegmentationConfig:
    return SegmentationConfig(learn_frames=EMPTY, min_blob_area_px=10, **kw)


def _run_by_stamp(frames, received, cfg, windows=None, view=0):
    """Feed the received frame indices as a node does: the window decides, then the segmenter."""
    windows = windows or LearningWindows(cfg.learn_frames)
    seg = BackgroundSegmenter(cfg)
    masks = {}
    for k in received:
        if seg.learning and not windows.admits(seg, T0 + k * T, view):
            assert seg.finish_learning() > 0
        masks[k] = seg.apply(frames[k])
    return seg, windows, masks


@pytest.mark.parametrize("kw", [{}, {"robust": "on"}, {"learn_from": "stable"}, {"kernel": "numpy"}],
                         ids=["colour", "robust", "stable", "numpy"])
def test_lost_learning_images_end_the_window_by_stamp_and_the_model_is_that_of_the_frames_it_got(kw):
    """Frames 3-5 lost: the model learns from 0-2 and 6-9 only (not 10-12, where the person is) and its masks are
    those of a segmenter that learnt from those same seven empty frames; counting images instead would have
    learnt the person (the masks differ; not in the robust mode or learn_from stable, which outvote three person
    frames)."""
    noise = 0.3 if kw.get("robust") else 0.0
    frames = _frames(20, noise=noise)
    received = [0, 1, 2] + list(range(6, 20))
    seg, windows, masks = _run_by_stamp(frames, received, _config(**kw))
    assert windows.learnt(seg) == [T0 + k * T for k in (0, 1, 2, 6, 7, 8, 9)]
    assert seg.images_learnt == 7 and not seg.learning
    assert windows.end_ns(seg) == T0 + 19 * T // 2
    same = BackgroundSegmenter(dataclasses.replace(_config(**kw), learn_frames=7))
    for k in (0, 1, 2, 6, 7, 8, 9):
        assert not same.apply(frames[k]).any()
    assert not any(masks[k].any() for k in (0, 1, 2, 6, 7, 8, 9))
    for k in range(10, 20):
        assert np.array_equal(masks[k], same.apply(frames[k])), k
    assert masks[19].any()
    if not (kw.get("robust") or kw.get("learn_from")):   # (the mode and stable keep 3 person frames of 10 out)
        by_count = BackgroundSegmenter(_config(**kw))
        counted = [by_count.apply(frames[k]) for k in received]
        assert not np.array_equal(counted[-1], masks[19])       # the person learnt into the background


def test_every_image_arriving_learns_as_before_bit_for_bit():
    """Lockstep: the count ends the learning at the window's last frame; masks equal the plain segmenter's."""
    frames = _frames(16, noise=0.3)
    for kw in ({}, {"robust": "on"}, {"learn_from": "stable"}):
        seg, windows, masks = _run_by_stamp(frames, range(16), _config(**kw))
        plain = BackgroundSegmenter(_config(**kw))
        assert all(np.array_equal(masks[k], plain.apply(frames[k])) for k in range(16))
        assert windows.learnt(seg) == [T0 + k * T for k in range(EMPTY)]


def test_a_view_that_lost_the_first_image_ends_its_window_with_the_others():
    """View 1 lost frame 0: its window starts at view 0's first stamp, so frame 10 (the person) stays out."""
    frames = _frames(14)
    cfg = _config()
    windows = LearningWindows(EMPTY)
    segs = [BackgroundSegmenter(cfg), BackgroundSegmenter(cfg)]
    for k in range(14):
        for v in (0, 1):
            if (v, k) == (1, 0):
                continue
            if segs[v].learning and not windows.admits(segs[v], T0 + k * T, v):
                segs[v].finish_learning()
            segs[v].apply(frames[k])
    assert windows.start_ns(segs[1]) == T0
    assert windows.learnt(segs[1]) == [T0 + k * T for k in range(1, EMPTY)]
    assert segs[1].images_learnt == EMPTY - 1


def test_the_period_from_a_frame_rate_or_a_views_own_gaps():
    w = LearningWindows(4)
    w.observe(T0, 0)
    w.observe(T0 + 1_000_000, 1)            # another camera's own stamps: no gap across views
    assert w.period_ns() == 0
    w.observe(T0 + 3 * T, 0)
    w.observe(T0 + 3 * T + 5 * 10**9, 0)    # a stream restart is no frame period
    assert w.period_ns() == 3 * T
    w.observe(T0 + 2 * T, 0)
    assert w.period_ns() == T
    assert LearningWindows(4, frame_rate=30.0).period_ns() == T
    with pytest.raises(ValueError, match="frame_rate"):
        LearningWindows(4, frame_rate=-1.0)


def test_finish_learning_before_any_image_learns_nothing():
    seg = BackgroundSegmenter(_config())
    assert seg.finish_learning() == 0 and seg.learning
