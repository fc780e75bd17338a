"""ATI Net F/T CAN protocol codec: pure functions on (arbitration id, payload bytes).

From the Net F/T manual (9620-05-Net FT, section 15 "CAN Bus Operation"):

* 11-bit identifiers; the CAN base address (and baud rate) is set with the DIP switches.
* A request is a 1-byte message sent to the **base address**; its byte is an opcode:
  0x01 = request long data (32-bit values in four messages), 0x02 = request short data
  (16-bit values in two messages), 0x04 = bias (zeroes the readings at the current load; no
  reply). A request received during an ongoing transmission aborts it.
* Short-data reply, two 8-byte messages, little-endian, signed two's complement:

  ======== ========================================================
  base + 5  Fx (int16), Tx (int16), Fy (int16), Ty (int16)
  base + 6  Fz (int16), Tz (int16), system status (16 bit), sample number (16 bit)
  ======== ========================================================

Not from the manual (talus choices, marked where they matter):

* Long data (0x01) is not implemented: its message identifiers were not verified.
* Which 16 bits of the 32-bit status word the short format carries was not verified; talus
  carries the upper half (``status32 >> 16``), which keeps the error (bit 31 -> 15) and
  out-of-range bits (30 -> 14, 27 -> 11) defined in ``rt.ati.rdt``.
* The scale of the 16-bit values (counts per N and per N m) is device configuration; the
  talus defaults (16 counts/N, 500 counts/(N m)) make the Delta SI-660-60 ranges (1980 N,
  60 N m) fit in int16. Set them from the sensor.
* The sample number is treated as an unsigned 16-bit counter.
"""
from __future__ import annotations

import math
import struct
from collections.abc import Sequence

from rt.ati.rdt import CountsPerUnit
from rt.errors import InputError, ProtocolError

OP_REQUEST_LONG = 0x01
OP_REQUEST_SHORT = 0x02
OP_BIAS = 0x04
#: opcode -> name, the requests talus speaks.
OPCODES: dict[int, str] = {OP_REQUEST_SHORT: "request short data", OP_BIAS: "bias"}

OFFSET_SHORT_XY = 5
OFFSET_SHORT_Z = 6
MAX_STANDARD_ID = 0x7FF
MAX_BASE_ID = MAX_STANDARD_ID - OFFSET_SHORT_Z

DEFAULT_CAN_COUNTS_PER_FORCE = 16.0
DEFAULT_CAN_COUNTS_PER_TORQUE = 500.0

_XY = struct.Struct("<4h")
_Z = struct.Struct("<2h2H")
FRAME_SIZE = 8
_INT16_MIN, _INT16_MAX = -(1 << 15), (1 << 15) - 1

#: Saturation bits of the 16-bit short-format status (talus mapping, see module docstring).
STATUS16_SATURATION_MASK = (1 << 14) | (1 << 11)


def default_can_counts() -> CountsPerUnit:
    """The talus default short-format scale (counts/N, counts/(N m))."""
    return CountsPerUnit(DEFAULT_CAN_COUNTS_PER_FORCE, DEFAULT_CAN_COUNTS_PER_TORQUE)


def check_base_id(base_id: int) -> int:
    """``base_id`` if its replies (base+5, base+6) fit in 11-bit identifiers."""
    if not 0 <= base_id <= MAX_BASE_ID:
        raise InputError(
            f"ATI CAN base id 0x{base_id:x} outside 0..0x{MAX_BASE_ID:x} (replies use base+6)")
    return base_id


def encode_request(opcode: int) -> bytes:
    """The 1-byte payload of a request (send it to the base id)."""
    if opcode not in OPCODES:
        raise InputError(f"unknown ATI CAN opcode 0x{opcode:02x}; known: "
                         + ", ".join(f"0x{o:02x} ({n})" for o, n in OPCODES.items()))
    return bytes((opcode,))


def decode_request(base_id: int, arbitration_id: int, data: bytes | bytearray) -> int:
    """The opcode of a request frame; ``ProtocolError`` names what is wrong."""
    if arbitration_id != base_id:
        raise ProtocolError(
            f"ATI CAN request sent to id 0x{arbitration_id:x}, expected base id 0x{base_id:x}")
    if len(data) != 1:
        raise ProtocolError(f"ATI CAN request has {len(data)} data bytes, expected 1")
    opcode = data[0]
    if opcode not in OPCODES:
        raise ProtocolError(f"ATI CAN request has unknown opcode 0x{opcode:02x}")
    return opcode


def to_counts16(values: Sequence[float], scale: CountsPerUnit) -> tuple[int, ...]:
    """N and N m -> int16 counts (rounded, clipped to the int16 range as the device saturates)."""
    out = []
    for i in range(6):
        x = values[i] * (scale.force if i < 3 else scale.torque)
        if math.isnan(x):
            raise InputError("cannot encode NaN as ATI CAN counts")
        out.append(_INT16_MAX if x >= _INT16_MAX else _INT16_MIN if x <= _INT16_MIN
                   else round(x))
    return tuple(out)


def status16_from_status32(status: int) -> int:
    """The 16-bit short-format status carried for a 32-bit status word (talus mapping)."""
    return (status >> 16) & 0xFFFF


def status32_from_status16(status16: int) -> int:
    """Back to the 32-bit word layout of ``rt.ati.rdt`` (the lower half is unknown: zero)."""
    return (status16 & 0xFFFF) << 16


def encode_short_response(counts: Sequence[int], status16: int,
                          sample: int) -> tuple[bytes, bytes]:
    """Payloads for base+5 and base+6 from counts (Fx, Fy, Fz, Tx, Ty, Tz, int16)."""
    if len(counts) != 6:
        raise InputError(f"a short reply carries 6 counts, got {len(counts)}")
    try:
        xy = _XY.pack(counts[0], counts[3], counts[1], counts[4])
        z = _Z.pack(counts[2], counts[5], status16 & 0xFFFF, sample & 0xFFFF)
    except struct.error as exc:
        raise InputError(f"ATI CAN counts out of int16 range: {exc}") from None
    return xy, z


def decode_short_xy(data: bytes | bytearray) -> tuple[int, int, int, int]:
    """(Fx, Tx, Fy, Ty) counts from a base+5 payload."""
    if len(data) != FRAME_SIZE:
        raise ProtocolError(f"ATI CAN Fx/Tx/Fy/Ty frame has {len(data)} data bytes, expected 8")
    return _XY.unpack(data)


def decode_short_z(data: bytes | bytearray) -> tuple[int, int, int, int]:
    """(Fz, Tz, status16, sample) from a base+6 payload."""
    if len(data) != FRAME_SIZE:
        raise ProtocolError(f"ATI CAN Fz/Tz/status frame has {len(data)} data bytes, expected 8")
    return _Z.unpack(data)
