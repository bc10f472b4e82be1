"""``isa-mocap``: the command-line entry point.

Each subcommand lives in its own module of this package and exposes
``register(subparsers) -> None``, which adds its parser and sets ``func`` (a callable taking the
parsed ``argparse.Namespace`` and returning an exit code). Add a module name to ``SUBCOMMANDS``
to make it available.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys

# Idle OpenMP workers of numba's parallel kernels sleep instead of spinning on the cores (set before
# numba is imported; a caller's own setting wins). On this shared 2-core machine `isa-mocap track`
# ran 3-5x slower with spinning workers under load (docs/nodes.md, "Where the CPU goes").
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

SUBCOMMANDS = [
    "play",
    "record",
    "launch",
    "run",
    "bag",
    "bench",
    "synth",
    "track",
    "evaluate",
    "calibration",
    "calibrate",
    "import_video",
    "warmup",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="isa-mocap",
        description="Markerless multi-view motion capture (ISA and friends) on ROS 2.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in SUBCOMMANDS:
        importlib.import_module(f"isa_mocap_ros.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:  # Ctrl-C while the command starts up ends it as quietly as while it runs
        from isa_mocap_ros.eval.peers import register_peers

        register_peers()  # the reference optimizers "pycma" and "scipy-de" are selectable too
        args = build_parser().parse_args(argv)
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
