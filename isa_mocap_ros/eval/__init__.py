"""isa_mocap_ros.eval: accuracy metrics (EA-vs-PF Eq. 20 joint error, ISA §13.4.2 knee RMSE).

See :mod:`.metrics`.
"""
from .metrics import (MetricsError, angle_difference, body_frames, frame_errors_mm, heading_errors_deg,
                      joint_errors_mm, knee_errors_deg, knee_rmse_deg, marker_positions, max_frame_error_mm, mpjpe_mm,
                      offset_removed_errors_mm, per_joint_angle_rmse_deg, score_markers, shared_markers)

__all__ = ["MetricsError", "joint_errors_mm", "frame_errors_mm", "mpjpe_mm", "max_frame_error_mm",
           "knee_rmse_deg", "knee_errors_deg", "per_joint_angle_rmse_deg", "angle_difference",
           "shared_markers", "marker_positions", "score_markers", "body_frames",
           "offset_removed_errors_mm", "heading_errors_deg"]
