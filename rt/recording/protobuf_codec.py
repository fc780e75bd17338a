"""Protobuf encoding of the recording's fast channels: the schema, the encoders, the decoders.

Why protobuf: MCAP's well-known binary encodings that Foxglove opens without a plugin are
protobuf, ROS 1/2 (needing a ROS message definition language and, for ROS 2, CDR), and
flatbuffers. Protobuf's schema is self-contained (a ``FileDescriptorSet`` in the Schema record,
``schema_encoding="protobuf"``, ``message_encoding="protobuf"``), every mcap reader decodes it
(``mcap_protobuf.decoder.DecoderFactory`` in Python), and its wire format for the fixed numeric
messages recorded at 1 kHz is a handful of tag bytes around little-endian IEEE floats, so a
whole drained block of ring rows is encoded at once with numpy (:class:`ProtoMessage.encode_rows`)
instead of one Python call per value.

Wire format used (protobuf encoding spec, "Message Structure", "Packed Repeated Fields"):

* ``double`` field: tag ``(n << 3) | 1`` then 8 bytes; ``float``: tag ``(n << 3) | 5`` then 4;
  ``bool``: tag ``(n << 3) | 0`` then one varint byte 0/1;
* ``repeated float`` (packed, proto3's default): tag ``(n << 3) | 2``, a varint byte count,
  the floats; ``string``: tag ``(n << 3) | 2``, a varint byte count, UTF-8.

Every field of a fixed message is always written, zeros included: a proto3 writer may omit a
default value and any reader accepts it present, and a constant size per message is what lets
the numpy encoder (and the reader's ``struct`` fast path) work on blocks. Field numbers stay
below 16 so every tag is one byte.

Decoded messages are the same dicts as the JSON channels' (same field names; arrays as lists;
a value that was not finite when recorded reads as ``None``, like the JSON recordings' ``null``;
an empty optional array or string is absent), so every reader of recordings is encoding-blind.
"""
from __future__ import annotations

import enum
import functools
import math
import operator
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

#: MCAP well-known schema encoding and message encoding for protobuf channels.
SCHEMA_ENCODING = "protobuf"
MESSAGE_ENCODING = "protobuf"
#: Protobuf package of every talus message (full names ``talus.RobotState`` ...).
PACKAGE = "talus"


class Kind(enum.Enum):
    """A field's protobuf scalar type. ``SFIXED32``/``SFIXED64`` carry a fixed-point number:
    an integer count of the field's ``scale`` (its SI value = count × scale)."""

    DOUBLE = "double"
    FLOAT = "float"
    BOOL = "bool"
    STRING = "string"
    SFIXED32 = "sfixed32"
    SFIXED64 = "sfixed64"


#: Variable-length repeated field (an optional array): ``ProtoField.width``.
VARIABLE = -1

_WIRE_TYPE = {Kind.DOUBLE: 1, Kind.FLOAT: 5, Kind.BOOL: 0, Kind.SFIXED32: 5, Kind.SFIXED64: 1}
_NUMPY = {Kind.DOUBLE: "<f8", Kind.FLOAT: "<f4", Kind.BOOL: "u1", Kind.SFIXED32: "<i4",
          Kind.SFIXED64: "<i8"}
_STRUCT = {Kind.DOUBLE: "d", Kind.FLOAT: "f", Kind.BOOL: "?", Kind.SFIXED32: "i",
           Kind.SFIXED64: "q"}
_SIZE = {Kind.DOUBLE: 8, Kind.FLOAT: 4, Kind.BOOL: 1, Kind.SFIXED32: 4, Kind.SFIXED64: 8}
#: A fixed-point field's count that means "not finite when recorded" (or beyond the type's
#: range): the most negative integer, which no in-range value rounds to.
NOT_FINITE = {Kind.SFIXED32: -(1 << 31), Kind.SFIXED64: -(1 << 63)}
_INT_MAX = {Kind.SFIXED32: (1 << 31) - 1, Kind.SFIXED64: (1 << 63) - 1}


class ProtoCodecError(ValueError):
    """A message that does not fit its protobuf layout (names the field)."""


@dataclass(frozen=True)
class ProtoField:
    """One field: name (as in the JSON channel), number (1-15), kind, width.

    ``width`` 0 is a scalar, ``n > 0`` a packed repeated field always holding ``n`` values
    (one per leg ...), :data:`VARIABLE` an optional repeated field (absent when empty).
    Units and descriptions are the channel's JSON Schema's (``rt.recording.channels``).
    """

    name: str
    number: int
    kind: Kind
    width: int = 0
    #: Fixed-point fields: SI units per count (e.g. 1e-6 for a field in µm holding metres).
    scale: float | None = None
    #: The decoded dict's key when it differs from the wire name (``q`` for ``q_um``): the
    #: dicts stay those of the JSON channels, in SI units, whatever the encoding.
    key: str | None = None
    #: An instrument's code instead of a plain count: ``(v_min, v_max, maxdata)`` of a
    #: converter's range. The count is then the code the converter makes of the value
    #: (``floor((v - v_min) / (v_max - v_min) * maxdata + 0.5)``, clamped to 0..maxdata, as
    #: comedi's ``comedi_from_phys``), and reads back as the value that code stands for
    #: (``v_min + code / maxdata * (v_max - v_min)``); ``scale`` is then one code's step.
    code_range: tuple[float, float, int] | None = None

    def __post_init__(self) -> None:
        if (self.kind in NOT_FINITE) != (self.scale is not None):
            raise ValueError(f"field {self.name}: a scale is for fixed-point fields, and they "
                             "need one")
        if self.code_range is not None:
            lo, hi, maxdata = self.code_range
            if self.scale is None or not (hi > lo and maxdata > 0) or \
                    abs(self.scale - (hi - lo) / maxdata) > 1e-12 * (hi - lo):
                raise ValueError(f"field {self.name}: code_range {self.code_range} needs a "
                                 "fixed-point kind and scale (v_max - v_min) / maxdata")
        if self.scale is not None and not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"field {self.name}: scale {self.scale}")
        if not 1 <= self.number <= 15:
            raise ValueError(f"field {self.name}: number {self.number} outside 1..15 (one-byte "
                             "tags)")
        if self.kind in (Kind.STRING, Kind.BOOL) and self.width != 0:
            raise ValueError(f"field {self.name}: repeated {self.kind.value} is not supported")
        if self.width < VARIABLE:
            raise ValueError(f"field {self.name}: width {self.width}")

    @property
    def dict_key(self) -> str:
        return self.key or self.name

    @property
    def fixed(self) -> bool:
        """Always present with a constant size (so block-encodable)."""
        return self.kind is not Kind.STRING and self.width != VARIABLE

    @property
    def tag(self) -> int:
        packed = self.width != 0 or self.kind is Kind.STRING
        return (self.number << 3) | (2 if packed else _WIRE_TYPE[self.kind])


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def _read_varint(data: bytes, i: int) -> tuple[int, int]:
    if i < len(data) and data[i] < 0x80:
        return data[i], i + 1          # every tag and length we write: one byte
    shift = result = 0
    while True:
        if i >= len(data):
            raise ProtoCodecError("message cut inside a varint")
        b = data[i]
        i += 1
        result |= (b & 0x7F) << shift
        if not b & 0x80:
            return result, i
        shift += 7
        if shift > 63:
            raise ProtoCodecError("varint longer than 10 bytes")


@functools.lru_cache(maxsize=256)
def _packed(code: str, count: int) -> struct.Struct:
    return struct.Struct(f"<{count}{code}")


def _finite(v: float) -> float | None:
    return v if math.isfinite(v) else None


#: Largest fixed-point count used (beyond it a value is not representable): the type's
#: range, and 2**53 for 64-bit counts so that a float64 count converts exactly.
_COUNT_LIMIT = {Kind.SFIXED32: float(_INT_MAX[Kind.SFIXED32]), Kind.SFIXED64: float(1 << 53)}


@functools.lru_cache(maxsize=64)
def _per_unit(scale: float) -> float:
    """Counts per SI unit: an integer when the scale is 10^-n, so that a count divided by it is
    the double nearest to the decimal value (12 µm → 1.2e-05 m, not 1.2000000000000002e-05)."""
    inv = 1.0 / scale
    return float(round(inv)) if abs(inv - round(inv)) <= 1e-9 * inv else inv


def _from_count(v: int, f: ProtoField) -> float | None:
    """A fixed-point count → its SI value (None for the not-finite mark)."""
    if v == NOT_FINITE[f.kind]:
        return None
    if f.code_range is not None:
        lo, hi, maxdata = f.code_range
        return lo + v / maxdata * (hi - lo)
    return v / _per_unit(f.scale)


def _code(v: float, code_range: tuple[float, float, int]) -> int:
    """A converter's code of ``v`` (``ProtoField.code_range``)."""
    lo, hi, maxdata = code_range
    s = (v - lo) / (hi - lo) * maxdata
    return 0 if s <= 0.0 else maxdata if s >= maxdata else math.floor(s + 0.5)


def _to_count(x: Any, f: ProtoField) -> int:
    """An SI value → the nearest count of ``f.scale`` (the not-finite mark for None, NaN,
    inf); ProtoCodecError beyond the type's range (names the field)."""
    if x is None:
        return NOT_FINITE[f.kind]
    v = float(x)
    if not math.isfinite(v):
        return NOT_FINITE[f.kind]
    if f.code_range is not None:
        return _code(v, f.code_range)
    c = round(v * _per_unit(f.scale))
    if abs(c) > _COUNT_LIMIT[f.kind]:
        raise ProtoCodecError(f"{f.name}: {v} is beyond what {f.kind.value} counts of "
                              f"{f.scale} hold")
    return c


def _counts(values: np.ndarray, f: ProtoField) -> np.ndarray:
    """Vectorised :func:`_to_count` for a ring block: a value that is not finite or beyond
    the range gets the not-finite mark (a ring value cannot be refused)."""
    if f.code_range is not None:
        lo, hi, maxdata = f.code_range
        finite = np.isfinite(values)
        s = (np.where(finite, values, 0.0) - lo) / (hi - lo) * maxdata
        # Clipped to [0, maxdata] before the rounding: floor(maxdata + 0.5) is maxdata.
        out = np.floor(np.clip(s, 0.0, float(maxdata)) + 0.5).astype(np.int64)
        out[~finite] = NOT_FINITE[f.kind]
        return out
    c = np.rint(values * _per_unit(f.scale))
    bad = ~(np.abs(c) <= _COUNT_LIMIT[f.kind])           # NaN compares False: bad too
    c[bad] = 0.0
    out = c.astype(np.int64)
    out[bad] = NOT_FINITE[f.kind]
    return out


class ProtoMessage:
    """A protobuf message type of the recording: its descriptor, encoders, decoders."""

    def __init__(self, name: str, fields: Sequence[ProtoField]):
        self.name = name                       # full name, e.g. "talus.RobotState"
        self.fields = tuple(fields)
        numbers = [f.number for f in self.fields]
        names = [f.name for f in self.fields]
        keys = [f.dict_key for f in self.fields]
        if len(set(numbers)) != len(numbers) or len(set(names)) != len(names) \
                or len(set(keys)) != len(keys):
            raise ValueError(f"{name}: duplicate field names, keys or numbers")
        if not name.startswith(PACKAGE + "."):
            raise ValueError(f"{name}: message names are {PACKAGE}[.version].Name")
        #: The protobuf package (``talus``, ``talus.v2`` ...) and the message's short name.
        self.package, self.short_name = name.rsplit(".", 1)
        self._by_number = {f.number: f for f in self.fields}
        self._by_name = {f.name: f for f in self.fields}
        self._by_key = {f.dict_key: f for f in self.fields}
        fixed = [f for f in self.fields if f.fixed]
        # The fixed part, in field order, as one struct: pack or unpack one message at once.
        fmt = ["<"]
        for f in fixed:
            fmt.append("B")
            if f.width:
                if f.width * _SIZE[f.kind] >= 128:
                    raise ValueError(f"{name}.{f.name}: a fixed array stays under 128 bytes")
                fmt.append("B")
                fmt.append(f"{f.width}{_STRUCT[f.kind]}")
            else:
                fmt.append(_STRUCT[f.kind])
        self._fixed = tuple(fixed)
        self._struct = struct.Struct("".join(fmt))
        # What encode() walks per message, computed once: (field, dict key, tag, width,
        # bytes, bool, fixed-point).
        self._fixed_plan = tuple((f, f.dict_key, f.tag, f.width, f.width * _SIZE[f.kind],
                                  f.kind is Kind.BOOL, f.scale is not None) for f in fixed)
        #: (field, dict key, tag byte, struct code or None for a string) of the optional
        #: fields.
        self._optional_plan = tuple(
            (f, f.dict_key, bytes((f.tag,)), None if f.kind is Kind.STRING else _STRUCT[f.kind])
            for f in self.fields if not f.fixed)
        # Where the struct's values hold tags and array lengths, and what they must be: a
        # message of another layout is recognised in one tuple comparison.
        positions, expected, k = [], [], 0
        for f in fixed:
            positions.append(k)
            expected.append(f.tag)
            k += 1
            if f.width:
                positions.append(k)
                expected.append(f.width * _SIZE[f.kind])
                k += 1 + f.width
            else:
                k += 1
        self._tags_of = operator.itemgetter(*positions) if len(positions) > 1 else \
            (lambda vals, _p=positions: tuple(vals[i] for i in _p))
        self._tags = tuple(expected)
        #: Bytes of the always-present part (the whole message when every field is fixed).
        self.fixed_size = self._struct.size
        self.all_fixed = len(fixed) == len(self.fields)
        #: Values per message of the fixed part, in order (a ring row's width).
        self.row_width = sum(max(f.width, 1) for f in fixed)
        #: Whether the payload carries the loop time ``t``. ``talus.v3`` messages do not: a
        #: message's MCAP log time is its cycle's time, and the reader rebuilds ``t`` from it
        #: (``rt.recording.channels.LoopClock``); a ring row's time column is then skipped.
        self.carries_t = "t" in self._by_key

    @property
    def fixed_layout(self) -> tuple[tuple[str, int], ...]:
        """The fixed fields as a ring row layout ``((key, width), ...)`` (scalars width 1)."""
        return tuple((f.dict_key, max(f.width, 1)) for f in self._fixed)

    # ------------------------------------------------------------------ schema

    @cached_property
    def file_descriptor_set(self) -> bytes:
        """The Schema record's data: a serialized ``FileDescriptorSet`` with this message
        (proto3, package ``talus``), deterministic bytes."""
        from google.protobuf import descriptor_pb2 as d

        fdp = d.FileDescriptorProto(name=f"{self.package.replace('.', '/')}/{self.short_name}"
                                         ".proto", package=self.package, syntax="proto3")
        self.add_descriptor(fdp)
        fds = d.FileDescriptorSet(file=[fdp])
        return fds.SerializeToString(deterministic=True)

    def add_descriptor(self, fdp: Any) -> None:
        """Add this message's ``DescriptorProto`` to ``fdp`` (a ``FileDescriptorProto`` of
        this message's package): also how a message that holds it as a field
        (``rt.recording.cycle``) declares it in its own file."""
        from google.protobuf import descriptor_pb2 as d

        types = {Kind.DOUBLE: d.FieldDescriptorProto.TYPE_DOUBLE,
                 Kind.FLOAT: d.FieldDescriptorProto.TYPE_FLOAT,
                 Kind.BOOL: d.FieldDescriptorProto.TYPE_BOOL,
                 Kind.STRING: d.FieldDescriptorProto.TYPE_STRING,
                 Kind.SFIXED32: d.FieldDescriptorProto.TYPE_SFIXED32,
                 Kind.SFIXED64: d.FieldDescriptorProto.TYPE_SFIXED64}
        msg = fdp.message_type.add(name=self.short_name)
        for f in self.fields:
            msg.field.add(
                name=f.name, number=f.number, type=types[f.kind],
                label=(d.FieldDescriptorProto.LABEL_REPEATED if f.width
                       else d.FieldDescriptorProto.LABEL_OPTIONAL),
                json_name=f.name)

    # ------------------------------------------------------------------ encoding

    def encode_rows(self, rows: np.ndarray) -> list[bytes]:
        """One message per row of ``rows`` (n × :attr:`row_width` float64: the fixed fields'
        values in field order, optional fields absent). See :meth:`row_encoder`."""
        return self._fixed_rows(rows)

    @cached_property
    def _fixed_rows(self) -> Callable[[np.ndarray], list[bytes]]:
        return self.row_encoder(self.fixed_layout)

    def row_encoder(self, layout: Sequence[tuple[str, int]]
                    ) -> Callable[[np.ndarray], list[bytes]]:
        """An encoder of ring rows laid out as ``layout`` (``((name, width), ...)``, the
        columns of a float64 row) into one message per row: numpy fills a record array whose
        tag and length columns are constants, so a message costs a slice of one buffer.

        The layout names every fixed field with its width and may add optional numeric
        arrays (any width); strings cannot come from a ring. Raises ProtoCodecError naming
        what does not fit."""
        columns: dict[str, tuple[int, int]] = {}
        k = 0
        for name, width in layout:
            columns[name] = (k, int(width))
            k += int(width)
        total = k
        unknown = [n for n in columns if n not in self._by_key
                   and not (n == "t" and not self.carries_t)]
        if unknown:
            raise ProtoCodecError(f"{self.name} has no field {unknown[0]!r}")
        plan: list[tuple[ProtoField, int, int]] = []      # field, first column, width
        np_fields: list[tuple[Any, ...]] = []
        consts: list[tuple[str, int]] = []
        for f in self.fields:          # field-number order: the fast decoder's order
            if f.dict_key not in columns:
                if f.fixed:
                    raise ProtoCodecError(f"{self.name}.{f.name} missing from the row layout")
                continue
            col, width = columns[f.dict_key]
            if f.kind is Kind.STRING:
                raise ProtoCodecError(f"{self.name}.{f.name} is a string: not from a ring")
            if f.fixed and width != max(f.width, 1):
                raise ProtoCodecError(f"{self.name}.{f.name}: width {max(f.width, 1)} "
                                      f"expected, got {width}")
            if f.width == 0 and width != 1:
                raise ProtoCodecError(f"{self.name}.{f.name} is a scalar, got width {width}")
            np_fields.append((f"tag{f.number}", "u1"))
            consts.append((f"tag{f.number}", f.tag))
            if f.width:
                nbytes = width * _SIZE[f.kind]
                if nbytes >= 128:
                    raise ProtoCodecError(f"{self.name}.{f.name}: arrays from a ring stay "
                                          "under 128 bytes")
                np_fields.append((f"len{f.number}", "u1"))
                consts.append((f"len{f.number}", nbytes))
                np_fields.append((f.name, _NUMPY[f.kind], (width,)))
            else:
                np_fields.append((f.name, _NUMPY[f.kind]))
            plan.append((f, col, width))
        dtype = np.dtype(np_fields)
        size = dtype.itemsize

        def encode(rows: np.ndarray) -> list[bytes]:
            if rows.ndim != 2 or rows.shape[1] != total:
                raise ProtoCodecError(f"{self.name}: rows of {total} values expected, got "
                                      f"shape {rows.shape}")
            block = np.empty(len(rows), dtype)
            for key, value in consts:
                block[key] = value
            for f, col, width in plan:
                cols = rows[:, col] if f.width == 0 else rows[:, col:col + width]
                block[f.name] = (cols != 0) if f.kind is Kind.BOOL else \
                    _counts(cols, f) if f.scale is not None else cols
            buf = block.tobytes()
            return [buf[i:i + size] for i in range(0, len(buf), size)]

        return encode

    def encode(self, message: dict[str, Any]) -> bytes:
        """One message from its dict (the JSON channel's shape). A missing fixed field, an
        array of the wrong length or a value of the wrong type raises ProtoCodecError naming
        the field; ``None`` in a number field is written as NaN (not finite)."""
        values: list[Any] = []
        name = ""
        try:
            for f, name, tag, width, nbytes, is_bool, scaled in self._fixed_plan:
                v = message[name]
                values.append(tag)
                if width:
                    if len(v) != width:
                        raise ProtoCodecError(f"{self.name}.{name}: {width} values expected, "
                                              f"got {len(v)}")
                    values.append(nbytes)
                    values.extend([_to_count(x, f) for x in v] if scaled else
                                  [math.nan if x is None else float(x) for x in v])
                elif is_bool:
                    values.append(bool(v))
                elif scaled:
                    values.append(_to_count(v, f))
                else:
                    values.append(math.nan if v is None else float(v))
            head = self._struct.pack(*values)
        except KeyError:
            raise ProtoCodecError(f"{self.name}: field {name!r} missing") from None
        except (TypeError, ValueError, struct.error) as exc:
            if isinstance(exc, ProtoCodecError):
                raise
            raise ProtoCodecError(f"{self.name}.{name}: {exc}") from None
        if self.all_fixed:
            return head
        parts = [head]
        for f, name, tag_byte, code in self._optional_plan:
            v = message.get(name)
            if v is None:
                continue
            if code is None:               # a string
                if not isinstance(v, str):
                    raise ProtoCodecError(f"{self.name}.{name}: a string expected, got "
                                          f"{type(v).__name__}")
                data = v.encode()
            else:
                try:
                    floats = [_to_count(x, f) for x in v] if f.scale is not None else \
                        [math.nan if x is None else float(x) for x in v]
                except (TypeError, ValueError) as exc:
                    if isinstance(exc, ProtoCodecError):
                        raise ProtoCodecError(f"{self.name}.{exc}") from None
                    raise ProtoCodecError(f"{self.name}.{name}: {exc}") from None
                data = _packed(code, len(floats)).pack(*floats)
            if data:
                n = len(data)
                parts.append(tag_byte + (bytes((n,)) if n < 0x80 else _varint(n)) + data)
        return b"".join(parts)

    def encode_strings(self, values: dict[str, str]) -> bytes:
        """The string fields named in ``values`` (dict keys), in field-number order: appended
        to a :meth:`row_encoder` message whose fields all come before them, they complete it
        (a run of messages with the same strings shares these bytes)."""
        parts = []
        for f in self.fields:
            v = values.get(f.dict_key)
            if f.kind is not Kind.STRING or not v:
                continue
            data = v.encode()
            parts.append(bytes((f.tag,)) + _varint(len(data)) + data)
        unknown = set(values) - {f.dict_key for f in self.fields if f.kind is Kind.STRING}
        if unknown:
            raise ProtoCodecError(f"{self.name} has no string field {min(unknown)!r}")
        return b"".join(parts)

    # ------------------------------------------------------------------ decoding

    def decode(self, data: bytes) -> dict[str, Any]:
        """The dict of one message written by any protobuf writer of this schema: our own
        layout (fixed part first, tags where expected) takes a ``struct`` fast path; anything
        else (fields omitted, reordered, unknown) goes through :meth:`decode_wire`."""
        size = self.fixed_size
        if len(data) >= size:
            vals = self._struct.unpack_from(data)
            if self._tags_of(vals) == self._tags:
                out = self._fixed_dict(vals)
                if len(data) == size:
                    return out
                if not self.all_fixed:
                    values = self._parse(data, size)
                    if not any(self._by_name[k].fixed for k in values):
                        self._finish(values, out, optional_only=True)
                        return out
        return self.decode_wire(data)

    def _fixed_dict(self, vals: tuple[Any, ...]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        k = 0
        for f in self._fixed:
            k += 2 if f.width else 1
            if f.width:
                out[f.dict_key] = [_from_count(x, f) for x in vals[k:k + f.width]] \
                    if f.scale is not None else [_finite(x) for x in vals[k:k + f.width]]
                k += f.width
            else:
                v = vals[k]
                out[f.dict_key] = v if f.kind is Kind.BOOL else \
                    _from_count(v, f) if f.scale is not None else _finite(v)
                k += 1
        return out

    def decode_wire(self, data: bytes) -> dict[str, Any]:
        """Any valid encoding of this message (proto3 rules: a scalar absent is its default,
        an unpacked repeated field is accepted, the last scalar wins, unknown fields are
        skipped)."""
        out: dict[str, Any] = {}
        self._finish(self._parse(bytes(data), 0), out, optional_only=False)
        return out

    def _parse(self, data: bytes, i: int) -> dict[str, Any]:
        values: dict[str, Any] = {}
        n = len(data)
        while i < n:
            key, i = _read_varint(data, i)
            number, wire = key >> 3, key & 7
            raw: Any
            if wire == 0:
                raw, i = _read_varint(data, i)
            elif wire in (1, 5):
                size = 8 if wire == 1 else 4
                raw = data[i:i + size]
                i += size
            elif wire == 2:
                length, i = _read_varint(data, i)
                raw = data[i:i + length]
                i += length
            else:
                raise ProtoCodecError(f"{self.name}: unsupported wire type {wire}")
            if i > n:
                raise ProtoCodecError(f"{self.name}: message cut inside field {number}")
            f = self._by_number.get(number)
            if f is not None:
                values[f.name] = _merge(f, values.get(f.name), wire, raw, self.name)
        return values

    def _finish(self, values: dict[str, Any], out: dict[str, Any], optional_only: bool) -> None:
        for f in self.fields:
            if optional_only and f.fixed:
                continue
            v = values.get(f.name)
            key = f.dict_key

            def number(x: Any, f: ProtoField = f) -> float | None:
                return _from_count(x, f) if f.scale is not None else _finite(x)
            if f.kind is Kind.STRING:
                if v:
                    out[key] = v
            elif f.width == VARIABLE:
                if v:
                    out[key] = [number(x) for x in v]
            elif f.width:
                v = v or []
                if len(v) != f.width:
                    raise ProtoCodecError(f"{self.name}.{f.name}: {f.width} values expected, "
                                          f"got {len(v)}")
                out[key] = [number(x) for x in v]
            elif f.kind is Kind.BOOL:
                out[key] = bool(v)
            else:
                out[key] = 0.0 if v is None else number(v)


def _merge(f: ProtoField, old: Any, wire: int, raw: Any, where: str) -> Any:
    if f.kind is Kind.STRING:
        if wire != 2:
            raise ProtoCodecError(f"{where}.{f.name}: wire type {wire} for a string")
        return bytes(raw).decode()
    if f.kind is Kind.BOOL:
        if wire != 0:
            raise ProtoCodecError(f"{where}.{f.name}: wire type {wire} for a bool")
        return bool(raw)
    code = _STRUCT[f.kind]
    size = _SIZE[f.kind]
    if wire == 2:
        if len(raw) % size:
            raise ProtoCodecError(f"{where}.{f.name}: packed length {len(raw)} not a multiple "
                                  f"of {size}")
        got = list(_packed(code, len(raw) // size).unpack(raw))
    elif wire == _WIRE_TYPE[f.kind]:
        if len(raw) != size:
            raise ProtoCodecError(f"{where}.{f.name}: message cut inside the field")
        got = [struct.unpack("<" + code, raw)[0]]
    else:
        raise ProtoCodecError(f"{where}.{f.name}: wire type {wire} for a {f.kind.value}")
    if f.width:
        return (old or []) + got
    return got[-1]
