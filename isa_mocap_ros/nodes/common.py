"""Shared plumbing for the thin rclpy nodes: Jazzy ``main()``, parameter descriptors, QoS, logging.

Every node of the package:

* declares its parameters with :func:`declare` (description + range), reads them once into a
  frozen config dataclass for the core;
* exposes ``QoSOverridingOptions.with_default_policies()`` on its publishers/subscriptions, so
  ``qos_overrides./topic.publisher.reliability`` etc. work from a params file;
* reports bad input with :class:`ProblemLog`: one clear line per problem kind, rate-limited, and
  a counter for ``/diagnostics``;
* runs through :func:`run_node` (the Jazzy ``main()`` shape of DESIGN §3), spun by the executor its
  ``executor`` parameter names (:func:`make_executor`, :func:`spin_until_shutdown`).
"""
from __future__ import annotations

import dataclasses
import os
import sys
import time
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Mapping

import rclpy
import yaml
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos_overriding_options import QoSOverridingOptions

import msg_adapters as ma
from isa_mocap_ros.intake import Setting

QOS_OVERRIDES = QoSOverridingOptions.with_default_policies()


@contextmanager
def one_numba_thread() -> Iterator[None]:
    """Run the compiled (numba ``parallel=True``) kernels called inside on the calling thread only.

    For the one-pose kernel calls of a node (the skeleton marker, an overlay): a parallel region
    wakes numba's OpenMP workers, which then spin; at one pose that costs ~4 ms of the caller's CPU
    and as much again in the workers, for ~10 µs of work. The thread count is numba's per-thread
    setting, so a tracker stepping on another thread is not affected, and each pose is computed by
    the same code, so the results are identical.
    """
    import numba

    n = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(n)


def declare(node: Node, name: str, default: Any, description: str, *, lo: float | None = None,
            hi: float | None = None, read_only: bool = False) -> Any:
    """Declare one parameter with a descriptor (and a range for numbers); return its value."""
    d = ParameterDescriptor(description=description, read_only=read_only)
    if lo is not None and isinstance(default, bool):
        pass
    elif lo is not None and isinstance(default, int):
        d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
    elif lo is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    try:
        return node.declare_parameter(name, default, d).value
    except InvalidParameterTypeException:
        # one line (run_node prints ValueErrors) instead of rclpy's traceback; YAML reads unquoted
        # on/off/yes/no/true/false as booleans, the usual way a string parameter receives a bool
        given = getattr(getattr(node, "_parameter_overrides", {}).get(name), "value", None)
        hint = (f' (YAML reads unquoted on/off/yes/no as booleans: quote the value, e.g. {name}: "off")'
                if isinstance(default, str) and isinstance(given, bool) else "")
        raise ValueError(f"parameter {name}: expected a {type(default).__name__}, received "
                         f"{type(given).__name__} {given!r}{hint}") from None


def config_leaves(cls) -> list[dataclasses.Field]:
    """The settings of the frozen config dataclass ``cls`` in order: its fields, with each field whose default
    is itself a config dataclass (a group, as :class:`~isa_mocap_ros.tracking.config.TrackerConfig`'s)
    replaced by that group's settings."""
    out = []
    for f in dataclasses.fields(cls):
        factory = f.default_factory
        if factory is not dataclasses.MISSING and isinstance(factory, type) and dataclasses.is_dataclass(factory):
            out.extend(config_leaves(factory))
        else:
            out.append(f)
    return out


def declare_config(node: Node, cls, docs: Mapping[str, str], *, skip: tuple = ()) -> dict[str, Any]:
    """Declare one parameter per setting of the frozen config dataclass ``cls`` (:func:`config_leaves`:
    a group's settings are declared by their own names; name, default and description from the dataclass:
    ``docs`` maps each setting to its one-line doc), except the settings in ``skip``; return the values by
    setting name (``cls(**values)`` for a flat class, ``TrackerConfig.from_flat(**values)``). The dataclass
    checks them (its error names the setting). A tuple setting is a list parameter, read back as a tuple; a
    mapping setting is a YAML/JSON string parameter (``"{}"`` = empty), read back as a dict."""
    values: dict[str, Any] = {}
    for f in config_leaves(cls):
        if f.name in skip:
            continue
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        if isinstance(default, Mapping):
            text = declare(node, f.name, yaml.safe_dump(dict(default), default_flow_style=True).strip(),
                           f"{docs[f.name]} (YAML/JSON mapping)")
            try:
                value = yaml.safe_load(text) or {}
            except yaml.YAMLError as exc:
                raise ValueError(f"parameter {f.name}: expected a YAML/JSON mapping, received {text!r} ({exc})") \
                    from None
            if not isinstance(value, dict):
                raise ValueError(f"parameter {f.name}: expected a YAML/JSON mapping, received {text!r}")
        elif isinstance(default, tuple):
            value = tuple(declare(node, f.name, list(default), docs[f.name]))
        else:
            value = declare(node, f.name, default, docs[f.name])
        values[f.name] = value
    return values


class ProblemLog:
    """Rate-limited logging of a node's input problems and expected events, with per-kind counters.

    ``report(kind, text)`` logs ``text`` at most once every ``period_s`` per ``kind`` (the first time
    always) and counts every occurrence in ``counts`` (the node's ``bad_inputs`` diagnostics): WARN for
    a rejected input (it needs attention), ``level="error"`` for data lost (a frame set that could not be
    tracked). ``event(kind, text)`` is the same at INFO for what a normal run does (the empty masks of
    the background-learning frames, the automatic initialization, the heading check), counted apart in
    ``events`` and never as a bad input.
    """

    def __init__(self, node: Node, *, period_s: float = 5.0) -> None:
        self._logger = node.get_logger()
        self._context = getattr(node, "context", None)     # None: a stand-in node (tests)
        self._period_s = period_s
        self._last: dict[str, float] = {}
        self.counts: dict[str, int] = {}
        self.events: dict[str, int] = {}

    def _due(self, kind: str) -> bool:
        # once the context is shut down (Ctrl-C: rclpy's signal handler does it on a thread of its own) a
        # log line cannot reach /rosout and rcl prints an error instead: count, do not log
        if self._context is not None and not self._context.ok():
            return False
        now = time.monotonic()
        if now - self._last.get(kind, -1e18) >= self._period_s:
            self._last[kind] = now
            return True
        return False

    def report(self, kind: str, text: str, *, level: str = "warn") -> None:
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if self._due(kind):
            n = self.counts[kind]
            text += f" ({n} so far)" if n > 1 else ""
            # one call site per severity: rclpy keys its per-call-site logging context by the caller's
            # line and raises ValueError when one site logs at two severities (it killed the worker)
            if level == "error":
                self._logger.error(text)
            else:
                self._logger.warn(text)

    def event(self, kind: str, text: str) -> None:
        self.events[kind] = self.events.get(kind, 0) + 1
        if self._due("event:" + kind):
            n = self.events[kind]
            self._logger.info(text + (f" ({n} so far)" if n > 1 else ""))

    @property
    def total(self) -> int:
        return sum(self.counts.values())


def camera_info_callback(v: int, problems: ProblemLog, problem_key: Callable[[Exception], str],
                         take: Callable[[int, Setting, Any], None]) -> Callable[[Any], None]:
    """The ``cam<v>/camera_info`` callback of the nodes that gate images on it (segmentation, keypoints,
    estimator): ``take(stamp_ns, Setting(frame_id, width, height), intrinsics)`` per good message; a bad one is
    reported under ``problem_key(exc)`` (an ``msg_adapters.AdapterError``, naming the field) and dropped. A camera
    sends the same camera_info with every image, so the intrinsics are converted again only when
    ``ma.camera_info_key`` changes (~10 µs for the key instead of ~0.2 ms; the same intrinsics bit for bit)."""
    last = [None, None]         # key and intrinsics of the last good message

    def cb(msg) -> None:
        try:
            stamp = ma.stamp_to_ns(msg.header)
            key = ma.camera_info_key(msg)
            if key is not None and key == last[0]:
                intr = last[1]
            else:
                intr = ma.camera_info_to_intrinsics(msg)
                last[:] = key, intr
        except ma.AdapterError as exc:
            problems.report(problem_key(exc), f"cam{v}/camera_info dropped: {exc}")
            return
        take(stamp, Setting(msg.header.frame_id, intr.width, intr.height), intr)
    return cb


def publishers_on(node: Node, topic: str) -> int:
    """How many publishers ``topic`` (a relative name is resolved in the node's namespace) has in the graph; 0 once
    the node's context is shut down. A node's worker thread that asks the graph while it waits (the estimator in
    lockstep: for a prediction node, a keypoint node) would otherwise die at Ctrl-C with rcl's "rcl node's context
    is invalid" (rclpy's signal handler shuts the context down on a thread of its own)."""
    try:
        return node.count_publishers(node.resolve_topic_name(topic))
    except Exception:
        if node.context.ok():
            raise
        return 0


def log_closing(node: Node, text: str) -> None:
    """Log a node's closing line: through its logger while the context is up, else on stderr.

    After Ctrl-C the rclpy signal handler has already shut the context down when ``close()`` runs;
    the logger then still tries to publish to ``/rosout`` and prints "Failed to publish log message
    to rosout: publisher's context is invalid" beside the line.
    """
    if node.context.ok():
        node.get_logger().info(text)
    else:
        print(f"[INFO] [{node.get_name()}]: {text}", file=sys.stderr, flush=True)


EXECUTORS = ("events", "single_threaded")
EXECUTOR_HELP = ("events: rclpy's C++ EventsExecutor (rclpy.experimental; ~0.5 ms less Python per message), "
                 "single_threaded: rclpy's SingleThreadedExecutor")


def declare_frame_sync(node: Node, n_views: int) -> dict[str, Any]:
    """Declare the frame-set matching parameters (``sync``, ``queue_size``, ``slop_s``, ``view_timeout_s``,
    ``min_views``) and return :class:`~isa_mocap_ros.tracking.sync.FrameSynchronizer`'s keyword arguments. The
    estimator and the keypoint node both declare them here, so the two form the same frame sets."""
    sync = declare(node, "sync", "exact", "frame-set matching: exact or approximate")
    queue = declare(node, "queue_size", 10, "stamps kept per view while synchronizing", lo=1, hi=1000)
    slop_s = declare(node, "slop_s", 0.01, "approximate sync window, seconds", lo=0.0, hi=10.0)
    view_timeout_s = declare(node, "view_timeout_s", 1.0, "emit a partial frame set after this wait (0 = never)",
                             lo=0.0, hi=60.0)
    min_views = declare(node, "min_views", 2, "views a partial frame set needs", lo=1, hi=64)
    if sync not in ("exact", "approximate"):
        raise ValueError(f"sync must be 'exact' or 'approximate', got {sync!r}")
    return dict(queue_size=queue, slop_ns=0 if sync == "exact" else int(slop_s * 1e9), max_wait_s=view_timeout_s,
                min_views=min(min_views, n_views))


def declare_executor(node: Node) -> str:
    """Declare the node's ``executor`` parameter (:data:`EXECUTORS`) and return its value."""
    kind = declare(node, "executor", "events", EXECUTOR_HELP, read_only=True)
    if kind not in EXECUTORS:
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, got {kind!r}")
    return kind


def make_executor(kind: str):
    """An executor of ``kind`` (:data:`EXECUTORS`); ``events`` falls back to the single-threaded one
    where rclpy has no ``rclpy.experimental.EventsExecutor``.

    Why it matters (docs/nodes.md "Where the CPU goes"): the Python ``SingleThreadedExecutor``
    rebuilds its wait set in Python for every message, ~0.3-0.5 ms of CPU *holding the GIL* on this
    machine; in the estimator that time is taken from the tracker thread (numba kernels hold the
    GIL too). The EventsExecutor dispatches from C++.
    """
    if kind == "events":
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:
            return SingleThreadedExecutor()
        return EventsExecutor()
    return SingleThreadedExecutor()


def spin_until_shutdown(executor, context=None, *, until: Callable[[], bool] | None = None,
                        step_s: float = 0.5) -> None:
    """``executor.spin()``, for either kind: the EventsExecutor's own ``spin()`` busy-waits on the
    rclpy wheels of Jazzy (a full core while idle) and misses the shutdown, so it is spun with bounded
    ``spin_once`` calls (``step_s``) until the context is shut down (a shutdown wakes it at once), or until
    ``until()`` holds (the player: its bag is played).

    An error raised by a callback once the context is shut down ends the spin as the shutdown does: at
    Ctrl-C rclpy's signal handler shuts the context down on a thread of its own, so a callback running at
    that moment can fail to publish ("publisher's context is invalid", seen as exit code 1 of a node stopped
    by SIGINT in 1 of 25 tries: a diagnostics timer). Errors while the context is up propagate."""
    try:
        if until is None and isinstance(executor, (SingleThreadedExecutor, MultiThreadedExecutor)):
            executor.spin()
            return
        while rclpy.ok(context=context) and not (until is not None and until()):
            executor.spin_once(timeout_sec=step_s)
    except Exception:
        if rclpy.ok(context=context):
            raise


def run_node(factory: Callable[..., Node], args: list[str] | None = None, *,
             multithreaded: bool = False, **kwargs) -> int:
    """Jazzy ``main()``: init, spin, catch Ctrl-C / external shutdown, destroy, ``try_shutdown``.

    A ``ValueError`` raised while the node is built (bad parameters, unreadable files) is printed
    as one line and gives exit code 2.
    """
    # Idle OpenMP workers of numba's parallel kernels sleep instead of spinning (read by the OpenMP
    # runtime when the first parallel kernel runs, so setting it here is in time): the nodes share
    # the cores, and spinning workers take the CPU the other nodes need (see launcher.Supervisor).
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = factory(**kwargs)
        kind = declare_executor(node)
        executor = MultiThreadedExecutor(num_threads=2) if multithreaded else make_executor(kind)
        executor.add_node(node)
        spin_until_shutdown(executor, node.context)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as exc:
        print(f"{getattr(factory, '__name__', 'node')}: {exc}", file=sys.stderr)
        code = 2
    finally:
        close_nodes([] if node is None else [node])
    return code


def close_nodes(nodes) -> None:
    """Close (their ``close()``, if any) and destroy ``nodes`` in reverse order, then ``try_shutdown``:
    the end of every process that spins nodes (one node, a launch, a composed process)."""
    for node in reversed(list(nodes)):
        close = getattr(node, "close", None)
        if callable(close):
            close()
        node.destroy_node()
    rclpy.try_shutdown()
