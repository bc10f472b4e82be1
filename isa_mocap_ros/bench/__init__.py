"""Benchmarks and paper reproductions, run by ``isa-mocap bench NAME`` (and ``make bench``).

One module per benchmark, each exposing ``add_arguments(parser)`` and ``run(args) -> int``:
``ackley`` (ISA §13.4.1), ``adapters`` (in ``msg_adapters.bench``), ``render``, ``energy``, ``compare`` (EA-vs-PF §5.2-5.4),
``robustness`` (ISA §13.4.2), ``speed``, ``keypoints`` (the 2-D landmark detector, tracking with the keypoint term),
``mesh_baseline`` (mesh bodies vs capsules), ``mesh`` (the headline: mesh subjects, automatic shape and initialization),
``mesh_motions`` (CMU clips of other kinds on mesh subjects),
``real`` (the real Pose2Sim recording, offline and through the network);
``results`` runs them all and writes ``docs/RESULTS.md``.
They sit apart from the core (which never imports them) and may import the CLI's offline
tracking/synthesis code (``cli.track.track_bag``, ``cli.synth.write_bag``).
"""
from __future__ import annotations

#: benchmark names (``isa-mocap bench NAME``), each a module of this package but ``adapters``, which
#: times ROS message conversion and so lives beside the adapters (only ``msg_adapters``, ``nodes`` and
#: ``cli`` import ROS)
BENCHES: list[str] = ["ackley", "adapters", "render", "energy", "compare", "robustness", "speed", "keypoints",
                      "mesh_baseline", "mesh", "mesh_motions", "real"]
_ELSEWHERE = {"adapters": "msg_adapters.bench"}


def module_name(name: str) -> str:
    """The importable module of benchmark ``name``."""
    return _ELSEWHERE.get(name, f"isa_mocap_ros.bench.{name}")
