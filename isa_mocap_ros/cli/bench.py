"""``isa-mocap bench NAME``: thin dispatch to the benchmarks in :mod:`isa_mocap_ros.bench`.

Each benchmark is a module (:func:`isa_mocap_ros.bench.module_name`) exposing ``add_arguments(parser)`` and
``run(args) -> int``; its name is in :data:`isa_mocap_ros.bench.BENCHES`. ``bench all`` runs every
benchmark with its defaults and regenerates ``docs/RESULTS.md`` (what ``make bench`` calls;
:mod:`isa_mocap_ros.bench.results`).
"""
from __future__ import annotations

import importlib

from isa_mocap_ros.bench import BENCHES, module_name


def register(sub) -> None:
    p = sub.add_parser("bench", help="run benchmarks and paper reproductions")
    bsub = p.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    for name in BENCHES:
        mod = importlib.import_module(module_name(name))
        bp = bsub.add_parser(name, help=(mod.__doc__ or "").strip().splitlines()[0].replace("%", "%%"))
        mod.add_arguments(bp)
        bp.set_defaults(func=mod.run)
    from isa_mocap_ros.bench import results

    ap = bsub.add_parser("all", help="run every benchmark and regenerate docs/RESULTS.md (make bench)")
    results.add_arguments(ap)
    ap.set_defaults(func=results.run)
