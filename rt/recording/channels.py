"""The channels of a session recording: topic → JSON Schema (DESIGN 9).

Every channel is written as MCAP ``message_encoding="json"`` with a ``jsonschema`` schema whose
root is an object: the form Foxglove opens and plots without plugins (PLATFORM, MCAP).

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

from dataclasses import dataclass, field
from typing import Any

#: JSON Schema dialect of every schema here.
SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"
#: MCAP schema encoding and message encoding for JSON channels (MCAP well-known values).
SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"

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
    STATE: ChannelSpec(STATE, "talus.RobotState", _STATE, {"rate_hz": "1000"}),
    WRENCH: ChannelSpec(WRENCH, "talus.Wrench", _WRENCH, {"rate_hz": "1000"}),
    EVENTS: ChannelSpec(EVENTS, "talus.SafetyEvent", _EVENTS),
    METADATA: ChannelSpec(METADATA, "talus.SessionMetadata", _METADATA),
    REFERENCE: ChannelSpec(REFERENCE, "talus.ProtocolReference", _REFERENCE),
    ANKLE: ChannelSpec(ANKLE, "talus.AnkleState", _ANKLE, {"rate_hz": "100"}),
}

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
