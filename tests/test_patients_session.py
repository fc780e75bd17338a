"""A session run for a patient on the twin is stored with its snapshots and outcome."""
from __future__ import annotations

from pathlib import Path

import pytest

from patients.models import Outcome
from patients.session_record import outcome_of, rt_patient, run_for_patient, twin_runner
from rt.errors import ProtocolValidationError

from patients_helpers import open_record, staff

LIB = Path(__file__).resolve().parents[1] / "protocols" / "library"


def fast(protocol_path):
    """The in-process twin, as fast as possible (``run_session``, the engine of tests)."""
    return twin_runner(protocol_path)


@pytest.fixture()
def clinic(tmp_path):
    record = open_record(str(tmp_path / "talus.db"))
    people = staff(record)
    code = record.add_patient(people.clinician, body_mass_kg=75, affected_side="right")["code"]
    yield record, people, code
    record.close()


def _short_rom(tmp_path: Path) -> Path:
    """ankle_rom, one repetition of pitch only: a short real twin run."""
    text = (LIB / "ankle_rom.yaml").read_text()
    text = text.replace("repetitions: 3", "repetitions: 1").replace(
        "sequence: [dorsi_plantar, inversion_eversion]", "sequence: [dorsi_plantar]")
    path = tmp_path / "short_rom.yaml"
    path.write_text(text)
    return path


def test_a_twin_session_is_stored_with_the_patients_limits(clinic, tmp_path):
    record, people, code = clinic
    record.set_limits(people.clinician, code, pitch_min_deg=-12, pitch_max_deg=12,
                      roll_min_deg=-9, roll_max_deg=9)
    mcap = tmp_path / "rom.mcap"
    protocol = _short_rom(tmp_path)
    stored = run_for_patient(record, people.clinician, code, protocol, mcap, fast(protocol))
    assert stored["outcome"] == "completed" and stored["stopped_by"] is None
    assert stored["limits"]["pitch_max_deg"] == 12 and stored["body_mass_kg"] == 75
    assert stored["recording_path"] == str(mcap) and len(stored["recording_sha256"]) == 64
    import hashlib
    assert hashlib.sha256(mcap.read_bytes()).hexdigest() == stored["recording_sha256"]
    assert stored["summary"]["rom_deg"]["pitch"][1] == pytest.approx(10.0, abs=0.2)


def test_a_refused_preflight_is_stored_as_refused(clinic):
    record, people, code = clinic
    # ankle_rom needs ±10° pitch: a ±5° prescription makes the pre-flight refuse it.
    record.set_limits(people.clinician, code, pitch_min_deg=-5, pitch_max_deg=5,
                      roll_min_deg=-5, roll_max_deg=5)
    with pytest.raises(ProtocolValidationError, match="ROM"):
        run_for_patient(record, people.clinician, code, LIB / "ankle_rom.yaml", None,
                        fast(LIB / "ankle_rom.yaml"))
    [s] = record.list_sessions(people.clinician, code)
    assert s["outcome"] == "refused" and "pre-flight" in s["stopped_by"]


def test_a_crashing_runner_leaves_no_running_session(clinic):
    record, people, code = clinic
    record.set_limits(people.clinician, code)

    def broken(setup, recording):
        raise RuntimeError("backend lost")
    with pytest.raises(RuntimeError):
        run_for_patient(record, people.clinician, code, LIB / "ankle_rom.yaml", None, broken)
    [s] = record.list_sessions(people.clinician, code)
    assert (s["outcome"], s["stopped_by"]) == ("stopped_by_fault",
                                               "software: RuntimeError: backend lost")


def test_the_rt_process_gets_the_code_mass_and_limits_in_force(clinic):
    record, people, code = clinic
    record.set_limits(people.clinician, code, max_force_n=300)
    seen = {}

    def rt_client(started, recording):  # what a runner built on run_remote receives
        seen.update(rt_patient(started))
        return {"completed": True, "stops": [], "recording": {"path": "r.mcap",
                                                                "sha256": "c" * 64}}
    stored = run_for_patient(record, people.clinician, code, LIB / "ankle_rom.yaml", None,
                             rt_client)
    assert seen["id"] == code and seen["weight_kg"] == 75
    assert seen["limits"]["max_force_n"] == 300 and len(seen["limits"]) == 7
    assert (stored["outcome"], stored["recording_sha256"]) == ("completed", "c" * 64)


@pytest.mark.parametrize("summary, expected", [
    ({"completed": True, "stops": []}, (Outcome.COMPLETED, None)),
    ({"completed": False, "stops": [{"cause": "hand_stop", "message": "m"}]},
     (Outcome.STOPPED_BY_USER, "patient: hand_stop")),
    ({"completed": False, "stops": [{"cause": "estop_gui", "message": "m"}]},
     (Outcome.STOPPED_BY_USER, "operator: estop_gui")),
    ({"completed": False, "stops": [{"cause": "max_force", "message": "force 900 N"}]},
     (Outcome.STOPPED_BY_FAULT, "max_force: force 900 N")),
])
def test_outcome_from_the_summary(summary, expected):
    assert outcome_of(summary) == expected
