"""Report inputs from the clinical record (``patients``): a stored session, a patient's history.

The reports themselves take plain data (``SessionReportInput``, ``ProgressInput``); this module
is the one place that reads them out of the record, through its service layer (so the user's
role decides what may be read, and reading identifying data is audited there).
"""
from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Any

from patients.anatomy import to_clinical
from patients.service import Actor, ClinicalRecord
from reports.inputs import ReportInputError
from reports.progress import ProgressInput, progress_input_from_dict
from reports.session_data import SessionReportInput, session_input_from_record

#: Stored outcomes → the progress report's (a refused session never started: not attended).
_OUTCOMES = {"completed": "completed", "stopped_by_user": "stopped",
             "stopped_by_fault": "stopped", "running": "stopped", "refused": "cancelled"}


def session_input(record: ClinicalRecord, actor: Actor, uid: str, robot: Any = None,
                  identify: bool = False) -> SessionReportInput:
    """A stored session's report input (its recording when it is still there); with
    ``identify`` the patient's identifying data, if the user's role may read them."""
    s = record.get_session(actor, uid)
    patient = record.get_patient(actor, s["patient"])
    meta = {"patient_id": s["patient"], "clinician": s["clinician"],
            "protocol_name": s["protocol_name"], "limits": s.get("limits") or {},
            "side": patient.get("affected_side")}
    recording = s.get("recording_path")
    rec_path = Path(recording) if recording and Path(recording).exists() else None
    inp = session_input_from_record(
        {"id": uid, "metadata": meta, "summary": s.get("summary"),
         "recording_sha256": s.get("recording_sha256")}, rec_path, robot)
    if identify:
        identity = record.get_patient(actor, s["patient"],
                                      include_identity=True).get("identity") or {}
        inp.identity = {k: str(v) for k, v in identity.items() if v}
    return inp


def progress_input(record: ClinicalRecord, actor: Actor, code: str,
                   since: dt.date | None = None, until: dt.date | None = None) -> ProgressInput:
    """A patient's progress input: the sessions stored in [since, until] and the ROM in force
    (the prescription) in clinical terms."""
    patient = record.get_patient(actor, code)
    limits = patient.get("limits")
    if not limits:
        raise ReportInputError(f"patient {code} has no limits prescribed: the progress report "
                               "compares with the prescribed range")
    side = patient.get("affected_side") or "right"
    rom = to_clinical(limits, side)
    if rom is None:
        raise ReportInputError(f"patient {code}: the affected foot is not recorded")
    start = None if since is None else dt.datetime.combine(since, dt.time.min, dt.UTC)
    end = None if until is None else dt.datetime.combine(until + dt.timedelta(days=1),
                                                         dt.time.min, dt.UTC)
    sessions = []
    for s in record.list_sessions(actor, code, since=start, until=end, full=True):
        summary = s.get("summary") or {}
        sessions.append({"id": s["uid"], "date": s["started_at"][:10],
                         "protocol": s["protocol_name"],
                         "outcome": _OUTCOMES.get(s["outcome"], "stopped"),
                         "kind": summary.get("kind"), "summary": summary or None,
                         "limits": s.get("limits")})
    return progress_input_from_dict({
        "patient_code": code, "side": "left" if str(side).lower().startswith("l") else "right",
        "prescribed_rom_deg": {k.removesuffix("_deg"): v for k, v in rom.as_dict().items()},
        "sessions": sessions}, f"patient {code}")
