"""Clinical-record figures (issue 11): time to list 10 000 sessions, database size per 1 000
sessions, on SQLite and on PostgreSQL.

Run:  .venv/bin/python bench/patients.py [--sessions 10000] [--pg-url URL] [--json]

* Size: 1 000 sessions stored through the service layer as the product stores them (start +
  finish: protocol YAML and limits snapshots, a summary like protocols/session.py's, the
  recording path and sha256, and their two audit entries); the database's growth is divided
  by 1 000. SQLite: the file after a WAL checkpoint. PostgreSQL: pg_database_size.
* Listing: the table is then filled to ``--sessions`` rows (bulk insert, same row content) and
  ``ClinicalRecord.list_sessions`` (all patients, without and with summaries) is timed, median
  of 5 runs after one warm-up.
Without --pg-url a throw-away PostgreSQL server is started (tests/pg_server.py, ≈ 2 s).
Numbers vary ±30 % on these shared VMs (PLATFORM.md).
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import statistics
import sys
import tempfile
import time
import uuid
from pathlib import Path

import sqlalchemy as sa
from argon2 import PasswordHasher

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from patients import db as dbmod  # noqa: E402
from patients.models import Outcome, TherapySession  # noqa: E402
from patients.service import ClinicalRecord  # noqa: E402

PROTOCOL = (ROOT / "protocols" / "library" / "ankle_rom.yaml").read_text()
SUMMARY = {"protocol": "Ankle passive ROM ±10° / ±8°", "kind": "ankle_rom", "twin": True,
           "rms_error_pct": None, "peak_force_n": 212.4,
           "rom_deg": {"roll": [-8.02, 8.01], "pitch": [-10.03, 10.02]},
           "stops": [], "completed": True,
           "preflight": {"duration_s": 64.0, "peak_actuator_force_n": 480.2,
                         "peak_slider_speed_m_s": 0.021,
                         "platform_angles_deg": {"roll": [-8.0, 8.0], "pitch": [-10.0, 10.0]},
                         "peak_platform_force_n": 210.0, "rms_error_pct": None},
           "recording": {"path": "recordings/2026-03-02/P7K3M9QX-0001.mcap",
                         "sha256": "ab" * 32}}
SIZE_SESSIONS = 1000


class Clock:
    def __init__(self) -> None:
        self.now = dt.datetime(2026, 1, 5, 8, tzinfo=dt.timezone.utc)

    def __call__(self) -> dt.datetime:
        self.now += dt.timedelta(minutes=7)
        return self.now


def _size(record: ClinicalRecord) -> int:
    path = dbmod.sqlite_file(record.engine.url)
    if path is not None:
        raw = record.engine.raw_connection()
        try:
            raw.driver_connection.execute("PRAGMA wal_checkpoint(TRUNCATE)")  # type: ignore[union-attr]
        finally:
            raw.close()
        return path.stat().st_size
    with record.engine.connect() as conn:
        return int(conn.execute(sa.text("SELECT pg_database_size(current_database())"))
                   .scalar_one())


def measure(url: str, n_sessions: int) -> dict:
    record = ClinicalRecord.open(url, create=True, clock=Clock(),
                                 hasher=PasswordHasher(time_cost=1, memory_cost=1024,
                                                       parallelism=1))
    try:
        admin = record.init_admin("admin", "bench password 1")
        record.add_user(admin, "ana", "clinician", "bench password 2")
        me = record.authenticate("ana", "bench password 2")
        codes = [record.add_patient(me, body_mass_kg=70 + i)["code"] for i in range(20)]
        for code in codes:
            record.set_limits(me, code)
        base = _size(record)
        for i in range(SIZE_SESSIONS):
            s = record.start_session(me, codes[i % len(codes)], PROTOCOL)
            record.finish_session(me, s["uid"], Outcome.COMPLETED, summary=SUMMARY,
                                  recording_path=SUMMARY["recording"]["path"],
                                  recording_sha256=SUMMARY["recording"]["sha256"])
        per_1000 = (_size(record) - base) * 1000 / SIZE_SESSIONS
        # Fill to n_sessions with the same content (bulk insert; no audit entries).
        with record.engine.begin() as conn:
            ids = conn.execute(sa.text("SELECT id FROM patients")).scalars().all()
            template = conn.execute(sa.select(TherapySession.__table__).limit(1)).mappings().one()
            start = dt.datetime(2026, 6, 1, tzinfo=dt.timezone.utc)
            rows = []
            for i in range(n_sessions - SIZE_SESSIONS):
                row = {k: v for k, v in template.items() if k != "id"}
                row.update(uid=str(uuid.uuid4()), patient_id=ids[i % len(ids)],
                           started_at=start + dt.timedelta(minutes=7 * i),
                           ended_at=start + dt.timedelta(minutes=7 * i + 5))
                rows.append(row)
            if rows:
                conn.execute(sa.insert(TherapySession.__table__), rows)
        timings = {}
        for full in (False, True):
            record.list_sessions(me, full=full)  # warm-up
            runs = []
            for _ in range(5):
                t0 = time.perf_counter()
                got = record.list_sessions(me, full=full)
                runs.append(time.perf_counter() - t0)
            assert len(got) == n_sessions
            timings["list_full_s" if full else "list_s"] = statistics.median(runs)
        return {"backend": record.engine.dialect.name, "sessions": n_sessions,
                **timings, "bytes_per_1000_sessions": per_1000}
    finally:
        record.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sessions", type=int, default=10_000)
    ap.add_argument("--pg-url", default=None, help="an empty PostgreSQL database to use")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        results.append(measure(str(Path(tmp) / "bench.db"), args.sessions))
    server = None
    pg_url = args.pg_url
    if pg_url is None:
        sys.path.insert(0, str(ROOT / "tests"))
        from pg_server import PostgresServer
        server = PostgresServer()
        server.start()
        pg_url = server.create_database()
    try:
        results.append(measure(pg_url, args.sessions))
    finally:
        if server is not None:
            server.stop()
    if args.json:
        print(json.dumps(results))
        return 0
    print(f"clinical record: {args.sessions} sessions (list = ClinicalRecord.list_sessions, "
          "median of 5)")
    print(f"{'backend':12s} {'list':>10s} {'list+summaries':>15s} {'size per 1000 sessions':>24s}")
    for r in results:
        print(f"{r['backend']:12s} {r['list_s'] * 1e3:8.0f} ms {r['list_full_s'] * 1e3:12.0f} ms "
              f"{r['bytes_per_1000_sessions'] / 1e6:20.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
