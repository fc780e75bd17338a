"""``talus.v4``: one MCAP message per loop cycle, its state, wrench and reference together.

Why (issue 16, ≤ 150 MB per hour at 1 kHz): recorded as three channels, each cycle paid
MCAP's message framing three times (a 31-byte record header whose log time, publish time and
sequence change every message: ≈ 50-67 MB/h of the 217 MB/h of ``talus.v3``). Joined, it is
paid once. Foxglove still plots every cycle: ``/robot/cycle`` carries one
``talus.v4.Cycle`` per cycle, and a plot path is ``/robot/cycle.wrench.fz_n16``.

The message (proto3, package ``talus.v4``, one ``.proto`` file in the schema's
``FileDescriptorSet``)::

    message Cycle {
      RobotState state = 1;              // rt.recording.channels.STATE_PROTO_V4
      Wrench wrench = 2;                 // WRENCH_PROTO_V4; absent: no ATI sample yet
      ProtocolReference reference = 3;   // REFERENCE_PROTO_V4; absent outside a program
    }

A part is absent when its source gave nothing for that cycle (the ATI has not answered yet,
the state ring lost rows, the reference starts after the state ring): nothing is invented.
The payload carries no time: the message's log time (= publish time) is the cycle's loop
time, through the channel's time origin (``rt.recording.channels.LoopClock``), as in v3.

The readers (``rt.recording.reader``) give a cycle back as its parts, on the topics they had
as channels (:data:`PARTS`: ``/robot/state``, ``/robot/wrench``, ``/protocol/reference``),
each with ``t``: the reports, Review, ``record info|export`` and identification read a v4 file
as they read v3's.

The parts come from different threads at different times (the state from the loop's ring,
drained every 20 ms; the wrench and reference from the session pump in blocks of ≈ 50 ms), so
the writer joins them by cycle time (:class:`CycleJoiner`) before writing a cycle.
"""
from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from rt.recording.channels import (
    _REFERENCE,
    _STATE,
    _WRENCH,
    CYCLE,
    REFERENCE,
    REFERENCE_PROTO_V4,
    SCHEMA_DIALECT,
    STATE,
    STATE_PROTO_V4,
    WRENCH,
    WRENCH_PROTO_V4,
)
from rt.recording.protobuf_codec import ProtoCodecError, ProtoMessage, _read_varint, _varint

#: Channel metadata of a cycle channel: cycles per message (1: every cycle is a message,
#: Foxglove plots each) and the parts' former topics (JSON: part field → topic).
CYCLES_PER_MESSAGE_KEY = "talus.cycles_per_message"
PARTS_KEY = "talus.parts"


@dataclass(frozen=True)
class Part:
    """One sub-message of a cycle: its field name and number, the topic it was recorded on
    as a channel (and is read back as), its message and JSON Schema."""

    name: str
    number: int
    topic: str
    proto: ProtoMessage
    schema: dict[str, Any]


class CycleMessage:
    """A message holding one loop cycle's parts as sub-messages (``talus.v4.Cycle``)."""

    def __init__(self, name: str, parts: Sequence[Part]):
        self.name = name
        self.package, self.short_name = name.rsplit(".", 1)
        self.parts = tuple(parts)
        for p in self.parts:
            if p.proto.package != self.package or not 1 <= p.number <= 15:
                raise ValueError(f"{name}: part {p.name} must be in package {self.package}, "
                                 "number 1..15")
            if p.proto.carries_t:
                raise ValueError(f"{name}: part {p.name} carries t (the log time is the time)")
        self.by_number = {p.number: p for p in self.parts}
        self.by_topic = {p.topic: p for p in self.parts}
        #: Topic of each part, in part order (what the readers give back).
        self.topics = tuple(p.topic for p in self.parts)
        self._tags = tuple(bytes(((p.number << 3) | 2,)) for p in self.parts)

    @cached_property
    def file_descriptor_set(self) -> bytes:
        """The Schema record's data: one proto3 file declaring the parts' messages and the
        cycle, deterministic bytes (what Foxglove and ``mcap_protobuf`` decode with)."""
        from google.protobuf import descriptor_pb2 as d

        fdp = d.FileDescriptorProto(name=f"{self.package.replace('.', '/')}/{self.short_name}"
                                         ".proto", package=self.package, syntax="proto3")
        for p in self.parts:
            p.proto.add_descriptor(fdp)
        msg = fdp.message_type.add(name=self.short_name)
        for p in self.parts:
            msg.field.add(name=p.name, number=p.number,
                          type=d.FieldDescriptorProto.TYPE_MESSAGE,
                          type_name=f".{p.proto.name}",
                          label=d.FieldDescriptorProto.LABEL_OPTIONAL, json_name=p.name)
        return d.FileDescriptorSet(file=[fdp]).SerializeToString(deterministic=True)

    @cached_property
    def json_schema(self) -> dict[str, Any]:
        """The decoded cycle's JSON Schema: each part's channel schema under its name (units
        and descriptions; ``t`` is the cycle's, from the log time)."""
        props = {p.name: {k: v for k, v in p.schema.items() if k != "$schema"}
                 for p in self.parts}
        return {"$schema": SCHEMA_DIALECT, "title": self.name,
                "description": "One loop cycle: " + ", ".join(
                    f"{p.name} (as {p.topic})" for p in self.parts) + "; a part is absent "
                    "when its source gave nothing that cycle.",
                "type": "object", "properties": props, "required": []}

    def metadata(self) -> dict[str, str]:
        """Channel metadata describing the cycle (besides the time origin)."""
        return {CYCLES_PER_MESSAGE_KEY: "1",
                PARTS_KEY: json.dumps({p.name: p.topic for p in self.parts})}

    def encode(self, parts: Sequence[bytes | None]) -> bytes:
        """The cycle from its parts' encoded sub-messages (None: absent), in part order."""
        out = []
        for tag, data in zip(self._tags, parts):
            if data is None:
                continue
            n = len(data)
            out.append(tag + (bytes((n,)) if n < 0x80 else _varint(n)) + data)
        return b"".join(out)

    def split(self, data: bytes) -> list[tuple[Part, bytes]]:
        """The parts present in ``data`` and their bytes (any proto3 order; unknown fields
        skipped; a repeated part: the last wins, as proto3 merges a message field... here
        the last one, which is all our writer ever writes)."""
        found: dict[int, bytes] = {}
        i, n = 0, len(data)
        while i < n:
            key, i = _read_varint(data, i)
            number, wire = key >> 3, key & 7
            if wire == 2:
                length, i = _read_varint(data, i)
                if i + length > n:
                    raise ProtoCodecError(f"{self.name}: message cut inside field {number}")
                if number in self.by_number:
                    found[number] = data[i:i + length]
                i += length
            elif wire == 0:
                _, i = _read_varint(data, i)
            elif wire in (1, 5):
                i += 8 if wire == 1 else 4
            else:
                raise ProtoCodecError(f"{self.name}: unsupported wire type {wire}")
        if i > n:
            raise ProtoCodecError(f"{self.name}: message cut short")
        return [(p, found[p.number]) for p in self.parts if p.number in found]

    def decode(self, data: bytes) -> dict[str, dict[str, Any]]:
        """Part name → its dict (the parts present)."""
        return {p.name: p.proto.decode(raw) for p, raw in self.split(bytes(data))}


#: ``talus.v4.Cycle``: the default 1 kHz recording (:attr:`Encoding.PROTOBUF`).
CYCLE_V4 = CycleMessage("talus.v4.Cycle", [
    Part("state", 1, STATE, STATE_PROTO_V4, _STATE),
    Part("wrench", 2, WRENCH, WRENCH_PROTO_V4, _WRENCH),
    Part("reference", 3, REFERENCE, REFERENCE_PROTO_V4, _REFERENCE)])

#: Cycle messages talus writes or wrote, by full name (the readers'), and the topic each is
#: written on.
CYCLE_MESSAGES: dict[str, CycleMessage] = {CYCLE_V4.name: CYCLE_V4}
CYCLE_TOPIC = CYCLE

#: Seconds (writer's monotonic clock) a cycle waits for a part whose source has not been
#: heard yet, or has fallen silent, before it is written without it. The session pump hands
#: its rows every ≈ 50 ms; a late part is still written (a cycle of that part alone, at its
#: time), so this bounds only how long a cycle may wait, never what is kept.
DEFAULT_HOLD_S = 0.5
#: ``CycleJoiner.reached`` of an expected source before it gave anything: below every key.
_NOTHING_YET = -(1 << 62)


class CycleJoiner:
    """Joins the parts of each cycle, arriving from different sources at different times.

    Each part is added with its cycle's key (the loop time in µs, an int) and its encoded
    bytes; ``passed(part, key)`` says that a source has gone past ``key`` without a part for
    it (e.g. a wrench row without a sample). A cycle is ready when each part is present, or
    its source has gone past the cycle or was never heard from, or the cycle has waited
    :data:`DEFAULT_HOLD_S` (``hold_s``); ready cycles come out in time order. A part that
    arrives after its cycle was written (e.g. the session pump's first block, after the
    state ring's first drain) is written in a cycle of its own at its time: nothing is
    dropped, and each part's topic stays in time order.
    """

    def __init__(self, n_parts: int, hold_s: float = DEFAULT_HOLD_S,
                 clock: Callable[[], float] = time.monotonic):
        self.n = n_parts
        self.hold_s = float(hold_s)
        self.clock = clock
        #: key → [t (s), first arrival (clock), part bytes or None ...]
        self._pending: dict[int, list[Any]] = {}
        #: Per part: the latest key its source has reached (None: not heard from yet).
        self.reached: list[int | None] = [None] * n_parts
        #: Parts written in a cycle of their own because they came after it was written.
        self.late = 0
        self._last_out: int | None = None

    def __len__(self) -> int:
        return len(self._pending)

    def add(self, part: int, key: int, t: float, data: bytes) -> None:
        entry = self._pending.get(key)
        if entry is None:
            entry = self._pending[key] = [t, self.clock(), *([None] * self.n)]
            if self._last_out is not None and key <= self._last_out:
                self.late += 1
        entry[2 + part] = data
        self.passed(part, key)

    def expect(self, part: int) -> None:
        """Wait for ``part`` from now on, before its source is heard from (a ring attached
        before the first row was drained): its cycles are not written without it."""
        if self.reached[part] is None:
            self.reached[part] = _NOTHING_YET

    def passed(self, part: int, key: int) -> None:
        r = self.reached[part]
        if r is None or key > r:
            self.reached[part] = key

    def ready(self, flush: bool = False) -> list[tuple[float, list[bytes | None]]]:
        """The cycles that can be written now (all, with ``flush``), oldest first: their
        ``t`` and parts."""
        pending = self._pending
        if not pending:
            return []
        keys = sorted(pending)
        out: list[tuple[float, list[bytes | None]]] = []
        now = self.clock()
        reached = self.reached
        n = self.n
        for key in keys:
            entry = pending[key]
            if not flush and now - entry[1] < self.hold_s:
                waiting = False
                for p in range(n):
                    if entry[2 + p] is None:
                        r = reached[p]
                        # A source never heard from is not waited for (a recording of the
                        # state alone must not hold its cycles back); one that has been
                        # heard is, until it passes the cycle or the cycle's hold ends.
                        if r is not None and r < key:
                            waiting = True
                            break
                if waiting:
                    break        # later cycles wait too: the file stays in time order
            del pending[key]
            out.append((entry[0], entry[2:]))
            if self._last_out is None or key > self._last_out:
                self._last_out = key
        return out
