"""The pseudonymous record of one patient as a JSON document (export, then import elsewhere).

It carries the code and everything clinical (data, limits history, plans with their protocol
YAML, sessions with summaries and recording path + sha256), never identifying data. Free-text
fields (diagnosis, notes) travel as written: clinicians must keep names out of them.

Validated on import with pydantic: a malformed document is refused naming the field, and
nothing is written.
"""
from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from patients.errors import InputError

KIND = "talus.patient_record"
SCHEMA_VERSION = 1


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ClinicalData(_Strict):
    code: str
    body_mass_kg: float | None = None
    height_m: float | None = None
    affected_side: str | None = None
    diagnosis: str | None = None
    notes: str | None = None
    created_at: dt.datetime
    created_by: str
    forgotten_at: dt.datetime | None = None


class LimitsEntry(_Strict):
    roll_min_deg: float
    roll_max_deg: float
    pitch_min_deg: float
    pitch_max_deg: float
    max_force_n: float
    max_angular_speed_deg_s: float
    rom_tolerance_deg: float
    set_by: str
    set_at: dt.datetime
    reason: str | None = None


class PlanEntry(_Strict):
    id: int
    protocol_name: str
    protocol_kind: str
    protocol_yaml: str
    protocol_sha256: str = Field(pattern=r"^[0-9a-f]{64}$")
    parameters: dict[str, Any] = {}
    assigned_by: str
    assigned_at: dt.datetime
    active: bool = True


class SessionEntry(_Strict):
    uid: str
    plan_id: int | None = None
    clinician: str
    protocol_name: str
    protocol_yaml: str
    protocol_sha256: str = Field(pattern=r"^[0-9a-f]{64}$")
    limits: dict[str, float]
    body_mass_kg: float | None = None
    started_at: dt.datetime
    ended_at: dt.datetime | None = None
    outcome: str
    stopped_by: str | None = None
    summary: dict[str, Any] | None = None
    recording_path: str | None = None
    recording_sha256: str | None = None


class Recording(_Strict):
    session_uid: str
    path: str
    sha256: str | None = None


class PatientRecord(_Strict):
    kind: Literal["talus.patient_record"]
    schema_version: Literal[1]
    exported_at: dt.datetime
    exported_by: str
    patient: ClinicalData
    limits: list[LimitsEntry]
    plans: list[PlanEntry]
    sessions: list[SessionEntry]
    recordings: list[Recording]


def parse(document: Any) -> PatientRecord:
    """Validate an export document; ``InputError`` names the first problems."""
    try:
        return PatientRecord.model_validate(document)
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(str(x) for x in e['loc']) or 'document'}: {e['msg']}"
                             for e in exc.errors()[:5])
        raise InputError(f"not a talus patient record: {problems}") from None
