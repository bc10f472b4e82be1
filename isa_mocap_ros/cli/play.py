"""``isa-mocap play BAG``: replay a bag on its topics (the player node, configured from flags)."""
from __future__ import annotations

import argparse
import json


def register(sub) -> None:
    p = sub.add_parser("play", help="replay an MCAP rosbag2 bag on its topics",
                       description="Replay a bag's recorded CDR bytes with their QoS, like `ros2 bag play`.")
    p.add_argument("bag", help="rosbag2 directory or .mcap file")
    p.add_argument("--rate", type=float, default=1.0, help="playback rate (default 1.0)")
    p.add_argument("--loop", action="store_true", help="start again at the end")
    p.add_argument("--start-offset", type=float, default=0.0, metavar="S", help="skip the first S seconds")
    p.add_argument("--topics", nargs="+", default=[], metavar="TOPIC", help="only these topics (globs allowed)")
    p.add_argument("--exclude-topics", nargs="+", default=[], metavar="TOPIC", help="not these topics")
    p.add_argument("--remap", nargs="+", default=[], metavar="OLD:=NEW", help="publish OLD under NEW")
    p.add_argument("--clock", nargs="?", type=float, const=40.0, default=None, metavar="HZ",
                   help="publish /clock from the bag's time")
    p.add_argument("--lockstep", default="", metavar="TOPIC",
                   help="publish frame k+1 only after TOPIC carried frame k's header.stamp")
    p.add_argument("--lockstep-type", default="sensor_msgs/msg/JointState", metavar="TYPE",
                   help="message type on the lockstep topic (default sensor_msgs/msg/JointState)")
    p.add_argument("--lockstep-timeout", type=float, default=10.0, metavar="S",
                   help="seconds to wait for each lockstep echo before going on (default 10)")
    p.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="S",
                   help="wait up to S seconds until every topic (and /clock with --clock) has a subscriber")
    p.add_argument("--delay", type=float, default=0.0, metavar="S", help="sleep S seconds before playing")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rclpy.parameter import Parameter

    from isa_mocap_ros.nodes.player import play

    params = [
        Parameter("bag", value=str(args.bag)),
        Parameter("rate", value=float(args.rate)),
        Parameter("loop", value=bool(args.loop)),
        Parameter("start_offset_s", value=float(args.start_offset)),
        Parameter("topics", value=list(args.topics) or [""]),
        Parameter("exclude_topics", value=list(args.exclude_topics) or [""]),
        Parameter("remap", value=list(args.remap) or [""]),
        Parameter("clock", value=args.clock is not None),
        Parameter("clock_hz", value=float(args.clock or 40.0)),
        Parameter("lockstep_topic", value=args.lockstep),
        Parameter("lockstep_type", value=args.lockstep_type),
        Parameter("lockstep_timeout_s", value=float(args.lockstep_timeout)),
        Parameter("wait_for_subscribers_s", value=float(args.wait_for_subscribers)),
        Parameter("delay_s", value=float(args.delay)),
    ]
    summary = play([], parameter_overrides=params)
    if summary is None:
        return 1  # interrupted, or replay stopped on an error already logged
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"played {summary['messages']} messages ({summary['frames']} frames) on {summary['topics']} "
              f"topics in {summary['seconds']:.2f} s")
    return 0
