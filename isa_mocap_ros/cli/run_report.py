"""The evaluation half of ``isa-mocap run``: read the recording, compare with the bag's ground truth,
write ``summary.json``, plots and overlay frames, print a table.

Latency is measured from the recording: the recorder's receive time of a frame's
``/mocap/cam0/image_raw`` to its receive time of that frame's ``/mocap/joint_states`` (both arrive
in the same process over the same DDS path the segmentation node uses).

Overlay frames (``overlays/<stamp>_cam<i>.png``) are drawn here, after the run, from the bag's
images, the recorded masks and the recorded estimates, for ``--overlay-frames`` frames spread over
the estimated ones: the same picture the estimator's ``cam<i>/overlay`` shows, without the network
drawing, publishing and recording four overlay images for every frame set while it runs."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from isa_mocap_ros.bag import BagReader


def read_estimates(path: Path, model) -> dict:
    """Estimates, latencies and diagnostics from a run's recording."""
    import msg_adapters as ma
    from isa_mocap_ros.body import joint_state_to_pose

    poses: dict[int, np.ndarray] = {}
    js_time: dict[int, int] = {}
    img_time: dict[int, int] = {}
    mask_time: dict[int, int] = {}       # the last of a set's masks to reach the recorder
    done: list[int] = []
    overlays: list[tuple[int, str, np.ndarray]] = []
    diag: dict[str, str] = {}
    with BagReader(path) as bag:
        for m in bag.messages():
            if m.topic == "/mocap/joint_states":
                msg = ma.from_cdr(m.data, m.type)
                _, q = ma.joint_state_to_arrays(msg, model.dof_names)
                s = ma.stamp_to_ns(msg.header)
                poses[s] = joint_state_to_pose(model, q)
                js_time[s] = m.log_time_ns
            elif m.topic == "/mocap/cam0/image_raw":
                img_time.setdefault(ma.header_stamp_ns_from_cdr(m.data), m.log_time_ns)
            elif m.topic.startswith("/mocap/cam") and m.topic.endswith("/mask"):
                s = ma.header_stamp_ns_from_cdr(m.data)
                mask_time[s] = max(mask_time.get(s, 0), m.log_time_ns)
            elif m.topic == "/mocap/estimator/done":
                done.append(ma.header_stamp_ns_from_cdr(m.data))
            elif m.topic.endswith("/overlay"):
                msg = ma.from_cdr(m.data, m.type)
                overlays.append((ma.stamp_to_ns(msg.header), m.topic, np.array(ma.image_to_array(msg))))
            elif m.topic == "/diagnostics":
                msg = ma.from_cdr(m.data, m.type)
                for st in msg.status:
                    if st.name.endswith("estimator"):
                        diag = {kv.key: kv.value for kv in st.values}
    lat = [(js_time[s] - img_time[s]) / 1e6 for s in js_time if s in img_time]
    # the latency's two parts per estimated set: image -> its last mask (segmentation, transport) and that mask ->
    # the estimate (the estimator's wait for its worker, the tracker's step, publishing)
    masks_lat = [(mask_time[s] - img_time[s]) / 1e6 for s in js_time if s in img_time and s in mask_time]
    est_lat = [(js_time[s] - mask_time[s]) / 1e6 for s in js_time if s in img_time and s in mask_time]
    return {"poses": poses, "latencies_ms": lat, "mask_latencies_ms": masks_lat, "estimator_latencies_ms": est_lat,
            "done": done, "overlays": overlays, "diagnostics": diag}


def read_masks(path: Path) -> dict[tuple[int, int], bytes]:
    """The recorded ``/mocap/cam<i>/mask`` messages as CDR bytes, keyed ``(stamp_ns, view)``."""
    import msg_adapters as ma
    from isa_mocap_ros.sequence import view_of_topic

    masks: dict[tuple[int, int], bytes] = {}
    with BagReader(path) as bag:
        topics = [t for t in bag.topics if (vk := view_of_topic(t)) is not None and vk[1] == "mask"]
        for m in bag.messages(topics):
            masks[(ma.header_stamp_ns_from_cdr(m.data), view_of_topic(m.topic)[0])] = m.data
    return masks


def write_overlays(folder: Path, model, seq, poses: dict[int, np.ndarray], masks: dict[tuple[int, int], bytes],
                   n_frames: int) -> list[Path]:
    """Draw the estimate on the images of ``n_frames`` estimated frames (spread evenly), the mask the
    estimator used shaded in, as ``folder/<stamp>_cam<i>.png``; returns the files written."""
    import cv2

    import msg_adapters as ma
    from isa_mocap_ros.body import capsule_endpoints
    from isa_mocap_ros.vision.overlay import draw_overlay

    images = {f.stamp_ns: f.images for f in seq.frames if f.images is not None}
    stamps = sorted(s for s in poses if s in images)
    if not stamps or n_frames <= 0:
        return []
    pick = sorted({stamps[i] for i in np.linspace(0, len(stamps) - 1, min(n_frames, len(stamps)), dtype=int)})
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for s in pick:
        E = capsule_endpoints(model, poses[s][None])[0]
        for v, (cam, img) in enumerate(zip(seq.cameras, images[s])):
            if img is None:
                continue
            data = masks.get((s, v))
            mask = None if data is None else ma.image_to_array(ma.from_cdr(data, "sensor_msgs/msg/Image"))
            out = draw_overlay(img, cam, E, model.capsule_radii, mask=mask)
            path = folder / f"{s}_cam{v}.png"
            cv2.imwrite(str(path), cv2.cvtColor(out, cv2.COLOR_RGB2BGR))
            written.append(path)
    return written


def _first_gap(estimated: list[int], played: list[int]) -> int:
    """The length of the first gap after the first estimated stamp: the sets played without an
    estimate before the next estimated one (0 when there is none, or when no estimate follows it)."""
    done = set(estimated)
    n = 0
    for s in sorted(v for v in played if v > estimated[0]):
        if s in done:
            if n:
                return n
        else:
            n += 1
    return 0


def published_model(est_path: Path):
    """The tracking model the estimates bag names on ``/mocap/model`` (None when it has none)."""
    from isa_mocap_ros.bag import BagReader
    from isa_mocap_ros.sequence import model_from_yaml
    from msg_adapters import from_cdr

    with BagReader(est_path) as bag:
        if "/mocap/model" not in bag.topics:
            return None
        for m in bag.messages(["/mocap/model"]):
            return model_from_yaml(from_cdr(m.data, m.type).data)[0]
    return None


def summary_rows(summary: dict) -> list[tuple[str, object]]:
    """The printed table's rows: accuracy rows only when the bag had ground truth to score against,
    else one row saying so plainly."""
    if summary.get("ground_truth"):
        acc = [("frames (with ground truth)", summary.get("frames")),
               ("mean joint error (mm)", summary.get("mpjpe_mm"))]
        if "offset_removed_mpjpe_mm" in summary:     # scored against named markers
            acc.append(("  joint offsets removed (mm)", summary["offset_removed_mpjpe_mm"]))
        acc.append(("max frame error (mm)", summary.get("max_frame_error_mm")))
        if "offset_removed_max_frame_error_mm" in summary:
            acc.append(("  joint offsets removed (mm)", summary["offset_removed_max_frame_error_mm"]))
        acc.append(("knee RMSE (deg)", summary.get("knee_rmse_deg")))
        if summary.get("frames_facing_backwards") is not None:
            acc.append(("frames facing backwards", summary["frames_facing_backwards"]))
    else:
        acc = [("accuracy", summary.get("accuracy", "no ground truth"))]
    return acc + [("frames estimated", summary.get("frames_estimated")), ("frames/s", summary["fps"]),
                  ("latency p50 / p95 (ms)", (summary["latency_ms_p50"], summary["latency_ms_p95"])),
                  ("  image -> masks / masks -> estimate", tuple(summary.get(f"latency_{p}_ms_p{q}", float("nan"))
                                                            for p in ("mask", "estimator") for q in (50, 95))),
                  ("dropped frame sets", summary["dropped_frames"]), ("bad inputs", summary.get("bad_inputs")),
                  ("optimizer", summary["optimizer"]), ("evaluations per frame", summary["evals_per_frame"])]


def write_report(bag: Path, out: Path, *, args: argparse.Namespace, play_summary: dict,
                 wall_seconds: float) -> int:
    import cv2

    from isa_mocap_ros.body import make_model
    from isa_mocap_ros.cli.track_io import read_sequence
    from isa_mocap_ros.eval.report import plot_sequence

    model = make_model(args.model or 39)
    published = published_model(out / "estimates")   # the estimator's own description (/mocap/model)
    if published is not None and published.dof == model.dof:
        model = published
    rec = read_estimates(out / "estimates", model)
    poses = rec["poses"]
    lat = np.array(rec["latencies_ms"], dtype=float)
    diag = rec["diagnostics"]
    summary = {
        "bag": str(bag), "out": str(out), "mode": "lockstep" if args.lockstep else f"real time x{args.rate}",
        "optimizer": diag.get("optimizer", args.optimizer), "evals_per_frame": int(diag.get("evals_per_frame", 0) or 0),
        "model_dof": model.dof, "tracker_threads": int(diag.get("tracker_threads", 0) or 0), "seed": args.seed if args.seed is not None else 0,
        "frame_sets_played": play_summary.get("frames"), "frames_processed": len(rec["done"]),
        "frames_estimated": len(poses),
        # frame sets per second while the bag was being replayed (the player's own clock, without the
        # start-up settle and discovery waits)
        "fps": len(rec["done"]) / play_summary["seconds"] if play_summary.get("seconds") else float("nan"),
        "latency_ms_p50": float(np.percentile(lat, 50)) if lat.size else float("nan"),
        "latency_ms_p95": float(np.percentile(lat, 95)) if lat.size else float("nan"),
        # its parts (the recorder's receive times): image -> the set's last mask, that mask -> the estimate
        **{f"latency_{part}_ms_p{q}": (float(np.percentile(rec[f"{part}_latencies_ms"], q))
                                       if rec[f"{part}_latencies_ms"] else float("nan"))
           for part in ("mask", "estimator") for q in (50, 95)},
        # every frame set the player sent that the estimator did not process: replaced while the tracker
        # was busy (the estimator's own count, "dropped_by_estimator"), or lost before it (best-effort image
        # and mask subscriptions drop what a busy segmentation/estimator cannot take; the estimator's last
        # 1 Hz diagnostics also miss its last second)
        "dropped_frames": max(int(play_summary.get("frames") or 0) - len(rec["done"]),
                              int(diag.get("dropped_frame_sets", 0) or 0)),
        "dropped_by_estimator": int(diag.get("dropped_frame_sets", 0) or 0),
        # of the sets reaching the estimator, those less than half a period after the one before (their masks came
        # late, then together), and its drops at those arrivals: the inputs' timing, not the tracker's pace
        "sets_bunched": int(diag.get("sets_bunched", 0) or 0),
        "dropped_at_bunched_arrivals": int(diag.get("dropped_at_bunched_arrivals", 0) or 0),
        # real time: sets that waited longer than the estimator's catch_up_ms, tracked without the contour
        # stage (from its last 1 Hz diagnostics)
        "frames_without_contour_stage": int(diag.get("frames_without_contour_stage", 0) or 0),
        # real time: sets that waited during the automatic initialization, tracked after it at the catch-up
        # budget (the estimator's startup_catch_up) instead of being dropped
        "startup_sets_caught_up": int(diag.get("startup_sets_caught_up", 0) or 0),
        # Tracker.step per tracked set, the estimator's 1 Hz figure over its last 300 of them
        "tracker_ms_p50": float(diag.get("tracker_ms_p50", "nan")),
        "tracker_ms_p95": float(diag.get("tracker_ms_p95", "nan")),
        # Tracker.step of the set the automatic initialization ran on (nan: initialized otherwise)
        "init_ms": float(diag.get("init_ms", "nan")),
        # its worker-thread CPU, and the CPU of the start-up rehearsal on the empty sets before it (startup_rehearsal)
        "init_cpu_ms": float(diag.get("init_cpu_ms", "nan")),
        "init_rehearsal_ms": float(diag.get("init_rehearsal_ms", "nan")),
        "bad_inputs": int(diag.get("bad_inputs", 0) or 0), "wall_seconds": round(wall_seconds, 1),
        # frame sets tracked with keypoints (run --keypoints; the estimator's last 1 Hz figure)
        "keypoint_sets": int(diag.get("keypoint_sets", 0) or 0),
        # real time under load (the estimator's degrade, isa_mocap_ros.tracking.load), its last 1 Hz diagnostics:
        # times the budget was lowered, the level at the end (0 = full; "off" in lockstep), re-initializations
        "budget_lowered": int(diag.get("budget_lowered", 0) or 0),
        "budget_level": diag.get("budget_level"),
        "track_resets": int(diag.get("track_resets", 0) or 0),
        "recoveries": int(diag.get("recoveries", 0) or 0),
    }
    seq = read_sequence(bag, want_images=True, want_masks=False)
    # of those, the sets of the start-up: the first run of sets without an estimate after the first
    # estimate (the automatic initialization, and in real time the heading check after it, whose
    # consecutive sets the estimator holds: its drops come right after the check's frames)
    est = sorted(poses)
    summary["dropped_while_initializing"] = (_first_gap(est, [f.stamp_ns for f in seq.frames])
                                             if len(est) >= 2 else None)
    from isa_mocap_ros.eval.report import plot_marker_score, score

    acc = score(model, seq, poses)
    if acc is not None:
        stamps = acc.pop("stamps")
        summary.update(acc)
        P = np.array([poses[s] for s in stamps])
        t = (np.array(stamps) - stamps[0]) / 1e9
        title = f"{summary['optimizer']}, {summary['evals_per_frame']} evals/frame, {model.dof} DOF"
        if acc["scored_by"] == "markers":
            fm = {f.stamp_ns: f.truth_markers for f in seq.frames}
            plot_marker_score(out / "knees_and_error.png", model, P, list(seq.truth_marker_names),
                              np.array([fm[s] for s in stamps]), times_s=t, title=title)
        else:
            truth = {f.stamp_ns: f.truth for f in seq.frames if f.truth is not None}
            plot_sequence(out / "knees_and_error.png", model, P, seq.truth_model,
                          np.array([truth[s] for s in stamps]), times_s=t, title=title)
        summary["ground_truth"] = True
    else:
        # no accuracy figures at all (not "frames 135" beside "mean joint error None")
        summary["ground_truth"] = False
        summary["accuracy"] = ("no ground truth in the bag" if not (seq.has_truth or seq.has_marker_truth)
                               else "no estimate on a frame with ground truth")
    ov = rec["overlays"]
    if ov and args.overlay_frames > 0:  # the estimator published overlays (publish_overlay in --params)
        stamps_ov = sorted({s for s, _, _ in ov})
        pick = set(stamps_ov[i] for i in np.linspace(0, len(stamps_ov) - 1, min(args.overlay_frames, len(stamps_ov)),
                                                      dtype=int))
        (out / "overlays").mkdir(exist_ok=True)
        for s, topic, img in ov:
            if s in pick:
                cam = topic.split("/")[-2]
                cv2.imwrite(str(out / "overlays" / f"{s}_{cam}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    elif poses and args.overlay_frames > 0:
        write_overlays(out / "overlays", model, seq, poses, read_masks(out / "estimates"), args.overlay_frames)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"\nrun summary ({summary['mode']}):")
    for k, v in summary_rows(summary):
        if isinstance(v, float):
            v = f"{v:.2f}"
        elif isinstance(v, tuple):
            v = " / ".join(f"{x:.1f}" for x in v)
        print(f"  {k:28s} {v}")
    if summary.get("scored_by") == "markers":
        from isa_mocap_ros.eval.report import marker_score_lines

        print("\n".join(marker_score_lines(summary)))
    print(f"run: wrote {out / 'summary.json'}, {out / 'estimates'}"
          + (f", {out / 'knees_and_error.png'}" if (out / 'knees_and_error.png').exists() else ""))
    return 0
