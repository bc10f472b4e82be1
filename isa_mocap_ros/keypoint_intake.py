"""What the keypoint node detects on: the views' image + mask pairs, synchronized into the estimator's frame sets.

Pure logic for :mod:`isa_mocap_ros.nodes.keypoints` (no rclpy). The keypoint schedule
(:class:`~isa_mocap_ros.vision.keypoint_schedule.KeypointSchedule`) counts a view's frames with a person, so a
lockstep replay gives the offline tracker's estimates only when the node counts exactly the frames the estimator
tracks. Those are *frame sets*: stamps at which every view (or, after a wait, ``min_views`` of them) has a mask
(:class:`~isa_mocap_ros.tracking.sync.FrameSynchronizer`, the estimator's matching). So:

* images pass the view's :class:`~isa_mocap_ros.intake.ViewGate` (the camera is what a camera_info and an image
  of one stamp agree on); a mask, at any stamp, is used only with an image of its stamp that passed the gate, and
  only when it is of that image's camera (frame id and size): it is judged when it meets its image, not when it
  arrives. (Judged on arrival against the view's camera, the first mask of a camera that changed -- its image
  waiting in the gate for the camera_info that confirms the change, which came after the segmentation node's mask --
  was dropped, its frame set never formed here, and a lockstep estimator waited for its keypoints until the player
  gave up 30 s later: test_network_fuzz's 10 of 12 frames. Judged against the frame sets' stamps, a stream that
  jumped ahead by more than ``max_gap_ns``, a camera paused, or a far set before the stream, made every later mask
  far, and the node never detected again.) Unpaired masks beyond ``keep`` go oldest first, those far from the
  view's stream (its last image, and the images waiting in the gate for their camera_info) before any other, so
  neither far ones nor a stale stream push out a real mask that came before its image;
* an image and a mask of one stamp make a view's *pair*; pairs go to a synchronizer with the estimator's settings;
* only a completed frame set moves the views' schedules, each present view once, in stamp order.

A pair that forms no frame set changes nothing. That is what keeps one view's valid-looking pair at a far stamp
out (an image and a camera_info of one stamp that agree, say at stamp 7 or an hour ahead, and the segmentation
node's mask of it): counted per view, it shifted the schedule, and the lockstep run with keypoints drifted from
``isa-mocap track`` (220 mm against 63 mm under ``test/fuzzer.py``).
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

from isa_mocap_ros.intake import Rejected, Setting, StampWindow, ViewGate
from isa_mocap_ros.tracking.sync import FrameSynchronizer, SyncError
from isa_mocap_ros.vision.keypoint_schedule import KeypointSchedule

__all__ = ["KeypointIntake", "Job", "KeypointInbox", "KeypointWait"]


@dataclass(frozen=True)
class Job:
    """One view of a completed frame set: detect on it (``detect``) or say it is skipped."""

    view: int
    stamp_ns: int
    image: Any
    mask: Any
    detect: bool


class KeypointIntake:
    """The keypoint node's input side (see the module docstring).

    Parameters
    ----------
    n_views : int
    every_k, dense_frames : int
        The schedule (:class:`KeypointSchedule`).
    max_gap_ns : int
        Images farther than this from the view's stream wait for a camera_info of their stamp (the gate's rule;
        0 = no check).
    keep : int
        Unpaired images (and masks) kept per view while the other of their stamp is on its way.
    queue_size, slop_ns, max_wait_s, min_views :
        The synchronizer's settings: keep them equal to the estimator's (``queue_size``, ``slop_s``,
        ``view_timeout_s``, ``min_views``), so both form the same frame sets.

    Every ``add_*`` and :meth:`poll` returns ``(jobs, problems)``: the views of completed sets in stamp order,
    and rejections as ``(key, text)`` (the key counts one kind of problem per view).
    """

    def __init__(self, n_views: int, *, every_k: int, dense_frames: int, max_gap_ns: int, keep: int = 8,
                 queue_size: int = 10, slop_ns: int = 0, max_wait_s: float = 0.0, min_views: int = 1) -> None:
        self.n_views = n_views
        self.keep = keep
        self.gates = [ViewGate(f"cam{v}", max_gap_ns=max_gap_ns) for v in range(n_views)]
        self.schedules = [KeypointSchedule(every_k, dense_frames=dense_frames) for _ in range(n_views)]
        self.sync = FrameSynchronizer(n_views, queue_size=queue_size, slop_ns=slop_ns, max_wait_s=max_wait_s,
                                      min_views=min(min_views, n_views))
        # unpaired, by stamp in arrival order: images (payload, the view's camera) and masks (payload, person, setting)
        self._images: list[OrderedDict[int, tuple[Any, Setting]]] = [OrderedDict() for _ in range(n_views)]
        self._masks: list[OrderedDict[int, tuple[Any, bool, Setting]]] = [OrderedDict() for _ in range(n_views)]
        self.unpaired = [0] * n_views             # images or masks that aged out without the other

    # -- input -------------------------------------------------------------------------------------
    def add_info(self, v: int, stamp_ns: int, setting: Setting, info: Any, now_s: float):
        """A camera_info of view ``v`` (it may let images waiting for it in)."""
        return self._settle(v, *self.gates[v].add_info(stamp_ns, setting, info), now_s)

    def add_image(self, v: int, stamp_ns: int, setting: Setting, image: Any, now_s: float):
        """An image of view ``v`` (``setting``: its frame id, size and encoding)."""
        return self._settle(v, *self.gates[v].add_image(stamp_ns, setting, image), now_s)

    def add_mask(self, v: int, stamp_ns: int, setting: Setting, mask: Any, has_person: bool, now_s: float):
        """A mask of view ``v`` (``setting``: its frame id and size; ``has_person``: any foreground)."""
        return self._pair(v, "mask", stamp_ns, (mask, has_person, setting), now_s)

    def poll(self, now_s: float):
        """Partial frame sets whose views waited longer than ``max_wait_s`` (the estimator's ``view_timeout_s``)."""
        return self._jobs(self.sync.poll(now_s)), []

    # -- internals ---------------------------------------------------------------------------------
    def _settle(self, v: int, accepted, rejected: list[Rejected], now_s: float):
        problems = [(f"info{v}:gate" if r.kind == "camera_info" else f"image{v}:{r.kind}", r.text) for r in rejected]
        jobs = []
        for a in accepted:       # each agrees with the view's camera once the gate took it
            j, p = self._pair(v, "image", a.stamp_ns, (a.payload, self.gates[v].setting), now_s)
            jobs += j
            problems += p
        return jobs, problems

    def _pair(self, v: int, kind: str, stamp_ns: int, payload: Any, now_s: float):
        mine, other = (self._images[v], self._masks[v]) if kind == "image" else (self._masks[v], self._images[v])
        partner = other.pop(stamp_ns, None)
        if partner is None:
            mine[stamp_ns] = payload
            while len(mine) > self.keep:
                del mine[self._images_to_drop(v) if kind == "image" else self._mask_to_drop(v)]
                self.unpaired[v] += 1
            return [], []
        (image, camera), (mask, has_person, setting) = (payload, partner) if kind == "image" else (partner, payload)
        if (setting.frame_id, setting.width, setting.height) != (camera.frame_id, camera.width, camera.height):
            return [], [(f"mask{v}", f"cam{v}/mask dropped: frame {setting.frame_id!r}, {setting.width}x"
                                     f"{setting.height}, is not the view's camera's ({camera.frame_id!r}, "
                                     f"{camera.width}x{camera.height}: its image of stamp {stamp_ns})")]
        try:
            sets = self.sync.add(v, stamp_ns, (image, mask, has_person), now_s)
        except SyncError as exc:
            return [], [(f"order{v}", f"cam{v} frame at {stamp_ns} ns dropped: {exc}")]
        return self._jobs(sets), []

    def _images_to_drop(self, v: int) -> int:
        """The unpaired image to drop: the farthest from the view's last accepted one (the oldest before any)."""
        images, last = self._images[v], self.gates[v].window.last_ns
        return next(iter(images)) if last is None else max(images, key=lambda t: abs(t - last))

    def _mask_to_drop(self, v: int) -> int:
        """The unpaired mask to drop: the oldest of those farther than ``max_gap_ns`` from the view's stream (its
        last accepted image and the images waiting in the gate for their camera_info), else the oldest."""
        gate = self.gates[v]
        anchors = [t for t in (gate.window.last_ns, *gate.waiting_stamps()) if t is not None]
        gap = gate.window.max_gap_ns
        masks = self._masks[v]
        far = (t for t in masks if gap > 0 and all(abs(t - a) > gap for a in anchors))
        return next(far, next(iter(masks)))

    def _jobs(self, sets) -> list[Job]:
        jobs = []
        for fs in sets:
            for v, item in enumerate(fs.items):
                if item is not None:
                    image, mask, has_person = item
                    jobs.append(Job(v, fs.stamps_ns[v], image, mask, self.schedules[v].due(has_person)))
        return jobs


class KeypointInbox:
    """The estimator's side: the keypoint node's messages per view and stamp until their frame set takes them.

    A message is a view's keypoints (any payload) or its skip notice (``None``); the keypoint node sends exactly
    one per view of each frame set it formed (:class:`KeypointIntake`). Messages are judged against the frame
    sets' stream (``stream``, the estimator's :class:`~isa_mocap_ros.intake.StampWindow`): before the first set
    they are held, since the keypoint node may answer a set before the estimator has formed it, and those far
    from the first set are dropped when it comes (:meth:`purge`); after it, far ones are dropped at once.

    Which views a set still waits for (:meth:`due`) depends on messages only, never on clocks: a view is due until
    its message of the set's stamp came, or a message of a later stamp did (the node formed a later set without
    this one: it lost a frame, and the set's message will never come). How long to wait is :class:`KeypointWait`.

    Parameters
    ----------
    n_views : int
    stream : StampWindow
        The frame sets' stamps (shared with the estimator, which moves it).
    depth : int
        Messages kept per view (the oldest go first).
    """

    def __init__(self, n_views: int, stream: StampWindow, *, depth: int = 64) -> None:
        self.stream = stream
        self.depth = depth
        self._store: list[dict[int, Any]] = [{} for _ in range(n_views)]
        # before the first set, in arrival order (the oldest arrivals go first: a flood of far stamps must not
        # push out the first set's own messages, which come last)
        self._held: list[OrderedDict[int, Any]] = [OrderedDict() for _ in range(n_views)]

    def add(self, v: int, stamp_ns: int, payload: Any) -> Rejected | None:
        """Keep view ``v``'s message (``payload`` None: a skip notice); returns why it was dropped (kind ``stamp``:
        far from the frame sets; ``twice``: a second keypoint message of the stamp), or None."""
        started = self.stream.last_ns is not None
        if started and (far := self.stream.far(stamp_ns)) is not None:
            return Rejected("stamp", far)
        store = self._store[v] if started else self._held[v]
        if store.get(stamp_ns) is not None and payload is not None:
            return Rejected("twice", f"a second message for stamp {stamp_ns}")
        if stamp_ns not in store or payload is not None:
            store[stamp_ns] = payload
        while len(store) > self.depth:
            if started:
                del store[min(store)]
            else:
                store.popitem(last=False)
        return None

    def purge(self) -> list[tuple[int, int, str]]:
        """Once the stream started: the messages held before it join the store, but for those far from it, which
        are dropped (returned as ``(view, stamp, why)``)."""
        out = []
        if self.stream.last_ns is None:
            return out
        for v, held in enumerate(self._held):
            while held:
                s, payload = held.popitem(last=False)
                if (why := self.stream.far(s)) is not None:
                    out.append((v, s, why))
                elif self._store[v].get(s) is None:
                    self._store[v][s] = payload
        return out

    def due(self, stamps_ns) -> list[int]:
        """The views of a frame set (``stamps_ns[v]``, None for a view without a mask) still waiting for their
        message: none of its stamp and none of a later one came."""
        return [v for v, s in enumerate(stamps_ns)
                if s is not None and s not in self._store[v] and not any(t > s for t in self._store[v])]

    def take(self, stamps_ns) -> list | None:
        """The set's payloads per view (None: skipped, or no message), None when no view has keypoints; this
        set's messages and older ones are dropped."""
        out = [self._store[v].get(s) if s is not None else None for v, s in enumerate(stamps_ns)]
        for v, s in enumerate(stamps_ns):
            if s is not None:
                for t in [t for t in self._store[v] if t <= s]:
                    del self._store[v][t]
        return out if any(o is not None for o in out) else None


@dataclass(frozen=True)
class KeypointWait:
    """Whether a frame set waits for its due views' keypoint messages (:meth:`KeypointInbox.due`).

    Lockstep (a replay equal to ``isa-mocap track``, at any machine speed): as long as a keypoint node is there
    to answer, with no time limit: a slow detection on a loaded machine must not turn the replay into another
    result (a 10 s limit did, from the first frame with a person, when the node's detection came late). Only
    while no keypoint node is in the graph (it crashed, or is being respawned) does ``limit_s`` run out.

    Real time: never. The set is tracked with the keypoints that have arrived when the tracker takes it; a view's
    keypoints that come later are dropped with the set's messages (:meth:`KeypointInbox.take` of a later set), not
    used for the next set: a landmark one frame period old pulls the limb toward where it was. (A wait of up to
    30 ms per set for the node's answer cost the tracker its frame period: bags/demo, idle, 51 of 145 sets dropped
    with the keypoint node against 5 without, session 25.)
    """

    lockstep: bool
    limit_s: float

    def goes_on(self, due: list[int], *, node_present: bool, waited_s: float) -> bool:
        """Whether the set stops waiting. ``waited_s``: the time waited so far without a keypoint node in the
        graph (lockstep)."""
        if not due or not self.lockstep:
            return True
        if node_present:
            return False
        return waited_s >= self.limit_s
