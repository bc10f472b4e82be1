"""Argument checks shared by the energies (:mod:`.silhouette`, :mod:`.restricted`, :mod:`.correspondence`,
:mod:`.keypoints`) and :class:`EnergyError`, the error they raise.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..body import BodyModel
from ..vision import Camera

__all__ = ["EnergyError"]


class EnergyError(ValueError):
    """Bad input to an energy (names the argument, the expected and the received value)."""


def _check_model(model: Any) -> BodyModel:
    if not isinstance(model, BodyModel):
        raise EnergyError(f"model: expected a BodyModel, received {type(model).__name__}")
    return model


def _check_cameras(cameras: Any) -> tuple[Camera, ...]:
    cams = tuple(getattr(cameras, "cameras", cameras)) if cameras is not None else ()
    if not cams or not all(isinstance(c, Camera) for c in cams):
        raise EnergyError(f"cameras: expected a non-empty sequence of Camera, received {cameras!r}")
    return cams


def _check_poses(model: BodyModel, X: Any) -> tuple[np.ndarray, np.ndarray]:
    """``X`` as ``(n, D)`` float64 and the ``(n,)`` mask of finite rows."""
    try:
        X = np.asarray(X, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EnergyError(f"X: expected a numeric array of shape (n, {model.dof}), received {X!r}") from exc
    if X.ndim == 1:
        X = X[None]
    if X.ndim != 2 or X.shape[1] != model.dof:
        raise EnergyError(f"X: expected shape (n, {model.dof}) for model {model.name}, received shape {X.shape}")
    X = np.ascontiguousarray(X)
    if np.isfinite(X.sum()):                  # one reduction for the usual all-finite batch
        return X, np.ones(X.shape[0], bool)
    return X, np.all(np.isfinite(X), axis=1)
