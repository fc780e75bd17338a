"""Sessions end to end on the twin: pre-flight, run, recording, summary, refusals."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from protocols.library import list_library
from protocols.session import SessionSetup, preflight, run_session
from rt.errors import ProtocolValidationError
from rt.recording.reader import read_recording
from rt.safety.limits import PatientLimits

LIB = {p.name: p for p in list_library()}


def test_sine_fz_session_recorded_and_summarized(tmp_path):
    out = tmp_path / "sine.mcap"
    s = run_session(SessionSetup(LIB["sine_fz.yaml"]), out)
    assert s["completed"] and s["stops"] == []
    # Force tracking on the twin's compliant foot at 1 Hz. Issue 6's target is ≤ 2 % of the
    # amplitude. On the realistic twin (issue 15) the nominal model's per-axis friction is up to
    # 30 % off the truth and the screw's compliance and backlash add their share: with Kp 20
    # the law measured 2.1 %; with Kp 40 (the retune for the realistic plant) 1.3 %.
    assert s["rms_error_pct"] <= 2.0 and s["rms_error_basis"] == "amplitude"
    # The ATI was tared on the unloaded platform before the force play (its tool side and
    # drift: a few N), and the summary (recorded) says so.
    assert s["ati_tare"]["state"] == "done" and abs(s["ati_tare"]["offset_n"][2]) < 10.0
    assert 380.0 <= s["peak_force_n"] <= 420.0          # 300 + 100 N
    rec = read_recording(out)
    state = rec["/robot/state"]
    assert len(state) > 20000                            # ≥ 20 s at 1 kHz
    assert {"/robot/wrench", "/protocol/metadata", "/protocol/reference"} <= set(rec)
    assert rec["/protocol/metadata"][0]["protocol_name"] == s["protocol"]
    assert s["recording"]["sha256"] and len(s["recording"]["sha256"]) == 64
    _first_messages_validate(out)


def _first_messages_validate(path: Path) -> None:
    """The first message of every channel, decoded (JSON or protobuf), validates against the
    channel's JSON Schema (the first wrench once carried nulls from before the sensor's first
    sample)."""
    import jsonschema

    from rt.recording.reader import RecordingScan

    seen: set[str] = set()
    scan = RecordingScan(path)
    for rec in scan:
        if rec.topic not in seen:
            seen.add(rec.topic)
            schema = scan.schema_for(rec.topic)
            assert schema is not None, rec.topic
            jsonschema.validate(rec.payload, schema, cls=jsonschema.Draft202012Validator)
    assert scan.info.complete
    assert {"/robot/wrench", "/robot/state", "/protocol/metadata"} <= seen


@pytest.mark.parametrize("record_as, force, message", [
    ("protocol", True, "is also an input"),
    ("existing", False, "exists; refused"),
])
def test_a_recorded_twin_run_never_overwrites_its_inputs_or_a_file(tmp_path, record_as, force,
                                                                   message):
    """The in-process run (benchmarks, tests); the RT process names its recordings itself and
    creates them exclusively (tests/test_rt_sessions.py)."""
    from rt.errors import TalusError

    protocol = tmp_path / "sine.yaml"
    protocol.write_text(LIB["sine_fz.yaml"].read_text())
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"last week's session")
    target = {"protocol": protocol, "existing": existing}[record_as]
    before = target.read_bytes()
    with pytest.raises(TalusError, match=message):
        run_session(SessionSetup(protocol), target, force=force)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.mcap", "sine.yaml"]


def test_ankle_rom_reaches_its_range():
    s = run_session(SessionSetup(LIB["ankle_rom.yaml"]), None)
    assert s["completed"]
    pitch = s["rom_deg"]["pitch"]
    roll = s["rom_deg"]["roll"]
    # ±10° dorsi/plantar and ±8° inversion/eversion, tracked within a tenth of a degree.
    assert pitch[0] == pytest.approx(-10.0, abs=0.2) and pitch[1] == pytest.approx(10.0, abs=0.2)
    assert roll[0] == pytest.approx(-8.0, abs=0.2) and roll[1] == pytest.approx(8.0, abs=0.2)


def test_preflight_refuses_a_protocol_beyond_the_patients_rom():
    narrow = PatientLimits(roll_min_deg=-5, roll_max_deg=5, pitch_min_deg=-5, pitch_max_deg=5)
    with pytest.raises(ProtocolValidationError, match="leaves the patient's ROM"):
        preflight(SessionSetup(LIB["ankle_rom.yaml"], patient_limits=narrow))


def test_preflight_refuses_a_force_beyond_the_patients_limit():
    weak = PatientLimits(max_force_n=350.0)
    with pytest.raises(ProtocolValidationError, match="force 400.0 N exceeds the patient's 350.0 N"):
        preflight(SessionSetup(LIB["sine_fz.yaml"], patient_limits=weak))


def test_preflight_reports_predicted_peaks():
    report = preflight(SessionSetup(LIB["gait_replay.yaml"], patient_weight_kg=75.0))
    p = report["predicted"]
    assert report["ok"] and p["peak_platform_force_n"] > 300.0
    assert 0.0 < p["peak_actuator_force_n"] <= 2100.0
    assert p["rms_error_pct"] <= 3.0


def test_session_cli_refuses_a_bad_protocol(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("schema_version: 1\nkind: sine_fz\nname: x\nmean_n: -5\n")
    proc = subprocess.run([sys.executable, "-m", "talus", "session", "run", "--protocol",
                           str(bad), "--fast", "--json"],
                           check=False, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 2
    assert "bad.yaml" in json.loads(proc.stdout)["error"]
