"""The main job's keypoint default, one rule for ``run``, ``track`` and ``bench mesh``.

The learned-keypoint term (BlazePose landmarks, docs/keypoints.md) is **on by default** in the main job: weight
``DEFAULT_KEYPOINT_WEIGHT`` at the keypoint node's rate (``vision.keypoint_schedule.EVERY_K``), chosen by the
figures of docs/decisions/014-keypoints-by-default.md. The landmark model is fetched by the project's set-up
(``make models``, from the mediapipe wheel on PyPI); when it is absent, a command left at its default tracks
without the term and says so in one line (an explicit ``--keypoint-weight W > 0`` or ``--keypoints`` still fails
with the fetch instructions). The library's own default (``TrackerConfig.keypoints.keypoint_weight``) stays 0:
the tracker uses keypoints only when it is given them, and the estimator node waits for a keypoint node only
when told to.
"""
from __future__ import annotations

__all__ = ["DEFAULT_KEYPOINT_WEIGHT", "default_keypoint_weight"]

#: weight of the keypoint term when a command is left at its default (weight 2 was no better than 1 on meshes)
DEFAULT_KEYPOINT_WEIGHT = 1.0


def default_keypoint_weight() -> tuple[float, str | None]:
    """``(weight, note)`` for a command left at its default: ``DEFAULT_KEYPOINT_WEIGHT`` when the landmark
    model is installed, else 0 with a note saying why and how to get it."""
    from isa_mocap_ros.vision.landmark_model import ModelUnavailable, landmark_model_path

    try:
        landmark_model_path()
    except ModelUnavailable as exc:
        return 0.0, f"keypoints off (the default is on): {exc}"
    return DEFAULT_KEYPOINT_WEIGHT, None
