"""Reading session recordings: complete files, crashed (truncated) files, CSV export.

A complete file (footer, summary, closing magic) is read with mcap's own reader, so what we
write is checked against the reference implementation. A file whose writer died has no
footer: :func:`recover` walks its records from the start (MCAP framing: opcode u8, length u64
little-endian, body) and keeps every chunk that is whole and passes its CRC, stopping at the
first record the end of the file cuts short. What a crash loses is therefore the last partial
chunk (plus what the writer had not yet received): ≤ ``flush_interval_s + drain_period_s`` of
data with the recorder's defaults (see ``rt.recording.writer``).
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import struct
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator, NamedTuple

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Header, Message, Schema
from mcap.stream_reader import breakup_chunk

from rt.errors import InputError

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")


class RecordingFileError(InputError):
    """A file is not a readable MCAP recording; the message names the file and the reason."""

    def __init__(self, path: str | os.PathLike[str], reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


class TruncatedRecordingError(RecordingFileError):
    """The recording has no footer (its writer did not finish): use :func:`recover`."""


class RecordedMessage(NamedTuple):
    """One message: topic, MCAP log time (ns since the epoch), decoded payload (a dict for
    JSON channels, raw bytes otherwise)."""

    topic: str
    log_time_ns: int
    payload: Any


@dataclass
class ScanInfo:
    """What a linear scan of a recording found."""

    path: str
    complete: bool = False              # footer and closing magic present
    chunks: int = 0                     # complete chunks read
    messages: dict[str, int] = field(default_factory=dict)   # per topic
    file_bytes: int = 0
    recovered_bytes: int = 0            # offset just past the last record read whole
    tail: str | None = None             # why reading stopped early, None when complete
    start_ns: int | None = None         # first/last message log time
    end_ns: int | None = None
    library: str = ""

    @property
    def message_total(self) -> int:
        return sum(self.messages.values())

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["message_total"] = self.message_total
        d["lost_tail_bytes"] = self.file_bytes - self.recovered_bytes
        d["duration_s"] = _duration(self.start_ns, self.end_ns)
        return d


def _duration(start_ns: int | None, end_ns: int | None) -> float:
    return 0.0 if start_ns is None or end_ns is None else (end_ns - start_ns) / 1e9


def _decode(channel: Channel, data: bytes) -> Any:
    if channel.message_encoding == "json":
        return json.loads(data)
    return bytes(data)


class RecordingScan:
    """Iterate a recording's messages in file order, complete or truncated.

    After (or during) iteration, :attr:`info` says how far the file could be read, and
    :attr:`channels` / :attr:`schemas` hold what the file declared. Raises
    :class:`RecordingFileError` for a file that is not MCAP at all.
    """

    def __init__(self, path: str | os.PathLike[str], topics: Iterable[str] | None = None):
        self.path = Path(path)
        self.topics = None if topics is None else frozenset(topics)
        self.info = ScanInfo(str(self.path))
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}

    def schema_for(self, topic: str) -> dict[str, Any] | None:
        """The JSON Schema (a dict) of ``topic``'s channel, if the file declared one."""
        for ch in self.channels.values():
            if ch.topic == topic and ch.schema_id in self.schemas:
                schema = self.schemas[ch.schema_id]
                if schema.encoding == "jsonschema":
                    return json.loads(schema.data)
        return None

    def topic_names(self) -> list[str]:
        return [c.topic for c in self.channels.values()]

    def _message(self, msg: Message) -> RecordedMessage | None:
        channel = self.channels.get(msg.channel_id)
        if channel is None:
            return None     # a message before its channel: not written by talus; skip it
        info = self.info
        info.messages[channel.topic] = info.messages.get(channel.topic, 0) + 1
        info.start_ns = msg.log_time if info.start_ns is None else min(info.start_ns,
                                                                       msg.log_time)
        info.end_ns = msg.log_time if info.end_ns is None else max(info.end_ns, msg.log_time)
        if self.topics is not None and channel.topic not in self.topics:
            return None
        return RecordedMessage(channel.topic, msg.log_time, _decode(channel, msg.data))

    def __iter__(self) -> Iterator[RecordedMessage]:
        info = self.info
        try:
            f = open(self.path, "rb")
        except OSError as exc:
            raise RecordingFileError(self.path, f"cannot open: {exc.strerror or exc}") from exc
        with f:
            info.file_bytes = os.fstat(f.fileno()).st_size
            magic = f.read(len(MAGIC))
            if not magic:
                raise RecordingFileError(self.path, "empty file, not an MCAP recording")
            if magic != MAGIC:
                raise RecordingFileError(
                    self.path, f"not an MCAP recording (starts with {magic!r}, expected the "
                               f"MCAP magic {MAGIC!r})")
            offset = len(MAGIC)
            info.recovered_bytes = offset
            first = True
            while True:
                head = f.read(_RECORD_HEAD.size)
                if len(head) < _RECORD_HEAD.size:
                    info.tail = ("file ends without a footer" if not head else
                                 f"record header cut short at byte {offset}")
                    break
                opcode, length = _RECORD_HEAD.unpack(head)
                if first and opcode != Opcode.HEADER:
                    raise RecordingFileError(self.path, "corrupt MCAP file: the first record "
                                                        f"is not a Header (opcode {opcode})")
                available = info.file_bytes - offset - _RECORD_HEAD.size
                if length > available:
                    info.tail = (f"{_opname(opcode)} record at byte {offset} cut short: "
                                 f"{length} bytes announced, {available} present")
                    break
                if opcode == 0:
                    # Opcode 0 is reserved: zero-filled space (e.g. after a power loss).
                    info.tail = f"zero bytes from byte {offset} on"
                    break
                body = f.read(length)
                try:
                    out = self._record(opcode, length, body)
                except Exception as exc:   # noqa: BLE001 - any corrupt record ends the scan
                    if first:
                        raise RecordingFileError(
                            self.path, f"corrupt MCAP header record: {exc}") from exc
                    info.tail = f"{_opname(opcode)} record at byte {offset} unreadable: {exc}"
                    break
                first = False
                offset += _RECORD_HEAD.size + length
                info.recovered_bytes = offset
                for rec in out:
                    yield rec
                if opcode == Opcode.FOOTER:
                    closing = f.read(len(MAGIC))
                    info.complete = closing == MAGIC
                    if info.complete:
                        info.recovered_bytes = offset + len(MAGIC)
                    else:
                        info.tail = "footer without the closing magic"
                    break

    def _record(self, opcode: int, length: int, body: bytes) -> list[RecordedMessage]:
        stream = ReadDataStream(io.BytesIO(body))
        if opcode == Opcode.HEADER:
            self.info.library = Header.read(stream).library
        elif opcode == Opcode.SCHEMA:
            schema = Schema.read(stream)
            self.schemas[schema.id] = schema
        elif opcode == Opcode.CHANNEL:
            channel = Channel.read(stream)
            self.channels[channel.id] = channel
        elif opcode == Opcode.MESSAGE:
            rec = self._message(Message.read(stream, length))
            return [] if rec is None else [rec]
        elif opcode == Opcode.CHUNK:
            # The chunk is decoded and CRC-checked whole before any of its messages is
            # returned: a damaged chunk yields nothing rather than half its messages.
            records = breakup_chunk(Chunk.read(stream), validate_crc=True)
            out: list[RecordedMessage] = []
            pending: list[Message] = []
            for r in records:
                if isinstance(r, Schema):
                    self.schemas[r.id] = r
                elif isinstance(r, Channel):
                    self.channels[r.id] = r
                elif isinstance(r, Message):
                    pending.append(r)
            for m in pending:
                rec = self._message(m)
                if rec is not None:
                    out.append(rec)
            self.info.chunks += 1
            return out
        # Indexes, statistics, summary offsets, data end, footer: nothing to return.
        return []


def _opname(opcode: int) -> str:
    try:
        return Opcode(opcode).name
    except ValueError:
        return f"unknown (opcode {opcode})"


def _has_closing_magic(path: Path) -> bool:
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if size < 2 * len(MAGIC):
            return False
        f.seek(size - len(MAGIC))
        return f.read(len(MAGIC)) == MAGIC


def _check_complete(path: Path) -> None:
    """Raise the precise error for a file mcap's reader cannot open (garbage or truncated)."""
    scan = RecordingScan(path)
    for _ in scan:
        pass
    if not scan.info.complete:
        raise TruncatedRecordingError(
            path, f"incomplete recording ({scan.info.tail}); {scan.info.message_total} "
                  f"messages in {scan.info.chunks} complete chunks can be read with "
                  "rt.recording.reader.recover()")


def read_recording(path: str | os.PathLike[str],
                   topics: Iterable[str] | None = None) -> dict[str, list[dict[str, Any]]]:
    """Every message of a complete recording: topic → payloads in log-time order.

    Raises :class:`TruncatedRecordingError` for a file without footer (use :func:`recover`)
    and :class:`RecordingFileError` for a file that is not an MCAP recording.
    """
    path = Path(path)
    topics = None if topics is None else list(topics)
    if not path.is_file():
        raise RecordingFileError(path, "no such file")
    if not _has_closing_magic(path):
        _check_complete(path)      # raises with the reason
    out: dict[str, list[dict[str, Any]]] = {}
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is not None:
                for ch in summary.channels.values():
                    if topics is None or ch.topic in topics:
                        out.setdefault(ch.topic, [])
            for _, channel, message in reader.iter_messages(topics=topics):
                out.setdefault(channel.topic, []).append(_decode(channel, message.data))
    except (McapError, struct.error, ValueError) as exc:
        _check_complete(path)
        raise RecordingFileError(path, f"unreadable MCAP file: {exc}") from exc
    return out


def recover(path: str | os.PathLike[str], topics: Iterable[str] | None = None
            ) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Any]]:
    """Read a recording, complete or not, up to its last complete chunk.

    Returns ``(messages_by_topic, info)``; ``info`` holds ``complete`` (False for a crashed
    writer), ``chunks`` and ``messages`` recovered, ``message_total``, ``tail`` (why reading
    stopped), ``recovered_bytes``/``lost_tail_bytes``, ``start_ns``/``end_ns``,
    ``duration_s``. Raises :class:`RecordingFileError` for a file that is not MCAP.
    """
    scan = RecordingScan(path, topics)
    out: dict[str, list[dict[str, Any]]] = {}
    for rec in scan:
        out.setdefault(rec.topic, []).append(rec.payload)
    for topic in scan.topic_names():
        if topics is None or topic in topics:
            out.setdefault(topic, [])
    return out, scan.info.as_dict()


def recording_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Channels, message counts, duration, chunks, complete or truncated, of a recording.

    A complete file is answered from its summary section (fast); a truncated one is scanned.
    """
    path = Path(path)
    if not path.is_file():
        raise RecordingFileError(path, "no such file")
    if _has_closing_magic(path):
        try:
            with open(path, "rb") as f:
                summary = make_reader(f).get_summary()
        except (McapError, struct.error, ValueError):
            summary = None
        if summary is not None and summary.statistics is not None:
            st = summary.statistics
            counts = {ch.topic: st.channel_message_counts.get(cid, 0)
                      for cid, ch in summary.channels.items()}
            start, end = (st.message_start_time, st.message_end_time) if st.message_count \
                else (None, None)
            return {"path": str(path), "complete": True, "channels": sorted(counts),
                    "messages": counts, "message_total": st.message_count,
                    "chunks": st.chunk_count, "duration_s": _duration(start, end),
                    "start_ns": start, "end_ns": end, "file_bytes": path.stat().st_size,
                    "tail": None}
    scan = RecordingScan(path)
    for _ in scan:
        pass
    info = scan.info.as_dict()
    for topic in scan.topic_names():
        info["messages"].setdefault(topic, 0)
    info["channels"] = sorted(info["messages"])
    return info


# ------------------------------------------------------------------------------ CSV export

def _columns(schema: dict[str, Any] | None, first: dict[str, Any] | None
             ) -> list[tuple[str, str, int]]:
    """``(column, field, index)``; index -1 for a scalar (or JSON-encoded) field.

    Fixed-length arrays (``minItems == maxItems``) are flattened as ``q0, q1, q2``; other
    arrays and objects go into one column as JSON.
    """
    cols: list[tuple[str, str, int]] = []
    if schema is not None and isinstance(schema.get("properties"), dict):
        for name, sub in schema["properties"].items():
            n = sub.get("maxItems") if isinstance(sub, dict) else None
            if (isinstance(sub, dict) and sub.get("type") == "array" and isinstance(n, int)
                    and sub.get("minItems") == n):
                cols += [(f"{name}{i}", name, i) for i in range(n)]
            else:
                cols.append((name, name, -1))
        return cols
    for name, value in (first or {}).items():     # no schema: the first message's shape
        if isinstance(value, list) and all(not isinstance(v, (list, dict)) for v in value):
            cols += [(f"{name}{i}", name, i) for i in range(len(value))]
        else:
            cols.append((name, name, -1))
    return cols


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ""
    if isinstance(value, (dict, list)):
        return json.dumps(value, separators=(",", ":"))
    return str(value)


def export_csv(path: str | os.PathLike[str], channel: str,
               out_csv: str | os.PathLike[str]) -> dict[str, Any]:
    """Write one channel of a recording (complete or truncated) to a CSV file.

    Columns: ``log_time_ns`` then the channel's fields in schema order, fixed-length arrays
    flattened (``q0, q1, q2``), objects as JSON, ``null`` as an empty cell. Returns
    ``{"out", "channel", "rows", "columns", "complete", "tail"}``. Raises
    :class:`RecordingFileError` for a non-MCAP file and :class:`InputError` for a channel the
    recording does not have (no output file is left behind then).
    """
    out_path = Path(out_csv)
    scan = RecordingScan(path, topics=[channel])
    rows = 0
    cols: list[tuple[str, str, int]] | None = None
    ok = False
    try:
        with open(out_path, "w", newline="") as f:
            writer = csv.writer(f)
            for rec in scan:
                if cols is None:
                    cols = _columns(scan.schema_for(channel), rec.payload)
                    writer.writerow(["log_time_ns"] + [c for c, _, _ in cols])
                p = rec.payload
                cells = [str(rec.log_time_ns)]
                for _, name, i in cols:
                    v = p.get(name) if isinstance(p, dict) else None
                    if i >= 0:
                        v = v[i] if isinstance(v, list) and i < len(v) else None
                    cells.append(_cell(v))
                writer.writerow(cells)
                rows += 1
            if channel not in scan.topic_names():
                raise InputError(f"{path}: no channel {channel!r} (channels: "
                                 f"{', '.join(scan.topic_names()) or 'none'})")
            if cols is None:        # a channel without messages: the header alone
                cols = _columns(scan.schema_for(channel), None)
                writer.writerow(["log_time_ns"] + [c for c, _, _ in cols])
        ok = True
    finally:
        if not ok:
            out_path.unlink(missing_ok=True)
    return {"out": str(out_path), "channel": channel, "rows": rows,
            "columns": ["log_time_ns"] + [c for c, _, _ in cols],
            "complete": scan.info.complete, "tail": scan.info.tail}
