"""Where the package's shipped files are: ``bags/`` and ``config/``.

In a source checkout (pip editable install) they sit at the repository root; in an ament/colcon
install, under ``share/isa_mocap_ros``. Pure: no ROS import.
"""
from __future__ import annotations

import sys
from pathlib import Path

_SRC_ROOT = Path(__file__).resolve().parents[1]


def _candidates(sub: str) -> list[Path]:
    return [_SRC_ROOT / sub, Path(sys.prefix) / "share" / "isa_mocap_ros" / sub]


def resource_dir(sub: str) -> Path:
    """The first existing ``sub`` folder (``bags`` or ``config``); FileNotFoundError names the places tried."""
    for c in _candidates(sub):
        if c.is_dir():
            return c
    raise FileNotFoundError(f"no '{sub}' folder in {[str(c) for c in _candidates(sub)]}")


def default_bag() -> Path:
    """The shipped demo bag."""
    return resource_dir("bags") / "demo"
