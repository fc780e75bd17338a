"""The calibration wizard driven by its buttons: plan (sites drawn), run (progress), fit
(PASS/FAIL and the COP error map), verify, certificate (a PDF read back, never over a file,
stored in the clinical record for the engineer); steps refuse to run out of order; the page
is the calibration engineer's."""
from __future__ import annotations

import shutil
import subprocess

import gui_support  # noqa: F401  (offscreen platform before Qt)
import pytest
from patients_helpers import PASSWORD, open_record, staff
from PySide6.QtCore import Qt

from app.calibration_flow import CalibrationFlow
from app.main_window import MainWindow
from app.settings import GuiSettings
from rt.errors import InputError

WAIT_MS = 300_000
#: A short plan (as the calibration tests use): 2 × 2 grid, three loads.
SHORT_PLAN = """schema_version: 1
name: short test plan
loads_n: [200.0, 800.0, 1500.0]
grid: {nx: 2, ny: 2, margin_m: 0.08}
sine_sites: none
gait_sites: centre
registration: nominal
"""


def test_steps_refuse_to_run_out_of_order(tmp_path):
    from calibration.plate import TWIN_PLATE_FILE

    flow = CalibrationFlow(tmp_path / "cal", TWIN_PLATE_FILE, "direct")
    for step in (flow.run, flow.fit, flow.verify):
        with pytest.raises(InputError, match="first"):
            step()
    with pytest.raises(InputError, match="plan"):
        flow.make_plan("schema_version: 1\nloads_n: [-5]\n")
    with pytest.raises(InputError, match="backend"):
        CalibrationFlow(tmp_path / "x", TWIN_PLATE_FILE, "rt").make_plan()
    assert not (tmp_path / "cal").exists()                 # nothing written by a refusal


@pytest.mark.skipif(shutil.which("pdftotext") is None, reason="poppler-utils missing")
def test_engineer_calibrates_a_plate_through_the_wizard(qtbot, tmp_path):
    record = open_record(str(tmp_path / "talus.db"))
    staff(record)
    try:
        window = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), record=record)
        qtbot.addWidget(window)
        window.show()
        window.login.user.setText("engineer")
        window.login.password.setText(PASSWORD)
        qtbot.mouseClick(window.login.button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: window.actor is not None, timeout=30_000)
        assert window.rail_buttons["calibrate"].isVisible()
        qtbot.mouseClick(window.rail_buttons["calibrate"], Qt.MouseButton.LeftButton)
        page = window.calibrate
        assert [k for k, b in page.buttons.items() if b.isEnabled()] == ["plan"]

        plan = tmp_path / "plan.yaml"
        plan.write_text(SHORT_PLAN)
        page.plan_file.setText(str(plan))
        page.work_folder.setText(str(tmp_path / "work"))
        page.backend.setCurrentIndex(page.backend.findData("direct"))

        def click(step: str) -> None:
            assert page.buttons[step].isEnabled(), step
            qtbot.mouseClick(page.buttons[step], Qt.MouseButton.LeftButton)
            qtbot.waitUntil(lambda: not page.busy, timeout=WAIT_MS)
            assert step in page.done, page.last_error

        click("plan")
        assert "trials at" in page.status.text()
        assert not page.buttons["fit"].isEnabled()         # run first
        click("run")
        assert page.progress.value() == page.progress.maximum() > 0
        assert not page.plate_file.isEnabled()             # the campaign is fixed now
        click("fit")
        flow = page.flow
        assert flow is not None and flow.record is not None
        verdict = flow.record["verdict"]["pass"]
        assert page.verdict.text() == ("PASS" if verdict else "FAIL")
        m = flow.record["metrics"]
        assert m["nonlinear"]["cop_rms_mm"] < m["before"]["cop_rms_mm"]   # it calibrated
        assert f"{m['nonlinear']['cop_rms_mm']:.1f} mm after" in page.status.text()
        click("verify")
        assert "Verification" in page.status.text()

        out = tmp_path / "certificate.pdf"
        page.ask_path = lambda title, suggested: out
        click("certificate")
        assert page.last_certificate == out
        text = subprocess.run(["pdftotext", "-layout", str(out), "-"], check=True,
                              capture_output=True, text=True).stdout
        assert flow.record["id"] in text
        stored = record.list_calibrations(window.actor)
        assert [c["record_id"] for c in stored] == [flow.record["id"]]
        # again to the same file: refused, the certificate untouched
        before = out.read_bytes()
        page.done.discard("certificate")
        qtbot.mouseClick(page.buttons["certificate"], Qt.MouseButton.LeftButton)
        assert "already exists" in page.status.text()
        assert out.read_bytes() == before
    finally:
        record.close()


def test_only_the_engineer_sees_calibrate(qtbot, tmp_path):
    record = open_record(str(tmp_path / "talus.db"))
    staff(record)
    try:
        window = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), record=record)
        qtbot.addWidget(window)
        window.show()
        window.login.user.setText("clinician")
        window.login.password.setText(PASSWORD)
        qtbot.mouseClick(window.login.button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: window.actor is not None, timeout=30_000)
        assert not window.rail_buttons["calibrate"].isVisible()
    finally:
        record.close()
