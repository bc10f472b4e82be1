"""``isa-mocap warmup``: compile the numba kernels ahead, so the first run does not wait for them.

numba compiles a kernel on its first call after an install (1.5-4 minutes for the estimator's on
2 cores) and keeps the machine code in its on-disk cache; later processes load it in seconds. This
command starts the segmentation and estimator nodes once with the parameter file (each runs its
warm-up: the segmentation's background kernels, the estimator's tracker on a tiny synthetic frame
with every stage of the configured budget), waits until both say they are ready, and stops them.
``make venv`` runs it after installing. The nodes run with ``ROS_AUTOMATIC_DISCOVERY_RANGE=OFF``:
they discover no other node (a test suite running beside it is not disturbed).

Beside them (``--library``, the default) it compiles the kernels other commands call first
(:mod:`.warmup_library`: the sampled energy and the tracker on it, the mesh rasterizer, the parallel forward
kinematics) in two processes of their own, on the core the nodes leave idle (the segmentation node is ready in
seconds, the estimator compiles on one core): three compiling processes on two cores keep both busy until the
end; the groups share few kernels with the estimator's (numba compiles a kernel in each process that calls it
before it is in the cache).
"""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import threading
import time

from isa_mocap_ros.resources import resource_dir
from isa_mocap_ros.rosenv import ros_env

READY = {"segmentation_node": "segmentation: ", "estimator_node": "estimator: ready"}
#: :mod:`.warmup_library`'s groups, in two processes beside the nodes (the tracker on the sampled energy loads
#: that energy's kernels the first process compiled before it)
LIBRARY = (("sampled_energy", "tracker_fast"), ("kinematics_batch", "sampled_coverage", "mesh_render"))


def register(sub) -> None:
    p = sub.add_parser("warmup", help="compile the numba kernels ahead (make venv runs it)")
    p.add_argument("--params", default=None, help="parameter file (default: the package's config/pipeline.yaml)")
    p.add_argument("--timeout", type=float, default=900.0, help="longest wait, seconds (default 900)")
    p.add_argument("--library", action=argparse.BooleanOptionalAction, default=True,
                   help="also compile the kernels of the sampled energy, of the tracker on it and of the mesh "
                        "rasterizer, which track, synth, calibrate and the benches call (default: on)")
    p.set_defaults(func=warmup)


def warmup(args: argparse.Namespace) -> int:
    params = args.params or str(resource_dir("config") / "pipeline.yaml")
    env = ros_env()
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "OFF"   # the nodes see no other node, on any domain
    t0 = time.monotonic()
    print("warmup: compiling the numba kernels of the segmentation and estimator nodes"
          f"{' and of the library' if args.library else ''} (the first time after an install "
          f"{'~7 min on 2 cores' if args.library else '1.5-4 min'}, seconds once cached)", flush=True)
    procs, ready = {}, {name: threading.Event() for name in READY}
    bindir = os.path.dirname(sys.executable)
    for name in READY:
        exe = os.path.join(bindir, name)
        cmd = [exe] if os.path.exists(exe) else [sys.executable, "-m", f"isa_mocap_ros.nodes.{name[:-5]}"]
        procs[name] = subprocess.Popen(cmd + ["--ros-args", "-r", "__ns:=/mocap", "--params-file", params],
                                       env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                       start_new_session=True)
        threading.Thread(target=_watch, args=(procs[name], READY[name], ready[name]), daemon=True).start()
    library = [_library(groups) for groups in LIBRARY] if args.library else []
    stopped: list[subprocess.Popen] = []          # signalled once only (a second SIGINT could interrupt its exit)
    try:
        deadline = time.monotonic() + args.timeout
        for name, ev in ready.items():
            while not ev.wait(0.5):
                if procs[name].poll() is not None or time.monotonic() > deadline:
                    print(f"warmup: {name} did not get ready (exit code {procs[name].poll()})", file=sys.stderr)
                    return 1
        for p in procs.values():                   # ready: the nodes need not wait for the library
            p.send_signal(signal.SIGINT)
            stopped.append(p)
        for p in library:
            try:
                code = p.wait(max(1.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                code = None
            if code != 0:
                print(f"warmup: {' '.join(p.args[3:])} failed (exit code {code})", file=sys.stderr)
                return 1
    finally:
        for p in list(procs.values()) + library:
            if p.poll() is None and p not in stopped:
                p.send_signal(signal.SIGINT)
        for p in list(procs.values()) + library:
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
    print(f"warmup: kernels compiled and cached ({time.monotonic() - t0:.0f} s)", flush=True)
    return 0


def _library(groups: tuple[str, ...]) -> subprocess.Popen:
    """A process compiling :mod:`.warmup_library`'s ``groups`` (its output passed through)."""
    return subprocess.Popen([sys.executable, "-m", "isa_mocap_ros.cli.warmup_library", *groups],
                            start_new_session=True)


def _watch(proc: subprocess.Popen, text: str, ready: threading.Event) -> None:
    for line in proc.stdout:
        if text in line:
            ready.set()
        if "ERROR" in line or "Traceback" in line or "warm-up failed" in line:
            print(line.rstrip(), file=sys.stderr, flush=True)
