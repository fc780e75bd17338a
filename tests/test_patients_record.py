"""The clinical record's service layer, on SQLite and on a real PostgreSQL server."""
from __future__ import annotations

import datetime as dt
from pathlib import Path

import pytest
import sqlalchemy as sa

from patients import anatomy
from patients.errors import (AccountLocked, AlreadyExists, AuthenticationFailed, InputError,
                             NotFound, PermissionDenied)
from patients.models import Outcome
from patients.service import LIMIT_FIELDS, Identity
from rt.safety.limits import PatientLimits

from patients_helpers import PASSWORD, PROTOCOL, Clock, open_record, staff

PROTOCOL_YAML = Path(PROTOCOL).read_text()


@pytest.fixture()
def clock() -> Clock:
    return Clock()


@pytest.fixture()
def record(database_url, clock):
    rec = open_record(database_url, clock)
    yield rec
    rec.close()


@pytest.fixture()
def people(record):
    return staff(record)


def test_first_admin_only_once_and_no_default_password(record):
    assert not record.has_users()
    with pytest.raises(InputError, match="at least 10"):
        record.init_admin("admin", "")
    assert not record.has_users()  # the refused init changed nothing
    record.init_admin("admin", PASSWORD)
    with pytest.raises(AlreadyExists, match="already has users"):
        record.init_admin("other", PASSWORD)


def test_passwords_are_argon2id_with_rfc9106_parameters(database_url):
    from patients.service import ClinicalRecord
    rec = ClinicalRecord.open(database_url, create=True)  # the production hasher
    try:
        rec.init_admin("admin", PASSWORD)
        with rec._tx() as db:
            stored = db.execute(sa.text("SELECT password_hash FROM users")).scalar_one()
        assert stored.startswith("$argon2id$v=19$m=65536,t=3,p=4$")
        assert PASSWORD not in stored
    finally:
        rec.close()


def test_lockout_after_repeated_failures_then_time_or_admin_unlocks(record, people, clock):
    for _ in range(4):
        with pytest.raises(AuthenticationFailed, match="wrong user name or password"):
            record.authenticate("clinician", "not the password")
    record.authenticate("clinician", PASSWORD)  # 4 failures: not locked, and the count resets
    for _ in range(5):
        with pytest.raises(AuthenticationFailed):
            record.authenticate("clinician", "not the password")
    with pytest.raises(AccountLocked, match="locked until"):
        record.authenticate("clinician", PASSWORD)  # even the right password
    clock.advance(15 * 60 - 1)
    with pytest.raises(AccountLocked):
        record.authenticate("clinician", PASSWORD)
    clock.advance(2)
    record.authenticate("clinician", PASSWORD)
    # An admin's new password unlocks at once.
    for _ in range(5):
        with pytest.raises(AuthenticationFailed):
            record.authenticate("viewer", "nope nope nope")
    record.set_password(people.admin, "viewer", "a new viewer password")
    record.authenticate("viewer", "a new viewer password")
    actions = [e["action"] for e in record.export_audit(people.admin)]
    assert actions.count("login.failed") == 14 and actions.count("login.refused") == 2


def test_unknown_user_and_disabled_user_cannot_log_in(record, people):
    with pytest.raises(AuthenticationFailed):
        record.authenticate("nobody", PASSWORD)
    record.set_user_disabled(people.admin, "viewer", True)
    with pytest.raises(AuthenticationFailed):
        record.authenticate("viewer", PASSWORD)
    with pytest.raises(AuthenticationFailed, match="disabled"):
        record.list_sessions(people.viewer)  # an open login stops working at once


def test_a_forged_actor_is_refused(record, people):
    from patients.roles import Role
    from patients.service import Actor
    with pytest.raises(AuthenticationFailed, match="not logged in"):
        record.list_users(Actor("admin", Role.ADMIN, "0" * 32))


def _patient(record, people, **kw):
    kw.setdefault("body_mass_kg", 72.5)
    kw.setdefault("affected_side", "left")
    return record.add_patient(people.clinician, identity=Identity(
        "Juana Pérez Gómez", dt.date(1961, 5, 17), "12345678Z", "+34 600 000 000"), **kw)["code"]


def test_patient_code_is_the_only_thing_the_pseudonymous_views_show(record, people):
    code = _patient(record, people)
    for role in ("admin", "clinician", "engineer", "viewer"):
        shown = str(record.get_patient(people.by_role(role), code)) \
            + str(record.list_patients(people.by_role(role)))
        assert code in shown and "Juana" not in shown and "12345678Z" not in shown
    with_id = record.get_patient(people.clinician, code, include_identity=True)
    assert with_id["identity"] == {"full_name": "Juana Pérez Gómez", "birth_date": "1961-05-17",
                                   "national_id": "12345678Z", "contact": "+34 600 000 000"}
    for role in ("engineer", "viewer"):
        with pytest.raises(PermissionDenied, match="identity.read"):
            record.get_patient(people.by_role(role), code, include_identity=True)
    reads = [e for e in record.export_audit(people.admin) if e["action"] == "identity.read"]
    assert len(reads) == 1 and reads[0]["username"] == "clinician"
    assert "Juana" not in str(record.export_audit(people.admin))  # fields, never values


def test_bad_patient_input_is_refused_and_changes_nothing(record, people):
    for kw, message in ((dict(body_mass_kg=7000), "body mass"), (dict(height_m=175), "metres"),
                        (dict(affected_side="up"), "unknown side"),
                        (dict(code="juana perez"), "patient code")):
        with pytest.raises(InputError, match=message):
            record.add_patient(people.clinician, **kw)
    assert record.list_patients(people.clinician) == []


def test_limits_in_force_are_the_latest_prescription_with_exactly_the_rt_fields(record, people,
                                                                                 clock):
    code = _patient(record, people)
    with pytest.raises(NotFound, match="no limits prescribed"):
        record.limits_in_force(people.clinician, code)
    record.set_limits(people.clinician, code, pitch_min_deg=-10, pitch_max_deg=10,
                      reason="first visit")
    clock.advance(7 * 86400)
    record.set_limits(people.clinician, code, pitch_max_deg=18, max_force_n=400)
    lim = record.limits_in_force(people.viewer, code)
    assert set(lim) == set(PatientLimits.model_fields) | {"body_mass_kg"}
    assert lim["pitch_min_deg"] == -10 and lim["pitch_max_deg"] == 18 and lim["max_force_n"] == 400
    assert lim["body_mass_kg"] == 72.5
    PatientLimits(**{k: lim[k] for k in LIMIT_FIELDS})  # the RT side accepts it as is
    history = record.limits_history(people.clinician, code)
    assert [h["set_at"] for h in history] == ["2026-03-02T09:00:00+00:00",
                                              "2026-03-09T09:00:00+00:00"]
    assert history[0]["set_by"] == "clinician" and history[0]["reason"] == "first visit"
    with pytest.raises(InputError, match="pitch_min_deg must be below pitch_max_deg"):
        record.set_limits(people.clinician, code, pitch_min_deg=20)
    with pytest.raises(InputError, match="max_force_n"):
        record.set_limits(people.clinician, code, max_force_n=-1)
    assert len(record.limits_history(people.clinician, code)) == 2


@pytest.mark.parametrize("side", ["left", "right"])
def test_clinical_rom_maps_to_roll_and_pitch_by_foot(side):
    rom = anatomy.ClinicalRom(dorsiflexion_deg=15, plantarflexion_deg=30, inversion_deg=20,
                              eversion_deg=10)
    robot = anatomy.to_robot(rom, side)
    assert robot["pitch_min_deg"] == -15 and robot["pitch_max_deg"] == 30
    # Right foot, toes to +x: +roll raises its medial edge (inversion); left foot: eversion.
    assert (robot["roll_max_deg"], robot["roll_min_deg"]) == \
        ((20, -10) if side == "right" else (10, -20))
    assert anatomy.to_clinical(robot, side) == rom
    with pytest.raises(InputError, match="left' or 'right"):
        anatomy.to_robot(rom, "both")


def test_a_session_stores_snapshots_outcome_and_recording(record, people, clock):
    code = _patient(record, people)
    record.set_limits(people.clinician, code, pitch_min_deg=-12, pitch_max_deg=12)
    plan = record.assign_plan(people.clinician, code, PROTOCOL_YAML, {"repetitions": 3})
    started = record.start_session(people.clinician, code, PROTOCOL_YAML, plan_id=plan["id"])
    assert started["limits"]["pitch_max_deg"] == 12 and started["body_mass_kg"] == 72.5
    assert started["protocol_sha256"] == plan["protocol_sha256"]
    # Limits changed during or after the session do not rewrite what the session ran with.
    record.set_limits(people.clinician, code, pitch_max_deg=5)
    clock.advance(95.5)
    summary = {"protocol": "ankle", "completed": False, "stops": [{"cause": "force"}]}
    done = record.finish_session(people.clinician, started["uid"], "stopped_by_fault",
                                 stopped_by="max_force_n", summary=summary,
                                 recording_path="out/s1.mcap", recording_sha256="a" * 64)
    assert done["limits"]["pitch_max_deg"] == 12
    assert done["ended_at"] == "2026-03-02T09:01:35.500000+00:00"
    shown = record.get_session(people.engineer, started["uid"])
    assert shown["summary"] == summary and shown["protocol_yaml"] == PROTOCOL_YAML
    assert (shown["outcome"], shown["stopped_by"]) == ("stopped_by_fault", "max_force_n")
    listed = record.list_sessions(people.viewer, code, full=True)
    assert listed == [{k: v for k, v in shown.items() if k != "protocol_yaml"}]
    with pytest.raises(InputError, match="already finished"):
        record.finish_session(people.clinician, started["uid"], Outcome.COMPLETED)
    with pytest.raises(InputError, match="needs stopped_by"):
        record.finish_session(people.clinician, started["uid"], Outcome.STOPPED_BY_USER)
    ended = record.end_plan(people.clinician, code, plan["id"])
    assert ended["active"] is False and record.plans(people.viewer, code)[0]["active"] is False
    with pytest.raises(InputError, match="has ended"):
        record.start_session(people.clinician, code, PROTOCOL_YAML, plan_id=plan["id"])
    with pytest.raises(PermissionDenied):
        record.end_plan(people.viewer, code, plan["id"])


def test_sessions_over_a_date_range(record, people, clock):
    code = _patient(record, people)
    other = _patient(record, people)
    record.set_limits(people.clinician, code)
    record.set_limits(people.clinician, other)
    uids = []
    for day in range(5):
        clock.now = dt.datetime(2026, 4, 1 + day, 10, tzinfo=dt.timezone.utc)
        uids.append(record.start_session(people.clinician, code, PROTOCOL_YAML)["uid"])
        record.start_session(people.clinician, other, PROTOCOL_YAML)
    got = record.list_sessions(people.viewer, code,
                               since=dt.datetime(2026, 4, 2, tzinfo=dt.timezone.utc),
                               until=dt.datetime(2026, 4, 4, tzinfo=dt.timezone.utc), full=True)
    assert [s["uid"] for s in got] == uids[1:3]
    assert all(s["limits"] and s["patient"] == code for s in got)
    assert len(record.list_sessions(people.viewer)) == 10


def test_a_protocol_that_fails_validation_is_not_stored(record, people):
    code = _patient(record, people)
    record.set_limits(people.clinician, code)
    from rt.errors import ProtocolValidationError
    with pytest.raises(ProtocolValidationError):
        record.assign_plan(people.clinician, code, "kind: nonsense\n")
    with pytest.raises(ProtocolValidationError):
        record.start_session(people.clinician, code, "schema_version: 1\n")
    assert record.plans(people.clinician, code) == []
    assert record.list_sessions(people.clinician) == []


def test_calibration_records_round_trip(record, people):
    rec = {"schema_version": 1, "kind": "talus.calibration_record", "id": "CAL-0001",
           "created_utc": "2026-11-23T17:00:00Z", "operator": "engineer",
           "plate": {"name": "AMTI OR6-7", "serial": "SN123"},
           "matrix": {"cal_matrix": [[1.0 if i == j else 0.0 for j in range(6)]
                                     for i in range(6)]},
           "metrics": {"linear": {"cop_rms_mm": 1.2}}, "verdict": {"pass": True}}
    with pytest.raises(PermissionDenied):
        record.add_calibration(people.clinician, rec)
    stored = record.add_calibration(people.engineer, rec, certificate_path="out/cal.pdf")
    assert stored["passed"] is True and stored["created_at"] == "2026-11-23T17:00:00+00:00"
    with pytest.raises(AlreadyExists):
        record.add_calibration(people.engineer, rec)
    assert [c["record_id"] for c in record.list_calibrations(people.viewer, "SN123")] == ["CAL-0001"]
    assert record.list_calibrations(people.viewer, "other") == []
    full = record.get_calibration(people.viewer, "CAL-0001")
    assert full["record"] == rec and full["matrix"] == rec["matrix"]
    with pytest.raises(InputError, match="schema_version"):
        record.add_calibration(people.engineer, {**rec, "id": "CAL-2", "schema_version": 9})


def test_users_change_their_own_password_only_with_the_current_one(record, people):
    with pytest.raises(AuthenticationFailed, match="current password is wrong"):
        record.set_password(people.viewer, "viewer", "a new password 22", old_password="nope")
    with pytest.raises(PermissionDenied, match="users.manage"):
        record.set_password(people.viewer, "clinician", "a new password 22")
    with pytest.raises(InputError, match="at least 10"):
        record.set_password(people.viewer, "viewer", "short", old_password=PASSWORD)
    record.set_password(people.viewer, "viewer", "a new password 22", old_password=PASSWORD)
    with pytest.raises(AuthenticationFailed):
        record.authenticate("viewer", PASSWORD)
    record.authenticate("viewer", "a new password 22")


def test_a_taken_code_is_refused_clearly(record, people):
    record.add_patient(people.clinician, "KNEE-1")
    with pytest.raises(AlreadyExists, match="taken"):
        record.add_patient(people.clinician, "KNEE-1")
