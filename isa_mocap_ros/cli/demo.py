"""``isa-mocap demo``: the main job on the shipped default bag (what ``make demo`` runs).

Replays ``bags/demo`` through the player and the recorder, each its own process talking over DDS
in a private ROS domain, then compares the recording with the source bag and prints the result.
"""
from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time
from pathlib import Path

from isa_mocap_ros.bag import BagReader, bag_info, format_bag_info
from isa_mocap_ros.resources import default_bag
from isa_mocap_ros.rosenv import ros_env


def register(sub) -> None:
    p = sub.add_parser("demo", help="replay the shipped demo bag through player and recorder")
    p.add_argument("bag", nargs="?", default=None, help="bag to replay (default: the shipped demo bag)")
    p.add_argument("--out", default="out/demo", help="output directory (default out/demo)")
    p.add_argument("--rate", type=float, default=1.0, help="playback rate")
    p.set_defaults(func=run)


def _counts(path: Path) -> dict[str, int]:
    with BagReader(path) as r:
        return {name: t.message_count for name, t in sorted(r.topics.items())}


def run(args: argparse.Namespace) -> int:
    bag = Path(args.bag) if args.bag else default_bag()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    recording = out / "recording"
    env = ros_env(keep_caller_domain=True)
    print(f"demo: replaying {bag} (ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}, discovery {env['ROS_AUTOMATIC_DISCOVERY_RANGE']})")
    print(format_bag_info(bag_info(bag)))
    cli = [sys.executable, "-m", "isa_mocap_ros.cli.main"]
    rec_log = open(out / "recorder.log", "w")
    rec = subprocess.Popen(cli + ["record", str(recording), "--all", "--overwrite"], env=env,
                           stdout=rec_log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 30
        while "recording to" not in (out / "recorder.log").read_text() and time.monotonic() < deadline:
            if rec.poll() is not None:
                print((out / "recorder.log").read_text(), file=sys.stderr)
                return 1
            time.sleep(0.1)
        t0 = time.monotonic()
        play = subprocess.run(cli + ["play", str(bag), "--rate", str(args.rate), "--wait-for-subscribers", "20"],
                              env=env, capture_output=True, text=True)
        print(play.stdout.strip())
        if play.returncode != 0:
            print(play.stderr, file=sys.stderr)
            return play.returncode
        time.sleep(1.0)
    finally:
        rec.send_signal(signal.SIGINT)
        rec.wait(30)
        rec_log.close()
    src, got = _counts(bag), _counts(recording)
    print(f"\ndemo: recorded to {recording} in {time.monotonic() - t0:.1f} s")
    print(f"{'topic':48s} {'bag':>6s} {'recorded':>9s}")
    for topic in sorted(src):
        print(f"{topic:48s} {src[topic]:6d} {got.get(topic, 0):9d}")
    missing = {t: src[t] - got.get(t, 0) for t in src if got.get(t, 0) != src[t]}
    if missing:
        print(f"demo: messages lost or extra: {missing}")
        return 1
    print("demo: every message of the bag was replayed and recorded")
    return 0
