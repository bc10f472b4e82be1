"""Foreground segmentation by background subtraction (the segmentation node's core).

EA-vs-PF §3.2 (yeguas_ea_vs_pf_mocap): "In an initial phase, a background model which captures
the color statistics of each pixel is created. Then, using background subtraction techniques, the
foreground images are obtained" -- the masks ``F_v^t`` of its Eq. 2 that the silhouette energy
(Eq. 4-5) compares with the projected model.

Methods
-------
``"colour"`` (default)
    One Gaussian per pixel and channel: mean ``mu`` and standard deviation ``s`` learnt from the
    first ``learn_frames`` images (or initialised from a clean plate). A pixel ``I`` is foreground
    when its normalised colour distance

        d(p) = sqrt( sum_c ((I_c(p) - mu_c(p)) / s_c(p))^2 )

    exceeds ``threshold`` (in units of the per-pixel standard deviation). The model keeps learning
    outside the (dilated) foreground (everywhere after a global change, see
    ``max_foreground_fraction``) with an exponential running update of rate ``rho``:
    ``mu += rho (I - mu)``, ``s^2 += rho ((I - mu)^2 - s^2)``. Optional shadow suppression uses the
    brightness / chromaticity distortion of Horprasert et al. (1999): with
    ``alpha = sum_c I_c mu_c / s_c^2 / sum_c mu_c^2 / s_c^2`` and
    ``CD = || (I - alpha mu) / s ||``, a foreground pixel with ``alpha`` in
    ``[shadow_min_brightness, shadow_max_brightness]`` and ``CD < shadow_chroma_threshold`` is a
    shadow (a darker copy of the background) and is returned as background.
``"mog2"``, ``"knn"``
    OpenCV's ``BackgroundSubtractorMOG2`` / ``BackgroundSubtractorKNN``; shadows (value 127) are
    background.

Every method ends with the same clean-up (:func:`clean_mask`): morphological opening (removes
speckle), closing (fills small gaps), removal of connected components smaller than
``min_blob_area_px``.

Robust mode (``"colour"``, ``robust``)
---------------------------------------
For the ISA paper's pixel noise (§13.4.2: each pixel replaced with probability ``p`` = 0.5 or 0.7
by a uniform random colour, in every frame, the empty learning frames included). The plain model
then learns a standard deviation of ~60 levels everywhere and finds nothing.

* Background: per pixel the *mode* of the learning samples (at most ``ROBUST_MAX_SAMPLES``): the
  sample agreeing (every channel within ``robust_radius``) with the most others, ties to the
  tightest group; ``mu`` / ``s^2`` are the mean / variance of the samples agreeing with it. Random
  colours rarely agree with anything, camera-noise copies of the background do. Pixels where no
  two samples agree are *unreliable*: filled from reliable neighbours and left out of the vote.
* Decision: the share ``f`` of learning samples at reliable pixels that the robust model calls
  foreground (``d > threshold``) is measured; ``robust="auto"`` uses the robust mode when
  ``f > robust_detect_fraction`` (clean images: < 1 %), otherwise the plain model above (same
  results as without this mode).
* Per frame (``vote="field"``, the default): the per-pixel test ``D = d > threshold`` is a coin
  flip of probability ``f`` on the background and ~1 on the person; a differing pixel whose colour
  agrees with a differing neighbour's is almost never noise (random colours rarely agree) and is
  strong person evidence. The three kinds of pixel (matches; differs and agrees; differs alone) are
  weighed by their likelihood ratios (background rates measured on every frame outside the
  previous dilated mask) and smoothed by a mean-field Markov random field
  (:meth:`BackgroundSegmenter._field`); then the usual clean-up. Optionally (``field_memory``) the
  earlier frames' positive evidence is carried into a pixel's (a leaky sum): noise is drawn anew each frame.
* Per frame (``vote="window"``, the earlier decision): ``f`` is re-measured on every frame (reliable pixels outside the
  previous dilated mask), and a pixel is foreground when the Gaussian-weighted share of ``D`` over
  reliable pixels around it exceeds ``f + (1 - f) / 2``. The window's ``sigma`` (``vote_sigma_px``,
  0 = automatic) is chosen from ``f`` so that the share on the background stays ``z = 2.5``
  standard deviations below the threshold (:func:`_auto_sigma`: 1.4 px at ``f`` = 0.5, 2.2 px at
  0.7). Then the usual clean-up.
* Update: only pixels that match the model (``D = 0``) outside the dilated mask (a noisy pixel
  must not pull the mean); a global change (lighting) is *not* learnt in this mode.

Occluders (random rectangles) are foreground to any background model; the robust estimate only
keeps those present in the learning frames out of the background.
"""
from __future__ import annotations

import cv2
import numpy as np

from .segmentation_build import ModelBuild, foreground_test
from .segmentation_config import LEARN_FROM, METHODS, ROBUST, VOTES, SegmentationConfig, SegmentationError  # noqa: F401
from .stable_background import estimate_background

from .robust_mode import (_robust_background_numba, _robust_background_numpy, _robust_finish_numba,  # noqa: F401
                          _robust_finish_numpy, _robust_pairs_numba, _robust_pairs_numpy)
# the per-pixel kernels (numpy reference and numba) live in ._segmentation_kernels; the names tests use
# are re-exported here
from ._segmentation_kernels import (_KERNELS, _LEARN_KERNELS, _agree_numba, _agree_numpy,  # noqa: F401
                                    _fill_from_reliable, _fill_numpy, _label_counts, _window_sum)

__all__ = ["SegmentationError", "SegmentationConfig", "BackgroundSegmenter", "clean_mask"]

#: learning frames kept for the robust background estimate (evenly spread over ``learn_frames``)
ROBUST_MAX_SAMPLES = 25
_VOTE_SHARE = 0.5
_VOTE_Z = 2.5
#: ``vote="field"``: share of person pixels whose colour agrees with a differing neighbour's, as a
#: share of the noise-free ones (1 - f); measured inside the eroded masks of the 70 % noise walk:
#: 0.82-1.0 (a clean person pixel next to another clean one of its part; part edges and the
#: rendered shading make the rest)
FIELD_PERSON_AGREE = 0.85
#: ``vote="field"``: share of person pixels that match the background model (same measurement:
#: 0.005-0.012)
FIELD_PERSON_MATCH = 0.01


def _ellipse(size: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (int(size), int(size)))


def clean_mask(mask: np.ndarray, *, open_kernel: int = 3, close_kernel: int = 3,
               min_blob_area_px: int = 50) -> np.ndarray:
    """Morphological clean-up of a raw foreground mask.

    Parameters
    ----------
    mask : (H, W) uint8 ndarray
        Raw mask, non-zero = foreground.
    open_kernel, close_kernel : int
        Elliptic structuring element sizes for opening then closing (0 or 1: skip).
    min_blob_area_px : int
        8-connected components with fewer pixels are removed (0: keep all).

    Returns
    -------
    (H, W) uint8 ndarray
        Cleaned mask with values 0 and 255 (a new array).
    """
    if mask.dtype == np.uint8 and mask.ndim == 2:
        out = cv2.threshold(mask, 0, 255, cv2.THRESH_BINARY)[1]
    else:
        out = np.where(mask > 0, np.uint8(255), np.uint8(0))
    if open_kernel > 1:
        out = cv2.morphologyEx(out, cv2.MORPH_OPEN, _ellipse(open_kernel))
    if close_kernel > 1:
        out = cv2.morphologyEx(out, cv2.MORPH_CLOSE, _ellipse(close_kernel))
    if min_blob_area_px > 0:
        # (connectedComponentsWithStats takes ~0.6 ms at 320x240, labels + their compiled count less)
        n, labels = cv2.connectedComponents(out, connectivity=8)
        if n > 1:
            keep = _label_counts(labels, n) >= min_blob_area_px
            keep[0] = False  # label 0 is the background
            if not keep[1:].all():  # else nothing to remove: out is already 255 exactly on the labels > 0
                out = np.take(np.where(keep, np.uint8(255), np.uint8(0)), labels)
    return out


class BackgroundSegmenter:
    """Per-view background model: one :meth:`apply` per image gives its foreground mask.

    Parameters
    ----------
    config : SegmentationConfig
        Method and settings.
    clean_plate : (H, W, 3) or (H, W) uint8 ndarray, optional
        An image of the empty scene. ``"colour"`` starts from it (mean = plate, std =
        ``initial_std``) and segments from the first image on; ``"mog2"``/``"knn"`` are fed it
        ``learn_frames`` times.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> bg = rng.integers(0, 200, size=(48, 64, 3)).astype(np.uint8)
    >>> seg = BackgroundSegmenter(SegmentationConfig(min_blob_area_px=10), clean_plate=bg)
    >>> img = bg.copy(); img[10:30, 20:40] = (250, 20, 250)
    >>> int(seg.apply(img)[20, 30]), int(seg.apply(bg)[5, 5])
    (255, 0)
    """

    def __init__(self, config: SegmentationConfig = SegmentationConfig(), *,
                 clean_plate: np.ndarray | None = None) -> None:
        if not isinstance(config, SegmentationConfig):
            raise SegmentationError(f"config: expected a SegmentationConfig, got {type(config).__name__}")
        self.config = config
        self._plate = None if clean_plate is None else self._check_image(clean_plate, "clean_plate").copy()
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget everything learnt (a clean plate given at construction is used again)."""
        self.frames_seen = 0
        self._shape: tuple[int, ...] | None = None
        self._sum = self._sumsq = None
        self._mu = self._var = None
        self._cv = None
        self._n_learnt = 0  # images the model has learnt from before segmenting
        self._learn_target = self.config.learn_frames   # images it learns from (fewer: finish_learning)
        self._samples = None       # (S, H, W, C) uint8: learning images kept for the robust estimate
        self._n_samples = 0        # of them filled
        self._pairs = None         # (n, spread) (S, H, W) int32: their agreements so far
        self._reliable = None      # robust mode: (H, W) uint8 1 where the background is known
        self._vote_sigma = 0.0     # robust mode: sigma of the vote window (0: not chosen yet)
        self._vote_norm = None     # robust mode: reliable pixels per vote window
        self._vote_exclude = None  # robust mode: previous dilated mask (left out of the noise level)
        self._outlier_fraction: float | None = None
        self._agree_fraction = 0.0  # robust field vote: share of background pixels of kind A
        self._field_evidence = None  # robust field vote with field_memory: the leaky sum of evidence
        self._buffer: list[np.ndarray] | None = None   # learn_from="stable": the learning images
        self._build: ModelBuild | None = None   # the model's build from the learning, while steps remain
        self._pending_pairs: int | None = None   # the last sample, its agreements left to the build
        if self.config.method != "colour":
            c = self.config
            if c.method == "mog2":
                self._cv = cv2.createBackgroundSubtractorMOG2(
                    history=c.history, varThreshold=float(c.threshold) ** 2,
                    detectShadows=bool(c.shadow_suppression))
            else:
                self._cv = cv2.createBackgroundSubtractorKNN(
                    history=c.history, dist2Threshold=float(c.knn_dist2_threshold),
                    detectShadows=bool(c.shadow_suppression))
        plate = None if self._plate is None else self._reduce(self._plate)
        if self._plate is not None and self.config.learn_from == "stable":
            self._shape = self._plate.shape   # the plate joins the estimate after the learning images
        elif self._plate is not None:
            self._shape = self._plate.shape
            if self._cv is None:
                self._mu = self._as3(plate).astype(np.float32)
                self._var = np.full_like(self._mu, max(self.config.initial_std, self.config.min_std) ** 2)
                self._n_learnt = self.config.learn_frames
                if self.config.robust == "on":   # one plate has no outlier statistics: "auto" is off
                    self._reliable = np.ones(self._mu.shape[:2], np.uint8)
            else:
                for _ in range(self.config.learn_frames):
                    self._cv.apply(plate, learningRate=-1)
                self._n_learnt = self.config.learn_frames

    @property
    def learning(self) -> bool:
        """True while the next image only feeds the background model (all-zero mask)."""
        return self._n_learnt < self._learn_target

    @property
    def building(self) -> bool:
        """True from the last learning image until the model is built (:meth:`advance_build`, or the next
        :meth:`apply`, which finishes it first)."""
        return self._build is not None

    def advance_build(self) -> bool:
        """One step of the model's build (a band of rows; :mod:`.segmentation_build`), for a caller with idle time
        before the next image; the model is bit for bit the same however many steps ran before :meth:`apply`.

        Returns
        -------
        bool
            True while steps remain.
        """
        if self._build is None:
            return False
        if self._build.step():
            return True
        self._take_build()
        return False

    def _complete_build(self) -> None:
        if self._build is not None:
            self._build.finish()
            self._take_build()

    @property
    def images_learnt(self) -> int:
        """Images the background was learnt from so far (``learn_frames`` once learnt, fewer after
        :meth:`finish_learning`; with a clean plate and ``learn_from="frames"``: ``learn_frames``)."""
        return self._n_learnt if self._buffer is None else len(self._buffer)

    def finish_learning(self) -> int:
        """End the learning phase now, on the images received so far (a learning window closed before
        ``learn_frames`` images came: some were lost). The model is the one a segmenter with ``learn_frames``
        equal to that number learns from the same images (the robust samples: the first ones of the
        ``learn_frames`` spread, every image when ``learn_frames`` <= ``ROBUST_MAX_SAMPLES``).

        Returns
        -------
        int
            The images learnt from; 0 when nothing was learnt yet (then the model stays learning).
        """
        n = self.images_learnt
        if not self.learning or n == 0:
            return self._n_learnt if not self.learning else 0
        self._learn_target = n
        if self._buffer is not None:
            self._learn_from_stable()
        elif self._cv is None:
            self._finish_learning()
        return n

    @property
    def robust_active(self) -> bool:
        """True when the ``"colour"`` model runs in the outlier-robust mode (decided after learning)."""
        return self._reliable is not None

    @property
    def outlier_fraction(self) -> float | None:
        """Fraction of pixels differing from the background outside the person.

        Measured on the learning images (``"colour"``, ``robust`` not ``"off"``), then, in the
        robust mode, on each segmented image outside the previous (dilated) mask; about the
        pixel-noise probability. None before it is known.
        """
        return self._outlier_fraction

    @property
    def image_shape(self) -> tuple[int, ...] | None:
        """Shape of the images this model was learnt on (None before the first image)."""
        return self._shape

    def background_image(self) -> np.ndarray | None:
        """Current background estimate, same shape as the input images, uint8 (None if unknown)."""
        self._complete_build()
        if self._cv is not None:
            if self._shape is None:
                return None
            img = self._cv.getBackgroundImage()
        elif self._mu is None:
            return None
        else:
            img = np.clip(np.rint(self._mu), 0, 255).astype(np.uint8)
        if img is None:
            return None
        if img.shape[:2] != self._shape[:2]:
            img = cv2.resize(img, (self._shape[1], self._shape[0]), interpolation=cv2.INTER_LINEAR)
        return img.reshape(self._shape)

    # ------------------------------------------------------------------ main call
    def apply(self, image: np.ndarray) -> np.ndarray:
        """Segment one image (and learn from it).

        Parameters
        ----------
        image : (H, W, 3) or (H, W) uint8 ndarray
            Colour or grey image; every image must have the shape of the first one (or of the
            clean plate).

        Returns
        -------
        (H, W) uint8 ndarray
            Foreground mask, 0 / 255; all zero while :attr:`learning`.

        Raises
        ------
        SegmentationError
            Wrong dtype, number of dimensions or channels, or a shape other than the learnt one.
        """
        image = self._check_image(image, "image")
        if self._shape is None:
            self._shape = image.shape
        elif image.shape != self._shape:
            raise SegmentationError(
                f"image: expected shape {self._shape} (the size the background was learnt at), "
                f"got {image.shape}")
        self.frames_seen += 1
        self._complete_build()
        work = self._reduce(image)
        mask = self._apply_opencv(work) if self._cv is not None else self._apply_colour(work)
        return self._expand(mask)

    def _reduce(self, image: np.ndarray) -> np.ndarray:
        """The image at the working resolution (``work_scale``; area average). The image itself at 1."""
        h, w = self._work_size(image.shape)
        if (h, w) == image.shape[:2]:
            return image
        return cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)

    def _work_size(self, shape) -> tuple[int, int]:
        s = self.config.work_scale
        return max(1, int(round(shape[0] * s))), max(1, int(round(shape[1] * s)))

    def _expand(self, mask: np.ndarray) -> np.ndarray:
        """A working-resolution mask at the image's size (bilinear, thresholded at half: 0 / 255)."""
        H, W = self._shape[:2]
        if mask.shape == (H, W):
            return mask
        up = cv2.resize(mask, (W, H), interpolation=cv2.INTER_LINEAR)
        return cv2.threshold(up, 127, 255, cv2.THRESH_BINARY)[1]

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _check_image(image, name: str) -> np.ndarray:
        if not isinstance(image, np.ndarray):
            raise SegmentationError(f"{name}: expected a numpy uint8 array, got {type(image).__name__}")
        if image.dtype != np.uint8:
            raise SegmentationError(f"{name}: expected dtype uint8, got {image.dtype}")
        if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
            raise SegmentationError(f"{name}: expected shape (H, W, 3) or (H, W), got {image.shape}")
        if image.shape[0] < 1 or image.shape[1] < 1:
            raise SegmentationError(f"{name}: expected a non-empty image, got shape {image.shape}")
        return image

    @staticmethod
    def _as3(image: np.ndarray) -> np.ndarray:
        return image[:, :, None] if image.ndim == 2 else image

    def _clean(self, raw: np.ndarray) -> np.ndarray:
        c = self.config
        area = c.min_blob_area_px if c.work_scale == 1.0 else int(round(c.min_blob_area_px * c.work_scale ** 2))
        return clean_mask(raw, open_kernel=c.open_kernel, close_kernel=c.close_kernel, min_blob_area_px=area)

    def _zero(self) -> np.ndarray:
        return np.zeros(self._shape[:2], np.uint8)

    def _apply_opencv(self, image: np.ndarray) -> np.ndarray:
        if self.learning:
            self._cv.apply(image, learningRate=-1)
            self._n_learnt += 1
            return self._zero()
        raw = self._cv.apply(image, learningRate=float(self.config.update_rate))
        return self._clean(np.where(raw == 255, np.uint8(255), np.uint8(0)))

    def _apply_colour(self, image: np.ndarray) -> np.ndarray:
        c = self.config
        img = self._as3(image)
        if self.learning:
            if c.learn_from == "stable":       # buffer; the background frames come at the last one
                if self._buffer is None:
                    self._buffer = []
                self._buffer.append(img.copy())
                if len(self._buffer) == self._learn_target:
                    self._learn_from_stable()
            else:
                self._learn_sample(img)
            return self._zero()

        kernels = _KERNELS[c.kernel]
        fg = self._foreground(img)
        robust = self._reliable is not None
        if robust:
            mask = self._clean(self._vote(fg, img))
        else:
            mask = self._clean(fg)

        if c.update_rate > 0 or robust:
            grown = cv2.dilate(mask, _ellipse(2 * c.update_margin_px + 1)) if c.update_margin_px > 0 else mask
            if robust:
                self._vote_exclude = grown
                frozen = cv2.max(grown, fg)    # learn only from pixels that match the model
            elif np.count_nonzero(fg) > c.max_foreground_fraction * fg.size:
                frozen = np.zeros(fg.shape, np.uint8)     # a global change: learn it everywhere
            else:
                frozen = grown
            if c.update_rate > 0:
                kernels[1](img, self._mu, self._var, frozen, np.float32(c.update_rate))
        return mask

    def _learn_sample(self, img: np.ndarray) -> None:
        """Add one background sample (mean / variance sums, robust samples); finish at the last one."""
        c = self.config
        if self._sum is None:    # exact integer sums (what float64 sums of the uint8 values held, cheaper)
            self._sum = np.zeros(img.shape, np.int64)
            self._sumsq = np.zeros(img.shape, np.int64)
        if c.robust != "off" and self._n_learnt in _sample_indices(self._learn_target):
            # the last learning image's agreements are left to the build (in bands)
            self._add_sample(img, defer=self._n_learnt + 1 >= self._learn_target)
        _LEARN_KERNELS[c.kernel][0](img, self._sum, self._sumsq)
        self._n_learnt += 1
        if not self.learning:  # last learning image: mean and variance over the K images
            self._finish_learning()

    def _learn_from_stable(self) -> None:
        """``learn_from="stable"``: background frames from the buffered images (and the plate), learnt."""
        frames = np.stack(self._buffer)
        self._buffer = None
        grey = frames.shape[-1] == 1
        f3 = np.repeat(frames, 3, axis=-1) if grey else frames
        plates = []
        if self._plate is not None:
            p = self._as3(self._reduce(self._plate))
            plates = [np.repeat(p, 3, axis=-1) if p.shape[-1] == 1 else p]
        est = estimate_background(f3, plates=plates)
        for f in est.frames(self._learn_target, f3):
            self._learn_sample(f[..., :1] if grey else f)

    def _foreground(self, img: np.ndarray) -> np.ndarray:
        return foreground_test(self.config, img, self._mu, self._var)

    def _add_sample(self, img: np.ndarray, *, defer: bool = False) -> None:
        """Keep a learning image for the robust estimate and add its agreements with the earlier
        ones (the pair work is done as the images arrive, not all at the last learning frame; the last
        one's, ``defer``, by the build)."""
        if self._samples is None:
            S = len(_sample_indices(self._learn_target))
            self._samples = np.empty((S,) + img.shape, np.uint8)
            self._pairs = (np.ones((S,) + img.shape[:2], np.int32), np.zeros((S,) + img.shape[:2], np.int32))
        k = self._n_samples
        self._samples[k] = img
        self._n_samples += 1
        if defer and k:
            self._pending_pairs = k
        elif k:
            _KERNELS[self.config.kernel][2](self._samples, k, *self._pairs, float(self.config.robust_radius))

    def _finish_learning(self) -> None:
        """Start the model's build from the learning (:class:`~.segmentation_build.ModelBuild`: mean / variance of
        the learning images; the robust estimate and the mode decision); :meth:`advance_build` steps it, the next
        :meth:`apply` finishes it."""
        S = self._n_samples
        self._build = ModelBuild(self.config, self._sum, self._sumsq, self._n_learnt,
                                 samples=self._samples[:S] if S else None, pairs=self._pairs if S else None,
                                 pending=self._pending_pairs)
        self._sum = self._sumsq = self._samples = self._pairs = self._pending_pairs = None
        self._n_samples = 0

    def _take_build(self) -> None:
        """The finished build's model becomes the segmenter's."""
        b, self._build = self._build, None
        self._mu, self._var, self._reliable = b.mu, b.var, b.reliable
        if b.outlier_fraction is not None:
            self._outlier_fraction = b.outlier_fraction

    def _vote(self, fg: np.ndarray, img: np.ndarray) -> np.ndarray:
        """Robust mode: the per-frame decision from the per-pixel test ``fg`` (``D``) on ``img``.

        A background pixel differs from the model (``D = 1``) with the measured outlier probability
        ``f`` (pixel noise), a person pixel with probability ~1. ``vote="window"``: foreground where
        the Gaussian-weighted share of differing reliable pixels exceeds ``f + (1 - f) / 2``.
        ``vote="field"``: see :meth:`_field`.
        """
        c = self.config
        rel = self._reliable
        fg = cv2.bitwise_and(fg, rel)
        outside = rel if self._vote_exclude is None else cv2.bitwise_and(rel, cv2.bitwise_not(self._vote_exclude))
        n_out = cv2.countNonZero(outside)
        if n_out:
            self._outlier_fraction = cv2.countNonZero(cv2.bitwise_and(fg, outside)) / n_out
        if c.vote == "field":
            return self._field(fg, img, rel, outside, n_out)
        f = min(self._outlier_fraction or 0.0, 0.99)
        if self._vote_norm is None:
            self._vote_sigma = float(c.vote_sigma_px) or _auto_sigma(f)
            self._vote_norm = _window_sum(rel.astype(np.float32), self._vote_sigma)
        votes = _window_sum(fg.astype(np.float32), self._vote_sigma)
        share = np.float32(f + _VOTE_SHARE * (1.0 - f))
        return (votes > share * self._vote_norm).view(np.uint8)

    def _field(self, fg, img, rel, outside, n_out) -> np.ndarray:
        """``vote="field"``: three kinds of evidence per reliable pixel, weighed by likelihood ratio,
        then a mean-field Markov random field.

        Kinds: ``A`` = differs and agrees in colour with a differing 8-neighbour (every channel
        within ``robust_radius``); ``B`` = differs alone; ``M`` = matches the background. On the
        background ``P(A)`` = ``a`` and ``P(D = 1)`` = ``f`` are measured on every frame outside
        the previous dilated mask (pixel noise: random colours rarely agree, ``a`` ~ 1 % at
        ``f`` = 0.7); on the person ``P(A) = FIELD_PERSON_AGREE (1 - f)`` (the noise-free person
        pixels, which agree with their noise-free neighbours), ``P(M) = FIELD_PERSON_MATCH``.
        Per pixel the log-likelihood ratio person : background of its kind is ``h`` (0 where the
        background is unreliable); the field iterates ``m = tanh(h / 2 + J sum_8 m)``
        (``field_coupling`` J, ``field_iterations`` times, from ``m = tanh(h / 2)``) and the mask
        is ``m > 0``. At 70 % pixel noise about 30 % of the person's pixels are thus positive
        evidence (kind A, ratio ~20), where the window vote had only the weak ratio ``1 / f`` of
        any differing pixel; the coupling smooths along the outline instead of blurring it.
        """
        c = self.config
        agree = _KERNELS[c.kernel][4](self._as3(img), fg, float(c.robust_radius))
        if n_out:
            self._agree_fraction = cv2.countNonZero(cv2.bitwise_and(agree, outside)) / n_out
        f = min(max(self._outlier_fraction or 0.0, 1e-4), 0.999)
        a = min(max(self._agree_fraction, 1e-4), f)
        pa = FIELD_PERSON_AGREE * (1.0 - f)
        pm = FIELD_PERSON_MATCH
        l_a = np.log(pa / a)
        l_b = np.log(max(1.0 - pa - pm, 1e-4) / max(f - a, 1e-4))
        l_m = np.log(pm / (1.0 - f))
        h = np.where(agree > 0, np.float32(l_a), np.where(fg > 0, np.float32(l_b), np.float32(l_m)))
        h = (h * rel).astype(np.float32) * np.float32(0.5)
        if c.field_memory > 0:              # H_t = h_t + w max(H_{t-1}, 0): the earlier frames' person evidence
            if self._field_evidence is not None:
                h = h + np.float32(c.field_memory) * np.maximum(self._field_evidence, 0)
            self._field_evidence = h
        m = np.tanh(h)
        J = np.float32(c.field_coupling)
        for _ in range(c.field_iterations if J > 0 else 0):
            s = cv2.filter2D(m, -1, _FIELD_KERNEL, borderType=cv2.BORDER_REFLECT)
            m = np.tanh(h + J * s)
        return (m > 0).view(np.uint8)


_FIELD_KERNEL = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], np.float32)


def _sample_indices(k: int) -> set[int]:
    """Indices of the learning images kept for the robust estimate (at most ROBUST_MAX_SAMPLES)."""
    return set(np.unique(np.rint(np.linspace(0, k - 1, min(k, ROBUST_MAX_SAMPLES))).astype(int)).tolist())


def _auto_sigma(f: float, z: float | None = None) -> float:
    """Vote window sigma that separates background from person by ``z`` standard deviations.

    With Gaussian weights ``w`` (sum 1) the weighted share of differing background pixels has mean
    ``f`` and variance ``f (1 - f) sum w^2 = f (1 - f) / (4 pi sigma^2)``; the threshold sits
    ``(1 - f) / 2`` above the mean, so ``4 pi sigma^2 >= 4 z^2 f / (1 - f)``. Clamped to
    [0.5, 5] px.
    """
    z = _VOTE_Z if z is None else z
    s = np.sqrt(z * z * f / (np.pi * max(1.0 - f, 1e-3)))
    return float(min(max(s, 0.5), 5.0))

