"""What a node lets in: one view's camera as its ``camera_info`` and its images agree on it, stamps
against the stream.

Pure logic for the segmentation and estimator nodes (no rclpy): they convert each message with
:mod:`msg_adapters` (malformed messages stop there) and ask a :class:`ViewGate` per view whether
the image (or mask) may change their state -- a learnt background, a synchronizer, a tracker.

**A view's camera is what its camera_info and an image of the same stamp agree on.** ROS drivers
publish ``camera_info`` with every image under the same header (``image_transport``'s
``CameraPublisher``; our camera node and bags do), so a pair with one stamp, one ``frame_id`` and
one size is the camera speaking; a lone message is not. The gate keeps the *confirmed setting* of
the view (frame id, width, height, encoding) from the last such pair:

* an image whose camera_info (same stamp) is at hand is judged against it: same ``frame_id``, same
  size, or it is rejected. A pair that agrees with itself but not with the confirmed setting is a
  camera that really changed (a new resolution): the setting is replaced and the node is told
  (:attr:`Accepted.changed`), so it restarts what it learnt for that view;
* an image whose camera_info has not come (yet) is accepted when it agrees with the confirmed
  setting and its stamp lies within ``max_gap_ns`` of the view's last accepted stamp; otherwise it
  waits (at most ``depth`` images) for its camera_info, and is rejected when it falls out of that
  queue or when a newer image of the view is accepted first;
* before any pair, images wait: nothing is learnt from an image no camera_info vouched for (a
  stray 7x3 image arriving first would otherwise fix the view's size for good);
* camera infos wait (``depth``) for their image; one that never meets an image and disagreed with
  the confirmed setting is counted as rejected when it leaves the queue.

With ``need_info=False`` (a camera without ``camera_info``) the first image fixes the setting and
every later one must agree with it (no pairs: a size change then needs a restart of the node).

:class:`StampWindow` is the stamp check on its own (the estimator applies it to predictions);
:class:`StreamJumps` follows a stream that may restart (the prediction node's estimates);
:class:`StreamForks` is the same rule for a stream that builds up a state (the segmentation node's background
models, after its :class:`ViewGate`: a lone pair that agrees within itself passes the gate at any stamp, and must
not reach the background model unless the stream continues from it).
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Callable

__all__ = ["Setting", "Accepted", "Rejected", "StampWindow", "ViewGate", "StreamJumps", "StreamForks", "FAR_RULE"]


@dataclass(frozen=True)
class Setting:
    """How a view's images look: ``frame_id``, ``width`` x ``height`` and (images only) ``encoding``."""

    frame_id: str
    width: int
    height: int
    encoding: str | None = None

    def __str__(self) -> str:
        return f"{self.width}x{self.height}" + (f" {self.encoding}" if self.encoding else "") + \
            f" in {self.frame_id!r}"


@dataclass(frozen=True)
class Accepted:
    """An image the node may use: its stamp, payload, the camera_info payload that vouches for it
    (the pair's, or the confirmed one), and ``changed`` (text) when it started a new setting."""

    stamp_ns: int
    payload: Any
    info: Any
    first: bool = False
    changed: str | None = None


@dataclass(frozen=True)
class Rejected:
    """A rejected message: ``kind`` (a short key for counting: ``size``, ``frame_id``, ``stamp``,
    ``encoding`` against the camera, ``pair`` for an image that disagrees with the camera_info of its
    stamp, ``no_camera_info``, ``camera_info``) and a sentence a user can act on."""

    kind: str
    text: str


class StampWindow:
    """Stamps against a stream: a stamp more than ``max_gap_ns`` from the last accepted one is far.

    ``max_gap_ns <= 0`` turns the check off; before the first :meth:`accept` nothing is far.
    """

    def __init__(self, max_gap_ns: int) -> None:
        self.max_gap_ns = int(max_gap_ns)
        self.last_ns: int | None = None

    def far(self, stamp_ns: int) -> str | None:
        """Why ``stamp_ns`` is far from the stream, or None."""
        if self.last_ns is None or self.max_gap_ns <= 0 or abs(stamp_ns - self.last_ns) <= self.max_gap_ns:
            return None
        return (f"stamp {stamp_ns} is {(stamp_ns - self.last_ns) / 1e9:+.3f} s from the stream (last accepted "
                f"{self.last_ns}; max_stamp_gap_s {self.max_gap_ns / 1e9:g})")

    def accept(self, stamp_ns: int) -> None:
        self.last_ns = int(stamp_ns)


class ViewGate:
    """The input check of one view (see the module docstring).

    Parameters
    ----------
    name : str
        The view's name in messages (``cam0``).
    max_gap_ns : int
        Stamps farther than this from the view's last accepted image are far (0 = no check).
    depth : int
        Images waiting for their camera_info, and camera infos waiting for their image.
    need_info : bool
        False: images alone (the first fixes the setting).
    """

    def __init__(self, name: str, *, max_gap_ns: int, depth: int = 10, need_info: bool = True) -> None:
        if depth < 1:
            raise ValueError(f"depth: expected >= 1, received {depth}")
        self.name = name
        self.depth = depth
        self.need_info = need_info
        self.window = StampWindow(max_gap_ns)
        self.setting: Setting | None = None      # confirmed by the last pair
        self.info: Any = None                     # that pair's camera_info payload
        self._infos: OrderedDict[int, tuple[Setting, Any]] = OrderedDict()
        self._images: OrderedDict[int, tuple[Setting, Any]] = OrderedDict()

    # -- input -------------------------------------------------------------------------------------
    def add_info(self, stamp_ns: int, setting: Setting, info: Any) -> tuple[list[Accepted], list[Rejected]]:
        """A camera_info of the view; returns the images it lets in (those waiting for it) and rejections."""
        return self._settled(*self._add_info(stamp_ns, setting, info))

    def add_image(self, stamp_ns: int, setting: Setting, payload: Any) -> tuple[list[Accepted], list[Rejected]]:
        """An image (or mask) of the view; returns what may be used now and the rejections."""
        return self._settled(*self._add_image(stamp_ns, setting, payload))

    def _settled(self, accepted: list[Accepted], rejected: list[Rejected]) -> tuple[list[Accepted], list[Rejected]]:
        """After an accepted image, the waiting ones older than it are rejected: a newer image got in
        first, so their camera_info is not coming."""
        if accepted:
            last = self.window.last_ns
            for s in [s for s in self._images if s < last]:
                rejected.append(self._unpaired(s, self._images.pop(s)[0]))
        return accepted, rejected

    def _add_info(self, stamp_ns: int, setting: Setting, info: Any) -> tuple[list[Accepted], list[Rejected]]:
        held = self._images.pop(stamp_ns, None)
        if held is not None:
            return self._pair(stamp_ns, held[0], held[1], setting, info)
        rejected = []
        self._infos[stamp_ns] = (setting, info)
        self._infos.move_to_end(stamp_ns)
        while len(self._infos) > self.depth:
            s, (st, _) = self._infos.popitem(last=False)
            if self.setting is not None and (st.frame_id, st.width, st.height) != \
                    (self.setting.frame_id, self.setting.width, self.setting.height):
                rejected.append(Rejected("camera_info", f"{self.name}/camera_info of stamp {s} ({st}) met no "
                                         f"image of its stamp; the view stays {self.setting}"))
        return [], rejected

    def _add_image(self, stamp_ns: int, setting: Setting, payload: Any) -> tuple[list[Accepted], list[Rejected]]:
        paired = self._infos.pop(stamp_ns, None)
        if paired is not None:
            return self._pair(stamp_ns, setting, payload, paired[0], paired[1])
        if not self.need_info and self.setting is None:
            return self._take(stamp_ns, setting, payload, None, first=True), []
        if self.setting is not None:
            why = self._disagrees(setting) or self.window.far(stamp_ns)
            if why is None:
                return self._take(stamp_ns, setting, payload, self.info), []
            if not self.need_info:
                return [], [self._rejection(setting, why)]
        # wait for the camera_info of this stamp
        self._images[stamp_ns] = (setting, payload)
        self._images.move_to_end(stamp_ns)
        rejected = []
        while len(self._images) > self.depth:
            s, (st, _) = self._images.popitem(last=False)
            rejected.append(self._unpaired(s, st))
        return [], rejected

    def waiting(self) -> int:
        """Images waiting for their camera_info."""
        return len(self._images)

    def waiting_stamps(self) -> list[int]:
        """The stamps of the images waiting for their camera_info (in arrival order)."""
        return list(self._images)

    # -- internals ---------------------------------------------------------------------------------
    def _disagrees(self, s: Setting) -> str | None:
        c = self.setting
        if (s.width, s.height) != (c.width, c.height):
            return f"size {s.width}x{s.height}, the camera's is {c.width}x{c.height}"
        if s.frame_id != c.frame_id:
            return f"frame_id {s.frame_id!r}, the camera's is {c.frame_id!r}"
        if s.encoding != c.encoding:
            return f"encoding {s.encoding!r}, the camera's is {c.encoding!r}"
        return None

    @staticmethod
    def _kind(why: str) -> str:
        return why.split(" ", 1)[0]   # size / frame_id / encoding / stamp

    def _rejection(self, setting: Setting, why: str) -> Rejected:
        return Rejected(self._kind(why), f"{self.name}: image {setting} dropped: {why}")

    def _unpaired(self, stamp_ns: int, setting: Setting) -> Rejected:
        if self.setting is None:
            return Rejected("no_camera_info", f"{self.name}: image of stamp {stamp_ns} ({setting}) dropped: no "
                                              f"camera_info of its stamp arrived (nothing is learnt from an image "
                                              f"no camera_info vouched for)")
        why = self._disagrees(setting) or self.window.far(stamp_ns) or "no camera_info of its stamp"
        return Rejected(self._kind(why), f"{self.name}: image of stamp {stamp_ns} ({setting}) dropped: {why}, and "
                                         f"no camera_info of its stamp says otherwise")

    def _pair(self, stamp_ns: int, image: Setting, payload: Any, info_setting: Setting,
              info: Any) -> tuple[list[Accepted], list[Rejected]]:
        if image.frame_id != info_setting.frame_id:
            return [], [Rejected("pair", f"{self.name}: image of stamp {stamp_ns} dropped: frame_id "
                                             f"{image.frame_id!r}, its camera_info's is {info_setting.frame_id!r}")]
        if (image.width, image.height) != (info_setting.width, info_setting.height):
            return [], [Rejected("pair", f"{self.name}: image of stamp {stamp_ns} dropped: size {image.width}x"
                                         f"{image.height}, its camera_info says {info_setting.width}x"
                                         f"{info_setting.height}")]
        first = self.setting is None
        changed = None
        if not first and image != self.setting:
            changed = f"{self.setting} -> {image}"
        return self._take(stamp_ns, image, payload, info, first=first, changed=changed), []

    def _take(self, stamp_ns: int, setting: Setting, payload: Any, info: Any, *, first: bool = False,
              changed: str | None = None) -> list[Accepted]:
        if first or changed:
            self.setting = setting
        if info is not None:
            self.info = info
        self.window.accept(stamp_ns)
        return [Accepted(stamp_ns, payload, self.info, first=first, changed=changed)]


#: what :class:`StreamJumps` does with a ``far`` stamp, for a log line
FAR_RULE = "taken as a restart only if the next one follows it"


class StreamJumps:
    """One stream's stamps when the stream may restart (a replayed bag, a camera paused): a stamp that
    continues the stream (newer than the last, by at most ``ahead_ns``) is taken; one older by at most
    ``back_ns`` is out of order (dropped); any other is *far*: it is dropped, but remembered, and the next
    stamp that continues *it* restarts the stream there. So one stray message far in time neither resets
    nor derails the stream, and a real restart costs its first message.

    The last ``candidates`` far stamps are remembered, and a stamp taken by the stream forgets none of them: a
    restart's first two stamps need not come back to back. (With one candidate, forgotten at the next stamp of the
    stream, a single message between them -- a far one, or one more of the old stream, say the last image of
    another source still in flight -- cost the restart its first stamp: the segmentation node then learnt its
    background from the second frame on, and under test/fuzzer.py the first frames with a person were taken for
    background.)

    :meth:`decide` returns ``(kind, why)``: ``take``, ``restart`` (from the candidate :attr:`restarted_from`),
    ``order`` (out of order: dropped) or ``far`` (dropped, remembered as a possible restart: :data:`FAR_RULE` says
    so in a log line); ``ahead_ns <= 0``: no limit ahead.
    """

    def __init__(self, *, back_ns: int, ahead_ns: int, candidates: int = 3) -> None:
        if candidates < 1:
            raise ValueError(f"candidates: expected >= 1, received {candidates}")
        self.back_ns = int(back_ns)
        self.ahead_ns = int(ahead_ns)
        self.max_candidates = candidates
        self.last_ns: int | None = None
        self.restarted_from: int | None = None     # the candidate the last restart continued
        self._candidates: list[int] = []           # far stamps, oldest first

    @property
    def candidates(self) -> tuple[int, ...]:
        """The far stamps remembered as possible restarts, oldest first."""
        return tuple(self._candidates)

    def _continues(self, ref: int, stamp_ns: int) -> bool:
        return stamp_ns > ref and (self.ahead_ns <= 0 or stamp_ns - ref <= self.ahead_ns)

    def decide(self, stamp_ns: int) -> tuple[str, str | None]:
        if self.last_ns is None or self._continues(self.last_ns, stamp_ns):
            self.last_ns = stamp_ns
            return "take", None
        d_s = (stamp_ns - self.last_ns) / 1e9
        if -self.back_ns <= stamp_ns - self.last_ns <= 0:
            return "order", (f"stamp {stamp_ns} is not newer than the last one's {self.last_ns} "
                             f"(out of order by {-d_s * 1e3:.1f} ms)")
        for c in reversed(self._candidates):         # the newest candidate it continues
            if self._continues(c, stamp_ns):
                self.last_ns, self.restarted_from, self._candidates = stamp_ns, c, []
                return "restart", f"the stream restarted {d_s:+.3f} s from its last stamp"
        self._candidates = [*self._candidates, stamp_ns][-self.max_candidates:]
        return "far", f"stamp {stamp_ns} is {d_s:+.3f} s from the stream (last {self.last_ns})"


class StreamForks:
    """:class:`StreamJumps` for a stream whose messages build up a state (a view's background model), where
    no message may wait (a lockstep replay waits for each one's result): a far stamp is processed at once on a
    *candidate* state of its own (``new_state()``), one per candidate the rule remembers. One that continues the
    stream goes on with the stream's state, which the far messages never touched; one that continues a far stamp
    makes that candidate the stream's state (a restart: a bag replayed or looped, a camera restarted).

    :meth:`state_for` returns ``(kind, state, why)``: ``take`` (the stream's state), ``restart`` (the candidate,
    now the stream's), ``far`` (a new candidate) or ``drop`` (out of order: ``state`` None).
    """

    def __init__(self, new_state: Callable[[], Any], *, back_ns: int, ahead_ns: int, candidates: int = 3) -> None:
        self.new_state = new_state
        self.jumps = StreamJumps(back_ns=back_ns, ahead_ns=ahead_ns, candidates=candidates)
        self.state = new_state()
        self._candidates: dict[int, Any] = {}     # far stamp -> its state (those the rule remembers)

    def state_for(self, stamp_ns: int) -> tuple[str, Any, str | None]:
        kind, why = self.jumps.decide(stamp_ns)
        if kind == "take":
            return kind, self.state, None
        if kind == "restart":
            self.state, self._candidates = self._candidates[self.jumps.restarted_from], {}
            return kind, self.state, why
        if kind == "far":                          # remembered by the rule as a possible restart
            kept = set(self.jumps.candidates)
            self._candidates = {s: st for s, st in self._candidates.items() if s in kept}
            self._candidates[stamp_ns] = self.new_state()
            return kind, self._candidates[stamp_ns], why
        return "drop", None, why
