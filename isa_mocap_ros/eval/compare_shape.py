"""The tracking model's body shape in the optimizer comparison (``isa-mocap bench compare``; issue 33).

A user has no ground-truth shape, so the comparison tracks, by default, with the shape calibrated from the
sequence's own silhouettes (:func:`isa_mocap_ros.tracking.shape_calibration.calibrate_shape`, the code of
``isa-mocap calibrate`` and ``--shape auto``), once per sequence with the design's first seed; every cell of
that sequence tracks with it. ``shape="truth"`` (the sequence's ground-truth model shape, what the papers'
calibrated subjects had) stays as a labelled diagnostic. The calibrated shape is cached beside the sequence
(named by the calibration's options, seed and module source) with its report: bone-length error against the
truth (the capsule model's rest pose, or the mesh skeleton's joint centres).
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from .compare import _load_sequence

__all__ = ["calibration_config", "sequence_shape_path", "calibrate_sequence_shape", "bone_error_summary"]


def calibration_config(calib, seed: int):
    """The :class:`ShapeCalibrationConfig` of a design's ``calib`` pairs (its other settings the defaults)."""
    from isa_mocap_ros.tracking.shape_calibration import ShapeCalibrationConfig

    return ShapeCalibrationConfig(**{**dict(calib), "seed": int(seed)})


def sequence_shape_path(cache_path: Path | str, calib, seed: int) -> Path:
    """Where :func:`calibrate_sequence_shape` keeps the calibrated shape of the sequence ``cache_path``."""
    from isa_mocap_ros.tracking import shape_calibration

    key = repr((sorted(dict(calib).items()), int(seed), 39))
    src = Path(shape_calibration.__file__).read_bytes()
    h = hashlib.sha1(key.encode() + src).hexdigest()[:10]
    p = Path(cache_path)
    return p.parent / f"{p.stem}.shape_{h}.yaml"


def calibrate_sequence_shape(cache_path: Path | str, calib=(), seed: int = 0) -> dict:
    """Calibrate the body shape of the cached sequence ``cache_path`` (:func:`~.compare.prepare_sequence`) from its
    silhouettes, once (reused when cached); return its report: ``shape_file``, ``params``, ``energy`` and the
    bone-length errors (``bone_error_mm``, ``limb_bone_error_mm`` and the default shape's) against the truth."""
    from isa_mocap_ros.body import make_model, save_shape
    from isa_mocap_ros.tracking.shape_calibration import (bone_errors, bone_lengths, calibrate_shape,
                                                          marker_bone_lengths)

    path = sequence_shape_path(cache_path, calib, seed)
    rep_path = path.with_suffix(".json")
    if path.is_file() and rep_path.is_file():
        return json.loads(rep_path.read_text())
    spec, masks, _truth, truth_model, _shape, rig, markers = _load_sequence(Path(cache_path))
    cfg = calibration_config(calib, seed)
    frames = [(k, list(masks[k])) for k in range(min(len(masks), cfg.window_frames))]
    res = calibrate_shape(39, rig.cameras, frames, config=cfg)
    truth = (marker_bone_lengths(markers[0], markers[1]) if markers is not None else bone_lengths(truth_model))
    err = bone_errors(bone_lengths(make_model(39, shape=res.shape)), truth)
    err0 = bone_errors(bone_lengths(make_model(39)), truth)
    report = {"sequence": spec.name, "shape_file": path.name, "params": {k: round(v, 4) for k, v in res.params.items()},
              "energy_default_shape": round(res.energy_default, 5), "energy": round(res.energy, 5),
              "bone_error_mm": round(err["mean_mm"], 1), "limb_bone_error_mm": round(err["limbs_mean_mm"], 1),
              "bone_error_default_shape_mm": round(err0["mean_mm"], 1),
              "limb_bone_error_default_shape_mm": round(err0["limbs_mean_mm"], 1)}
    tmp = path.with_suffix(".tmp.yaml")
    save_shape({**dict(res.shape), "name": f"calibrated:{spec.name}"}, tmp)
    tmp.replace(path)
    rep_path.write_text(json.dumps(report, indent=2) + "\n")
    return report


def bone_error_summary(reports) -> dict:
    """Mean bone-length errors over the sequences' calibrations (mm)."""
    keys = ("bone_error_mm", "limb_bone_error_mm", "bone_error_default_shape_mm", "limb_bone_error_default_shape_mm")
    return {k: float(np.mean([r[k] for r in reports])) for k in keys} if reports else {}
