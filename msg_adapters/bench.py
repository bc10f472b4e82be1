"""Message adapter speed: Image <-> ndarray, CDR, and the header stamp fast path (msg_adapters).

Times the conversions a node does per frame on a ``--width`` x ``--height`` frame (640x480 by
default) next to the naive alternatives the adapters avoid (assigning a numpy array to
``Image.data``, passing ``data=`` to the ``Image`` constructor, deserializing a whole message
for its stamp). Each figure is the best of ``--repeat`` rounds of ``--number`` calls, in
microseconds per call.
"""
from __future__ import annotations

import argparse
import array
import json
import timeit

import numpy as np


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--number", type=int, default=50, help="calls per round")
    p.add_argument("--repeat", type=int, default=5, help="rounds (the best is reported)")
    p.add_argument("--naive", action="store_true", help="also time the slow naive ndarray assignment (~70 ms)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def _best_us(fn, number: int, repeat: int) -> float:
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def run(args: argparse.Namespace) -> int:
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Image

    import msg_adapters as ma

    rng = np.random.default_rng(0)
    h, w = args.height, args.width
    rgb = rng.integers(0, 256, size=(h, w, 3), dtype=np.uint8)
    depth = rng.integers(0, 65536, size=(h, w), dtype=np.uint16)
    msg = ma.array_to_image(rgb, "rgb8", stamp_ns=1, frame_id="cam0")
    padded = Image(height=h, width=w, encoding="rgb8", step=w * 3 + 64)
    padded.data = array.array("B", bytes(h * (w * 3 + 64)))
    big = Image(height=h, width=w, encoding="mono16", is_bigendian=1, step=w * 2)
    big.data = array.array("B", depth.astype(">u2").tobytes())
    cdr = ma.to_cdr(msg)
    n, r = args.number, args.repeat

    buf = array.array("B", rgb.tobytes())
    rows = {
        f"array_to_image rgb8 {w}x{h}": _best_us(lambda: ma.array_to_image(rgb, "rgb8"), n, r),
        "naive Image(data=arr.tobytes())": _best_us(lambda: Image(data=rgb.tobytes()), n, r),
        "naive Image(data=array.array)": _best_us(lambda: Image(data=buf), max(1, n // 5), r),
        "image_to_array view": _best_us(lambda: ma.image_to_array(msg), n * 20, r),
        "image_to_array view, padded step": _best_us(lambda: ma.image_to_array(padded), n * 20, r),
        "image_to_array copy=True": _best_us(lambda: ma.image_to_array(msg, copy=True), n, r),
        "image_to_array mono16 big-endian (swap)": _best_us(lambda: ma.image_to_array(big), n, r),
        "to_cdr Image": _best_us(lambda: ma.to_cdr(msg), n, r),
        "from_cdr Image": _best_us(lambda: ma.from_cdr(cdr, Image), n, r),
        "header_stamp_ns_from_cdr": _best_us(lambda: ma.header_stamp_ns_from_cdr(cdr), n * 20, r),
        "deserialize + stamp_to_ns": _best_us(lambda: ma.stamp_to_ns(deserialize_message(cdr, Image).header),
                                              n, r),
    }
    if args.naive:
        def naive():
            m = Image()
            m.data = rgb.reshape(-1)
        rows["naive msg.data = ndarray"] = _best_us(naive, 1, 3)
    if args.json:
        print(json.dumps({k: round(v, 2) for k, v in rows.items()}, indent=1))
    else:
        width = max(map(len, rows))
        for k, v in rows.items():
            print(f"{k:<{width}}  {v:12.2f} us")
    return 0
