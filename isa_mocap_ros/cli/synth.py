"""``isa-mocap synth MOTION OUT``: render a motion into a multi-view rosbag2 MCAP bag with ground truth.

MOTION is a generated motion name (walk, jog, walk_turns, wave, box) or a BVH file. ``--body mesh``
(default) renders a skinned MakeHuman human mesh (``--subject``); ``--body capsules`` the tracking
model's capsules. The pure work
(motion, rendering, stamps) is :mod:`isa_mocap_ros.synth`; this module converts to ROS messages
(:mod:`msg_adapters`) and writes the bag (:class:`isa_mocap_ros.bag.BagWriter`).

Topics (``i`` = view index; see ``docs/synthetic_sequences.md``):

* ``/mocap/cam<i>/image_raw`` ``sensor_msgs/msg/Image`` rgb8, frame ``cam<i>_optical_frame``
* ``/mocap/cam<i>/camera_info`` ``sensor_msgs/msg/CameraInfo`` (every frame)
* ``/mocap/cam<i>/extrinsics`` ``geometry_msgs/msg/TransformStamped`` world -> ``cam<i>_optical_frame``,
  latched (transient local, depth 1), once at ``t0``
* ``/mocap/cam<i>/mask`` ``sensor_msgs/msg/Image`` mono8 0/255 exact silhouette (``--masks`` only)
* ``/mocap/ground_truth/joint_states`` ``sensor_msgs/msg/JointState`` (``model.dof_names``; root
  as x, y, z, roll, pitch, yaw), body frames only
* ``/mocap/ground_truth/markers`` ``geometry_msgs/msg/PoseArray`` in ``world``: one pose per joint named
  in the model YAML's ``model.marker_joints``, in that order (position = joint centre; orientation =
  the joint frame for capsule bodies, identity for mesh bodies), body frames only
* ``/mocap/ground_truth/model`` ``std_msgs/msg/String`` YAML (model, shape, motion, seed), latched

Every message of frame ``k`` has ``header.stamp`` = log time = ``T0_NS + round(k * 1e9 / fps)``.
Exit codes: 0 done, 2 bad input (message on stderr), 130 interrupted.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

TOPIC = "/mocap"


def register(sub) -> None:
    p = sub.add_parser("synth", help="render a generated motion or a BVH file into a multi-view MCAP bag",
                       description="Render MOTION (walk, jog, walk_turns, wave, box, or a .bvh file) into V "
                                   "calibrated views with exact ground truth, as a rosbag2 MCAP bag OUT.")
    p.add_argument("motion", metavar="MOTION", help="generated motion name or BVH file")
    p.add_argument("out", metavar="OUT", help="bag directory to write")
    p.add_argument("--views", type=int, default=None, help="number of cameras (default 4; all of --rig)")
    p.add_argument("--width", type=int, default=None, help="image width (default 320; a --rig keeps its own)")
    p.add_argument("--height", type=int, default=None, help="image height (default 240; a --rig keeps its own)")
    p.add_argument("--fps", type=float, default=30.0, help="frame rate; a BVH is resampled (default 30)")
    p.add_argument("--model", type=int, choices=(18, 28, 39), default=39, help="body model DOF (default 39)")
    p.add_argument("--start-s", type=float, default=0.0, metavar="S", help="skip the first S seconds of the motion")
    p.add_argument("--duration-s", type=float, default=None, metavar="S",
                   help="seconds of motion (default: a BVH's rest, 5 s of a generated motion)")
    p.add_argument("--empty-frames", type=int, default=0, metavar="K",
                   help="K background-only frames first, without ground truth (default 0)")
    p.add_argument("--noise", type=float, default=0.0, metavar="P", help="pixel-noise probability (ISA §13.4.2)")
    p.add_argument("--occluders", type=int, default=0, metavar="K", help="occluding rectangles per image")
    p.add_argument("--rig", default=None, metavar="FILE",
                   help="camera rig YAML or any calibration file: Pose2Sim/anipose TOML, Qualisys .qca.txt, OpenCV "
                        "FileStorage, camera_info (default config/rigs/default_4cam.yaml)")
    p.add_argument("--seed", type=int, default=0, help="seed of motion, backgrounds and distortions (default 0)")
    p.add_argument("--bvh-scale", type=float, default=None, metavar="M", help="metres per BVH unit (default: detect)")
    p.add_argument("--body", choices=("mesh", "capsules"), default="mesh",
                   help="mesh (default): a skinned MakeHuman human mesh; capsules: the tracking model's own "
                        "capsules (a control)")
    p.add_argument("--subject", default="average_man",
                   choices=("slim_woman", "average_man", "heavy_man", "random"),
                   help="mesh subject: slim_woman (1.60 m), average_man (1.78 m, default), heavy_man (1.88 m), "
                        "random (drawn from --seed)")
    p.add_argument("--skirt", action="store_true", help="mesh subject wears MakeHuman's (CC0) helper skirt")
    p.add_argument("--stretch-mesh", action="store_true",
                   help="BVH on a mesh, a diagnostic: the mesh follows the BVH's own joints, each segment stretched to "
                        "the BVH's bone length (default: the BVH's motion on the subject's own skeleton)")
    p.add_argument("--masks", action="store_true", help="also write the exact silhouettes on /mocap/cam<i>/mask")
    p.add_argument("--compression", choices=("zstd", "lz4", "none"), default="zstd", help="MCAP chunk compression")
    p.add_argument("--chunk-mb", type=float, default=32.0, metavar="MB",
                   help="MCAP chunk size before compression (default 32: the fixed backgrounds of all views "
                        "then compress against each other)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing bag at OUT")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _fail(msg: str) -> int:
    print(f"isa-mocap synth: error: {msg}", file=sys.stderr)
    return 2


def _rig(args):
    from isa_mocap_ros.vision import default_rig
    from isa_mocap_ros.vision.calib_formats import read_calibration
    from isa_mocap_ros.vision.calibration import Rig

    if args.views is not None and args.views < 1:
        raise ValueError(f"--views: expected an integer >= 1, received {args.views}")
    for name in ("width", "height"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise ValueError(f"--{name}: expected an integer >= 1, received {v}")
    if args.rig is None:
        return default_rig(n_views=args.views or 4, width=args.width or 320, height=args.height or 240)
    if not Path(args.rig).is_file():
        raise ValueError(f"--rig: expected a rig YAML file or another calibration file, received {args.rig!r} (no such file)")
    rig = read_calibration(args.rig)
    if args.views is not None:
        if args.views > len(rig):
            raise ValueError(f"--views: expected at most the {len(rig)} cameras of {args.rig}, received {args.views}")
        rig = Rig(rig.cameras[:args.views], rig.name, rig.capture_volume)
    if args.width is not None or args.height is not None:
        c0 = rig.cameras[0]
        rig = rig.resized(args.width or c0.width, args.height or c0.height)
    return rig


def camera_info_message(cam, stamp_ns, frame_id):
    """The ``sensor_msgs/CameraInfo`` of camera ``cam`` (0 or 4 distortion coefficients padded to 5)."""
    from msg_adapters import Intrinsics, intrinsics_to_camera_info

    D = np.asarray(cam.dist, dtype=float)
    if D.size in (0, 4):
        D = np.concatenate([D, np.zeros(5 - D.size)])
    P = np.hstack([cam.K, np.zeros((3, 1))])
    intr = Intrinsics(K=cam.K, D=D, P=P, R=np.eye(3), width=cam.width, height=cam.height,
                      distortion_model=cam.distortion_model)
    return intrinsics_to_camera_info(intr, stamp_ns=stamp_ns, frame_id=frame_id)


def _pose_array(positions, rotations, stamp_ns):
    from geometry_msgs.msg import Pose, PoseArray

    from msg_adapters import make_header, matrix_to_quaternion

    msg = PoseArray(header=make_header(stamp_ns, "world"))
    poses = []
    for p, R in zip(positions, rotations):
        q = matrix_to_quaternion(R)
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = (float(v) for v in p)
        pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = (float(v) for v in q)
        poses.append(pose)
    msg.poses = poses
    return msg


def canonical_cdr(cdr: bytes, type_name: str) -> bytes:
    """The CDR bytes of a message with zeroed alignment padding.

    rclpy's serializer (Fast-CDR) leaves the padding bytes between fields uninitialised (and may
    append a few bytes after the message), so two serializations of equal messages can differ; a
    round trip through the rosbags typestore (which writes zeros) makes the bytes a function of the
    message alone (byte-identical bags). Little-endian input, as rclpy writes on every platform we
    run on.
    """
    from isa_mocap_ros.bag.writer import typestore

    ts = typestore()
    if cdr[:2] != b"\x00\x01":
        raise ValueError(f"CDR of {type_name}: expected little-endian encapsulation 00 01, received {cdr[:2].hex()}")
    msgdef = ts.get_msgdef(type_name)
    msg, _ = msgdef.deserialize_cdr_le(memoryview(cdr)[4:], 0, msgdef.cls, ts)
    return bytes(ts.serialize_cdr(msg, type_name))


def write_bag(args) -> dict:
    """Do the work of ``isa-mocap synth`` (raises ValueError subclasses on bad input); return a summary."""
    from std_msgs.msg import String
    from tqdm import tqdm

    from isa_mocap_ros.bag import QOS_DEFAULT, QOS_LATCHED, BagWriter
    from isa_mocap_ros.body import pose_to_joint_state
    from isa_mocap_ros.synth import T0_NS, make_clip, make_renderer, model_yaml, synthesize
    from msg_adapters import array_to_image, arrays_to_joint_state, rt_to_transform, to_cdr, type_name_of

    def cdr(msg) -> bytes:
        return canonical_cdr(to_cdr(msg), type_name_of(msg))

    out = Path(args.out)
    if (out.exists() or out.is_symlink()) and not args.overwrite:
        raise FileExistsError(f"OUT: {out} exists; expected a new bag path (pass --overwrite to replace it)")
    if args.empty_frames < 0:
        raise ValueError(f"--empty-frames: expected an integer >= 0, received {args.empty_frames}")
    rig = _rig(args)
    show = not args.no_progress
    clip = make_clip(args.motion, dof=args.model, fps=args.fps, start_s=args.start_s, duration_s=args.duration_s,
                     seed=args.seed, bvh_scale=args.bvh_scale, body=getattr(args, "body", "mesh"),
                     subject=getattr(args, "subject", "average_man"), skirt=getattr(args, "skirt", False),
                     stretch=getattr(args, "stretch_mesh", False))
    renderer = make_renderer(clip, rig, seed=args.seed, noise=args.noise, occluders=args.occluders)
    V = len(rig)
    frames_total = args.empty_frames + clip.n_frames
    names = list(clip.model.dof_names)
    unseen = np.zeros(V, dtype=int)
    t_start = time.perf_counter()
    if not args.chunk_mb > 0:
        raise ValueError(f"--chunk-mb: expected a size > 0 MB, received {args.chunk_mb}")
    with BagWriter(out, compression=args.compression, overwrite=args.overwrite,
                   chunk_size=int(args.chunk_mb * 1024 * 1024)) as bag:
        for i in range(V):
            bag.add_topic(f"{TOPIC}/cam{i}/image_raw", "sensor_msgs/msg/Image", qos=[QOS_DEFAULT])
            bag.add_topic(f"{TOPIC}/cam{i}/camera_info", "sensor_msgs/msg/CameraInfo", qos=[QOS_DEFAULT])
            bag.add_topic(f"{TOPIC}/cam{i}/extrinsics", "geometry_msgs/msg/TransformStamped", qos=[QOS_LATCHED])
            if args.masks:
                bag.add_topic(f"{TOPIC}/cam{i}/mask", "sensor_msgs/msg/Image", qos=[QOS_DEFAULT])
        bag.add_topic(f"{TOPIC}/ground_truth/joint_states", "sensor_msgs/msg/JointState", qos=[QOS_DEFAULT])
        bag.add_topic(f"{TOPIC}/ground_truth/markers", "geometry_msgs/msg/PoseArray", qos=[QOS_DEFAULT])
        bag.add_topic(f"{TOPIC}/ground_truth/model", "std_msgs/msg/String", qos=[QOS_LATCHED])
        # latched descriptions at t0
        for i, cam in enumerate(rig.cameras):
            tf = rt_to_transform(cam.R.T, cam.center, parent_frame="world", child_frame=f"cam{i}_optical_frame",
                                 stamp_ns=T0_NS)
            bag.write(f"{TOPIC}/cam{i}/extrinsics", cdr(tf), T0_NS)
        text = model_yaml(clip, seed=args.seed, empty_frames=args.empty_frames, rig=rig, noise=args.noise,
                          occluders=args.occluders)
        bag.write(f"{TOPIC}/ground_truth/model", cdr(String(data=text)), T0_NS)
        bar = tqdm(total=frames_total, unit="frame", desc="synth", file=sys.stderr, disable=not show)
        for fr in synthesize(clip, renderer, empty_frames=args.empty_frames):
            s = fr.stamp_ns
            for i, cam in enumerate(rig.cameras):
                fid = f"cam{i}_optical_frame"
                bag.write(f"{TOPIC}/cam{i}/image_raw", cdr(array_to_image(fr.images[i], "rgb8", stamp_ns=s,
                                                                           frame_id=fid)), s)
                bag.write(f"{TOPIC}/cam{i}/camera_info", cdr(camera_info_message(cam, s, fid)), s)
                if args.masks:
                    bag.write(f"{TOPIC}/cam{i}/mask", cdr(array_to_image(fr.masks[i], "mono8", stamp_ns=s,
                                                                          frame_id=fid)), s)
                if not fr.empty and not fr.masks[i].any():
                    unseen[i] += 1
            if not fr.empty:
                q = pose_to_joint_state(clip.model, fr.pose)
                bag.write(f"{TOPIC}/ground_truth/joint_states",
                          cdr(arrays_to_joint_state(names, q, stamp_ns=s, frame_id="world")), s)
                bag.write(f"{TOPIC}/ground_truth/markers", cdr(_pose_array(fr.markers, fr.marker_rotations, s)), s)
            bar.update(1)
        bar.close()
    seconds = time.perf_counter() - t_start
    size = sum(f.stat().st_size for f in out.iterdir() if f.is_file())
    return {"bag": str(out), "frames": frames_total, "empty_frames": args.empty_frames, "views": V,
            "size": f"{rig.cameras[0].width}x{rig.cameras[0].height}", "fps": clip.fps, "model": clip.model.name,
            "motion": clip.name if clip.source == "generated" else clip.source, "seconds": seconds,
            "body": clip.body if clip.mesh is None else f"mesh ({clip.mesh.subject.name}, "
                                                          f"{clip.mesh.subject.stature_m:.2f} m)",
            "frames_per_s": frames_total / seconds if seconds > 0 else float("inf"), "bytes": size,
            "frames_without_body": {f"cam{i}": int(n) for i, n in enumerate(unseen) if n},
            "params": clip.params}


def run(args: argparse.Namespace) -> int:
    try:
        summary = write_bag(args)
    except (ValueError, FileExistsError) as exc:   # SynthError, BodyError, VisionError, BagError, AdapterError
        return _fail(str(exc))
    print(f"synth: wrote {summary['bag']}: {summary['frames']} frames ({summary['empty_frames']} empty) x "
          f"{summary['views']} views at {summary['size']}, {summary['fps']:g} fps, body {summary['body']}, "
          f"{summary['model']}, motion "
          f"{summary['motion']}; {summary['bytes'] / 1e6:.2f} MB in {summary['seconds']:.1f} s "
          f"({summary['frames_per_s']:.1f} frames/s)")
    if "retarget_mean_mm" in summary["params"]:
        print(f"synth: retargeting residual {summary['params']['retarget_mean_mm']:.1f} mm (mean joint distance)")
    if summary["frames_without_body"]:
        print(f"synth: warning: body outside the image in some frames: {summary['frames_without_body']}",
              file=sys.stderr)
    return 0
