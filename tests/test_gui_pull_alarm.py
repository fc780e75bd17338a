"""The GUI tells the staff what the robot cannot fix (issue 15): while the RT status carries the
``pull_in_stop`` alarm (a pull that persists after a stop, beyond the drives) the status band
across the top of every page shows one persistent, specific instruction — what is happening,
the force, what to do — in English and in Spanish, hides it once the status no longer does, and
warns before a Reset hands the load back to drives that cannot hold it."""
from __future__ import annotations

import gui_support  # noqa: F401  (offscreen platform before Qt)
import pytest

from app.i18n import install_language
from app.status_band import StatusBand
from app.words import cause_words

#: The alarm as ``Supervisor.alarms`` puts it in the status (the 700 kg twin run's figures).
ALARM = {"cause": "pull_in_stop", "fz_n": -1732.9, "since_t": 3.054,
         "message": "the foot is still pulled (-1733 N) in the stop: ..."}


def _status(alarms: list[dict]) -> dict:
    return {"state": "hard_stop", "latched": [{"id": 6, "cause": "force_limit",
                                               "reaction": "hard_stop"}],
            "alarms": alarms, "owner": None, "session": None}


@pytest.fixture()
def band(qtbot):
    b = StatusBand()
    qtbot.addWidget(b)
    b.resize(1100, 200)
    b.show()
    return b


def test_the_pull_alarm_stays_in_the_band_while_the_status_carries_it(band):
    label = band.alarm_label
    assert label.isHidden()
    band.update_status(_status([ALARM]), True)
    assert label.isVisible()
    text = label.text()
    for words in ("1733 N", "cannot lift", "Support the patient's leg", "release the strap"):
        assert words in text, (words, text)
    # Persistent: every status that carries it keeps it (a newer force is shown), ...
    band.update_status(_status([dict(ALARM, fz_n=-1700.2)]), True)
    assert label.isVisible() and "1700 N" in label.text()
    # ... a status without the field (an older RT process) or none (the link lost) leaves
    # it: the pull is most likely still there, ...
    band.update_status({"state": "hard_stop"}, True)
    band.update_status(None, False, "no reply")
    assert label.isVisible() and "1700 N" in label.text()
    # ... and the status without the alarm (the pull ended) hides it.
    band.update_status(_status([]), True)
    assert label.isHidden() and label.text() == ""


def test_the_alarm_event_shows_it_at_once(band):
    """The published warning shows the instruction before the next status arrives."""
    band.remember_event({"kind": "warn", "cause": "pull_in_stop", "reaction": "warn", "id": 7,
                         "values": {"fz_n": -381.4, "since_t": 3.063, "for_s": 1.0}})
    assert band.alarm_label.isVisible() and "381 N" in band.alarm_label.text()


def test_reset_warns_while_the_strap_is_still_pulled(band):
    band.update_status(_status([ALARM]), True)
    band.reset_button.click()
    text = band.ack_label.text()
    assert text.startswith("The strap is still pulling") and "Reset will clear" in text, text
    # Without the alarm, the acknowledgement lists the faults only.
    band.cancel_button.click()
    band.update_status(_status([]), True)
    band.reset_button.click()
    assert band.ack_label.text().startswith("Reset will clear")


def test_every_page_shows_it(qtbot, tmp_path):
    """The band is the main window's, above whichever page is open."""
    from app.main_window import MainWindow
    from app.settings import GuiSettings

    w = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)))
    qtbot.addWidget(w)
    w.show()
    w.band.update_status(_status([ALARM]), True)
    for page in range(w.stack.count()):
        w.stack.setCurrentIndex(page)
        assert w.band.alarm_label.isVisible(), w.stack.currentWidget()


def test_the_instruction_in_spanish(band):
    install_language("es")
    try:
        band.show_alarms([ALARM])
        text = band.alarm_label.text()
        assert text.startswith("ALARMA") and "1733 N" in text, text
        assert "suelte la correa" in text and "Sujete la pierna" in text, text
        band.update_status(_status([ALARM]), True)
        band.reset_button.click()
        assert band.ack_label.text().startswith("La correa sigue tirando"), \
            band.ack_label.text()
        assert cause_words("contact_lost").startswith("se perdió el contacto")
    finally:
        install_language("en")
