"""Where the package's shipped files are (``bags/``, ``config/``) and where the shared data is.

In a source checkout (pip editable install) they sit at the repository root; in an ament/colcon
install, under ``share/isa_mocap_ros``. Pure: no ROS import.
"""
from __future__ import annotations

import os
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


def shared_data_dir() -> Path:
    """The shared data folder (motion capture, meshes, real recordings) that is never committed:
    ``$ISA_MOCAP_SHARED/data``, by default ``shared/data`` beside the checkout (``<repo>/../shared``).
    It may be absent; callers check for the files they need and skip with a message."""
    return Path(os.environ.get("ISA_MOCAP_SHARED", _SRC_ROOT.parent / "shared")) / "data"


def cmu_walk_bvh() -> Path:
    """The CMU walk (subject 131, trial 01) in the shared data; may not exist."""
    return shared_data_dir() / "mocap" / "cmu_131_01_walk.bvh"
