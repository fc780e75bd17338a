"""The patient's ankle setup in the clinical record (SQLite and PostgreSQL): entered, refused
when implausible (nothing stored), its history kept, carried into a session's start and on to
the RT process's ``session_start.patient``."""
from __future__ import annotations

import datetime as dt
from pathlib import Path

import pytest
from patients_helpers import PROTOCOL, Clock, open_record, staff

from patients.errors import InputError, PermissionDenied
from patients.service import Identity
from patients.session_record import rt_patient
from rt.model.ankle import AnkleSetup


@pytest.fixture()
def record(database_url):
    rec = open_record(database_url, Clock())
    yield rec
    rec.close()


def _patient(record, people) -> str:
    return record.add_patient(people.clinician, identity=Identity(
        "Ana Ruiz", dt.date(1970, 1, 2), None, None), body_mass_kg=70.0,
        affected_side="right")["code"]


def test_ankle_setup_entered_kept_and_sent_with_the_session(record) -> None:
    people = staff(record)
    code = _patient(record, people)
    assert record.ankle_in_force(people.viewer, code) is None
    record.set_ankle(people.clinician, code, height_above_sole_m=0.072, offset_x_m=0.015)
    new = record.set_ankle(people.clinician, code, offset_y_m=-0.01, source="camera",
                           reason="measured with malleolus markers")
    # Unset fields keep the values in force; the side defaults to the affected side.
    assert new["side"] == "right" and new["height_above_sole_m"] == 0.072
    assert new["offset_x_m"] == 0.015 and new["offset_y_m"] == -0.01
    assert new["source"] == "camera"
    assert AnkleSetup(**record.ankle_in_force(people.viewer, code)).offset_y_m == -0.01
    record.set_limits(people.clinician, code, pitch_min_deg=-10, pitch_max_deg=10)
    started = record.start_session(people.clinician, code, Path(PROTOCOL).read_text())
    assert started["ankle"]["height_above_sole_m"] == 0.072
    assert rt_patient(started)["ankle"] == started["ankle"]


@pytest.mark.parametrize("fields, words", [
    ({"height_above_sole_m": -0.02}, "below the sole"),
    ({"height_above_sole_m": 72.0}, "not a plausible"),
    ({"height_above_sole_m": 0.07, "offset_x_m": 3.0}, "outside the platform"),
    ({"offset_x_m": 0.01}, "height_above_sole_m"),
    ({"height_above_sole_m": 0.07, "knee": 1.0}, "unknown ankle field"),
])
def test_an_implausible_ankle_setup_is_refused_and_nothing_is_stored(record, fields,
                                                                     words) -> None:
    people = staff(record)
    code = _patient(record, people)
    with pytest.raises(InputError, match=words):
        record.set_ankle(people.clinician, code, **fields)
    assert record.ankle_in_force(people.clinician, code) is None


def test_only_a_clinician_enters_the_ankle_setup(record) -> None:
    people = staff(record)
    code = _patient(record, people)
    with pytest.raises(PermissionDenied):
        record.set_ankle(people.viewer, code, height_above_sole_m=0.07)
