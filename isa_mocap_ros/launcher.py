"""A small process launcher for ROS 2 YAML launch files (the ``ros2 launch`` YAML frontend subset).

No ``launch`` package exists on PyPI, so ``isa-mocap launch`` reads the same files a full ROS
install's ``ros2 launch isa_mocap_ros mocap.launch.yaml`` reads::

    launch:
    - arg: {name: params, default: "$(find-pkg-share isa_mocap_ros)/config/pipeline.yaml"}
    - node:
        pkg: isa_mocap_ros
        exec: camera_node
        name: camera
        namespace: /mocap
        respawn: "true"
        respawn_delay: 1.0
        param: [{from: "$(var params)"}]
        remap: [{from: cam0/image_raw, to: /other}]

Supported: ``arg`` (name, default), ``node`` (pkg, exec, name, namespace, param ``from``/``name``
+``value``, remap, respawn, respawn_delay, args), substitutions ``$(var NAME)`` and
``$(find-pkg-share isa_mocap_ros)``. Pure module (no rclpy): it builds command lines and
supervises child processes: output prefixed with the node name, SIGINT/SIGTERM forwarded,
crashed nodes respawned when configured, escalation SIGINT -> SIGTERM -> SIGKILL on shutdown.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import yaml

from isa_mocap_ros.resources import resource_dir

PACKAGE = "isa_mocap_ros"
_SUBST = re.compile(r"\$\((var|find-pkg-share)\s+([^)\s]+)\)")


class LaunchError(ValueError):
    """A launch file that cannot be read or used."""


@dataclass(frozen=True)
class NodeSpec:
    """One node to run: executable, ROS name/namespace, parameter files/values, remaps, respawn."""

    exec: str
    name: str
    namespace: str = ""
    params_files: tuple[str, ...] = ()
    params: tuple[tuple[str, str], ...] = ()
    remaps: tuple[tuple[str, str], ...] = ()
    respawn: bool = False
    respawn_delay_s: float = 1.0
    extra_args: tuple[str, ...] = ()
    nice: int = 0            # added to the process's niceness (0 = unchanged; > 0 = lower CPU priority)
    members: tuple["NodeSpec", ...] = ()   # non-empty: one process hosting these nodes on one executor

    @property
    def module(self) -> str:
        """``camera_node`` -> ``isa_mocap_ros.nodes.camera``."""
        base = self.exec[:-5] if self.exec.endswith("_node") else self.exec
        return f"{PACKAGE}.nodes.{base}"

    def ros_args(self) -> list[str]:
        args = ["--ros-args", "-r", f"__node:={self.name}"]
        if self.namespace:
            args += ["-r", f"__ns:={self.namespace}"]
        for f in self.params_files:
            args += ["--params-file", f]
        for k, v in self.params:
            args += ["-p", f"{k}:={v}"]
        for a, b in self.remaps:
            args += ["-r", f"{a}:={b}"]
        return args

    def command(self, python: str = sys.executable) -> list[str]:
        if self.members:     # isa_mocap_ros.cli.compose: the member nodes in one process, one executor
            return [python, "-m", f"{PACKAGE}.cli.compose", json.dumps([m.to_json() for m in self.members])]
        return [python, "-m", self.module, *self.extra_args, *self.ros_args()]

    def to_json(self) -> dict:
        """The spec as JSON-able values (:meth:`from_json` reads it back)."""
        if self.members:
            raise LaunchError(f"{self.name}: a composed spec cannot be a member of another")
        return {k: list(map(list, v)) if k in ("params", "remaps") else list(v) if isinstance(v, tuple) else v
                for k, v in self.__dict__.items() if k != "members"}

    @classmethod
    def from_json(cls, d: Mapping) -> "NodeSpec":
        return cls(**{k: tuple(map(tuple, v)) if k in ("params", "remaps") else tuple(v) if isinstance(v, list) else v
                      for k, v in d.items()})


def niceness(increment: int) -> Callable[[], None] | None:
    """A ``preexec_fn`` that lowers the child's CPU priority by ``increment`` (None for 0)."""
    if increment <= 0:
        return None
    return lambda: os.nice(increment)


def _prctl():
    """libc's ``prctl`` (Linux), looked up before any fork (a child runs nothing but the call), or None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _prctl()
_PR_SET_PDEATHSIG = 1


def child_setup(increment: int) -> Callable[[], None]:
    """The nodes' ``preexec_fn``: :func:`niceness`, and SIGTERM to the node when the launching thread dies.

    The nodes run in sessions of their own (a Ctrl-C reaches them through :meth:`Supervisor.shutdown`, in order), so
    a launcher killed outright (SIGKILL: ``subprocess.run(timeout=)`` in a test, the OOM killer) left its nodes
    running: on a test's ROS domain they answered the next test's network (a second estimator on ``/diagnostics``,
    masks and frame sets of another run), a cascade of failures under load. Linux only (elsewhere: niceness)."""
    nice = niceness(increment)
    parent = os.getpid()

    def setup() -> None:
        if nice is not None:
            nice()
        if _PRCTL is not None:
            _PRCTL(_PR_SET_PDEATHSIG, int(signal.SIGTERM))
            if os.getppid() != parent:      # the launcher died before the call
                os.kill(os.getpid(), signal.SIGTERM)
    return setup


def _substitute(value, variables: Mapping[str, str]):
    if not isinstance(value, str):
        return value

    def repl(m: re.Match) -> str:
        kind, name = m.group(1), m.group(2)
        if kind == "var":
            if name not in variables:
                raise LaunchError(f"$(var {name}) is not defined; declare it with an 'arg' entry or pass {name}:=VALUE")
            return str(variables[name])
        if name != PACKAGE:
            raise LaunchError(f"$(find-pkg-share {name}): only '{PACKAGE}' is known here")
        return str(resource_dir("config").parent)
    return _SUBST.sub(repl, value)


def _bool(v) -> bool:
    return v if isinstance(v, bool) else str(v).strip().lower() in ("true", "1", "yes")


def load_launch_file(path: str | Path, arguments: Mapping[str, str] | None = None) -> list[NodeSpec]:
    """Parse a YAML launch file into node specs; ``arguments`` override ``arg`` defaults."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise LaunchError(f"cannot read launch file {path}: {exc}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("launch"), list):
        raise LaunchError(f"{path}: expected a top-level 'launch:' list, got {type(doc).__name__}")
    variables: dict[str, str] = {}
    given = dict(arguments or {})
    nodes: list[NodeSpec] = []
    for i, entry in enumerate(doc["launch"]):
        if not isinstance(entry, dict) or len(entry) != 1:
            raise LaunchError(f"{path}: entry {i} must be a one-key mapping (arg: or node:), got {entry!r}")
        (kind, body), = entry.items()
        if kind == "arg":
            name = body.get("name")
            if not name:
                raise LaunchError(f"{path}: arg entry {i} has no name")
            if name in given:
                variables[name] = given.pop(name)
            elif "default" in body:
                variables[name] = _substitute(str(body["default"]), variables)
            else:
                raise LaunchError(f"{path}: argument '{name}' has no default; pass {name}:=VALUE")
        elif kind == "node":
            nodes.append(_node_spec(path, i, body, variables))
        else:
            raise LaunchError(f"{path}: entry {i}: unsupported action '{kind}' (supported: arg, node)")
    if given:
        raise LaunchError(f"unknown launch arguments {sorted(given)}; the file declares {sorted(variables)}")
    return nodes


def _node_spec(path: Path, i: int, body: Mapping, variables: Mapping[str, str]) -> NodeSpec:
    sub = lambda v: _substitute(v, variables)  # noqa: E731
    if sub(body.get("pkg", PACKAGE)) != PACKAGE:
        raise LaunchError(f"{path}: node {i}: only pkg '{PACKAGE}' can be started here, got {body.get('pkg')!r}")
    exe = sub(body.get("exec", ""))
    if not exe:
        raise LaunchError(f"{path}: node {i} has no 'exec'")
    files, values = [], []
    for p in body.get("param", []) or []:
        if "from" in p:
            f = sub(p["from"])
            if not Path(f).is_file():
                raise LaunchError(f"{path}: node {exe}: parameter file {f} does not exist")
            files.append(f)
        elif "name" in p and "value" in p:
            values.append((p["name"], str(sub(p["value"]))))
        else:
            raise LaunchError(f"{path}: node {exe}: param entries need 'from' or 'name'+'value', got {p!r}")
    remaps = [(sub(r["from"]), sub(r["to"])) for r in body.get("remap", []) or []]
    args = sub(body.get("args", "")) or ""
    return NodeSpec(exec=exe, name=sub(body.get("name", exe.removesuffix("_node"))),
                    namespace=sub(body.get("namespace", "")) or "", params_files=tuple(files),
                    params=tuple(values), remaps=tuple(remaps), respawn=_bool(sub(body.get("respawn", False))),
                    respawn_delay_s=float(sub(body.get("respawn_delay", 1.0))), extra_args=tuple(args.split()))


@dataclass
class _Child:
    spec: NodeSpec
    popen: subprocess.Popen | None = None
    restarts: int = 0
    reader: threading.Thread | None = None
    exit_codes: list[int] = field(default_factory=list)


class Supervisor:
    """Runs node processes, prefixes their output, respawns, and shuts them down in order.

    ``out`` receives each output line (default: ``print``). ``run()`` blocks until every
    non-respawning node has exited or ``stop()`` is called (e.g. from a signal handler);
    it returns the worst exit code of nodes that ended on their own.
    """

    def __init__(self, specs: Sequence[NodeSpec], *, env: Mapping[str, str] | None = None,
                 out: Callable[[str], None] | None = None, python: str = sys.executable) -> None:
        if not specs:
            raise LaunchError("nothing to launch: the launch description has no nodes")
        names = [s.name for s in specs]
        if len(set(names)) != len(names):
            raise LaunchError(f"node names must be unique, got {names}")
        self.children = [_Child(s) for s in specs]
        self.env = dict(env if env is not None else os.environ)
        # Idle OpenMP workers (numba's threading layer) sleep instead of spinning: the nodes share the
        # cores, and a spinning worker of one node takes the CPU another node needs (measured on the
        # loaded 2-core machine: `isa-mocap track` 49.6 s CPU, 2.9 frames/s spinning; 9.1 s, 16.1
        # frames/s passive; identical estimates). The caller's own setting wins.
        self.env.setdefault("OMP_WAIT_POLICY", "PASSIVE")
        self.out = out or (lambda line: print(line, flush=True))
        self.python = python
        self._stop = threading.Event()
        self._lock = threading.Lock()

    def _start(self, child: _Child) -> None:
        child.popen = subprocess.Popen(child.spec.command(self.python), env=self.env, stdout=subprocess.PIPE,
                                       stderr=subprocess.STDOUT, start_new_session=True,
                                       preexec_fn=child_setup(child.spec.nice))
        tag = f"[{child.spec.name}-{child.popen.pid}]"
        self.out(f"[launch] started {child.spec.name} (pid {child.popen.pid}): {' '.join(child.spec.command(self.python)[1:])}")

        def pump(stream=child.popen.stdout) -> None:
            for raw in iter(stream.readline, b""):
                self.out(f"{tag} {raw.decode(errors='replace').rstrip()}")
        child.reader = threading.Thread(target=pump, daemon=True)
        child.reader.start()

    def stop(self) -> None:
        self._stop.set()

    def run(self, *, poll_s: float = 0.1) -> int:
        for c in self.children:
            self._start(c)
        worst = 0
        try:
            while not self._stop.is_set():
                alive = 0
                for c in self.children:
                    if c.popen is None:
                        continue
                    rc = c.popen.poll()
                    if rc is None:
                        alive += 1
                        continue
                    c.exit_codes.append(rc)
                    if c.reader is not None:
                        c.reader.join(timeout=1.0)
                    if c.spec.respawn and not self._stop.is_set():
                        self.out(f"[launch] {c.spec.name} exited with code {rc}; respawning in "
                                 f"{c.spec.respawn_delay_s:.1f} s")
                        self._stop.wait(c.spec.respawn_delay_s)
                        if not self._stop.is_set():
                            c.restarts += 1
                            self._start(c)
                            alive += 1
                    else:
                        self.out(f"[launch] {c.spec.name} exited with code {rc}")
                        worst = max(worst, abs(rc))
                        c.popen = None
                if alive == 0:
                    break
                self._stop.wait(poll_s)
        finally:
            self.shutdown()
        return worst

    def shutdown(self, *, grace_s: float = 5.0) -> None:
        """SIGINT every running child, then SIGTERM, then SIGKILL, each after ``grace_s``."""
        running = [c for c in self.children if c.popen is not None and c.popen.poll() is None]
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if not running:
                break
            for c in running:
                try:
                    c.popen.send_signal(sig)
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + grace_s
            while running and time.monotonic() < deadline:
                running = [c for c in running if c.popen.poll() is None]
                time.sleep(0.05)
            if running and sig != signal.SIGKILL:
                self.out(f"[launch] {[c.spec.name for c in running]} still running after {sig.name}; escalating")
        for c in self.children:
            if c.reader is not None:
                c.reader.join(timeout=1.0)
