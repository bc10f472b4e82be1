"""``python -m isa_mocap_ros.cli.compose SPECS_JSON``: several nodes in one process, on one executor.

The process that ``isa-mocap run --single-process`` starts for segmentation, prediction and estimator
(and keypoints when on): each node is built with its own ``--ros-args`` (name, namespace, parameter
files and values, remaps, as :class:`~isa_mocap_ros.launcher.NodeSpec` gives them) and all are added to
one executor (the ``executor`` parameter's kind, ``events`` by default: messages dispatched from C++).
Messages between them still go through rmw (intra-process delivery is not exposed by rclpy), but
there is one process, one executor and one Python interpreter instead of three or four: no
per-process executor spinning, and one copy of the imports and compiled kernels in memory. The
estimator's tracker keeps its own worker thread, so a segmentation callback never waits for a step.
"""
from __future__ import annotations

import json
import os
import sys

from isa_mocap_ros.launcher import LaunchError, NodeSpec


def run_composed(specs: list[NodeSpec]) -> int:
    """Build every node of ``specs`` in this process, spin them on one executor until shut down."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")   # as run_node: idle OpenMP workers sleep
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from isa_mocap_ros.cli.launch import node_class
    from isa_mocap_ros.nodes.common import close_nodes, declare_executor, make_executor, spin_until_shutdown

    rclpy.init()
    nodes = []
    code = 0
    try:
        kinds = []
        for spec in specs:
            node = node_class(spec)(cli_args=spec.ros_args())
            nodes.append(node)
            kinds.append(declare_executor(node))
        executor = make_executor(kinds[-1] if kinds else "events")
        for node, spec in zip(nodes, specs):
            executor.add_node(node)
            print(f"[compose] {spec.name} in-process ({spec.module})", flush=True)
        spin_until_shutdown(executor, nodes[0].context if nodes else None)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as exc:   # bad parameters or files: one line, exit code 2 (as run_node)
        print(f"compose: {exc}", file=sys.stderr)
        code = 2
    finally:
        close_nodes(nodes)
    return code


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:
        specs = [NodeSpec.from_json(d) for d in json.loads(argv[0])] if argv else []
    except (ValueError, TypeError, json.JSONDecodeError) as exc:
        print(f"compose: expected one JSON list of node specs, got {argv[:1]!r} ({exc})", file=sys.stderr)
        return 2
    if not specs:
        print("compose: no nodes to run", file=sys.stderr)
        return 2
    try:
        return run_composed(specs)
    except LaunchError as exc:
        print(f"compose: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
