"""The estimator node's inputs: camera_info, extrinsics, masks, predictions and keypoints, checked and
assembled into frame sets (:class:`EstimatorIntake`, a part of :class:`isa_mocap_ros.nodes.estimator.EstimatorNode`).

The callbacks run on the executor's thread; everything they share with the tracker's worker is guarded by the
node's condition ``_cv``. The checks are :mod:`isa_mocap_ros.intake`'s (see the estimator module's docstring);
accepted masks go to the frame synchronizer and complete frame sets to the worker's slot.
"""
from __future__ import annotations

import time

import numpy as np
from geometry_msgs.msg import PolygonStamped, TransformStamped
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Header

import msg_adapters as ma
from isa_mocap_ros.intake import Setting
from isa_mocap_ros.nodes.common import camera_info_callback, declare, publishers_on
from isa_mocap_ros.tracking.sync import SyncError
from isa_mocap_ros.vision import Camera

#: distinct child frames kept per view from cam<i>/extrinsics (the one the view's masks name is used)
MAX_CAMERA_FRAMES = 8

#: cameras per view whose data the worker builds ahead from camera_infos alone (:meth:`EstimatorIntake._hinted_cameras`)
MAX_HINTED_CAMERAS = 2


class EstimatorIntake:
    """The input side of the estimator node: subscription callbacks, the cameras they make, and the lookup of a
    frame set's prediction and keypoints. Mixed into :class:`~isa_mocap_ros.nodes.estimator.EstimatorNode`, whose
    ``__init__`` sets the state these methods use (``gates``, ``sync``, ``slot``, ``_cv``, ``_intrinsics``, ...)."""

    # -- the tracker ----------------------------------------------------------------------------------------------
    def _declare_degrade(self):
        """The real-time budget's parameters (``degrade*``, ``recovery``; docs/nodes.md): ``(governor, recovery,
        degrade_min_evals)``, the governor ``None`` with ``degrade`` off and the recovery ``None`` with ``recovery`` off
        (lockstep uses neither: isa_mocap_ros.tracking.realtime)."""
        from isa_mocap_ros.tracking.load import LoadGovernor, LoadSettings
        from isa_mocap_ros.tracking.recovery import Recovery

        degrade = declare(self, "degrade", True, "real time: while the tracker does not keep up with the frame sets, "
                          "lower its budget (contour stage off, then fewer evaluations) before dropping sets, and "
                          "return to the full budget when it catches up (isa_mocap_ros.tracking.load; lockstep: never)")
        min_evals = declare(self, "degrade_min_evals", 300, "degrade: fewest evaluations a set", lo=1, hi=10**6)
        headroom = declare(self, "degrade_headroom", 0.85, "degrade: a budget fits when its step time is "
                           "below this share of frame_period_s", lo=0.05, hi=1.0)
        slow_only = declare(self, "degrade_slow_drops_only", True, "degrade: a dropped set is overload only beside a "
                            "step over the headroom")
        up_cost = declare(self, "degrade_contour_up_cost", True, "degrade: a step up to the contour stage is projected "
                          "with its cost (a level that cannot fit is not tried)")
        fixed_share = declare(self, "degrade_fixed_share", 0.3, "degrade: share of a full-budget step that does not "
                              "scale with the evaluations (projects a step between levels)", lo=0.0, hi=0.95)
        recovery = declare(self, "recovery", False, "real time: after the track drifted at a lowered budget, a fresh "
                           "initialization on the same set replaces it when clearly better (tracking/recovery.py; off: "
                           "measured worse, docs/nodes.md)")
        governor = LoadGovernor(LoadSettings(
            evals=self.tracker_config.search.evals, period_s=self.frame_period_s, headroom=headroom,
            min_evals=min_evals, slow_drops_only=slow_only, contour_up_cost=up_cost,
            fixed_share=fixed_share)) if degrade else None
        return governor, (Recovery() if recovery else None), min_evals

    def _new_tracker(self, cams: list):
        """A tracker of ``cams`` with the node's config; its own prediction (used when the prediction node's is
        missing) goes through the same JointState conversions as the prediction node's."""
        from isa_mocap_ros.tracking.published import PublishedPredictor
        from isa_mocap_ros.tracking.tracker import Tracker

        tracker = Tracker(self.model, cams, self.tracker_config)
        tracker.predictor = PublishedPredictor(self.model, tracker.predictor)
        return tracker

    def _second_opinion(self, masks: list, stamp_ns: int, result):
        """The recovery's probe on the set just tracked (:meth:`~isa_mocap_ros.tracking.realtime.RealTimeSchedule.probe`):
        an adopted probe replaces the tracker and its result the track's (its notes say so: one INFO line); the sets
        dropped meanwhile are not counted as load. Returns the set's result."""
        cams = self.tracker.cameras
        probe, probe_result, adopted = self.schedule.probe(result, masks, stamp_ns, lambda: self._new_tracker(cams))
        with self._cv:
            self.schedule.seen_drops()
            if adopted:
                self.tracker = probe
                self.schedule.recovered(probe)
        return probe_result if adopted else result

    # -- calibration and masks: checked before they reach the synchronizer (isa_mocap_ros.intake) ----------
    def _info_cb(self, v: int):
        def take(stamp_ns, setting, intr) -> None:
            with self._cv:
                self._settle(v, *self.gates[v].add_info(stamp_ns, setting, intr))
                hint = self._camera_hints[v]
                if hint is None or hint[0] != setting.frame_id or hint[1] is not intr:   # (intr: cached per camera)
                    self._camera_hints[v] = (setting.frame_id, intr)    # the worker builds its data when idle
                    self._cv.notify_all()
        return camera_info_callback(v, self.problems, lambda exc: f"info{v}", take)

    def _hinted_cameras(self) -> list[Camera]:
        """(Under ``_cv``.) Before the tracker is made: the cameras the last camera_info of each view and its
        extrinsics describe, whose per-camera data (:func:`isa_mocap_ros.tracking.camera_data.prepare_cameras`) were
        not built yet. Not vouched for by a mask (the gate's rule, :mod:`isa_mocap_ros.intake`): they only fill the
        caches a tracker made of the same cameras finds (keyed by the geometry, ``Camera.key``), so a wrong one
        changes no result. A camera_info of another size than the view's camera (once known) is not taken, and
        at most :data:`MAX_HINTED_CAMERAS` per view are built, so stray camera_infos cost little."""
        if self.tracker is not None:
            return []
        cams = []
        for v, hint in enumerate(self._camera_hints):
            known = self.gates[v].setting
            if hint is None or self._hinted[v] >= MAX_HINTED_CAMERAS:
                continue
            frame, intr = hint
            if known is not None and (known.frame_id, known.width, known.height) != (frame, intr.width, intr.height):
                continue
            store = self._extrinsics[v]
            pose = store.get(frame) if frame else (next(reversed(store.values())) if store else None)
            if pose is None:
                continue
            cam = Camera.from_intrinsics_and_pose(f"cam{v}", K=intr.K, D=intr.D, width=intr.width,
                                                  height=intr.height, R_wc=pose[0], t_wc=pose[1])
            if cam.key() not in self._prepared_keys:
                self._prepared_keys.add(cam.key())
                self._hinted[v] += 1
                cams.append(cam)
        return cams

    def _extr_cb(self, v: int):
        def cb(msg: TransformStamped) -> None:
            try:
                parent = msg.header.frame_id
                if parent != self.world_frame:
                    raise ma.AdapterError("TransformStamped.header.frame_id", f"the world frame {self.world_frame!r}",
                                          parent)
                known = self.gates[v].setting
                if known is not None and known.frame_id and msg.child_frame_id != known.frame_id:
                    raise ma.AdapterError("TransformStamped.child_frame_id", f"the frame of cam{v}'s camera "
                                          f"{known.frame_id!r}", msg.child_frame_id)
                rt = ma.transform_to_rt(msg)
                store = self._extrinsics[v]
                if msg.child_frame_id not in store and len(store) >= MAX_CAMERA_FRAMES:
                    raise ma.AdapterError("TransformStamped.child_frame_id", f"one of the {MAX_CAMERA_FRAMES} camera "
                                          f"frames seen so far ({', '.join(map(repr, store))})", msg.child_frame_id)
            except ma.AdapterError as exc:
                self.problems.report(f"extr{v}", f"cam{v}/extrinsics dropped: {exc}")
                return
            with self._cv:
                store[msg.child_frame_id] = rt   # used when it is the frame of the view's masks (_cameras)
                self._cv.notify_all()            # the worker may build the view's camera data now
        return cb

    def _pose_of(self, v: int):
        """The extrinsics of view ``v`` for the frame its camera_info and masks name (any, when they name none)."""
        frame = self.gates[v].setting.frame_id if self.gates[v].setting is not None else None
        store = self._extrinsics[v]
        if frame is None:
            return None
        if frame == "" and store:
            return next(reversed(store.values()))
        return store.get(frame)

    def _cameras(self, frame_set=None) -> list[Camera] | None:
        """The tracker's cameras: each view's camera_info that vouched for ``frame_set``'s mask (the view's last
        accepted one for a view without a mask in the set), and its extrinsics. The set's own: the last accepted
        one could be a lone pair's that came after the set (one view's mask and camera_info at a stamp of their own)."""
        poses = [self._pose_of(v) for v in range(self.n_views)]
        intrinsics = list(self._intrinsics)
        if frame_set is not None:
            for v, s in enumerate(frame_set.stamps_ns):
                if s is not None and s in self._set_infos[v]:
                    intrinsics[v] = self._set_infos[v][s]
        if any(i is None for i in intrinsics) or any(p is None for p in poses):
            return None
        cams = []
        for v, (intr, (R, t)) in enumerate(zip(intrinsics, poses)):
            # extrinsics carry the camera pose in the world (TF: parent world, child optical frame)
            cams.append(Camera.from_intrinsics_and_pose(f"cam{v}", K=intr.K, D=intr.D, width=intr.width,
                                                        height=intr.height, R_wc=R, t_wc=t))
        return cams

    def _mask_cb(self, v: int):
        def cb(msg: Image) -> None:
            try:
                mask = ma.image_to_array(msg)
                if mask.ndim != 2 or mask.dtype != np.uint8:
                    raise ma.AdapterError(f"cam{v}/mask.encoding", "mono8", msg.encoding)
                stamp = ma.stamp_to_ns(msg.header)
            except ma.AdapterError as exc:
                self.problems.report(f"mask{v}", f"cam{v}/mask dropped: {exc}")
                return
            with self._cv:
                self._settle(v, *self.gates[v].add_image(stamp, Setting(msg.header.frame_id, mask.shape[1],
                                                                        mask.shape[0], "mono8"), mask))
        return cb

    def _settle(self, v: int, accepted, rejected) -> None:
        """(Under ``_cv``.) Report view ``v``'s rejected inputs; its accepted masks go to the synchronizer."""
        for r in rejected:
            self.problems.report(f"info{v}:gate" if r.kind == "camera_info" else f"mask{v}:{r.kind}",
                                 r.text.replace(": image", ": mask", 1))
        for a in accepted:
            self._intrinsics[v] = a.info
            infos = self._set_infos[v]         # by stamp: a set's cameras are its own masks' (_cameras)
            infos[a.stamp_ns] = a.info
            while len(infos) > 64:
                del infos[min(infos)]
            if a.changed and self.tracker is not None:
                self._camera_changed = f"cam{v}: {a.changed}"
                self.get_logger().warn(f"cam{v}: the camera changed ({a.changed}; its camera_info and mask of stamp "
                                       f"{a.stamp_ns} agree): the tracker restarts with the new cameras")
            try:
                sets = self.sync.add(v, a.stamp_ns, a.payload, time.monotonic())
            except SyncError as exc:
                self.problems.report(f"order{v}", f"cam{v}/mask dropped: {exc}")
                continue
            for fs in sets:   # the frame sets' stream: one view's mask far in time (its own pair) makes no set
                self._stream.accept(fs.stamp_ns)
                self._put(fs)
        if accepted:
            self._cv.notify_all()

    def _put(self, frame_set) -> None:
        """(Under ``_cv``.) Hand a complete frame set to the worker's slot, counting the sets that arrive less than half a
        frame period after the one before (bunched: the masks came late, then together) and the sets dropped then: a
        drop there is the inputs' timing (segmentation, executor, transport), not the tracker's pace."""
        now = time.monotonic()
        dropped = self.slot.dropped
        self.slot.put((frame_set, now))
        if self._last_arrival is not None and now - self._last_arrival < 0.5 * self.frame_period_s:
            self.sets_bunched += 1
            self.dropped_bunched += self.slot.dropped - dropped
        self._last_arrival = now

    def _image_cb(self, v: int):
        def cb(msg: Image) -> None:
            try:
                img = ma.image_to_array(msg, copy=True)
            except ma.AdapterError as exc:
                self.problems.report(f"image{v}", f"cam{v}/image_raw dropped: {exc}")
                return
            store = self._images[v]
            store[ma.stamp_to_ns(msg.header)] = img
            while len(store) > 30:
                del store[min(store)]
        return cb

    def _prediction_cb(self, msg: JointState) -> None:
        try:
            _, q = ma.joint_state_to_arrays(msg, self.model.dof_names)
            stamp = ma.stamp_to_ns(msg.header)
        except ma.AdapterError as exc:
            self.problems.report(f"prediction:{exc.field.split(' of ')[0]}", f"prediction dropped: {exc}")
            return
        with self._cv:
            far = self._stream.far(stamp) if self._stream.last_ns is not None else "it came before any frame set"
            if far is not None:   # never stored: it could push the frames' own predictions out
                self.problems.report("prediction:stamp", f"prediction dropped: {far}")
                return
            self._predictions[stamp] = q
            while len(self._predictions) > 100:
                del self._predictions[min(self._predictions)]
            self._cv.notify_all()

    def _keypoints_cb(self, v: int):
        def cb(msg: PolygonStamped) -> None:
            stamp = ma.stamp_to_ns(msg.header)
            try:
                kp = ma.polygon_to_keypoints(msg)
            except ma.AdapterError as exc:
                self.problems.report(f"keypoints{v}", f"cam{v}/keypoints dropped: {exc}")
                return
            self._store_keypoints(v, stamp, kp, f"cam{v}/keypoints")
        return cb

    def _skipped_cb(self, v: int):
        def cb(msg: Header) -> None:
            self._store_keypoints(v, ma.stamp_to_ns(msg), None, f"cam{v}/keypoints_skipped")
        return cb

    def _store_keypoints(self, v: int, stamp: int, kp, topic: str) -> None:
        with self._cv:
            rejected = self.keypoint_inbox.add(v, stamp, kp)
            if rejected is not None:
                self.problems.report(f"keypoints{v}:{rejected.kind}", f"{topic} dropped: {rejected.text}")
                return
            self._cv.notify_all()

    def _keypoint_node_present(self) -> bool:
        """Whether a keypoint node (a publisher of every view's skip notices) is in the graph."""
        return all(publishers_on(self, f"cam{v}/keypoints_skipped") > 0 for v in range(self.n_views))

    def _keypoints_for(self, frame_set) -> list | None:
        """(Under ``_cv``.) The set's keypoints per view ((uv, confidence) or None), None when no view has any.
        Lockstep: after waiting for every view with a mask to have its message (keypoints or skip notice), with no
        time limit while a keypoint node is in the graph (the rule: :class:`~isa_mocap_ros.keypoint_intake.KeypointWait`).
        Real time: what has arrived, at once."""
        inbox = self.keypoint_inbox
        for v, s, why in inbox.purge():      # held before the first frame set, far from it
            self.problems.report(f"keypoints{v}:stamp", f"cam{v}/keypoints (or skip notice) of stamp {s} dropped: "
                                                        f"{why}")
        stamps = frame_set.stamps_ns
        waited_s, last, present, checked = 0.0, time.monotonic(), True, -1.0
        while due := inbox.due(stamps):
            now = time.monotonic()
            if self.lockstep and now - checked >= 0.5:     # the graph, twice a second
                present, checked = self._keypoint_node_present(), now
            waited_s += (now - last) if not present else 0.0
            last = now
            if self._stop.is_set() or self.keypoint_wait.goes_on(due, node_present=present, waited_s=waited_s):
                if self.lockstep:
                    self.problems.report("nokeypoints", f"frame set {frame_set.stamp_ns}: no keypoints or skip notice "
                                         f"from views {due} within {self.keypoint_wait.limit_s:.3f} s without a "
                                         f"keypoint node in the graph; tracked without them")
                else:                       # real time never waits: a detection still running is expected
                    self.problems.event("keypoints_late", f"frame set {frame_set.stamp_ns}: keypoints or skip notice "
                                                          f"of views {due} not in yet; tracked without them")
                break
            self._cv.wait(0.05)
        return inbox.take(stamps)

    def _poll_partial(self) -> None:
        with self._cv:
            for s in self.sync.poll(time.monotonic()):
                self.problems.report("partial", f"frame set {s.stamp_ns} without views {list(s.missing)} "
                                                f"after {self.view_timeout_s:.1f} s; tracking with the others")
                self._stream.accept(s.stamp_ns)
                self.slot.put((s, time.monotonic()))
            self._cv.notify_all()

    def _prediction_for(self, stamp_ns: int) -> np.ndarray | None:
        """The prediction node's prediction for this frame (stamps within half a period), if any."""
        half = self.frame_period_s * 0.5e9
        best = [s for s in self._predictions if abs(s - stamp_ns) < half]
        return self._predictions.get(best[0]) if best else None
