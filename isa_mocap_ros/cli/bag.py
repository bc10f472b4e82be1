"""``isa-mocap bag info BAG`` and ``isa-mocap bag repair BAG`` (issue 2, items 6-7).

``info`` prints topics, types, counts, QoS, duration and start/end like ``ros2 bag info``
(``--json`` for the :func:`isa_mocap_ros.bag.bag_info` dict). ``repair`` makes a bag whose
recorder was killed complete again (index, summary, ``metadata.yaml``).
"""
from __future__ import annotations

import argparse
import json
import sys

from isa_mocap_ros.bag import BagError, bag_info, format_bag_info, repair_bag


def register(sub) -> None:
    p = sub.add_parser("bag", help="inspect and repair rosbag2 MCAP bags")
    bsub = p.add_subparsers(dest="bag_command", metavar="ACTION")
    bsub.required = True
    ip = bsub.add_parser("info", help="topics, types, counts, QoS, duration (like ros2 bag info)")
    ip.add_argument("bag", help="rosbag2 directory or .mcap file")
    ip.add_argument("--json", action="store_true", help="print the info as JSON")
    ip.set_defaults(func=_info)
    rp = bsub.add_parser("repair", help="rebuild index and metadata of a bag whose writer was killed")
    rp.add_argument("bag", help="rosbag2 directory or .mcap file")
    rp.add_argument("--version", type=int, choices=(8, 9), default=None,
                    help="metadata.yaml version to write (default: keep or infer)")
    rp.set_defaults(func=_repair)


def _info(args: argparse.Namespace) -> int:
    try:
        info = bag_info(args.bag)
    except BagError as exc:
        print(f"isa-mocap bag info: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(info, indent=2) if args.json else format_bag_info(info))
    return 0


def _repair(args: argparse.Namespace) -> int:
    try:
        report = repair_bag(args.bag, version=args.version)
    except BagError as exc:
        print(f"isa-mocap bag repair: {exc}", file=sys.stderr)
        return 2
    if report["rewritten"]:
        action = f"rewrote {', '.join(report['rewritten'])}"
    else:
        action = "storage already complete, nothing rewritten"
    if report["metadata_written"]:
        action += "; wrote metadata.yaml"
    print(f"{report['path']}: {action}")
    print(f"recovered {report['messages']} messages on {len(report['topics'])} topics, "
          f"dropped {report['dropped_bytes']} bytes")
    for name, count in report["topics"].items():
        print(f"  {name}: {count}")
    for note in report["notes"]:
        print(f"note: {note}")
    return 0
