"""``SessionRecorder``: one session's MCAP file, written from a non-real-time thread.

Data flow (DESIGN 3): the 1 kHz loop never touches the file. State leaves the loop through
``RecorderTap``'s preallocated ring, which the recorder's thread drains every
``drain_period_s``; rare or optional messages (safety events, wrench, protocol reference) are
handed over with a non-blocking append to a bounded queue. The thread encodes, feeds the
mcap ``Writer`` and owns the file.

Encoding (``rt.recording.channels``): by default (``talus.v4``) the 1 kHz state, wrench and
reference are the parts of one protobuf message per loop cycle on ``/robot/cycle``
(``rt.recording.cycle``): each part is encoded as it arrives (a drained block of ring rows at
once with numpy), the parts are joined by cycle time (``CycleJoiner``: a cycle waits for a
part whose source has been heard from, at most ``cycle_hold_s``), and each cycle is written
as one MCAP message; and
the file carries no per-message index (MCAP MessageIndex records: 16 bytes per message that
compression never touches, a quarter of the file at 1 kHz; readers, Foxglove and mcap's own,
find messages through the chunk indexes and read the chunk). ``encoding="json"`` writes the
recordings made before issue 16 (all JSON, every index).

Never blocking the caller: every enqueue is a length check and a ``deque.append`` (no lock, no
I/O); a full queue drops the message and counts it. A ring the thread has not drained in time
is overwritten by the loop (``RecorderTap`` keeps the newest rows); the recorder sees the gap in
the row counter and counts the lost rows. ``close()`` reports both.

Crash tolerance: the file is chunked (zstd). Besides closing a chunk when it exceeds
``chunk_size`` bytes (uncompressed), the thread closes the open chunk and flushes the file
every ``flush_interval_s``. A process killed at any instant therefore leaves on disk every
message produced more than about ``flush_interval_s + drain_period_s`` (+ one pump's work)
earlier; with the defaults ≈ 0.27 s (measured: at most 0.26 s over 20 SIGKILLs of a 1 kHz
recording, also with two CPU hogs running; ``bench/costs.py --crash`` measures it, the tests
check that what is recovered is an exact prefix). ``rt.recording.reader.recover`` reads such a
file up to its last complete chunk.
With talus.v4 a cycle is written once its parts are in: in a session the pump hands the
wrench and reference every ≈ 50 ms, which adds that much to the window (a killed writer's file
is still an exact prefix of cycles, tested).
Data reaches the OS page cache, which survives a process crash; surviving a power loss needs
``fsync=True`` (an fsync per flush).
"""
from __future__ import annotations

import collections
import enum
import hashlib
import importlib.metadata
import json
import math
import numbers
import os
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any, Protocol, Self

import numpy as np
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, IndexType, Writer

from rt.errors import InputError, TalusError
from rt.output_files import PARTIAL_SUFFIX, check_output, commit_output, partial_path
from rt.recording import protobuf_codec
from rt.recording.channels import (
    CHANNELS,
    CYCLE,
    EVENTS,
    JSONSCHEMA_METADATA_KEY,
    MESSAGE_ENCODING,
    METADATA,
    METADATA_REQUIRED_FROM_CALLER,
    PROTOS,
    REFERENCE,
    SCHEMA_ENCODING,
    STATE,
    STATE_ROW_LAYOUT,
    T_QUANTUM_S,
    WRENCH,
    ChannelSpec,
    Encoding,
    LoopClock,
    time_metadata,
)
from rt.recording.cycle import CYCLE_V4, DEFAULT_HOLD_S, CycleJoiner, CycleMessage
from rt.recording.protobuf_codec import ProtoCodecError, ProtoMessage

#: Chunk size, bytes of uncompressed records: ≈ 1 s of 1 kHz state. The flush timer, not the
#: size, usually closes chunks, so this only caps a chunk when many channels are busy.
DEFAULT_CHUNK_SIZE = 256 * 1024
#: Close the open chunk and flush the file this often (s): the crash-loss window.
DEFAULT_FLUSH_INTERVAL_S = 0.25
#: Drain the rings this often (s). A RecorderTap ring of 65536 rows holds 65 s at 1 kHz.
DEFAULT_DRAIN_PERIOD_S = 0.02
#: Queued messages (events, wrench, reference) before drops: 16 s of 1 kHz wrench.
DEFAULT_QUEUE_CAPACITY = 16384
#: The writer thread lets other threads take the GIL after this many messages.
_YIELD_EVERY = 64

_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                "none": CompressionType.NONE}


class RecordingError(TalusError):
    """The recorder could not write its file (disk full, permission ...)."""


class RingSource(Protocol):
    """What the recorder drains: ``RecorderTap`` (rt.components.blocks) and alike.

    A source that also has ``capacity`` (rows) gets its drained rows checked against overwrite
    during the copy (see ``SessionRecorder._pump``).
    """

    written: int

    def drain(self, start: int) -> tuple[np.ndarray, int]:
        """Rows written since ``start`` (a copy, oldest first) and the new start index."""
        ...


class RowLayout:
    """How a ring row (float64 columns) becomes a JSON message.

    ``fields`` is ``((name, width), ...)``; width 1 is a number, width > 1 an array. The first
    field must be ``t`` (loop time, s): it sets the message's log time.
    """

    def __init__(self, fields: Iterable[tuple[str, int]]):
        self.fields = tuple((str(n), int(w)) for n, w in fields)
        if not self.fields or self.fields[0] != ("t", 1):
            raise InputError(f"a row layout starts with ('t', 1), got {self.fields[:1]}")
        if any(w < 1 for _, w in self.fields):
            raise InputError(f"row layout widths must be >= 1: {self.fields}")
        self.width = sum(w for _, w in self.fields)
        parts = []
        for name, w in self.fields:
            value = "%r" if w == 1 else "[" + ",".join(["%r"] * w) + "]"
            parts.append(json.dumps(name) + ":" + value)
        # A %-format over the row's Python floats: ≈ 3x faster than json.dumps of a dict and
        # exact (repr is the shortest round-tripping form). Valid JSON only for finite values,
        # which encode() checks per batch.
        self._format = "{" + ",".join(parts) + "}"

    def to_dict(self, row: Iterable[float]) -> dict[str, Any]:
        """The message for one row, non-finite values as ``None`` (the slow, exact path)."""
        values = [v if math.isfinite(v) else None for v in row]
        out: dict[str, Any] = {}
        k = 0
        for name, w in self.fields:
            out[name] = values[k] if w == 1 else values[k:k + w]
            k += w
        return out

    def encode(self, rows: np.ndarray) -> list[bytes]:
        """JSON bytes for each row of ``rows`` (n × width)."""
        if rows.shape[1] != self.width:
            raise InputError(f"ring rows have {rows.shape[1]} columns, layout expects "
                             f"{self.width}")
        fmt = self._format
        finite = np.isfinite(rows).all(axis=1)
        lists = rows.tolist()
        if finite.all():
            return [(fmt % tuple(r)).encode() for r in lists]
        return [(fmt % tuple(r)).encode() if ok else
                json.dumps(self.to_dict(r), separators=(",", ":")).encode()
                for r, ok in zip(lists, finite.tolist())]


STATE_LAYOUT = RowLayout(STATE_ROW_LAYOUT)


def _json_default(obj: Any) -> Any:
    # Event values come from the supervisor: numpy scalars/arrays, enums.
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, enum.Enum):
        return obj.name.lower()
    return str(obj)


def _finite_or_none(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if isinstance(obj, (np.ndarray, np.generic)):
        return _finite_or_none(obj.tolist())
    return obj


def encode_json(message: dict[str, Any]) -> bytes:
    """Compact JSON; NaN/inf become ``null`` (JSON has neither)."""
    try:
        text = json.dumps(message, separators=(",", ":"), allow_nan=False,
                          default=_json_default)
    except ValueError:
        text = json.dumps(_finite_or_none(message), separators=(",", ":"), allow_nan=False,
                          default=_json_default)
    return text.encode()


def software_version() -> str:
    """The installed talus version (``"unknown"`` when run from an uninstalled tree)."""
    try:
        return importlib.metadata.version("talus")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def _open_output(path: Path) -> IO[bytes]:
    """The file the recorder writes (a seam for tests that simulate a slow disk).

    ``path`` is a new name (created exclusively: never an existing file) or the empty partial
    file ``rt.output_files.partial_path`` just created for a ``force`` replacement.
    """
    return open(path, "wb" if path.name.endswith(PARTIAL_SUFFIX) else "xb")


class _HashingStream:
    """Write-through wrapper computing the file's sha256 as it is written (the mcap writer only
    appends and never seeks, so the running hash is the finished file's hash)."""

    def __init__(self, raw: IO[bytes]):
        self.raw = raw
        self.sha256 = hashlib.sha256()
        self.bytes = 0

    def write(self, data: bytes) -> int:
        self.sha256.update(data)
        self.bytes += len(data)
        return self.raw.write(data)

    def tell(self) -> int:
        return self.bytes

    def flush(self) -> None:
        self.raw.flush()

    def close(self) -> None:
        self.raw.close()


@dataclass
class _Block:
    """A queued block of one channel's messages (rows of numbers, and per-row strings)."""

    rows: np.ndarray
    strings: tuple[tuple[str, ...], ...] = ()

    def __len__(self) -> int:
        return len(self.rows)


@dataclass
class _RingTap:
    topic: str
    channel_id: int
    source: RingSource
    layout: RowLayout
    start: int
    #: rows (n × width) → one message each: JSON or protobuf.
    encode: Callable[[np.ndarray], list[bytes]]
    dropped: int = 0


class SessionRecorder:
    """Records one session into an MCAP file from its own thread. Context manager.

    ``metadata`` must hold ``protocol_name``, ``protocol_version``, ``parameters`` (dict),
    ``patient_id`` (pseudonym) and ``robot_description``; ``software_version`` defaults to the
    installed talus version and ``start_wall_time`` is set from ``start_wall_ns``. It is
    written once, as the first message of ``/protocol/metadata``.

    Times: loop time ``loop_t0`` (s) corresponds to wall clock ``start_wall_ns`` (ns since the
    epoch, default: now); a message with loop time ``t`` gets MCAP log time
    ``start_wall_ns + (t - loop_t0)·1e9``.

    ``extra_channels`` (topic → :class:`ChannelSpec`) adds channels to the standard ones of
    ``rt.recording.channels.CHANNELS``; write to them with :meth:`publish` or
    :meth:`attach_ring`.

    ``cycle_hold_s`` (talus.v4): how long (s, the writer's clock) a cycle waits for a part
    whose source has been heard from (or attached) but has not reached it yet, before it is
    written without it (``rt.recording.cycle.CycleJoiner``).

    ``encoding``: ``"protobuf"`` (default) writes the channels that have a protobuf message
    (``ChannelSpec.proto``) as protobuf, the others as JSON; ``"json"`` writes every channel
    as JSON, as recordings were before issue 16 (kept for comparison and compatibility tests).

    The file is opened, the channels registered and the metadata written to disk before the
    constructor returns, so a bad path fails here, not in the thread.
    """

    def __init__(self, path: str | os.PathLike[str], metadata: dict[str, Any], *,
                 chunk_size: int = DEFAULT_CHUNK_SIZE, compression: str = "zstd",
                 flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S,
                 drain_period_s: float = DEFAULT_DRAIN_PERIOD_S,
                 queue_capacity: int = DEFAULT_QUEUE_CAPACITY, loop_t0: float = 0.0,
                 start_wall_ns: int | None = None,
                 extra_channels: dict[str, ChannelSpec] | None = None, fsync: bool = False,
                 force: bool = False, inputs: Iterable[str | os.PathLike[str]] = (),
                 encoding: Encoding | str = Encoding.PROTOBUF,
                 cycle_hold_s: float = DEFAULT_HOLD_S):
        try:
            self.encoding = Encoding(encoding)
        except ValueError:
            raise InputError(f"encoding must be one of {[e.value for e in Encoding]}, got "
                             f"{encoding!r}") from None
        if compression not in _COMPRESSION:
            raise InputError(f"compression must be one of {sorted(_COMPRESSION)}, "
                             f"got {compression!r}")
        if chunk_size <= 0 or flush_interval_s <= 0 or drain_period_s <= 0 \
                or queue_capacity <= 0:
            raise InputError("chunk_size, flush_interval_s, drain_period_s and queue_capacity "
                             "must be positive")
        if not cycle_hold_s > 0:
            raise InputError(f"cycle_hold_s must be positive, got {cycle_hold_s!r}")
        missing = [k for k in METADATA_REQUIRED_FROM_CALLER if k not in metadata]
        if missing:
            raise InputError(f"session metadata lacks {missing} (needs "
                             f"{list(METADATA_REQUIRED_FROM_CALLER)})")
        if not isinstance(metadata["parameters"], dict):
            raise InputError("session metadata 'parameters' must be a dict")
        # Nothing lost (rt.output_files): an existing file is refused unless ``force``, an input
        # always. A new recording is written in place, created exclusively, so that after a
        # crash its data are where the user looks (``recover`` reads them). A replacement is
        # written to a partial file beside the old one and renamed over it only when complete:
        # the old recording survives a failed or crashed new one.
        self.path = check_output(path, inputs, force=force, what="recording")
        self._partial = partial_path(self.path) if os.path.lexists(self.path) else None
        # Every standard channel is always registered; more are one dict entry away.
        self.channels = {**CHANNELS, **(extra_channels or {})}
        for topic, spec in self.channels.items():
            if topic != spec.topic or spec.schema.get("type") != "object":
                raise InputError(f"channel {topic!r}: the key must be the spec's topic and "
                                 "the schema an object")
        #: topic → protobuf message, for the channels written as protobuf: the standard
        #: channels' message of this encoding, an added channel's own.
        standard = PROTOS[self.encoding]
        self._protos: dict[str, ProtoMessage] = {}
        if self.encoding is not Encoding.JSON:
            for topic, spec in self.channels.items():
                proto = standard.get(topic, spec.proto)
                if proto is not None:
                    self._protos[topic] = proto
        # Fixed-point recordings keep loop times to the µs (v2: their ``t_us``; v3, v4: the
        # log time is the time), so a message's log time and its payload agree.
        self._t_quantum = T_QUANTUM_S if self.encoding in (
            Encoding.PROTOBUF, Encoding.PROTOBUF_V3, Encoding.PROTOBUF_V2) else None
        # talus.v4: the three 1 kHz channels' messages are parts of one message per cycle
        # (rt.recording.cycle): encoded as before, then joined by cycle time and written on
        # the cycle channel. ``_part`` maps a part's topic to its index in the cycle.
        self._cycle: CycleMessage | None = CYCLE_V4 if self.encoding is Encoding.PROTOBUF \
            else None
        self._part = {} if self._cycle is None else \
            {topic: k for k, topic in enumerate(self._cycle.topics)}
        self._joiner = None if self._cycle is None else CycleJoiner(len(self._part),
                                                                     cycle_hold_s)
        # The queued wrench samples (t, fx..tz, stale, saturated) as protobuf rows.
        wrench_proto = self._protos.get(WRENCH)
        self._wrench_rows = None if wrench_proto is None else wrench_proto.row_encoder(
            [("t", 1), ("fx", 1), ("fy", 1), ("fz", 1), ("tx", 1), ("ty", 1), ("tz", 1),
             ("stale", 1), ("saturated", 1)])
        self._reference_rows: Callable[[np.ndarray], list[bytes]] | None = None
        self.loop_t0 = float(loop_t0)
        self.start_wall_ns = time.time_ns() if start_wall_ns is None else int(start_wall_ns)
        self._clock = LoopClock(self.start_wall_ns, self.loop_t0, self._t_quantum)
        self.flush_interval_s = float(flush_interval_s)
        self.drain_period_s = float(drain_period_s)
        self.queue_capacity = int(queue_capacity)
        self._fsync = fsync

        # Producer side: a deque without maxlen (maxlen would silently drop the *oldest*)
        # bounded by an explicit length check, so a drop is counted and the newest kept out.
        self._queue: collections.deque[tuple[str, float, Any]] = collections.deque()
        self._taps: tuple[_RingTap, ...] = ()
        self._closed = False
        self._dropped = {topic: 0 for topic in self.channels}
        #: Messages written per topic: a channel's MCAP messages, and for a cycle's parts
        #: the parts written (so a part's topic counts as it is read back).
        self._messages = {topic: 0 for topic in self.channels}
        #: MCAP messages written per channel (the sequence numbers).
        self._sequence: dict[str, int] = {}
        self._error: str | None = None
        self._wrench_without_sample = 0
        self._busy_s = 0.0
        self._flushes = 0
        self._summary: dict[str, Any] | None = None
        self._close_lock = threading.Lock()
        self._stop = threading.Event()
        self._t_open = time.monotonic()

        self.metadata = self._complete_metadata(metadata)
        try:
            self._stream = _HashingStream(_open_output(self._partial or self.path))
        except OSError as exc:
            if self._partial is not None:
                self._partial.unlink(missing_ok=True)
            raise RecordingError(f"cannot create recording {self.path}: {exc}") from exc
        try:
            # Data-section CRC in DataEnd (besides the chunk and summary CRCs): a flipped byte
            # outside any chunk (a message index) is detected too.
            # No MessageIndex records with protobuf (see the module docstring); the JSON
            # encoding keeps them, so it writes what recordings were before issue 16.
            index_types = IndexType.ALL if self.encoding is Encoding.JSON \
                else IndexType.ALL & ~IndexType.MESSAGE
            self._mcap = Writer(self._stream, chunk_size=int(chunk_size),  # type: ignore[arg-type]
                                compression=_COMPRESSION[compression], index_types=index_types,
                                enable_data_crcs=True)
            self._mcap.start(profile="", library=f"talus {software_version()}; "
                                                 f"{LIBRARY_IDENTIFIER}")
            self._channel_ids: dict[str, int] = {}
            if self._cycle is not None:
                self._register_cycle(self._cycle)
            for spec in self.channels.values():
                if spec.topic in self._part:
                    continue            # written inside the cycle channel
                proto = self._protos.get(spec.topic)
                if proto is None:
                    schema_id = self._mcap.register_schema(
                        name=spec.schema_name, encoding=SCHEMA_ENCODING,
                        data=json.dumps(spec.schema).encode())
                    self._channel_ids[spec.topic] = self._mcap.register_channel(
                        topic=spec.topic, message_encoding=MESSAGE_ENCODING,
                        schema_id=schema_id, metadata=dict(spec.metadata))
                    continue
                schema_id = self._mcap.register_schema(
                    name=proto.name, encoding=protobuf_codec.SCHEMA_ENCODING,
                    data=proto.file_descriptor_set)
                # The JSON Schema rides along: units and descriptions stay in the file. A
                # message without its time gets it back from the log time and this origin;
                # a converter's code field says its range.
                extra: dict[str, str] = {}
                if not proto.carries_t:
                    extra.update(time_metadata(self.start_wall_ns, self.loop_t0,
                                               self._t_quantum or 1e-9))
                for f in proto.fields:
                    if f.code_range is not None:
                        extra[f"talus.{f.name}.range"] = ",".join(map(repr, f.code_range))
                self._channel_ids[spec.topic] = self._mcap.register_channel(
                    topic=spec.topic, message_encoding=protobuf_codec.MESSAGE_ENCODING,
                    schema_id=schema_id,
                    metadata={**spec.metadata, **extra,
                              JSONSCHEMA_METADATA_KEY: json.dumps(spec.schema)})
            self._write(METADATA, self.loop_t0, encode_json(self.metadata))
            # The first chunk (schemas, channels, metadata) goes to disk now: a recording
            # whose writer dies later still says what it was.
            self._flush_chunk()
        except (OSError, ValueError) as exc:
            self._stream.close()
            (self._partial or self.path).unlink(missing_ok=True)   # we created it, empty
            raise RecordingError(f"cannot start recording {self.path}: {exc}") from exc
        self._thread = threading.Thread(target=self._run, name="talus-recorder", daemon=True)
        self._thread.start()

    def _register_cycle(self, cycle: CycleMessage) -> None:
        """The cycle channel (v4): its schema, the time origin, what its parts are."""
        schema_id = self._mcap.register_schema(
            name=cycle.name, encoding=protobuf_codec.SCHEMA_ENCODING,
            data=cycle.file_descriptor_set)
        extra = {**CHANNELS[STATE].metadata, **cycle.metadata(),
                 **time_metadata(self.start_wall_ns, self.loop_t0, self._t_quantum or 1e-9)}
        for part in cycle.parts:
            for f in part.proto.fields:
                if f.code_range is not None:
                    extra[f"talus.{part.name}.{f.name}.range"] = ",".join(map(repr,
                                                                             f.code_range))
        self._channel_ids[CYCLE] = self._mcap.register_channel(
            topic=CYCLE, message_encoding=protobuf_codec.MESSAGE_ENCODING,
            schema_id=schema_id,
            metadata={**extra, JSONSCHEMA_METADATA_KEY: json.dumps(cycle.json_schema)})

    # ------------------------------------------------------------------ producer side (any
    # thread, including the loop's): O(1), no lock, no I/O.

    def attach_state_ring(self, tap: RingSource, start: int | None = None) -> None:
        """Record ``tap``'s rows (a ``RecorderTap``) as ``/robot/state``, one message per row."""
        self.attach_ring(STATE, tap, STATE_LAYOUT, start)

    def attach_ring(self, topic: str, source: RingSource,
                    layout: RowLayout | Iterable[tuple[str, int]],
                    start: int | None = None) -> None:
        """Drain ``source`` periodically into channel ``topic``, one message per row, the row's
        columns named by ``layout`` (a :class:`RowLayout` or its ``((name, width), ...)``).

        ``start`` is the first row index to record (default: the source's current ``written``,
        i.e. rows from now on).
        """
        if not isinstance(layout, RowLayout):
            layout = RowLayout(layout)
        if topic not in self._channel_ids and topic not in self._part:
            raise InputError(f"unknown channel {topic!r}; channels: {sorted(self._channel_ids)}")
        if self._closed:
            raise InputError("the recorder is closed")
        encode: Callable[[np.ndarray], list[bytes]] = layout.encode
        proto = self._protos.get(topic)
        if proto is not None:
            try:
                encode = proto.row_encoder(layout.fields)
            except ProtoCodecError as exc:
                raise InputError(f"channel {topic!r}: ring rows {list(layout.fields)} do not "
                                 f"fit: {exc}") from None
        tap = _RingTap(topic, self._channel_ids.get(topic, -1), source, layout,
                       source.written if start is None else int(start), encode)
        # Copy-on-write: the thread iterates whatever tuple it read, never a list being changed.
        self._taps = self._taps + (tap,)
        part = self._part.get(topic)
        if part is not None and self._joiner is not None:
            # The ring's rows are expected from now on: the cycles of the parts queued before
            # its first drain wait for them (up to cycle_hold_s), not written without them.
            self._joiner.expect(part)

    def expect(self, *topics: str) -> None:
        """Say that ``topics`` (``/robot/wrench``, ``/protocol/reference``) will be given for
        every cycle from now on (a session pump is about to hand them over): with talus.v4 the
        state's cycles wait for them (at most ``cycle_hold_s``) instead of being written
        before their first block arrives. Other encodings: nothing to do."""
        unknown = [t for t in topics if t not in self._channel_ids and t not in self._part]
        if unknown:
            raise InputError(f"unknown channel {unknown[0]!r}; channels: "
                             f"{sorted(self._channel_ids)}")
        if self._joiner is not None:
            for topic in topics:
                part = self._part.get(topic)
                if part is not None:
                    self._joiner.expect(part)

    def event(self, event: dict[str, Any]) -> bool:
        """Enqueue a safety event dict (``SafetyEvent.as_dict()``); usable as
        ``EventLog.listener``. False when dropped (queue full or recorder closed)."""
        t = event.get("t")
        if t is None:
            t = self.loop_t0 + (time.time_ns() - self.start_wall_ns) * 1e-9
        return self._enqueue(EVENTS, float(t), dict(event))

    def wrench(self, t: float, fx: float, fy: float, fz: float, tx: float, ty: float,
               tz: float, stale: bool = False, saturated: bool = False) -> bool:
        """Enqueue one wrench sample (N, N·m) at loop time ``t`` (s). False when dropped."""
        return self._enqueue(WRENCH, t, (fx, fy, fz, tx, ty, tz, stale, saturated))

    def wrench_rows(self, rows: np.ndarray) -> bool:
        """Enqueue a block of wrench samples at once: rows of (t s, fx, fy, fz N, tx, ty, tz
        N·m, stale, saturated) (a copy is kept; flags > 0.5 are true). One queue entry, encoded
        as one numpy block by the writer: the non-real-time producer (the session pump) spends
        no Python per sample. False when dropped (every row counted)."""
        block = np.array(rows, dtype=float, ndmin=2)
        if block.shape[1] != 9:
            raise InputError(f"wrench rows have 9 columns (t, fx..tz, stale, saturated), got "
                             f"{block.shape[1]}")
        if not len(block):
            return True
        return self._enqueue(WRENCH, float(block[0, 0]), _Block(block), len(block))

    def reference_rows(self, t: np.ndarray, force: np.ndarray, phase: Sequence[str],
                       mode: Sequence[str]) -> bool:
        """Enqueue a block of ``/protocol/reference`` messages: loop times ``t`` (s), forces
        (n × 3, N), and per row the phase and mode names. One queue entry, encoded by the
        writer as numpy blocks of equal (phase, mode). False when dropped (rows counted)."""
        tt = np.array(t, dtype=float, ndmin=1)
        ff = np.array(force, dtype=float, ndmin=2)
        if ff.shape != (len(tt), 3) or len(phase) != len(tt) or len(mode) != len(tt):
            raise InputError(f"reference rows: {len(tt)} times need {len(tt)} × 3 forces and "
                             f"as many phases and modes (got {ff.shape}, {len(phase)}, "
                             f"{len(mode)})")
        if not len(tt):
            return True
        block = _Block(np.column_stack([tt, ff]), (tuple(phase), tuple(mode)))
        return self._enqueue(REFERENCE, float(tt[0]), block, len(tt))

    def publish(self, topic: str, message: dict[str, Any]) -> bool:
        """Enqueue a message (with ``t``, loop time in s) on any registered channel, e.g.
        ``/protocol/reference``. False when dropped.

        A protobuf channel's message is encoded here, so a message that does not fit its
        schema (a missing field, a wrong length) is refused with :class:`InputError` now,
        not lost in the writer thread. Not for the loop: it costs a few µs."""
        if topic not in self._channel_ids and topic not in self._part:
            raise InputError(f"unknown channel {topic!r}; channels: {sorted(self._channel_ids)}")
        t = message.get("t")
        if not isinstance(t, numbers.Real) or isinstance(t, bool):
            raise InputError(f"channel {topic!r}: a message needs 't', the loop time in s")
        proto = self._protos.get(topic)
        if proto is not None:
            try:
                return self._enqueue(topic, float(t), proto.encode(message))
            except ProtoCodecError as exc:
                raise InputError(f"channel {topic!r}: {exc}") from None
        return self._enqueue(topic, float(t), message)

    def reference(self, t: float, force: Iterable[float] | None = None,
                  position: Iterable[float] | None = None, phase: str | None = None) -> bool:
        """Enqueue the protocol reference at loop time ``t`` (force N, position m)."""
        msg: dict[str, Any] = {"t": t}
        if force is not None:
            msg["force"] = list(force)
        if position is not None:
            msg["position"] = list(position)
        if phase is not None:
            msg["phase"] = phase
        return self.publish(REFERENCE, msg)

    def _enqueue(self, topic: str, t: float, payload: Any, count: int = 1) -> bool:
        q = self._queue
        if self._closed or len(q) >= self.queue_capacity:
            # Unlocked increment: two producers dropping at the same instant may lose a count;
            # the alternative, a lock, could make the loop wait on the writer thread.
            self._dropped[topic] += count
            return False
        q.append((topic, t, payload))
        return True

    # ------------------------------------------------------------------ state, summary

    @property
    def error(self) -> str | None:
        """Why the writer thread stopped writing, or None while healthy (poll it to warn)."""
        return self._error

    @property
    def closed(self) -> bool:
        return self._closed

    def wait_for_room(self, fraction: float = 0.5, timeout_s: float = 10.0) -> bool:
        """For non-real-time producers that can wait (a pump feeding a fast twin run): block
        until the queue is below ``fraction`` of its capacity, so nothing is dropped; False on
        timeout or when the recorder closed. Never call it from the loop."""
        deadline = time.monotonic() + timeout_s
        while len(self._queue) >= fraction * self.queue_capacity:
            if self._closed or time.monotonic() > deadline:
                return False
            time.sleep(0.002)
        return True

    def dropped(self) -> dict[str, int]:
        """Messages lost so far per topic (queue full, ring overrun), a snapshot."""
        out = dict(self._dropped)
        for tap in self._taps:
            out[tap.topic] += tap.dropped
        return out

    def close(self, timeout_s: float = 30.0) -> dict[str, Any]:
        """Write what is pending, finish the file (summary, footer), join the thread.

        Returns the summary: ``path``, ``complete`` (footer written), ``sha256`` and ``bytes``
        of the file, ``messages`` and ``dropped`` per topic, ``dropped_total``,
        ``duration_s`` (wall), ``writer_busy_s`` and ``writer_us_per_message`` (the thread's
        CPU time, encoding + compression + writing), ``flushes``, ``error``,
        ``wrench_without_sample`` (wrenches not written: no finite sample yet). Safe to call
        twice (returns the same summary).
        """
        with self._close_lock:
            if self._summary is not None:
                return self._summary
            self._closed = True
            self._stop.set()
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                self._error = self._error or f"writer thread did not finish in {timeout_s} s"
            dropped = self.dropped()
            # Whatever is still queued was never written: enqueued after the thread's last
            # pump, or left behind by a thread that died.
            for topic, _, payload in list(self._queue):
                dropped[topic] += len(payload) if isinstance(payload, _Block) else 1
            if self._error is not None:
                for tap in self._taps:
                    dropped[tap.topic] += max(0, tap.source.written - tap.start)
            n = sum(self._sequence.values())       # MCAP messages
            if self._error is None and self._partial is not None:
                try:
                    commit_output(self._partial, self.path, force=True)
                except TalusError as exc:
                    self._error = str(exc)
            elif self._partial is not None and self._error is not None:
                self._error += f"; the previous {self.path} is untouched, this recording " \
                               f"is in {self._partial}"
            complete = self._error is None
            self._summary = {
                "path": str(self.path),
                "complete": complete,
                "sha256": self._stream.sha256.hexdigest() if complete else None,
                "bytes": self._stream.bytes,
                "messages": dict(self._messages),
                "mcap_messages": n,
                "cycles": 0 if self._cycle is None else self._sequence.get(CYCLE, 0),
                "late_parts": 0 if self._joiner is None else self._joiner.late,
                "dropped": dropped,
                "dropped_total": sum(dropped.values()),
                "wrench_without_sample": self._wrench_without_sample,
                "duration_s": time.monotonic() - self._t_open,
                "writer_busy_s": self._busy_s,
                "writer_us_per_message": 1e6 * self._busy_s / n if n else 0.0,
                "flushes": self._flushes,
                "encoding": self.encoding.value,
                "error": self._error,
            }
            return self._summary

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ writer thread

    def _complete_metadata(self, metadata: dict[str, Any]) -> dict[str, Any]:
        start = datetime.fromtimestamp(self.start_wall_ns / 1e9, tz=UTC)
        out = {"t": self.loop_t0, **metadata}
        out.setdefault("software_version", software_version())
        out["start_wall_time"] = start.astimezone().isoformat(timespec="microseconds")
        for key in ("protocol_name", "protocol_version", "patient_id", "robot_description",
                    "software_version"):
            out[key] = str(out[key])
        return out

    def _log_time(self, t: float) -> int:
        # publish_time is the same: the cycle's time is when the message was produced.
        return self.start_wall_ns + round((self._clock.quantize(t) - self.loop_t0) * 1e9)

    def _write(self, topic: str, t: float, data: bytes) -> None:
        part = self._part.get(topic)
        if part is not None:
            # A part of a cycle (v4): joined with the cycle's other parts, written by
            # _write_cycles.
            self._messages[topic] += 1
            assert self._joiner is not None
            self._joiner.add(part, round(self._clock.quantize(t) * 1e6), t, data)
            return
        self._messages[topic] += 1
        self._add(topic, t, data)

    def _add(self, topic: str, t: float, data: bytes) -> None:
        ns = self._log_time(t)
        # Per-channel sequence numbers 1, 2, 3...: a reader sees exactly which messages a
        # skipped (damaged) chunk held, per channel.
        seq = self._sequence[topic] = self._sequence.get(topic, 0) + 1
        self._mcap.add_message(channel_id=self._channel_ids[topic], log_time=ns, data=data,
                               publish_time=ns, sequence=seq)

    def _passed(self, topic: str, ts: Iterable[float]) -> None:
        """A part's source went past these times without a part (a wrench row without a
        sample): its cycles need not wait for it."""
        part = self._part.get(topic)
        if part is not None and self._joiner is not None:
            last = max(ts, default=None)
            if last is not None:
                self._joiner.passed(part, round(self._clock.quantize(last) * 1e6))

    def _write_cycles(self, flush: bool = False) -> int:
        """Write the cycles whose parts are all in (every one with ``flush``)."""
        if self._joiner is None or self._cycle is None:
            return 0
        encode = self._cycle.encode
        ready = self._joiner.ready(flush)
        for t, parts in ready:
            self._add(CYCLE, t, encode(parts))
        return len(ready)

    def _flush_chunk(self) -> None:
        flush = getattr(self._mcap, "flush", None)
        if flush is not None:
            flush()
        else:
            # mcap < 1.6 has no public Writer.flush(): close the open chunk through the private
            # method it uses itself (pin mcap >= 1.6 to drop this branch).
            self._mcap._Writer__finalize_chunk()  # type: ignore[attr-defined]
            self._mcap._Writer__flush()  # type: ignore[attr-defined]
        self._stream.flush()
        if self._fsync:
            os.fsync(self._stream.raw.fileno())
        self._flushes += 1

    def _pump(self) -> None:
        """Write everything available: ring rows, then the queue."""
        written = 0
        for tap in self._taps:
            rows, end = tap.source.drain(tap.start)
            capacity = getattr(tap.source, "capacity", None)
            if capacity is not None:
                # The loop keeps writing while drain() copies: row i shares its slot with row
                # i + capacity, so rows below (written now - capacity) may have been
                # overwritten mid-copy. Only an almost-full ring (a stalled writer) gets here.
                first = end - len(rows)
                unsafe = tap.source.written - capacity - first
                if unsafe > 0:
                    rows = rows[unsafe:]
            tap.dropped += (end - tap.start) - len(rows)
            tap.start = end
            if not len(rows):
                continue
            ts = rows[:, 0].tolist()
            for t, data in zip(ts, tap.encode(rows)):
                self._write(tap.topic, t, data)
                written += 1
                if written % _YIELD_EVERY == 0:
                    time.sleep(0)   # let the loop thread have the GIL
        q = self._queue
        # Only what was queued when this turn began: a producer that keeps the queue busy
        # must not starve the rings (the state would fall far behind in the file).
        items = [q.popleft() for _ in range(len(q))]
        wrenches = self._encode_wrenches(items)
        k = 0
        try:
            for k, (topic, t, payload) in enumerate(items):
                if isinstance(payload, _Block):
                    for t_row, data in self._encode_block(topic, payload):
                        self._write(topic, t_row, data)
                        written += 1
                    time.sleep(0)
                    continue
                if isinstance(payload, bytes):      # encoded by publish()
                    data = payload
                elif topic == WRENCH:
                    if wrenches is not None:
                        encoded = wrenches.get(k)
                        if encoded is None:         # no sample: counted by the encoder
                            continue
                        data = encoded
                    else:
                        fx, fy, fz, tx, ty, tz, stale, saturated = payload
                        if not all(math.isfinite(v) for v in (fx, fy, fz, tx, ty, tz)):
                            # No sample yet (the sensor's NaN): not a measurement, and as
                            # nulls it would break the channel's schema. Counted, not written.
                            self._wrench_without_sample += 1
                            continue
                        data = encode_json({
                            "t": t, "fx": float(fx), "fy": float(fy), "fz": float(fz),
                            "tx": float(tx), "ty": float(ty), "tz": float(tz),
                            "stale": bool(stale), "saturated": bool(saturated)})
                else:
                    data = encode_json(payload)
                self._write(topic, t, data)
                written += 1
                if written % _YIELD_EVERY == 0:
                    time.sleep(0)
        except BaseException:
            for topic, _, payload in items[k:]:       # taken from the queue, never written
                self._dropped[topic] += len(payload) if isinstance(payload, _Block) else 1
            raise
        self._write_cycles()

    def _encode_block(self, topic: str, block: _Block) -> list[tuple[float, bytes]]:
        """(t, bytes) of each message of a queued block (:meth:`wrench_rows`,
        :meth:`reference_rows`)."""
        rows = block.rows
        if topic == WRENCH:
            finite = np.isfinite(rows[:, 1:7]).all(axis=1)
            self._wrench_without_sample += int(len(rows) - finite.sum())
            self._passed(WRENCH, rows[:, 0].tolist())
            rows = rows[finite]
            ts = rows[:, 0].tolist()
            if self._wrench_rows is not None:
                return list(zip(ts, self._wrench_rows(rows)))
            names = ("fx", "fy", "fz", "tx", "ty", "tz")
            return [(t, encode_json({"t": t, **dict(zip(names, r[1:7])),
                                     "stale": bool(r[7] > 0.5), "saturated": bool(r[8] > 0.5)}))
                    for t, r in zip(ts, rows.tolist())]
        phase, mode = block.strings
        ts = rows[:, 0].tolist()
        proto = self._protos.get(topic)
        if proto is None:
            return [(t, encode_json({"t": t, "force": r[1:4], "phase": p, "mode": m}))
                    for t, r, p, m in zip(ts, rows.tolist(), phase, mode)]
        encode = self._reference_rows
        if encode is None:
            encode = self._reference_rows = proto.row_encoder([("t", 1), ("force", 3)])
        numeric = encode(rows)
        out: list[tuple[float, bytes]] = []
        start = 0
        n = len(ts)
        while start < n:               # runs of one (phase, mode): one suffix each
            end = start + 1
            while end < n and phase[end] == phase[start] and mode[end] == mode[start]:
                end += 1
            suffix = proto.encode_strings({"phase": phase[start], "mode": mode[start]})
            out.extend((ts[i], numeric[i] + suffix) for i in range(start, end))
            start = end
        return out

    def _encode_wrenches(self, items: list[tuple[str, float, Any]]) -> dict[int, bytes] | None:
        """Protobuf bytes of the queued wrench samples of ``items`` (by index), encoded as one
        numpy block; samples without a finite value (the sensor has not answered yet) are
        counted and left out. None when the wrench channel is JSON."""
        if self._wrench_rows is None:
            return None
        index = [i for i, (topic, _, payload) in enumerate(items)
                 if topic == WRENCH and not isinstance(payload, (bytes, _Block))]
        if not index:
            return {}
        rows = np.array([(items[i][1], *items[i][2]) for i in index], dtype=float)
        finite = np.isfinite(rows[:, 1:7]).all(axis=1)
        self._passed(WRENCH, rows[:, 0].tolist())
        self._wrench_without_sample += int(len(index) - finite.sum())
        encoded = self._wrench_rows(rows[finite])
        return dict(zip(np.asarray(index)[finite].tolist(), encoded))

    def _run(self) -> None:
        next_flush = time.monotonic() + self.flush_interval_s
        try:
            while True:
                stopping = self._stop.wait(self.drain_period_s)
                t0 = time.thread_time()    # CPU time: waits for the GIL are not the cost
                self._pump()
                if not stopping and time.monotonic() >= next_flush:
                    self._flush_chunk()
                    next_flush = time.monotonic() + self.flush_interval_s
                self._busy_s += time.thread_time() - t0
                if stopping:
                    break
            t0 = time.thread_time()
            while self._queue:     # what producers queued while the last turn ran
                self._pump()
            self._write_cycles(flush=True)      # v4: cycles still waiting for a part
            self._mcap.finish()
            self._stream.flush()
            if self._fsync:
                os.fsync(self._stream.raw.fileno())
            self._busy_s += time.thread_time() - t0
        except Exception as exc:   # noqa: BLE001 - reported by close() and .error
            self._error = f"{type(exc).__name__}: {exc}"
            self._closed = True    # producers now count drops instead of filling the queue
        finally:
            try:
                self._stream.close()
            except OSError as exc:
                self._error = self._error or f"closing {self.path}: {exc}"
