"""Frame sources of the camera node: real files made here, devices that fail, the synthetic rig."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from isa_mocap_ros.synth import SceneRenderer, make_clip
from isa_mocap_ros.vision import default_rig
from isa_mocap_ros.vision.sources import (DeviceSource, DistortedSource, EndOfSource, FrameSource,
                                          ImageFolderSource, SourceError, SyntheticSource, VideoFileSource)


def _frames(rng: np.random.Generator, n: int, h: int = 48, w: int = 64) -> list[np.ndarray]:
    """Distinct RGB frames: a flat colour per frame (survives MJPG compression well)."""
    cols = rng.integers(30, 226, size=(n, 3))
    return [np.broadcast_to(c.astype(np.uint8), (h, w, 3)).copy() for c in cols]


def _write_video(path, frames: list[np.ndarray], fps: float = 10.0) -> None:
    h, w = frames[0].shape[:2]
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    assert vw.isOpened()
    for f in frames:
        vw.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    vw.release()


# -------------------------------------------------------------------------------- video files
def test_video_files_give_rgb_frames_in_order_and_end(tmp_path):
    rng = np.random.default_rng(3)
    views = [_frames(rng, 5), _frames(rng, 5)]
    paths = []
    for v, fr in enumerate(views):
        paths.append(tmp_path / f"cam{v}.avi")
        _write_video(paths[-1], fr)
    src = VideoFileSource(paths)
    assert isinstance(src, FrameSource) and src.n_views == 2
    for k in range(5):
        got = src.read()
        assert len(got) == 2
        for v in range(2):
            assert got[v].shape == (48, 64, 3) and got[v].dtype == np.uint8
            # MJPG is lossy: compare mean colours (a BGR/RGB swap would be off by far more).
            err = np.abs(got[v].reshape(-1, 3).mean(0) - views[v][k][0, 0].astype(float)).max()
            assert err < 4.0, (k, v, err)
    with pytest.raises(EndOfSource, match="ended after 5 frames"):
        src.read()
    src.close()


def test_video_loop_rewinds(tmp_path):
    rng = np.random.default_rng(4)
    fr = _frames(rng, 3)
    _write_video(tmp_path / "a.avi", fr)
    src = VideoFileSource([tmp_path / "a.avi"], loop=True)
    got = [src.read()[0] for _ in range(7)]
    for k, img in enumerate(got):
        assert np.abs(img.reshape(-1, 3).mean(0) - fr[k % 3][0, 0]).max() < 4.0
    assert any(e.kind == "info" and "looped" in e.text for e in src.events)
    src.close()


def test_video_bad_paths_raise(tmp_path):
    with pytest.raises(SourceError, match="does not exist"):
        VideoFileSource([tmp_path / "missing.avi"])
    (tmp_path / "junk.avi").write_bytes(b"not a video at all" * 10)
    with pytest.raises(SourceError, match="cannot open"):
        VideoFileSource([tmp_path / "junk.avi"])
    with pytest.raises(SourceError, match="non-empty list"):
        VideoFileSource([])


# ------------------------------------------------------------------------------- image folders
def test_image_folders_sorted_exact_and_cut_to_shortest(tmp_path):
    rng = np.random.default_rng(5)
    imgs = {v: [rng.integers(0, 256, (20, 30, 3), dtype=np.uint8) for _ in range(4 + v)] for v in range(2)}
    for v, lst in imgs.items():
        d = tmp_path / f"cam{v}"
        d.mkdir()
        # written out of order; names sort to frame order
        for k in reversed(range(len(lst))):
            cv2.imwrite(str(d / f"frame_{k:03d}.png"), cv2.cvtColor(lst[k], cv2.COLOR_RGB2BGR))
    src = ImageFolderSource([str(tmp_path / "cam0" / "*.png"), str(tmp_path / "cam1" / "*.png")])
    assert src.n_frames == 4
    assert any("using the first 4" in e.text for e in src.events)
    for k in range(4):
        got = src.read()
        for v in range(2):
            np.testing.assert_array_equal(got[v], imgs[v][k])  # PNG is lossless: exact RGB
    with pytest.raises(EndOfSource):
        src.read()


def test_image_folder_loop_and_unreadable_file(tmp_path):
    rng = np.random.default_rng(6)
    a = rng.integers(0, 256, (10, 12, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "0.png"), a)
    (tmp_path / "1.png").write_bytes(b"broken png")
    src = ImageFolderSource([str(tmp_path / "*.png")], loop=True)
    seq = [src.read()[0] for _ in range(4)]
    assert seq[1] is None and seq[3] is None
    np.testing.assert_array_equal(seq[2], seq[0])
    assert any(e.kind == "failed" and "1.png" in e.text for e in src.events)


def test_image_folder_empty_glob_raises(tmp_path):
    with pytest.raises(SourceError, match="matches no file"):
        ImageFolderSource([str(tmp_path / "*.png")])


# ------------------------------------------------------------------------------------- devices
def test_missing_device_reports_without_raising():
    events = []
    src = DeviceSource([97], on_event=events.append, retry_s=0.2)
    got = src.read()
    assert got == [None]
    assert events and events[0].kind == "failed" and "camera 0 (device 97)" in events[0].text
    assert "retrying in" in events[0].text
    src.close()


class _FakeCapture:
    """A capture that works ``n_ok`` times, then fails (unplugged)."""

    def __init__(self, image: np.ndarray, n_ok: int):
        self.image, self.n_ok = image, n_ok

    def isOpened(self):
        return True

    def read(self):
        if self.n_ok <= 0:
            return False, None
        self.n_ok -= 1
        return True, self.image[:, :, ::-1].copy()  # BGR like OpenCV

    def release(self):
        pass


def test_device_fails_then_reconnects_with_backoff():
    img = np.random.default_rng(7).integers(0, 256, (8, 10, 3), dtype=np.uint8)
    now = [0.0]
    plugged = [True, False, False, True]  # open, (unplugged) fail, fail, plugged back
    calls = []

    def opener(index):
        calls.append(now[0])
        ok = plugged[min(len(calls) - 1, len(plugged) - 1)]
        return _FakeCapture(img, 1) if ok else None

    src = DeviceSource([2], opener=opener, clock=lambda: now[0], retry_s=1.0, max_retry_s=4.0)
    np.testing.assert_array_equal(src.read()[0], img)       # RGB again
    assert src.read() == [None]                              # unplugged: read fails at t=0
    now[0] = 0.5
    assert src.read() == [None] and len(calls) == 1          # before the retry time: not touched
    now[0] = 1.0
    assert src.read() == [None] and len(calls) == 2          # retry 1 fails, next wait 2 s
    now[0] = 2.5
    assert src.read() == [None] and len(calls) == 2
    now[0] = 3.0
    assert src.read() == [None] and len(calls) == 3          # retry 2 fails, next wait 4 s
    now[0] = 7.0
    np.testing.assert_array_equal(src.read()[0], img)       # plugged back in
    kinds = [e.kind for e in src.events]
    assert kinds == ["failed", "retry", "retry", "reconnected"], src.events
    assert src.events[-1].text == "reconnected camera 0 (device 2)"


# ------------------------------------------------------------------------------------ synthetic
def test_synthetic_source_matches_the_offline_renderer():
    rig = default_rig(n_views=2, width=80, height=60)
    src = SyntheticSource(rig, "walk", fps=30, model_dof=18, seed=3, noise=0.2, occluders=2, empty_frames=2,
                          duration_s=0.2, loop=False)
    clip = make_clip("walk", dof=18, fps=30, seed=3, duration_s=0.2)
    ref = SceneRenderer(clip.model, rig, seed=3, noise=0.2, occluders=2)
    n = 2 + clip.n_frames
    for k in range(n):
        got = src.read()
        pose = None if k < 2 else clip.poses[k - 2]
        want, masks = ref.render(pose, k)
        for v in range(2):
            np.testing.assert_array_equal(got[v], want[v])
            np.testing.assert_array_equal(src.last_masks[v], masks[v])
        assert (src.last_pose is None) == (k < 2)
    with pytest.raises(EndOfSource):
        src.read()


def test_synthetic_source_loops_and_counts_frames():
    rig = default_rig(n_views=1, width=64, height=48)
    src = SyntheticSource(rig, "wave", fps=10, model_dof=18, seed=0, duration_s=0.3, loop=True)
    n = src.clip.n_frames
    first = [src.read()[0] for _ in range(n)]
    again = src.read()[0]
    np.testing.assert_array_equal(again, first[0])  # no distortions: the loop repeats the images
    assert src.frame == n + 1
    assert any("looped" in e.text for e in src.events)


def test_synthetic_bad_arguments():
    rig = default_rig(n_views=1, width=64, height=48)
    with pytest.raises(ValueError, match="motion"):
        SyntheticSource(rig, "moonwalk")
    with pytest.raises(SourceError, match="rig"):
        SyntheticSource("rig", "walk")
    with pytest.raises(SourceError, match="empty_frames"):
        SyntheticSource(rig, "walk", empty_frames=-1)


# ---------------------------------------------------------------------------------- distortions
class _Const:
    n_views = 2

    def __init__(self, img):
        self.img = img

    def read(self):
        return [self.img, None]

    def close(self):
        pass


def test_distorted_source_is_reproducible_per_frame():
    img = np.full((30, 40, 3), 100, np.uint8)
    a = DistortedSource(_Const(img), seed=5, noise=0.3, occluders=2)
    b = DistortedSource(_Const(img), seed=5, noise=0.3, occluders=2)
    fa = [a.read() for _ in range(3)]
    fb = [b.read() for _ in range(3)]
    for x, y in zip(fa, fb):
        np.testing.assert_array_equal(x[0], y[0])
        assert x[1] is None
    assert not np.array_equal(fa[0][0], fa[1][0])  # a new draw per frame
    assert (fa[0][0] != img).any()
    np.testing.assert_array_equal(img, 100)  # input untouched
    with pytest.raises(SourceError, match="noise"):
        DistortedSource(_Const(img), noise=1.5)


def test_synthetic_source_renders_a_bvh_motion(cmu_walk):
    rig = default_rig(n_views=2, width=80, height=60)
    src = SyntheticSource(rig, cmu_walk, fps=30, model_dof=18, seed=0, duration_s=0.2, loop=False)
    assert src.clip.source == str(cmu_walk) and src.model.dof == 18
    for _ in range(src.clip.n_frames):
        images = src.read()
        assert len(images) == 2 and src.last_pose is not None
        assert all(m.any() for m in src.last_masks)  # the person is in both views
    with pytest.raises(EndOfSource):
        src.read()
