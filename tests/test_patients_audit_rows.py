"""Every change to the clinical record leaves exactly one audit row naming it, and reads leave
none unless they show identifying data or export the record: checked method by method over
the whole public surface of ``ClinicalRecord`` (a new method fails this test until it is
classified here), and the guard that refuses an unaudited change."""
from __future__ import annotations

import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from patients_helpers import PASSWORD, PROTOCOL, open_record
from sqlalchemy.orm import Session

from patients import audit
from patients.errors import RecordError
from patients.roles import Action
from patients.service import ClinicalRecord, Identity

YAML = Path(PROTOCOL).read_text()
#: Public members that touch no database (the connection's own lifecycle, the login table).
NO_DATABASE = {"open", "close", "logout"}
#: Reads that leave no audit row.
SILENT_READS = {"has_users", "list_users", "list_patients", "get_patient", "limits_in_force",
                "ankle_in_force", "limits_history", "plans", "list_sessions", "get_session",
                "list_calibrations", "get_calibration", "verify_audit"}


def _calibration(record_id: str) -> dict[str, Any]:
    return {"schema_version": 1, "kind": "talus.calibration_record", "id": record_id,
            "created_utc": "2026-11-23T17:00:00Z", "operator": "engineer",
            "plate": {"name": "plate", "serial": "S1"}, "matrix": {}, "metrics": {}}


def _entries(record: ClinicalRecord) -> list[dict[str, Any]]:
    with Session(record.engine) as db:
        return list(audit.export(db))


def test_every_change_writes_one_audit_row_and_silent_reads_none(tmp_path) -> None:
    record = open_record(str(tmp_path / "talus.db"))
    s: dict[str, Any] = {}     # what the steps hand on to each other

    def new_patient() -> None:
        s["code"] = record.add_patient(s["admin"], body_mass_kg=70,
                                       affected_side="left")["code"]

    def plan() -> None:
        s["plan"] = record.assign_plan(s["clin"], s["code"], YAML)["id"]

    def start() -> None:
        s["uid"] = record.start_session(s["clin"], s["code"], YAML)["uid"]

    def export() -> None:
        s["export"] = record.export_patient(s["admin"], s["code"])

    def engineer() -> None:
        record.add_user(s["admin"], "eng", "engineer", PASSWORD)
        s["eng"] = record.authenticate("eng", PASSWORD)

    # (method, call, the audit action it must write; None: a read that writes nothing), in
    # an order where each step has what it needs, each by a role allowed to.
    steps: list[tuple[str, Callable[[], object], str | None]] = [
        ("has_users", lambda: record.has_users(), None),
        ("init_admin", lambda: s.setdefault("admin", record.init_admin("admin", PASSWORD)),
         "users.init"),
        ("add_user", lambda: record.add_user(s["admin"], "clin", "clinician", PASSWORD),
         "user.create"),
        ("authenticate", lambda: s.setdefault("clin", record.authenticate("clin", PASSWORD)),
         "login"),
        ("", engineer, None),       # set-up, not counted: an engineer for the calibrations
        ("set_password", lambda: record.set_password(s["admin"], "clin", PASSWORD + "!"),
         "user.passwd"),
        ("list_users", lambda: record.list_users(s["admin"]), None),
        ("add_patient", new_patient, "patient.create"),
        ("update_patient", lambda: record.update_patient(s["clin"], s["code"], notes="seen"),
         "patient.update"),
        ("set_identity", lambda: record.set_identity(s["admin"], s["code"], Identity("Ana Ruiz")),
         "identity.create"),
        ("get_patient", lambda: record.get_patient(s["admin"], s["code"]), None),
        ("list_patients", lambda: record.list_patients(s["admin"]), None),
        ("set_limits", lambda: record.set_limits(s["clin"], s["code"], max_force_n=500),
         "limits.set"),
        ("limits_in_force", lambda: record.limits_in_force(s["clin"], s["code"]), None),
        ("limits_history", lambda: record.limits_history(s["clin"], s["code"]), None),
        ("set_ankle", lambda: record.set_ankle(s["clin"], s["code"], height_above_sole_m=0.07),
         "ankle.set"),
        ("ankle_in_force", lambda: record.ankle_in_force(s["clin"], s["code"]), None),
        ("assign_plan", plan, "plan.assign"),
        ("plans", lambda: record.plans(s["clin"], s["code"]), None),
        ("start_session", start, "session.start"),
        ("finish_session", lambda: record.finish_session(s["clin"], s["uid"], "completed"),
         "session.finish"),
        ("list_sessions", lambda: record.list_sessions(s["clin"]), None),
        ("get_session", lambda: record.get_session(s["clin"], s["uid"]), None),
        ("end_plan", lambda: record.end_plan(s["clin"], s["code"], s["plan"]), "plan.end"),
        ("export_patient", export, "record.export"),
        ("import_patient", lambda: record.import_patient(s["admin"], {
            **s["export"], "patient": {**s["export"]["patient"], "code": "IMP-1"},
            "sessions": []}), "record.import"),
        ("forget_patient", lambda: record.forget_patient(s["admin"], s["code"]), "patient.forget"),
        ("add_calibration", lambda: record.add_calibration(s["eng"], _calibration("CAL-1")),
         "calibration.add"),
        ("attach_calibration_certificate", lambda: record.attach_calibration_certificate(
            s["eng"], "CAL-1", "cert.pdf", "c" * 64), "calibration.certify"),
        ("list_calibrations", lambda: record.list_calibrations(s["admin"]), None),
        ("get_calibration", lambda: record.get_calibration(s["admin"], "CAL-1"), None),
        ("verify_audit", lambda: record.verify_audit(s["admin"]), None),
        ("export_audit", lambda: record.export_audit(s["admin"]), "audit.export"),
        ("set_user_disabled", lambda: record.set_user_disabled(s["admin"], "clin", True),
         "user.disable"),
        ("note_database_action", lambda: record.note_database_action(s["admin"], "db.backup", {}),
         "db.backup"),
    ]
    public = {name for name, _ in inspect.getmembers(ClinicalRecord, callable)
              if not name.startswith("_")}
    covered = {name for name, _, _ in steps if name}
    assert covered | NO_DATABASE == public, "classify every public method of ClinicalRecord here"
    assert {name for name, _, action in steps if name and action is None} == SILENT_READS
    try:
        for name, call, action in steps:
            before = _entries(record)
            call()
            if name:
                new = _entries(record)[len(before):]
                assert [e["action"] for e in new] == ([action] if action else []), name
    finally:
        record.close()


def test_a_change_that_writes_no_audit_row_is_refused_and_rolled_back(tmp_path) -> None:
    record = open_record(str(tmp_path / "talus.db"))
    try:
        admin = record.init_admin("admin", PASSWORD)
        code = record.add_patient(admin, notes="first")["code"]
        rows = len(_entries(record))
        with pytest.raises(RecordError, match="wrote no audit row; nothing was saved"), \
                record._acting(admin, Action.PATIENT_CREATE, writes=True) as act:
            act.patient(code).notes = "changed behind the audit trail"
        assert record.get_patient(admin, code)["notes"] == "first"
        assert len(_entries(record)) == rows
    finally:
        record.close()
