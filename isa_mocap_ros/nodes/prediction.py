"""Prediction node: the estimates in, the pose prediction for the NEXT frame out.

Run alone (relative topic names; the network runs it in ``/mocap``)::

    prediction_node --ros-args -r __ns:=/mocap -p predictor:=ar -p order:=1
    python -m isa_mocap_ros.nodes.prediction --ros-args -r __ns:=/mocap --params-file config/pipeline.yaml

Subscribes ``joint_states`` (the estimator's estimates, reliable depth 10) and publishes
``prediction/joint_states`` (reliable depth 10) after every accepted estimate.

Stamp convention: the prediction made from the estimate of frame ``k`` (stamp ``t_k``) is the
prediction FOR frame ``k + 1`` and carries the stamp ``t_k + frame_period_s``; the estimator looks
the prediction of a frame up by that stamp (within half a period). Estimates more than one period
apart (frame sets the estimator dropped) teach the predictor the motion per period
(:mod:`isa_mocap_ros.tracking.predict`, "Gaps"). Joint names are published as
received (the order of the first estimate); ``header.frame_id`` is copied.

The estimates carry the root rotation as roll/pitch/yaw (``isa_mocap_ros.body.pose_to_joint_state``);
the node turns them back into pose vectors, predicts with the configured predictor
(:mod:`isa_mocap_ros.tracking.predict`: ``ar`` = autoregression on twists with damping, ISA 13.28;
``constant_pose``; ``constant_velocity``) and publishes the prediction the same way
(:class:`isa_mocap_ros.tracking.published.PublishedPredictor`, the exact arithmetic of the
offline tracker). The body model is chosen by the number of joints of the first estimate (18, 28
or 39) unless ``model_dof`` is set.

Faults, each dropped and counted with one rate-limited log line: a non-finite position, a name list
missing one of the reference joints or disagreeing with the positions, an estimate whose stamp is
not newer than the last accepted one (by at most ``restart_after_s``), an estimate far in time from
the stream (more than ``restart_after_s`` back or ``max_stamp_gap_s`` ahead). A far estimate that the
next one continues (a replayed or looped bag starting again) starts a new sequence: the history is
cleared and that next estimate accepted (:class:`isa_mocap_ros.intake.StreamJumps`), so one stray
message far in time neither resets nor derails the predictor. Later estimates may list the joints in
another order; they are reordered by name.
"""
from __future__ import annotations

import sys

from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

import msg_adapters as ma
from isa_mocap_ros.body import make_model
from isa_mocap_ros.intake import FAR_RULE, StreamJumps
from isa_mocap_ros.nodes import qos
from isa_mocap_ros.nodes.common import QOS_OVERRIDES, ProblemLog, declare, run_node
from isa_mocap_ros.tracking.predict import (ArPredictor, ConstantPosePredictor, ConstantVelocityPredictor,
                                            PredictionError, periods_between)
from isa_mocap_ros.tracking.published import PublishedPredictor

__all__ = ["PredictionNode", "PREDICTORS", "make_predictor", "main"]

PREDICTORS = ("ar", "constant_pose", "constant_velocity")


def make_predictor(name: str, *, order: int = 2, damping=None):
    """The predictor called ``name`` (``ar`` takes ``order`` and ``damping``)."""
    if name == "ar":
        return ArPredictor(order=order, damping=damping)
    if name == "constant_pose":
        return ConstantPosePredictor()
    if name == "constant_velocity":
        return ConstantVelocityPredictor()
    raise PredictionError(f"predictor: expected one of {', '.join(PREDICTORS)}, received {name!r}")


class PredictionNode(Node):
    """Thin node over :class:`PublishedPredictor` (see the module docstring)."""

    def __init__(self, **kwargs) -> None:
        super().__init__("prediction", **kwargs)
        self.predictor_name = declare(self, "predictor", "ar", "ar (ISA 13.28), constant_pose or constant_velocity")
        self.order = declare(self, "order", 1, "ar: number of past motions used", lo=1, hi=50)
        damping = declare(self, "damping", Parameter.Type.DOUBLE_ARRAY,
                          "ar: weights of the past motions, oldest first, `order` values (unset = "
                          "proportional to recency)")
        self.damping = None if not damping else [float(x) for x in damping]
        self.frame_period_s = declare(self, "frame_period_s", 1.0 / 30.0,
                                      "the prediction's stamp = estimate stamp + this (the next frame)",
                                      lo=1e-6, hi=3600.0)
        self.model_dof = declare(self, "model_dof", 0, "body model 18, 28 or 39 (0 = from the first estimate's "
                                 "joint count)", lo=0, hi=39)
        self.restart_after_s = declare(self, "restart_after_s", 1.0, "a stamp this much older than the last, "
                                       "followed by the next one, starts a new sequence (bag replayed); smaller "
                                       "steps back are dropped", lo=0.0, hi=1e9)
        gap_s = declare(self, "max_stamp_gap_s", 5.0, "an estimate this far ahead of the last is dropped unless the "
                        "next one follows it (then a new sequence; 0 = no limit)", lo=0.0, hi=1e9)
        self.jumps = StreamJumps(back_ns=int(self.restart_after_s * 1e9), ahead_ns=int(gap_s * 1e9))
        if self.model_dof not in (0, 18, 28, 39):
            raise ValueError(f"model_dof: expected 0, 18, 28 or 39, received {self.model_dof}")
        make_predictor(self.predictor_name, order=self.order, damping=self.damping)  # validate now
        self.problems = ProblemLog(self)
        self.pub = self.create_publisher(JointState, "prediction/joint_states", qos.RELIABLE,
                                         qos_overriding_options=QOS_OVERRIDES)
        self.create_subscription(JointState, "joint_states", self._on_estimate, qos.RELIABLE,
                                 qos_overriding_options=QOS_OVERRIDES)
        self.names: list[str] | None = None   # reference joint order (the first estimate's)
        self.predictor: PublishedPredictor | None = None
        self._perm = None                      # reference order -> model.dof_names order
        self.last_stamp_ns: int | None = None
        self.published = 0
        self.restarts = 0
        self.get_logger().info(f"prediction: {self.predictor_name}"
                               + (f" order {self.order}" if self.predictor_name == "ar" else "")
                               + f", stamps + {self.frame_period_s:.6f} s")

    # -- first message: reference names and model ----------------------------------------------
    def _setup(self, names: list[str]) -> None:
        dof = self.model_dof or len(names)
        if dof not in (18, 28, 39):
            raise ValueError(f"JointState.name: expected the joints of an 18, 28 or 39 DOF body model, "
                             f"received {len(names)} joints")
        model = make_model(dof)
        missing = [n for n in model.dof_names if n not in names]
        if missing or len(names) != dof:
            raise ValueError(f"JointState.name: expected the {dof} joints of model {model.name!r}"
                             + (f"; missing {missing[:3]}" if missing else f", received {len(names)} joints"))
        index = {n: i for i, n in enumerate(names)}
        self._perm = [index[n] for n in model.dof_names]
        self.names = list(names)
        self.model = model
        self.predictor = PublishedPredictor(model, make_predictor(self.predictor_name, order=self.order,
                                                                  damping=self.damping))

    # -- callback ------------------------------------------------------------------------------
    def _on_estimate(self, msg: JointState) -> None:
        try:
            stamp = ma.stamp_to_ns(msg.header)
            names, q = ma.joint_state_to_arrays(msg, self.names)
        except ma.AdapterError as exc:  # one rate-limited line per offending field (position, name, ...)
            self.problems.report(exc.field.split(" of ")[0], f"joint_states dropped: {exc}")
            return
        if self.predictor is None:
            try:
                self._setup(names)
            except ValueError as exc:
                self.problems.report("names", f"joint_states dropped: {exc}")
                return
        kind, why = self.jumps.decide(stamp)
        if kind in ("order", "far"):
            self.problems.report("order" if kind == "order" else "stamp",
                                 f"joint_states dropped: {why}" + (f"; {FAR_RULE}" if kind == "far" else ""))
            return
        if kind == "restart":
            self.restarts += 1
            self.predictor.reset()
            self.last_stamp_ns = None
            self.get_logger().info(f"joint_states: {why}: a new sequence; history cleared")
        x_model = q[self._perm]
        # frame periods since the last estimate: more than 1 when the estimator dropped frame sets,
        # so the motion is learnt per period (the prediction is still for the next frame)
        try:
            self.predictor.update_from_message(x_model, periods_between(self.last_stamp_ns, stamp, self.frame_period_s))
            pred = self.predictor.message()
        except (PredictionError, ValueError) as exc:
            self.problems.report("predict", f"joint_states dropped: {exc}")
            return
        self.last_stamp_ns = stamp
        out = q.copy()
        out[self._perm] = pred
        pred_msg = ma.arrays_to_joint_state(self.names, out, stamp_ns=stamp + int(round(self.frame_period_s * 1e9)),
                                            frame_id=msg.header.frame_id)
        # counted first: a Ctrl-C arriving right after publish() would otherwise lose the count of a
        # message the subscribers already have (seen once in CI: "7 published" after 8 arrived)
        self.published += 1
        self.pub.publish(pred_msg)

    def close(self) -> None:
        """Log how many predictions went out."""
        text = (f"prediction: {self.published} predictions published, {self.problems.total} estimates dropped, "
                f"{self.restarts} restarts")
        if self.context.ok():
            self.get_logger().info(text)
        else:
            print(text, file=sys.stderr, flush=True)


def main(args: list[str] | None = None) -> int:
    """Console script ``prediction_node``."""
    return run_node(PredictionNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
