"""isa_mocap_ros.tracking: prediction (ISA 13.28), initialization and the per-frame tracker.

Modules: :mod:`.predict` (AR on twists and baselines), :mod:`.init` (initial pose from the masks),
:mod:`.tracker` (prediction → optimizer → estimate) with its pieces (:mod:`.config`, :mod:`.frame_context`,
:mod:`.state`, :mod:`.plan`, :mod:`.frame_masks`, :mod:`.frame_prediction`, :mod:`.objective`, :mod:`.stages`,
:mod:`.first_frame`, :mod:`.heading`), :mod:`.sync` (frame-set synchronizer), :mod:`.published`.
See ``docs/tracking.md``.
"""
from .init import InitError, InitResult, initial_pose, root_from_masks, triangulate_rays
from .predict import ArPredictor, ConstantPosePredictor, ConstantVelocityPredictor, PredictionError
from .tracker import FrameResult, Tracker, TrackerConfig, TrackerError, frame_rng, make_tracker

__all__ = ["ArPredictor", "ConstantPosePredictor", "ConstantVelocityPredictor", "PredictionError",
           "InitError", "InitResult", "initial_pose", "root_from_masks", "triangulate_rays",
           "Tracker", "TrackerConfig", "TrackerError", "FrameResult", "make_tracker", "frame_rng"]
