"""The exception of the vision area (cameras, calibration files, rigs, renderer, distortions)."""
from __future__ import annotations

__all__ = ["VisionError"]


class VisionError(ValueError):
    """Bad input to a vision function: the message names the field, the expected and the received value."""
