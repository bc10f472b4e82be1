"""``bag info``: a bag's topics, types, counts, QoS, duration and times, like ``ros2 bag info``.

The text layout follows ``ros2 bag info`` (rosbag2 ``ros2bag/verb/info.py`` and
``rosbag2_cpp/info.cpp`` format: Files, Bag size, Storage id, Duration, Start, End, Messages,
Topic information), with times in UTC and a QoS summary per topic.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

from .reader import BagReader


def bag_info(path: str | Path) -> dict:
    """Describe a bag (rosbag2 directory or bare ``.mcap``).

    Returns
    -------
    dict
        ``path``, ``files``, ``size_bytes``, ``storage_identifier``, ``version`` (None without
        metadata.yaml), ``ros_distro``, ``compression``, ``indexed``, ``start_ns``, ``end_ns``,
        ``duration_ns``, ``message_count``, ``topics`` (list of dicts: ``name``, ``type``,
        ``serialization_format``, ``message_count``, ``latched``, ``offered_qos`` as rosbag2 v9
        mappings) and ``notes``.

    Raises
    ------
    BagError
        When the bag cannot be opened.
    """
    with BagReader(path) as bag:
        return {
            "path": str(bag.path),
            "files": [p.name for p in bag.files],
            "size_bytes": bag.size_bytes,
            "storage_identifier": "mcap",
            "version": bag.version,
            "ros_distro": bag.ros_distro,
            "compression": bag.compression,
            "indexed": bag.indexed,
            "start_ns": bag.start_ns,
            "end_ns": bag.end_ns,
            "duration_ns": bag.duration_ns,
            "message_count": bag.message_count,
            "topics": [{"name": t.name, "type": t.type, "serialization_format": t.serialization_format,
                        "message_count": t.message_count, "latched": t.latched,
                        "offered_qos": [q.to_dict(version=9) for q in t.offered_qos]}
                       for t in bag.topics.values()],
            "notes": list(bag.notes),
        }


def _size(n: int) -> str:
    value = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if value < 1024 or unit == "GiB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024
    return f"{n} B"


def _time(ns: int) -> str:
    sec, rem = divmod(ns, 1_000_000_000)
    stamp = _dt.datetime.fromtimestamp(sec, tz=_dt.timezone.utc).strftime("%b %d %Y %H:%M:%S")
    return f"{stamp}.{rem:09d} UTC ({sec}.{rem:09d})"


def _qos(profiles: list[dict]) -> str:
    if not profiles:
        return "none recorded"
    parts = []
    for q in profiles:
        hist = f"keep_last({q['depth']})" if q["history"] == "keep_last" else q["history"]
        parts.append(f"{q['reliability']}, {q['durability']}, {hist}")
    return " / ".join(parts)


def format_bag_info(info: dict) -> str:
    """Human-readable text for a :func:`bag_info` dict."""
    label = 19
    lines = []

    def row(key: str, value: str) -> None:
        lines.append(f"{key + ':':<{label}}{value}")

    files = info["files"]
    row("Files", files[0] if files else "")
    for f in files[1:]:
        lines.append(" " * label + f)
    row("Bag size", _size(info["size_bytes"]))
    row("Storage id", info["storage_identifier"])
    row("Version", str(info["version"]) if info["version"] is not None else "(no metadata.yaml)")
    row("ROS Distro", info["ros_distro"] or "unknown")
    row("Compression", info["compression"] or "none")
    dur = info["duration_ns"]
    row("Duration", f"{dur // 1_000_000_000}.{dur % 1_000_000_000:09d}s")
    if info["message_count"]:
        row("Start", _time(info["start_ns"]))
        row("End", _time(info["end_ns"]))
    row("Messages", str(info["message_count"]))
    topics = info["topics"]
    width = max((len(t["name"]) for t in topics), default=0)
    twidth = max((len(t["type"]) for t in topics), default=0)
    first = True
    for t in topics:
        text = (f"Topic: {t['name']:<{width}} | Type: {t['type']:<{twidth}} | Count: {t['message_count']} | "
                f"Serialization Format: {t['serialization_format']} | QoS: {_qos(t['offered_qos'])}"
                + (" | latched" if t["latched"] else ""))
        if first:
            row("Topic information", text)
            first = False
        else:
            lines.append(" " * label + text)
    if not topics:
        row("Topic information", "(none)")
    for i, note in enumerate(info["notes"]):
        if i == 0:
            row("Notes", note)
        else:
            lines.append(" " * label + note)
    return "\n".join(lines)
