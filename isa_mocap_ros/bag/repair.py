"""Repair a bag whose writer died: recover every complete message, rebuild index and metadata.

A writer killed by SIGKILL leaves an MCAP file with a header, schemas/channels, the chunks it
had flushed (each followed by its message indexes) and perhaps a torn last record, but no
summary, footer or ``metadata.yaml``. :func:`repair_bag` scans such a file record by record
(:func:`.mcapfile.scan_mcap`, stopping at the torn tail), rewrites the recovered records as a
complete indexed MCAP into a temporary file beside it, fsyncs it and renames it over the
original (``os.replace``: atomic), then writes ``metadata.yaml`` (MCAP spec, "Summary
Section"; rosbag2 ``metadata.yaml`` layout as in :mod:`.metadata`).
"""
from __future__ import annotations

import os
from pathlib import Path

from mcap.writer import LIBRARY_IDENTIFIER, CompressionType
from mcap.writer import Writer as _McapWriter

from .mcapfile import McapIndex, open_mcap, read_block
from .metadata import METADATA_FILE, BagMetadata, FileInfo, fsync_dir, read_metadata, write_metadata
from .model import BagError, TopicInfo, qos_from_yaml
from .writer import LIBRARY

_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "": CompressionType.NONE}


def _infer_version(indexes: list[McapIndex]) -> int:
    """8 when channel QoS uses rmw integers (iron and older), else 9."""
    import yaml

    for idx in indexes:
        for ch in idx.channels.values():
            text = ch.metadata.get("offered_qos_profiles", "")
            try:
                items = yaml.safe_load(text) if text else None
            except yaml.YAMLError:
                continue
            if isinstance(items, list) and items and isinstance(items[0], dict):
                return 8 if isinstance(items[0].get("history"), int) else 9
    return 9


def _derive_metadata(indexes: list[McapIndex], *, version: int, old: BagMetadata | None,
                     notes: list[str]) -> BagMetadata:
    topics: dict[str, dict] = {}
    for idx in indexes:
        for cid, ch in idx.channels.items():
            schema = idx.schema_of(ch)
            t = topics.setdefault(ch.topic, {"type": schema.name if schema else "", "fmt": ch.message_encoding,
                                             "qos": (), "hash": "", "count": 0})
            if not t["qos"] and ch.metadata.get("offered_qos_profiles"):
                try:
                    t["qos"] = qos_from_yaml(ch.metadata["offered_qos_profiles"],
                                             where=f"{idx.path.name}: channel {ch.topic}")
                except BagError as exc:
                    notes.append(f"{exc}; QoS left empty")
            t["hash"] = t["hash"] or ch.metadata.get("topic_type_hash", "")
            t["count"] += idx.counts.get(cid, 0)
    with_msgs = [i for i in indexes if i.message_count]
    start = min((i.start_ns for i in with_msgs), default=0)
    end = max((i.end_ns for i in with_msgs), default=0)
    count = sum(i.message_count for i in indexes)
    return BagMetadata(
        version=version, storage_identifier="mcap", relative_file_paths=[i.path.name for i in indexes],
        starting_time_ns=start, duration_ns=end - start, message_count=count,
        topics=[TopicInfo(n, t["type"], t["fmt"] or "cdr", tuple(t["qos"]), t["count"], t["hash"])
                for n, t in topics.items()],
        files=[FileInfo(i.path.name, i.start_ns, i.end_ns - i.start_ns, i.message_count) for i in indexes],
        custom_data=dict(old.custom_data) if old else {},
        ros_distro=(old.ros_distro if old and old.ros_distro else os.environ.get("ROS_DISTRO", "jazzy")))


def _rewrite(idx: McapIndex, md: BagMetadata | None) -> None:
    """Write the recovered content of ``idx`` as a complete MCAP and atomically replace the file."""
    tmp = idx.path.with_name(idx.path.name + ".repair.tmp")
    try:
        with open(idx.path, "rb") as src, open(tmp, "wb") as out:
            w = _McapWriter(out, chunk_size=4 * 1024 * 1024,
                            compression=_COMPRESSION.get(idx.compression, CompressionType.ZSTD))
            w.start(profile=idx.profile or "ros2", library=idx.library or f"{LIBRARY}; {LIBRARY_IDENTIFIER}")
            schema_ids = {sid: w.register_schema(s.name, s.encoding, bytes(s.data))
                          for sid, s in sorted(idx.schemas.items())}
            channel_ids = {cid: w.register_channel(c.topic, c.message_encoding, schema_ids.get(c.schema_id, 0),
                                                   dict(c.metadata))
                           for cid, c in sorted(idx.channels.items())}
            for block in sorted(idx.blocks, key=lambda b: b.offset):
                for m in read_block(src, block, path=idx.path):
                    w.add_message(channel_ids[m.channel_id], m.log_time, bytes(m.data), m.publish_time, m.sequence)
            for name, meta in idx.metadata.items():
                if name != "rosbag2" or md is None:
                    w.add_metadata(name, meta)
            if md is not None:
                w.add_metadata("rosbag2", {"serialized_metadata": md.to_yaml(wrapped=False)})
            w.finish()
            out.flush()
            os.fsync(out.fileno())
        os.replace(tmp, idx.path)
        fsync_dir(idx.path.parent)
    finally:
        if tmp.exists():
            tmp.unlink()


def repair_bag(path: str | Path, *, version: int | None = None) -> dict:
    """Make a bag whose writer was killed complete and readable again.

    Parameters
    ----------
    path : str or Path
        A rosbag2 directory (with or without ``metadata.yaml``) or a bare ``.mcap`` file.
    version : {8, 9}, optional
        ``metadata.yaml`` version to write; default: the old metadata's, else inferred from the
        channels' QoS spelling (integers: 8), else 9.

    Returns
    -------
    dict
        ``messages`` (recovered, int), ``topics`` (name -> count), ``dropped_bytes`` (torn tail
        bytes left out, int), ``files`` (names), ``rewritten`` (names of files rewritten;
        complete files are left untouched), ``metadata_written`` (bool), ``notes`` (list[str]).

    Raises
    ------
    BagError
        When the path holds no MCAP file, a file is not MCAP, or ``version`` is not 8 or 9.
    """
    if version is not None and version not in (8, 9):
        raise BagError(f"repair_bag version: expected 8, 9 or None, received {version!r}")
    path = Path(path)
    if path.is_file() and path.name == METADATA_FILE:
        path = path.parent
    notes: list[str] = []
    old: BagMetadata | None = None
    if path.is_file():
        bag_dir, files = None, [path]
    elif path.is_dir():
        bag_dir = path
        if (path / METADATA_FILE).is_file():
            try:
                old = read_metadata(path)
            except BagError as exc:
                notes.append(f"ignored unreadable metadata: {exc}")
        files = []
        if old is not None:
            files = [path / p for p in old.relative_file_paths if (path / p).is_file()]
            missing = [p for p in old.relative_file_paths if not (path / p).is_file()]
            if missing:
                notes.append(f"{METADATA_FILE} names missing files {missing}; using the .mcap files present")
                files = []
        if not files:
            files = sorted(p for p in path.iterdir() if p.suffix == ".mcap" and p.is_file())
        if not files:
            raise BagError(f"{path}: repair expected .mcap files in the bag directory, found none")
    else:
        raise BagError(f"{path}: repair expected a rosbag2 directory or an .mcap file, found nothing")

    indexes = [open_mcap(f) for f in files]
    broken = [i for i in indexes if not i.complete]
    if version is None:
        version = old.version if old is not None and old.version in (8, 9) else _infer_version(indexes)
    md = _derive_metadata(indexes, version=version, old=old, notes=notes) if bag_dir is not None else None
    for idx in broken:
        if idx.stop_reason:
            notes.append(f"{idx.path.name}: {idx.stop_reason}; {idx.dropped_bytes} bytes dropped")
        _rewrite(idx, md)
    metadata_written = False
    if bag_dir is not None and (broken or old is None):
        write_metadata(bag_dir, md)
        metadata_written = True
    topics: dict[str, int] = {}
    for idx in indexes:
        for cid, ch in idx.channels.items():
            topics[ch.topic] = topics.get(ch.topic, 0) + idx.counts.get(cid, 0)
    return {"path": str(path), "files": [f.name for f in files],
            "messages": sum(i.message_count for i in indexes), "topics": topics,
            "dropped_bytes": sum(i.dropped_bytes for i in indexes),
            "rewritten": [i.path.name for i in broken], "metadata_written": metadata_written, "notes": notes}
