#!/usr/bin/env python3
"""Compare two ``isa-mocap track`` outputs (or bench ``--json`` files) bit for bit.

    tools/same_results.py BEFORE AFTER      # directories of track outputs, or two JSON files

A track output is the same when every message of ``estimates/`` has the same topic, log time and
fields (CDR bytes compared first; when they differ the messages are deserialized and compared field by
field, since CDR alignment padding carries arbitrary bytes), and ``summary.json`` agrees in every field except the timings (``fps``, ``seconds``, ``out``).
JSON files (``bench ... --json``) are compared the same way, timing keys left out. Used to check a
behaviour-preserving refactor; prints one line per difference and exits 1 if there is any.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

TIMING = {"fps", "seconds", "out", "frames_per_s", "wall_s", "elapsed_s", "evals_per_s", "time_s", "cache",
          "frame_ms", "ms", "latency_ms", "keypoint_ms_per_frame_set"}


def _strip(v):
    if isinstance(v, dict):
        return {k: _strip(x) for k, x in v.items() if k not in TIMING and not k.endswith(("_s", "_ms", "per_s", "seconds"))}
    if isinstance(v, list):
        return [_strip(x) for x in v]
    return v


def _diff(a, b, path="") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}.{k}: only in one" for k in sorted(set(a) ^ set(b))]
        for k in sorted(set(a) & set(b)):
            out += _diff(a[k], b[k], f"{path}.{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: length {len(a)} != {len(b)}"]
        out = []
        for i, (x, y) in enumerate(zip(a, b)):
            out += _diff(x, y, f"{path}[{i}]")
        return out
    return [] if a == b or (a != a and b != b) else [f"{path}: {a!r} != {b!r}"]


def _json(path: Path):
    text = path.read_text().strip()
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return json.loads(text.splitlines()[-1])


def compare_tracks(a: Path, b: Path) -> list[str]:
    from isa_mocap_ros.bag import BagReader

    out = _diff(_strip(_json(a / "summary.json")), _strip(_json(b / "summary.json")), "summary")
    with BagReader(a / "estimates") as ra, BagReader(b / "estimates") as rb:
        ma = [(m.topic, m.log_time_ns, m.type, m.data) for m in ra.messages()]
        mb = [(m.topic, m.log_time_ns, m.type, m.data) for m in rb.messages()]
    if len(ma) != len(mb):
        out.append(f"estimates: {len(ma)} != {len(mb)} messages")
    out += [f"estimates: message {i} ({x[0]} at {x[1]}) differs" for i, (x, y) in enumerate(zip(ma, mb))
            if x[:2] != y[:2] or (x[3] != y[3] and not _same_fields(x[2], x[3], y[3]))]
    return out


def _same_fields(type_name: str, a: bytes, b: bytes) -> bool:
    from rclpy.serialization import deserialize_message
    import importlib

    pkg, _, name = type_name.split("/")
    cls = getattr(importlib.import_module(f"{pkg}.msg"), name)
    return _plain(deserialize_message(a, cls)) == _plain(deserialize_message(b, cls))


def _plain(msg):
    if hasattr(msg, "get_fields_and_field_types"):
        return {k: _plain(getattr(msg, k)) for k in msg.get_fields_and_field_types()}
    if isinstance(msg, (list, tuple)) or type(msg).__name__ in ("array", "ndarray"):
        return [_plain(v) for v in msg]
    return msg


def main(argv: list[str]) -> int:
    a, b = Path(argv[0]), Path(argv[1])
    diffs = compare_tracks(a, b) if a.is_dir() else _diff(_strip(_json(a)), _strip(_json(b)))
    for d in diffs[:50]:
        print(d)
    print(f"{'SAME' if not diffs else 'DIFFERENT'}: {a} vs {b}" + (f" ({len(diffs)} differences)" if diffs else ""))
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
