"""Reading session recordings: complete files, crashed (truncated) files, CSV export.

Both encodings are read (``rt.recording.channels``): JSON channels with ``json.loads``,
protobuf channels of talus's own messages with their ``struct`` fast path
(``rt.recording.protobuf_codec``), any other protobuf schema through
``mcap_protobuf.decoder``; every payload comes out as the same dict, so callers never ask which
encoding a file has. A ``talus.v4`` cycle channel (``/robot/cycle``, ``rt.recording.cycle``)
is read as its parts: each cycle gives a ``/robot/state``, ``/robot/wrench`` and
``/protocol/reference`` message (those present), counted under those topics; the cycle
channel's own messages are counted in ``ScanInfo.cycles``, and asking for its topic gives the
cycle whole.

What a crash loses with v4: the writer holds a cycle until its parts are in (the session
pump's ≈ 50 ms, at most ``cycle_hold_s``), so besides the last partial chunk up to that much
more of the tail.

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
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Message, Schema
from mcap.stream_reader import breakup_chunk

from rt.errors import InputError
from rt.output_files import atomic_output
from rt.recording import protobuf_codec
from rt.recording.channels import JSONSCHEMA_METADATA_KEY, PROTO_MESSAGES, LoopClock
from rt.recording.cycle import CYCLE_MESSAGES, CycleMessage

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
    #: Records that failed their CRC or could not be decoded: offset, record, reason. Without
    #: salvage the scan stops at the first one; with salvage it skips each and goes on.
    bad_chunks: list[dict[str, Any]] = field(default_factory=list)
    crc_errors: list[str] = field(default_factory=list)      # DataEnd / Footer CRC mismatches
    data_crc_checked: bool = False      # the file carried a data-section CRC and it was read
    sequence_gaps: dict[str, int] = field(default_factory=dict)   # per topic: messages missing
    orphan_messages: int = 0            # messages whose channel is unknown (not decodable)
    #: talus.v4: MCAP messages per cycle channel (``/robot/cycle``); their parts are counted
    #: in ``messages`` under the topics they are read as (``/robot/state`` ...).
    cycles: dict[str, int] = field(default_factory=dict)

    @property
    def message_total(self) -> int:
        return sum(self.messages.values())

    @property
    def corrupt(self) -> bool:
        """A CRC failed or a whole record could not be decoded (not merely cut short)."""
        return bool(self.bad_chunks or self.crc_errors)

    def problem(self) -> str | None:
        """One sentence naming the first damage found, None for an undamaged file."""
        if self.bad_chunks:
            bad = self.bad_chunks[0]
            more = len(self.bad_chunks) - 1
            return (f"{bad['record']} at byte {bad['offset']} is corrupt ({bad['reason']})"
                    + (f"; {more} more damaged records" if more else ""))
        if self.crc_errors:
            return self.crc_errors[0]
        return None

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["message_total"] = self.message_total
        d["lost_tail_bytes"] = self.file_bytes - self.recovered_bytes
        d["duration_s"] = _duration(self.start_ns, self.end_ns)
        d["corrupt"] = self.corrupt
        d["first_bad_chunk"] = self.bad_chunks[0] if self.bad_chunks else None
        d["problem"] = self.problem()
        return d


def _duration(start_ns: int | None, end_ns: int | None) -> float:
    return 0.0 if start_ns is None or end_ns is None else (end_ns - start_ns) / 1e9


#: (message bytes, MCAP log time in ns) → payload.
Decoder = Callable[[bytes, int], Any]


class CycleParts(dict[str, dict[str, Any]]):
    """A decoded ``talus.v4`` cycle: the parts present, topic → dict (with ``t``), the
    topics they were recorded on as channels (``/robot/state`` ...). The readers give each
    part as a message of its topic."""

    cycle: CycleMessage

    def whole(self) -> dict[str, Any]:
        """The cycle as one dict: ``t`` and each part present under its field name
        (``state`` ...), without its own ``t`` (what ``/robot/cycle`` reads as)."""
        out: dict[str, Any] = {"t": next(iter(self.values()))["t"] if self else None}
        for topic, part in self.items():
            out[self.cycle.by_topic[topic].name] = {k: v for k, v in part.items() if k != "t"}
        return out


def cycle_of(channel: Channel, schema: Schema | None) -> CycleMessage | None:
    """The cycle message (``rt.recording.cycle``) a channel carries, None for any other."""
    if (schema is None or channel.message_encoding != protobuf_codec.MESSAGE_ENCODING
            or schema.encoding != protobuf_codec.SCHEMA_ENCODING):
        return None
    cycle = CYCLE_MESSAGES.get(schema.name)
    if cycle is None or bytes(schema.data) != cycle.file_descriptor_set:
        return None
    return cycle


def _bytes(data: bytes, log_time_ns: int) -> Any:
    return bytes(data)


def _json(data: bytes, log_time_ns: int) -> Any:
    return json.loads(data)


def decoder_for(channel: Channel, schema: Schema | None) -> Decoder:
    """(bytes, log time) → payload for ``channel``'s messages: a dict for JSON and protobuf
    channels, the raw bytes for an encoding we do not know.

    A ``talus.v3`` message carries no time: its dict gets ``t`` from the log time through the
    channel's time origin (``rt.recording.channels.LoopClock``), so every encoding reads as
    the same dicts."""
    if channel.message_encoding == "json":
        return _json
    cycle = cycle_of(channel, schema)
    if cycle is not None:
        clock_ = LoopClock.from_metadata(dict(channel.metadata)) or LoopClock(0, 0.0, None)

        def cycle_parts(data: bytes, log_time_ns: int) -> CycleParts:
            out = CycleParts()
            out.cycle = cycle
            t = clock_(log_time_ns)
            for part, raw in cycle.split(bytes(data)):
                d = part.proto.decode(raw)
                d["t"] = t
                out[part.topic] = d
            return out
        return cycle_parts
    if (channel.message_encoding == protobuf_codec.MESSAGE_ENCODING and schema is not None
            and schema.encoding == protobuf_codec.SCHEMA_ENCODING):
        ours = PROTO_MESSAGES.get(schema.name)
        if ours is not None and bytes(schema.data) == ours.file_descriptor_set:
            decode = ours.decode
            if ours.carries_t:
                return lambda data, log_time_ns: decode(data)
            # Without a declared origin (another writer of our schema) t is the log time
            # itself, in s since the Unix epoch.
            clock = LoopClock.from_metadata(dict(channel.metadata)) or LoopClock(0, 0.0, None)

            def timed(data: bytes, log_time_ns: int) -> dict[str, Any]:
                out = decode(data)
                out["t"] = clock(log_time_ns)
                return out
            return timed
        return _generic_protobuf(schema)
    return _bytes


def _generic_protobuf(schema: Schema) -> Decoder:
    """A protobuf schema that is not one of ours (another writer, a later talus): the field
    library decodes it, and the message becomes a dict of its fields."""
    from google.protobuf.message import Message as ProtoMessage
    from mcap_protobuf.decoder import DecoderFactory

    decode = DecoderFactory().decoder_for(protobuf_codec.MESSAGE_ENCODING, schema)
    if decode is None:
        return _bytes

    def to_dict(msg: ProtoMessage) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for fd, value in msg.ListFields():
            if fd.message_type is not None:
                value = ([to_dict(v) for v in value]
                         if fd.label == fd.LABEL_REPEATED else to_dict(value))
            elif fd.label == fd.LABEL_REPEATED:
                value = [_finite_or_none(v) for v in value]
            else:
                value = _finite_or_none(value)
            out[fd.name] = value
        return out

    return lambda data, log_time_ns: to_dict(decode(data))


def _finite_or_none(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


class RecordingScan:
    """Iterate a recording's messages in file order, complete or truncated.

    After (or during) iteration, :attr:`info` says how far the file could be read, and
    :attr:`channels` / :attr:`schemas` hold what the file declared. Raises
    :class:`RecordingFileError` for a file that is not MCAP at all.
    """

    def __init__(self, path: str | os.PathLike[str], topics: Iterable[str] | None = None,
                 salvage: bool = False):
        self.path = Path(path)
        self.topics = None if topics is None else frozenset(topics)
        self.salvage = salvage
        self.info = ScanInfo(str(self.path))
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self._sequence: dict[str, int] = {}     # last sequence number seen per topic
        self._decoders: dict[int, Decoder] = {}  # per channel id

    def schema_for(self, topic: str) -> dict[str, Any] | None:
        """The JSON Schema (a dict) of ``topic``'s channel, if the file declared one: the
        schema of a JSON channel, the one a protobuf channel carries in its metadata."""
        for ch in self.channels.values():
            cycle = self._cycle_of(ch)
            if cycle is not None and topic in cycle.by_topic \
                    and JSONSCHEMA_METADATA_KEY in ch.metadata:
                # A cycle's part: its channel schema, kept in the cycle's JSON Schema.
                root = json.loads(ch.metadata[JSONSCHEMA_METADATA_KEY])
                sub = root["properties"].get(cycle.by_topic[topic].name)
                # The part's channel schema ("t" included), a root schema again.
                return None if sub is None else {"$schema": root.get("$schema"), **sub}
            if ch.topic == topic and JSONSCHEMA_METADATA_KEY in ch.metadata:
                return json.loads(ch.metadata[JSONSCHEMA_METADATA_KEY])
            if ch.topic == topic and ch.schema_id in self.schemas:
                schema = self.schemas[ch.schema_id]
                if schema.encoding == "jsonschema":
                    return json.loads(schema.data)
        return None

    def _decode(self, channel: Channel, msg: Message) -> Any:
        decode = self._decoders.get(channel.id)
        if decode is None:
            decode = decoder_for(channel, self.schemas.get(channel.schema_id))
            self._decoders[channel.id] = decode
        return decode(msg.data, msg.log_time)

    def _cycle_of(self, channel: Channel) -> CycleMessage | None:
        return cycle_of(channel, self.schemas.get(channel.schema_id))

    def topic_names(self) -> list[str]:
        """The topics a reader can ask for: every channel's, and for a cycle channel (v4)
        its parts' too."""
        out: list[str] = []
        for c in self.channels.values():
            out.append(c.topic)
            cycle = self._cycle_of(c)
            if cycle is not None:
                out += [t for t in cycle.topics if t not in out]
        return out

    def channel_topic(self, topic: str) -> str:
        """The channel a topic's messages are in: a cycle's part's is the cycle channel."""
        for c in self.channels.values():
            cycle = self._cycle_of(c)
            if cycle is not None and topic in cycle.by_topic:
                return c.topic
        return topic

    def read_topics(self) -> list[str]:
        """The topics a whole read gives: every channel's, a cycle channel's as its parts."""
        out: list[str] = []
        for c in self.channels.values():
            cycle = self._cycle_of(c)
            out += [t for t in (cycle.topics if cycle is not None else (c.topic,))
                    if t not in out]
        return out

    def _message(self, msg: Message, payload: Any = None) -> list[RecordedMessage]:
        channel = self.channels.get(msg.channel_id)
        if channel is None:
            self.info.orphan_messages += 1   # a message whose channel was never declared
            return []
        info = self.info
        last = self._sequence.get(channel.topic)
        if last is not None and msg.sequence > last + 1:
            gaps = info.sequence_gaps
            gaps[channel.topic] = gaps.get(channel.topic, 0) + msg.sequence - last - 1
        self._sequence[channel.topic] = msg.sequence
        info.start_ns = msg.log_time if info.start_ns is None else min(info.start_ns,
                                                                       msg.log_time)
        info.end_ns = msg.log_time if info.end_ns is None else max(info.end_ns, msg.log_time)
        cycle = self._cycle_of(channel)
        if cycle is not None:
            return self._cycle_message(cycle, channel, msg, payload)
        info.messages[channel.topic] = info.messages.get(channel.topic, 0) + 1
        if self.topics is not None and channel.topic not in self.topics:
            return []
        if payload is None:
            payload = self._decode(channel, msg)
        return [RecordedMessage(channel.topic, msg.log_time, payload)]

    def _cycle_message(self, cycle: CycleMessage, channel: Channel, msg: Message,
                       payload: Any) -> list[RecordedMessage]:
        """A v4 cycle: counted per part, given as its parts' messages (and as itself when
        its own topic is asked for)."""
        info = self.info
        topics = self.topics
        info.cycles[channel.topic] = info.cycles.get(channel.topic, 0) + 1
        wanted = topics is None or channel.topic in topics or any(
            t in topics for t in cycle.topics)
        if not wanted:      # only counted: the parts present, without decoding their fields
            for part, _ in cycle.split(bytes(msg.data)):
                info.messages[part.topic] = info.messages.get(part.topic, 0) + 1
            return []
        if payload is None:
            payload = self._decode(channel, msg)
        out = []
        for topic, part in payload.items():
            info.messages[topic] = info.messages.get(topic, 0) + 1
            if topics is None or topic in topics:
                out.append(RecordedMessage(topic, msg.log_time, part))
        if topics is not None and channel.topic in topics:
            out.append(RecordedMessage(channel.topic, msg.log_time, payload.whole()))
        return out

    def __iter__(self) -> Iterator[RecordedMessage]:
        yield from self._scan()
        info = self.info
        if not info.complete and not info.corrupt and _has_closing_magic(self.path):
            # A finished file (it ends with the closing magic) whose records break before
            # the footer was damaged afterwards (e.g. a record length), not cut by a crash.
            info.crc_errors.append(f"the file was finished but its records break at byte "
                                   f"{info.recovered_bytes} ({info.tail}): damaged")

    def _scan(self) -> Iterator[RecordedMessage]:
        info = self.info
        try:
            f = open(self.path, "rb")  # noqa: SIM115 - closed by the with below; open errors apart
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
            if self.salvage:
                self._channels_from_summary()
            offset = len(MAGIC)
            info.recovered_bytes = offset
            data_crc = zlib.crc32(MAGIC)     # of the data section, checked against DataEnd
            summary_crc: int | None = None   # of the summary section, checked by the Footer
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
                if opcode == Opcode.DATA_END:
                    self._check_data_crc(body, data_crc, offset)
                    summary_crc = 0
                elif summary_crc is None:
                    data_crc = zlib.crc32(body, zlib.crc32(head, data_crc))
                elif opcode != Opcode.FOOTER:
                    summary_crc = zlib.crc32(body, zlib.crc32(head, summary_crc))
                try:
                    out = self._record(opcode, length, body)
                except Exception as exc:
                    if first:
                        raise RecordingFileError(
                            self.path, f"corrupt MCAP header record: {exc}") from exc
                    what = (f"chunk {info.chunks + len(info.bad_chunks)}"
                            if opcode == Opcode.CHUNK else f"{_opname(opcode)} record")
                    info.bad_chunks.append({"offset": offset, "record": what,
                                            "reason": _reason(exc)})
                    if not self.salvage:
                        info.tail = f"{what} at byte {offset} is corrupt: {_reason(exc)}"
                        break
                    out = []
                first = False
                offset += _RECORD_HEAD.size + length
                info.recovered_bytes = offset
                yield from out
                if opcode == Opcode.FOOTER:
                    self._check_summary_crc(head, body, summary_crc or 0, offset - length - 9)
                    closing = f.read(len(MAGIC))
                    info.complete = closing == MAGIC
                    if info.complete:
                        info.recovered_bytes = offset + len(MAGIC)
                    else:
                        info.tail = "footer without the closing magic"
                    break

    def _check_data_crc(self, body: bytes, computed: int, offset: int) -> None:
        stored = DataEnd.read(ReadDataStream(io.BytesIO(body))).data_section_crc
        self.info.data_crc_checked = stored != 0     # 0: the writer did not compute it
        if stored != 0 and stored != computed:
            self.info.crc_errors.append(
                f"data section CRC mismatch (DataEnd at byte {offset}: stored {stored:#010x}, "
                f"computed {computed:#010x})")

    def _check_summary_crc(self, head: bytes, body: bytes, computed: int, offset: int) -> None:
        footer = Footer.read(ReadDataStream(io.BytesIO(body)))
        if footer.summary_crc == 0:
            return
        computed = zlib.crc32(head + body[:16], computed)
        if computed != footer.summary_crc:
            self.info.crc_errors.append(
                f"summary section CRC mismatch (Footer at byte {offset})")

    def _channels_from_summary(self) -> None:
        """Salvage: learn schemas and channels from the summary too, in case the chunk that
        declared them is the damaged one."""
        try:
            with open(self.path, "rb") as f:
                summary = make_reader(f).get_summary()
        except Exception:   # noqa: BLE001 - a damaged summary just teaches us nothing
            return
        if summary is not None:
            self.schemas.update(summary.schemas)
            self.channels.update(summary.channels)

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
            return self._message(Message.read(stream, length))
        elif opcode == Opcode.CHUNK:
            # The chunk is decoded, CRC-checked and its JSON parsed whole before any of its
            # messages is returned: a damaged chunk yields nothing rather than half of it.
            records = breakup_chunk(Chunk.read(stream), validate_crc=True)
            schemas: list[Schema] = []
            channels: list[Channel] = []
            pending: list[Message] = []
            for r in records:
                if isinstance(r, Schema):
                    schemas.append(r)
                elif isinstance(r, Channel):
                    channels.append(r)
                elif isinstance(r, Message):
                    pending.append(r)
            self.schemas.update((x.id, x) for x in schemas)
            self.channels.update((x.id, x) for x in channels)
            for x in channels:
                self._decoders.pop(x.id, None)
            decoded = [self._decoded(m) for m in pending]
            out = [rec for m, payload in decoded for rec in self._message(m, payload)]
            self.info.chunks += 1
            return out
        # Indexes, statistics, summary offsets, footer: nothing to return.
        return []

    def _decoded(self, msg: Message) -> tuple[Message, Any]:
        channel = self.channels.get(msg.channel_id)
        return msg, None if channel is None else self._decode(channel, msg)


def _reason(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    return text if len(text) <= 200 else text[:200] + "…"


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
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            channel_topics = topics
            if summary is not None:
                for ch in summary.channels.values():
                    cycle = cycle_of(ch, summary.schemas.get(ch.schema_id))
                    if cycle is None:
                        if topics is None or ch.topic in topics:
                            out.setdefault(ch.topic, [])
                        continue
                    # A v4 cycle channel is read for its parts (/robot/state ...).
                    for t in cycle.topics:
                        if topics is None or t in topics:
                            out.setdefault(t, [])
                            if channel_topics is not None and ch.topic not in channel_topics:
                                channel_topics = [*channel_topics, ch.topic]
            decoders: dict[int, Decoder] = {}
            for schema, channel, message in reader.iter_messages(topics=channel_topics):
                decode = decoders.get(channel.id)
                if decode is None:
                    decode = decoders[channel.id] = decoder_for(channel, schema)
                payload = decode(message.data, message.log_time)
                if isinstance(payload, CycleParts):
                    for t, part in payload.items():
                        if topics is None or t in topics:
                            out.setdefault(t, []).append(part)
                    if topics is None or channel.topic not in topics:
                        continue
                    payload = payload.whole()
                out.setdefault(channel.topic, []).append(payload)
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
    for topic in scan.read_topics() if topics is None else scan.topic_names():
        if topics is None or topic in topics:
            out.setdefault(topic, [])
    return out, scan.info.as_dict()


def recording_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Channels, message counts, duration, chunks, complete or truncated, and damage.

    Every record is read and every CRC checked (chunks, the data section against DataEnd,
    the summary against the Footer): a summary can say "complete" over flipped bytes.
    ``corrupt`` is True when something failed; ``first_bad_chunk`` and ``problem`` say what
    and where. Reading stops at the first damaged chunk, as export does without ``salvage``.
    """
    path = Path(path)
    if not path.is_file():
        raise RecordingFileError(path, "no such file")
    scan = RecordingScan(path)
    for _ in scan:
        pass
    info = scan.info.as_dict()
    for topic in scan.read_topics():
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


def export_csv(path: str | os.PathLike[str], channel: str, out_csv: str | os.PathLike[str],
               *, force: bool = False, salvage: bool = False) -> dict[str, Any]:
    """Write one channel of a recording (complete or truncated) to a CSV file.

    Columns: ``log_time_ns`` then the channel's fields in schema order, fixed-length arrays
    flattened (``q0, q1, q2``), objects as JSON, ``null`` as an empty cell. Returns
    ``{"out", "channel", "rows", "columns", "complete", "tail", "bad_chunks",
    "sequence_gaps"}``.

    Nothing is lost (``rt.output_files``): an existing ``out_csv`` is refused unless
    ``force``, the recording itself always; the CSV is written to a partial file renamed
    only when complete, so a refusal leaves no file and any previous one untouched.

    A damaged chunk (CRC) stops the export with :class:`RecordingFileError` naming it;
    with ``salvage`` damaged chunks are skipped and listed, and ``sequence_gaps`` counts the
    messages of the channel they held. Raises :class:`InputError` for a channel the
    recording does not have.
    """
    out_path = Path(out_csv)
    scan = RecordingScan(path, topics=[channel], salvage=salvage)
    rows = 0
    cols: list[tuple[str, str, int]] | None = None
    with atomic_output(out_path, "w", newline="", force=force, inputs=[path],
                       what="CSV output") as f:
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
        problem = scan.info.problem()
        if problem is not None and not salvage:
            raise RecordingFileError(path, f"{problem}; nothing written (--salvage exports "
                                           "the readable chunks)")
        if channel not in scan.topic_names():
            raise InputError(f"{path}: no channel {channel!r} (channels: "
                             f"{', '.join(scan.topic_names()) or 'none'})")
        if cols is None:        # a channel without messages: the header alone
            cols = _columns(scan.schema_for(channel), None)
            writer.writerow(["log_time_ns"] + [c for c, _, _ in cols])
    return {"out": str(out_path), "channel": channel, "rows": rows,
            "columns": ["log_time_ns"] + [c for c, _, _ in cols],
            "complete": scan.info.complete, "tail": scan.info.tail,
            "bad_chunks": scan.info.bad_chunks, "crc_errors": scan.info.crc_errors,
            # A cycle's part (v4): the gaps of the cycle channel that holds it.
            "sequence_gaps": scan.info.sequence_gaps.get(scan.channel_topic(channel), 0)}
