"""``isa-mocap launch [LAUNCH_FILE] [name:=value ...]``: start the node network.

Each node runs as its own process (``--single-process``: all in one executor), with
``--ros-args --params-file`` from the launch file; SIGINT/SIGTERM are forwarded, nodes marked
``respawn`` are restarted after a crash, and shutdown escalates SIGINT -> SIGTERM -> SIGKILL.
The default launch file is the package's ``launch/mocap.launch.yaml``.
"""
from __future__ import annotations

import argparse
import importlib
import inspect
import signal
import sys

from isa_mocap_ros.launcher import LaunchError, NodeSpec, Supervisor, load_launch_file
from isa_mocap_ros.resources import resource_dir
from isa_mocap_ros.rosenv import ros_env


def register(sub) -> None:
    p = sub.add_parser("launch", help="start the node network from a YAML launch file")
    p.add_argument("launch_file", nargs="?", default=None,
                   help="YAML launch file (default: the package's launch/mocap.launch.yaml)")
    p.add_argument("arguments", nargs="*", metavar="NAME:=VALUE", help="launch arguments")
    p.add_argument("--single-process", action="store_true", help="run every node in one process and executor")
    p.add_argument("--respawn", action="store_true", help="respawn every node that crashes")
    p.add_argument("--list", action="store_true", help="print the commands and exit")
    p.set_defaults(func=run)


def _parse_arguments(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            raise LaunchError(f"launch arguments look like name:=value, got {item!r}")
        out[name] = value
    return out


def node_class(spec: NodeSpec):
    """The rclpy Node subclass defined in the spec's module."""
    from rclpy.node import Node
    module = importlib.import_module(spec.module)
    for _, obj in inspect.getmembers(module, inspect.isclass):
        if issubclass(obj, Node) and obj is not Node and obj.__module__ == module.__name__:
            return obj
    raise LaunchError(f"{spec.module} defines no rclpy Node subclass")


def run_single_process(specs: list[NodeSpec]) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor

    from isa_mocap_ros.nodes.common import close_nodes, spin_until_shutdown

    rclpy.init()
    nodes = []
    executor = MultiThreadedExecutor()
    try:
        for spec in specs:
            node = node_class(spec)(cli_args=spec.ros_args())
            nodes.append(node)
            executor.add_node(node)
            print(f"[launch] {spec.name} started in-process ({spec.module})", flush=True)
        spin_until_shutdown(executor, nodes[0].context if nodes else None)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        close_nodes(nodes)
    return 0


def run(args: argparse.Namespace) -> int:
    path = args.launch_file or str(resource_dir("launch") / "mocap.launch.yaml")
    try:
        specs = load_launch_file(path, _parse_arguments(args.arguments))
    except LaunchError as exc:
        print(f"isa-mocap launch: {exc}", file=sys.stderr)
        return 2
    if args.respawn:
        specs = [NodeSpec(**{**s.__dict__, "respawn": True}) for s in specs]
    if args.list:
        for s in specs:
            print(" ".join(s.command()))
        return 0
    if args.single_process:
        return run_single_process(specs)
    env = ros_env(keep_caller_domain=True)
    print(f"[launch] {len(specs)} nodes, ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}", flush=True)
    sup = Supervisor(specs, env=env)

    def on_signal(signum, _frame) -> None:
        print(f"[launch] {signal.Signals(signum).name}: shutting down", flush=True)
        sup.stop()
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    return sup.run()
