"""rosbag2 ``metadata.yaml``: read versions 1-9, write version 8 or 9.

Layout as encoded by ``rosbag2_storage/include/rosbag2_storage/yaml.hpp`` (jazzy): a mapping
``rosbag2_bagfile_information`` with ``version``, ``storage_identifier``, ``duration``
(``nanoseconds``), ``starting_time`` (``nanoseconds_since_epoch``), ``message_count``,
``topics_with_message_count`` (``topic_metadata``: ``name``, ``type``,
``serialization_format``, ``offered_qos_profiles``, ``type_description_hash``; and
``message_count``), ``compression_format``, ``compression_mode``, ``relative_file_paths``,
``files`` (v5+: ``path``, ``starting_time``, ``duration``, ``message_count``),
``custom_data`` (v6+) and ``ros_distro`` (v8+). Version 9 stores ``offered_qos_profiles``
as a YAML list with policy names; versions 4-8 as one YAML *string* with rmw integers.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .model import BagError, TopicInfo, qos_from_yaml, qos_to_yaml

METADATA_FILE = "metadata.yaml"
SUPPORTED_WRITE_VERSIONS = (8, 9)


@dataclass
class FileInfo:
    """One entry of ``files``: a storage file's name, first log time, duration and count."""

    path: str
    starting_time_ns: int = 0
    duration_ns: int = 0
    message_count: int = 0


@dataclass
class BagMetadata:
    """The content of a rosbag2 ``metadata.yaml``."""

    version: int = 9
    storage_identifier: str = "mcap"
    relative_file_paths: list[str] = field(default_factory=list)
    starting_time_ns: int = 0
    duration_ns: int = 0
    message_count: int = 0
    topics: list[TopicInfo] = field(default_factory=list)
    compression_format: str = ""
    compression_mode: str = ""
    files: list[FileInfo] = field(default_factory=list)
    custom_data: dict[str, str] = field(default_factory=dict)
    ros_distro: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The inner ``rosbag2_bagfile_information`` mapping in this version's layout."""
        def topic(t: TopicInfo) -> dict[str, Any]:
            if self.version >= 9:
                qos: Any = [q.to_dict(version=self.version) for q in t.offered_qos]
            else:
                qos = qos_to_yaml(t.offered_qos, version=self.version)
            return {"topic_metadata": {"name": t.name, "type": t.type,
                                       "serialization_format": t.serialization_format,
                                       "offered_qos_profiles": qos,
                                       "type_description_hash": t.type_description_hash},
                    "message_count": t.message_count}

        return {
            "version": self.version,
            "storage_identifier": self.storage_identifier,
            "duration": {"nanoseconds": self.duration_ns},
            "starting_time": {"nanoseconds_since_epoch": self.starting_time_ns},
            "message_count": self.message_count,
            "topics_with_message_count": [topic(t) for t in self.topics],
            "compression_format": self.compression_format,
            "compression_mode": self.compression_mode,
            "relative_file_paths": list(self.relative_file_paths),
            "files": [{"path": f.path,
                       "starting_time": {"nanoseconds_since_epoch": f.starting_time_ns},
                       "duration": {"nanoseconds": f.duration_ns},
                       "message_count": f.message_count} for f in self.files],
            "custom_data": dict(self.custom_data) or None,
            "ros_distro": self.ros_distro,
        }

    def to_yaml(self, *, wrapped: bool = True) -> str:
        """YAML text; ``wrapped`` adds the ``rosbag2_bagfile_information`` top key (the file form)."""
        body = self.to_dict()
        return yaml.safe_dump({"rosbag2_bagfile_information": body} if wrapped else body,
                              sort_keys=False, default_flow_style=False)


def _get(d: dict, key: str, typ: type | tuple, where: str, *, default: Any = ...) -> Any:
    if key not in d or d[key] is None:
        if default is ...:
            raise BagError(f"{where}: expected key {key!r}, received keys {sorted(d)}")
        return default
    value = d[key]
    if not isinstance(value, typ) or (typ is int and isinstance(value, bool)):
        tname = typ.__name__ if isinstance(typ, type) else "/".join(t.__name__ for t in typ)
        raise BagError(f"{where}: {key} expected {tname}, received {value!r}")
    return value


def _ns(d: dict, key: str, sub: str, where: str, *, default: int | None = None) -> int:
    node = _get(d, key, dict, where, default={sub: default} if default is not None else ...)
    return int(_get(node, sub, int, f"{where}.{key}"))


def parse_metadata(doc: Any, *, where: str) -> BagMetadata:
    """Validate a loaded ``metadata.yaml`` document and return its content."""
    if not isinstance(doc, dict) or "rosbag2_bagfile_information" not in doc:
        keys = sorted(doc) if isinstance(doc, dict) else type(doc).__name__
        raise BagError(f"{where}: expected a mapping with key 'rosbag2_bagfile_information', received {keys}")
    info = doc["rosbag2_bagfile_information"]
    if not isinstance(info, dict):
        raise BagError(f"{where}: rosbag2_bagfile_information expected a mapping, received {info!r}")
    w = f"{where}: rosbag2_bagfile_information"
    version = _get(info, "version", int, w)
    if version < 1:
        raise BagError(f"{w}.version expected >= 1, received {version}")
    md = BagMetadata(version=version)
    md.storage_identifier = _get(info, "storage_identifier", str, w)
    paths = _get(info, "relative_file_paths", list, w)
    if not all(isinstance(p, str) and p for p in paths):
        raise BagError(f"{w}.relative_file_paths expected non-empty strings, received {paths!r}")
    md.relative_file_paths = list(paths)
    md.duration_ns = _ns(info, "duration", "nanoseconds", w, default=0)
    md.starting_time_ns = _ns(info, "starting_time", "nanoseconds_since_epoch", w, default=0)
    md.message_count = _get(info, "message_count", int, w, default=0)
    md.compression_format = _get(info, "compression_format", str, w, default="")
    md.compression_mode = _get(info, "compression_mode", str, w, default="")
    custom = _get(info, "custom_data", dict, w, default={})
    md.custom_data = {str(k): str(v) for k, v in custom.items()}
    md.ros_distro = str(_get(info, "ros_distro", str, w, default=""))
    for i, entry in enumerate(_get(info, "topics_with_message_count", list, w, default=[])):
        we = f"{w}.topics_with_message_count[{i}]"
        if not isinstance(entry, dict):
            raise BagError(f"{we}: expected a mapping, received {entry!r}")
        tm = _get(entry, "topic_metadata", dict, we)
        name = _get(tm, "name", str, f"{we}.topic_metadata")
        md.topics.append(TopicInfo(
            name=name,
            type=_get(tm, "type", str, f"{we}.topic_metadata"),
            serialization_format=_get(tm, "serialization_format", str, f"{we}.topic_metadata", default="cdr"),
            offered_qos=qos_from_yaml(tm.get("offered_qos_profiles"),
                                      where=f"{where}: topic {name} offered_qos_profiles"),
            message_count=_get(entry, "message_count", int, we, default=0),
            type_description_hash=str(tm.get("type_description_hash") or ""),
        ))
    for i, entry in enumerate(_get(info, "files", list, w, default=[])):
        wf = f"{w}.files[{i}]"
        if not isinstance(entry, dict):
            raise BagError(f"{wf}: expected a mapping, received {entry!r}")
        md.files.append(FileInfo(path=_get(entry, "path", str, wf),
                                 starting_time_ns=_ns(entry, "starting_time", "nanoseconds_since_epoch", wf, default=0),
                                 duration_ns=_ns(entry, "duration", "nanoseconds", wf, default=0),
                                 message_count=_get(entry, "message_count", int, wf, default=0)))
    return md


def read_metadata(bag_dir: str | Path) -> BagMetadata:
    """Read and validate ``bag_dir/metadata.yaml``.

    Raises
    ------
    BagError
        When the file is missing, is not YAML, or a field is missing or of the wrong type.
    """
    path = Path(bag_dir) / METADATA_FILE
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise BagError(f"{path}: expected a rosbag2 metadata file, found none") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BagError(f"{path}: could not be read: {exc}") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise BagError(f"{path}: expected YAML, could not parse it: {exc}") from None
    return parse_metadata(doc, where=str(path))


def write_metadata(bag_dir: str | Path, md: BagMetadata) -> Path:
    """Write ``bag_dir/metadata.yaml`` atomically (temp file, fsync, rename).

    Raises
    ------
    BagError
        When ``md.version`` is not 8 or 9.
    """
    if md.version not in SUPPORTED_WRITE_VERSIONS:
        raise BagError(f"metadata version: expected one of {SUPPORTED_WRITE_VERSIONS}, received {md.version!r}")
    path = Path(bag_dir) / METADATA_FILE
    tmp = path.with_name(METADATA_FILE + ".tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(md.to_yaml())
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    fsync_dir(path.parent)
    return path


def fsync_dir(path: Path) -> None:
    """Make a rename or a new file in ``path`` durable (no-op where directories cannot be opened)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
