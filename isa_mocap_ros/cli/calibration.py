"""``isa-mocap calibration import|export|show|intrinsics``: calibration files of other tools.

* ``import IN... OUT``: any calibration (Pose2Sim/anipose/caliscope TOML, Qualisys ``.qca.txt``,
  OpenCV FileStorage YAML/XML, one ROS ``camera_info`` YAML per camera, or a rig YAML) -> the
  project's rig YAML (``docs/vision.md``).
* ``export IN OUT --format F``: a calibration -> F (``toml``, ``qualisys``, ``opencv``,
  ``camera_info`` with ``{name}`` in OUT for one file per camera, ``rig``).
* ``show IN...``: per camera size, focal lengths, principal point, distortion, centre, direction.
* ``intrinsics IMAGES... --board 4x7 --square-mm 60``: calibrate one camera from checkerboard (or
  ``--charuco DICT``) images; prints the reprojection error and, with ``--out``, writes the camera
  as a ``camera_info`` YAML; ``--compare FILE --camera NAME`` prints the focal-length difference to a
  calibration.

Exit codes: 0 done, 2 bad input (one line on stderr naming the file, camera and field).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("calibration", help="import, export, show calibrations; intrinsics from board images",
                       description="Calibration files of other tools to and from the project's rig YAML, "
                                   "and intrinsic calibration from checkerboard / ChArUco images.")
    csub = p.add_subparsers(dest="calibration_command", metavar="ACTION")
    csub.required = True
    fmts = ("auto", "rig", "toml", "qualisys", "opencv", "camera_info")
    ip = csub.add_parser("import", help="any calibration file(s) -> rig YAML")
    ip.add_argument("inputs", nargs="+", metavar="IN", help="calibration file(s); several = one camera each")
    ip.add_argument("out", metavar="OUT", help="rig YAML to write")
    ip.add_argument("--format", dest="fmt", choices=fmts, default="auto", help="input format (default: detect)")
    ip.add_argument("--name", default=None, help="rig name (default: the input's file name)")
    ip.add_argument("--no-volume-check", action="store_true",
                    help="do not require every camera to see the default capture volume")
    ip.set_defaults(func=_import)
    ep = csub.add_parser("export", help="a calibration -> another format")
    ep.add_argument("input", metavar="IN", help="calibration file (any format)")
    ep.add_argument("out", metavar="OUT", help="file to write ('{name}' = one file per camera, camera_info)")
    ep.add_argument("--format", dest="fmt", choices=fmts, default="auto", help="output format (default: from OUT)")
    ep.set_defaults(func=_export)
    sp = csub.add_parser("show", help="print a calibration's cameras")
    sp.add_argument("inputs", nargs="+", metavar="IN")
    sp.add_argument("--format", dest="fmt", choices=fmts, default="auto")
    sp.set_defaults(func=_show)
    np_ = csub.add_parser("intrinsics", help="calibrate one camera from checkerboard / ChArUco images")
    np_.add_argument("images", nargs="+", metavar="IMAGE", help="board images of one camera")
    np_.add_argument("--board", required=True, metavar="AxB",
                     help="inner corners of the checkerboard (ChArUco: squares), e.g. 4x7")
    np_.add_argument("--square-mm", type=float, required=True, metavar="MM", help="side of a square")
    np_.add_argument("--charuco", default=None, metavar="DICT", help="ChArUco board with this aruco dictionary")
    np_.add_argument("--k3", action="store_true", help="also estimate the radial k3")
    np_.add_argument("--name", default="cam0", help="camera name written to --out")
    np_.add_argument("--out", default=None, metavar="FILE", help="write the camera as camera_info YAML")
    np_.add_argument("--compare", default=None, metavar="FILE", help="a calibration to compare focal lengths with")
    np_.add_argument("--camera", default=None, metavar="NAME", help="camera of --compare (default: --name)")
    np_.set_defaults(func=_intrinsics)


def _fail(msg: str) -> int:
    print(f"isa-mocap calibration: error: {msg}", file=sys.stderr)
    return 2


def _import(args: argparse.Namespace) -> int:
    from isa_mocap_ros.vision import VisionError
    from isa_mocap_ros.vision.calib_formats import format_rig, read_calibration, write_calibration

    try:
        rig = read_calibration(args.inputs, fmt=args.fmt, name=args.name,
                               capture_volume=None if args.no_volume_check else "default")
        write_calibration(rig, args.out, fmt="rig")
    except (VisionError, OSError) as exc:
        return _fail(str(exc))
    print(format_rig(rig))
    print(f"wrote {args.out}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from isa_mocap_ros.vision import VisionError
    from isa_mocap_ros.vision.calib_formats import read_calibration, write_calibration

    try:
        rig = read_calibration(args.input, capture_volume=None)
        write_calibration(rig, args.out, fmt=args.fmt)
    except (VisionError, OSError) as exc:
        return _fail(str(exc))
    print(f"wrote {args.out} ({len(rig)} cameras)")
    return 0


def _show(args: argparse.Namespace) -> int:
    from isa_mocap_ros.vision import VisionError
    from isa_mocap_ros.vision.calib_formats import format_rig, read_calibration

    try:
        rig = read_calibration(args.inputs, fmt=args.fmt, capture_volume=None)
    except (VisionError, OSError) as exc:
        return _fail(str(exc))
    print(format_rig(rig))
    return 0


def _intrinsics(args: argparse.Namespace) -> int:
    from isa_mocap_ros.vision import VisionError, save_camera
    from isa_mocap_ros.vision.calib_formats import read_calibration
    from isa_mocap_ros.vision.intrinsics import calibrate_intrinsics

    try:
        a, b = (int(v) for v in args.board.lower().split("x"))
    except ValueError:
        return _fail(f"--board: expected AxB (e.g. 4x7), received {args.board!r}")
    try:
        res = calibrate_intrinsics(args.images, board=(a, b), square_mm=args.square_mm, charuco=args.charuco,
                                   k3=args.k3, name=args.name)
    except VisionError as exc:
        return _fail(str(exc))
    c = res.camera
    print(f"{c.name}: {c.width}x{c.height}, board found in {len(res.used)} of {len(res.used) + len(res.rejected)} "
          f"images; RMS reprojection error {res.rms_px:.3f} px")
    for path, e in res.per_image_px.items():
        print(f"  {Path(path).name}: {e:.3f} px")
    for path in res.rejected:
        print(f"  {Path(path).name}: board not found")
    print(f"fx {c.fx:.2f}  fy {c.fy:.2f}  cx {c.cx:.2f}  cy {c.cy:.2f}  dist {[round(float(v), 5) for v in c.dist]}")
    if args.compare:
        try:
            ref = read_calibration(args.compare, capture_volume=None)
        except VisionError as exc:
            return _fail(str(exc))
        want = args.camera or args.name
        cams = {r.name: r for r in ref.cameras}
        if want not in cams:
            return _fail(f"--camera: {want!r} is not in {args.compare} (cameras: {sorted(cams)})")
        r = cams[want]
        print(f"vs {args.compare} [{want}]: fx {r.fx:.2f} ({100 * (c.fx / r.fx - 1):+.2f} %), "
              f"fy {r.fy:.2f} ({100 * (c.fy / r.fy - 1):+.2f} %)")
    if args.out:
        save_camera(c, args.out)
        print(f"wrote {args.out}")
    return 0
