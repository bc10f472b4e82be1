"""Options and helpers of the body-shape calibration shared by ``calibrate``, ``track`` and ``run``.

See :mod:`isa_mocap_ros.tracking.shape_calibration` and ``docs/shape_calibration.md``. Imports no other
``cli`` module (``track`` and ``calibrate`` both use it).
"""
from __future__ import annotations

import argparse

import numpy as np


def add_calibration_arguments(p: argparse.ArgumentParser) -> None:
    """The calibration's own options (shared by ``calibrate``, ``track``)."""
    p.add_argument("--calib-frames", type=int, default=None, metavar="N",
                   help="shape calibration: first frames tracked to calibrate on (default 30)")
    p.add_argument("--calib-rounds", type=int, default=None, metavar="N",
                   help="shape calibration: pose/shape alternations (default 4)")
    p.add_argument("--calib-evals", type=int, default=None, metavar="N",
                   help="shape calibration: shape-fit evaluations per round (default 1500)")
    p.add_argument("--calib-restarts", type=int, default=None, metavar="N",
                   help="shape calibration: whole calibrations from other seeds, combined by --calib-combine (default 3)")
    p.add_argument("--calib-combine", choices=("lowest", "median"), default=None,
                   help="shape calibration with restarts: keep the lowest judged energy, or the median of each factor "
                        "(default lowest)")
    p.add_argument("--calib-judge", choices=("fit", "track"), default=None,
                   help="shape calibration with restarts: judge each restart by its own shape fit's energy (fit, the "
                        "default) or by the mean tracker energy of the first 60 frames tracked with its shape (track)")
    p.add_argument("--calib-radius-prior", type=float, default=None, metavar="W",
                   help="shape calibration: weight of a prior pulling the radius factors towards 1.15 (their level on "
                        "clean mesh bags; 0 = off, the default: docs/shape_calibration.md)")
    p.add_argument("--calib-energy", choices=("raster", "fast"), default=None,
                   help="shape calibration: the shape fit's silhouette energy, raster (counted on the pixel grid, no "
                        "sample) or fast (sampled) (default raster)")


def calibration_config(args, seed: int):
    from isa_mocap_ros.tracking.shape_calibration import ShapeCalibrationConfig

    kw = {"seed": seed}
    for opt, key in (("calib_frames", "window_frames"), ("calib_rounds", "rounds"), ("calib_evals", "shape_evals"),
                     ("calib_restarts", "restarts"), ("calib_combine", "combine"), ("calib_energy", "energy"),
                     ("calib_radius_prior", "radius_prior"), ("calib_judge", "judge")):
        v = getattr(args, opt, None)
        if v is not None:
            kw[key] = v
    return ShapeCalibrationConfig(**kw)


def calibration_frames(seq, *, use_masks: bool, learn: int, first: int, n: int) -> list:
    """``(stamp, masks)`` of ``n`` frames from ``first``: the recorded masks or fresh segmenters' (learning
    the background from the first ``learn`` frames, as ``track`` does)."""
    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    out = []
    segs = None if use_masks else [BackgroundSegmenter(SegmentationConfig(learn_frames=learn)) for _ in seq.cameras]
    for fr in seq.frames[:first + n]:
        masks = list(fr.masks) if use_masks else [None if img is None else s.apply(img)
                                                   for s, img in zip(segs, fr.images)]
        if fr.index >= first:
            out.append((int(fr.stamp_ns), masks))
    return out


def save_calibrated_shape(res, bag_name: str, path):
    """Write a calibration's shape (``res.shape``), named ``calibrated:<bag_name>``, to the body-shape YAML
    ``path`` (its folder made; exact numbers, :func:`~isa_mocap_ros.body.save_shape`): what ``calibrate``
    writes, and what ``track`` and ``run`` track with."""
    from pathlib import Path

    from isa_mocap_ros.body import save_shape

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    save_shape({**dict(res.shape), "name": f"calibrated:{bag_name}"}, path)


def calibrate_sequence(seq, args, *, dof: int, use_masks: bool, learn: int, first: int, tracker_config=None,
                       progress=None):
    """Run the calibration on a read sequence; returns (result, report dict)."""
    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.tracking.shape_calibration import (bone_errors, bone_lengths, calibrate_shape,
                                                          marker_bone_lengths)

    cfg = calibration_config(args, args.seed)
    n = max(cfg.window_frames, cfg.judge_frames if cfg.judge == "track" and cfg.restarts > 1 else 0)
    frames = calibration_frames(seq, use_masks=use_masks, learn=learn, first=first, n=n)
    res = calibrate_shape(dof, seq.cameras, frames, tracker_config=tracker_config, config=cfg, progress=progress)
    model = make_model(dof, shape=res.shape)
    report = {"params": {k: round(v, 4) for k, v in res.params.items()},
              "energy_default_shape": round(res.energy_default, 5), "energy": round(res.energy, 5),
              "frames": len(res.frame_keys), "window_frames": cfg.window_frames, "rounds": list(res.rounds),
              "notes": list(res.notes), "bones_m": {k: round(v, 4) for k, v in bone_lengths(model).items()}}
    marks = [f.truth_markers for f in seq.frames if f.truth_markers is not None]
    if marks:
        # evaluation only: the truth never enters the fit
        truth = marker_bone_lengths(seq.truth_marker_names, np.array(marks))
        report["truth_bones_m"] = {k: round(v, 4) for k, v in truth.items()}
        report["bone_error"] = bone_errors(bone_lengths(model), truth)
        report["bone_error_default_shape"] = bone_errors(bone_lengths(make_model(dof)), truth)
    return res, report
