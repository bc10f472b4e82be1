"""Write rosbag2 MCAP bags incrementally: ``<dir>/<dir>_0.mcap`` plus ``<dir>/metadata.yaml``.

The MCAP file follows the ``ros2`` profile as rosbag2's jazzy MCAP storage plugin writes it
(``rosbag2_storage_mcap/src/mcap_storage.cpp``): schema encoding ``ros2msg`` with the
``=====``-separated dependency text, message encoding ``cdr``, channel metadata
``offered_qos_profiles`` (YAML text: names for metadata version 9, rmw integers for 8) and
``topic_type_hash`` (RIHS01, empty when unknown); chunked (zstd, lz4 or none) with message
indexes, chunk indexes and statistics; at close a ``rosbag2`` metadata record holding
``serialized_metadata`` and then ``metadata.yaml`` (see :mod:`.metadata`). ``flush()``
closes the open chunk and fsyncs, so everything written before it survives a SIGKILL.
"""
from __future__ import annotations

import os
import re
import shutil
from pathlib import Path
from typing import Sequence

from mcap.writer import LIBRARY_IDENTIFIER, CompressionType
from mcap.writer import Writer as _McapWriter

from .metadata import METADATA_FILE, BagMetadata, FileInfo, fsync_dir, write_metadata
from .model import QOS_DEFAULT, BagError, QosProfile, TopicInfo, qos_to_yaml

_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
_TYPE_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*/msg/[A-Za-z][A-Za-z0-9_]*$")
_BAG_FILE_SUFFIXES = {".mcap", ".yaml", ".tmp", ".db3", ".zstd"}
LIBRARY = "isa_mocap_ros"

_typestore = None


def typestore():
    """The rosbags ROS 2 Jazzy typestore (loaded once)."""
    global _typestore
    if _typestore is None:
        from rosbags.typesys import Stores, get_typestore

        _typestore = get_typestore(Stores.ROS2_JAZZY)
    return _typestore


def msgdef_for(type_name: str) -> tuple[str, str]:
    """(ros2msg schema text, RIHS01 type hash) of a ROS 2 Jazzy type from the rosbags typestore.

    Raises
    ------
    BagError
        When the type is not in the typestore.
    """
    from rosbags.typesys import TypesysError

    ts = typestore()
    try:
        text, _ = ts.generate_msgdef(type_name, ros_version=2)
        rihs = ts.hash_rihs01(type_name)
    except (TypesysError, KeyError) as exc:
        raise BagError(f"type_name {type_name!r}: expected a ROS 2 Jazzy message type known to the rosbags "
                       f"typestore (or pass msgdef=), received an unknown type ({exc})") from None
    return text, rihs


def _finish_chunk(writer: _McapWriter) -> None:
    """Write the open chunk (with its message index) and flush the writer's stream.

    mcap 1.6 (tested) has the public ``Writer.flush()``; for releases without it the private,
    name-mangled ``__finalize_chunk`` is used, here and nowhere else.
    """
    if hasattr(writer, "flush"):
        writer.flush()
    else:  # pragma: no cover - older mcap releases
        writer._Writer__finalize_chunk()


def _remove_old_bag(path: Path) -> None:
    if path.is_file() or path.is_symlink():
        path.unlink()
        return
    entries = list(path.iterdir())
    foreign = [e.name for e in entries if not e.is_file() or e.suffix not in _BAG_FILE_SUFFIXES]
    if foreign:
        raise BagError(f"{path}: overwrite=True expected a bag directory (only .mcap/.yaml files), "
                       f"received one that also holds {foreign[:5]}; refusing to delete it")
    shutil.rmtree(path)


class BagWriter:
    """Write a rosbag2 MCAP bag directory incrementally.

    Parameters
    ----------
    path : str or Path
        The bag directory to create; it will hold ``<name>_0.mcap`` and ``metadata.yaml``.
    version : {9, 8}
        rosbag2 metadata version (9: jazzy and later; 8: iron).
    compression : {"zstd", "lz4", "none"}
        MCAP chunk compression.
    chunk_size : int
        Uncompressed bytes after which a chunk is closed and written.
    overwrite : bool
        Replace an existing bag directory at ``path`` (a directory holding other files is
        never deleted).
    ros_distro : str, optional
        Written to ``metadata.yaml``; default ``$ROS_DISTRO`` or ``"jazzy"``.
    custom_data : dict[str, str], optional
        rosbag2 ``custom_data``.

    Raises
    ------
    BagError
        For a bad argument, or an existing ``path`` without ``overwrite``.

    Examples
    --------
    >>> with BagWriter(tmp / "bag") as w:                       # doctest: +SKIP
    ...     w.add_topic("/joint_states", "sensor_msgs/msg/JointState", qos=[QOS_LATCHED])
    ...     w.write("/joint_states", cdr_bytes, log_time_ns=1_000)
    """

    def __init__(self, path: str | Path, *, version: int = 9, compression: str = "zstd",
                 chunk_size: int = 4 * 1024 * 1024, overwrite: bool = False, ros_distro: str | None = None,
                 custom_data: dict[str, str] | None = None):
        if version not in (8, 9):
            raise BagError(f"BagWriter version: expected 8 or 9, received {version!r}")
        if compression not in _COMPRESSION:
            raise BagError(f"BagWriter compression: expected one of {list(_COMPRESSION)}, received {compression!r}")
        if not isinstance(chunk_size, int) or isinstance(chunk_size, bool) or chunk_size < 1:
            raise BagError(f"BagWriter chunk_size: expected an int >= 1 (bytes), received {chunk_size!r}")
        custom = dict(custom_data or {})
        if not all(isinstance(k, str) and isinstance(v, str) for k, v in custom.items()):
            raise BagError(f"BagWriter custom_data: expected str keys and values, received {custom!r}")
        path = Path(path)
        if path.exists() or path.is_symlink():
            if not overwrite:
                raise BagError(f"{path}: BagWriter expected a path that does not exist yet, it exists "
                               "(pass overwrite=True to replace a bag)")
            _remove_old_bag(path)
        self.path = path
        self.version = version
        self.compression = compression
        self.ros_distro = ros_distro if ros_distro is not None else os.environ.get("ROS_DISTRO", "jazzy")
        self.custom_data = custom
        path.mkdir(parents=True)
        self.mcap_path = path / f"{path.name}_0.mcap"
        self._fh = open(self.mcap_path, "wb")
        self._mcap = _McapWriter(self._fh, chunk_size=chunk_size, compression=_COMPRESSION[compression])
        self._mcap.start(profile="ros2", library=f"{LIBRARY}; {LIBRARY_IDENTIFIER}")
        self._sync()
        fsync_dir(path)
        self._schema_ids: dict[str, int] = {}
        self._hashes: dict[str, str] = {}
        self._topics: dict[str, dict] = {}
        self._start_ns: int | None = None
        self._end_ns = 0
        self._count = 0
        self._closed = False

    # -- topics ---------------------------------------------------------------------------------
    def add_topic(self, name: str, type_name: str, *, qos: Sequence[QosProfile] | None = None,
                  msgdef: str | None = None, type_description_hash: str | None = None) -> None:
        """Declare a topic before writing to it.

        Parameters
        ----------
        name : str
            Fully qualified topic name (``/cam0/image``).
        type_name : str
            ``pkg/msg/Type``.
        qos : sequence of QosProfile, optional
            The profiles offered by the recorded publishers; default ``[QOS_DEFAULT]``; an empty
            sequence records no QoS.
        msgdef : str, optional
            ``ros2msg`` schema text (with dependencies); default from the rosbags Jazzy typestore.
        type_description_hash : str, optional
            RIHS01 hash; default from the typestore when it knows the type, else empty.

        Raises
        ------
        BagError
            For an unknown type without ``msgdef``, a malformed name or type, a non-QosProfile in
            ``qos``, or a topic added before with a different type or QoS.
        """
        self._check_open("add_topic")
        if not isinstance(name, str) or not name.strip():
            raise BagError(f"add_topic name: expected a non-empty topic name, received {name!r}")
        if not isinstance(type_name, str) or not _TYPE_RE.match(type_name):
            raise BagError(f"add_topic type_name: expected 'pkg/msg/Type', received {type_name!r}")
        profiles = (QOS_DEFAULT,) if qos is None else tuple(qos)
        for q in profiles:
            if not isinstance(q, QosProfile):
                raise BagError(f"add_topic qos: expected QosProfile items, received {q!r}")
        if name in self._topics:
            old = self._topics[name]
            if old["type"] == type_name and old["qos"] == profiles:
                return
            raise BagError(f"add_topic {name}: already added as {old['type']} with {len(old['qos'])} QoS "
                           f"profile(s), received {type_name} with {len(profiles)} different one(s)")
        if type_name in self._schema_ids:
            rihs = self._hashes[type_name]
        else:
            if msgdef is None:
                msgdef, rihs = msgdef_for(type_name)
            else:
                if not isinstance(msgdef, str):
                    raise BagError(f"add_topic msgdef: expected ros2msg text, received {type(msgdef).__name__}")
                try:
                    rihs = msgdef_for(type_name)[1]
                except BagError:
                    rihs = ""
            self._schema_ids[type_name] = self._mcap.register_schema(type_name, "ros2msg", msgdef.encode())
            self._hashes[type_name] = rihs
        if type_description_hash is not None:
            rihs = type_description_hash
        meta = {"offered_qos_profiles": qos_to_yaml(profiles, version=self.version), "topic_type_hash": rihs}
        cid = self._mcap.register_channel(topic=name, message_encoding="cdr",
                                          schema_id=self._schema_ids[type_name], metadata=meta)
        self._topics[name] = {"id": cid, "type": type_name, "qos": profiles, "hash": rihs, "count": 0}

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """The topics added so far, with the number of messages written to each."""
        return {n: TopicInfo(n, t["type"], "cdr", t["qos"], t["count"], t["hash"]) for n, t in self._topics.items()}

    @property
    def message_count(self) -> int:
        return self._count

    # -- messages -------------------------------------------------------------------------------
    def write(self, topic: str, data: bytes, log_time_ns: int, *, publish_time_ns: int | None = None) -> None:
        """Append one CDR-serialized message.

        Raises
        ------
        BagError
            For a topic not added, data that is not bytes-like, or a time that is not an int >= 0.
        """
        self._check_open("write")
        t = self._topics.get(topic)
        if t is None:
            raise BagError(f"write topic: expected one added with add_topic {sorted(self._topics)}, "
                           f"received {topic!r}")
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise BagError(f"write data: expected CDR bytes, received {type(data).__name__}")
        for key, value in (("log_time_ns", log_time_ns), ("publish_time_ns", publish_time_ns)):
            if value is None and key == "publish_time_ns":
                continue
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < 2**64:
                raise BagError(f"write {key}: expected an int in [0, 2**64) ns, received {value!r}")
        publish = log_time_ns if publish_time_ns is None else publish_time_ns
        self._mcap.add_message(channel_id=t["id"], log_time=log_time_ns, data=bytes(data),
                               publish_time=publish, sequence=0)
        t["count"] += 1
        self._count += 1
        self._start_ns = log_time_ns if self._start_ns is None else min(self._start_ns, log_time_ns)
        self._end_ns = max(self._end_ns, log_time_ns)

    def flush(self) -> None:
        """Close the open chunk, write it with its message index and fsync the file."""
        self._check_open("flush")
        _finish_chunk(self._mcap)
        self._sync()

    def _sync(self) -> None:
        self._fh.flush()
        os.fsync(self._fh.fileno())

    # -- close ----------------------------------------------------------------------------------
    def bag_metadata(self) -> BagMetadata:
        """The metadata as it stands now (what ``close()`` writes)."""
        start = self._start_ns or 0
        duration = self._end_ns - start if self._count else 0
        return BagMetadata(
            version=self.version, storage_identifier="mcap", relative_file_paths=[self.mcap_path.name],
            starting_time_ns=start, duration_ns=duration, message_count=self._count,
            topics=list(self.topics.values()), compression_format="", compression_mode="",
            files=[FileInfo(self.mcap_path.name, start, duration, self._count)],
            custom_data=dict(self.custom_data), ros_distro=self.ros_distro)

    def close(self) -> None:
        """Finish the MCAP (summary, indexes, footer) and write ``metadata.yaml``. Idempotent."""
        if self._closed:
            return
        self._closed = True
        md = self.bag_metadata()
        try:
            _finish_chunk(self._mcap)
            self._mcap.add_metadata("rosbag2", {"serialized_metadata": md.to_yaml(wrapped=False)})
            self._mcap.finish()
            self._sync()
        finally:
            self._fh.close()
        write_metadata(self.path, md)

    @property
    def closed(self) -> bool:
        return self._closed

    def _check_open(self, what: str) -> None:
        if self._closed:
            raise BagError(f"{self.path}: {what}() called after close()")

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()  # also on an exception: what was written is kept as a complete bag

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"BagWriter({str(self.path)!r}, {state}, {len(self._topics)} topics, {self._count} messages)"


__all__ = ["BagWriter", "METADATA_FILE", "msgdef_for", "typestore"]
