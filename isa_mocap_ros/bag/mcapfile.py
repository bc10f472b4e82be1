"""One MCAP file: its schemas, channels and a block index, from the summary or a sequential scan.

Follows the MCAP specification (https://mcap.dev/spec, records and opcodes; the ``ros2``
profile: ``ros2msg`` schemas, ``cdr`` messages, channel metadata ``offered_qos_profiles`` and
``topic_type_hash``). A complete file is indexed from its summary section (chunk indexes and
statistics). A file without a usable summary -- its writer was killed, or the file was cut --
is scanned record by record from the start; the scan stops cleanly at the first record that
is torn (shorter than its length field), undecodable or fails its CRC, and reports the bytes it
dropped. Messages are then read block by block (a block is one chunk, or one message outside
any chunk) and merged into log-time order with a heap that holds only the blocks overlapping
the current time.
"""
from __future__ import annotations

import heapq
import io
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Header, Message, Metadata, Schema

from .model import BagError

MAGIC = bytes((137, 77, 67, 65, 80, 48, 13, 10))
_RECORD_HEADER = struct.Struct("<BQ")
_KNOWN_OPCODES = frozenset(int(o) for o in Opcode)


@dataclass(frozen=True)
class Block:
    """A chunk (or a lone message record) at ``offset`` spanning ``length`` bytes incl. its header."""

    offset: int
    length: int
    start_ns: int
    end_ns: int
    channel_ids: frozenset[int] | None  # None: unknown without reading it


@dataclass
class McapIndex:
    """What one MCAP file holds, enough to list topics and to read messages in log-time order."""

    path: Path
    size: int
    profile: str = ""
    library: str = ""
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    blocks: list[Block] = field(default_factory=list)
    counts: dict[int, int] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    message_count: int = 0
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    compression: str = ""
    complete: bool = True       # summary section read (False: sequential scan)
    good_end: int = 0           # offset just after the last complete record (scan)
    dropped_bytes: int = 0      # bytes after good_end that could not be used (scan)
    stop_reason: str = ""       # why the scan stopped before a footer (scan)

    def schema_of(self, channel: Channel) -> Schema | None:
        return self.schemas.get(channel.schema_id)


def chunk_records(chunk: Chunk, *, where: str) -> list:
    """The records inside a chunk, after decompression and CRC check.

    The only use of mcap's module-level chunk helper (``mcap.stream_reader.breakup_chunk``,
    not in that module's ``__all__``); isolated here so an mcap upgrade touches one place.
    """
    from mcap.stream_reader import breakup_chunk

    try:
        return breakup_chunk(chunk, validate_crc=True)
    except (McapError, ValueError, struct.error, EOFError, RuntimeError, zlib.error) as exc:
        raise BagError(f"{where}: chunk could not be decoded ({type(exc).__name__}: {exc})") from None
    except Exception as exc:  # zstandard.ZstdError, lz4 errors: not ValueError subclasses
        raise BagError(f"{where}: chunk could not be decompressed ({type(exc).__name__}: {exc})") from None


def _parse_record(opcode: int, body: bytes):
    stream = ReadDataStream(io.BytesIO(body))
    if opcode == Opcode.HEADER:
        return Header.read(stream)
    if opcode == Opcode.SCHEMA:
        return Schema.read(stream)
    if opcode == Opcode.CHANNEL:
        return Channel.read(stream)
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, len(body))
    if opcode == Opcode.CHUNK:
        return Chunk.read(stream)
    if opcode == Opcode.METADATA:
        return Metadata.read(stream)
    return None


def _check_magic(path: Path, f) -> None:
    head = f.read(8)
    if head != MAGIC:
        raise BagError(f"{path}: expected an MCAP file starting with magic {MAGIC!r}, received {head!r}")


def open_mcap(path: str | Path) -> McapIndex:
    """Index one MCAP file: from its summary when complete, else by a sequential scan.

    Raises
    ------
    BagError
        When the file is missing, is not MCAP (bad magic) or has no readable header.
    """
    path = Path(path)
    if not path.is_file():
        raise BagError(f"{path}: expected an MCAP file, found {'a directory' if path.is_dir() else 'nothing'}")
    with open(path, "rb") as f:
        _check_magic(path, f)
        idx = _from_summary(path, f)
    return idx if idx is not None else scan_mcap(path)


def _from_summary(path: Path, f) -> McapIndex | None:
    size = path.stat().st_size
    f.seek(size - 8)
    if size < 8 + 9 + 8 or f.read(8) != MAGIC:
        return None
    try:
        f.seek(0)
        reader = SeekingReader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            return None
        stats = summary.statistics
        if stats.message_count > 0 and not summary.chunk_indexes:
            return None  # unchunked file: blocks are only known by scanning
        idx = McapIndex(path=path, size=size, profile=header.profile, library=header.library,
                        schemas=dict(summary.schemas), channels=dict(summary.channels),
                        counts=dict(stats.channel_message_counts), message_count=stats.message_count,
                        start_ns=stats.message_start_time, end_ns=stats.message_end_time,
                        good_end=size)
        for ci in summary.chunk_indexes:
            ids = frozenset(ci.message_index_offsets) if ci.message_index_offsets else None
            idx.blocks.append(Block(ci.chunk_start_offset, ci.chunk_length, ci.message_start_time,
                                    ci.message_end_time, ids))
            idx.compression = idx.compression or ci.compression
        for m in reader.iter_metadata():
            idx.metadata[m.name] = dict(m.metadata)
        for cid in idx.counts:
            if cid not in idx.channels:
                return None
        return idx
    except (McapError, ValueError, struct.error, EOFError, KeyError, OSError, UnicodeDecodeError):
        return None


def scan_mcap(path: str | Path) -> McapIndex:
    """Index an MCAP file by reading its records in order, stopping at the first broken one.

    Every record wholly present and decodable is used; a torn or corrupt tail (a killed
    writer's last, partly written chunk) is left out and counted in ``dropped_bytes``.
    """
    path = Path(path)
    size = path.stat().st_size
    idx = McapIndex(path=path, size=size, complete=False)
    with open(path, "rb") as f:
        _check_magic(path, f)
        pos = 8
        idx.good_end = pos
        while True:
            hdr = f.read(9)
            if len(hdr) == 0:
                idx.stop_reason = "end of file without a footer"
                break
            if len(hdr) < 9:
                idx.stop_reason = f"torn record header at byte {pos}"
                break
            opcode, length = _RECORD_HEADER.unpack(hdr)
            if pos + 9 + length > size:
                idx.stop_reason = (f"torn record at byte {pos} (opcode 0x{opcode:02x} claims {length} bytes, "
                                   f"{size - pos - 9} remain)")
                break
            if opcode == Opcode.FOOTER:
                idx.good_end = pos
                idx.stop_reason = ""
                break
            if opcode not in (Opcode.HEADER, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE, Opcode.CHUNK,
                              Opcode.METADATA):
                if opcode < 0x80 and opcode not in _KNOWN_OPCODES:
                    idx.stop_reason = f"invalid opcode 0x{opcode:02x} at byte {pos}"
                    break
                f.seek(length, io.SEEK_CUR)  # index/summary records and private (>= 0x80) ones
                pos += 9 + length
                idx.good_end = pos
                continue
            body = f.read(length)
            try:
                rec = _parse_record(opcode, body)
                inner = chunk_records(rec, where=f"{path} byte {pos}") if isinstance(rec, Chunk) else None
            except (BagError, McapError, ValueError, struct.error, EOFError, UnicodeDecodeError) as exc:
                idx.stop_reason = f"undecodable record at byte {pos}: {exc}"
                break
            if isinstance(rec, Header):
                idx.profile, idx.library = rec.profile, rec.library
            elif isinstance(rec, Metadata):
                idx.metadata[rec.name] = dict(rec.metadata)
            elif isinstance(rec, Chunk):
                idx.compression = idx.compression or rec.compression
                ids: set[int] = set()
                n = 0
                for r in inner:
                    if isinstance(r, Message):
                        _count(idx, r)
                        ids.add(r.channel_id)
                        n += 1
                    else:
                        _add_def(idx, r)
                if n:
                    idx.blocks.append(Block(pos, 9 + length, rec.message_start_time, rec.message_end_time,
                                            frozenset(ids)))
            elif isinstance(rec, Message):
                _count(idx, rec)
                idx.blocks.append(Block(pos, 9 + length, rec.log_time, rec.log_time,
                                        frozenset((rec.channel_id,))))
            else:
                _add_def(idx, rec)
            pos += 9 + length
            idx.good_end = pos
    idx.dropped_bytes = 0 if not idx.stop_reason else size - idx.good_end
    for cid in idx.counts:
        if cid not in idx.channels:
            raise BagError(f"{path}: messages on channel id {cid}, but no channel record with that id")
    return idx


def _count(idx: McapIndex, msg: Message) -> None:
    if idx.message_count == 0:
        idx.start_ns = idx.end_ns = msg.log_time
    idx.start_ns = min(idx.start_ns, msg.log_time)
    idx.end_ns = max(idx.end_ns, msg.log_time)
    idx.message_count += 1
    idx.counts[msg.channel_id] = idx.counts.get(msg.channel_id, 0) + 1


def _add_def(idx: McapIndex, rec) -> None:
    if isinstance(rec, Schema):
        idx.schemas[rec.id] = rec
    elif isinstance(rec, Channel):
        idx.channels[rec.id] = rec


def read_block(f, block: Block, *, path: Path) -> list[Message]:
    """The messages of one block, in file order."""
    f.seek(block.offset)
    raw = f.read(block.length)
    if len(raw) != block.length:
        raise BagError(f"{path}: block at byte {block.offset} expected {block.length} bytes, "
                       f"received {len(raw)} (file truncated since it was indexed?)")
    opcode, length = _RECORD_HEADER.unpack_from(raw)
    try:
        rec = _parse_record(opcode, raw[9:9 + length])
    except (McapError, ValueError, struct.error, EOFError, UnicodeDecodeError) as exc:
        raise BagError(f"{path}: record at byte {block.offset} could not be decoded: {exc}") from None
    if isinstance(rec, Message):
        return [rec]
    if isinstance(rec, Chunk):
        return [r for r in chunk_records(rec, where=f"{path} byte {block.offset}") if isinstance(r, Message)]
    raise BagError(f"{path}: expected a chunk or message record at byte {block.offset}, "
                   f"received opcode 0x{opcode:02x}")


def iter_messages(idx: McapIndex, *, channel_ids: set[int] | None = None, start_ns: int | None = None,
                  end_ns: int | None = None) -> Iterator[Message]:
    """Messages of one file in log-time order (ties: file order), ``start_ns <= t <= end_ns``."""
    blocks = [b for b in idx.blocks
              if (channel_ids is None or b.channel_ids is None or b.channel_ids & channel_ids)
              and (start_ns is None or b.end_ns >= start_ns)
              and (end_ns is None or b.start_ns <= end_ns)]
    blocks.sort(key=lambda b: (b.start_ns, b.offset))
    heap: list[tuple[int, int, int, Message]] = []
    i = 0
    with open(idx.path, "rb") as f:
        while i < len(blocks) or heap:
            while i < len(blocks) and (not heap or blocks[i].start_ns <= heap[0][0]):
                b = blocks[i]
                for k, m in enumerate(read_block(f, b, path=idx.path)):
                    if channel_ids is not None and m.channel_id not in channel_ids:
                        continue
                    if (start_ns is not None and m.log_time < start_ns) or (end_ns is not None and m.log_time > end_ns):
                        continue
                    heapq.heappush(heap, (m.log_time, b.offset, k, m))
                i += 1
            if heap:
                yield heapq.heappop(heap)[3]
