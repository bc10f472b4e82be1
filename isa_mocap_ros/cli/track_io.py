"""Reading a bag for ``isa-mocap track`` and the other commands, and ``track``'s mask and overlay helpers.

:func:`read_sequence` converts a bag's messages (``msg_adapters``) into a
:class:`isa_mocap_ros.sequence.Sequence`; :func:`refine_by_model`, :func:`reference_coverage` and
:func:`write_overlay_media` are the ``--refine-masks``, mask coverage and ``--overlays`` steps of
:func:`isa_mocap_ros.cli.track.track_bag`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

TOPIC = "/mocap"


def read_sequence(path, *, want_images: bool, want_masks: bool):
    """Read a bag into a :class:`~isa_mocap_ros.sequence.Sequence` (message conversion lives here)."""
    from isa_mocap_ros.bag import BagReader
    from isa_mocap_ros.sequence import SequenceBuilder, view_of_topic
    from msg_adapters import (camera_info_to_intrinsics, from_cdr, image_to_array, joint_state_to_arrays,
                              stamp_to_ns, transform_to_rt)

    b = SequenceBuilder()
    with BagReader(path) as bag:
        wanted = []
        for name in bag.topics:
            vk = view_of_topic(name)
            if vk is not None:
                kind = vk[1]
                if kind in ("camera_info", "extrinsics") or (kind == "image_raw" and want_images) \
                        or (kind == "mask" and want_masks):
                    wanted.append(name)
            elif name in (f"{TOPIC}/ground_truth/joint_states", f"{TOPIC}/ground_truth/model",
                          f"{TOPIC}/ground_truth/markers", f"{TOPIC}/ground_truth/reference"):
                wanted.append(name)
        seen_info: set[int] = set()
        for m in bag.messages(wanted):
            vk = view_of_topic(m.topic)
            if vk is not None:
                v, kind = vk
                if kind == "camera_info":
                    if v in seen_info:       # intrinsics are the same every frame: decode once
                        continue
                    seen_info.add(v)
                    intr = camera_info_to_intrinsics(from_cdr(m.data, m.type))
                    b.add_camera_info(v, K=intr.K, D=intr.D, width=intr.width, height=intr.height)
                elif kind == "extrinsics":
                    R, t = transform_to_rt(from_cdr(m.data, m.type))
                    b.add_extrinsics(v, R, t)
                else:
                    msg = from_cdr(m.data, m.type)
                    arr = np.array(image_to_array(msg), copy=True)
                    stamp = stamp_to_ns(msg.header)
                    (b.add_image if kind == "image_raw" else b.add_mask)(v, stamp, arr)
            elif m.topic.endswith("/model"):
                b.set_model_yaml(from_cdr(m.data, m.type).data)
            elif m.topic.endswith("/reference"):
                b.set_reference_yaml(from_cdr(m.data, m.type).data)
            elif m.topic.endswith("/markers"):
                msg = from_cdr(m.data, m.type)
                b.add_truth_markers(stamp_to_ns(msg.header),
                                    [(p.position.x, p.position.y, p.position.z) for p in msg.poses])
            else:
                msg = from_cdr(m.data, m.type)
                names, pos = joint_state_to_arrays(msg)
                b.add_truth(stamp_to_ns(msg.header), names, pos)
    return b.build()


def refine_by_model(model, cameras, pose, images, masks) -> list:
    """``masks`` refined per view by :func:`isa_mocap_ros.vision.refine.refine_mask` with the silhouette
    of ``pose`` (the previous estimate) as the shape prior; views without an image keep their mask."""
    from isa_mocap_ros.body import capsule_endpoints
    from isa_mocap_ros.vision.refine import refine_mask
    from isa_mocap_ros.vision.render import render_mask

    E = capsule_endpoints(model, np.asarray(pose)[None])[0]
    out = []
    for cam, img, m in zip(cameras, images, masks):
        if img is None or m is None or img.ndim != 3:
            out.append(m)
            continue
        out.append(refine_mask(img, m, render_mask(cam, E, model.capsule_radii)))
    return out


def write_overlay_media(folder: Path, model, seq, tracked: list, *, strip_frames: int = 5,
                        slow_down: float = 4.0) -> dict:
    """The estimate drawn on every view: ``folder/strip.png`` (``strip_frames`` frames spread over the
    tracked ones, one row each, all views side by side) and ``folder/overlay.mp4`` (every tracked
    frame, played ``slow_down`` times slower than recorded). ``tracked``: (frame index, images, masks
    used, pose) per tracked frame. The reference's points, when the bag has them, are drawn as red dots."""
    import cv2

    from isa_mocap_ros.body import capsule_endpoints
    from isa_mocap_ros.vision.overlay import VideoStrip, overlay_row, write_strip

    by_index = {f.index: f for f in seq.frames}
    E = capsule_endpoints(model, np.array([t[3] for t in tracked]))
    stamps = [by_index[t[0]].stamp_ns for t in tracked]
    fps = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / 1e9) if len(stamps) > 1 and stamps[-1] > stamps[0] else 30.0

    def row(k):
        idx, images, masks, _ = tracked[k]
        r = overlay_row(images, seq.cameras, E[k], model.capsule_radii, masks=masks, label=f"frame {idx}")
        pts = by_index[idx].truth_markers
        if pts is not None:
            P = pts[np.all(np.isfinite(pts), axis=1)]
            x_off = 0
            for cam, img in zip(seq.cameras, images):
                w = img.shape[1] if img is not None else 0
                if img is not None and len(P):
                    for u, v in cam.project(P)[cam.depth(P) > 0]:
                        if 0 <= u < w and 0 <= v < img.shape[0]:
                            cv2.circle(r, (int(round(u)) + x_off, int(round(v))), 2, (255, 30, 30), -1, cv2.LINE_AA)
                x_off += w
        return r

    pick = sorted(set(np.linspace(0, len(tracked) - 1, min(strip_frames, len(tracked))).round().astype(int)))
    folder.mkdir(parents=True, exist_ok=True)
    write_strip(folder / "strip.png", [row(k) for k in pick])
    video = VideoStrip(folder / "overlay.mp4", fps / slow_down)
    try:
        for k in range(len(tracked)):
            video.add(row(k))
    finally:
        video.close()
    return {"strip": str(folder / "strip.png"), "strip_frames": [int(tracked[k][0]) for k in pick],
            "video": str(folder / "overlay.mp4"), "video_frames": video.frames, "video_fps": round(fps / slow_down, 3)}


def reference_coverage(cameras, points, masks) -> float:
    """Share of the reference points ``(M, 3)`` (world, NaN = missing) that project inside the image
    and fall on the foreground of that view's mask, over all views (NaN when none is in view)."""
    hit = n = 0
    P = np.asarray(points, float)
    P = P[np.all(np.isfinite(P), axis=1)]
    for cam, m in zip(cameras, masks):
        if m is None or not len(P):
            continue
        uv = np.round(cam.project(P)).astype(int)
        ok = (cam.depth(P) > 0) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] < m.shape[1]) & (uv[:, 1] < m.shape[0])
        n += int(ok.sum())
        hit += int(np.count_nonzero(m[uv[ok, 1], uv[ok, 0]]))
    return hit / n if n else float("nan")


def smooth_track(model, stamps_ns: dict, estimates: dict, cutoff_hz: float, *, order: int = 4) -> dict:
    """``track --smooth-hz``: the estimates (frame index -> pose) low-passed without delay
    (:func:`isa_mocap_ros.tracking.smooth.smooth_poses`), each run of consecutive tracked frames on its own (the
    frame rate from the run's stamps); frame index -> smoothed pose."""
    from isa_mocap_ros.tracking.smooth import smooth_poses

    keys = sorted(estimates)
    if len(keys) < 2:
        return dict(estimates)
    step = min(b - a for a, b in zip(keys, keys[1:]))
    runs, cur = [], [keys[0]]
    for k in keys[1:]:
        if k - cur[-1] == step:
            cur.append(k)
        else:
            runs.append(cur)
            cur = [k]
    runs.append(cur)
    out = {}
    for run in runs:
        X = np.array([estimates[k] for k in run])
        if len(run) >= 4:
            fps = 1e9 * (len(run) - 1) / (stamps_ns[run[-1]] - stamps_ns[run[0]])
            X = smooth_poses(model, X, fps, cutoff_hz, order=order)
        out.update(zip(run, X))
    return out


class JointStateBag:
    """A rosbag2 of ``/mocap/joint_states`` with ``/mocap/model`` latched beside it (the model the joint states
    belong to, with the shape tracked with: a self-describing result), written as the poses come: ``track``'s
    estimates and :func:`write_joint_states`. The model is written once, at ``model_stamp_ns`` or, when that
    is None, at the first pose's stamp."""

    def __init__(self, path: Path, model, *, role: str, overwrite: bool, model_stamp_ns: int | None = None) -> None:
        from isa_mocap_ros.bag import QOS_DEFAULT, QOS_LATCHED, BagWriter

        self.model, self._role = model, role
        self._bag = BagWriter(path, overwrite=overwrite)
        self._bag.add_topic(f"{TOPIC}/joint_states", "sensor_msgs/msg/JointState", qos=[QOS_DEFAULT])
        self._bag.add_topic(f"{TOPIC}/model", "std_msgs/msg/String", qos=[QOS_LATCHED])
        self._model_written = False
        if model_stamp_ns is not None:
            self._write_model(int(model_stamp_ns))

    def _write_model(self, stamp_ns: int) -> None:
        from std_msgs.msg import String

        from isa_mocap_ros.sequence import model_to_yaml
        from msg_adapters import to_cdr

        self._bag.write(f"{TOPIC}/model", to_cdr(String(data=model_to_yaml(self.model, role=self._role))), stamp_ns)
        self._model_written = True

    def write(self, stamp_ns: int, pose) -> None:
        """One pose (the model's state vector) as a ``sensor_msgs/JointState`` stamped ``stamp_ns``."""
        from isa_mocap_ros.body import pose_to_joint_state
        from msg_adapters import arrays_to_joint_state, to_cdr

        if not self._model_written:
            self._write_model(int(stamp_ns))
        q = pose_to_joint_state(self.model, pose)
        self._bag.write(f"{TOPIC}/joint_states",
                        to_cdr(arrays_to_joint_state(self.model.dof_names, q, stamp_ns=int(stamp_ns), frame_id="world")),
                        int(stamp_ns))

    def close(self) -> None:
        self._bag.close()

    def __enter__(self) -> "JointStateBag":
        return self

    def __exit__(self, *exc) -> None:
        self.close()    # also on an exception: what was written is kept as a complete bag


def write_joint_states(path: Path, model, poses_by_stamp: dict, *, overwrite: bool) -> None:
    """A rosbag2 with ``/mocap/joint_states`` of ``poses_by_stamp`` (stamp ns -> pose), as ``track`` writes its
    estimates (``/mocap/model`` latched beside them)."""
    with JointStateBag(path, model, role="isa-mocap track --smooth-hz", overwrite=overwrite) as bag:
        for s in sorted(poses_by_stamp):
            bag.write(s, poses_by_stamp[s])
