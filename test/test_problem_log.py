"""ProblemLog (nodes/common.py): rate-limited lines, WARN/ERROR for problems, INFO for expected events."""
from isa_mocap_ros.nodes.common import ProblemLog


class _Logger:
    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(("INFO", text))

    def warn(self, text):
        self.lines.append(("WARN", text))

    def error(self, text):
        self.lines.append(("ERROR", text))


class _Node:
    def __init__(self):
        self.logger = _Logger()

    def get_logger(self):
        return self.logger


def test_problems_are_counted_and_rate_limited_events_apart():
    node = _Node()
    log = ProblemLog(node, period_s=60.0)
    for _ in range(3):
        log.report("mask0:size", "cam0: mask dropped")
    log.report("calib", "frame set lost", level="error")
    for _ in range(5):
        log.event("note:view 0", "view 0: empty mask (nobody in view)")
    assert log.counts == {"mask0:size": 3, "calib": 1} and log.total == 4
    assert log.events == {"note:view 0": 5}          # expected events are no bad inputs
    assert node.logger.lines == [("WARN", "cam0: mask dropped"), ("ERROR", "frame set lost"),
                                 ("INFO", "view 0: empty mask (nobody in view)")]
    log2 = ProblemLog(_Node(), period_s=0.0)
    log2.report("k", "again")
    log2.report("k", "again")
    assert log2._logger.lines[-1] == ("WARN", "again (2 so far)")


def test_a_real_rclpy_logger_takes_warn_and_error_from_one_problem_log(ros_domain):
    # rclpy raises ValueError when one call site logs at two severities; that killed the estimator's
    # worker thread the first time a frame set was lost after a warned-about input
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_domain)
    try:
        node = rclpy.create_node("problem_log_test", context=ctx)
        log = ProblemLog(node, period_s=0.0)
        log.report("mask0:stamp", "cam0: mask dropped")
        log.report("calib", "frame set lost", level="error")
        log.report("mask0:stamp", "cam0: mask dropped")
        assert log.counts == {"mask0:stamp": 2, "calib": 1}
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
