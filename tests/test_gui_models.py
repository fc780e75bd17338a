"""The GUI's Qt-free parts: settings file, patient context, clinician words, preview."""
from __future__ import annotations

import json

import gui_support  # noqa: F401  (offscreen platform before Qt)
import numpy as np
import pytest
from pydantic import ValidationError

from app import settings as settings_io
from app.patient_context import PatientContext
from app.preview import compute_preview
from protocols.library import LIBRARY_DIR
from protocols.rt_session import protocol_document
from rt.errors import ConfigurationError, ProtocolValidationError


def test_settings_round_trip_and_atomic_save(tmp_path):
    path = tmp_path / "talus" / "gui.json"
    assert settings_io.load(path) == settings_io.GuiSettings()      # defaults, nothing written
    assert not path.exists()
    s = settings_io.GuiSettings(rt_endpoint="tcp://10.0.0.5:5560", language="es",
                                idle_lock_s=300.0, clinic_name="Hospital La Fe")
    settings_io.save(s, path)
    assert settings_io.load(path) == s
    assert [p.name for p in path.parent.iterdir()] == ["gui.json"]   # no temp file left


def test_bad_settings_file_is_named_and_bad_values_refused(tmp_path):
    path = tmp_path / "gui.json"
    path.write_text(json.dumps({"schema_version": 1, "idle_lock_s": 5}))
    with pytest.raises(ConfigurationError, match=r"gui.json: idle_lock_s"):
        settings_io.load(path)
    with pytest.raises(ValidationError):
        settings_io.GuiSettings(rt_endpoint="not an endpoint")
    with pytest.raises(ValidationError):
        settings_io.GuiSettings(language="fr")


def test_patient_context_is_what_the_rt_process_takes():
    p = PatientContext("P-7", 64.5, {"pitch_min_deg": -10.0, "pitch_max_deg": 8.0})
    assert p.rt_patient() == {"id": "P-7", "weight_kg": 64.5,
                              "limits": {"pitch_min_deg": -10.0, "pitch_max_deg": 8.0}}
    assert p.patient_limits().pitch_max_deg == 8.0
    with pytest.raises(ValidationError):
        PatientContext("P-8", None, {"pitch_min_deg": 5.0, "pitch_max_deg": 1.0}).patient_limits()


def test_cause_words_are_a_clinicians(qapp):
    from app.words import cause_words, display_state, event_words

    assert cause_words("hand_stop") == "the patient pressed the hand switch"
    assert cause_words("force_limit") == "force above the patient's limit"
    assert cause_words("stroke_2") == "actuator 3 at the end of its travel"
    assert cause_words("something_new") == "something_new"     # never hidden
    assert event_words({"cause": "rom_pitch", "values": {"angle_deg": 15.26}}) == \
        "dorsi/plantarflexion at the end of the patient's range (15.3°)"
    assert display_state(None, True) == "disconnected"
    assert display_state({"state": "run", "session": "s1"}, True) == "running"
    assert display_state({"state": "run", "session": None, "phase_name": "rest"}, True) == "idle"
    assert display_state({"state": "soft_stop"}, True) == "soft_stop"
    assert display_state({"state": "run"}, False) == "disconnected"


def test_preview_of_the_sine_is_the_prescribed_force():
    doc = protocol_document(LIBRARY_DIR / "sine_fz.yaml")
    doc.update(cycles=2, ramp_in_s=1.0, ramp_out_s=1.0)
    pv = compute_preview(doc)
    assert pv.force_protocol and not pv.violations
    # mean 300 N ± 100 N in the play phase: the peaks are 400 N and 200 N (± 1 N of sampling)
    assert np.max(pv.fz_n) == pytest.approx(400.0, abs=1.0)
    assert pv.duration_s >= 2 + 1 + 1 - 0.05
    doc["amplitude_n"] = 400.0            # pulls below zero: the schema refuses it
    with pytest.raises(ProtocolValidationError, match="amplitude_n"):
        compute_preview(doc)


def test_record_instants_read_in_local_time(monkeypatch):
    import time

    from app.words import local_time

    monkeypatch.setenv("TZ", "Europe/Madrid")
    time.tzset()
    try:
        # The clinical record stores UTC; a Madrid clinic reads 21:57 UTC in November as 22:57.
        assert local_time("2026-11-25T21:57:03.123456+00:00") == "2026-11-25 22:57"
        assert local_time("2026-11-25T21:57:03") == "2026-11-25 22:57"   # naive = UTC
        assert local_time("2026-07-01T10:00:00+00:00") == "2026-07-01 12:00"   # summer time
        assert local_time("not a date") == "not a date" and local_time(None) == "—"
    finally:
        monkeypatch.undo()
        time.tzset()


def test_every_cause_the_robot_reports_has_a_clinicians_words(qapp):
    """Every cause the supervisor, the drives' failover and the loop's components can latch
    is shown in words, never as its internal name."""
    from app.words import cause_words
    from rt.safety.supervisor import CAUSES

    others = ["estop_gui", "estop_keyboard", "estop_cli", "stop_client", "heartbeat_lost",
              "component_failed", "dac_card_0", "dac_card_1"]
    for cause in (*CAUSES, *others):
        words = cause_words(cause)
        assert words != cause and "_" not in words, cause
    assert cause_words("dac_card_1") == "motor drive card 2 failed; the spare card took over"
    assert cause_words("estop_pedal") == "E-STOP (pedal)"
