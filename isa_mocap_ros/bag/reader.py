"""Read rosbag2 MCAP bags: a rosbag2 directory (metadata.yaml v1-9) or a bare ``.mcap`` file.

File names come from ``relative_file_paths`` (resolved against the bag directory, then its
parent, as rosbag2 does for old bags). Topic QoS comes from ``metadata.yaml`` when present,
else from each channel's ``offered_qos_profiles`` metadata (MCAP ``ros2`` profile). Messages
of all files are merged into one log-time order. A file without a summary (a killed writer)
is read sequentially up to its last complete record; what was left out is said in ``notes``.
"""
from __future__ import annotations

import heapq
from pathlib import Path
from typing import Iterable, Iterator

from .mcapfile import McapIndex, iter_messages, open_mcap
from .metadata import METADATA_FILE, BagMetadata, read_metadata
from .model import BagError, BagMessage, TopicInfo, qos_from_yaml


def resolve_bag(path: str | Path) -> tuple[Path, BagMetadata | None, list[Path], list[str]]:
    """(bag path, metadata or None, storage files, notes) for a bag directory or a bare MCAP.

    Raises
    ------
    BagError
        When the path does not exist, a directory holds neither ``metadata.yaml`` nor ``.mcap``
        files, the metadata names a file that is missing, or the storage is not MCAP.
    """
    path = Path(path)
    notes: list[str] = []
    if path.is_file() and path.name == METADATA_FILE:
        path = path.parent
    if path.is_file():
        return path, None, [path], notes
    if not path.is_dir():
        raise BagError(f"{path}: expected a rosbag2 directory or an .mcap file, found nothing at this path")
    if not (path / METADATA_FILE).is_file():
        mcaps = sorted(p for p in path.iterdir() if p.suffix == ".mcap" and p.is_file())
        if not mcaps:
            content = sorted(p.name for p in path.iterdir())[:10]
            raise BagError(f"{path}: expected a rosbag2 directory with {METADATA_FILE} or .mcap files, "
                           f"found neither (contents: {content})")
        notes.append(f"{path / METADATA_FILE} is missing; metadata derived from "
                     f"{', '.join(p.name for p in mcaps)}")
        return path, None, mcaps, notes
    md = read_metadata(path)
    where = f"{path / METADATA_FILE}"
    if md.storage_identifier != "mcap":
        raise BagError(f"{where}: storage_identifier expected 'mcap', received {md.storage_identifier!r} "
                       "(convert the bag with `ros2 bag convert` or rosbags-convert)")
    if md.compression_mode not in ("", "none", "NONE"):
        raise BagError(f"{where}: compression_mode expected '' (MCAP chunk compression), received "
                       f"{md.compression_mode!r} (rosbag2 file/message compression is not supported)")
    if not md.relative_file_paths:
        raise BagError(f"{where}: relative_file_paths expected at least one file, received []")
    files = []
    for rel in md.relative_file_paths:
        candidates = [path / rel, path.parent / rel]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            raise BagError(f"{where}: relative_file_paths names {rel!r}, expected it at {path / rel}, "
                           "found no such file")
        files.append(found)
    return path, md, files, notes


class BagReader:
    """Read a rosbag2 MCAP bag.

    Parameters
    ----------
    path : str or Path
        A rosbag2 directory (``metadata.yaml`` version 1-9 plus the files it names; without
        ``metadata.yaml`` every ``.mcap`` in it, with a note) or a bare ``.mcap`` file.

    Attributes
    ----------
    path : Path
    topics : dict[str, TopicInfo]
        By topic name, in recorded order.
    start_ns, end_ns, duration_ns : int
        First and last log time and their difference (0 for an empty bag).
    message_count : int
    notes : list[str]
        What was derived or recovered rather than read as written (missing metadata.yaml, files
        without an index, torn tails, disagreeing counts).
    metadata : BagMetadata or None
        The parsed ``metadata.yaml``, if any.

    Examples
    --------
    >>> with BagReader("bags/demo") as bag:                      # doctest: +SKIP
    ...     for m in bag.messages(["/joint_states"]):
    ...         print(m.log_time_ns, len(m.data))
    """

    def __init__(self, path: str | Path):
        self.path, self.metadata, paths, self.notes = resolve_bag(path)
        self._files: list[McapIndex] = [open_mcap(p) for p in paths]
        self._closed = False
        for f in self._files:
            if not f.complete:
                tail = (f"; {f.dropped_bytes} trailing bytes dropped ({f.stop_reason})"
                        if f.dropped_bytes else "")
                self.notes.append(f"{f.path.name}: no summary/index (writer killed or file cut); read "
                                  f"sequentially, {f.message_count} complete messages{tail}. "
                                  "`isa-mocap bag repair` rewrites it as a complete bag")
            if f.profile not in ("ros2", ""):
                self.notes.append(f"{f.path.name}: MCAP profile {f.profile!r}, expected 'ros2'")
        self._build_topics()

    # -- construction --------------------------------------------------------------------------
    def _build_topics(self) -> None:
        topics: dict[str, dict] = {}
        self._schemas: dict[str, str] = {}
        self._chan: list[dict[int, tuple[str, str]]] = []
        for f in self._files:
            cmap: dict[int, tuple[str, str]] = {}
            for cid, ch in f.channels.items():
                schema = f.schema_of(ch)
                type_name = schema.name if schema is not None else ""
                if schema is not None and type_name not in self._schemas:
                    self._schemas[type_name] = bytes(schema.data).decode("utf-8", errors="replace")
                cmap[cid] = (ch.topic, type_name)
                t = topics.setdefault(ch.topic, {"type": type_name, "fmt": ch.message_encoding,
                                                 "qos": None, "hash": "", "count": 0})
                if t["qos"] is None and ch.metadata.get("offered_qos_profiles"):
                    try:
                        t["qos"] = qos_from_yaml(ch.metadata["offered_qos_profiles"],
                                                 where=f"{f.path.name}: channel {ch.topic} offered_qos_profiles")
                    except BagError as exc:
                        self.notes.append(f"{exc}; QoS left empty")
                t["hash"] = t["hash"] or ch.metadata.get("topic_type_hash", "")
                t["count"] += f.counts.get(cid, 0)
            self._chan.append(cmap)
        md_topics = {t.name: t for t in self.metadata.topics} if self.metadata else {}
        self.topics: dict[str, TopicInfo] = {}
        for name, t in topics.items():
            m = md_topics.get(name)
            if m is not None and m.message_count != t["count"]:
                self.notes.append(f"{METADATA_FILE}: topic {name} message_count is {m.message_count}, "
                                  f"the storage holds {t['count']}; using {t['count']}")
            qos = m.offered_qos if m is not None and m.offered_qos else (t["qos"] or ())
            self.topics[name] = TopicInfo(
                name=name, type=t["type"] or (m.type if m else ""),
                serialization_format=t["fmt"] or (m.serialization_format if m else "cdr"),
                offered_qos=tuple(qos), message_count=t["count"],
                type_description_hash=(m.type_description_hash if m and m.type_description_hash else t["hash"]))
        for name, m in md_topics.items():  # topics announced but without any channel in storage
            if name not in self.topics:
                self.topics[name] = TopicInfo(name=name, type=m.type, serialization_format=m.serialization_format,
                                              offered_qos=m.offered_qos, message_count=0,
                                              type_description_hash=m.type_description_hash)
        with_msgs = [f for f in self._files if f.message_count]
        self.message_count = sum(f.message_count for f in self._files)
        self.start_ns = min((f.start_ns for f in with_msgs), default=0)
        self.end_ns = max((f.end_ns for f in with_msgs), default=0)
        self.duration_ns = self.end_ns - self.start_ns

    # -- public API ----------------------------------------------------------------------------
    @property
    def files(self) -> list[Path]:
        """The storage files, in the order of ``relative_file_paths``."""
        return [f.path for f in self._files]

    @property
    def size_bytes(self) -> int:
        return sum(f.size for f in self._files)

    @property
    def version(self) -> int | None:
        """``metadata.yaml`` version, None for a bare MCAP or a directory without metadata."""
        return self.metadata.version if self.metadata else None

    @property
    def ros_distro(self) -> str:
        if self.metadata and self.metadata.ros_distro:
            return self.metadata.ros_distro
        for f in self._files:
            ser = f.metadata.get("rosbag2", {})
            if "ROS_DISTRO" in ser:
                return ser["ROS_DISTRO"]
        return ""

    @property
    def compression(self) -> str:
        """MCAP chunk compression of the first file that has chunks ('' if none)."""
        return next((f.compression for f in self._files if f.compression), "")

    @property
    def indexed(self) -> bool:
        """True when every file has a summary section (none needed a sequential scan)."""
        return all(f.complete for f in self._files)

    def msgdef(self, type_name: str) -> str:
        """The ``ros2msg`` schema text stored in the bag for ``type_name``.

        Raises
        ------
        BagError
            When no schema for that type is stored.
        """
        try:
            return self._schemas[type_name]
        except KeyError:
            raise BagError(f"{self.path}: msgdef type_name expected one of {sorted(self._schemas)}, "
                           f"received {type_name!r}") from None

    def messages(self, topics: Iterable[str] | None = None, *, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[BagMessage]:
        """Messages in log-time order (ties in file order), ``start_ns <= log_time_ns <= end_ns``.

        Parameters
        ----------
        topics : iterable of str, optional
            Only these topics; each must be in ``self.topics``. None: all topics.
        start_ns, end_ns : int, optional
            Inclusive log-time bounds in ns.

        Raises
        ------
        BagError
            For a topic the bag does not hold, after ``close()``, or when a block cannot be read.
        """
        if self._closed:
            raise BagError(f"{self.path}: messages() called after close()")
        wanted: set[str] | None = None
        if topics is not None:
            wanted = set([topics] if isinstance(topics, str) else topics)
            unknown = sorted(wanted - set(self.topics))
            if unknown:
                raise BagError(f"{self.path}: topics expected a subset of {sorted(self.topics)}, "
                               f"received unknown {unknown}")
        for name, value in (("start_ns", start_ns), ("end_ns", end_ns)):
            if value is not None and (not isinstance(value, int) or isinstance(value, bool)):
                raise BagError(f"messages(): {name} expected an int in ns or None, received {value!r}")
        return self._merged(wanted, start_ns, end_ns)

    def _merged(self, wanted, start_ns, end_ns) -> Iterator[BagMessage]:
        iters = []
        for f, cmap in zip(self._files, self._chan):
            ids = None if wanted is None else {cid for cid, (t, _) in cmap.items() if t in wanted}
            if ids is not None and not ids:
                continue
            iters.append(self._file_messages(f, cmap, ids, start_ns, end_ns))
        yield from heapq.merge(*iters, key=lambda m: m.log_time_ns)

    @staticmethod
    def _file_messages(f: McapIndex, cmap, ids, start_ns, end_ns) -> Iterator[BagMessage]:
        try:
            for m in iter_messages(f, channel_ids=ids, start_ns=start_ns, end_ns=end_ns):
                try:
                    topic, type_name = cmap[m.channel_id]
                except KeyError:
                    raise BagError(f"{f.path}: message on channel id {m.channel_id}, expected one of "
                                   f"{sorted(cmap)}") from None
                yield BagMessage(topic, type_name, m.log_time, m.publish_time, bytes(m.data))
        except OSError as exc:
            raise BagError(f"{f.path}: could not be read: {exc}") from None

    def close(self) -> None:
        self._closed = True

    def __enter__(self) -> "BagReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"BagReader({str(self.path)!r}: {len(self.topics)} topics, {self.message_count} messages, "
                f"{self.duration_ns / 1e9:.3f} s)")
