"""An ankle exercise about the patient's ankle centre, end to end on the twin: pre-flight
predicts the centre's displacement, the twin's foot turns about the same centre, the summary
gives ankle angles and torques in clinical terms and the recording an ``/ankle/state``
channel."""
from __future__ import annotations

import datetime as dt
import math
import shutil
import subprocess

import jsonschema
import pytest

from protocols.schema import validate_protocol_data
from protocols.session import SessionSetup, preflight, run_session
from reports.session_data import session_input_from_recording
from reports.session_report import render_session_report
from rt.errors import ProtocolValidationError
from rt.model.ankle import AnkleSetup
from rt.recording.channels import ANKLE, CHANNELS
from rt.recording.reader import read_recording

SETUP = AnkleSetup(side="left", height_above_sole_m=0.07, offset_x_m=0.01)


def rom(amplitude: float) -> dict:
    return {"schema_version": 1, "kind": "ankle_rom", "name": "rom",
            "pose": {"z_m": 0.63}, "sequence": ["dorsi_plantar", "inversion_eversion"],
            "amplitude_deg": {"dorsiflexion": amplitude, "plantarflexion": amplitude,
                              "inversion": amplitude, "eversion": amplitude},
            "speed_deg_s": 20.0, "hold_s": 0.3, "max_acceleration_deg_s2": 200.0,
            "max_jerk_deg_s3": 4000.0}


def test_session_about_the_ankle_summarized_and_recorded_in_clinical_terms(tmp_path) -> None:
    out = tmp_path / "rom.mcap"
    setup = SessionSetup(protocol=validate_protocol_data(rom(8.0)), ankle=SETUP)
    s = run_session(setup, out)
    assert s["completed"], s["stops"]
    pre = s["preflight"]["ankle_displacement_mm"]
    # 8°: h_P sin 8° + the parasitic y of roll: 150 mm · 0.139 + 0.9 ≈ 21.8 mm.
    assert 20.0 < pre["peak"] < 23.0 and pre["limit"] == pytest.approx(30.0)
    ankle = s["ankle"]
    assert ankle["side"] == "left"
    for direction in ("dorsiflexion", "plantarflexion", "inversion", "eversion"):
        # The position loop on the twin reaches the commanded 8° within 0.5°.
        assert ankle["rom_deg"][direction] == pytest.approx(8.0, abs=0.5), direction
    # The passive ankle resists: at 8° plantarflexion the twin's joint pushes back with
    # 45 N m/rad · 0.14 rad · (1 + (8/20)²) ≈ 7.3 N m (dorsiflexion torque), the foot's own
    # damping and the residual shank forces add a little.
    assert 5.0 < ankle["peak_torque_nm"]["dorsiflexion"] < 10.0
    assert 5.0 < ankle["peak_torque_nm"]["plantarflexion"] < 10.0
    rec = read_recording(out)
    states = rec[ANKLE]
    assert len(states) > 100
    for m in states[:: max(1, len(states) // 20)]:
        jsonschema.validate(m, CHANNELS[ANKLE].schema)
    peak = max(m["plantarflexion_deg"] for m in states)
    assert peak == pytest.approx(8.0, abs=0.5)
    # About the ankle, the centre's height is held: the recorded vertical displacement stays
    # within the tracking error (≤ 2 mm), its horizontal part is the mechanism's.
    assert max(abs(m["centre_displacement_mm"][2]) for m in states) < 2.0
    assert max(math.hypot(*m["centre_displacement_mm"][:2]) for m in states) > 15.0
    # The session report reads the same channel: clinical angles and torques, the left foot.
    inp = session_input_from_recording(out)
    fig = inp.figures["ankle"]
    assert fig["rom_deg"]["eversion"] == pytest.approx(ankle["rom_deg"]["eversion"], abs=0.2)
    assert fig["peak_torque_nm"]["plantarflexion"] == pytest.approx(
        ankle["peak_torque_nm"]["plantarflexion"], abs=1.0)
    pdf = tmp_path / "rom.pdf"
    render_session_report(inp, pdf, clock=lambda: dt.datetime(2026, 11, 25, tzinfo=dt.UTC))
    if shutil.which("pdftotext"):
        text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True,
                              text=True, check=True).stdout
        assert "Peak plantarflexion torque" in text and "Ankle centre moved" in text
        assert "Foot" in text and "left" in text


def test_preflight_refuses_a_range_the_ankle_centre_cannot_follow() -> None:
    setup = SessionSetup(protocol=validate_protocol_data(rom(15.0)), ankle=SETUP)
    with pytest.raises(ProtocolValidationError, match=r"ankle centre: at dorsiflexion 1[12]\.\d "
                                                      r"deg .* narrow the range"):
        preflight(setup)
