"""The clinical-record CLI (`talus db|users|patients|sessions|audit`), in process, on SQLite and
PostgreSQL: exit codes, one-line errors, --json, non-interactive passwords."""
from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest
import sqlalchemy as sa

from talus.cli import main

from patients_helpers import PROTOCOL, fast_hasher

ADMIN_PW, CLIN_PW = "admin password 1", "clinician password 1"


@pytest.fixture(autouse=True)
def _fast_argon2(monkeypatch):
    # Argon2id still; cheap parameters so a CLI test logs in many times quickly.
    monkeypatch.setattr("patients.passwords.default_hasher", fast_hasher)
    for var in ("TALUS_PASSWORD", "TALUS_NEW_PASSWORD", "TALUS_USER", "TALUS_DATABASE_URL"):
        monkeypatch.delenv(var, raising=False)


def run(capsys, *argv: str, password: str | None = None, new: str | None = None):
    """Run talus in process; returns (exit code, stdout, stderr)."""
    env = {"TALUS_PASSWORD": password, "TALUS_NEW_PASSWORD": new}
    old = {k: os.environ.get(k) for k in env}
    try:
        for k, v in env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        code = main(list(argv))
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture()
def clinic(database_url, capsys):
    """A database with admin 'root' and clinician 'ana'."""
    assert run(capsys, "users", "init", "--db", database_url, "--user", "root",
               password=ADMIN_PW)[0] == 0
    assert run(capsys, "users", "add", "ana", "--role", "clinician", "--db", database_url,
               "--user", "root", password=ADMIN_PW, new=CLIN_PW)[0] == 0
    return database_url


def test_users_init_is_non_interactive_once_and_needs_a_password(database_url, capsys):
    code, out, err = run(capsys, "users", "init", "--db", database_url, "--user", "root")
    assert code == 2 and "TALUS_PASSWORD" in err and len(err.strip().splitlines()) == 1
    code, out, _ = run(capsys, "users", "init", "--db", database_url, "--user", "root",
                       "--json", password=ADMIN_PW)
    assert code == 0 and json.loads(out)["admin"] == "root"
    code, out, _ = run(capsys, "users", "init", "--db", database_url, "--user", "eve",
                       "--json", password="another password")
    assert code == 2 and "already has users" in json.loads(out)["error"]


def test_a_clinical_workflow_through_the_cli(clinic, capsys):
    db = ["--db", clinic, "--json"]
    code, out, _ = run(capsys, "patients", "add", "--mass-kg", "68", "--side", "left",
                       "--name", "Lucía Fernández", "--birth-date", "1975-09-09", "--user",
                       "ana", *db, password=CLIN_PW)
    assert code == 0
    pid = json.loads(out)["code"]
    code, out, _ = run(capsys, "patients", "limits", pid, "--dorsiflexion", "12",
                       "--plantarflexion", "25", "--inversion", "15", "--eversion", "6",
                       "--max-force-n", "450", "--reason", "week 1", "--user", "ana", *db,
                       password=CLIN_PW)
    lim = json.loads(out)
    # Left foot: +roll is eversion (patients/anatomy.py).
    assert (lim["roll_min_deg"], lim["roll_max_deg"]) == (-15, 6)
    assert (lim["pitch_min_deg"], lim["pitch_max_deg"], lim["max_force_n"]) == (-12, 25, 450)
    assert run(capsys, "patients", "plan", pid, "--protocol", PROTOCOL, "--user", "ana", *db,
               password=CLIN_PW)[0] == 0
    code, out, _ = run(capsys, "patients", "show", pid, "--identity", "--user", "ana", *db,
                       password=CLIN_PW)
    shown = json.loads(out)
    assert shown["identity"]["full_name"] == "Lucía Fernández" and len(shown["plans"]) == 1
    code, out, _ = run(capsys, "patients", "list", "--user", "ana", *db, password=CLIN_PW)
    assert [p["code"] for p in json.loads(out)] == [pid] and "Lucía" not in out
    # Refusals are one line with exit code 2, and change nothing.
    code, out, _ = run(capsys, "patients", "forget", pid, "--yes", "--user", "ana", *db,
                       password=CLIN_PW)
    assert code == 2 and "may not patient.forget" in json.loads(out)["error"]
    code, out, _ = run(capsys, "patients", "limits", pid, "--pitch-min-deg", "40", "--user",
                       "ana", *db, password=CLIN_PW)
    assert code == 2 and "pitch_min_deg must be below" in json.loads(out)["error"]
    code, _, err = run(capsys, "patients", "list", "--db", clinic, "--user", "ana",
                       password="wrong password")
    assert code == 2 and err.strip() == "error: wrong user name or password"
    code, out, _ = run(capsys, "patients", "forget", pid, "--user", "root", *db,
                       password=ADMIN_PW)
    assert code == 2 and "--yes" in json.loads(out)["error"]
    assert run(capsys, "patients", "forget", pid, "--yes", "--user", "root", *db,
               password=ADMIN_PW)[0] == 0
    code, out, _ = run(capsys, "sessions", "list", "--patient", pid, "--since", "2020-01-01",
                       "--user", "ana", *db, password=CLIN_PW)
    assert code == 0 and json.loads(out) == []
    code, out, _ = run(capsys, "audit", "verify", "--user", "root", *db, password=ADMIN_PW)
    assert code == 0 and json.loads(out)["ok"]


def test_audit_verify_exits_nonzero_on_a_tampered_log(clinic, capsys):
    from patients import db as dbmod
    engine = dbmod.create_engine(dbmod.resolve_url(clinic))
    with engine.begin() as conn:
        if conn.dialect.name == "sqlite":
            conn.exec_driver_sql("DROP TRIGGER audit_log_no_update")
        else:
            conn.exec_driver_sql("ALTER TABLE audit_log DISABLE TRIGGER USER")
        conn.execute(sa.text("UPDATE audit_log SET after = '{}' WHERE seq = 2"))
    engine.dispose()
    code, out, _ = run(capsys, "audit", "verify", "--db", clinic, "--user", "root",
                       password=ADMIN_PW)
    assert code == 1 and "AUDIT LOG BROKEN" in out and "entry 2" in out


def test_export_refuses_to_overwrite_and_import_round_trips(clinic, capsys, tmp_path):
    db = ["--db", clinic, "--user", "ana"]
    code, out, _ = run(capsys, "patients", "add", "--code", "KNEE-7", "--mass-kg", "90", *db,
                       "--json", password=CLIN_PW)
    out_file = tmp_path / "knee7.json"
    out_file.write_text("precious")
    code, _, err = run(capsys, "patients", "export", "KNEE-7", "--out", str(out_file), *db,
                       password=CLIN_PW)
    assert code == 2 and "exists" in err and out_file.read_text() == "precious"
    assert run(capsys, "patients", "export", "KNEE-7", "--out", str(out_file), "--force", *db,
               password=CLIN_PW)[0] == 0
    assert stat.S_IMODE(out_file.stat().st_mode) == 0o600
    other = str(tmp_path / "other.db")
    run(capsys, "users", "init", "--db", other, "--user", "root", password=ADMIN_PW)
    code, out, _ = run(capsys, "patients", "import", str(out_file), "--db", other, "--user",
                       "root", "--json", password=ADMIN_PW)
    assert code == 0 and json.loads(out)["code"] == "KNEE-7" and json.loads(out)["body_mass_kg"] == 90


def test_db_backup_and_restore_on_sqlite_and_the_postgresql_hint(clinic, capsys, tmp_path):
    admin = ["--db", clinic, "--user", "root"]
    out_file = tmp_path / "backup.db"
    code, out, err = run(capsys, "db", "backup", "--out", str(out_file), *admin,
                         password=ADMIN_PW)
    if clinic.startswith("postgresql"):
        assert code == 2 and "pg_dump" in err and not out_file.exists()
        return
    assert code == 0 and out_file.exists()
    run(capsys, "patients", "add", "--code", "AFTER-1", "--db", clinic, "--user", "ana",
        password=CLIN_PW)
    code, _, err = run(capsys, "db", "restore", str(out_file), *admin, password=ADMIN_PW)
    assert code == 2 and "--force" in err
    assert run(capsys, "db", "restore", str(out_file), "--force", *admin,
               password=ADMIN_PW)[0] == 0
    code, out, _ = run(capsys, "patients", "list", "--json", "--db", clinic, "--user", "ana",
                       password=CLIN_PW)
    assert json.loads(out) == []  # AFTER-1 came after the backup


def test_db_demo_is_idempotent_and_keeps_its_password_private(tmp_path, capsys):
    db = str(tmp_path / "demo" / "talus.db")
    code, out, _ = run(capsys, "db", "demo", "--db", db, "--json")
    first = json.loads(out)
    assert code == 0 and first["created"] == ["demo-admin", "demo-clinician", "DEMO-001"]
    creds = Path(db).parent / "talus-demo-credentials.json"
    assert stat.S_IMODE(creds.stat().st_mode) == 0o600
    password = json.loads(creds.read_text())["password"]
    code, out, _ = run(capsys, "db", "demo", "--db", db, "--json")
    assert code == 0 and json.loads(out)["created"] == []
    code, out, _ = run(capsys, "patients", "show", "DEMO-001", "--db", db, "--user",
                       "demo-clinician", "--json", password=password)
    assert json.loads(out)["limits"]["max_force_n"] == 1200
    run(capsys, "users", "add", "real-user", "--role", "viewer", "--db", db, "--user",
        "demo-admin", password=password, new="a real password 1")
    code, _, err = run(capsys, "db", "demo", "--db", db)
    assert code == 2 and "other users" in err


def test_a_missing_database_is_not_created_by_a_read(tmp_path, capsys):
    db = tmp_path / "nothing.db"
    code, _, err = run(capsys, "patients", "list", "--db", str(db), "--user", "ana",
                       password=CLIN_PW)
    assert code == 2 and "no database" in err and not db.exists()


def test_db_upgrade_creates_then_finds_nothing_to_do(tmp_path, capsys):
    db = str(tmp_path / "new.db")
    code, out, _ = run(capsys, "db", "upgrade", "--db", db, "--json")
    assert code == 0 and json.loads(out)["from"] is None and json.loads(out)["to"]
    code, out, _ = run(capsys, "db", "upgrade", "--db", db, "--json")
    head = json.loads(out)["to"]
    assert code == 0 and json.loads(out)["from"] == head
    assert stat.S_IMODE(Path(db).stat().st_mode) == 0o600


def test_users_list_disable_and_the_audit_anchor(clinic, capsys):
    admin = ["--db", clinic, "--user", "root", "--json"]
    code, out, _ = run(capsys, "users", "list", *admin, password=ADMIN_PW)
    assert [(u["username"], u["role"]) for u in json.loads(out)] == [("ana", "clinician"),
                                                                    ("root", "admin")]
    assert "password" not in out  # no hash leaves the service
    assert run(capsys, "users", "disable", "ana", *admin, password=ADMIN_PW)[0] == 0
    code, _, err = run(capsys, "patients", "list", "--db", clinic, "--user", "ana",
                       password=CLIN_PW)
    assert code == 2
    code, out, _ = run(capsys, "users", "list", "--db", clinic, "--user", "ana", "--json",
                       password=CLIN_PW)
    assert code == 2
    code, out, _ = run(capsys, "audit", "verify", *admin, password=ADMIN_PW)
    head = json.loads(out)["head"]
    code, out, _ = run(capsys, "audit", "verify", "--anchor", head, *admin, password=ADMIN_PW)
    assert code == 0 and json.loads(out)["ok"]
    code, out, _ = run(capsys, "audit", "verify", "--anchor", "999999:" + "0" * 64, *admin,
                       password=ADMIN_PW)
    assert code == 1 and "anchor entry 999999" in json.loads(out)["problems"][-1]


def test_sessions_list_and_show(clinic, capsys):
    from patients.service import ClinicalRecord
    record = ClinicalRecord.open(clinic)
    try:
        me = record.authenticate("ana", CLIN_PW)
        code = record.add_patient(me, body_mass_kg=64)["code"]
        record.set_limits(me, code)
        uid = record.start_session(me, code, Path(PROTOCOL).read_text())["uid"]
        record.finish_session(me, uid, "stopped_by_user", stopped_by="patient: hand_stop",
                              summary={"completed": False, "peak_force_n": 120.5})
    finally:
        record.close()
    db = ["--db", clinic, "--user", "ana"]
    code_, out, _ = run(capsys, "sessions", "list", "--full", "--json", *db, password=CLIN_PW)
    [listed] = json.loads(out)
    assert listed["uid"] == uid and listed["summary"]["peak_force_n"] == 120.5
    code_, out, _ = run(capsys, "sessions", "show", uid, *db, password=CLIN_PW)
    assert code_ == 0 and "stopped_by_user" in out and "patient: hand_stop" in out
    assert "peak_force_n=120.5" in out
    code_, _, err = run(capsys, "sessions", "list", "--since", "yesterday", *db,
                        password=CLIN_PW)
    assert code_ == 2 and "--since 'yesterday'" in err
