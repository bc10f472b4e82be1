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
