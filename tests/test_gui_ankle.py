"""The patient's ankle setup in the GUI (issue 17): shown and entered on the patient's card
through the clinical record (its refusals shown as it words them, nothing saved), carried to
the RT process as ``session_start``/``session_preflight``'s ``patient.ankle``, and pre-flight's
predicted ankle-centre displacement shown in clinical words on Prescribe."""
from __future__ import annotations

import gui_support  # noqa: F401  (offscreen platform before Qt)
import numpy as np
import pytest
from PySide6.QtCore import Qt

from app.journal import SessionJournal
from app.main_window import MainWindow
from app.pages.prescribe import _key, _peaks
from app.patient_context import PatientContext
from app.review_data import ReviewData, load_review
from app.settings import GuiSettings
from patients.service import ClinicalRecord
from protocols.schema import validate_protocol_data
from protocols.session import SessionSetup, preflight, run_session
from rt.errors import ProtocolValidationError
from rt.model.ankle import AnkleSetup

PASSWORD = "correct horse battery"


@pytest.fixture()
def record(tmp_path):
    rec = ClinicalRecord.open(str(tmp_path / "talus.db"), create=True)
    admin = rec.init_admin("admin", PASSWORD)
    rec.add_user(admin, "ana", "clinician", PASSWORD)
    ana = rec.authenticate("ana", PASSWORD)
    rec.add_patient(ana, "P-0007", body_mass_kg=72, affected_side="left")
    rec.set_limits(ana, "P-0007", pitch_min_deg=-10, pitch_max_deg=15)
    yield rec
    rec.close()


@pytest.fixture()
def window(qtbot, record, tmp_path):
    w = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path), idle_lock_s=600.0),
                   record=record, idle_clock=lambda: 0.0)
    qtbot.addWidget(w)
    w.show()
    page = w.login
    page.user.setText("ana")
    page.password.setText(PASSWORD)
    qtbot.keyClick(page.password, Qt.Key.Key_Return)
    qtbot.waitUntil(lambda: w.actor is not None, timeout=10_000)
    patients = w.patients
    qtbot.waitUntil(lambda: patients.list.count() == 1, timeout=10_000)
    patients.list.setCurrentRow(0)
    qtbot.waitUntil(lambda: patients.current is not None and bool(patients.ankle_label.text()),
                    timeout=10_000)
    return w


def _enter(page, **mm: str) -> None:
    for key, text in mm.items():
        page.ankle_edits[key].setText(text)


def test_ankle_setup_entered_shown_and_sent_with_the_patient(window, qtbot, record):
    page = window.patients
    ana = window.actor
    assert "No ankle setup entered" in page.ankle_label.text()
    # The affected side is the default foot for the first entry.
    assert page.ankle_side.currentData() == "left"
    assert page.ankle_button.isEnabled()

    # At the sole: the record refuses, its words are shown, nothing is saved.
    _enter(page, height_above_sole_m="-5", offset_x_m="10")
    qtbot.mouseClick(page.ankle_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "refused" in page.message.text(), timeout=10_000)
    assert "at or below the sole" in page.message.text()
    assert record.ankle_in_force(ana, "P-0007") is None
    assert "No ankle setup entered" in page.ankle_label.text()

    # A typo that is not a number never reaches the record.
    _enter(page, height_above_sole_m="8 5")
    qtbot.mouseClick(page.ankle_button, Qt.MouseButton.LeftButton)
    assert "a number is needed" in page.message.text()
    assert record.ankle_in_force(ana, "P-0007") is None

    # 85 mm above the sole, 12 mm towards the toes, 4 mm across (mm typed, m stored).
    _enter(page, height_above_sole_m="85", offset_x_m="12", offset_y_m="-4",
           sole_above_sensor_m="", reason="measured at the malleoli")
    qtbot.mouseClick(page.ankle_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "85 mm above the sole" in page.ankle_label.text(), timeout=10_000)
    stored = record.ankle_in_force(ana, "P-0007")
    assert stored == pytest.approx({"side": "left", "height_above_sole_m": 0.085,
                                    "offset_x_m": 0.012, "offset_y_m": -0.004,
                                    "sole_above_sensor_m": 0.0, "source": "entered"})
    text = page.ankle_label.text()
    assert "left foot" in text and "+12 mm along the foot" in text and "-4 mm across" in text
    assert "entered by hand" in text
    assert page.ankle_edits["height_above_sole_m"].text() == "85"

    # An empty field keeps the value in force: only the height changes.
    _enter(page, height_above_sole_m="90", offset_x_m="", offset_y_m="", reason="")
    qtbot.mouseClick(page.ankle_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "90 mm above the sole" in page.ankle_label.text(), timeout=10_000)
    again = record.ankle_in_force(ana, "P-0007")
    assert again["height_above_sole_m"] == pytest.approx(0.090)
    assert again["offset_x_m"] == pytest.approx(0.012)

    # "Use for the session": pre-flight and the session get patient.ankle.
    qtbot.mouseClick(page.use_button, Qt.MouseButton.LeftButton)
    ctx = window.patient
    assert ctx is not None and ctx.ankle == again
    sent = ctx.rt_patient()
    assert sent["ankle"] == again and sent["id"] == "P-0007"
    # With the record the session's row is opened first: its snapshot carries the same ankle.
    journal = SessionJournal(record, lambda: ana)
    doc = window.prescribe.form.document
    started = journal.begin("P-0007", doc)
    assert started["ankle"] == again and started["limits"]["pitch_max_deg"] == 15.0


def test_preflight_ankle_displacement_in_clinical_words_and_refusal_as_is(qtbot, tmp_path):
    ankle = {"side": "right", "height_above_sole_m": 0.08, "offset_x_m": 0.0,
             "offset_y_m": 0.0, "sole_above_sensor_m": 0.0, "source": "entered"}
    patient = PatientContext("P-0001", 70.0, {"pitch_min_deg": -15.0, "pitch_max_deg": 15.0,
                                              "roll_min_deg": -10.0, "roll_max_deg": 10.0},
                             side="right", ankle=ankle)
    w = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), tmp_path / "gui.json")
    qtbot.addWidget(w)
    w.set_patient(patient)
    page = w.prescribe
    page.select_stem("ankle_rom")
    key = _key(page.form.document, page.patient)
    assert '"ankle"' in key          # a new ankle setup asks for a new pre-flight

    predicted = {"duration_s": 30.0,
                 "ankle_displacement_mm": {"peak": 21.84, "rms": 9.46, "limit": 30.0}}
    page._replied(f"preflight:{key}", {"ok": True, "predicted": predicted}, "")
    assert "the ankle centre moves at most 21.8 mm (RMS 9.5 mm; comfort limit 30 mm)" \
        in page.verdict.text()
    assert page.last_preflight is not None

    # The refusal is pre-flight's own text (the narrowing it proposes included), shown as is.
    doc = {"schema_version": 1, "kind": "ankle_rom", "name": "rom", "pose": {"z_m": 0.63},
           "sequence": ["dorsi_plantar"], "amplitude_deg": {
               "dorsiflexion": 15.0, "plantarflexion": 15.0, "inversion": 5.0,
               "eversion": 5.0}, "speed_deg_s": 20.0, "hold_s": 0.3}
    with pytest.raises(ProtocolValidationError, match="ankle centre") as refused:
        preflight(SessionSetup(protocol=validate_protocol_data(doc),
                               ankle=AnkleSetup(**ankle)))
    refusal = str(refused.value)
    page._replied(f"preflight:{key}", None, refusal)
    assert page.verdict.text() == f"REFUSED: {refusal}"


def test_peaks_without_an_ankle_setup_say_nothing_about_the_ankle() -> None:
    # No ankle setup: pre-flight predicts no displacement and the verdict does not invent one.
    assert "ankle centre" not in _peaks({"duration_s": 12.0, "peak_platform_force_n": 40.0})
    # A malformed figure (missing limit) is left out rather than shown half.
    assert "ankle centre" not in _peaks({"ankle_displacement_mm": {"peak": 3.0, "rms": 1.0}})


def test_review_shows_the_ankle_in_clinical_terms(qtbot, tmp_path):
    # A real recording: an 8° ROM about a left ankle 70 mm above the sole on the twin.
    doc = {"schema_version": 1, "kind": "ankle_rom", "name": "rom", "pose": {"z_m": 0.63},
           "sequence": ["dorsi_plantar", "inversion_eversion"], "amplitude_deg": {
               "dorsiflexion": 8.0, "plantarflexion": 8.0, "inversion": 8.0,
               "eversion": 8.0}, "speed_deg_s": 20.0, "hold_s": 0.3,
           "max_acceleration_deg_s2": 200.0, "max_jerk_deg_s3": 4000.0}
    out = tmp_path / "rom.mcap"
    ankle = AnkleSetup(side="left", height_above_sole_m=0.07, offset_x_m=0.01)
    summary = run_session(SessionSetup(protocol=validate_protocol_data(doc), ankle=ankle), out)
    assert summary["completed"], summary["stops"]

    data = load_review(out)
    assert data.has_ankle and len(data.t_ankle) > 100
    # The position loop on the twin reaches the commanded 8° within 0.5° each way.
    assert float(data.plantarflexion_deg.max()) == pytest.approx(8.0, abs=0.5)
    assert float(data.plantarflexion_deg.min()) == pytest.approx(-8.0, abs=0.5)
    assert float(np.abs(data.inversion_deg).max()) == pytest.approx(8.0, abs=0.5)

    w = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), tmp_path / "gui.json")
    qtbot.addWidget(w)
    review = w.review
    review.open(out)
    qtbot.waitUntil(lambda: review.data is not None, timeout=120_000)
    names = [item.name() for item in review.angle_plot.getPlotItem().listDataItems()]
    assert "ankle: plantar(+)/dorsi(−) flexion" in names
    assert "ankle: inversion(+)/eversion(−)" in names
    assert "platform pitch (engineers)" in names          # kept for engineers
    info = review.info.text()
    assert "ankle reached dorsiflexion 8." in info or "ankle reached dorsiflexion 7." in info
    # The passive ankle pushes back at 8°: a few N·m (test_ankle_session: 5-10 N·m).
    df_torque = float(info.split("peak torques DF ")[1].split(",")[0])
    assert 5.0 < df_torque < 10.0


def test_review_without_an_ankle_setup_keeps_the_platform_angles(qtbot, tmp_path):
    data = ReviewData("x.mcap", True, np.array([0.0, 1.0]), np.array([0.0, 2.0]),
                      np.array([0.0, -3.0]), np.zeros(0), np.zeros(0), np.zeros(0),
                      np.zeros(0))
    assert not data.has_ankle
    w = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), tmp_path / "gui.json")
    qtbot.addWidget(w)
    w.review._show(data, "")
    names = [item.name() for item in w.review.angle_plot.getPlotItem().listDataItems()]
    assert "plantar(+)/dorsi(−) flexion" in names and not any("ankle:" in n for n in names)
    assert "ankle reached" not in w.review.info.text()


def test_run_reads_inversion_on_the_foot_of_the_ankle_setup(qtbot, tmp_path):
    limits = {"pitch_min_deg": -15.0, "pitch_max_deg": 15.0, "roll_min_deg": -4.0,
              "roll_max_deg": 10.0}
    w = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), tmp_path / "gui.json")
    qtbot.addWidget(w)
    run = w.run
    # Affected side "both" falls back to right; the ankle setup says the left foot is on it.
    left = {"side": "left", "height_above_sole_m": 0.08, "offset_x_m": 0.0, "offset_y_m": 0.0,
            "sole_above_sensor_m": 0.0, "source": "entered"}
    run.set_patient(PatientContext("P-0002", 70.0, limits, side="right", ankle=left))
    assert run._inversion_sign() == -1.0
    # Left foot: the roll band −4…10° is inversion −10…4° (mirrored).
    assert run.rom_bands["roll"].getRegion() == pytest.approx((-10.0, 4.0))
    run.set_patient(PatientContext("P-0002", 70.0, limits, side="right"))
    assert run._inversion_sign() == 1.0
    assert run.rom_bands["roll"].getRegion() == pytest.approx((-4.0, 10.0))


def test_run_shows_live_ankle_torques_in_clinical_words(qtbot, tmp_path):
    from rt.model.ankle import ankle_torques
    limits = {"pitch_min_deg": -15.0, "pitch_max_deg": 15.0}
    w = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), tmp_path / "gui.json")
    qtbot.addWidget(w)
    run = w.run
    run.set_patient(PatientContext("P-0003", 70.0, limits, side="right"))
    run.show_ankle({"wrench": [0.0, 0.0, -200.0, 0.0, 0.0, 0.0]})
    assert run.ankle_label.isHidden()                     # no ankle setup: nothing invented
    setup = {"side": "right", "height_above_sole_m": 0.08, "offset_x_m": 0.03,
             "offset_y_m": 0.0, "sole_above_sensor_m": 0.01, "source": "entered"}
    run.set_patient(PatientContext("P-0003", 70.0, limits, side="right", ankle=setup))
    assert not run.ankle_label.isHidden() and run.ankle_label.text() == "Ankle torque: —"
    # 200 N down on the plate and 3 N·m about the sensor's x: the torques about the ankle
    # centre are rt.model.ankle's (hand statics tested in test_ankle.py), in words.
    wrench = [5.0, 0.0, -200.0, 3.0, 0.0, 0.0]
    tp, ti, _ = ankle_torques(wrench, AnkleSetup(**setup))
    run.show_ankle({"wrench": wrench})
    text = run.ankle_label.text()
    pf = "plantarflexion" if tp >= 0 else "dorsiflexion"
    inv = "inversion" if ti >= 0 else "eversion"
    assert text == f"Ankle torque: {pf} {abs(tp):.1f} N·m, {inv} {abs(ti):.1f} N·m"
    assert abs(tp) > 1.0                       # the 30 mm offset makes a real moment arm
    run.show_ankle({"wrench": [None] * 6})     # a stale sensor sample
    assert run.ankle_label.text() == "Ankle torque: —"
