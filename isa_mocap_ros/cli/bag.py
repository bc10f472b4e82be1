"""``isa-mocap bag info BAG`` and ``isa-mocap bag repair BAG`` (issue 2, items 6-7)."""
from __future__ import annotations

import argparse
import sys


def register(sub) -> None:
    p = sub.add_parser("bag", help="inspect and repair rosbag2 MCAP bags")
    bsub = p.add_subparsers(dest="bag_command", metavar="ACTION")
    bsub.required = True
    ip = bsub.add_parser("info", help="topics, types, counts, duration (like ros2 bag info)")
    ip.add_argument("bag", help="rosbag2 directory or .mcap file")
    ip.set_defaults(func=_info)
    rp = bsub.add_parser("repair", help="rebuild index and metadata of a bag whose writer was killed")
    rp.add_argument("bag", help="rosbag2 directory or .mcap file")
    rp.set_defaults(func=_repair)


def _info(args: argparse.Namespace) -> int:
    print("isa-mocap bag info: not implemented yet", file=sys.stderr)
    return 1


def _repair(args: argparse.Namespace) -> int:
    print("isa-mocap bag repair: not implemented yet", file=sys.stderr)
    return 1
