"""Settings of the background segmentation (:class:`~.segmentation.BackgroundSegmenter`):
:class:`SegmentationConfig` with its checks, and :class:`SegmentationError`. The methods are described
in :mod:`.segmentation` and docs/segmentation_prior_prediction.md.
"""
from __future__ import annotations

from dataclasses import dataclass

from isa_mocap_ros.config_checks import check_choice, check_number

__all__ = ["SegmentationError", "SegmentationConfig"]

METHODS = ("colour", "mog2", "knn")
ROBUST = ("auto", "on", "off")
VOTES = ("field", "window")
LEARN_FROM = ("frames", "stable")


class SegmentationError(ValueError):
    """Bad configuration or a bad image given to the segmentation."""


@dataclass(frozen=True)
class SegmentationConfig:
    """Settings of :class:`BackgroundSegmenter` (fixed; the segmenter holds the changing state).

    Attributes
    ----------
    method : {"colour", "mog2", "knn"}
        Background model (see the module docstring).
    learn_frames : int
        Number of first images used only to learn the background (an all-zero mask is returned for
        them). Ignored by ``"colour"`` when a clean plate is given.
    threshold : float
        ``"colour"``: foreground when the normalised colour distance ``d`` exceeds this many
        per-pixel standard deviations. ``"mog2"``: its ``varThreshold`` is ``threshold**2``
        (the same squared Mahalanobis distance).
    min_std : float
        Floor of the per-pixel standard deviation, in intensity levels (uint8 units).
    initial_std : float
        Per-pixel standard deviation assumed when the model starts from a clean plate (one image
        carries no noise statistics); the running update refines it.
    std_smoothing_px : int
        Side of the box filter applied to the learnt variance image (0 or 1: none). Ten frames
        give a noisy per-pixel variance; averaging over a small neighbourhood steadies it.
    update_rate : float
        Running update rate ``rho`` in [0, 1] of the model outside the foreground (0: frozen).
        ``"mog2"``/``"knn"`` get it as OpenCV's ``learningRate`` after the learning phase.
    update_margin_px : int
        The foreground is dilated by this many pixels before it is excluded from the update, so
        the silhouette's fringe does not leak into the background.
    max_foreground_fraction : float
        When the raw foreground covers more than this fraction of the image, the frame is taken
        as a global change (lighting, exposure, a bumped camera) rather than a person, and the
        ``"colour"`` model is updated at every pixel; otherwise a selective update could never
        learn such a change. The mask of that frame is still returned as computed.
    shadow_suppression : bool
        Return shadows (darker, same chromaticity) as background. ``"mog2"``/``"knn"``: OpenCV's
        ``detectShadows``.
    shadow_min_brightness, shadow_max_brightness : float
        Brightness-distortion range ``alpha`` of a shadow (``"colour"`` only).
    shadow_chroma_threshold : float
        Largest chromaticity distortion ``CD`` of a shadow, in per-pixel standard deviations.
    open_kernel, close_kernel : int
        Sizes (pixels, elliptic element) of the morphological opening and closing; 0 or 1 skips.
    min_blob_area_px : int
        Connected foreground components (8-connected) with fewer pixels are removed.
    history : int
        OpenCV's ``history`` for ``"mog2"``/``"knn"``.
    knn_dist2_threshold : float
        OpenCV's ``dist2Threshold`` for ``"knn"`` (squared intensity distance).
    kernel : {"numba", "numpy"}
        Implementation of the ``"colour"`` per-pixel steps: a compiled single pass (default) or
        the plain numpy reference (same results up to float32 rounding).
    robust : {"auto", "on", "off"}
        ``"colour"`` only: outlier-robust mode for images with impulsive pixel noise (ISA
        §13.4.2) or other outliers in the learning frames (module docstring, "Robust mode").
        ``"auto"`` switches it on when more than ``robust_detect_fraction`` of the learning
        samples disagree with the robust background estimate; ``"on"`` / ``"off"`` force it.
    robust_detect_fraction : float
        ``robust="auto"``: the fraction of outlying learning samples above which the robust mode
        is used (clean camera images: well below 1 %; 50 % pixel noise: ~0.5).
    robust_radius : float
        Robust background estimate: two samples of a pixel agree when every channel differs by at
        most this many intensity levels.
    vote : {"field", "window"}
        Robust mode's per-frame decision (module docstring, "Robust mode"): ``"field"`` (default)
        weighs three kinds of pixel evidence (matches the background; differs and agrees in colour
        with a differing neighbour; differs alone) by their measured likelihoods and smooths them
        with a mean-field Markov random field; ``"window"`` is the earlier Gaussian-window share
        of differing pixels.
    vote_sigma_px : float
        ``vote="window"``: standard deviation of the Gaussian window of the neighbourhood vote,
        pixels (0 = automatic from the measured outlier fraction: 1.4 px at 50 % pixel noise,
        2.2 px at 70 %).
    field_coupling : float
        ``vote="field"``: coupling ``J`` of each pixel to its 8 neighbours in the mean-field
        iteration (0: no smoothing, every pixel decided by its own evidence).
    field_iterations : int
        ``vote="field"``: mean-field iterations (synchronous; deterministic).
    field_memory : float
        ``vote="field"``: weight ``w`` in [0, 1) of the earlier frames' person evidence in a pixel's
        (``H_t = h_t + w max(H_{t-1}, 0)``, the field then run on ``H_t``). Pixel noise is drawn anew each
        frame, so a person pixel that carries no evidence in this frame (70 % of them at 70 % noise) keeps
        what it showed in the last ones; only the positive part is carried, as a part that moves onto the
        background would otherwise be held back by its old background evidence. The rim lags the motion:
        the mask grows on the trailing side. 0 (default): each frame decided on its own evidence.
    learn_from : {"frames", "stable"}
        ``"colour"`` only. ``"frames"``: the ``learn_frames`` first images are the background samples
        (they must show the empty scene). ``"stable"``: the person may be in them -- they are buffered,
        and per pixel the frames where the background shows are found
        (:func:`~isa_mocap_ros.vision.stable_background.estimate_background`: temporal mode, person
        region, the clean plate if given as an image of the empty scene); the model then learns from
        ``learn_frames`` background frames drawn from those.
    work_scale : float
        Working resolution of the model as a share of the image's side, in (0, 1]: the image is
        reduced (area average) to ``round(W * work_scale) x round(H * work_scale)`` before the
        model sees it, and the mask is brought back to the image's size (bilinear, then
        thresholded at half). 1 (default) = the image's resolution, the model untouched. Every
        pixel setting (kernels, margins, ``std_smoothing_px``, ``vote_sigma_px``) then counts
        working pixels, except ``min_blob_area_px``, which stays in image pixels (scaled by
        ``work_scale**2``).
    """

    method: str = "colour"
    learn_frames: int = 10
    threshold: float = 4.0
    min_std: float = 2.0
    initial_std: float = 5.0
    std_smoothing_px: int = 5
    update_rate: float = 0.02
    update_margin_px: int = 3
    max_foreground_fraction: float = 0.5
    shadow_suppression: bool = False
    shadow_min_brightness: float = 0.4
    shadow_max_brightness: float = 1.0
    shadow_chroma_threshold: float = 3.0
    open_kernel: int = 3
    close_kernel: int = 3
    min_blob_area_px: int = 50
    history: int = 200
    knn_dist2_threshold: float = 400.0
    kernel: str = "numba"
    robust: str = "auto"
    robust_detect_fraction: float = 0.05
    robust_radius: float = 20.0
    vote: str = "field"
    vote_sigma_px: float = 0.0
    field_coupling: float = 0.3
    field_iterations: int = 8
    field_memory: float = 0.0
    learn_from: str = "frames"
    work_scale: float = 1.0

    def __post_init__(self) -> None:
        err = SegmentationError
        check_choice("method", self.method, METHODS, error=err)
        check_choice("kernel", self.kernel, ("numba", "numpy"), error=err)
        check_choice("robust", self.robust, ROBUST, error=err)
        check_number("robust_detect_fraction", self.robust_detect_fraction, lo=0.0, hi=1.0, lo_open=True,
                     hi_open=True, error=err)
        check_number("robust_radius", self.robust_radius, lo=0.0, error=err)
        check_choice("learn_from", self.learn_from, LEARN_FROM, error=err)
        if self.learn_from == "stable" and self.learn_frames < 3:
            raise SegmentationError(f"learn_frames: learn_from 'stable' needs at least 3, got {self.learn_frames}")
        if self.learn_from == "stable" and self.method != "colour":
            raise SegmentationError(f"learn_from: 'stable' needs method 'colour', got method {self.method!r}")
        check_choice("vote", self.vote, VOTES, error=err)
        check_number("field_coupling", self.field_coupling, lo=0.0, hi=10.0, error=err)
        check_number("field_iterations", self.field_iterations, lo=0, integer=True, error=err)
        check_number("field_memory", self.field_memory, lo=0.0, hi=1.0, hi_open=True, error=err)
        check_number("vote_sigma_px", self.vote_sigma_px, lo=0.0, hi=50.0, error=err)
        check_number("learn_frames", self.learn_frames, lo=1, integer=True, error=err)
        for name in ("threshold", "min_std", "initial_std", "shadow_chroma_threshold",
                     "knn_dist2_threshold"):
            check_number(name, getattr(self, name), lo=0.0, lo_open=True, error=err)
        check_number("update_rate", self.update_rate, lo=0.0, hi=1.0, error=err)
        check_number("max_foreground_fraction", self.max_foreground_fraction, lo=0.0, hi=1.0, lo_open=True, error=err)
        check_number("shadow_min_brightness", self.shadow_min_brightness, lo=0.0, error=err)
        if not self.shadow_min_brightness < self.shadow_max_brightness:
            raise SegmentationError(
                "shadow_min_brightness, shadow_max_brightness: expected 0 <= min < max, got "
                f"{self.shadow_min_brightness!r}, {self.shadow_max_brightness!r}")
        for name in ("std_smoothing_px", "update_margin_px", "open_kernel", "close_kernel",
                     "min_blob_area_px"):
            check_number(name, getattr(self, name), lo=0, integer=True, error=err)
        check_number("history", self.history, lo=1, integer=True, error=err)
        check_number("work_scale", self.work_scale, lo=0.05, hi=1.0, error=err)
