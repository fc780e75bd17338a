"""The channels of a session recording: topic → JSON Schema and protobuf message (DESIGN 9).

Encodings, all MCAP well-known ones that Foxglove opens and plots without plugins:

* **one message per cycle** (``talus.v4``, the default, :attr:`Encoding.PROTOBUF`): the
  three 1 kHz channels joined into one ``talus.v4.Cycle`` message per loop cycle on
  :data:`CYCLE` (``/robot/cycle``), with ``state``, ``wrench`` and ``reference``
  sub-messages (:mod:`rt.recording.cycle`): MCAP's per-message framing is paid once per cycle
  instead of three times, and the quanta are the instruments' (:data:`V4_SPEED_QUANTUM_M_S`
  ...). Foxglove plots every cycle (``/robot/cycle.wrench.fz_25mn``); talus's readers give
  the three parts back as ``/robot/state``, ``/robot/wrench`` and ``/protocol/reference``
  dicts, so callers never see the difference.
* **protobuf, fixed point, three channels** (``talus.v3``, :attr:`Encoding.PROTOBUF_V3`,
  25-26 November 2026; read always): the 1 kHz channels
  (``/robot/state``, ``/robot/wrench``, ``/protocol/reference``) and ``/ankle/state`` as
  ``message_encoding="protobuf"`` with a ``protobuf`` schema (a ``FileDescriptorSet``,
  :mod:`rt.recording.protobuf_codec`, package ``talus.v3``). Every number of the 1 kHz
  channels is an ``sfixed32`` count of a stated quantum, the unit in the wire name
  (``q_um``, ``tau_mn``), or the code an instrument made of it (``volts_dac``: the DAC's
  code, so the voltage it output, exactly); decoded, they are the JSON channels' SI dicts
  (``q`` in m ...). A value that was not finite reads back as ``None``. The payloads carry
  no time: a message's MCAP log time (and publish time) is its cycle's loop time, and the
  channel's metadata the origin (:data:`TIME_ORIGIN_NS_KEY`, :class:`LoopClock`), from
  which the readers put ``t`` back in the dicts. Why: the time repeated in 3 payloads per
  cycle besides the log time cost 15 % of the file (issue 16's 150 MB/h).
* **protobuf, fixed point with the time** (:attr:`Encoding.PROTOBUF_V2`, package
  ``talus.v2``, ``t_us`` in every payload, volts in mV): the recordings of 25 November 2026
  before ``talus.v3``; read always.
* **protobuf, float32** (:attr:`Encoding.PROTOBUF_F32`, package ``talus``): the recordings
  made with issue 16's first round, floats as float32 and ``t`` as a double; read always.
* **json** (every recording before issue 16, :attr:`Encoding.JSON`):
  ``message_encoding="json"`` with a ``jsonschema`` schema whose root is an object.

The rare channels (``/safety/events``, ``/protocol/metadata``, added ones such as
``/session/summary``) are JSON in every encoding: a handful of messages per session whose
``values``/``parameters`` are free-form objects a fixed schema would not hold. Protobuf
channels carry their JSON Schema in the MCAP channel metadata (``talus.jsonschema``): units
and descriptions travel with the file, and CSV columns are the same for every encoding.

Why fixed point (size, issue 16's ≤ 150 MB per hour at 1 kHz). A float32 keeps 24 bits of
mantissa whatever the signal resolves, and the low bytes of a noisy signal (qd, tau, volts,
the wrench) are random: zstd cannot compress them, and they were most of the 340 MB/h of the
float32 files. A count of the finest quantum the hardware can resolve (or finer) holds only the
bits that mean something, its high bytes constant, and zstd removes those. The quanta, each at
or below what the robot resolves (so nothing measured is lost):

* ``t`` → µs (v2's ``t_us``, sfixed64; v3's log times): the loop's period is 1000 µs and its
  lateness is reported by the loop itself; a double's ns-level jitter digits cost ≈ 5 bytes
  per message and mean nothing. The messages' MCAP log times use the same µs-rounded time.
* ``q``, ``q_ref``, ``position`` → µm: the encoders count 20 µm (robot description
  ``encoder.m_per_count``), 20x coarser; a measured ``q`` is an exact number of µm.
* ``qd``, ``qd_ref`` → µm/s: the estimate's own quantum is a count per cycle, 20 000 µm/s.
* ``tau``, forces ``fx..fz``, reference ``force`` → mN: what reaches a motor is resolved by
  the DAC's 4.88 mV LSB times ``drive.force_per_volt_n`` (newtons per LSB), the ATI SI-660-60
  resolves 1/8 N (1/4 N on z).
* ``volts`` → the PCI-1720's code (v3; its LSB is 4.88 mV, ``DAC_RANGE``): what the DAC
  output, exactly (the driver writes ``volts_to_code`` of the command); v2: mV.
* torques ``tx..tz`` → mN·m: the ATI resolves 7.5 mN·m.

Quantisation error is at most half a quantum (0.5 µm, 0.5 mN ...), below the resolution of the
instrument that produced the value. Ranges: sfixed32 holds ±2.1 km, ±2.1 km/s, ±2.1 MN,
±2.1 MV; a value beyond its type's range is written as not finite.

The float32 encoding's resolutions, for reading older files: ``q``, ``q_ref``, ``position``
step ≤ 3e-8 m; ``qd`` ≤ 6e-8 m/s; ``tau`` ≤ 1e-3 N; ``volts`` ≤ 1e-6 V; wrench ≤ 2.4e-4 N /
1.5e-5 N·m; ``t`` a double.

Conventions, shared by all channels:

* ``t`` is the loop time, s. A message's MCAP ``log_time``/``publish_time`` is
  ``start_wall_ns + round((t - loop_t0) * 1e9)`` ns: the session's wall clock at start plus the
  loop time since start (:func:`log_time_ns`), so Foxglove shows wall-clock time while the
  payload keeps the loop's own clock.
* SI units, stated in every field's ``description``.
* JSON has no NaN or infinity: a non-finite number is written as ``null``. Numeric fields stay
  ``"type": "number"`` (not ``["number", "null"]``) because viewers derive plot paths from a
  single type; a ``null`` therefore marks a value that was not finite when recorded. The one
  exception: a ``/robot/wrench`` with no finite sample (the sensor has not answered yet) is not
  a measurement and is not written (the recorder counts it, ``wrench_without_sample``), so the
  wrench channel's messages, the first included, validate against its schema.

Adding a channel is one entry in :data:`CHANNELS`; the writer registers every entry.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

from rt.recording.protobuf_codec import VARIABLE, Kind, ProtoField, ProtoMessage

#: JSON Schema dialect of every schema here.
SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"
#: MCAP schema encoding and message encoding for JSON channels (MCAP well-known values).
SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
#: MCAP channel metadata key holding a protobuf channel's JSON Schema (units, descriptions,
#: the shape of the decoded dicts).
JSONSCHEMA_METADATA_KEY = "talus.jsonschema"


class Encoding(enum.Enum):
    """How a recording encodes its channels that have a protobuf message.

    ``PROTOBUF``: one ``talus.v4.Cycle`` message per loop cycle on ``/robot/cycle`` (state,
    wrench and reference together, fixed point at the instruments' quanta, no time in the
    payload; the default, :mod:`rt.recording.cycle`); ``PROTOBUF_V3``: the three 1 kHz
    channels apart, fixed point without the time (``talus.v3``, 25-26 November 2026, still
    written for comparison and compatibility tests); ``PROTOBUF_V2``: fixed point with ``t_us`` (``talus.v2``, 25 November 2026, still
    written for comparison and compatibility tests); ``PROTOBUF_F32``:
    float32 (``talus`` messages, recordings of November 2026 before the fixed-point change,
    still written for comparison and compatibility tests); ``JSON``: every channel JSON, as
    recordings were before issue 16."""

    PROTOBUF = "protobuf"
    PROTOBUF_V3 = "protobuf-v3"
    PROTOBUF_V2 = "protobuf-v2"
    PROTOBUF_F32 = "protobuf-f32"
    JSON = "json"

STATE = "/robot/state"
WRENCH = "/robot/wrench"
EVENTS = "/safety/events"
METADATA = "/protocol/metadata"
REFERENCE = "/protocol/reference"
ANKLE = "/ankle/state"
#: ``talus.v4``: the three 1 kHz channels above joined, one message per loop cycle.
CYCLE = "/robot/cycle"


@dataclass(frozen=True)
class ChannelSpec:
    """One recorded channel: its topic, the schema's name and the JSON Schema (a dict)."""

    topic: str
    schema_name: str
    schema: dict[str, Any]
    #: MCAP channel metadata (string → string), e.g. the nominal rate.
    metadata: dict[str, str] = field(default_factory=dict)
    #: The protobuf message of the channel (same fields as the JSON Schema), None for a
    #: channel always written as JSON.
    proto: ProtoMessage | None = None

    @property
    def required(self) -> tuple[str, ...]:
        return tuple(self.schema.get("required", ()))


def _t() -> dict[str, Any]:
    return {"type": "number", "description": "loop time, s"}


def _num(description: str) -> dict[str, Any]:
    return {"type": "number", "description": description}


def _vec3(description: str) -> dict[str, Any]:
    return {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3,
            "description": description + " (one per leg: 0, 1, 2)"}


def _object(title: str, description: str, properties: dict[str, Any],
            required: list[str]) -> dict[str, Any]:
    return {"$schema": SCHEMA_DIALECT, "title": title, "description": description,
            "type": "object", "properties": properties, "required": required}


_STATE = _object(
    "talus.RobotState", "One cycle of the position loop (1 kHz): joints, references, outputs.",
    {
        "t": _t(),
        "q": _vec3("slider positions, m"),
        "qd": _vec3("slider velocities (estimated), m/s"),
        "q_ref": _vec3("slider position references, m"),
        "qd_ref": _vec3("slider velocity references, m/s (optional)"),
        "tau": _vec3("actuator forces commanded by the controller, N"),
        "volts": _vec3("drive voltages written to the DAC after the supervisor, V"),
    },
    ["t", "q", "qd", "q_ref", "tau", "volts"])

_WRENCH = _object(
    "talus.Wrench", "Force/torque at the tool (ATI sensor, sensor frame).",
    {
        "t": _t(),
        "fx": _num("force along x, N"), "fy": _num("force along y, N"),
        "fz": _num("force along z, N"),
        "tx": _num("torque about x, N·m"), "ty": _num("torque about y, N·m"),
        "tz": _num("torque about z, N·m"),
        "stale": {"type": "boolean", "description": "no new sample since the last cycle"},
        "saturated": {"type": "boolean", "description": "a gauge was at its range limit"},
    },
    ["t", "fx", "fy", "fz", "tx", "ty", "tz", "stale", "saturated"])

_EVENTS = _object(
    "talus.SafetyEvent", "A safety supervisor event (rt.safety.events.SafetyEvent.as_dict).",
    {
        "t": _t(),
        "kind": {"type": "string",
                 "description": "fault, warn, reset, reset_refused or failover"},
        "cause": {"type": "string",
                  "description": "machine-readable cause, e.g. rom_roll_max, estop_gui"},
        "reaction": {"type": "string",
                     "description": "none, warn, soft_stop, hard_stop or failover"},
        "message": {"type": "string", "description": "human-readable explanation"},
        "values": {"type": "object",
                   "description": "the values that triggered the event, SI units, named by "
                                  "the supervisor"},
        "wall": {"type": "number", "description": "host wall clock, s since the Unix epoch"},
    },
    ["t", "kind", "cause", "reaction", "message", "values"])

_METADATA = _object(
    "talus.SessionMetadata", "What was run, on whom, with what (written once, at start).",
    {
        "t": _t(),
        "protocol_name": {"type": "string", "description": "protocol name"},
        "protocol_version": {"type": "string", "description": "protocol version"},
        "parameters": {"type": "object",
                       "description": "the protocol's parameters as run, SI units"},
        "patient_id": {"type": "string",
                       "description": "patient pseudonym id (never a name)"},
        "robot_description": {"type": "string",
                              "description": "name of the robot description in use"},
        "software_version": {"type": "string", "description": "talus version"},
        "start_wall_time": {"type": "string", "format": "date-time",
                            "description": "session start, ISO 8601 with time zone"},
    },
    ["t", "protocol_name", "protocol_version", "parameters", "patient_id",
     "robot_description", "software_version", "start_wall_time"])

_REFERENCE = _object(
    "talus.ProtocolReference", "The protocol's reference as played (force and/or position).",
    {
        "t": _t(),
        "force": {"type": "array", "items": {"type": "number"},
                  "description": "force reference fx, fy, fz, N (optional)"},
        "position": {"type": "array", "items": {"type": "number"},
                     "description": "position reference (joint space), m (optional)"},
        "phase": {"type": "string", "description": "protocol phase name (optional)"},
        "mode": {"type": "string",
                 "description": "what the loop tracks: force or position (optional)"},
    },
    ["t"])

_D, _F, _B, _S = Kind.DOUBLE, Kind.FLOAT, Kind.BOOL, Kind.STRING
_I32, _I64 = Kind.SFIXED32, Kind.SFIXED64
#: Fixed-point quanta (SI units per count) of the ``talus.v2`` messages; why each is enough is
#: in the module docstring.
T_QUANTUM_S = 1e-6
POSITION_QUANTUM_M = 1e-6
SPEED_QUANTUM_M_S = 1e-6
FORCE_QUANTUM_N = 1e-3
VOLTS_QUANTUM_V = 1e-3
TORQUE_QUANTUM_NM = 1e-3


def _fx(name: str, number: int, kind: Kind, scale: float, key: str,
        width: int = 0) -> ProtoField:
    return ProtoField(name, number, kind, width, scale=scale, key=key)


#: The 1 kHz channels as fixed-point integers with the time in the payload (``talus.v2``,
#: recordings of 25 November 2026 before ``talus.v3``; read always, written with
#: ``Encoding.PROTOBUF_V2``): wire names carry the unit (``q_um``), decoded dicts the JSON
#: channels' SI keys (``q``).
STATE_PROTO_V2 = ProtoMessage("talus.v2.RobotState", [
    _fx("t_us", 1, _I64, T_QUANTUM_S, "t"),
    _fx("q_um", 2, _I32, POSITION_QUANTUM_M, "q", 3),
    _fx("qd_um_s", 3, _I32, SPEED_QUANTUM_M_S, "qd", 3),
    _fx("q_ref_um", 4, _I32, POSITION_QUANTUM_M, "q_ref", 3),
    _fx("tau_mn", 5, _I32, FORCE_QUANTUM_N, "tau", 3),
    _fx("volts_mv", 6, _I32, VOLTS_QUANTUM_V, "volts", 3),
    _fx("qd_ref_um_s", 7, _I32, SPEED_QUANTUM_M_S, "qd_ref", VARIABLE)])
WRENCH_PROTO_V2 = ProtoMessage("talus.v2.Wrench", [
    _fx("t_us", 1, _I64, T_QUANTUM_S, "t"),
    _fx("fx_mn", 2, _I32, FORCE_QUANTUM_N, "fx"), _fx("fy_mn", 3, _I32, FORCE_QUANTUM_N, "fy"),
    _fx("fz_mn", 4, _I32, FORCE_QUANTUM_N, "fz"),
    _fx("tx_mnm", 5, _I32, TORQUE_QUANTUM_NM, "tx"),
    _fx("ty_mnm", 6, _I32, TORQUE_QUANTUM_NM, "ty"),
    _fx("tz_mnm", 7, _I32, TORQUE_QUANTUM_NM, "tz"),
    ProtoField("stale", 8, _B), ProtoField("saturated", 9, _B)])
REFERENCE_PROTO_V2 = ProtoMessage("talus.v2.ProtocolReference", [
    _fx("t_us", 1, _I64, T_QUANTUM_S, "t"),
    _fx("force_mn", 2, _I32, FORCE_QUANTUM_N, "force", VARIABLE),
    _fx("position_um", 3, _I32, POSITION_QUANTUM_M, "position", VARIABLE),
    ProtoField("phase", 4, _S), ProtoField("mode", 5, _S)])
#: /ankle/state (100 Hz): float32 angles and torques (0.01° and 1 mN·m need no more than
#: float32's 7 digits), the time as the other channels'.
ANKLE_PROTO_V2 = ProtoMessage("talus.v2.AnkleState", [
    _fx("t_us", 1, _I64, T_QUANTUM_S, "t"),
    ProtoField("plantarflexion_deg", 2, _F), ProtoField("inversion_deg", 3, _F),
    ProtoField("abduction_deg", 4, _F), ProtoField("plantarflexion_torque_nm", 5, _F),
    ProtoField("inversion_torque_nm", 6, _F), ProtoField("abduction_torque_nm", 7, _F),
    ProtoField("centre_displacement_mm", 8, _F, 3), ProtoField("platform_roll_deg", 9, _F),
    ProtoField("platform_pitch_deg", 10, _F)])

#: The drive command's DAC: the PCI-1720 on its ±10 V range, 12 bits (``rt.drivers.pci1720``:
#: ``RANGE_BIPOLAR_10V``, ``volts_to_code``; tests check these against it). One code is
#: 20/4095 V = 4.88 mV.
DAC_RANGE: tuple[float, float, int] = (-10.0, 10.0, 4095)
DAC_STEP_V = (DAC_RANGE[1] - DAC_RANGE[0]) / DAC_RANGE[2]

#: ``talus.v3`` (the default encoding, :attr:`Encoding.PROTOBUF`): the ``talus.v2`` fields
#: less the time (a message's MCAP log time is its cycle's loop time, :class:`LoopClock`),
#: and the drive command as the DAC's code (``volts_dac``: the code the PCI-1720 writes for
#: it, so the voltage it outputs, exactly). Field numbers of v2 are kept; 1 (``t_us``) and 6
#: (``volts_mv``) are retired.
STATE_PROTO = ProtoMessage("talus.v3.RobotState", [
    _fx("q_um", 2, _I32, POSITION_QUANTUM_M, "q", 3),
    _fx("qd_um_s", 3, _I32, SPEED_QUANTUM_M_S, "qd", 3),
    _fx("q_ref_um", 4, _I32, POSITION_QUANTUM_M, "q_ref", 3),
    _fx("tau_mn", 5, _I32, FORCE_QUANTUM_N, "tau", 3),
    ProtoField("volts_dac", 8, _I32, 3, scale=DAC_STEP_V, key="volts", code_range=DAC_RANGE),
    _fx("qd_ref_um_s", 7, _I32, SPEED_QUANTUM_M_S, "qd_ref", VARIABLE)])
WRENCH_PROTO = ProtoMessage("talus.v3.Wrench", [
    _fx("fx_mn", 2, _I32, FORCE_QUANTUM_N, "fx"), _fx("fy_mn", 3, _I32, FORCE_QUANTUM_N, "fy"),
    _fx("fz_mn", 4, _I32, FORCE_QUANTUM_N, "fz"),
    _fx("tx_mnm", 5, _I32, TORQUE_QUANTUM_NM, "tx"),
    _fx("ty_mnm", 6, _I32, TORQUE_QUANTUM_NM, "ty"),
    _fx("tz_mnm", 7, _I32, TORQUE_QUANTUM_NM, "tz"),
    ProtoField("stale", 8, _B), ProtoField("saturated", 9, _B)])
REFERENCE_PROTO = ProtoMessage("talus.v3.ProtocolReference", [
    _fx("force_mn", 2, _I32, FORCE_QUANTUM_N, "force", VARIABLE),
    _fx("position_um", 3, _I32, POSITION_QUANTUM_M, "position", VARIABLE),
    ProtoField("phase", 4, _S), ProtoField("mode", 5, _S)])
ANKLE_PROTO = ProtoMessage("talus.v3.AnkleState", [
    ProtoField("plantarflexion_deg", 2, _F), ProtoField("inversion_deg", 3, _F),
    ProtoField("abduction_deg", 4, _F), ProtoField("plantarflexion_torque_nm", 5, _F),
    ProtoField("inversion_torque_nm", 6, _F), ProtoField("abduction_torque_nm", 7, _F),
    ProtoField("centre_displacement_mm", 8, _F, 3), ProtoField("platform_roll_deg", 9, _F),
    ProtoField("platform_pitch_deg", 10, _F)])

#: ``talus.v4`` quanta that differ from v3's, each at most a fifth of the resolution of the
#: instrument that measured (or receives) the value, so that the quantisation error (RMS
#: quantum/√12) adds at most 2 % in quadrature to the instrument's own:
#:
#: * ``qd`` → 0.1 mm/s: the Kalman estimate of 20 µm encoder counts is itself uncertain by
#:   0.19 mm/s RMS at best (at 0.05 m/s), 1.0 mm/s at rest, up to 1.45 mm/s
#:   (``rt.estimation.velocity``); 0.1 mm/s steps add 0.029 mm/s RMS;
#: * ``tau`` → 0.1 N: what reaches a motor is the DAC's code, 4.88 mV × 339 N/V = 1.66 N per
#:   code (``drive.force_per_volt_n``); 0.1 N is 1/16 of it;
#: * ATI forces ``fx..fz`` → 1/16 N and torques ``tx..tz`` → 2 mN·m: the ATI's own counts on
#:   its CAN short data format (``rt.ati.can_protocol``: 16 counts/N, 500 counts/(N·m)), so
#:   a CAN-transported wrench is recorded exactly, like the DAC's code; over Net F/T (finer
#:   counts) they are still finer than what the SI-660-60 resolves, 1/8 N (1/4 N on z) and
#:   7.5 mN·m: the error (≤ 31 mN, ≤ 1 mN·m) stays below half the sensor's own step;
#: * the reference ``force`` → 1/16 N, the measured forces' quantum, so a force error is a
#:   whole number of quanta;
#: * unchanged: ``q``, ``q_ref``, ``position`` 1 µm (1/20 of a count), ``volts`` the DAC's
#:   own code (exact).
#:
#: What each saves on an RT twin session (bench/recording.py, the issue-16 note): with v3's
#: quanta one message per cycle is ≈ 175 MB/h; these bring it under 150.
V4_SPEED_QUANTUM_M_S = 1e-4
V4_TAU_QUANTUM_N = 0.1
V4_ATI_FORCE_QUANTUM_N = 1 / 16
V4_ATI_TORQUE_QUANTUM_NM = 2e-3

#: ``talus.v4``'s parts of a cycle (:mod:`rt.recording.cycle` joins them into one
#: ``talus.v4.Cycle`` per loop cycle): v3's messages at the v4 quanta. A field whose quantum
#: changed has a new number and name (the unit in the name: ``qd_100um_s``, ``tau_dn`` in
#: decinewtons, ``fz_n16`` in sixteenths of a newton, ``tz_2mnm``); the others keep v3's.
STATE_PROTO_V4 = ProtoMessage("talus.v4.RobotState", [
    _fx("q_um", 2, _I32, POSITION_QUANTUM_M, "q", 3),
    _fx("qd_100um_s", 9, _I32, V4_SPEED_QUANTUM_M_S, "qd", 3),
    _fx("q_ref_um", 4, _I32, POSITION_QUANTUM_M, "q_ref", 3),
    _fx("tau_dn", 10, _I32, V4_TAU_QUANTUM_N, "tau", 3),
    ProtoField("volts_dac", 8, _I32, 3, scale=DAC_STEP_V, key="volts", code_range=DAC_RANGE),
    _fx("qd_ref_100um_s", 11, _I32, V4_SPEED_QUANTUM_M_S, "qd_ref", VARIABLE)])
WRENCH_PROTO_V4 = ProtoMessage("talus.v4.Wrench", [
    _fx("fx_n16", 10, _I32, V4_ATI_FORCE_QUANTUM_N, "fx"),
    _fx("fy_n16", 11, _I32, V4_ATI_FORCE_QUANTUM_N, "fy"),
    _fx("fz_n16", 12, _I32, V4_ATI_FORCE_QUANTUM_N, "fz"),
    _fx("tx_2mnm", 13, _I32, V4_ATI_TORQUE_QUANTUM_NM, "tx"),
    _fx("ty_2mnm", 14, _I32, V4_ATI_TORQUE_QUANTUM_NM, "ty"),
    _fx("tz_2mnm", 15, _I32, V4_ATI_TORQUE_QUANTUM_NM, "tz"),
    ProtoField("stale", 8, _B), ProtoField("saturated", 9, _B)])
REFERENCE_PROTO_V4 = ProtoMessage("talus.v4.ProtocolReference", [
    _fx("force_n16", 6, _I32, V4_ATI_FORCE_QUANTUM_N, "force", VARIABLE),
    _fx("position_um", 3, _I32, POSITION_QUANTUM_M, "position", VARIABLE),
    ProtoField("phase", 4, _S), ProtoField("mode", 5, _S)])

#: The float32 messages of the recordings made between issue 16's first round and the
#: fixed-point change (read always; written with ``Encoding.PROTOBUF_F32``). Numbers are never
#: reused (a removed field keeps its number retired).
STATE_PROTO_F32 = ProtoMessage("talus.RobotState", [
    ProtoField("t", 1, _D), ProtoField("q", 2, _F, 3), ProtoField("qd", 3, _F, 3),
    ProtoField("q_ref", 4, _F, 3), ProtoField("tau", 5, _F, 3), ProtoField("volts", 6, _F, 3),
    ProtoField("qd_ref", 7, _F, VARIABLE)])
WRENCH_PROTO_F32 = ProtoMessage("talus.Wrench", [
    ProtoField("t", 1, _D), ProtoField("fx", 2, _F), ProtoField("fy", 3, _F),
    ProtoField("fz", 4, _F), ProtoField("tx", 5, _F), ProtoField("ty", 6, _F),
    ProtoField("tz", 7, _F), ProtoField("stale", 8, _B), ProtoField("saturated", 9, _B)])
REFERENCE_PROTO_F32 = ProtoMessage("talus.ProtocolReference", [
    ProtoField("t", 1, _D), ProtoField("force", 2, _F, VARIABLE),
    ProtoField("position", 3, _F, VARIABLE), ProtoField("phase", 4, _S),
    ProtoField("mode", 5, _S)])

_ANKLE = _object(
    "talus.AnkleState", "The patient's ankle in clinical terms (rt.model.ankle.AnkleMonitor): "
    "angles of the foot from neutral, the torques about the ankle centre (the foot's effort: "
    "plantarflexors and invertors +), the centre's displacement; written at 100 Hz when the "
    "session has the patient's ankle setup.",
    {
        "t": _t(),
        "plantarflexion_deg": _num("plantarflexion (+) / dorsiflexion (-), degrees"),
        "inversion_deg": _num("inversion (+) / eversion (-), degrees"),
        "abduction_deg": _num("rotation about the vertical (the platform's parasitic yaw), "
                              "degrees"),
        "plantarflexion_torque_nm": _num("plantarflexion (+) / dorsiflexion (-) torque about "
                                         "the ankle centre, N·m"),
        "inversion_torque_nm": _num("inversion (+) / eversion (-) torque, N·m"),
        "abduction_torque_nm": _num("torque about the vertical through the ankle centre, N·m"),
        "centre_displacement_mm": {"type": "array", "items": {"type": "number"},
                                   "minItems": 3, "maxItems": 3,
                                   "description": "the ankle centre's displacement from "
                                                  "where it started, base frame x, y, z, mm"},
        "platform_roll_deg": _num("platform roll (engineers), degrees"),
        "platform_pitch_deg": _num("platform pitch (engineers), degrees"),
    },
    ["t", "plantarflexion_deg", "inversion_deg", "plantarflexion_torque_nm",
     "inversion_torque_nm"])

#: topic → spec; the writer registers all of them, in this order.
CHANNELS: dict[str, ChannelSpec] = {
    STATE: ChannelSpec(STATE, "talus.RobotState", _STATE, {"rate_hz": "1000"}, STATE_PROTO),
    WRENCH: ChannelSpec(WRENCH, "talus.Wrench", _WRENCH, {"rate_hz": "1000"}, WRENCH_PROTO),
    EVENTS: ChannelSpec(EVENTS, "talus.SafetyEvent", _EVENTS),
    METADATA: ChannelSpec(METADATA, "talus.SessionMetadata", _METADATA),
    REFERENCE: ChannelSpec(REFERENCE, "talus.ProtocolReference", _REFERENCE,
                           proto=REFERENCE_PROTO),
    ANKLE: ChannelSpec(ANKLE, "talus.AnkleState", _ANKLE, {"rate_hz": "100"}, ANKLE_PROTO),
}

#: The standard channels' protobuf message per protobuf encoding (added channels use their
#: spec's ``proto``).
PROTOS: dict[Encoding, dict[str, ProtoMessage]] = {
    # v4: the parts of a cycle (rt.recording.cycle), each encoded alone then joined; the
    # 100 Hz ankle channel stays on its own, in its v3 message.
    Encoding.PROTOBUF: {STATE: STATE_PROTO_V4, WRENCH: WRENCH_PROTO_V4,
                        REFERENCE: REFERENCE_PROTO_V4, ANKLE: ANKLE_PROTO},
    Encoding.PROTOBUF_V3: {STATE: STATE_PROTO, WRENCH: WRENCH_PROTO, REFERENCE: REFERENCE_PROTO,
                           ANKLE: ANKLE_PROTO},
    Encoding.PROTOBUF_V2: {STATE: STATE_PROTO_V2, WRENCH: WRENCH_PROTO_V2,
                           REFERENCE: REFERENCE_PROTO_V2, ANKLE: ANKLE_PROTO_V2},
    Encoding.PROTOBUF_F32: {STATE: STATE_PROTO_F32, WRENCH: WRENCH_PROTO_F32,
                            REFERENCE: REFERENCE_PROTO_F32},
    Encoding.JSON: {},
}

#: Protobuf messages talus writes or wrote, by full name: the reader's fast decoders.
PROTO_MESSAGES: dict[str, ProtoMessage] = {
    m.name: m for m in (STATE_PROTO_V4, WRENCH_PROTO_V4, REFERENCE_PROTO_V4,
                        STATE_PROTO, WRENCH_PROTO, REFERENCE_PROTO, ANKLE_PROTO,
                        STATE_PROTO_V2, WRENCH_PROTO_V2, REFERENCE_PROTO_V2, ANKLE_PROTO_V2,
                        STATE_PROTO_F32, WRENCH_PROTO_F32, REFERENCE_PROTO_F32)}

#: Column layout of a ``RecorderTap`` row (rt.components.blocks): field name → width.
STATE_ROW_LAYOUT: tuple[tuple[str, int], ...] = (
    ("t", 1), ("q", 3), ("qd", 3), ("q_ref", 3), ("tau", 3), ("volts", 3))

#: Keys the caller must give in the session metadata (the recorder fills ``t``,
#: ``software_version`` when absent, and ``start_wall_time``).
METADATA_REQUIRED_FROM_CALLER = ("protocol_name", "protocol_version", "parameters",
                                 "patient_id", "robot_description")


def log_time_ns(t: float, start_wall_ns: int, loop_t0: float = 0.0) -> int:
    """MCAP log time, ns since the Unix epoch, of loop time ``t`` (s)."""
    return start_wall_ns + round((t - loop_t0) * 1e9)


# ------------------------------------------------------------------------------ time
#: Channel metadata of a ``talus.v3`` protobuf channel: the time origin that turns a
#: message's MCAP log time (ns since the Unix epoch) back into the loop time ``t`` (s): the
#: log time of loop time ``origin_loop_s`` (decimal strings), and the quantum ``t`` was
#: rounded to.
TIME_ORIGIN_NS_KEY = "talus.time_origin_ns"
TIME_ORIGIN_LOOP_S_KEY = "talus.time_origin_loop_s"
TIME_QUANTUM_KEY = "talus.time_quantum_s"


def time_metadata(start_wall_ns: int, loop_t0: float, quantum_s: float) -> dict[str, str]:
    """The time origin of a recording's channels (:data:`TIME_ORIGIN_NS_KEY` ...)."""
    return {TIME_ORIGIN_NS_KEY: str(int(start_wall_ns)),
            TIME_ORIGIN_LOOP_S_KEY: repr(float(loop_t0)), TIME_QUANTUM_KEY: repr(quantum_s)}


class LoopClock:
    """Loop time ``t`` (s) of a message from its MCAP log time, for messages that do not carry
    it (``talus.v3``): ``origin_loop_s + (log_time_ns - origin_ns) / 1e9``, rounded to the
    recording's quantum (1 µs), which gives back exactly the ``t`` a ``talus.v2`` payload
    held (``t_us`` / 1e6): the writer's log time is ``origin_ns + round((t_q - t0) * 1e9)``
    with ``t_q`` the µs-rounded time, so the rebuilt value is within 1 ns of ``t_q``."""

    def __init__(self, origin_ns: int, origin_loop_s: float, quantum_s: float | None) -> None:
        self.origin_ns = int(origin_ns)
        self.origin_loop_s = float(origin_loop_s)
        self.per_unit = None if quantum_s is None else _per_quantum(quantum_s)

    @classmethod
    def from_metadata(cls, metadata: dict[str, str]) -> LoopClock | None:
        """The clock a channel's metadata declares, None when it declares none."""
        if TIME_ORIGIN_NS_KEY not in metadata:
            return None
        quantum = metadata.get(TIME_QUANTUM_KEY)
        return cls(int(metadata[TIME_ORIGIN_NS_KEY]),
                   float(metadata.get(TIME_ORIGIN_LOOP_S_KEY, "0.0")),
                   None if quantum is None else float(quantum))

    def __call__(self, log_time_ns: int) -> float:
        t = self.origin_loop_s + (log_time_ns - self.origin_ns) * 1e-9
        per = self.per_unit
        return t if per is None else round(t * per) / per

    def quantize(self, t: float) -> float:
        """``t`` rounded to the quantum (what the writer stamps)."""
        per = self.per_unit
        return t if per is None else round(t * per) / per


def _per_quantum(quantum_s: float) -> float:
    inv = 1.0 / quantum_s
    return float(round(inv)) if abs(inv - round(inv)) <= 1e-9 * inv else inv
