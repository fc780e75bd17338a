"""Reports from the clinical record: a stored session's report (from its recording, its hash
checked) and a patient's progress from the stored sessions, through the service layer (the
role decides; identifying data only when asked and allowed)."""
from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from patients_helpers import open_record, staff
from test_patients_session import _short_rom

from patients.session_record import run_for_patient, twin_runner
from reports.from_record import progress_input, session_input
from reports.progress import render_progress_report
from reports.session_report import render_session_report


def _text(pdf: Path) -> str:
    return subprocess.run(["pdftotext", "-layout", str(pdf), "-"], check=True,
                          capture_output=True, text=True).stdout


@pytest.fixture()
def treated(tmp_path):
    record = open_record(str(tmp_path / "talus.db"))
    people = staff(record)
    code = record.add_patient(people.clinician, body_mass_kg=75, affected_side="left")["code"]
    record.set_limits(people.clinician, code, pitch_min_deg=-12, pitch_max_deg=12,
                      roll_min_deg=-9, roll_max_deg=9)
    protocol = _short_rom(tmp_path)
    stored = run_for_patient(record, people.clinician, code, protocol, tmp_path / "rom.mcap",
                             twin_runner(protocol))
    yield record, people, code, stored
    record.close()


def test_a_stored_session_report_from_the_record(treated, tmp_path):
    record, people, _code, stored = treated
    inp = session_input(record, people.clinician, stored["uid"])
    assert inp.figures["completed"] and inp.identity is None
    out = tmp_path / "s.pdf"
    render_session_report(inp, out)
    text = _text(out)
    # (The in-process twin runner's recording names no patient; the RT process's does.)
    assert "COMPLETED" in text
    pitch = stored["summary"]["rom_deg"]["pitch"][1]
    assert f"{pitch:.1f}" in text                       # the stored figure, as printed


def test_a_progress_report_from_the_stored_sessions(treated, tmp_path):
    record, people, code, _stored = treated
    inp = progress_input(record, people.clinician, code)
    assert inp.side == "left" and len(inp.sessions) == 1
    assert inp.prescribed_rom_deg == {"dorsiflexion": 12.0, "plantarflexion": 12.0,
                                      "inversion": 9.0, "eversion": 9.0}
    out = tmp_path / "p.pdf"
    render_progress_report(inp, out)
    assert code in _text(out)


def test_a_viewer_reads_no_identity(treated):
    from patients.errors import PermissionDenied

    record, people, _code, stored = treated
    with pytest.raises(PermissionDenied):
        session_input(record, people.viewer, stored["uid"], identify=True)
