"""Estimator node: synchronized multi-view masks + prediction -> body pose (the tracker, once per frame set).

Subscribes (relative names, launched in ``/mocap``): ``cam<i>/mask`` (mono8, sensor-data QoS),
``cam<i>/camera_info``, latched ``cam<i>/extrinsics`` (world -> camera optical frame),
``prediction/joint_states``, with ``publish_overlay`` ``cam<i>/image_raw``, and with ``keypoint_weight`` > 0
the keypoint node's ``cam<i>/keypoints`` (``PolygonStamped``) and ``cam<i>/keypoints_skipped`` (``Header``).

Publishes ``joint_states`` (JointState, ``model.dof_names``; root rotation as roll/pitch/yaw so
the exported URDF draws it), ``root_pose`` (PoseStamped), ``markers`` (MarkerArray skeleton),
``estimator/done`` (std_msgs/Header, one per processed frame set, tracked or not: the lockstep
topic for the player), ``cam<i>/overlay`` (optional), ``/diagnostics`` and the REP-155 view
``/humans/bodies/<id>/joint_states`` + latched ``/humans/bodies/<id>/urdf``; latched ``model`` (String YAML:
the tracking body model with its shape, the schema of ``/mocap/ground_truth/model``).

Frame sets are synchronized exactly or approximately (:mod:`isa_mocap_ros.tracking.sync`); a
worker thread runs the tracker so callbacks never block. In real-time mode a frame set that waits
while the tracker is busy is replaced by a newer one and counted as dropped; in lockstep mode every
set is processed and the estimator waits up to ``prediction_wait_s`` (10 s) for the prediction node's
prediction of that frame while a prediction node publishes (none: no wait).

Keypoints (``keypoint_weight`` > 0, docs/keypoints.md): a keypoint message belongs to the frame set of its
stamp and view; the tracker gets the set's keypoints with its masks. The keypoint node detects on some
frames only and says so for the others (``keypoints_skipped``): in lockstep the estimator waits until each view
of the set has one or the other, with no time limit while a keypoint node is in the graph (so the player, which
waits for ``estimator/done``, waits for the keypoint node too, and a replay is deterministic at any machine
speed), up to ``keypoint_wait_s`` while none is; a view whose message of a later set came is not waited for (the
node lost that frame: its message will never come). In real time it never waits: the set is tracked with the
keypoints that have arrived when the tracker takes it (:mod:`isa_mocap_ros.keypoint_intake`). A malformed
keypoint message (not 0 or 33 points, a non-finite pixel, a confidence outside [0, 1]) or one whose stamp lies far
from the frame sets (before the first set: from the first set) is dropped with one line and counted (in lockstep
the frame still waits for its view's own message).

Input checks, before anything reaches the synchronizer or the tracker (:mod:`isa_mocap_ros.intake`):
a view's camera is what a ``camera_info`` and a mask of the same stamp agree on (frame id, size); a
mask that disagrees with it, or lies more than ``max_stamp_gap_s`` from the view's stream, waits for
a camera_info of its own stamp and is dropped when none comes. The tracker's cameras are made from
those camera infos and from the ``extrinsics`` whose parent is ``world_frame`` and whose child is the
frame the view's masks name. A prediction is stored only when it is well formed (the model's joints,
finite) and its stamp lies within ``max_stamp_gap_s`` of the frame sets. A camera that changes (a
pair of a new size) restarts the tracker with the new cameras. Every dropped message is counted
(``bad_inputs`` in ``/diagnostics``) and logged, one rate-limited line per kind. The input callbacks are in
:mod:`isa_mocap_ros.nodes.estimator_intake`.
"""
from __future__ import annotations

import json
import re
import threading
import time
from collections import deque

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PolygonStamped, PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import ColorRGBA, Header, String
from geometry_msgs.msg import TransformStamped
from visualization_msgs.msg import Marker, MarkerArray

import msg_adapters as ma
from isa_mocap_ros.body import capsule_endpoints, joint_positions, make_model, pose_to_joint_state
from isa_mocap_ros.body.hri import hri_joint_names, hri_urdf
from isa_mocap_ros.eval.peers import register_peers
from isa_mocap_ros.geometry import exp_so3
from isa_mocap_ros.intake import StampWindow, ViewGate
from isa_mocap_ros.keypoint_intake import KeypointInbox, KeypointWait
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.nodes.common import (QOS_OVERRIDES, ProblemLog, declare, declare_config, declare_frame_sync,
                                       one_numba_thread, publishers_on, run_node)
from isa_mocap_ros.nodes.estimator_intake import EstimatorIntake
from isa_mocap_ros.tracking.predict import periods_between
from isa_mocap_ros.tracking.sync import FrameSynchronizer
from isa_mocap_ros.tracking.config import TrackerConfig, field_docs
from isa_mocap_ros.tracking.load import StartupCatchUp
from isa_mocap_ros.tracking.realtime import RealTimeSchedule, warm_up
from isa_mocap_ros.vision.overlay import draw_overlay


#: frame sets in a row without foreground before the worker rehearses the first-frame hull (``startup_rehearsal``): a
#: rehearsal (15-33 CPU ms on bags/demo) started right before the person's first set would delay its initialization by
#: that much; the segmentation's 10 learning frames leave 8 sets after it
REHEARSAL_AFTER_EMPTY_SETS = 2

#: TrackerConfig fields that are not parameters of this node (none: every setting is one)
NOT_PARAMETERS: tuple[str, ...] = ()

#: the starts of the tracker's notes (``FrameResult.notes``) on what a normal run does: the empty masks of
#: the frames before anyone is in view (the segmentation's background-learning frames), the automatic
#: initialization, the heading check, stages that their budget share or the pose leaves out. Logged at
#: INFO and counted apart from bad inputs; every other note is logged at WARN and counted as a problem.
EXPECTED_NOTES = ("initialized automatically", "heading check", "initialization polish", "recovered: ",
                  "no usable view and no estimate yet", "contour stage: stopped", "limb stage: ",
                  "prediction: the external one follows the estimates from before the heading check")
_EXPECTED_NOTE_PATTERNS = (re.compile(r"view \d+: empty mask \(nobody in view\)"),
                           re.compile(r"(pelvis|torso|limb|refinement|contour) stage skipped"),
                           re.compile(r"keypoints: (\d+ in \d+ views|none usable)"),
                           re.compile(r"keypoints screened: "))   # tracking/keypoint_screen.py: landmarks left out


def note_is_expected(note: str) -> bool:
    """Whether a tracker note reports an expected event (:data:`EXPECTED_NOTES`) rather than a problem."""
    return note.startswith(EXPECTED_NOTES) or any(p.match(note) for p in _EXPECTED_NOTE_PATTERNS)


class EstimatorNode(EstimatorIntake, Node):
    """Thin node over :class:`isa_mocap_ros.tracking.tracker.Tracker` (see the module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__("estimator", **kwargs)
        register_peers()  # the reference optimizers "pycma" and "scipy-de" are selectable too
        self.n_views = declare(self, "views", 4, "number of camera views", lo=1, hi=64)
        dof = declare(self, "model_dof", 39, "body model: 18, 28 or 39 DOF", lo=18, hi=39)
        shape = declare(self, "body_shape", "", "body-shape YAML file ('' = default shape)")
        # the tracker's settings: one parameter per TrackerConfig field, with its name, default and one-line doc
        settings = declare_config(self, TrackerConfig, field_docs(TrackerConfig), skip=NOT_PARAMETERS)
        sync_kw = declare_frame_sync(self, self.n_views)
        self.view_timeout_s = sync_kw["max_wait_s"]
        self.tracker_threads = declare(self, "tracker_threads", 1,
                                       "numba threads of the tracker's energy kernels (0 = numba's default, "
                                       "all cores; 1 leaves the other cores to the rest of the network); "
                                       "results do not depend on it", lo=0, hi=256)
        self.lockstep = declare(self, "lockstep", False, "process every frame set (no dropping) and wait "
                                "for the prediction of each frame")
        self.catch_up_ms = declare(self, "catch_up_ms", 15.0, "real time: a frame set that waited longer than this "
                                   "for the tracker is tracked without the contour stage, so the tracker catches up "
                                   "instead of dropping sets (0 = never)", lo=0.0, hi=60_000.0)
        self.backlog = declare(self, "backlog", 1, "real time: frame sets kept waiting while the tracker is busy "
                               "(the newest; older ones are dropped)", lo=1, hi=100)
        self.startup_catch_up = declare(
            self, "startup_catch_up", 0, "real time: frame sets kept waiting, in order, while the tracker initializes "
            "itself; once initialized it tracks them with degrade_min_evals evaluations and no contour stage until "
            "none waits, instead of dropping them (0, the default: keep only the heading check's sets; docs/nodes.md)", lo=0, hi=1000)
        self.startup_catch_up_ms = declare(
            self, "startup_catch_up_ms", 1000.0, "startup_catch_up: a caught-up set that waited longer than this, "
            "or no shorter than the one before (the tracker does not gain on the stream), ends the catch-up (the "
            "sets still waiting are dropped)", lo=0.0, hi=60_000.0)
        self.startup_catch_up_stale_ms = declare(
            self, "startup_catch_up_stale_ms", 0.0, "startup_catch_up: a held set that already waited longer than this "
            "when its turn comes is dropped instead, the oldest first (its estimate would come too late, and tracking "
            "it would make the newer sets late too); the newer ones are caught up (0 = never)", lo=0.0, hi=60_000.0)
        self.rehearsal = declare(
            self, "startup_rehearsal", True, "while the frame sets are empty (the segmentation's learning frames, "
            "nobody in view yet), run the first-frame hull once on the real cameras with a rendered standing body, so "
            "the first real initialization does not pay its one-time costs (~15-20 CPU ms on bags/demo); the estimates "
            "do not depend on it (docs/nodes.md)")
        self.use_prediction = declare(self, "use_prediction", True, "use prediction/joint_states when it arrives")
        trace = declare(self, "trace_file", "", "append one JSON line per frame set tracked (stamp, gap, budget, step "
                        "and wait ms, the governor's account: energy, reference, lost count) to this file ('' = off)")
        self.trace = open(trace, "a", encoding="utf-8", buffering=1) if trace else None  # noqa: SIM115 (close())
        self.keypoint_wait_s = declare(self, "keypoint_wait_s", 10.0, "lockstep, keypoint_weight > 0: longest wait "
                                       "for a view's keypoints (or skip notice) of a frame set while no keypoint node "
                                       "is in the graph (with one there, the wait has no time limit)",
                                       lo=0.0, hi=600.0)
        self.prediction_wait_s = declare(self, "prediction_wait_s", 10.0,
                                         "lockstep: longest wait for a frame's prediction while a prediction node "
                                         "is there", lo=0.0, hi=60.0)
        self.frame_period_s = declare(self, "frame_period_s", 1.0 / 30.0,
                                      "frame period, to match predictions to frames", lo=1e-4, hi=10.0)
        self.overlay = declare(self, "publish_overlay", False, "publish cam<i>/overlay images")
        self.overlay_every = declare(self, "overlay_every", 1, "overlay every n-th frame", lo=1, hi=10000)
        self.body_id = declare(self, "body_id", "mocap", "REP-155 body id (/humans/bodies/<id>/...)")
        self.world_frame = declare(self, "world_frame", "world", "frame of root_pose and markers")
        self.wait_for_inputs_s = declare(self, "wait_for_inputs_s", 0.0, "before saying ready, wait up to this "
                                         "long until every cam<i>/mask (and the prediction) has a publisher",
                                         lo=0.0, hi=600.0)
        gap_s = declare(self, "max_stamp_gap_s", 5.0, "a mask or prediction farther than this in time from the "
                        "view's stream is dropped (a mask with its own camera_info is taken; 0 = no check)",
                        lo=0.0, hi=1e9)
        depth = declare(self, "input_queue", 10, "masks waiting for the camera_info of their stamp (and camera "
                        "infos for their mask), per view", lo=1, hi=1000)
        self.problems = ProblemLog(self)
        self.model = make_model(dof, shape=shape or None)
        self.hri_names = hri_joint_names(self.model, self.body_id)
        self.tracker_config = TrackerConfig.from_flat(**settings)   # checks every setting (TrackerError names it)
        # real time: which sets the tracker gets and at what budget (isa_mocap_ros.tracking.realtime): the frame
        # budget under load (governor; None: always the full budget), the start-up's sets caught up after the
        # initialization, late sets without the contour stage
        governor, recovery, min_evals = self._declare_degrade()
        self.schedule = RealTimeSchedule(
            evals=self.tracker_config.search.evals, heading_sets=self.tracker_config.heading.init_confirm_frames,
            lockstep=self.lockstep, backlog=self.backlog, catch_up_ms=self.catch_up_ms,
            startup=StartupCatchUp(sets=self.startup_catch_up, evals=min_evals,
                                   limit_ms=self.startup_catch_up_ms, stale_ms=self.startup_catch_up_stale_ms),
            governor=governor, recovery=recovery)
        self.governor = self.schedule.governor
        self.catch_up = self.schedule.startup
        self.budget_reason = ""          # the governor's last change, for /diagnostics
        self.sync = FrameSynchronizer(self.n_views, **sync_kw)
        self.slot = self.schedule.slot
        self.threads_in_use = 0          # numba threads of the tracker's worker (set when it starts)
        self._cv = threading.Condition()
        # input checks (isa_mocap_ros.intake): a view's camera is what a camera_info and a mask of one stamp
        # agree on; _intrinsics[v] is that camera_info's, _extrinsics[v] maps child frame -> (R, t)
        self.gates = [ViewGate(f"cam{v}", max_gap_ns=int(gap_s * 1e9), depth=depth) for v in range(self.n_views)]
        self._stream = StampWindow(int(gap_s * 1e9))     # the frame sets' stamps, for the predictions
        self._intrinsics: list = [None] * self.n_views
        self._set_infos: list[dict[int, object]] = [{} for _ in range(self.n_views)]   # stamp -> its camera_info
        self._extrinsics: list[dict[str, tuple]] = [{} for _ in range(self.n_views)]
        self._camera_changed: str | None = None   # a view's camera changed after the tracker was made
        self._images: list[dict[int, np.ndarray]] = [{} for _ in range(self.n_views)]
        # the last camera_info of each view (frame id, intrinsics), and the cameras whose data the worker built
        self._camera_hints: list = [None] * self.n_views
        self._prepared_keys: set[bytes] = set()
        self._hinted = [0] * self.n_views   # cameras built ahead per view (at most MAX_HINTED_CAMERAS)
        self.prepare_ms = 0.0           # CPU the worker spent building camera data ahead of the frame sets
        self.cameras_ready_ahead = 0    # of the tracker's cameras when it was made, those built ahead
        self._last_arrival: float | None = None     # when the last complete frame set reached the slot
        self.sets_bunched = 0           # sets that arrived < half a period after the one before (EstimatorIntake._put)
        self.dropped_bunched = 0        # sets the slot dropped at those arrivals
        self._predictions: dict[int, np.ndarray] = {}
        # the keypoint node's messages per view and stamp: (uv, confidence) or None (skipped / nobody)
        self.keypoint_inbox = KeypointInbox(self.n_views, self._stream)
        self.keypoint_wait = KeypointWait(self.lockstep, self.keypoint_wait_s)   # real time: never waits
        self.use_keypoints = self.tracker_config.keypoints.keypoint_weight > 0
        self.keypoint_sets = 0          # frame sets tracked with keypoints
        self._prev_stamp_ns: int | None = None   # stamp of the last frame set given to the tracker
        self.tracker = None
        self.frames_done = 0
        self.last_result = None
        # the last 300 of each, for the 1 Hz diagnostics' percentiles
        self.latencies_ms: deque[float] = deque(maxlen=300)
        self.step_ms: deque[float] = deque(maxlen=300)   # Tracker.step wall time per tracked set
        self.init_ms = float("nan")     # Tracker.step wall time of the automatic initialization's set
        self.init_cpu_ms = float("nan")  # its worker-thread CPU time
        self._empty_sets = 0            # frame sets in a row without foreground (and no estimate yet)
        self._rehearsed: object = None  # the tracker the start-up rehearsal ran for (_rehearse)
        self.rehearsal_ms = 0.0         # worker CPU of the rehearsal
        self._published_any = False
        self._stop = threading.Event()

        sensor = qos.SENSOR_DATA
        for v in range(self.n_views):
            self.create_subscription(Image, f"cam{v}/mask", self._mask_cb(v), sensor,
                                     qos_overriding_options=QOS_OVERRIDES)
            self.create_subscription(CameraInfo, f"cam{v}/camera_info", self._info_cb(v), sensor,
                                     qos_overriding_options=QOS_OVERRIDES)
            self.create_subscription(TransformStamped, f"cam{v}/extrinsics", self._extr_cb(v), qos.LATCHED)
            if self.overlay:
                self.create_subscription(Image, f"cam{v}/image_raw", self._image_cb(v), sensor)
        self.create_subscription(JointState, "prediction/joint_states", self._prediction_cb, qos.RELIABLE)
        if self.use_keypoints:
            for v in range(self.n_views):
                self.create_subscription(PolygonStamped, f"cam{v}/keypoints", self._keypoints_cb(v), qos.RELIABLE,
                                         qos_overriding_options=QOS_OVERRIDES)
                self.create_subscription(Header, f"cam{v}/keypoints_skipped", self._skipped_cb(v), qos.RELIABLE)
        self.pub_js = self.create_publisher(JointState, "joint_states", qos.RELIABLE,
                                            qos_overriding_options=QOS_OVERRIDES)
        self.pub_root = self.create_publisher(PoseStamped, "root_pose", qos.RELIABLE)
        self.pub_markers = self.create_publisher(MarkerArray, "markers", qos.RELIABLE)
        self.pub_done = self.create_publisher(Header, "estimator/done", qos.RELIABLE)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.RELIABLE)
        self.pub_hri = self.create_publisher(JointState, f"/humans/bodies/{self.body_id}/joint_states", qos.RELIABLE)
        self.pub_urdf = self.create_publisher(String, f"/humans/bodies/{self.body_id}/urdf", qos.LATCHED)
        self.pub_urdf.publish(String(data=hri_urdf(self.model, self.body_id)))
        # our own body model description (the schema of /mocap/ground_truth/model, with the shape we
        # track with), latched, so a recording of our joint states describes itself
        from isa_mocap_ros.sequence import model_to_yaml

        self.pub_model = self.create_publisher(String, "model", qos.LATCHED)
        self.pub_model.publish(String(data=model_to_yaml(self.model, role="estimator")))
        self.pub_overlay = [self.create_publisher(Image, f"cam{v}/overlay", qos.RELIABLE)
                            for v in range(self.n_views)] if self.overlay else []
        self.create_timer(0.05, self._poll_partial)
        self.create_timer(1.0, self._publish_diagnostics)
        self._worker = threading.Thread(target=self._work, name="estimator", daemon=True)
        self._worker.start()
        self.get_logger().info(
            f"estimator: {self.model.name} ({self.model.dof} DOF), {self.tracker_config.search.optimizer} with "
            f"{self.tracker_config.search.evals} evaluations per frame, {self.n_views} views, "
            f"seed {self.tracker_config.search.seed}, {'lockstep' if self.lockstep else 'real time'}")

    # -- the work -------------------------------------------------------------------------------
    def _warm_up(self) -> None:
        """Compile (or load from numba's cache) the tracker's kernels on a tiny synthetic frame
        (:func:`isa_mocap_ros.tracking.realtime.warm_up`: the automatic initialization, then a tracked frame), then
        say "ready". The frames are tracked with the configured budget, so every stage a real frame runs is loaded
        here: with a 400-evaluation warm-up the first real frame with stages paid ~38 ms of first calls (bags/demo,
        the frame after the initialization: 63 instead of 25 ms), one or two more sets dropped in real time; with
        a warm-up from a given pose the initialized frame paid ~50 CPU ms of first calls (session 27)."""
        t0 = time.monotonic()
        # said before the wait, so a first run is not a silent minute: numba compiles the kernels on their
        # first call after an install (`make venv` does it ahead, `isa-mocap warmup`) and loads its cache after
        self.get_logger().info("estimator: loading the compiled kernels (a few seconds from numba's cache; "
                               "1.5-4 min when they were never compiled since the install: run `isa-mocap warmup` "
                               "once to do that ahead)")
        try:
            warm_up(self.model, self.tracker_config)      # the automatic initialization's kernels too
        except Exception as exc:  # noqa: BLE001 - warm-up is an optimisation, never fatal
            self.get_logger().warn(f"warm-up failed ({type(exc).__name__}: {exc}); the first frame will be slow")
        self._wait_for_inputs()
        self.get_logger().info(f"estimator: ready (warm-up {time.monotonic() - t0:.1f} s)")

    def _wait_for_inputs(self) -> None:
        """Wait (bounded) until the mask, prediction (and keypoint) publishers are in the graph, so a replay
        started on "ready" loses no frame to discovery."""
        deadline = time.monotonic() + self.wait_for_inputs_s
        topics = [f"cam{v}/mask" for v in range(self.n_views)] + (["prediction/joint_states"]
                                                                  if self.use_prediction else [])
        if self.use_keypoints:       # the keypoint node loads its model: a replay before it would lose frames
            topics += [f"cam{v}/keypoints" for v in range(self.n_views)]
        missing = topics
        while self.wait_for_inputs_s > 0 and not self._stop.is_set():
            missing = [t for t in topics if publishers_on(self, t) == 0]
            if not missing or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        if self.wait_for_inputs_s > 0 and missing:
            self.get_logger().warn(f"no publisher after {self.wait_for_inputs_s:.0f} s on {missing}")
        elif self.wait_for_inputs_s > 0:
            time.sleep(0.5)  # let the matched endpoints finish their handshake

    def _work(self) -> None:
        import numba

        if self.tracker_threads > 0:
            # numba's thread count is per calling thread: this worker is the only one that steps the
            # tracker (docs/nodes.md: 1 vs all cores measured equal in real time on 2 cores).
            numba.set_num_threads(min(self.tracker_threads, numba.config.NUMBA_NUM_THREADS))
        self.threads_in_use = numba.get_num_threads()
        self._warm_up()
        while not self._stop.is_set():
            with self._cv:
                # the oldest waiting set, with the sets after it held in sequence where the tracker's
                # initialization or a heading re-check needs them (tracking/realtime.py)
                item = self.schedule.take(self.tracker, waited_ms=lambda it: (time.monotonic() - it[1]) * 1e3)
                if item is None:
                    # idle: the per-camera data of the cameras the camera_infos announce, built before their
                    # first frame set needs them (tracking/camera_data.py); then the start-up rehearsal
                    cams = self._hinted_cameras()
                    rehearse = not cams and self._rehearsal_due()
                    if not cams and not rehearse:
                        self._cv.wait(0.1)
                        continue
                else:
                    frame_set, t_ready = item
                    prediction, keypoints = self._inputs_of(frame_set)
                    # a worker that is never idle (a loaded machine) rehearses before an empty set: that set gives no
                    # estimate, so its wait costs nothing
                    rehearse = self._rehearsal_due() and not any(m is not None and np.any(m) for m in frame_set.items)
            if item is None:
                if rehearse:
                    self._rehearse()
                else:
                    self._prepare(cams)
                continue
            if rehearse:
                self._rehearse()
            try:
                self._process(frame_set, prediction, t_ready, keypoints)
            except Exception as exc:  # noqa: BLE001 - a node must survive any one bad frame set
                if self._stop.is_set() or not self.context.ok():
                    return  # shutting down: publishers are gone with the context
                self.problems.report("error", f"frame set {frame_set.stamp_ns} failed: {type(exc).__name__}: {exc}",
                                     level="error")
                try:
                    self._done(frame_set.stamp_ns)
                except Exception:  # noqa: BLE001 - the context may have gone meanwhile
                    return

    def _inputs_of(self, frame_set):
        """(Under ``_cv``.) The frame set's prediction message (or None) and keypoints (or None)."""
        prediction = None
        if self.use_prediction and self._published_any:
            # lockstep waits as long as a prediction node is there to answer (a slow one on a loaded
            # machine must not turn the replay into another result), at most prediction_wait_s
            wait_s = self.prediction_wait_s if self.lockstep and publishers_on(
                self, "prediction/joint_states") > 0 else 0.0
            deadline = time.monotonic() + wait_s
            while (prediction := self._prediction_for(frame_set.stamp_ns)) is None:
                left = deadline - time.monotonic()
                if left <= 0 or self._stop.is_set():
                    break
                self._cv.wait(min(left, 0.05))
            if prediction is None and self.lockstep:
                self.problems.report("noprediction", f"no prediction for frame {frame_set.stamp_ns} "
                                     + (f"within {wait_s:.2f} s" if wait_s else "(no prediction node)")
                                     + "; using the estimator's own")
        keypoints = self._keypoints_for(frame_set) if self.use_keypoints else None
        return prediction, keypoints

    def _prepare(self, cams: list) -> None:
        """Build the per-camera data of ``cams`` (:func:`~isa_mocap_ros.tracking.camera_data.prepare_cameras`; a
        camera it cannot build is left to the tracker, which reports it with the frame set that needs it)."""
        from isa_mocap_ros.tracking.camera_data import prepare_cameras

        t0 = time.thread_time()
        try:
            prepare_cameras(cams, self.tracker_config)
        except Exception:  # noqa: BLE001 - a cache fill only; the tracker's own build reports the camera
            return
        self.prepare_ms += (time.thread_time() - t0) * 1e3

    def _rehearsal_due(self) -> bool:
        """(Under ``_cv``.) Whether the worker, idle, rehearses the first-frame hull now: a tracker made and
        not initialized, :data:`REHEARSAL_AFTER_EMPTY_SETS` frame sets in a row without foreground just tracked (the
        segmentation's learning frames: the person's first set is likely some sets away), not done yet for this
        tracker."""
        return (self.rehearsal and self.tracker is not None and not self.tracker.initialized
                and self._rehearsed is not self.tracker and self._empty_sets >= REHEARSAL_AFTER_EMPTY_SETS)

    def _rehearse(self) -> None:
        """The start-up rehearsal (:func:`~isa_mocap_ros.tracking.realtime.rehearse`: the first-frame hull) on the
        tracker's cameras; a failure only costs the first initialization its one-time costs."""
        from isa_mocap_ros.tracking.realtime import rehearse

        self._rehearsed = self.tracker
        t0 = time.thread_time()
        try:
            rehearse(self.model, self.tracker.cameras)
        except Exception as exc:  # noqa: BLE001 - an optimisation, never fatal
            self.problems.event("rehearsal", f"start-up rehearsal failed ({type(exc).__name__}: {exc})")
        self.rehearsal_ms += (time.thread_time() - t0) * 1e3

    def _process(self, frame_set, prediction_msg, t_ready: float, keypoints=None) -> None:
        if self._camera_changed is not None and self.tracker is not None:
            self.tracker = None          # made again below with the new cameras; it initializes itself anew
            self._prev_stamp_ns = None
            self.problems.event("camera_changed", f"frame set {frame_set.stamp_ns}: tracker restarted "
                                                  f"({self._camera_changed})")
        self._camera_changed = None
        if self.tracker is None:
            with self._cv:
                cams = self._cameras(frame_set)
            if cams is None:
                missing = [v for v in range(self.n_views)
                           if self._intrinsics[v] is None or self._pose_of(v) is None]
                self.problems.report("calib", f"frame set {frame_set.stamp_ns} dropped: no camera_info/extrinsics "
                                              f"(world -> the masks' frame) yet for views {missing}", level="error")
                self._done(frame_set.stamp_ns)
                return
            # of its cameras, those whose data the worker built ahead from the camera_infos (Tracker() finds them)
            self.cameras_ready_ahead = sum(c.key() in self._prepared_keys for c in cams)
            self.tracker = self._new_tracker(cams)
        prediction = None
        if prediction_msg is not None:
            from isa_mocap_ros.body import joint_state_to_pose
            prediction = joint_state_to_pose(self.model, prediction_msg)
        masks = list(frame_set.items)
        # frame periods since the last set given to the tracker: more than 1 after sets dropped for
        # lack of time (or missing views), so the tracker's own prediction looks as far ahead
        gap = periods_between(self._prev_stamp_ns, frame_set.stamp_ns, self.frame_period_s)
        self._prev_stamp_ns = frame_set.stamp_ns
        # real time: the governor's budget under load, the start-up catch-up's, no contour stage for a set that
        # waited longer than catch_up_ms (tracking/realtime.py); lockstep: the full budget
        budget = self.schedule.budget(self.tracker, (time.monotonic() - t_ready) * 1e3)
        cpu0 = time.thread_time()
        result = self.tracker.step(masks, frame_set.stamp_ns, prediction=prediction, frames_elapsed=gap,
                                   contour_stage=budget.contour_stage, evals=budget.evals, keypoints=keypoints)
        self.keypoint_sets += keypoints is not None
        with self._cv:
            # the governor's account (a track lost for long re-initializes the tracker), the catch-up's
            d = self.schedule.after(self.tracker, result, budget=budget, waited_ms=(time.monotonic() - t_ready) * 1e3)
        if self.schedule.probe_due:      # a drift at a lowered budget: a second opinion (tracking/recovery.py)
            result = self._second_opinion(masks, frame_set.stamp_ns, result)
        if self.trace is not None:
            self.trace.write(json.dumps({
                "stamp": frame_set.stamp_ns, "gap": gap, "evals": result.n_evals, "init": result.initialized,
                "contour": budget.contour_stage, "step_ms": 1e3 * result.time_s, "energy": result.energy,
                "step_cpu_ms": 1e3 * (time.thread_time() - cpu0),   # (and the governor's account, ~0.1 ms)
                "waited_ms": 1e3 * (time.monotonic() - t_ready), **(self.schedule.last_account or {})},
                default=float) + "\n")
        if d is not None:
            self.budget_reason = d.reason
            self.problems.event("budget", f"frame {frame_set.stamp_ns}: budget level {d.level}: {d.reason}")
        self.frames_done += 1
        self.last_result = result
        if result.x is not None and not result.fell_back and not result.initialized:
            self.step_ms.append(result.time_s * 1e3)   # tracked sets (not the initialization)
        if result.initialized:
            self.init_ms = result.time_s * 1e3
            self.init_cpu_ms = (time.thread_time() - cpu0) * 1e3
        # sets in a row with nobody in view before the first estimate: the rehearsal's cue
        self._empty_sets = self._empty_sets + 1 if result.x is None and result.views_used == 0 else 0
        if result.x is not None:
            with one_numba_thread():
                self._publish(frame_set.stamp_ns, result)
            self._published_any = True
        for note in result.notes:
            kind = f"note:{note.split(':')[0].split('(')[0].strip()}"
            if note_is_expected(note):   # what a normal run does: INFO, not a bad input
                self.problems.event(kind, f"frame {frame_set.stamp_ns}: {note}")
            else:
                self.problems.report(kind, f"frame {frame_set.stamp_ns}: {note}")
        self.latencies_ms.append((time.monotonic() - t_ready) * 1e3)
        self._done(frame_set.stamp_ns)
        if self.overlay and self.frames_done % self.overlay_every == 0 and result.x is not None:
            with one_numba_thread():
                self._publish_overlay(frame_set, result.x)

    def _done(self, stamp_ns: int) -> None:
        if self.lockstep:   # the figures of every set before its done: a run's last ones are then its final ones
            self._publish_diagnostics()   # (the 1 Hz timer's may come late or not at all on a loaded machine)
        self.pub_done.publish(ma.make_header(stamp_ns, self.world_frame))

    def _publish(self, stamp_ns: int, result) -> None:
        q = pose_to_joint_state(self.model, result.x)
        self.pub_js.publish(ma.arrays_to_joint_state(self.model.dof_names, q, stamp_ns=stamp_ns))
        self.pub_hri.publish(ma.arrays_to_joint_state(self.hri_names, q, stamp_ns=stamp_ns))
        pose = PoseStamped(header=ma.make_header(stamp_ns, self.world_frame))
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = map(float, result.x[:3])
        qx, qy, qz, qw = ma.matrix_to_quaternion(exp_so3(result.x[3:6]))
        pose.pose.orientation.x, pose.pose.orientation.y = float(qx), float(qy)
        pose.pose.orientation.z, pose.pose.orientation.w = float(qz), float(qw)
        self.pub_root.publish(pose)
        self.pub_markers.publish(self._skeleton(stamp_ns, result.x))

    def _skeleton(self, stamp_ns: int, x: np.ndarray) -> MarkerArray:
        P = joint_positions(self.model, x[None])[0]
        header = ma.make_header(stamp_ns, self.world_frame)
        joints = Marker(header=header, ns="joints", id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
        joints.scale.x = joints.scale.y = joints.scale.z = 0.05
        joints.color = ColorRGBA(r=1.0, g=0.8, b=0.1, a=1.0)
        joints.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in P]
        bones = Marker(header=header, ns="bones", id=1, type=Marker.LINE_LIST, action=Marker.ADD)
        bones.scale.x = 0.025
        bones.color = ColorRGBA(r=0.1, g=0.9, b=0.3, a=1.0)
        for j, parent in enumerate(self.model.parents):
            if parent >= 0:
                bones.points += [Point(x=float(c[0]), y=float(c[1]), z=float(c[2])) for c in (P[parent], P[j])]
        return MarkerArray(markers=[joints, bones])

    def _publish_overlay(self, frame_set, x: np.ndarray) -> None:
        E = capsule_endpoints(self.model, x[None])[0]
        for v, cam in enumerate(self.tracker.cameras):
            img = self._images[v].get(frame_set.stamps_ns[v]) if frame_set.stamps_ns[v] is not None else None
            if img is None:
                continue
            out = draw_overlay(img, cam, E, self.model.capsule_radii, mask=frame_set.items[v])
            self.pub_overlay[v].publish(ma.array_to_image(out, "rgb8", stamp_ns=frame_set.stamp_ns,
                                                          frame_id=f"cam{v}_optical_frame"))

    def _publish_diagnostics(self) -> None:
        st = DiagnosticStatus(name="isa_mocap_ros: estimator", hardware_id=self.body_id)
        r = self.last_result
        lat = np.array(self.latencies_ms)
        p50, p95 = (float(np.percentile(lat, 50)), float(np.percentile(lat, 95))) if lat.size else (0.0, 0.0)
        # the tracker's own time per tracked set: above the frame period, the tracker alone drops sets
        steps = np.array(self.step_ms)
        t50, t95 = (float(np.percentile(steps, 50)), float(np.percentile(steps, 95))) if steps.size else (0.0, 0.0)
        values = {
            "frames": self.frames_done, "dropped_frame_sets": self.slot.dropped,
            "frames_without_contour_stage": self.schedule.frames_caught_up,
            "startup_sets_caught_up": self.catch_up.caught_up,
            "sync_dropped_messages": self.sync.dropped, "bad_inputs": self.problems.total,
            "optimizer": self.tracker_config.search.optimizer, "evals_per_frame": self.tracker_config.search.evals,
            "tracker_threads": self.threads_in_use,
            "energy": getattr(r, "energy", float("nan")), "evaluations": getattr(r, "n_evals", 0),
            "views_used": getattr(r, "views_used", 0), "keypoint_sets": self.keypoint_sets,
            "latency_ms_p50": p50, "latency_ms_p95": p95,
            "tracker_ms_p50": t50, "tracker_ms_p95": t95, "init_ms": self.init_ms,
            "init_cpu_ms": round(self.init_cpu_ms, 1), "init_rehearsal_ms": round(self.rehearsal_ms, 1),
            # the per-camera data built ahead from the camera_infos (CPU ms; cameras), and how many of the tracker's
            # cameras found theirs ready when it was made
            "camera_data_ahead_ms": round(self.prepare_ms, 1), "cameras_built_ahead": len(self._prepared_keys),
            "cameras_ready_ahead": self.cameras_ready_ahead,
            # real time: sets arriving < half a frame period after the one before, and the drops at those arrivals
            "sets_bunched": self.sets_bunched, "dropped_at_bunched_arrivals": self.dropped_bunched,
            # the budget under load (isa_mocap_ros.tracking.load): level 0 = full, its evaluations and contour stage
            **({"budget_level": g.level, "budget_evals": g.decision().evals,
                "budget_contour_stage": g.decision().contour_stage, "budget_lowered": g.lowered,
                "budget_reason": self.budget_reason, "track_resets": g.resets,
                "recovery_probes": getattr(self.schedule.recovery, "probes", 0),
                "recoveries": getattr(self.schedule.recovery, "adopted", 0)}
               if (g := self.governor) is not None else {"budget_level": "off"}),
            "problems": json.dumps(self.problems.counts), "events": json.dumps(self.problems.events),
        }
        st.level = DiagnosticStatus.OK if self.problems.total == 0 else DiagnosticStatus.WARN
        st.message = "tracking" if self.tracker is not None else "waiting for calibration and masks"
        st.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        self.pub_diag.publish(DiagnosticArray(header=ma.make_header(self.get_clock().now().nanoseconds),
                                              status=[st]))

    def close(self) -> None:
        self._stop.set()
        with self._cv:
            self._cv.notify_all()
        self._worker.join(timeout=5.0)
        if self.trace is not None:
            self.trace.close()


def main(args: list[str] | None = None) -> None:
    raise SystemExit(run_node(EstimatorNode, args))


if __name__ == "__main__":
    main()
