"""The session screen tells the staff what the robot cannot fix (issue 15): while the RT
status carries the ``pull_in_stop`` alarm (a pull that persists after a stop, beyond the
drives) the Run page shows one persistent, specific instruction — what is happening, the
force, what to do — in English and in Spanish, and hides it once the status no longer does."""
from __future__ import annotations

import gui_support  # noqa: F401  (offscreen platform before Qt)
import pytest

from app.i18n import install_language
from app.pages.run import RunPage
from app.rt_link import RtLink
from app.words import cause_words

#: The alarm as ``Supervisor.alarms`` puts it in the status (the 700 kg twin run's figures).
ALARM = {"cause": "pull_in_stop", "fz_n": -1732.9, "since_t": 3.054,
         "message": "the foot is still pulled (-1733 N) in the stop: ..."}


def _status(alarms: list[dict]) -> dict:
    return {"state": "hard_stop", "latched": [{"id": 6, "cause": "force_limit",
                                               "reaction": "hard_stop"}],
            "alarms": alarms, "owner": None, "session": None}


@pytest.fixture()
def page(qtbot):
    link = RtLink("tcp://127.0.0.1:9")      # not started: nothing is contacted
    p = RunPage(link)
    qtbot.addWidget(p)
    p.resize(1100, 640)
    p.show()
    yield p
    link.close()


def test_the_pull_alarm_stays_on_the_run_page_while_the_status_carries_it(page, qtbot):
    label = page.alarm_label
    assert label.isHidden()
    page.link.status_changed.emit(_status([ALARM]))      # as the status watcher delivers it
    assert label.isVisible()
    text = label.text()
    for words in ("1733 N", "cannot lift", "Support the patient's leg", "release the strap"):
        assert words in text, (words, text)
    # Persistent: every status that carries it keeps it (a newer force is shown), ...
    page.link.status_changed.emit(_status([dict(ALARM, fz_n=-1700.2)]))
    assert label.isVisible() and "1700 N" in label.text()
    # ... a status without the field (an older RT process) changes nothing, ...
    page.show_alarms({"state": "hard_stop"})
    assert label.isVisible()
    # ... and the status without the alarm (the pull ended) hides it.
    page.link.status_changed.emit(_status([]))
    assert label.isHidden() and label.text() == ""


def test_the_alarm_event_shows_it_at_once(page):
    """The published warning shows the instruction before the next status arrives."""
    page._event({"kind": "warn", "cause": "pull_in_stop", "reaction": "warn",
                 "values": {"fz_n": -381.4, "since_t": 3.063, "for_s": 1.0}})
    assert page.alarm_label.isVisible() and "381 N" in page.alarm_label.text()


def test_the_instruction_in_spanish(page):
    install_language("es")
    try:
        page.show_alarms(_status([ALARM]))
        text = page.alarm_label.text()
        assert text.startswith("ALARMA") and "1733 N" in text, text
        assert "suelte la correa" in text and "Sujete la pierna" in text, text
        assert cause_words("contact_lost").startswith("se perdió el contacto")
    finally:
        install_language("en")
