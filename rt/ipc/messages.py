"""Wire format of the RT process boundary, protocol version 1 (JSON, UTF-8).

Requests (client → server, one frame)::

    {"v": 1, "id": <int | str>, "client": "<client id>", "cmd": "<name>", "args": {...}}

Replies (server → client, one frame)::

    {"v": 1, "id": <the request's id>, "ok": true,  "result": {...}}
    {"v": 1, "id": <the request's id or null>, "ok": false, "error": "<what was wrong>"}

Commands and their ``args`` (strict: no type coercion, unknown keys refused):

===================  ===========================================================  ========
command              ``args``                                                     who
===================  ===========================================================  ========
``status``           ``{}`` — state, latched faults with their event ids, owner    anyone
``heartbeat``        ``{}`` — only the owner's counts for the supervisor          anyone
``stop``             ``{}`` — soft stop (latched until reset)                      anyone
``estop``            ``{"source": "gui" | "cli" | "keyboard"}`` — hard stop        anyone
``control_acquire``  ``{"name": str}`` — become the one controlling client         see below
``control_release``  ``{}`` — give control back (refused while a motion runs)     owner
``reset``            ``{"acknowledge": [event id, ...]}`` — clear exactly those    owner
                     latched faults (ids from ``status``); all or nothing; the
                     reply comes after the cycle that took it
``set_gains``        ``{"controller": str, "gains": {str: finite number, ...}}``  owner
``run``              ``{"program": str, "params": {...}}`` — a motion program      owner
``session_start``    ``{"protocol": {...}, "patient": {"id": str, "weight_kg"?:   owner
                     number, "limits"?: {...}}, "record": {"dir"?: str}}`` —
                     validated and pre-flighted in the RT process, recorded by it;
                     the reply comes after pre-flight: the session id and the
                     predicted peaks, or the refusal's reason. The same client's
                     passing ``session_preflight`` of the same protocol and patient
                     is reused when nothing changed (``rt.preflight_reuse``):
                     ``preflight_reused``, ``preflight_id``, ``preflight_not_reused``
``session_preflight``  same ``protocol`` and ``patient`` as ``session_start``: the    anyone
                     pre-flight alone (predicted peaks or the refusal), nothing
                     moves; the reply comes when it is done
``session_status``   ``{}`` — phase, progress, elapsed, forces, stops; the last    anyone
                     session's summary once it ended
``session_abort``    ``{}`` — soft stop of the session, then return to rest        anyone
``subscribe_info``   ``{}`` — answered by the server: the PUB endpoint and topics  anyone
===================  ===========================================================  ========

Ownership: one client controls the robot at a time (``control_acquire``). Taking control from
a live owner is refused; after the owner went silent for the heartbeat timeout it is allowed
once the robot is at rest. While a motion or a session runs the owner must keep heartbeating:
when its requests stop for the timeout the supervisor soft-stops, whatever other clients do.

Publications (server PUB socket, two frames: topic, body)::

    telemetry: {"v": 1, "topic": "telemetry", "t": <s>, ...}   (decimated loop state: q, pose,
               wrench, force reference, phase, progress, supervisor mode and causes, session)
    event:     {"v": 1, "topic": "event", "t": <s>, "kind": str, "cause": str, ...}  (safety
               events; kind "session_end" carries the session's summary)

Incoming requests larger than :data:`MAX_MESSAGE_BYTES`, not UTF-8, not JSON (NaN/Infinity
tokens and duplicate keys included), not an object, of another version, with an unknown command
or bad arguments are refused with an error reply naming the problem. This module does not
import zmq.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from rt.errors import InputError, ProtocolError

PROTOCOL_VERSION = 1
#: Default request/reply (ROUTER) and publish (PUB) addresses of the RT server: loopback only.
DEFAULT_ENDPOINT = "tcp://127.0.0.1:5560"
DEFAULT_PUB_ENDPOINT = "tcp://127.0.0.1:5561"
#: Largest accepted request, bytes (all frames together).
MAX_MESSAGE_BYTES = 64 * 1024
#: Publication topics, also the first frame of every published message.
TOPICS: tuple[str, ...] = ("telemetry", "event")
#: Keys every publication of a topic must carry (besides ``v`` and ``topic``, added by the server).
REQUIRED_KEYS: dict[str, tuple[str, ...]] = {"telemetry": ("t",), "event": ("t", "kind", "cause")}

_NAME = Annotated[str, Field(min_length=1, max_length=128)]


# --------------------------------------------------------------------------- command arguments

class _Args(BaseModel):
    """Base of every command's arguments: strict types, no unknown keys, finite numbers."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


class StatusArgs(_Args):
    """``status``: no arguments."""


class HeartbeatArgs(_Args):
    """``heartbeat``: no arguments (the client id comes from the envelope)."""


class StopArgs(_Args):
    """``stop`` (soft stop: decelerate to hold, ramp force down): no arguments."""


class EstopArgs(_Args):
    """``estop`` (hard stop: outputs to zero, drives disabled)."""

    source: Literal["gui", "cli", "keyboard"]


class ResetArgs(_Args):
    """``reset``: clear the latched faults whose event ids are listed (ids from ``status``)."""

    acknowledge: list[Annotated[int, Field(ge=1)]] = Field(max_length=1024)


class ControlAcquireArgs(_Args):
    """``control_acquire``: become the controlling client; ``name`` says who (shown to others)."""

    name: _NAME


class ControlReleaseArgs(_Args):
    """``control_release``: no arguments."""


class PatientArgs(_Args):
    """The patient of a session: a pseudonymous code (never identifying data), the body mass
    (kg; gait replay scales to it) and the limits in force (``PatientLimits`` fields)."""

    id: Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9._-]+$")]
    weight_kg: Annotated[float, Field(gt=0.0, le=400.0)] | None = None
    limits: dict[str, Any] | None = None
    #: The ankle setup (``rt.model.ankle.AnkleSetup`` fields: side, height_above_sole_m,
    #: offset_x_m, offset_y_m ...), validated by the RT process against its platform.
    ankle: dict[str, Any] | None = None


class RecordArgs(_Args):
    """Where the RT process writes the session's recording: ``dir`` (an existing directory;
    default the RT process's ``recordings_dir``). The file name is the RT process's choice."""

    dir: Annotated[str, Field(min_length=1, max_length=4096)] | None = None


class SessionStartArgs(_Args):
    """``session_start``: the protocol document (validated by the protocol schema in the RT
    process), the patient, the recording."""

    protocol: dict[str, Any]
    patient: PatientArgs
    record: RecordArgs = Field(default_factory=RecordArgs)


class SessionPreflightArgs(_Args):
    """``session_preflight``: the protocol document and the patient, as for ``session_start``."""

    protocol: dict[str, Any]
    patient: PatientArgs


class SessionStatusArgs(_Args):
    """``session_status``: no arguments."""


class SessionAbortArgs(_Args):
    """``session_abort``: no arguments."""


class SetGainsArgs(_Args):
    """``set_gains``: new gains for one controller (names and units are the controller's)."""

    controller: _NAME
    gains: dict[_NAME, float] = Field(min_length=1)


class RunArgs(_Args):
    """``run``: start a motion program with its parameters (validated by the program)."""

    program: _NAME
    params: dict[str, Any]


class SubscribeInfoArgs(_Args):
    """``subscribe_info``: no arguments."""


#: command name -> its argument model
COMMANDS: dict[str, type[_Args]] = {
    "status": StatusArgs,
    "heartbeat": HeartbeatArgs,
    "stop": StopArgs,
    "estop": EstopArgs,
    "reset": ResetArgs,
    "control_acquire": ControlAcquireArgs,
    "control_release": ControlReleaseArgs,
    "set_gains": SetGainsArgs,
    "run": RunArgs,
    "session_start": SessionStartArgs,
    "session_preflight": SessionPreflightArgs,
    "session_status": SessionStatusArgs,
    "session_abort": SessionAbortArgs,
    "subscribe_info": SubscribeInfoArgs,
}


class _Envelope(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    v: Literal[1]
    id: int | str
    client: _NAME
    cmd: Annotated[str, Field(max_length=64)]
    args: dict[str, Any]

    @field_validator("id", mode="plain")
    @classmethod
    def _check_id(cls, value: Any) -> int | str:
        # A plain validator: one clear message instead of one per member of int | str.
        rid = _peek_id({"id": value})
        if rid is None:
            raise ValueError("should be an integer or a string of at most 128 characters")
        return rid


# --------------------------------------------------------------------------- publications

class TelemetryMessage(BaseModel):
    """A telemetry sample; fields besides these are the caller's (decimated loop state)."""

    model_config = ConfigDict(extra="allow")

    v: Literal[1]
    topic: Literal["telemetry"]
    t: float = Field(description="loop time, s")


class EventMessage(BaseModel):
    """A supervisor/loop event (warn, soft stop, hard stop, fault, reset ...), with its cause."""

    model_config = ConfigDict(extra="allow")

    v: Literal[1]
    topic: Literal["event"]
    t: float = Field(description="loop time, s")
    kind: str
    cause: str


_PUBLICATION_MODELS: dict[str, type[BaseModel]] = {
    "telemetry": TelemetryMessage, "event": EventMessage}


# --------------------------------------------------------------------------- requests

class RequestRejected(InputError):
    """A request failed validation; ``request_id`` is its id when it could be read, else None."""

    def __init__(self, message: str, request_id: int | str | None = None) -> None:
        super().__init__(message)
        self.request_id = request_id


@dataclass(frozen=True)
class Request:
    """A validated request; ``args`` is the command's argument model."""

    id: int | str
    client: str
    cmd: str
    args: _Args

    def kwargs(self) -> dict[str, Any]:
        """The arguments as keyword arguments for the handler (values not copied)."""
        # Not model_dump(): it would deep-copy (and recurse into) arbitrary ``run`` params.
        return {name: getattr(self.args, name) for name in type(self.args).model_fields}


class _DuplicateKey(ValueError):
    pass


def _reject_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    obj: dict[str, Any] = {}
    for key, value in pairs:
        if key in obj:
            # Which one would win is a JSON-library accident: refuse instead of guessing.
            raise _DuplicateKey(f"duplicate key {key!r}")
        obj[key] = value
    return obj


def _reject_constant(token: str) -> Any:
    raise ValueError(f"{token} is not valid JSON")


def _loads_strict(text: str) -> Any:
    return json.loads(text, object_pairs_hook=_reject_duplicates, parse_constant=_reject_constant)


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def describe_validation_error(err: ValidationError) -> str:
    """One line naming every offending field: ``'source': Input should be ... (got 'x')``."""
    parts: list[str] = []
    for e in err.errors(include_url=False):
        loc = ".".join(str(p) for p in e["loc"]) or "(value)"
        if e["type"] == "missing":
            parts.append(f"missing {loc!r}")
        elif e["type"] == "extra_forbidden":
            parts.append(f"unknown key {loc!r}")
        else:
            # Our own validators' messages come without pydantic's "Value error, " prefix.
            msg = str(e["ctx"]["error"]) if e["type"] == "value_error" else e["msg"]
            parts.append(f"{loc!r}: {msg} (got {_short(e['input'])})")
    return "; ".join(parts)


def _peek_id(obj: dict[str, Any]) -> int | str | None:
    """The request id if it is well-formed, so even a refusal can be matched by the client."""
    rid = obj.get("id")
    if type(rid) is int or (isinstance(rid, str) and len(rid) <= 128):
        return rid
    return None


def decode_request(raw: bytes) -> Request:
    """Validate one request frame.

    Raises:
        RequestRejected: with a message naming what was wrong (and the id when readable).
    """
    if len(raw) > MAX_MESSAGE_BYTES:
        raise RequestRejected(
            f"message too large: {len(raw)} bytes > {MAX_MESSAGE_BYTES} bytes allowed")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RequestRejected(f"malformed message: not UTF-8 text ({exc.reason} at byte "
                              f"{exc.start})") from None
    try:
        obj = _loads_strict(text)
    except RecursionError:
        raise RequestRejected("malformed JSON: nested too deeply") from None
    except ValueError as exc:  # JSONDecodeError, duplicate keys, NaN/Infinity
        raise RequestRejected(f"malformed JSON: {exc}") from None
    if not isinstance(obj, dict):
        raise RequestRejected(
            f"malformed request: expected a JSON object, got {type(obj).__name__}")
    rid = _peek_id(obj)
    if "v" not in obj:
        raise RequestRejected(
            f"missing 'v' (the protocol version; this server speaks v{PROTOCOL_VERSION})", rid)
    if type(obj["v"]) is not int or obj["v"] != PROTOCOL_VERSION:
        raise RequestRejected(f"unsupported protocol version {_short(obj['v'])}; this server "
                              f"speaks v{PROTOCOL_VERSION}", rid)
    try:
        env = _Envelope.model_validate(obj)
    except ValidationError as exc:
        raise RequestRejected(f"bad request: {describe_validation_error(exc)}", rid) from None
    model = COMMANDS.get(env.cmd)
    if model is None:
        raise RequestRejected(f"unknown command {_short(env.cmd)}; known commands: "
                              f"{', '.join(sorted(COMMANDS))}", env.id)
    try:
        args = model.model_validate(env.args)
    except ValidationError as exc:
        raise RequestRejected(
            f"bad args for {env.cmd!r}: {describe_validation_error(exc)}", env.id) from None
    except RecursionError:
        raise RequestRejected(f"bad args for {env.cmd!r}: nested too deeply", env.id) from None
    return Request(id=env.id, client=env.client, cmd=env.cmd, args=args)


def encode_request(request_id: int | str, client: str, cmd: str, args: dict[str, Any]) -> bytes:
    """Build a request frame, validating it exactly as the server will.

    Raises:
        InputError: the request would be refused by the server (nothing is sent).
    """
    try:
        body = json.dumps({"v": PROTOCOL_VERSION, "id": request_id, "client": client,
                           "cmd": cmd, "args": args}, separators=(",", ":"),
                          default=_json_default, allow_nan=False).encode()
    except (TypeError, ValueError) as exc:  # not serializable, or NaN/inf
        raise InputError(f"bad args for {cmd!r}: {exc}") from None
    decode_request(body)  # same checks as the server: fail here, before the network
    return body


# --------------------------------------------------------------------------- replies

@dataclass(frozen=True)
class Reply:
    """A decoded reply: ``result`` when ``ok``, else ``error``."""

    id: int | str | None
    ok: bool
    result: dict[str, Any] | None = None
    error: str | None = None


def _json_default(obj: Any) -> Any:
    # numpy arrays and scalars (loop state) without importing numpy here.
    tolist = getattr(obj, "tolist", None)
    if callable(tolist):
        return tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON-serializable")


def dumps(obj: dict[str, Any]) -> bytes:
    """Compact JSON bytes; numpy values become lists/numbers (NaN stays NaN, as Python reads)."""
    return json.dumps(obj, separators=(",", ":"), default=_json_default).encode()


def ok_reply(request_id: int | str | None, result: dict[str, Any]) -> bytes:
    """A success reply frame. Raises TypeError/ValueError when ``result`` is not JSON."""
    return dumps({"v": PROTOCOL_VERSION, "id": request_id, "ok": True, "result": result})


def error_reply(request_id: int | str | None, message: str) -> bytes:
    """A refusal frame carrying ``message``."""
    return dumps({"v": PROTOCOL_VERSION, "id": request_id, "ok": False, "error": message})


def decode_reply(raw: bytes) -> Reply:
    """Decode a reply frame.

    Raises:
        ProtocolError: the frame is not a version-1 reply.
    """
    try:
        obj = json.loads(raw)
    except (ValueError, RecursionError) as exc:
        raise ProtocolError(f"RT server sent malformed JSON: {exc}") from None
    if not isinstance(obj, dict) or obj.get("v") != PROTOCOL_VERSION:
        raise ProtocolError(f"RT server sent something that is not a v{PROTOCOL_VERSION} reply: "
                            f"{_short(obj)}")
    ok = obj.get("ok")
    if ok is True and isinstance(obj.get("result"), dict):
        return Reply(id=obj.get("id"), ok=True, result=obj["result"])
    if ok is False and isinstance(obj.get("error"), str):
        return Reply(id=obj.get("id"), ok=False, error=obj["error"])
    raise ProtocolError(f"RT server sent a reply without ok+result or error: {_short(obj)}")


# --------------------------------------------------------------------------- publications

def check_publication(topic: str, payload: dict[str, Any]) -> str | None:
    """Why ``payload`` cannot be published on ``topic`` (None when it can). Cheap: no copies."""
    required = REQUIRED_KEYS.get(topic)
    if required is None:
        return f"unknown topic {topic!r}; topics: {', '.join(TOPICS)}"
    if not isinstance(payload, dict):
        return f"{topic} payload must be a dict, got {type(payload).__name__}"
    for key in required:
        if key not in payload:
            return f"{topic} payload lacks {key!r}"
    if "v" in payload or "topic" in payload:
        return "payload must not carry 'v' or 'topic' (publish adds them)"
    return None


def encode_publication(topic: str, payload: dict[str, Any]) -> list[bytes]:
    """The two frames (topic, body) of a publication; the payload must pass
    :func:`check_publication`. Raises TypeError/ValueError when it is not JSON-serializable."""
    body = {"v": PROTOCOL_VERSION, "topic": topic}
    body.update(payload)
    return [topic.encode(), dumps(body)]


def decode_publication(frames: list[bytes]) -> dict[str, Any]:
    """Decode and check a publication's frames.

    Raises:
        ProtocolError: not a version-1 telemetry/event message.
    """
    if len(frames) != 2:
        raise ProtocolError(f"publication has {len(frames)} frames, expected 2 (topic, body)")
    topic = frames[0].decode("utf-8", "replace")
    model = _PUBLICATION_MODELS.get(topic)
    if model is None:
        raise ProtocolError(f"publication on unknown topic {topic!r}")
    try:
        obj: dict[str, Any] = json.loads(frames[1])
    except (ValueError, RecursionError) as exc:
        raise ProtocolError(f"publication on {topic!r} is not JSON: {exc}") from None
    try:
        model.model_validate(obj)
    except ValidationError as exc:
        raise ProtocolError(
            f"bad {topic} publication: {describe_validation_error(exc)}") from None
    return obj

