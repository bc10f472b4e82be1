"""``isa-mocap record OUT``: record topics to an MCAP rosbag2 bag (the recorder node)."""
from __future__ import annotations

import argparse


def register(sub) -> None:
    p = sub.add_parser("record", help="record topics to an MCAP rosbag2 bag",
                       description="Record topics (raw CDR bytes, offered QoS kept) until SIGINT/SIGTERM.")
    p.add_argument("output", help="rosbag2 directory to create")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--topics", nargs="+", metavar="TOPIC", help="topics (globs allowed) to record")
    g.add_argument("--all", action="store_true", help="record every topic")
    p.add_argument("--exclude-topics", nargs="+", default=[], metavar="TOPIC", help="topics not to record")
    p.add_argument("--version", type=int, choices=(8, 9), default=9, help="rosbag2 metadata version")
    p.add_argument("--compression", choices=("zstd", "lz4", "none"), default="zstd")
    p.add_argument("--overwrite", action="store_true", help="replace an existing bag at OUTPUT")
    p.add_argument("--flush-period", type=float, default=1.0, metavar="S", help="flush at least every S s")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rclpy.parameter import Parameter

    from isa_mocap_ros.nodes.recorder import main

    params = [
        Parameter("output", value=str(args.output)),
        Parameter("topics", value=list(args.topics or []) or [""]),
        Parameter("all", value=bool(args.all)),
        Parameter("exclude_topics", value=list(args.exclude_topics) or [""]),
        Parameter("version", value=int(args.version)),
        Parameter("compression", value=args.compression),
        Parameter("overwrite", value=bool(args.overwrite)),
        Parameter("flush_period_s", value=float(args.flush_period)),
    ]
    main([], parameter_overrides=params)
    return 0
