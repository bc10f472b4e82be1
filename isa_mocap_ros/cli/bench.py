"""``isa-mocap bench NAME``: benchmarks and paper reproductions.

Each benchmark is a module ``isa_mocap_ros.cli.bench_<name>`` exposing
``add_arguments(parser)`` and ``run(args) -> int``; add its name to ``BENCHES``.
``bench all`` runs every benchmark with its defaults (what ``make bench`` calls).
"""
from __future__ import annotations

import argparse
import importlib

BENCHES: list[str] = ["ackley", "adapters", "render", "energy", "compare"]


def register(sub) -> None:
    p = sub.add_parser("bench", help="run benchmarks and paper reproductions")
    bsub = p.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    for name in BENCHES:
        mod = importlib.import_module(f"isa_mocap_ros.cli.bench_{name}")
        bp = bsub.add_parser(name, help=(mod.__doc__ or "").strip().splitlines()[0])
        mod.add_arguments(bp)
        bp.set_defaults(func=mod.run)
    ap = bsub.add_parser("all", help="run every benchmark with its defaults (make bench)")
    ap.set_defaults(func=_run_all)


def _run_all(args: argparse.Namespace) -> int:
    if not BENCHES:
        print("isa-mocap bench: no benchmarks registered yet")
        return 0
    rc = 0
    for name in BENCHES:
        mod = importlib.import_module(f"isa_mocap_ros.cli.bench_{name}")
        bp = argparse.ArgumentParser()
        mod.add_arguments(bp)
        print(f"== bench {name}")
        rc = max(rc, int(mod.run(bp.parse_args([])) or 0))
    return rc
