"""The channels of a session recording: topic → JSON Schema and protobuf message (DESIGN 9).

Two encodings, both MCAP well-known ones that Foxglove opens and plots without plugins:

* **protobuf** (the default since issue 16): the 1 kHz channels (``/robot/state``,
  ``/robot/wrench``, ``/protocol/reference``) as ``message_encoding="protobuf"`` with a
  ``protobuf`` schema (a ``FileDescriptorSet``, :mod:`rt.recording.protobuf_codec`), numbers
  as float32 where the resolution allows (below) and ``t`` as double. The JSON Schema of each
  channel goes into the MCAP channel metadata (``talus.jsonschema``): units and descriptions
  travel with the file, and the decoded dicts are the JSON channels' dicts. The rare channels
  (``/safety/events``, ``/protocol/metadata``, added ones) stay JSON: a handful of messages per
  session whose ``values``/``parameters`` are free-form objects a fixed schema would not hold.
* **json** (every recording before issue 16, and ``SessionRecorder(encoding="json")``):
  ``message_encoding="json"`` with a ``jsonschema`` schema whose root is an object.

Float32 (24-bit mantissa, relative step 6e-8) against what each field can resolve:

* ``q``, ``q_ref``, ``position`` (m, at most 0.5 m of stroke): step ≤ 3e-8 m, against the
  encoder's 20 µm per count (robot description ``encoder.m_per_count``): 600x finer.
* ``qd`` (m/s, < 1 m/s): step ≤ 6e-8 m/s; the estimate's own quantum is a count per cycle,
  0.02 m/s at 1 kHz.
* ``tau`` (N, < 10 kN): step ≤ 1e-3 N; what reaches the motors is resolved by the DAC's
  4.88 mV LSB (``volts``), far coarser.
* ``volts`` (V, ±10 V): step ≤ 1e-6 V, against the PCI-1720's 4.88 mV LSB.
* wrench ``fx..fz`` (N, < 2.5 kN) step ≤ 2.4e-4 N and ``tx..tz`` (N·m, < 200) step ≤ 1.5e-5,
  against the Delta SI-660-60's 1/8 N (1/4 N on z) and 7.5 mN·m.
* reference ``force`` (N): as the wrench.

``t`` (loop time, s) stays double: float32 would step by 0.24 ms after an hour, a quarter of a
1 kHz period.

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
    """How a recording encodes its channels that have a protobuf message."""

    PROTOBUF = "protobuf"
    JSON = "json"

STATE = "/robot/state"
WRENCH = "/robot/wrench"
EVENTS = "/safety/events"
METADATA = "/protocol/metadata"
REFERENCE = "/protocol/reference"
ANKLE = "/ankle/state"


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

#: Protobuf messages of the 1 kHz channels: the JSON Schemas' fields, same names; numbers
#: are never reused (a removed field keeps its number retired).
STATE_PROTO = ProtoMessage("talus.RobotState", [
    ProtoField("t", 1, _D), ProtoField("q", 2, _F, 3), ProtoField("qd", 3, _F, 3),
    ProtoField("q_ref", 4, _F, 3), ProtoField("tau", 5, _F, 3), ProtoField("volts", 6, _F, 3),
    ProtoField("qd_ref", 7, _F, VARIABLE)])
WRENCH_PROTO = ProtoMessage("talus.Wrench", [
    ProtoField("t", 1, _D), ProtoField("fx", 2, _F), ProtoField("fy", 3, _F),
    ProtoField("fz", 4, _F), ProtoField("tx", 5, _F), ProtoField("ty", 6, _F),
    ProtoField("tz", 7, _F), ProtoField("stale", 8, _B), ProtoField("saturated", 9, _B)])
REFERENCE_PROTO = ProtoMessage("talus.ProtocolReference", [
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
    ANKLE: ChannelSpec(ANKLE, "talus.AnkleState", _ANKLE, {"rate_hz": "100"}),
}

#: Protobuf messages talus writes, by full name: the reader's fast decoders.
PROTO_MESSAGES: dict[str, ProtoMessage] = {
    m.name: m for m in (STATE_PROTO, WRENCH_PROTO, REFERENCE_PROTO)}

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
