"""Replay planning for the bag player: topic selection, remapping and lockstep frames.

Pure logic (no rclpy), used by :mod:`isa_mocap_ros.nodes.player`.

A *frame* is a run of consecutive messages (log-time order) whose header stamps are equal; our
bags (``isa-mocap synth``) give all views of one frame set the same ``header.stamp``. Messages on
latched (transient-local) topics and unstamped messages never open a frame: latched ones go out
at once, unstamped ones travel with the frame they sit in. In lockstep mode the player publishes
frame k+1 only after the downstream node acknowledged frame k's stamp.
"""
from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass, field
from typing import Callable, Iterable, Iterator, Mapping, Sequence

from . import BagError, BagMessage, TopicInfo

_FIELD_RE = re.compile(r"^\s*([A-Za-z0-9_/]+)(\[[0-9<=]*\])?\s+[A-Za-z_][A-Za-z0-9_]*\s*(=.*)?$")


@dataclass(frozen=True)
class PlaybackOptions:
    """What to replay and how (mirrors ``ros2 bag play`` options)."""

    rate: float = 1.0
    loop: bool = False
    start_offset_s: float = 0.0
    topics: tuple[str, ...] = ()
    exclude_topics: tuple[str, ...] = ()
    remap: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.rate > 0.0:
            raise BagError(f"playback rate must be > 0, got {self.rate}")
        if self.start_offset_s < 0.0:
            raise BagError(f"start offset must be >= 0 s, got {self.start_offset_s}")


def parse_remaps(items: Iterable[str]) -> dict[str, str]:
    """``["/a:=/b", ...]`` -> ``{"/a": "/b"}``; a malformed item raises :class:`BagError`."""
    out: dict[str, str] = {}
    for item in items:
        old, sep, new = item.partition(":=")
        if not sep or not old.strip() or not new.strip():
            raise BagError(f"remap must look like 'old:=new', got {item!r}")
        out[old.strip()] = new.strip()
    return out


def select_topics(topics: Mapping[str, TopicInfo], options: PlaybackOptions) -> list[str]:
    """Topics to replay: ``options.topics`` (names or glob patterns; all when empty) minus excludes."""
    names = sorted(topics)
    if options.topics:
        unknown = [t for t in options.topics
                   if not any(fnmatch.fnmatchcase(n, t) for n in names)]
        if unknown:
            raise BagError(f"topics not in the bag: {unknown}; the bag has {names}")
        names = [n for n in names if any(fnmatch.fnmatchcase(n, t) for t in options.topics)]
    return [n for n in names if not any(fnmatch.fnmatchcase(n, t) for t in options.exclude_topics)]


def first_field_is_header(msgdef: str) -> bool:
    """True when a ``ros2msg`` definition's first field is a ``std_msgs/Header``."""
    for line in msgdef.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith("==="):
            return False
        m = _FIELD_RE.match(line)
        if m is None or m.group(3):  # constants do not count as fields
            continue
        return m.group(1) in ("std_msgs/Header", "std_msgs/msg/Header", "Header")
    return False


@dataclass
class Frame:
    """Messages published together; ``stamp_ns`` is None for latched/unstamped preambles."""

    stamp_ns: int | None
    messages: list[BagMessage]

    @property
    def log_time_ns(self) -> int:
        return self.messages[0].log_time_ns


def frames(messages: Iterable[BagMessage], *, stamped_topics: Sequence[str],
           latched_topics: Sequence[str],
           stamp_of: Callable[[BagMessage], int | None]) -> Iterator[Frame]:
    """Group messages into frames by header stamp (see the module docstring).

    ``stamp_of`` reads a message's header stamp (the node passes the CDR fast path of
    ``msg_adapters``) and may return None for a message it cannot read; such a message travels
    with the current frame.
    """
    stamped, latched = set(stamped_topics), set(latched_topics)
    current: Frame | None = None
    for msg in messages:
        if msg.topic in latched:
            if current is not None:
                yield current
                current = None
            yield Frame(None, [msg])
            continue
        stamp = stamp_of(msg) if msg.topic in stamped else None
        if current is None:
            current = Frame(stamp, [msg])
        elif stamp is not None and current.stamp_ns is not None and stamp != current.stamp_ns:
            yield current
            current = Frame(stamp, [msg])
        else:
            if current.stamp_ns is None and stamp is not None:
                current.stamp_ns = stamp
            current.messages.append(msg)
    if current is not None:
        yield current
