"""``isa-mocap calibrate BAG --out body.yaml``: the subject's body shape from the images of a bag.

Segments the bag's images (or takes its recorded masks with ``--use-masks``) as ``isa-mocap track``
does, runs :func:`isa_mocap_ros.tracking.shape_calibration.calibrate_shape` on the first frames the
person is in view, and writes the body-shape YAML (the format of ``config/body/default.yaml``) that
``track``/``run --shape FILE`` and the estimator's ``body_shape`` parameter read. With ground-truth
joint centres in the bag (``/mocap/ground_truth/markers``) it also reports the calibrated bone lengths
against them (the bag's truth is read for that report only, never for the fit). Exit codes: 0 done,
2 bad input.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from isa_mocap_ros.cli.shape_options import add_calibration_arguments, calibrate_sequence, save_calibrated_shape


def register(sub) -> None:
    p = sub.add_parser("calibrate", help="estimate the subject's body shape from a bag's images -> body YAML",
                       description="Fit segment lengths and capsule radii (left/right symmetric) to the silhouettes "
                                   "of the first frames of BAG; write a body-shape YAML for track/run --shape FILE.")
    p.add_argument("bag", metavar="BAG", help="rosbag2 directory or .mcap file")
    p.add_argument("--out", required=True, metavar="YAML", help="body-shape file to write")
    add_calibration_arguments(p)
    p.add_argument("--model", type=int, choices=(18, 28, 39), default=39, help="tracking model DOF (default 39)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random stream (default 0)")
    p.add_argument("--start", type=int, default=0, metavar="K",
                   help="first frame (default: the first after the background learning)")
    p.add_argument("--use-masks", action="store_true", help="use /mocap/cam<i>/mask when the bag has it")
    p.add_argument("--learn-frames", type=int, default=None, metavar="K",
                   help="frames the segmenter learns the background from (default: the bag's empty frames, else 10)")
    p.add_argument("--report", default=None, metavar="JSON", help="also write the factors, energies and (with "
                                                                  "ground truth) bone-length errors here")
    p.add_argument("--overwrite", action="store_true", help="replace YAML if it exists")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.bag import BagReader
    from isa_mocap_ros.tracking.shape_calibration import ShapeCalibrationError

    def fail(msg):
        print(f"isa-mocap calibrate: error: {msg}", file=sys.stderr)
        return 2

    bag = Path(args.bag)
    out = Path(args.out)
    if not bag.exists():
        return fail(f"BAG: expected a rosbag2 directory or .mcap file, received {args.bag!r} (no such path)")
    if out.exists() and not args.overwrite:
        return fail(f"--out: {out} exists; pass --overwrite to replace it")
    try:
        with BagReader(bag) as probe:
            has_masks = any(t.startswith("/mocap/cam") and t.endswith("/mask") for t in probe.topics)
        use_masks = bool(args.use_masks and has_masks)
        seq = read_sequence(bag, want_images=not use_masks, want_masks=use_masks)
        if not seq.frames:
            return fail("BAG: expected frames with images, received none")
        learn = 0 if use_masks else (args.learn_frames if args.learn_frames is not None else (seq.empty_frames or 10))
        if not use_masks and learn < 1:
            return fail(f"--learn-frames: expected an integer >= 1, received {learn}")
        first = max(args.start, learn)
        if first >= len(seq.frames):
            return fail(f"--start: expected a frame before the bag's end ({len(seq.frames)} frames), received {first}")
        res, report = calibrate_sequence(seq, args, dof=args.model, use_masks=use_masks, learn=learn, first=first,
                                         progress=lambda s: print(s, file=sys.stderr, flush=True))
    except (ValueError, ShapeCalibrationError) as exc:
        return fail(str(exc))
    save_calibrated_shape(res, bag.name, out)
    report.update(bag=str(bag), out=str(out))
    if args.report:
        Path(args.report).write_text(json.dumps(report, indent=2) + "\n")
    print(f"calibrate: silhouette energy {report['energy_default_shape']:.4f} (default shape) -> "
          f"{report['energy']:.4f} over {report['frames']} frames; factors "
          + ", ".join(f"{k} {v:.3f}" for k, v in report["params"].items()))
    if "bone_error" in report:
        e, e0 = report["bone_error"], report["bone_error_default_shape"]
        print(f"calibrate: mean bone-length error against the bag's joint centres {e['mean_mm']:.1f} mm "
              f"(default shape {e0['mean_mm']:.1f} mm); the 8 limb bones {e['limbs_mean_mm']:.1f} mm "
              f"(default shape {e0['limbs_mean_mm']:.1f} mm)")
    print(f"calibrate: wrote {out}")
    return 0
