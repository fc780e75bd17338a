"""Roles, GDPR erasure, audit tamper detection, concurrent writers, migrations, backup and
import/export of the clinical record, on SQLite and on a real PostgreSQL server."""
from __future__ import annotations

import copy
import datetime as dt
import itertools
import threading
from pathlib import Path

import pytest
import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy.orm import Session

from patients import backup, db as dbmod
from patients.errors import AlreadyExists, ConcurrentUpdate, InputError, PermissionDenied
from patients.models import Base, Patient
from patients.roles import PERMISSIONS, Action, Role, allowed, roles_markdown
from patients.service import Identity

from patients_helpers import PASSWORD, PROTOCOL, Clock, open_record, staff

ROOT = Path(__file__).resolve().parents[1]
YAML = (ROOT / PROTOCOL).read_text()
NAME, NATIONAL_ID = "Bartolomé Zurbarán-Quintanilla", "98765432X"


@pytest.fixture()
def record(database_url):
    rec = open_record(database_url)
    yield rec
    rec.close()


@pytest.fixture()
def people(record):
    return staff(record)


def _populated(record, people) -> str:
    code = record.add_patient(people.clinician, identity=Identity(NAME, dt.date(1950, 1, 31),
                                                                   NATIONAL_ID, "calle Mayor 1"),
                              body_mass_kg=81, affected_side="right", diagnosis="TKA rehab")["code"]
    record.set_limits(people.clinician, code, pitch_min_deg=-10, pitch_max_deg=10)
    record.assign_plan(people.clinician, code, YAML)
    s = record.start_session(people.clinician, code, YAML)
    record.finish_session(people.clinician, s["uid"], "completed", summary={"completed": True},
                          recording_path="out/a.mcap", recording_sha256="b" * 64)
    return code


# ------------------------------------------------------------------ roles

def _calibration(n: int) -> dict:
    return {"schema_version": 1, "kind": "talus.calibration_record", "id": f"CAL-{n}",
            "created_utc": "2026-11-23T17:00:00Z", "operator": "engineer",
            "plate": {"name": "plate", "serial": "S1"}, "matrix": {}, "metrics": {}}


def test_every_role_is_allowed_and_refused_exactly_what_the_table_says(record, people):
    code = _populated(record, people)
    export = record.export_patient(people.clinician, code)
    n = itertools.count()
    act = {
        Action.USERS_MANAGE: lambda a: record.list_users(a),
        Action.PATIENT_CREATE: lambda a: record.add_patient(a),
        Action.PATIENT_READ: lambda a: record.get_patient(a, code),
        Action.PATIENT_UPDATE: lambda a: record.update_patient(a, code, notes="seen"),
        Action.IDENTITY_READ: lambda a: record.get_patient(a, code, include_identity=True),
        Action.IDENTITY_WRITE: lambda a: record.set_identity(a, code, Identity(NAME)),
        Action.PATIENT_FORGET: lambda a: record.forget_patient(
            a, record.add_patient(people.clinician)["code"]),
        Action.LIMITS_SET: lambda a: record.set_limits(a, code, max_force_n=500),
        Action.PLAN_ASSIGN: lambda a: record.assign_plan(a, code, YAML),
        Action.SESSION_RUN: lambda a: record.start_session(a, code, YAML),
        Action.SESSION_READ: lambda a: record.list_sessions(a),
        Action.RECORD_EXPORT: lambda a: record.export_patient(a, code),
        Action.RECORD_IMPORT: lambda a: record.import_patient(a, {
            **export, "patient": {**export["patient"], "code": f"IMP-{next(n)}"},
            "sessions": []}),
        Action.CALIBRATION_WRITE: lambda a: record.add_calibration(a, _calibration(next(n))),
        Action.CALIBRATION_READ: lambda a: record.list_calibrations(a),
        Action.AUDIT_READ: lambda a: record.verify_audit(a),
        Action.DATABASE_ADMIN: lambda a: record.note_database_action(a, "db.backup", {}),
    }
    assert set(act) == set(Action), "every action needs its line here"
    outcomes = {}
    for action, call in act.items():
        for role in Role:
            try:
                call(people.by_role(role.value))
                outcomes[action, role] = True
            except PermissionDenied as exc:
                assert action.value in str(exc) and role.value in str(exc)
                outcomes[action, role] = False
    assert outcomes == {(a, r): allowed(r, a) for a in Action for r in Role}
    # Sanity of the table itself: identifying data stays with admin and clinician.
    assert PERMISSIONS[Action.IDENTITY_READ][0] == {Role.ADMIN, Role.CLINICIAN}


def test_docs_roles_table_is_the_enforced_table():
    assert roles_markdown() in (ROOT / "docs" / "roles.md").read_text()


# ------------------------------------------------------------------ GDPR erasure

def _files_mention(url: str, needles: list[str]) -> list[str]:
    path = dbmod.sqlite_file(dbmod.resolve_url(url))
    assert path is not None
    found = []
    for f in path.parent.glob(path.name + "*"):
        data = f.read_bytes()
        found += [f"{f.name}: {n}" for n in needles if n.encode() in data]
    return found


def test_forget_erases_identity_everywhere_and_keeps_the_history(record, people, database_url,
                                                                 request):
    code = _populated(record, people)
    record.get_patient(people.clinician, code, include_identity=True)
    needles = [NAME, "Zurbar", NATIONAL_ID, "calle Mayor"]
    is_pg = database_url.startswith("postgresql")
    dump = (lambda: request.getfixturevalue("postgres").pg_dump(database_url)) if is_pg else None
    before = dump() if dump else " ".join(_files_mention(database_url, needles))
    assert NATIONAL_ID in before  # the search can find it: the test can fail
    with pytest.raises(PermissionDenied):
        record.forget_patient(people.clinician, code)
    assert record.forget_patient(people.admin, code) == {"code": code, "identity_erased": True,
                                                         "storage_scrubbed": True}
    if dump:
        after = dump()
        assert [n for n in needles if n in after] == []
    else:
        assert _files_mention(database_url, needles) == []
    shown = record.get_patient(people.clinician, code, include_identity=True)
    assert shown["identity"] is None and shown["forgotten_at"] is not None
    assert shown["diagnosis"] == "TKA rehab" and shown["limits"]["pitch_max_deg"] == 10
    assert len(record.list_sessions(people.clinician, code)) == 1
    with pytest.raises(InputError, match="forgotten"):
        record.set_identity(people.clinician, code, Identity(NAME))
    assert record.verify_audit(people.admin).ok


# ------------------------------------------------------------------ audit chain

def _drop_append_only_triggers(conn: sa.Connection) -> None:
    if conn.dialect.name == "sqlite":
        conn.exec_driver_sql("DROP TRIGGER audit_log_no_update")
        conn.exec_driver_sql("DROP TRIGGER audit_log_no_delete")
    else:
        conn.exec_driver_sql("ALTER TABLE audit_log DISABLE TRIGGER USER")


def test_the_database_refuses_changes_to_the_audit_log(record, people):
    _populated(record, people)
    for sql in ("UPDATE audit_log SET username = 'x' WHERE seq = 2",
                "DELETE FROM audit_log WHERE seq = 2", "DELETE FROM audit_head"):
        with pytest.raises(sa.exc.DatabaseError, match="append-only"):
            with record.engine.begin() as conn:
                conn.exec_driver_sql(sql)
    assert record.verify_audit(people.admin).ok


@pytest.mark.parametrize("tamper, expected", [
    ("UPDATE audit_log SET username = 'mallory' WHERE seq = 3",
     "entry 3: its content does not match its hash"),
    ("DELETE FROM audit_log WHERE seq = 4", "entries 4 missing"),
    ("DELETE FROM audit_log WHERE seq >= (SELECT MAX(seq) - 1 FROM audit_log)",
     "entries at the end were deleted"),
    ("rehash 3", "entry 4: does not link"),
])
def test_audit_verify_detects_direct_tampering(record, people, tamper, expected):
    _populated(record, people)
    assert record.verify_audit(people.admin).ok
    with record.engine.begin() as conn:
        _drop_append_only_triggers(conn)
        if tamper.startswith("rehash"):
            # A careful forger edits a row and recomputes its hash: the next link breaks.
            from patients.audit import row_hash
            row = conn.execute(sa.text("SELECT * FROM audit_log WHERE seq = 3")).mappings().one()
            fields = {**row, "username": "mallory"}
            conn.execute(sa.text("UPDATE audit_log SET username = 'mallory', hash = :h "
                                 "WHERE seq = 3"), {"h": row_hash(row["prev_hash"], fields)})
        else:
            conn.exec_driver_sql(tamper)
    result = record.verify_audit(people.admin)
    assert not result.ok
    assert any(expected in p for p in result.problems), result.problems


def test_an_anchor_kept_outside_catches_a_chain_rewritten_whole(record, people):
    _populated(record, people)
    anchor = record.verify_audit(people.admin).head
    seq, digest = anchor.split(":")
    assert int(seq) == record.verify_audit(people.admin).entries and len(digest) == 64
    with record.engine.begin() as conn:
        _drop_append_only_triggers(conn)
        conn.exec_driver_sql("DELETE FROM audit_log")
        conn.execute(sa.text("UPDATE audit_head SET seq = 0, hash = :g"), {"g": "0" * 64})
    assert record.verify_audit(people.admin).ok  # an empty chain is self-consistent...
    result = record.verify_audit(people.admin, anchor)  # ...but not the one noted
    assert not result.ok and f"anchor entry {seq} is not in the chain" in result.problems[0]
    with pytest.raises(InputError, match="SEQ:HASH"):
        record.verify_audit(people.admin, "12:abc")


# ------------------------------------------------------------------ concurrency

def test_two_writers_never_lose_an_update(database_url):
    first = open_record(database_url)
    people = staff(first)
    code = first.add_patient(people.clinician, notes="")["code"]
    second = open_record(database_url)  # its own engine: its own connections
    try:
        me2 = second.authenticate("clinician", PASSWORD)
        # A form opened on two workstations: the second save names the version it edited.
        seen1 = first.get_patient(people.clinician, code)
        seen2 = second.get_patient(me2, code)
        first.update_patient(people.clinician, code, seen1["version"], diagnosis="A")
        with pytest.raises(ConcurrentUpdate, match="changed by someone else"):
            second.update_patient(me2, code, seen2["version"], diagnosis="B")
        assert first.get_patient(people.clinician, code)["diagnosis"] == "A"

        # Both append lines at once, each retrying on conflict: every line arrives.
        def writer(rec, actor, tag):
            for i in range(12):
                while True:
                    p = rec.get_patient(actor, code)
                    try:
                        rec.update_patient(actor, code, p["version"],
                                           notes=p["notes"] + f"{tag}{i}\n")
                        break
                    except ConcurrentUpdate:
                        continue
        threads = [threading.Thread(target=writer, args=(first, people.clinician, "a")),
                   threading.Thread(target=writer, args=(second, me2, "b"))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        lines = first.get_patient(people.clinician, code)["notes"].split()
        assert sorted(lines) == sorted([f"a{i}" for i in range(12)] + [f"b{i}" for i in range(12)])
        assert first.verify_audit(people.admin).ok  # the chain did not fork
    finally:
        second.close()
        first.close()


def test_the_orm_refuses_a_stale_row_inside_racing_transactions(database_url):
    """Two transactions read the same version; the second UPDATE finds it gone (PostgreSQL
    runs both at once; SQLite's BEGIN IMMEDIATE makes the second wait, which also loses
    nothing, so there only the first half applies)."""
    rec = open_record(database_url)
    people = staff(rec)
    code = rec.add_patient(people.clinician)["code"]
    rec.close()
    url = dbmod.resolve_url(database_url)
    e1, e2 = dbmod.create_engine(url), dbmod.create_engine(url)
    try:
        if url.get_backend_name() != "postgresql":
            return
        from sqlalchemy.orm.exc import StaleDataError
        with Session(e1) as s1, Session(e2) as s2:
            p1 = s1.execute(sa.select(Patient).where(Patient.code == code)).scalar_one()
            p2 = s2.execute(sa.select(Patient).where(Patient.code == code)).scalar_one()
            p1.notes = "one"
            s1.commit()
            p2.notes = "two"
            with pytest.raises(StaleDataError):
                s2.commit()
    finally:
        e1.dispose()
        e2.dispose()


# ------------------------------------------------------------------ migrations

def test_migrations_up_and_down_from_empty_and_models_match(database_url):
    url = dbmod.resolve_url(database_url)
    engine = dbmod.create_engine(url, create=True)
    try:
        assert dbmod.current_revision(engine) is None
        dbmod.upgrade(engine)
        assert dbmod.current_revision(engine) == dbmod.head_revision()
        with engine.connect() as conn:
            diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
        assert diff == []
        dbmod.downgrade(engine, "base")
        assert set(sa.inspect(engine).get_table_names()) == {"alembic_version"}
        dbmod.upgrade(engine, "0001")
        dbmod.upgrade(engine)
        assert set(sa.inspect(engine).get_table_names()) >= {"patients", "audit_log"}
    finally:
        engine.dispose()


def test_an_old_schema_is_refused_until_upgraded(database_url):
    from patients.errors import DatabaseUnavailable
    from patients.service import ClinicalRecord
    engine = dbmod.create_engine(dbmod.resolve_url(database_url), create=True)
    dbmod.upgrade(engine, "0001")
    engine.dispose()
    with pytest.raises(DatabaseUnavailable, match="talus db upgrade"):
        ClinicalRecord.open(database_url)


# ------------------------------------------------------------------ backup, export, import

def _table_rows(url: str) -> dict[str, list]:
    engine = dbmod.create_engine(dbmod.resolve_url(url))
    try:
        with engine.connect() as conn:
            return {t.name: [tuple(r) for r in conn.execute(
                sa.select(t).order_by(*t.primary_key.columns))]
                for t in Base.metadata.sorted_tables}
    finally:
        engine.dispose()


def test_sqlite_backup_then_restore_equals_the_original(tmp_path):
    url = str(tmp_path / "live.db")
    rec = open_record(url)
    people = staff(rec)
    _populated(rec, people)
    original = _table_rows(url)
    copy = tmp_path / "backups" / "talus-backup.db"
    assert backup.backup(Path(url), copy) > 0
    with pytest.raises(InputError, match="exists"):
        backup.backup(Path(url), copy)
    rec.add_patient(people.clinician, body_mass_kg=60)  # work after the backup
    assert _table_rows(url) != original
    backup.restore(copy, Path(url))
    assert _table_rows(url) == original
    assert rec.verify_audit(rec.authenticate("admin", PASSWORD)).ok
    rec.close()
    not_a_db = tmp_path / "x.db"
    not_a_db.write_text("hello")
    with pytest.raises(InputError, match="not an SQLite database"):
        backup.restore(not_a_db, Path(url))


def test_export_then_import_into_another_database(record, people, tmp_path):
    code = _populated(record, people)
    doc = record.export_patient(people.clinician, code)
    assert NAME not in str(doc) and NATIONAL_ID not in str(doc)
    assert doc["recordings"] == [{"session_uid": doc["sessions"][0]["uid"],
                                  "path": "out/a.mcap", "sha256": "b" * 64}]
    other = open_record(str(tmp_path / "other-clinic.db"))
    try:
        admin = other.init_admin("admin", PASSWORD)
        imported = other.import_patient(admin, doc)
        assert imported["code"] == code and imported["limits"]["pitch_max_deg"] == 10
        again = other.export_patient(admin, code)

        def norm(d: dict) -> dict:  # what may differ: who/when exported, local plan ids
            d = copy.deepcopy({k: v for k, v in d.items()
                               if k not in ("exported_at", "exported_by")})
            for plan in d["plans"]:
                plan.pop("id")
            for s in d["sessions"]:
                s.pop("plan_id")
            return d
        assert norm(again) == norm(doc)
        with pytest.raises(AlreadyExists):
            other.import_patient(admin, doc)
        with pytest.raises(InputError, match="patient.body_mass_kg"):
            other.import_patient(admin, {**doc, "patient": {**doc["patient"],
                                                            "body_mass_kg": "heavy"}})
    finally:
        other.close()
