"""Body models (39/28/18 DOF), batch forward kinematics, capsule skin, URDF export, BVH import.

Sources: EA-vs-PF §3.1/Table 1 and §3.3 (full-body models, hierarchy), ISA §13.4.2 (18-DOF lower
body, rotation-vector root). See ``docs/body_models.md``.
"""
from .bvh import BVH_TO_WORLD, BvhMotion, load_bvh, parse_bvh
from .kinematics import capsule_endpoints, forward_kinematics, joint_positions, position_jacobian
from .model import (DEFAULT_SHAPE_PATH, FULL_BODY_JOINTS, ROOT_DOF_NAMES, BodyError, BodyModel,
                    default_shape, load_shape, make_model, save_shape)
from .retarget import RetargetReport, map_skeleton, model_from_bvh, retarget
from .urdf import (euler_to_root_rotvec, joint_state_to_pose, pose_to_joint_state, root_rotvec_to_euler,
                   to_urdf)

__all__ = ["BodyError", "BodyModel", "make_model", "load_shape", "save_shape", "default_shape",
           "DEFAULT_SHAPE_PATH", "FULL_BODY_JOINTS", "ROOT_DOF_NAMES", "forward_kinematics",
           "joint_positions", "capsule_endpoints", "position_jacobian", "to_urdf",
           "root_rotvec_to_euler", "euler_to_root_rotvec", "pose_to_joint_state", "joint_state_to_pose",
           "BvhMotion", "load_bvh", "parse_bvh", "BVH_TO_WORLD", "map_skeleton", "model_from_bvh", "retarget",
           "RetargetReport"]
