"""``isa-mocap import OUT INPUT... --calibration FILE``: real videos or image folders -> a network bag.

INPUT is one video file (anything OpenCV decodes), image folder (its ``*.png``/``*.jpg``/...
files sorted by name) or glob per view, in view order; view ``i`` takes camera ``i`` of the
calibration (any format of :mod:`isa_mocap_ros.vision.calib_formats`), or the ``--cameras`` named.
Each view's frames are adapted to its calibration (same size / scaled / letterboxed: bars cut, see
:mod:`isa_mocap_ros.vision.adapt`; ``--fit crop`` for a centred cut) and resized to the working
size (``--width`` or ``--max-side``), the intrinsics scaled to match.

Topics (the layout of ``isa-mocap synth``; ``i`` = view index):

* ``/mocap/cam<i>/image_raw`` rgb8, ``/mocap/cam<i>/camera_info`` (adapted intrinsics, every frame),
  ``/mocap/cam<i>/extrinsics`` latched, world -> ``cam<i>_optical_frame``
* ``--background-frames K`` (default 10): K background-only frames first, made from the recording
  by :func:`isa_mocap_ros.vision.stable_background.estimate_background` (per pixel, the frames where
  the background shows; ``--background DIR`` adds images of the empty scene, one per view), so the
  segmentation's learn-from-empty-frames start works on a recording where the person never leaves;
  ``--find-person auto`` (default; ``on``/``off``): the person found in each frame by the BlazePose
  model's segmentation (:mod:`isa_mocap_ros.vision.person_masks`) when the model is installed, the
  background per pixel from the frames where it is not
* ``--reference FILE.trc``: ``/mocap/ground_truth/markers`` (``geometry_msgs/PoseArray`` in ``world``,
  one pose per TRC marker in file order, identity orientation, NaN for a missing marker) for every
  recording frame (TRC row ``start + j`` for frame ``j``), axes mapped by ``--reference-axes``
  (``pose2sim``: y-up TRC -> our z-up world); the marker names in the latched
  ``/mocap/ground_truth/reference`` (``std_msgs/String`` YAML: ``marker_names``, ``source``, ``axes``)

Frame ``k`` (background frames first) has stamp ``T0_NS + round(k * 1e9 / fps)``; fps = ``--fps``
or the first video's rate. Exit codes: 0 done, 2 bad input (one line on stderr), 130 interrupted.
"""
from __future__ import annotations

import argparse
import glob as globlib
import sys
import time
from pathlib import Path

import numpy as np
import yaml

TOPIC = "/mocap"
#: frames (spread over the recording) the person-masked background is estimated from
MAX_PERSON_FRAMES = 100
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
AXES = {"pose2sim": "world = (Z, X, Y) of the TRC point (Pose2Sim's zup2yup undone)", "none": "as in the file"}


def register(sub) -> None:
    p = sub.add_parser("import", help="real videos / image folders + a calibration -> a bag the network replays",
                       description="Turn synchronised videos or image folders (one per view) and a calibration "
                                   "into a rosbag2 MCAP bag in the network's topic layout.")
    p.add_argument("out", metavar="OUT", help="bag directory to write")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="one video file, image folder or glob per view")
    p.add_argument("--calibration", "--rig", dest="calibration", required=True, metavar="FILE",
                   help="calibration: rig YAML, Pose2Sim/anipose TOML, Qualisys .qca.txt, OpenCV FileStorage")
    p.add_argument("--cameras", default=None, metavar="A,B,..",
                   help="calibration camera names for the inputs, in order (default: the first cameras)")
    p.add_argument("--fit", choices=("auto", "scale", "letterbox", "crop"), default="auto",
                   help="frames of another size than the calibration (default auto: scale or letterbox)")
    size = p.add_mutually_exclusive_group()
    size.add_argument("--width", type=int, default=None, help="working width, aspect kept (default 320)")
    size.add_argument("--max-side", type=int, default=None, metavar="PX", help="working size: longer side")
    p.add_argument("--fps", type=float, default=None, help="frame rate (default: the first video's, else 30)")
    p.add_argument("--start", type=int, default=0, metavar="N", help="skip the first N frames")
    p.add_argument("--frames", type=int, default=None, metavar="N", help="import at most N frames")
    p.add_argument("--background", default=None, metavar="DIR",
                   help="images of the empty scene, one per view (sorted by name), same geometry as the inputs")
    p.add_argument("--background-frames", type=int, default=10, metavar="K",
                   help="background-only frames written first (default 10; 0 = none)")
    p.add_argument("--find-person", choices=("auto", "on", "off"), default="auto",
                   help="find the person in each frame with the BlazePose model's segmentation (the keypoints extra "
                        "and `make models`) and learn the background where it is not; auto (default): when the model "
                        "is installed; off: the temporal mode and the --background images alone")
    p.add_argument("--reference", default=None, metavar="TRC", help="reference 3-D markers (TRC) as ground truth")
    p.add_argument("--reference-axes", choices=tuple(AXES), default="pose2sim",
                   help="axes of the TRC file (default pose2sim: y-up, mapped to the z-up world)")
    p.add_argument("--check-png", default=None, metavar="PNG",
                   help="also write a contact sheet to look at: per view a frame with the reference markers "
                        "projected, the background estimate, and the mask the default segmentation finds")
    p.add_argument("--compression", choices=("zstd", "lz4", "none"), default="zstd")
    p.add_argument("--overwrite", action="store_true", help="replace an existing bag at OUT")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run)


class ImportInputError(ValueError):
    """Bad input to ``isa-mocap import``."""


def _open_inputs(inputs):
    """One frame source per view and a label for messages."""
    from isa_mocap_ros.vision.sources import ImageFolderSource, VideoFileSource

    srcs = []
    for s in inputs:
        p = Path(s)
        if p.is_dir():
            files = sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
            if not files:
                raise ImportInputError(f"{s}: folder holds no image ({', '.join(IMAGE_SUFFIXES)})")
            srcs.append(ImageFolderSource([str(p / ("*" + files[0].suffix))]))
        elif p.is_file():
            srcs.append(VideoFileSource([p]))
        elif globlib.glob(s):
            srcs.append(ImageFolderSource([s]))
        else:
            raise ImportInputError(f"{s}: no such video file, image folder or glob")
    return srcs


class _Joined:
    """Several one-view sources read together as one multi-view source."""

    def __init__(self, sources):
        self.sources = sources
        self.n_views = len(sources)

    def read(self):
        return [s.read()[0] for s in self.sources]

    def close(self):
        for s in self.sources:
            s.close()


def _select_cameras(rig, names, n):
    if names:
        want = [x.strip() for x in names.split(",") if x.strip()]
        have = {c.name: c for c in rig.cameras}
        missing = [w for w in want if w not in have]
        if missing:
            raise ImportInputError(f"--cameras: {missing} not in the calibration (cameras: {sorted(have)})")
        cams = [have[w] for w in want]
    else:
        cams = list(rig.cameras[:n])
    if len(cams) != n:
        raise ImportInputError(f"inputs: {n} views given, the calibration has {len(cams)} cameras selected "
                           f"({[c.name for c in rig.cameras]}); give one input per camera or --cameras")
    return cams


def _read_plates(directory, sensors, geoms, sizes):
    import cv2

    from isa_mocap_ros.vision.adapt import adapt_frame, frame_geometry

    d = Path(directory)
    files = sorted(f for f in d.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES) if d.is_dir() else []
    if len(files) != len(sensors):
        raise ImportInputError(f"--background {directory}: expected one image per view ({len(sensors)}), found "
                           f"{len(files)}")
    plates = []
    for f, cam, g, size in zip(files, sensors, geoms, sizes):
        img = cv2.imread(str(f), cv2.IMREAD_COLOR)
        if img is None:
            raise ImportInputError(f"--background: OpenCV cannot read {f}")
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
        pg = frame_geometry(cam, img.shape[1], img.shape[0], fit="auto" if g.fit != "crop" else "crop", frame=img,
                            source=str(f))
        plates.append(adapt_frame(img, pg, size))
    return plates


def _person_finder(mode: str):
    """The BlazePose landmarker for ``--find-person`` (None: off, or auto without the model)."""
    if mode == "off":
        return None
    from isa_mocap_ros.vision.errors import VisionError
    from isa_mocap_ros.vision.landmark_model import ModelUnavailable
    from isa_mocap_ros.vision.landmarks import PoseLandmarker

    try:
        return PoseLandmarker()
    except (ModelUnavailable, VisionError) as exc:
        if mode == "on":
            raise ImportInputError(f"--find-person on: {exc}") from exc
        print(f"import: the person is not found by a model ({exc}); background from the temporal mode and "
              "--background images", file=sys.stderr)
        return None


def _pose_array_positions(points, stamp_ns):
    from geometry_msgs.msg import Pose, PoseArray

    from msg_adapters import make_header

    msg = PoseArray(header=make_header(stamp_ns, "world"))
    poses = []
    for p in points:
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = (float(v) for v in p)
        pose.orientation.w = 1.0
        poses.append(pose)
    msg.poses = poses
    return msg


def write_import(args) -> dict:
    """Do the work of ``isa-mocap import``; raise ValueError subclasses on bad input; return a summary."""
    from std_msgs.msg import String
    from tqdm import tqdm

    from isa_mocap_ros.bag import QOS_DEFAULT, QOS_LATCHED, BagWriter
    from isa_mocap_ros.cli.synth import camera_info_message, canonical_cdr
    from isa_mocap_ros.eval.trc import TRC_TO_WORLD, read_trc
    from isa_mocap_ros.synth import T0_NS, stamp_ns
    from isa_mocap_ros.vision.calib_formats import read_calibration
    from isa_mocap_ros.vision.sources import AdaptedSource, EndOfSource
    from isa_mocap_ros.vision.person_masks import PERSON_THRESHOLD, find_person, people_in_plates
    from isa_mocap_ros.vision.stable_background import estimate_background
    from msg_adapters import array_to_image, rt_to_transform, to_cdr, type_name_of

    def cdr(msg) -> bytes:
        return canonical_cdr(to_cdr(msg), type_name_of(msg))

    out = Path(args.out)
    if (out.exists() or out.is_symlink()) and not args.overwrite:
        raise FileExistsError(f"OUT: {out} exists; expected a new bag path (pass --overwrite to replace it)")
    for name in ("start", "background_frames"):
        if getattr(args, name) < 0:
            raise ImportInputError(f"--{name.replace('_', '-')}: expected an integer >= 0, received {getattr(args, name)}")
    if args.frames is not None and args.frames < 1:
        raise ImportInputError(f"--frames: expected an integer >= 1, received {args.frames}")
    if not Path(args.calibration).is_file():
        raise ImportInputError(f"--calibration: {args.calibration} does not exist")
    rig = read_calibration(args.calibration)
    sensors = _select_cameras(rig, args.cameras, len(args.inputs))
    width = args.width if args.width is not None else (0 if args.max_side else 320)

    def open_adapted():
        return AdaptedSource(_Joined(_open_inputs(args.inputs)), sensors, fit=args.fit, width=width,
                             max_side=args.max_side or 0, rig_name=rig.name, capture_volume=None,
                             labels=list(args.inputs))

    src = open_adapted()
    fps = args.fps
    if fps is None:
        rates = [getattr(s, "fps", [0.0])[0] for s in src.source.sources]
        fps = rates[0] if rates and rates[0] > 0 else 30.0
    if not fps > 0:
        raise ImportInputError(f"--fps: expected a rate > 0, received {fps}")
    V = src.n_views
    cams = src.rig.cameras

    def frames_of(source):
        """The adapted frame sets of [start, start + frames)."""
        k = 0
        while args.frames is None or k < args.start + args.frames:
            try:
                imgs = source.read()
            except EndOfSource:
                return
            if k >= args.start:
                yield imgs
            k += 1

    # pass 1: samples for the background (every frame, thinned to at most 200 by doubling the stride)
    est = landmarker = None
    if args.background_frames:
        samples: list[list[np.ndarray]] = [[] for _ in range(V)]
        stride, n = 1, 0
        for imgs in frames_of(src):
            if n % stride == 0 and all(i is not None for i in imgs):
                for v in range(V):
                    samples[v].append(imgs[v])
                if len(samples[0]) >= 200:
                    samples = [s[::2] for s in samples]
                    stride *= 2
            n += 1
        src.close()
        if len(samples[0]) < 3:
            raise ImportInputError(f"inputs: {len(samples[0])} complete frame sets; the background needs at least 3 "
                               "(or --background-frames 0)")
        plates = (_read_plates(args.background, sensors, src.geometries, src.sizes) if args.background
                  else [[] for _ in range(V)])
        landmarker = _person_finder(args.find_person)
        est = []
        for v in range(V):
            stack = np.stack(samples[v])
            vplates = [plates[v]] if args.background else []
            if landmarker is None:
                e = estimate_background(stack, plates=vplates)
            else:
                stack = stack[np.unique(np.linspace(0, len(stack) - 1, min(len(stack), MAX_PERSON_FRAMES)).round()
                                        .astype(int))]
                person = find_person(stack, landmarker=landmarker) > PERSON_THRESHOLD
                e = estimate_background(stack, plates=vplates, person=person, plate_people=people_in_plates(
                    vplates, person.any(axis=0), landmarker=landmarker))
            est.append((e, e.frames(args.background_frames, stack)))
        src = open_adapted()
    elif args.background:
        raise ImportInputError("--background: needs --background-frames K > 0 (the background is written as frames)")

    ref = None
    if args.reference:
        trc = read_trc(args.reference)
        pts = trc.in_world(TRC_TO_WORLD if args.reference_axes == "pose2sim" else np.eye(3))
        ref = (trc, pts)

    K = args.background_frames
    t_start = time.perf_counter()
    custom = {"isa_mocap_import": yaml.safe_dump({
        "inputs": [str(s) for s in args.inputs], "calibration": str(args.calibration),
        "cameras": [c.name for c in sensors], "geometry": src.describe(), "fps": float(fps),
        "background_frames": K, "background_images": args.background, "reference": args.reference,
        "background_person": None if not K else ("found by the landmark model" if landmarker is not None else "not found"),
        "start": args.start}, sort_keys=False, width=200)}
    written = 0
    with BagWriter(out, compression=args.compression, overwrite=args.overwrite, chunk_size=32 * 1024 * 1024,
                   custom_data=custom) as bag:
        for i in range(V):
            bag.add_topic(f"{TOPIC}/cam{i}/image_raw", "sensor_msgs/msg/Image", qos=[QOS_DEFAULT])
            bag.add_topic(f"{TOPIC}/cam{i}/camera_info", "sensor_msgs/msg/CameraInfo", qos=[QOS_DEFAULT])
            bag.add_topic(f"{TOPIC}/cam{i}/extrinsics", "geometry_msgs/msg/TransformStamped", qos=[QOS_LATCHED])
        if ref is not None:
            bag.add_topic(f"{TOPIC}/ground_truth/markers", "geometry_msgs/msg/PoseArray", qos=[QOS_DEFAULT])
            bag.add_topic(f"{TOPIC}/ground_truth/reference", "std_msgs/msg/String", qos=[QOS_LATCHED])
        for i, cam in enumerate(cams):
            tf = rt_to_transform(cam.R.T, cam.center, parent_frame="world", child_frame=f"cam{i}_optical_frame",
                                 stamp_ns=T0_NS)
            bag.write(f"{TOPIC}/cam{i}/extrinsics", cdr(tf), T0_NS)
        if ref is not None:
            text = yaml.safe_dump({"format": 1, "kind": "reference_markers", "source": str(args.reference),
                                   "marker_names": list(ref[0].names), "units": "m", "frame": "world",
                                   "axes": AXES[args.reference_axes], "first_row": args.start}, sort_keys=False)
            bag.write(f"{TOPIC}/ground_truth/reference", cdr(String(data=text)), T0_NS)

        def write_set(k, imgs):
            s = stamp_ns(k, fps)
            for i, cam in enumerate(cams):
                if imgs[i] is None:
                    continue
                fid = f"cam{i}_optical_frame"
                bag.write(f"{TOPIC}/cam{i}/image_raw", cdr(array_to_image(imgs[i], "rgb8", stamp_ns=s, frame_id=fid)), s)
                bag.write(f"{TOPIC}/cam{i}/camera_info", cdr(camera_info_message(cam, s, fid)), s)
            return s

        for k in range(K):
            write_set(k, [est[v][1][k] for v in range(V)])
        bar = tqdm(unit="frame", desc="import", file=sys.stderr, disable=args.no_progress)
        kept = {}
        for j, imgs in enumerate(frames_of(src)):
            if args.check_png and j % 10 == 0:
                kept[j] = imgs
            s = write_set(K + j, imgs)
            row = args.start + j
            if ref is not None and row < len(ref[1]):
                bag.write(f"{TOPIC}/ground_truth/markers", cdr(_pose_array_positions(ref[1][row], s)), s)
            written += 1
            bar.update(1)
        bar.close()
    src.close()
    if written == 0:
        raise ImportInputError(f"inputs: no frame after --start {args.start}")
    seconds = time.perf_counter() - t_start
    if args.check_png:
        j = sorted(kept)[len(kept) // 2]
        check_sheet(args.check_png, cams, kept[j], None if ref is None or args.start + j >= len(ref[1])
                    else ref[1][args.start + j], None if est is None else [e for e, _ in est],
                    None if est is None else [f for _, f in est], label=f"frame {args.start + j}")
    return {"bag": str(out), "frames": written, "background_frames": K, "views": V, "fps": fps,
            "sizes": [f"{c.width}x{c.height}" for c in cams], "geometry": src.describe(),
            "reference_frames": 0 if ref is None else min(written, max(0, len(ref[1]) - args.start)),
            "reference_rows": 0 if ref is None else len(ref[1]), "seconds": seconds,
            "background_sources": None if est is None else [
                {int(c): int((e.source == c).sum()) for c in np.unique(e.source)} for e, _ in est]}


def check_sheet(path, cams, images, points, estimates, background_frames, *, label=""):
    """Contact sheet PNG: row 1 the frame with ``points`` (world, (M, 3)) projected as red dots; row 2 the
    background estimate (person region outlined); row 3 the frame with the mask of the default
    :class:`~isa_mocap_ros.vision.segmentation.BackgroundSegmenter` learnt from ``background_frames``
    (foreground tinted green). Columns = views."""
    import cv2

    from isa_mocap_ros.vision.segmentation import BackgroundSegmenter, SegmentationConfig

    cols = []
    h = max(img.shape[0] for img in images if img is not None)
    for v, cam in enumerate(cams):
        img = images[v]
        if img is None:
            continue
        top = img.copy()
        if points is not None:
            for u, w in cam.project(points[np.isfinite(points).all(axis=1)]):
                cv2.circle(top, (int(round(u)), int(round(w))), 3, (255, 0, 0), -1)
        cv2.putText(top, f"cam{v} {label}", (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 0), 1)
        rows = [top]
        if estimates is not None:
            bg = estimates[v].image.copy()
            cnts, _ = cv2.findContours(estimates[v].person_region, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
            cv2.drawContours(bg, cnts, -1, (255, 255, 0), 1)
            seg = BackgroundSegmenter(SegmentationConfig(learn_frames=len(background_frames[v])))
            for f in background_frames[v]:
                seg.apply(f)
            mask = seg.apply(img) > 0
            tint = img.copy()
            tint[mask] = (0.5 * tint[mask] + 0.5 * np.array([0, 255, 0])).astype(np.uint8)
            rows += [bg, tint]
        col = np.vstack([np.pad(r, ((0, h - r.shape[0]), (0, 0), (0, 0))) for r in rows])
        cols.append(col)
    sheet = np.hstack(cols)
    cv2.imwrite(str(path), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))


def run(args: argparse.Namespace) -> int:
    try:
        summary = write_import(args)
    except (ValueError, FileExistsError) as exc:
        print(f"isa-mocap import: error: {exc}", file=sys.stderr)
        return 2
    for i, line in enumerate(summary["geometry"]):
        print(f"import: cam{i}: {line}")
    if args.check_png:
        print(f"import: contact sheet {args.check_png}")
    print(f"import: wrote {summary['bag']}: {summary['background_frames']} background + {summary['frames']} frames x "
          f"{summary['views']} views ({', '.join(summary['sizes'])}) at {summary['fps']:g} fps in "
          f"{summary['seconds']:.1f} s")
    if summary["reference_rows"]:
        print(f"import: reference markers for {summary['reference_frames']} frames ({summary['reference_rows']} "
              "rows in the TRC file)")
        whole = args.frames is None and args.start == 0
        if summary["reference_frames"] < summary["frames"] or (whole and summary["reference_rows"] != summary["frames"]):
            print("import: warning: the TRC file and the videos have different frame counts; row start + j is "
                  "taken for frame j", file=sys.stderr)
    return 0
