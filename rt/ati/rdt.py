"""ATI Net F/T Raw Data Transfer (RDT) codec: pure functions, no sockets.

Facts taken from ATI's manuals (Net F/T manual 9620-05-Net FT, Ethernet Axia manual
9610-05-Ethernet Axia §12 "UDP Interface Using RDT", which documents the same protocol):

* The sensor listens on UDP port 49152 and answers to the IP address and port that sent the
  command; a newly received command takes precedence over earlier ones.
* Every value is transferred in network byte order (big-endian).
* Request (8 bytes): ``uint16 header = 0x1234``, ``uint16 command``, ``uint32 sample_count``
  (0 = endless). Commands used here: 0x0000 stop streaming, 0x0002 start high-speed real-time
  streaming (one record per datagram), 0x0003 start high-speed buffered streaming (the
  configured "RDT buffer size" records per datagram), 0x0042 set software bias.
  The manual also lists 0x0001 (Axia: single block), 0x0004 (multi-unit streaming) and 0x0041
  (reset threshold latch); talus does not use them and refuses them as unknown.
* Record (36 bytes): ``uint32 rdt_sequence, uint32 ft_sequence, uint32 status``, then
  ``int32 Fx, Fy, Fz, Tx, Ty, Tz`` in counts. Force = counts / counts-per-force (N with the
  usual metric calibration), torque = counts / counts-per-torque (N m); both factors come from
  the device's configuration (``cfgcpf``/``cfgcpt``; 1,000,000 for typical calibrations).
* Status word bits (Ethernet Axia manual, "Status Code" table): bit 31 = any error,
  bit 30 = force/torque out of range (sensing range exceeded), bit 27 = gage out of range.
  **Not verified for the Net F/T** (its status-word table was not available); the twin uses
  these positions and the clients test exactly these bits.

Not from the manual (talus choices, documented where used): ``sample_count`` counts records,
not datagrams, in buffered mode too; ``rdt_sequence`` numbers every record (also inside a
buffered datagram) and restarts at 1 after each start command.
"""
from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

from rt.errors import InputError, ProtocolError

#: Default UDP port of the RDT server on the sensor.
RDT_PORT = 49152
#: Fixed header of every RDT request.
RDT_HEADER = 0x1234

CMD_STOP = 0x0000
CMD_START_REALTIME = 0x0002
CMD_START_BUFFERED = 0x0003
CMD_SET_SOFTWARE_BIAS = 0x0042

#: command code -> name, the commands talus speaks.
COMMANDS: dict[int, str] = {
    CMD_STOP: "stop",
    CMD_START_REALTIME: "start real-time streaming",
    CMD_START_BUFFERED: "start buffered streaming",
    CMD_SET_SOFTWARE_BIAS: "set software bias",
}

REQUEST_STRUCT = struct.Struct(">HHI")
RECORD_STRUCT = struct.Struct(">III6i")
REQUEST_SIZE = REQUEST_STRUCT.size  # 8 bytes
RECORD_SIZE = RECORD_STRUCT.size  # 36 bytes

STATUS_ANY_ERROR = 1 << 31
STATUS_FT_OUT_OF_RANGE = 1 << 30
STATUS_GAGE_OUT_OF_RANGE = 1 << 27
#: Bits that mean "the reading is clipped/saturated"; clients set ``Wrench.saturated`` from them.
STATUS_SATURATION_MASK = STATUS_FT_OUT_OF_RANGE | STATUS_GAGE_OUT_OF_RANGE

#: Net F/T default counts per force unit (counts/N) and per torque unit (counts/(N m)).
DEFAULT_COUNTS_PER_FORCE = 1_000_000.0
DEFAULT_COUNTS_PER_TORQUE = 1_000_000.0

_UINT32_MAX = 0xFFFF_FFFF
_INT32_MIN = -(1 << 31)
_INT32_MAX = (1 << 31) - 1


class RdtRequest(NamedTuple):
    """A decoded request: ``command`` code and ``sample_count`` (records, 0 = endless)."""

    command: int
    sample_count: int


class RdtRecord(NamedTuple):
    """One decoded record; ``counts`` are Fx, Fy, Fz, Tx, Ty, Tz in raw counts."""

    rdt_sequence: int
    ft_sequence: int
    status: int
    counts: tuple[int, int, int, int, int, int]


@dataclass(frozen=True, slots=True)
class CountsPerUnit:
    """Scale between raw counts and SI: ``force`` in counts/N, ``torque`` in counts/(N m)."""

    force: float = DEFAULT_COUNTS_PER_FORCE
    torque: float = DEFAULT_COUNTS_PER_TORQUE

    def __post_init__(self) -> None:
        if not (self.force > 0.0 and self.torque > 0.0):
            raise InputError(
                f"counts per unit must be positive, got force={self.force}, torque={self.torque}")

    def to_si(self, counts: Sequence[int], out: list[float]) -> list[float]:
        """Counts (Fx..Tz) -> N and N m written into ``out`` (len 6) and returned."""
        cpf, cpt = self.force, self.torque
        out[0] = counts[0] / cpf
        out[1] = counts[1] / cpf
        out[2] = counts[2] / cpf
        out[3] = counts[3] / cpt
        out[4] = counts[4] / cpt
        out[5] = counts[5] / cpt
        return out

    def to_counts(self, values: Sequence[float]) -> tuple[int, int, int, int, int, int]:
        """N and N m -> counts, rounded to nearest and clipped to the int32 range of a record."""
        cpf, cpt = self.force, self.torque
        return (
            _clip_int32(values[0] * cpf), _clip_int32(values[1] * cpf),
            _clip_int32(values[2] * cpf), _clip_int32(values[3] * cpt),
            _clip_int32(values[4] * cpt), _clip_int32(values[5] * cpt),
        )


def _clip_int32(x: float) -> int:
    if math.isnan(x):  # NaN has no count; the device never sends one, so neither do we
        raise InputError("cannot encode NaN as RDT counts")
    if x >= _INT32_MAX:
        return _INT32_MAX
    if x <= _INT32_MIN:
        return _INT32_MIN
    return round(x)


def encode_request(command: int, sample_count: int = 0) -> bytes:
    """The 8-byte request for ``command`` with ``sample_count`` records (0 = endless)."""
    if command not in COMMANDS:
        raise InputError(f"unknown RDT command 0x{command:04x}; known: "
                         + ", ".join(f"0x{c:04x} ({n})" for c, n in COMMANDS.items()))
    if not 0 <= sample_count <= _UINT32_MAX:
        raise InputError(f"RDT sample count {sample_count} outside 0..{_UINT32_MAX}")
    return REQUEST_STRUCT.pack(RDT_HEADER, command, sample_count)


def decode_request(data: bytes | bytearray | memoryview) -> RdtRequest:
    """Parse one request datagram; ``ProtocolError`` names what is wrong."""
    if len(data) != REQUEST_SIZE:
        raise ProtocolError(
            f"RDT request has wrong length: {len(data)} bytes, expected {REQUEST_SIZE}")
    header, command, count = REQUEST_STRUCT.unpack(data)
    if header != RDT_HEADER:
        raise ProtocolError(
            f"RDT request has wrong header 0x{header:04x}, expected 0x{RDT_HEADER:04x}")
    if command not in COMMANDS:
        raise ProtocolError(f"RDT request has unknown command 0x{command:04x}")
    return RdtRequest(command, count)


def encode_record(rdt_sequence: int, ft_sequence: int, status: int,
                  counts: Sequence[int]) -> bytes:
    """One 36-byte record; sequence numbers wrap modulo 2**32 as on the device."""
    out = bytearray(RECORD_SIZE)
    pack_record_into(out, 0, rdt_sequence, ft_sequence, status, counts)
    return bytes(out)


def pack_record_into(buffer: bytearray | memoryview, offset: int, rdt_sequence: int,
                     ft_sequence: int, status: int, counts: Sequence[int]) -> None:
    """Write one record at ``offset`` of a preallocated ``buffer`` (no allocation per record)."""
    if len(counts) != 6:
        raise InputError(f"an RDT record carries 6 counts, got {len(counts)}")
    try:
        RECORD_STRUCT.pack_into(
            buffer, offset, rdt_sequence & _UINT32_MAX, ft_sequence & _UINT32_MAX,
            status & _UINT32_MAX, counts[0], counts[1], counts[2], counts[3], counts[4],
            counts[5])
    except struct.error as exc:
        raise InputError(f"RDT record values out of range: {exc}") from None


def decode_record(data: bytes | bytearray | memoryview, offset: int = 0) -> RdtRecord:
    """Parse the record at ``offset``; ``ProtocolError`` if fewer than 36 bytes remain."""
    if len(data) - offset < RECORD_SIZE:
        raise ProtocolError(
            f"RDT record truncated: {len(data) - offset} bytes at offset {offset}, "
            f"expected {RECORD_SIZE}")
    v = RECORD_STRUCT.unpack_from(data, offset)
    return RdtRecord(v[0], v[1], v[2], (v[3], v[4], v[5], v[6], v[7], v[8]))


def check_datagram(data: bytes | bytearray | memoryview) -> int:
    """Number of records in a response datagram; ``ProtocolError`` if its length is wrong."""
    n = len(data)
    if n == 0 or n % RECORD_SIZE:
        raise ProtocolError(
            f"RDT datagram has wrong length: {n} bytes, expected a positive multiple of "
            f"{RECORD_SIZE}")
    return n // RECORD_SIZE


def decode_datagram(data: bytes | bytearray | memoryview) -> list[RdtRecord]:
    """Every record of one response datagram (one in real-time mode, several when buffered)."""
    n = check_datagram(data)
    return [decode_record(data, i * RECORD_SIZE) for i in range(n)]


def encode_datagram(records: Sequence[RdtRecord]) -> bytes:
    """Pack several records into one datagram (buffered mode)."""
    if not records:
        raise InputError("an RDT datagram carries at least one record")
    out = bytearray(RECORD_SIZE * len(records))
    for i, r in enumerate(records):
        pack_record_into(out, i * RECORD_SIZE, r.rdt_sequence, r.ft_sequence, r.status,
                         r.counts)
    return bytes(out)


def is_saturated(status: int) -> bool:
    """True when the status word flags force/torque or gage out of range."""
    return bool(status & STATUS_SATURATION_MASK)


def sequence_gap(previous: int, current: int) -> int:
    """Records lost between two consecutive ``rdt_sequence`` values (uint32, wrapping).

    Returns 0 for the next record, n for n missing ones, and -1 for a repeat or a backwards
    jump (reordering or a restarted stream), which is not a loss.
    """
    delta = (current - previous) & _UINT32_MAX
    if delta == 0 or delta >= 1 << 31:
        return -1
    return delta - 1
