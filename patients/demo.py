"""The demo clinic (``talus db demo``): one admin, one clinician, one patient with limits.

Idempotent: run it twice and the second run finds everything in place. It refuses a database
with other users (a real clinic's). There is no default password: the demo accounts get
$TALUS_PASSWORD if set, else a random password written to a 0600 file next to the database
(SQLite) or in the current directory (PostgreSQL); that file is never overwritten.
"""
from __future__ import annotations

import json
import os
import secrets
from pathlib import Path
from typing import Any

from patients import db as dbmod
from patients.errors import RecordError
from patients.service import ClinicalRecord

ADMIN, CLINICIAN, PATIENT = "demo-admin", "demo-clinician", "DEMO-001"
DEMO_PATIENT: dict[str, Any] = {"body_mass_kg": 75.0, "height_m": 1.75, "affected_side": "right",
                "diagnosis": "lateral ankle sprain, grade II (demo)"}
#: Wider than the shipped protocols need (ankle_rom: ±10° pitch, ±8° roll).
DEMO_LIMITS = {"roll_min_deg": -12.0, "roll_max_deg": 12.0, "pitch_min_deg": -15.0,
               "pitch_max_deg": 15.0, "max_force_n": 1200.0, "max_angular_speed_deg_s": 60.0,
               "rom_tolerance_deg": 0.5}


def credentials_file(record: ClinicalRecord) -> Path:
    path = dbmod.sqlite_file(record.engine.url)
    return (path.parent if path else Path.cwd()) / "talus-demo-credentials.json"


def _password(record: ClinicalRecord) -> tuple[str, Path | None]:
    if os.environ.get("TALUS_PASSWORD"):
        return os.environ["TALUS_PASSWORD"], None
    file = credentials_file(record)
    if file.exists():
        return str(json.loads(file.read_text())["password"]), file
    password = secrets.token_urlsafe(18)
    fd = os.open(file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        json.dump({"users": [ADMIN, CLINICIAN], "password": password}, f)
    return password, file


def ensure_demo(record: ClinicalRecord) -> dict[str, Any]:
    """Create what is missing of the demo clinic; returns who/what and where the password is."""
    from patients.models import User
    import sqlalchemy as sa
    with record._tx() as db:
        users = set(db.execute(sa.select(User.username)).scalars())
    if users - {ADMIN, CLINICIAN}:
        raise RecordError("this database has other users: `talus db demo` only fills a new or "
                          "demo database (use another --db)")
    password, file = _password(record)
    created: list[str] = []
    if ADMIN not in users:
        admin = record.init_admin(ADMIN, password)
        created.append(ADMIN)
    else:
        admin = record.authenticate(ADMIN, password)
    if CLINICIAN not in users:
        record.add_user(admin, CLINICIAN, "clinician", password)
        created.append(CLINICIAN)
    clinician = record.authenticate(CLINICIAN, password)
    codes = {p["code"] for p in record.list_patients(clinician)}
    if PATIENT not in codes:
        record.add_patient(clinician, PATIENT, **DEMO_PATIENT)
        record.set_limits(clinician, PATIENT, reason="demo prescription", **DEMO_LIMITS)
        created.append(PATIENT)
    return {"database": dbmod.describe(record.engine.url), "admin": ADMIN,
            "clinician": CLINICIAN, "patient": PATIENT, "created": created,
            "password": "from TALUS_PASSWORD" if file is None else f"in {file}"}
