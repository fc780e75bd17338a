"""Prescribe shows where a protocol asks more than the robot can give (the pre-flight's
``at_robot_limit``): a real gait record's heel strike asks the ≈ 2 kN drives for more for a
few ms; the clinician reads it in the patient's terms before starting, and Start stays enabled
(a warning, not a refusal). A gentle protocol shows nothing. Real Qt window, real RT process on
the twin, the real C3D files of ``../shared/data/c3d``."""
from __future__ import annotations

import gui_support
import numpy as np
import pytest
from PySide6.QtCore import QLocale, Qt
from test_gait_real_files import DATA, _bench

from app.i18n import install_language
from app.pages.prescribe import beyond_words, clinical_limits, saturation_words
from app.patient_context import PatientContext
from protocols.rt_session import protocol_document

#: The bench's patient (75 kg: gait replay scales the record to 60 % of it).
PATIENT = PatientContext("P-GAIT", 75.0)
WAIT_MS = 180_000
#: One heel-strike record (test_gait_real_files.HEEL_STRIKES) and its plate.
HEEL_STRIKE_FILE = "type2_vicon.c3d"


def test_beyond_words_say_what_the_patient_gets():
    """The words of each limit, with its figures in the language's number format."""
    entry = {"what": "actuator force", "limit": 2000.0, "unit": "N", "longest_s": 0.004,
             "from_s": 1.3345, "from_play_s": 1.2345, "peak": 2951.7}
    saved = QLocale()
    QLocale.setDefault(QLocale(QLocale.Language.English, QLocale.Country.UnitedStates))
    try:
        assert beyond_words(entry) == (
            "the robot will deliver at most 2,000 N per drive where the protocol asks up to "
            "2,952 N, for 4 ms from t = 1.23 s: there the force on the foot falls short of "
            "the prescribed one")
        volts = {"what": "drive command", "limit": 6.0, "unit": "V", "longest_s": 0.0125,
                 "from_s": 0.5, "peak": 6.0}
        assert beyond_words(volts) == (
            "the drives run at full power (their 6.0 V command limit) for 13 ms from "
            "t = 0.50 s: there the platform follows the protocol less closely")
        # An older RT process gives the session's time only.
        assert "from t = 1.33 s" in beyond_words({**entry, "from_play_s": None})
        # What it does not understand (a newer RT process's entry, a broken one) says nothing.
        assert beyond_words({**entry, "what": "slider speed"}) == ""
        assert beyond_words({**entry, "peak": None}) == ""
        assert beyond_words({**entry, "from_play_s": float("nan")}) == ""
        assert beyond_words("actuator force") == ""
        # The drive command clipped at the moment the force is beyond the drive is the same
        # moment said twice: one line; a command at its limit elsewhere is its own line.
        same = {**volts, "from_s": 1.336, "longest_s": 0.003}
        assert clinical_limits([entry, same]) == [entry]
        assert clinical_limits([entry, volts]) == [entry, volts]
        assert clinical_limits([volts]) == [volts]
    finally:
        QLocale.setDefault(saved)


def test_saturation_words_say_how_close_the_drives_came_to_the_stop(qtbot):
    """The sustained-saturation margin (``drive_saturation``) in words and the language's
    numbers; nothing when nothing saturated or the entry is not understood."""
    sat = {"peak_s": 0.0043, "per_axis_s": [0.0043, 0.001, 0.0], "window_s": 0.5,
           "stops_beyond_s": 0.25}
    saved = QLocale()
    QLocale.setDefault(QLocale(QLocale.Language.English, QLocale.Country.UnitedStates))
    try:
        assert saturation_words(sat) == (
            "The drives stay at their limit for at most 4 ms in any 0.5 s; the robot stops "
            "itself beyond 250 ms.")
        assert saturation_words({**sat, "peak_s": 0.0}) == ""
        assert saturation_words({**sat, "window_s": float("nan")}) == ""
        assert saturation_words({**sat, "stops_beyond_s": "250"}) == ""
        assert saturation_words(None) == ""
        install_language("es")
        QLocale.setDefault(QLocale(QLocale.Language.Spanish, QLocale.Country.Spain))
        text = saturation_words(sat)
        assert "como máximo 4 ms" in text and "0,5 s" in text and "250 ms" in text
    finally:
        install_language("en")
        QLocale.setDefault(saved)


def test_beyond_words_in_spanish(qtbot):
    install_language("es")
    try:
        text = beyond_words({"what": "actuator force", "limit": 2000.0, "unit": "N",
                             "longest_s": 0.004, "from_s": 1.2345, "peak": 2951.7})
        assert "como máximo" in text and "1,23 s" in text and "4 ms" in text
    finally:
        install_language("en")


@pytest.fixture()
def gui(qtbot, tmp_path):
    rec = tmp_path / "recordings"
    rec.mkdir()
    proc, endpoint, _pub = gui_support.start_rt_for_gui(str(rec))
    with gui_support.window_on_rt(qtbot, proc, endpoint, str(rec)) as window:
        yield window


@pytest.mark.skipif(DATA is None, reason="the real C3D files (../shared/data/c3d) are absent")
def test_prescribe_warns_where_a_heel_strike_asks_more_than_the_drives(gui, qtbot, tmp_path):
    window = gui
    window.set_patient(PATIENT)
    qtbot.mouseClick(window.rail_buttons["prescribe"], Qt.MouseButton.LeftButton)
    page = window.prescribe
    bench = _bench()
    case = next(c for c in bench.CASES if c.file == HEEL_STRIKE_FILE)
    path = tmp_path / "heel_strike.yaml"
    path.write_text(bench.protocol_text(case, DATA))
    # The clinician's protocol from the real record (the form shows any protocol document;
    # the library's cards are one source of them).
    page.form.load(protocol_document(path))
    qtbot.waitUntil(page.check_button.isEnabled, timeout=10_000)
    assert not page.beyond.isVisible()
    qtbot.mouseClick(page.check_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: page.last_preflight is not None or page.last_refusal is not None,
                    timeout=WAIT_MS)
    assert page.last_preflight is not None, page.last_refusal
    beyond = {b["what"]: b for b in page.last_preflight["predicted"]["at_robot_limit"]}
    # The RT process's figures are the heel strike's (test_gait_real_files checks the same
    # pre-flight in-process): more than the 2000 N limit asked of a drive, for at most the
    # 20 ms pre-flight allows, inside the replay.
    hit = beyond["actuator force"]
    assert hit["peak"] > hit["limit"] == 2000.0 and 0.0 < hit["longest_s"] <= 0.02
    assert 0.0 < hit["from_s"] < page.last_preflight["predicted"]["duration_s"]
    # On the protocol's own time, the preview's axis: the drives reach their limit as the
    # heel strikes, where the preview's force first rises (20 N: the record's contact), within
    # 10 ms (the force law reads the protocol 5 ms ahead) and a preview step. Measured: 40 ms
    # into the replay, 172 ms into the session (its approach and tare come first).
    preview = page.preview
    assert preview is not None and preview.force_protocol
    contact = float(preview.t[int(np.argmax(preview.fz_n > 20.0))])
    step = float(preview.t[1] - preview.t[0])
    assert abs(hit["from_play_s"] - contact) <= 0.010 + step, (hit, contact)
    assert hit["from_play_s"] < hit["from_s"]
    # ... and the page shows each of them in the patient's terms, under the passed verdict.
    assert page.beyond.isVisible() and "passed" in page.verdict.text()
    text = page.beyond.text()
    assert text.startswith("Warning: this protocol asks more than the robot can give")
    shown = clinical_limits(list(beyond.values()))
    assert hit in shown and text.count("•") == len(shown)
    for entry in shown:
        assert beyond_words(entry) in text
    # How close the heel strikes came to the sustained-saturation stop: a few ms of the
    # 250 ms (half the 0.5 s window) that stop the robot, said under the lines.
    sat = page.last_preflight["predicted"]["drive_saturation"]
    assert 0.0 < sat["peak_s"] <= 0.05 and sat["stops_beyond_s"] == 0.25
    assert saturation_words(sat) and text.endswith(saturation_words(sat))
    locale = QLocale()
    for figure in (locale.toString(hit["limit"], "f", 0), locale.toString(hit["peak"], "f", 0),
                   locale.toString(hit["longest_s"] * 1e3, "f", 0),
                   locale.toString(hit["from_play_s"], "f", 2)):
        assert figure in text, (figure, text)
    # A warning, not a refusal: Start is enabled.
    assert page.start_button.isEnabled()

    # A gentle protocol (the library's sine Fz, short): the form's change clears the warning,
    # and its own pre-flight reports nothing beyond the robot.
    page.select_stem("sine_fz")
    assert not page.beyond.isVisible() and page.beyond.text() == ""
    for field, value in {"cycles": "3", "ramp_in_s": "1", "ramp_out_s": "1"}.items():
        page.form.set_value(field, value)
    qtbot.waitUntil(page.check_button.isEnabled, timeout=10_000)
    qtbot.mouseClick(page.check_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(page.start_button.isEnabled, timeout=WAIT_MS)
    assert page.last_preflight["predicted"]["at_robot_limit"] == []
    assert not page.beyond.isVisible() and page.beyond.text() == ""
