"""The GUI driven as a clinician would, against a real RT process on the twin (offscreen):
pick a protocol, see the pre-flight refusal beyond the patient's ROM, run a short session,
press STOP, acknowledge what Reset clears, review the recording; a lost RT process is shown
at once and disables motion."""
from __future__ import annotations

import gui_support
import pytest
from PySide6.QtCore import Qt

from app.main_window import MainWindow
from app.patient_context import PatientContext
from app.rt_link import RtLink
from app.settings import GuiSettings

#: A patient whose dorsi/plantarflexion range is ±5°: the library's ankle ROM (±10°) is beyond.
NARROW = PatientContext("P-NARROW", 70.0, {"pitch_min_deg": -5.0, "pitch_max_deg": 5.0,
                                           "roll_min_deg": -12.0, "roll_max_deg": 12.0})
#: Long enough to press STOP in the middle on a loaded machine.
SESSION = {"cycles": "6", "ramp_in_s": "1", "ramp_out_s": "1"}
WAIT_MS = 180_000


@pytest.fixture()
def gui(qtbot, tmp_path):
    rec = tmp_path / "recordings"
    rec.mkdir()
    proc, endpoint, _pub = gui_support.start_rt_for_gui(str(rec))
    link = RtLink(endpoint, name="GUI test")
    window = MainWindow(link, GuiSettings(recordings_dir=str(rec)))
    qtbot.addWidget(window)
    link.start()
    window.show()
    try:
        qtbot.waitUntil(lambda: link.connected, timeout=30_000)
        yield window, proc
    finally:
        window.close()
        link.close()
        gui_support.stop_rt(proc)


def test_clinician_flow_refusal_run_stop_acknowledge_review(gui, qtbot):
    window, _ = gui
    window.set_patient(NARROW)
    assert "P-NARROW" in window.band.patient_label.text()
    page = window.prescribe
    qtbot.mouseClick(window.rail_buttons["prescribe"], Qt.MouseButton.LeftButton)

    # 1. Ankle ROM ±10° for a patient with ±5°: pre-flight refuses, Start stays disabled.
    page.select_stem("ankle_rom")
    qtbot.waitUntil(page.check_button.isEnabled, timeout=10_000)
    qtbot.mouseClick(page.check_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: page.last_refusal is not None or page.last_preflight is not None,
                    timeout=WAIT_MS)
    assert page.last_refusal is not None, page.last_preflight
    assert "REFUSED" in page.verdict.text() and "pitch" in page.verdict.text().lower()
    assert not page.start_button.isEnabled()

    # 2. A short sine Fz: pre-flight passes with its predicted peaks; Start goes to Run.
    page.select_stem("sine_fz")
    for path, text in SESSION.items():
        page.form.set_value(path, text)
    qtbot.waitUntil(page.check_button.isEnabled, timeout=10_000)
    qtbot.mouseClick(page.check_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(page.start_button.isEnabled, timeout=WAIT_MS)
    assert "passed" in page.verdict.text()
    page.form.set_value("cycles", "7")                  # any edit invalidates the verdict
    assert not page.start_button.isEnabled()
    page.form.set_value("cycles", SESSION["cycles"])
    qtbot.mouseClick(page.check_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(page.start_button.isEnabled, timeout=WAIT_MS)
    qtbot.mouseClick(page.start_button, Qt.MouseButton.LeftButton)
    run = window.run
    assert window.stack.currentWidget() is run

    # 3. Take control, start, see live telemetry, press STOP.
    assert not run.start_button.isEnabled()             # not the owner yet
    qtbot.mouseClick(run.control_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(run.start_button.isEnabled, timeout=10_000)
    qtbot.mouseClick(run.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: run.session_id is not None or bool(run.last_error), timeout=WAIT_MS)
    assert run.session_id is not None, run.last_error
    frames = run.frames
    qtbot.waitUntil(lambda: run.frames > frames + 20 and run.samples_shown > 50,
                    timeout=30_000)
    qtbot.waitUntil(lambda: window.band.state == "running", timeout=30_000)

    def sine_played() -> bool:
        # STOP once the live plot has shown the sine's crest (300 ± 100 N): with the Prescribe
        # page's pre-flight reused the session starts at once, and 20 frames are still the
        # ramp-in.
        latest = run.link.telemetry.latest or {}
        return (latest.get("session") == run.session_id
                and (latest.get("force_n") or 0.0) > 360.0)
    qtbot.waitUntil(sine_played, timeout=60_000)
    qtbot.keyClick(window, Qt.Key.Key_Escape)          # STOP from the keyboard
    qtbot.waitUntil(lambda: window.band.state == "soft_stop" and bool(window.band.latched),
                    timeout=10_000)
    assert [f["cause"] for f in window.band.latched] == ["stop_client"]
    assert "STOP pressed" in window.band.detail_label.text()
    assert not run.start_button.isEnabled()             # stopped: motion needs a reset

    # 4. Reset says what it clears and asks; acknowledging clears exactly that.
    qtbot.mouseClick(window.band.reset_button, Qt.MouseButton.LeftButton)
    assert "Reset will clear" in window.band.ack_label.text()
    assert "STOP pressed" in window.band.ack_label.text()
    qtbot.mouseClick(window.band.ack_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: not window.band.latched and window.band.state != "soft_stop",
                    timeout=10_000)
    qtbot.waitUntil(lambda: run.session_id is None and run.last_summary is not None,
                    timeout=60_000)

    # 5. Review: the recording, with the stop marked where it happened.
    qtbot.mouseClick(window.rail_buttons["review"], Qt.MouseButton.LeftButton)
    review = window.review
    qtbot.waitUntil(lambda: review.sessions.count() == 1, timeout=10_000)
    qtbot.mouseClick(review.open_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: review.data is not None, timeout=60_000)
    data = review.data
    assert [c for _, c, _ in data.stops] == ["stop_client"]
    assert data.metadata["patient_id"] == "P-NARROW"
    # the sine was played: 300 ± 100 N, so the measured force passed 350 N before the stop
    assert max(data.force_n[data.t_force < data.stops[0][0]]) > 350.0
    assert "STOP pressed" in review.info.text()


def test_losing_the_rt_process_disables_motion_at_once(gui, qtbot):
    window, proc = gui
    window.set_patient(NARROW)
    run = window.run
    qtbot.waitUntil(run.control_button.isEnabled, timeout=10_000)
    proc.kill()
    proc.wait()
    # (the link's flag flips on its watcher thread; the band follows when the queued signal
    # reaches the GUI thread, the next turn of the event loop)
    qtbot.waitUntil(lambda: not window.link.connected and window.band.state == "disconnected",
                    timeout=5_000)
    assert "NOT connected" in window.band.connection_label.text()
    assert not run.control_button.isEnabled() and not run.start_button.isEnabled()
    assert not window.prescribe.check_button.isEnabled()
    assert window.stops.stop_button.isEnabled()       # STOP is always there to press
