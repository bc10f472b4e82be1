"""``isa-mocap launch [LAUNCH_FILE] [name:=value ...]``: start the node network.

Each node runs as its own process (``--single-process``: all in one executor), with
``--ros-args --params-file`` from the launch file; SIGINT/SIGTERM are forwarded, nodes marked
``respawn`` are restarted after a crash, and shutdown escalates SIGINT -> SIGTERM -> SIGKILL.
The default launch file is the package's ``launch/mocap.launch.yaml``.

Frame period: the camera node stamps its frame sets ``1 / fps`` apart (its timer), and the prediction and
estimator nodes match predictions to frames by ``frame_period_s``. When the network has a camera node,
``launch`` hands both nodes ``frame_period_s = 1 / fps`` of the camera (its parameter as the launch file and
its parameter files give it, else the node's default 30), as ``isa-mocap run`` hands them a bag's period;
a ``frame_period_s`` set on a node in the launch file itself is kept.
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


_PERIOD_NODES = ("prediction_node", "estimator_node")
_CAMERA_DEFAULT_FPS = 30.0       # isa_mocap_ros.nodes.camera's fps default


def _file_parameter(files, node_name: str, namespace: str, key: str):
    """The value of parameter ``key`` for node ``node_name`` in ROS parameter files (later files win; keys
    ``name``, ``/ns/name``, ``/**``, ``ns/name``), or None."""
    import yaml

    full = f"{namespace.rstrip('/')}/{node_name}" if namespace else f"/{node_name}"
    value = None
    for f in files:
        try:
            with open(f) as fh:
                doc = yaml.safe_load(fh) or {}
        except (OSError, yaml.YAMLError):
            continue                    # the node reports an unreadable file itself
        for k in ("/**", node_name, full, full.lstrip("/")):
            block = doc.get(k) if isinstance(doc, dict) else None
            params = block.get("ros__parameters") if isinstance(block, dict) else None
            if isinstance(params, dict) and key in params:
                value = params[key]
    return value


def _parameter(spec: NodeSpec, key: str):
    given = dict(spec.params)
    return given[key] if key in given else _file_parameter(spec.params_files, spec.name, spec.namespace, key)


def with_camera_frame_period(specs: list[NodeSpec]) -> tuple[list[NodeSpec], str | None]:
    """``specs`` with ``frame_period_s = 1 / fps`` of the camera node given to the prediction and estimator nodes
    (module docstring), and a line saying so (None when there is no camera node or nothing to change)."""
    flat = [m for s in specs for m in (s.members or (s,))]
    cams = [s for s in flat if s.exec == "camera_node"]
    if not cams:
        return specs, None
    fps = _parameter(cams[0], "fps")
    try:
        fps = float(_CAMERA_DEFAULT_FPS if fps is None else fps)
    except (TypeError, ValueError):
        return specs, None              # the camera node refuses a bad fps itself
    if not fps > 0:
        return specs, None
    period = 1.0 / fps
    changed = []

    def fix(s: NodeSpec) -> NodeSpec:
        if s.members:
            return NodeSpec(**{**s.__dict__, "members": tuple(fix(m) for m in s.members)})
        if s.exec not in _PERIOD_NODES or "frame_period_s" in dict(s.params):
            return s
        old = _file_parameter(s.params_files, s.name, s.namespace, "frame_period_s")
        if old is not None and abs(float(old) - period) < 1e-9:
            return s
        changed.append(f"{s.name} (was {float(old):.6f})" if old is not None else s.name)
        return NodeSpec(**{**s.__dict__, "params": tuple(s.params) + (("frame_period_s", repr(period)),)})

    out = [fix(s) for s in specs]
    if not changed:
        return specs, None
    return out, (f"[launch] camera at {fps:g} fps: frame_period_s = {period:.6f} s for {', '.join(changed)}")


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
    specs, line = with_camera_frame_period(specs)
    if line:
        print(line, flush=True)
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
