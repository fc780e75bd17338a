"""Report buttons: Review → "Session report (PDF)" from the clinical record's session (its
recording read, its limits snapshot), Patients → "Progress report (PDF)"; each written where
the user chose, never over an existing file; the PDFs read back with pdftotext."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import gui_support  # noqa: F401  (offscreen platform before Qt)
import pytest
from patients_helpers import PASSWORD, open_record, staff
from PySide6.QtCore import Qt
from test_patients_session import _short_rom

from app.main_window import MainWindow
from app.settings import GuiSettings
from patients.session_record import run_for_patient, twin_runner

WAIT_MS = 120_000
pytestmark = pytest.mark.skipif(shutil.which("pdftotext") is None,
                                reason="pdftotext (poppler-utils, installed by make) missing")


def _text(pdf: Path) -> str:
    return subprocess.run(["pdftotext", "-layout", str(pdf), "-"], check=True,
                          capture_output=True, text=True).stdout


@pytest.fixture()
def treated(tmp_path):
    """A record with one patient and one stored twin session (short ankle ROM), its recording
    in the GUI's recordings folder."""
    record = open_record(str(tmp_path / "talus.db"))
    people = staff(record)
    code = record.add_patient(people.clinician, "P-REPORT", body_mass_kg=75,
                              affected_side="left")["code"]
    record.set_limits(people.clinician, code, pitch_min_deg=-12, pitch_max_deg=12,
                      roll_min_deg=-9, roll_max_deg=9)
    recs = tmp_path / "recordings"
    recs.mkdir()
    protocol = _short_rom(tmp_path)
    stored = run_for_patient(record, people.clinician, code, protocol, recs / "rom.mcap",
                             twin_runner(protocol))
    yield record, code, stored, recs
    record.close()


def test_session_and_progress_reports_from_their_buttons(qtbot, treated, tmp_path):
    record, code, stored, recs = treated
    window = MainWindow(None, GuiSettings(recordings_dir=str(recs),
                                          clinic_name="Hospital La Fe — Rehabilitación"),
                        record=record)
    qtbot.addWidget(window)
    window.show()
    window.login.user.setText("clinician")
    window.login.password.setText(PASSWORD)
    qtbot.mouseClick(window.login.button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: window.actor is not None, timeout=WAIT_MS)
    out_dir = tmp_path / "reports"
    out_dir.mkdir()

    # Review: open the session, then its report where the user chooses
    qtbot.mouseClick(window.rail_buttons["review"], Qt.MouseButton.LeftButton)
    review = window.review
    review.refresh()
    assert review.sessions.count() == 1
    assert not review.report_button.isEnabled()           # nothing opened yet
    qtbot.mouseClick(review.open_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: review.data is not None, timeout=WAIT_MS)
    asked: list[tuple[str, Path]] = []
    report = review.report
    report.ask_path = lambda title, suggested: asked.append((title, suggested)) or \
        out_dir / "session"                                # ".pdf" is added
    qtbot.mouseClick(review.report_button, Qt.MouseButton.LeftButton)
    assert not review.report_button.isEnabled()            # one report at a time
    qtbot.waitUntil(lambda: report.last is not None or "No report" in
                    review.report_message.text(), timeout=WAIT_MS)
    assert report.last == out_dir / "session.pdf", review.report_message.text()
    assert asked[0][1].name == "session-rom.pdf"
    assert review.report_button.isEnabled() and review.open_report_button.isEnabled()
    assert "Report written" in review.report_message.text()
    text = _text(report.last)
    assert "COMPLETED" in text
    assert report.last_result is not None
    assert report.last_result["session"] == stored["uid"]  # built from the record's session
    assert "Hospital La Fe" in text                        # the clinic from the settings
    pitch = stored["summary"]["rom_deg"]["pitch"][1]
    assert f"{pitch:.1f}" in text

    # the same path again: refused, the file untouched
    before = report.last.read_bytes()
    report.last = None
    qtbot.mouseClick(review.report_button, Qt.MouseButton.LeftButton)
    assert "already exists" in review.report_message.text()
    assert (out_dir / "session.pdf").read_bytes() == before
    assert review.report_button.isEnabled()                # nothing started
    # cancelled: nothing happens
    report.ask_path = lambda title, suggested: None
    qtbot.mouseClick(review.report_button, Qt.MouseButton.LeftButton)
    assert report.last is None and sorted(p.name for p in out_dir.iterdir()) == \
        ["session.pdf"]

    # Patients: the progress report of the chosen patient
    qtbot.mouseClick(window.rail_buttons["patients"], Qt.MouseButton.LeftButton)
    page = window.patients
    qtbot.waitUntil(lambda: page.list.count() == 1, timeout=WAIT_MS)
    page.list.setCurrentRow(0)
    qtbot.waitUntil(lambda: page.report_button.isEnabled(), timeout=WAIT_MS)
    # the folder of the last report is suggested again (one helper, per page)
    suggested_in: list[Path] = []
    page.report.ask_path = lambda title, suggested: suggested_in.append(suggested) or \
        out_dir / suggested.name
    qtbot.mouseClick(page.report_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: page.report.last is not None or "No report" in
                    page.message.text(), timeout=WAIT_MS)
    assert page.report.last == out_dir / f"progress-{code}.pdf", page.message.text()
    assert suggested_in[0].parent == Path.home()           # this page's first report
    text = _text(page.report.last)
    assert code in text and "Hospital La Fe" in text
    assert not list(out_dir.glob("*.tmp"))                 # written by rename, nothing left
