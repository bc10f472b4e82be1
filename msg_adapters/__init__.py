"""ROS 2 messages ⇄ numpy and plain Python values; rclpy messages ⇄ CDR bytes.

Pure functions over the rclpy message classes of ``sensor_msgs``, ``std_msgs``,
``geometry_msgs`` and ``builtin_interfaces`` (definitions: ROS 2 Jazzy ``common_interfaces``;
conventions: REP-103, REP-104). This package imports nothing from ``isa_mocap_ros``; nodes use
it to keep message handling out of the core. Every rejection raises :class:`AdapterError`
(a ``ValueError``) whose message names the field, the expected and the received value.

Adapters (details and speed: ``docs/msg_adapters.md``):

- ``image_to_array`` / ``array_to_image``: ``sensor_msgs/Image`` ⇄ (H, W[, C]) ndarray
- ``camera_info_to_intrinsics`` / ``intrinsics_to_camera_info``: ``CameraInfo`` ⇄ :class:`Intrinsics`;
  ``camera_info_key``: a cheap equality key of the fields read
- ``transform_to_rt`` / ``rt_to_transform``: ``TransformStamped`` ⇄ (R, t)
- ``joint_state_to_arrays`` / ``arrays_to_joint_state``: ``JointState`` ⇄ (names, positions)
- ``keypoints_to_polygon`` / ``polygon_to_keypoints``: ``PolygonStamped`` ⇄ (uv, confidence) 2-D keypoints
- ``stamp_to_ns`` / ``ns_to_stamp`` / ``make_header``: ``Time``/``Header`` ⇄ int nanoseconds
- ``to_cdr`` / ``from_cdr`` / ``message_type`` / ``header_stamp_ns_from_cdr``: CDR bytes
"""
from .camera_info import (DISTORTION_MODELS, Intrinsics, camera_info_key, camera_info_to_intrinsics,
                          intrinsics_to_camera_info)
from .cdr import from_cdr, header_stamp_ns_from_cdr, message_type, to_cdr, type_name_of
from .errors import AdapterError
from .image import ENCODINGS, array_to_image, image_to_array
from .keypoints import keypoints_to_polygon, polygon_to_keypoints
from .joint_state import arrays_to_joint_state, joint_state_to_arrays
from .stamp import make_header, ns_to_stamp, stamp_to_ns
from .transform import (ORTHONORMAL_TOL, matrix_to_quaternion, quaternion_to_matrix, rt_to_transform,
                        transform_to_rt)

__all__ = [
    "AdapterError",
    "ENCODINGS", "image_to_array", "array_to_image",
    "DISTORTION_MODELS", "Intrinsics", "camera_info_to_intrinsics", "intrinsics_to_camera_info", "camera_info_key",
    "ORTHONORMAL_TOL", "quaternion_to_matrix", "matrix_to_quaternion", "transform_to_rt", "rt_to_transform",
    "joint_state_to_arrays", "arrays_to_joint_state",
    "keypoints_to_polygon", "polygon_to_keypoints",
    "stamp_to_ns", "ns_to_stamp", "make_header",
    "to_cdr", "from_cdr", "message_type", "type_name_of", "header_stamp_ns_from_cdr",
]
