"""Prediction exactly as the node network computes it, for bit-identical offline replays.

In the network, estimates travel as ``sensor_msgs/JointState`` whose root rotation is published as
roll/pitch/yaw (:func:`isa_mocap_ros.body.pose_to_joint_state`), the prediction node turns them
back into pose vectors, predicts, and publishes the prediction the same way; the estimator turns it
into a pose vector again. :class:`PublishedPredictor` wraps any predictor with exactly those
conversions, so ``isa-mocap track`` and the prediction node + estimator produce the same numbers.
"""
from __future__ import annotations

import numpy as np

from isa_mocap_ros.body import BodyModel, joint_state_to_pose, pose_to_joint_state
from isa_mocap_ros.tracking.predict import frames_kwargs


def through_message(model: BodyModel, x: np.ndarray) -> np.ndarray:
    """The pose vector a receiver gets for ``x`` sent as JointState positions."""
    return joint_state_to_pose(model, pose_to_joint_state(model, x))


class PublishedPredictor:
    """``predictor`` fed and read through JointState conversions (see the module docstring)."""

    def __init__(self, model: BodyModel, predictor) -> None:
        self.model = model
        self.predictor = predictor

    def update_from_message(self, positions: np.ndarray, frames: float = 1) -> None:
        """What the prediction node does with a received estimate (JointState positions);
        ``frames``: periods since the previous estimate."""
        self.predictor.update(joint_state_to_pose(self.model, positions), **frames_kwargs(frames))

    def message(self, frames: float = 1) -> np.ndarray:
        """JointState positions of the prediction ``frames`` periods ahead, as the prediction node publishes them."""
        return pose_to_joint_state(self.model, self.predictor.predict(**frames_kwargs(frames)))

    def update(self, x: np.ndarray, frames: float = 1) -> None:
        self.update_from_message(pose_to_joint_state(self.model, x), frames)

    def predict(self, frames: float = 1) -> np.ndarray:
        return joint_state_to_pose(self.model, self.message(frames))

    def reset(self) -> None:
        self.predictor.reset()

    @property
    def n_estimates(self) -> int | None:
        """The wrapped predictor's number of estimates held (None if it does not say)."""
        return getattr(self.predictor, "n_estimates", None)

    @property
    def capacity(self) -> int | None:
        """The wrapped predictor's history length (None if it does not say)."""
        return getattr(self.predictor, "capacity", None)
