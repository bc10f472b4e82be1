"""SO(3)/SE(3) geometry: Rodrigues exp/log (ISA Eq. 13.20-13.21), rotation mean (13.22-13.24),
twists exp/log (13.25-13.27) with ``(v, ω)`` ordering, the adjoint, root-pose matrices."""
from .se3 import adjoint, exp_se3, log_se3, matrix_to_pose, pose_to_matrix, twist_hat
from .so3 import GeometryError, exp_so3, hat, log_so3, nearest_rotvec, rot_x, rot_y, rot_z, rotation_mean, vee

__all__ = ["GeometryError", "hat", "vee", "exp_so3", "log_so3", "rotation_mean", "nearest_rotvec", "rot_x", "rot_y",
           "rot_z", "exp_se3", "log_se3", "adjoint", "pose_to_matrix", "matrix_to_pose", "twist_hat"]
