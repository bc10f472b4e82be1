"""The background model built from its learning images, a band of rows at a time.

When a :class:`~isa_mocap_ros.vision.segmentation.BackgroundSegmenter` has its last learning image, its model is
built from what the learning gathered: the mean and variance of the images (their exact sums), and, unless
``robust="off"``, the robust estimate (the per-pixel mode of the kept samples, :mod:`.robust_mode`), its
unreliable pixels filled, and the decision between the two (the share of the samples the robust model calls
foreground). Done in one go this is the costliest moment of a view's stream (docs/history/issue35_speed.md,
session 34), so :class:`ModelBuild` does it in steps: the last sample's agreements and the mode in bands of
``band_rows`` rows, the neighbourhood filters (variance smoothing, the fill) in one step on the whole image,
the foreground test of the samples in bands again, the decision last. Every band's arithmetic is per pixel
and the filters see the whole image, so the model is bit for bit the one-go build's whatever the steps'
schedule: a caller may run them in idle time (the segmentation node's timer) and finish the rest when the
first image to segment comes (:meth:`ModelBuild.finish`).
"""
from __future__ import annotations

import cv2
import numpy as np

from ._segmentation_kernels import _KERNELS, _fill_from_reliable
from .robust_mode import _robust_finish_numpy, _robust_pairs_numpy, _robust_finish_rows_numba, _robust_pairs_rows_numba
from .segmentation_config import SegmentationConfig

__all__ = ["ModelBuild", "BAND_ROWS", "foreground_test"]

#: rows per band of the banded steps (at 320x240 about 1/8 of the image: a few ms a band)
BAND_ROWS = 32


def foreground_test(config: SegmentationConfig, img: np.ndarray, mu: np.ndarray, var: np.ndarray) -> np.ndarray:
    """The raw per-pixel test ``d > threshold`` (shadows removed if configured) of ``img`` against ``mu``, ``var``:
    (H, W) uint8 0/1."""
    c = config
    return _KERNELS[c.kernel][0](
        img, mu, var, np.float32(c.min_std) ** 2, np.float32(c.threshold) ** 2,
        bool(c.shadow_suppression), np.float32(c.shadow_min_brightness),
        np.float32(c.shadow_max_brightness), np.float32(c.shadow_chroma_threshold) ** 2)


def _pairs_rows(kernel: str, stack, k, n, spread, radius, y0, y1) -> None:
    if kernel == "numba":
        _robust_pairs_rows_numba(stack, k, n, spread, float(radius), y0, y1)
    else:       # numpy: the reference on the rows' views (per pixel, in place)
        _robust_pairs_numpy(stack[:, y0:y1], k, n[:, y0:y1], spread[:, y0:y1], radius)


def _finish_rows(kernel: str, stack, n, spread, radius, y0, y1, mu, var, count) -> None:
    if kernel == "numba":
        _robust_finish_rows_numba(stack, n, spread, float(radius), y0, y1, mu, var, count)
    else:
        mu[y0:y1], var[y0:y1], count[y0:y1] = _robust_finish_numpy(stack[:, y0:y1], n[:, y0:y1], spread[:, y0:y1],
                                                                    radius)


class ModelBuild:
    """The steps from the learning's sums and samples to the background model (see the module docstring).

    Parameters
    ----------
    config : SegmentationConfig
        The segmenter's settings.
    total, total_sq : (H, W, C) int64 ndarray
        Exact sums of the ``images`` learning images and of their squares.
    images : int
        Learning images summed.
    samples : (S, H, W, C) uint8 ndarray or None
        The robust estimate's samples (None: no robust estimate).
    pairs : ((S, H, W), (S, H, W)) int32 ndarrays or None
        Their agreement counts and distance sums (:func:`~.robust_mode._robust_pairs_numpy`), complete for the
        samples before ``pending``.
    pending : int or None
        A sample whose agreements with the earlier ones are still to be added (the last one), or None.
    band_rows : int
        Rows per band.

    After :meth:`step` returned False (or :meth:`finish`): ``mu``, ``var`` (float32, (H, W, C)) the model,
    ``reliable`` ((H, W) uint8 1/0, or None: the plain model), ``outlier_fraction`` (None without samples).
    """

    def __init__(self, config: SegmentationConfig, total: np.ndarray, total_sq: np.ndarray, images: int, *,
                 samples: np.ndarray | None = None, pairs=None, pending: int | None = None,
                 band_rows: int = BAND_ROWS) -> None:
        if band_rows < 1:
            raise ValueError(f"band_rows: expected an integer >= 1, got {band_rows}")
        self.config = config
        self.mu = self.var = self.reliable = None
        self.outlier_fraction: float | None = None
        self._steps = self._run(total, total_sq, int(images), samples, pairs, pending, int(band_rows))
        self.done = False

    def step(self) -> bool:
        """Do the next step; True while steps remain."""
        if not self.done:
            try:
                next(self._steps)
            except StopIteration:
                self.done = True
        return not self.done

    def finish(self) -> None:
        """Do every step left."""
        while self.step():
            pass

    def _run(self, total, total_sq, k, samples, pairs, pending, band):
        c = self.config
        kern = c.kernel
        H = total.shape[0]
        bands = [(y0, min(H, y0 + band)) for y0 in range(0, H, band)]
        S = 0 if samples is None else len(samples)
        if S:
            n, spread = pairs[0][:S], pairs[1][:S]
            stack = samples[:S]
            rmu = np.zeros(samples.shape[1:], np.float32)
            rvar = np.zeros(samples.shape[1:], np.float32)
            count = np.zeros(samples.shape[1:3], np.int32)
            for y0, y1 in bands:     # the last sample's agreements, then the mode, per band
                if pending is not None:
                    _pairs_rows(kern, samples, pending, *pairs, float(c.robust_radius), y0, y1)
                _finish_rows(kern, stack, n, spread, float(c.robust_radius), y0, y1, rmu, rvar, count)
                yield
        mu = total / k
        var = np.maximum(total_sq / k - mu * mu, 0.0) * (k / max(k - 1, 1))
        if c.std_smoothing_px > 1:
            var = cv2.blur(var.astype(np.float32), (c.std_smoothing_px,) * 2,
                           borderType=cv2.BORDER_REFLECT).reshape(mu.shape)
        self.mu, self.var = mu.astype(np.float32), var.astype(np.float32)
        if not S:
            return
        reliable = (count >= min(2, S)).astype(np.uint8)
        if not reliable.any():
            reliable[:] = 1
        # unreliable pixels (no two samples agree) take the mean of their reliable neighbours (once the robust
        # mode is chosen: the share below counts reliable pixels only, where the fill keeps rmu);
        # the variance is smoothed over reliable pixels only
        side = max(5, c.std_smoothing_px)
        rvar = _fill_from_reliable(rvar, reliable, side, smooth=c.std_smoothing_px > 1)
        yield
        hits = 0
        for y0, y1 in bands:        # the share of the samples the robust model calls foreground, per band
            rel = reliable[y0:y1]
            hits += sum(int(np.count_nonzero(foreground_test(c, s[y0:y1], rmu[y0:y1], rvar[y0:y1]) & rel))
                        for s in stack)
            yield
        self.outlier_fraction = hits / (S * int(np.count_nonzero(reliable)))
        if c.robust == "on" or self.outlier_fraction > c.robust_detect_fraction:
            self.reliable = reliable
            self.mu, self.var = _fill_from_reliable(rmu, reliable, 5), rvar
