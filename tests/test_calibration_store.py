"""Calibration records in the clinical database: the record ``talus calibrate fit`` writes is
stored whole with its headline figures as columns, audited; its certificate is attached once;
revision 0003_calibration backfills the figures of records stored before it."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
import sqlalchemy as sa
from patients_helpers import PASSWORD, Clock, open_record, staff

from patients import db as dbmod
from patients.calibrations_cli import certificate
from patients.errors import AlreadyExists, InputError, NotFound, PermissionDenied
from patients.service import calibration_figures
from talus.cli import main as talus_main

EXAMPLE = Path(__file__).resolve().parents[1] / "reports" / "data" / \
    "example_calibration_record.json"


@pytest.fixture()
def record(database_url):
    rec = open_record(database_url, Clock())
    yield rec
    rec.close()


def _example() -> dict:
    return json.loads(EXAMPLE.read_text(encoding="utf-8"))


def test_the_fit_record_is_stored_with_its_figures_and_certified_once(record, tmp_path) -> None:
    people = staff(record)
    rec = _example()
    stored = record.add_calibration(people.engineer, rec)
    m = rec["metrics"]["nonlinear"]
    assert stored["figures_stage"] == "nonlinear"
    assert stored["cop_rms_mm"] == m["cop_rms_mm"] and stored["cop_max_mm"] == m["cop_max_mm"]
    assert stored["force_pct_fs"] == max(m["force_pct_fs"][:3])
    assert stored["reference_serial"] == rec["reference_sensor"]["serial"]
    assert stored["plate_serial"] == rec["plate"]["serial"]
    assert stored["certificate_path"] is None
    pdf = tmp_path / "cal.pdf"
    pdf.write_bytes(b"%PDF-1.4 certificate")
    path, digest = certificate(str(pdf))
    with pytest.raises(PermissionDenied):
        record.attach_calibration_certificate(people.clinician, rec["id"], path, digest)
    with pytest.raises(InputError, match="64 lowercase hex"):
        record.attach_calibration_certificate(people.engineer, rec["id"], path, "abc")
    with pytest.raises(NotFound):
        record.attach_calibration_certificate(people.engineer, "CAL-none", path, digest)
    certified = record.attach_calibration_certificate(people.engineer, rec["id"], path, digest)
    assert certified["certificate_path"] == path and certified["certificate_sha256"] == digest
    with pytest.raises(AlreadyExists, match="never replaced"):
        record.attach_calibration_certificate(people.engineer, rec["id"], path, "0" * 64)
    assert record.get_calibration(people.viewer, rec["id"])["certificate_sha256"] == digest
    # Both writes are in the audit log, and the chain still verifies.
    assert record.verify_audit(people.admin).ok
    log = [e for e in record.export_audit(people.admin) if e["entity_key"] == rec["id"]]
    assert [e["action"] for e in log] == ["calibration.add", "calibration.certify"]


def test_figures_of_a_linear_only_or_sparse_record() -> None:
    rec = {"metrics": {"linear": {"cop_rms_mm": 1.5, "force_pct_fs": [0.3, None, 0.2, 9.0]}}}
    assert calibration_figures(rec) == {"reference_serial": None, "cop_rms_mm": 1.5,
                                        "cop_max_mm": None, "force_pct_fs": 0.3,
                                        "figures_stage": "linear"}
    assert calibration_figures({"metrics": "junk"})["figures_stage"] is None


def test_the_migration_backfills_records_stored_before_it(tmp_path) -> None:
    url = dbmod.resolve_url(str(tmp_path / "old.db"))
    engine = dbmod.create_engine(url, create=True)
    try:
        dbmod.upgrade(engine, "0002")
        rec = _example()
        with engine.begin() as conn:
            conn.execute(sa.text(
                "INSERT INTO calibrations (record_id, plate_name, plate_serial, created_at, "
                "operator, passed, matrix, metrics, record, record_sha256, added_by, added_at) "
                "VALUES (:id, 'p', 's', '2026-11-23 17:00:00.000000', 'o', 1, '{}', '{}', "
                ":record, 'x', 'eng', '2026-11-23 17:00:00.000000')"),
                {"id": rec["id"], "record": json.dumps(rec)})
        dbmod.upgrade(engine)
        with engine.connect() as conn:
            row = conn.execute(sa.text("SELECT cop_rms_mm, force_pct_fs, reference_serial, "
                                       "figures_stage FROM calibrations")).one()
        assert tuple(row) == (rec["metrics"]["nonlinear"]["cop_rms_mm"],
                              max(rec["metrics"]["nonlinear"]["force_pct_fs"][:3]),
                              rec["reference_sensor"]["serial"], "nonlinear")
        dbmod.downgrade(engine, "0002")
        cols = {c["name"] for c in sa.inspect(engine).get_columns("calibrations")}
        assert "cop_rms_mm" not in cols and "certificate_sha256" not in cols
    finally:
        engine.dispose()


def test_calibrations_cli_add_list_show_and_refusals(tmp_path, capsys, monkeypatch) -> None:
    db = str(tmp_path / "t.db")
    monkeypatch.setenv("TALUS_PASSWORD", PASSWORD)
    rec = open_record(f"sqlite:///{db}", Clock())
    staff(rec)
    rec.close()

    def run(*argv: str) -> tuple[int, object]:
        code = talus_main(["calibrations", *argv, "--db", db, "--json"])
        return code, json.loads(capsys.readouterr().out)

    code, out = run("add", "--record", str(EXAMPLE), "--user", "engineer")
    assert code == 0 and out["record_id"] == "CAL-20261123-0001"
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2]")
    code, out = run("add", "--record", str(bad), "--user", "engineer")
    assert code == 2 and "not a calibration record" in out["error"]
    code, out = run("certify", "CAL-20261123-0001", "--certificate", str(tmp_path / "no.pdf"),
                    "--user", "engineer")
    assert code == 2 and "no such certificate" in out["error"]
    code, out = run("list", "--plate-serial", "IBV-600-0417", "--user", "viewer")
    assert code == 0 and [r["record_id"] for r in out] == ["CAL-20261123-0001"]
    code, out = run("show", "CAL-20261123-0001", "--user", "viewer")
    assert code == 0 and out["record"] == _example()
