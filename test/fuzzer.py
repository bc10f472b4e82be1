"""Publishes malformed and valid-but-wrong messages on every input topic of the node network, until killed.

``python fuzzer.py VIEWS RATE_HZ SEED [PREFIX]`` (in the caller's ROS domain, namespace /mocap; PREFIX: only
the kinds whose name starts with it, e.g. ``keypoints``). Each tick it
picks the next kind of a fixed cycle and a view (seeded), and publishes one message on
``cam<v>/image_raw``, ``cam<v>/camera_info``, ``cam<v>/extrinsics``, ``cam<v>/mask``,
``prediction/joint_states``, ``cam<v>/keypoints`` or ``cam<v>/keypoints_skipped`` (the estimator takes the
last two only with ``keypoint_weight`` > 0). It listens to ``cam0/camera_info`` to learn the stream's stamps and the
cameras' size, so the valid-but-wrong messages come *near* the stream (a few ms after a real frame's
stamp, never on it) where a stamp check alone would not catch them.

What a correct network must reject (module docstring of ``isa_mocap_ros.intake``):
malformed messages (truncated data, unknown encodings, NaN, zero K or quaternion, mismatched joint
lists), and messages that disagree with what the node knows: another size or encoding than the
view's camera, another frame id, a camera_info with no image of its stamp, a stamp far from the
stream, extrinsics from another parent frame or for another child frame, predictions far from the
frame sets, keypoints of another count than 0 or 33, with NaN or a confidence above 1 (on the next frame's
own stamp: a lockstep estimator must still wait for that view's real message), keypoints and skip notices
far from the stream (each far message at a stamp of its own), and images and camera infos that agree, each view
at a stamp of its own (one view alone is no frame set of the rig: the segmentation node segments them, the estimator and
the keypoint node's schedule must not count them). It never sends what a network cannot tell from the cameras
themselves: every view's image and camera_info of one stamp that agree, or a well-formed mask / prediction right
in the stream.

Prints ``sent <kind> <n>`` lines every second and a total per kind at exit (SIGINT/SIGTERM).
"""
import signal
import sys
import time

import numpy as np
import rclpy
from geometry_msgs.msg import Point32, PolygonStamped, TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Header

import msg_adapters as ma
from isa_mocap_ros.body import make_model

HOUR_NS = 3600 * 10**9


class Fuzzer(Node):
    def __init__(self, views: int, rate_hz: float, seed: int, prefix: str = "") -> None:
        super().__init__("fuzzer", namespace="/mocap")
        self.views = views
        self.rng = np.random.default_rng(seed)
        rel = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.img = [self.create_publisher(Image, f"cam{v}/image_raw", rel) for v in range(views)]
        self.info = [self.create_publisher(CameraInfo, f"cam{v}/camera_info", rel) for v in range(views)]
        self.mask = [self.create_publisher(Image, f"cam{v}/mask", rel) for v in range(views)]
        self.extr = [self.create_publisher(TransformStamped, f"cam{v}/extrinsics", latched) for v in range(views)]
        self.pred = self.create_publisher(JointState, "prediction/joint_states", rel)
        self.kp = [self.create_publisher(PolygonStamped, f"cam{v}/keypoints", rel) for v in range(views)]
        self.kp_skipped = [self.create_publisher(Header, f"cam{v}/keypoints_skipped", rel) for v in range(views)]
        self.names = make_model(39).dof_names
        self.last_real_ns = 1_700_000_000_000_000_000   # until the stream is heard: the project's bags' epoch
        self.size = (320, 240)
        self.unique = 0
        self.heard = False                       # a real camera_info of cam0 came
        self.own_info_stamps: set[int] = set()   # its own camera infos come back to its subscription
        self.create_subscription(CameraInfo, "cam0/camera_info", self._heard, rel)
        self.kinds = [k for k in dir(self) if k.startswith("k_" + prefix)]
        self.sent: dict[str, int] = {k[2:]: 0 for k in self.kinds}
        self.tick = 0
        self.create_timer(1.0 / rate_hz, self._send)
        self.create_timer(1.0, lambda: print("sent " + " ".join(f"{k}={n}" for k, n in self.sent.items()),
                                             flush=True))

    def _heard(self, msg: CameraInfo) -> None:
        s = ma.stamp_to_ns(msg.header)
        # only what fits the stream: the fuzzer's own camera infos (far stamps, 7x3) must not steer it
        if s in self.own_info_stamps:
            return
        if msg.header.frame_id == "cam0_optical_frame" and msg.width > 16 and abs(s - self.last_real_ns) < HOUR_NS:
            self.last_real_ns = max(self.last_real_ns, s)
            self.size = (msg.width, msg.height)
            self.heard = True

    # -- stamps ------------------------------------------------------------------------------------
    def near(self) -> int:
        """A stamp a few ms after the last real frame, never a real frame's (frames are 33.3 ms apart)."""
        self.unique += 1
        return self.last_real_ns + 3_000_000 + 1_000 * self.unique % 20_000_000 + 7

    def far(self) -> int:
        """A stamp far from the stream (an hour ahead or back, or near 0), each 10 s from every other far stamp sent.
        With one far stamp per frame (7, or the last frame's +- 1 h), the far images, camera infos and masks of a
        slow (loaded) run met at one stamp on every view: a frame set of the rig, which the network must take as
        data (the estimator's stream jumped an hour ahead and took no real frame again); and far stamps a few us
        apart continue each other: a stream restarting there (the segmentation node's rule). Neither is the
        fuzzer's to send."""
        self.unique += 1
        step = 10 * 10**9 * self.unique
        base = int(self.rng.choice([self.last_real_ns + HOUR_NS, self.last_real_ns - HOUR_NS, 7]))
        return base - step if base < self.last_real_ns - HOUR_NS // 2 and base != 7 else base + step

    def frame(self, v: int) -> str:
        return f"cam{v}_optical_frame"

    # -- images ------------------------------------------------------------------------------------
    def k_image_7x3_bgr8(self, v):        # the stray image: valid, tiny, near the stream
        return self.img[v], ma.array_to_image(self.rng.integers(0, 255, (3, 7, 3), dtype=np.uint8), "bgr8",
                                              stamp_ns=self.near(), frame_id=self.frame(v))

    def k_image_right_size_other_encoding(self, v):
        w, h = self.size
        enc = ["bgr8", "mono8"][self.unique % 2]
        shape = (h, w, 3) if enc == "bgr8" else (h, w)
        return self.img[v], ma.array_to_image(self.rng.integers(0, 255, shape, dtype=np.uint8), enc,
                                              stamp_ns=self.near(), frame_id=self.frame(v))

    def k_image_far_stamp(self, v):
        w, h = self.size
        return self.img[v], ma.array_to_image(self.rng.integers(0, 255, (h, w, 3), dtype=np.uint8), "rgb8",
                                              stamp_ns=self.far(), frame_id=self.frame(v))

    def k_image_and_info_before_stream(self, v):
        """Until the stream is heard: on every view an image and a camera_info that agree, each view at a stamp of its
        own (no frame set of the rig: one view each, like a lone camera starting); after: one view's image and
        camera_info that agree, far in time (a lone camera's pair, no frame set either)."""
        w, h = self.size
        if self.heard:
            stamp = self.far()
            self.info[v].publish(self._info(v, w, h, stamp, self.frame(v)))
            return self.img[v], ma.array_to_image(self.rng.integers(0, 255, (h, w, 3), dtype=np.uint8), "rgb8",
                                                  stamp_ns=stamp, frame_id=self.frame(v))
        mine = None
        for u in range(self.views):
            self.unique += 1
            stamp = 5 * 10**9 + self.unique * 1_000_000 + u
            self.info[u].publish(self._info(u, w, h, stamp, self.frame(u)))
            msg = ma.array_to_image(self.rng.integers(0, 255, (h, w, 3), dtype=np.uint8), "rgb8", stamp_ns=stamp,
                                    frame_id=self.frame(u))
            if u == v:
                mine = msg
            else:
                self.img[u].publish(msg)
        return self.img[v], mine

    def k_image_other_frame(self, v):
        w, h = self.size
        return self.img[v], ma.array_to_image(self.rng.integers(0, 255, (h, w, 3), dtype=np.uint8), "rgb8",
                                              stamp_ns=self.near(), frame_id=self.frame((v + 1) % self.views))

    def k_image_malformed(self, v):
        w, h = self.size
        msg = ma.array_to_image(np.zeros((h, w, 3), np.uint8), "rgb8", stamp_ns=self.near(), frame_id=self.frame(v))
        pick = self.unique % 5
        if pick == 0:
            msg.data = msg.data[: len(msg.data) // 2]            # truncated
        elif pick == 1:
            msg.encoding = "yuv422_fuzz"                          # unknown encoding
        elif pick == 2:
            msg.encoding = "rgba8"                                # known, not segmented (and data too short)
        elif pick == 3:
            msg = Image(header=msg.header, height=0, width=0, encoding="rgb8", step=0)   # empty
        else:
            msg = ma.array_to_image(np.zeros((960, 1280, 3), np.uint8), "rgb8", stamp_ns=self.near(),
                                    frame_id=self.frame(v))        # huge
        return self.img[v], msg

    # -- camera infos --------------------------------------------------------------------------------
    def _info(self, v, w, h, stamp, frame):
        intr = ma.Intrinsics(K=np.array([[250.0, 0, w / 2], [0, 250.0, h / 2], [0, 0, 1]]), D=np.zeros(5),
                             P=np.array([[250.0, 0, w / 2, 0], [0, 250.0, h / 2, 0], [0, 0, 1, 0]]), R=np.eye(3),
                             width=w, height=h)
        self.own_info_stamps.add(stamp)
        return ma.intrinsics_to_camera_info(intr, stamp_ns=stamp, frame_id=frame)

    def k_info_7x3(self, v):
        return self.info[v], self._info(v, 7, 3, self.near(), self.frame(v))

    def k_info_other_k_far_stamp(self, v):
        return self.info[v], self._info(v, *self.size, self.far(), self.frame(v))

    def k_info_other_frame(self, v):
        return self.info[v], self._info(v, *self.size, self.near(), "fuzz_optical_frame")

    def k_info_malformed(self, v):
        msg = self._info(v, *self.size, self.near(), self.frame(v))
        pick = self.unique % 3
        if pick == 0:
            msg.k = np.zeros(9)
        elif pick == 1:
            msg.d = [float("nan")] * 5
        else:
            msg.distortion_model = "fisheye_fuzz"
        return self.info[v], msg

    # -- extrinsics ----------------------------------------------------------------------------------
    def _tf(self, parent, child, *, q=(0.0, 0.0, 0.0, 1.0), t=(3.0, -2.0, 1.0)):
        tf = TransformStamped()
        tf.header = ma.make_header(self.near(), parent)
        tf.child_frame_id = child
        tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z = map(float, t)
        r = tf.transform.rotation
        r.x, r.y, r.z, r.w = map(float, q)
        return tf

    def k_extrinsics_other_parent(self, v):
        return self.extr[v], self._tf("map", self.frame(v))

    def k_extrinsics_other_child(self, v):
        return self.extr[v], self._tf("world", ["fuzz_optical_frame", "base_link"][self.unique % 2])

    def k_extrinsics_malformed(self, v):
        if self.unique % 2:
            return self.extr[v], self._tf("world", self.frame(v), q=(0.0, 0.0, 0.0, 0.0))
        return self.extr[v], self._tf("world", self.frame(v), t=(float("nan"), 0.0, 0.0))

    # -- masks ---------------------------------------------------------------------------------------
    def k_mask_7x3(self, v):
        return self.mask[v], ma.array_to_image(np.full((3, 7), 255, np.uint8), "mono8", stamp_ns=self.near(),
                                               frame_id=self.frame(v))

    def k_mask_far_stamp(self, v):
        w, h = self.size
        return self.mask[v], ma.array_to_image(np.full((h, w), 255, np.uint8), "mono8", stamp_ns=self.far(),
                                               frame_id=self.frame(v))

    def k_mask_other_frame(self, v):
        w, h = self.size
        return self.mask[v], ma.array_to_image(np.full((h, w), 255, np.uint8), "mono8", stamp_ns=self.near(),
                                               frame_id="fuzz_optical_frame")

    def k_mask_malformed(self, v):
        w, h = self.size
        if self.unique % 2:
            return self.mask[v], ma.array_to_image(np.zeros((h, w, 3), np.uint8), "rgb8", stamp_ns=self.near(),
                                                   frame_id=self.frame(v))
        msg = ma.array_to_image(np.zeros((h, w), np.uint8), "mono8", stamp_ns=self.near(), frame_id=self.frame(v))
        msg.data = msg.data[:-5]
        return self.mask[v], msg

    # -- predictions ---------------------------------------------------------------------------------
    def _pred(self, names, q, stamp):
        msg = JointState(header=ma.make_header(stamp))
        msg.name = list(names)
        msg.position = [float(x) for x in q]
        return msg

    def k_prediction_nan(self, v):
        q = np.zeros(len(self.names))
        q[self.unique % len(q)] = float("nan")
        return self.pred, self._pred(self.names, q, self.last_real_ns + 33_333_333)

    def k_prediction_wrong_names(self, v):
        names = [f"fuzz_joint_{i}" for i in range(len(self.names))]
        return self.pred, self._pred(names, np.zeros(len(names)), self.last_real_ns + 33_333_333)

    def k_prediction_wrong_length(self, v):
        msg = self._pred(self.names, np.zeros(len(self.names)), self.last_real_ns + 33_333_333)
        msg.position = msg.position[: len(msg.position) // 2]
        return self.pred, msg

    def k_prediction_far_stamp(self, v):
        q = self.rng.normal(0.0, 0.3, len(self.names))
        return self.pred, self._pred(self.names, q, self.far())

    # -- keypoints -----------------------------------------------------------------------------------
    def _kp(self, v, n, stamp, *, bad=None):
        msg = PolygonStamped(header=ma.make_header(stamp, self.frame(v)))
        pts = [Point32(x=float(10 + i), y=float(20 + i), z=0.9) for i in range(n)]
        if bad == "nan":
            pts[self.unique % n].x = float("nan")
        elif bad == "confidence":
            pts[self.unique % n].z = 1.5
        msg.polygon.points = pts
        self.unique += 1
        return self.kp[v], msg

    def k_keypoints_wrong_count(self, v):
        return self._kp(v, 17, self.last_real_ns + 33_333_333)

    def k_keypoints_nan(self, v):
        return self._kp(v, 33, self.last_real_ns + 33_333_333, bad="nan")

    def k_keypoints_confidence_above_one(self, v):
        return self._kp(v, 33, self.last_real_ns + 33_333_333, bad="confidence")

    def k_keypoints_far_stamp(self, v):
        return self._kp(v, 33, self.far())

    def k_keypoints_skipped_far_stamp(self, v):
        return self.kp_skipped[v], ma.make_header(self.far(), self.frame(v))

    # ----------------------------------------------------------------------------------------------
    def _send(self) -> None:
        kind = self.kinds[self.tick % len(self.kinds)]
        self.tick += 1
        v = int(self.rng.integers(self.views))
        pub, msg = getattr(self, kind)(v)
        pub.publish(msg)
        self.sent[kind[2:]] += 1


def main() -> None:
    views, rate, seed = int(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
    rclpy.init()
    node = Fuzzer(views, rate, seed, sys.argv[4] if len(sys.argv) > 4 else "")
    signal.signal(signal.SIGTERM, lambda *a: rclpy.try_shutdown())
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        print("total " + " ".join(f"{k}={n}" for k, n in node.sent.items()), flush=True)
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
