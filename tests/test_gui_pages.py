"""GUI views without a robot (offscreen, pytest-qt): the generated protocol form and its
messages, STOP/E-STOP shortcuts, the 1366×768 layout and target sizes, Spanish."""
from __future__ import annotations

import gui_support  # noqa: F401  (offscreen platform before Qt)
import pytest
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QAbstractButton, QLineEdit

from app.main_window import SCREEN_SIZE, MainWindow
from app.pages.prescribe import library_documents
from app.patient_context import PatientContext
from app.protocol_form import ProtocolForm
from app.settings import GuiSettings
from protocols.schema import validate_protocol_data

PATIENT = PatientContext("P-0001", 70.0, {"pitch_min_deg": -15.0, "pitch_max_deg": 15.0,
                                          "roll_min_deg": -10.0, "roll_max_deg": 10.0})


@pytest.fixture()
def window(qtbot, tmp_path):
    w = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), tmp_path / "gui.json")
    qtbot.addWidget(w)
    w.set_patient(PATIENT)
    w.show()
    return w


def test_every_library_protocol_loads_valid_into_the_form(qtbot):
    form = ProtocolForm()
    qtbot.addWidget(form)
    docs = library_documents()
    assert {d["kind"] for _, d in docs} == {"sine_fz", "gait_replay", "ankle_rom",
                                           "isometric_hold", "active_assist",
                                           "position_playback"}
    for stem, doc in docs:
        form.load(doc)
        assert form.valid, (stem, form.errors(), form.general_error.text())
        # the form changes nothing until edited (None and omitted are the same to the schema)
        assert validate_protocol_data(form.document) == validate_protocol_data(doc), stem


def test_validation_messages_sit_next_to_the_field(qtbot):
    form = ProtocolForm()
    qtbot.addWidget(form)
    form.load(next(d for s, d in library_documents() if s == "sine_fz"))
    form.set_value("amplitude_n", "400")          # above mean_n: the force would pull
    assert not form.valid
    assert "amplitude_n" in form.errors() and "mean_n" in form.errors()["amplitude_n"]
    form.set_value("amplitude_n", "abc")
    assert form.errors() == {"amplitude_n": "a number is needed"}
    form.set_value("amplitude_n", "80")
    assert form.valid and form.errors() == {}
    assert form.document["amplitude_n"] == 80.0
    form.set_value("frequency_hz", "")            # required
    assert form.errors()["frequency_hz"] == "required"


def test_prescribe_disables_start_without_a_passed_preflight(window):
    page = window.prescribe
    page.select_stem("ankle_rom")
    assert page.form.valid
    assert not page.start_button.isEnabled()      # no robot, no pre-flight
    assert not page.check_button.isEnabled()      # not connected


def test_stop_and_estop_shortcuts_work_from_any_page(window, qtbot):
    stops, estops = [], []
    window.stops.stop_pressed.connect(lambda: stops.append(1))
    window.stops.estop_pressed.connect(estops.append)
    for key in window.pages:
        window.show_page(key)
        edit = window.stack.currentWidget().findChild(QLineEdit)
        if edit is not None:
            edit.setFocus()                       # even while typing in a field
        qtbot.keyClick(window, Qt.Key.Key_Escape)
        qtbot.keyClick(window, Qt.Key.Key_F12)
    assert len(stops) == len(window.pages)
    assert estops == ["keyboard"] * len(window.pages)
    assert "[Esc]" in window.stops.stop_button.text()
    assert "[F12]" in window.stops.estop_button.text()
    qtbot.mouseClick(window.stops.estop_button, Qt.MouseButton.LeftButton)
    assert estops[-1] == "gui"


def test_fits_the_clinic_screen_with_large_targets(window, qtbot):
    width, height = SCREEN_SIZE
    for key in window.pages:
        window.show_page(key)
        qtbot.wait(50)
        hint = window.minimumSizeHint()
        assert hint.width() <= width and hint.height() <= height, (key, hint)
        for button in window.findChildren(QAbstractButton):
            if button.isVisible() and button.objectName() != "qt_scrollarea_viewport" \
                    and not button.objectName().startswith("qt_"):
                assert button.height() >= 40, (key, button.text(), button.height())
    assert window.stops.stop_button.width() >= 120
    assert window.stops.isVisible()


def test_rail_and_pages_are_keyboard_operable(window, qtbot):
    keys = list(window.pages)
    for i, key in enumerate(keys):
        qtbot.keyClick(window, Qt.Key(Qt.Key.Key_1 + i), Qt.KeyboardModifier.ControlModifier)
        assert window.stack.currentWidget() is window.pages[key]


def test_settings_page_refuses_bad_values_and_saves_good_ones(window, tmp_path):
    page = window.settings_page
    page.endpoint.setText("nonsense")
    assert not page.save()
    assert "rt_endpoint" in page.result.text()
    assert not (tmp_path / "gui.json").exists()
    page.endpoint.setText("tcp://127.0.0.1:6000")
    page.idle.setText("5")
    assert page.save()
    assert '"rt_endpoint": "tcp://127.0.0.1:6000"' in (tmp_path / "gui.json").read_text()


def test_idle_lock_waits_for_the_session_and_counts_input(qtbot):
    from PySide6.QtWidgets import QApplication, QPushButton

    from app.idle_lock import IdleWatcher

    now = [0.0]
    running = [True]
    watcher = IdleWatcher(600.0, busy=lambda: running[0], clock=lambda: now[0])
    watcher.start(QApplication.instance())
    locks = []
    watcher.lock_requested.connect(lambda: locks.append(now[0]))
    now[0] = 3600.0
    watcher.check()
    assert locks == []                       # a session runs: never lock
    running[0] = False
    now[0] = 3600.0 + 599.0
    watcher.check()
    assert locks == []                       # idle counts from the session's end
    button = QPushButton("x")
    qtbot.addWidget(button)
    qtbot.mouseClick(button, Qt.MouseButton.LeftButton)   # the user touches the screen
    now[0] += 599.0
    watcher.check()
    assert locks == []
    now[0] += 1.0
    watcher.check()
    watcher.check()
    assert locks == [now[0]]                 # once
    watcher.reset()
    assert not watcher.locked
