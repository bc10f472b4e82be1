"""What every frame source shares (:mod:`.sources`, :mod:`.source_wrappers`): the :class:`FrameSource`
protocol, :class:`EndOfSource`, :class:`SourceError`, the :class:`SourceEvent` a source reports and the
mixin that gathers them, and the BGR-to-RGB conversion of OpenCV images.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol, runtime_checkable

import cv2
import numpy as np

from .errors import VisionError

__all__ = ["FrameSource", "EndOfSource", "SourceError", "SourceEvent"]


class SourceError(VisionError):
    """Bad arguments to a frame source (unopenable file, empty glob, bad numbers)."""


class EndOfSource(Exception):
    """Raised by :meth:`FrameSource.read` when a finite source has no more frame sets."""


@dataclass(frozen=True)
class SourceEvent:
    """Something a source wants the node to log.

    Attributes
    ----------
    kind : {"failed", "retry", "reconnected", "warning", "info"}
        ``failed``: a view's device or file failed (first time); ``retry``: a reopen attempt failed;
        ``reconnected``: a failed device works again; ``warning``: frames dropped or cut;
        ``info``: nothing lost (e.g. a loop restarted).
    view : int
        View index (``-1`` for the whole source).
    text : str
        One human-readable line, e.g. ``"reconnected camera 2 (device 5)"``.
    """

    kind: str
    view: int
    text: str


@runtime_checkable
class FrameSource(Protocol):
    """What the camera node reads frame sets from."""

    n_views: int

    def read(self) -> list[np.ndarray | None]:
        """One RGB ``(H, W, 3) uint8`` image per view (``None`` for a view that failed this time).

        Raises
        ------
        EndOfSource
            No more frame sets.
        """

    def close(self) -> None:
        """Release devices and files."""


def _bgr_to_rgb(img: np.ndarray) -> np.ndarray:
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


class _EventMixin:
    """``events`` list (bounded) plus an optional callback."""

    _MAX_EVENTS = 1000

    def _init_events(self, on_event: Callable[[SourceEvent], None] | None) -> None:
        self.events: list[SourceEvent] = []
        self._on_event = on_event

    def _emit(self, kind: str, view: int, text: str) -> None:
        ev = SourceEvent(kind, view, text)
        self.events.append(ev)
        del self.events[:-self._MAX_EVENTS]
        if self._on_event is not None:
            self._on_event(ev)

    def drain_events(self) -> list[SourceEvent]:
        """Return and forget the events gathered so far."""
        out, self.events = self.events, []
        return out
