"""The protocols package's side of a session in the RT process (``rt.sessions``): validate the
protocol document a client sent, build its generator, pre-flight it on the twin, and give the
RT process what it needs to run, record and summarize it.

Data files a protocol names (a gait record, a playback CSV) resolve in the protocol library
directory when relative; a client that loaded its protocol from elsewhere sends them absolute
(:func:`protocol_document`).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path, PurePath
from typing import Any

from protocols.generators import make_generator
from protocols.library import LIBRARY_DIR, load_protocol
from protocols.schema import GaitReplay, PositionPlayback, ProtocolModel, validate_protocol_data
from protocols.session import SessionFigures, SessionSetup, protocol_limits_of, preflight, start_pose
from rt.errors import ProtocolValidationError
from rt.model import RobotModel
from rt.references.program import Program
from rt.safety.limits import ProtocolLimits
from rt.sessions import PatientInfo, SessionContext

#: Where a session_start's protocol is said to come from in messages.
DOCUMENT_SOURCE = "session_start.protocol"


def _data_field(protocol: ProtocolModel) -> str | None:
    """The name of the field holding a data file's path, if the kind has one."""
    if isinstance(protocol, GaitReplay):
        return "source"
    if isinstance(protocol, PositionPlayback):
        return "file"
    return None


def protocol_document(path: str | Path) -> dict[str, Any]:
    """A protocol file as the JSON object ``session_start`` sends: validated here first (errors
    name the file and the line), its data file's path made absolute."""
    protocol = load_protocol(path)
    doc = protocol.model_dump(mode="json")
    name = _data_field(protocol)
    if name is not None and not PurePath(doc[name]).is_absolute():
        base = Path(path).resolve().parent
        doc[name] = str(base / doc[name])
    return doc


def _sha256(path: Path) -> str | None:
    try:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        return h.hexdigest()
    except OSError:
        return None


@dataclass
class ProtocolSession:
    """A prepared protocol session (``rt.sessions.PreparedSession``)."""

    protocol: ProtocolModel
    program: Program
    model: RobotModel
    preflight: dict[str, Any]
    start_pose: tuple[float, float, float]
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.protocol.name

    @property
    def kind(self) -> str:
        return self.protocol.kind

    @property
    def protocol_limits(self) -> ProtocolLimits | None:
        return protocol_limits_of(self.protocol)

    def figures(self) -> SessionFigures:
        return SessionFigures(self.protocol, self.model)


class ProtocolSessions:
    """The RT process's session factory (``rt.sessions.SessionFactory``)."""

    def __init__(self, base_dir: Path = LIBRARY_DIR):
        self.base_dir = base_dir

    def prepare(self, protocol: dict[str, Any], patient: PatientInfo,
                context: SessionContext) -> ProtocolSession:
        model_obj = validate_protocol_data(protocol, DOCUMENT_SOURCE)
        setup = SessionSetup(patient_weight_kg=patient.weight_kg,
                             patient_limits=patient.limits,
                             robot_limits=context.robot_limits, protocol=model_obj,
                             base_dir=self.base_dir)
        pre = preflight(setup, context.model)
        gen = make_generator(model_obj, dt=1.0 / context.rate_hz, kinematics=context.model.kin,
                             patient_weight_kg=patient.weight_kg, base_dir=self.base_dir)
        report = gen.validate()
        if not report.ok:  # cannot differ from pre-flight's; kept as the program's own check
            raise ProtocolValidationError(f"{DOCUMENT_SOURCE}: " + "; ".join(report.violations))
        parameters = model_obj.model_dump(mode="json")
        meta: dict[str, Any] = {"protocol_name": model_obj.name,
                                "protocol_version": int(getattr(model_obj, "schema_version", 1)),
                                "parameters": parameters}
        name = _data_field(model_obj)
        if name is not None:
            data = Path(parameters[name])
            data = data if data.is_absolute() else self.base_dir / data
            meta["data_file"] = {"path": str(data), "sha256": _sha256(data)}
        return ProtocolSession(model_obj, gen, context.model, pre["predicted"],
                               start_pose(gen), meta)
