"""Isometric holds with an ankle-torque target (issue 17): the schema, the regulation against a
hand-computed spring ankle, the worst-case bounds pre-flight checks, the per-hold figures,
and on the twin's passive ankle the torque reported against the target and the truth."""
from __future__ import annotations

import datetime as dt
import itertools
import math
import shutil
import subprocess

import numpy as np
import pytest

from protocols.generators import make_generator
from protocols.output import GeneratorInput, GeneratorStatus
from protocols.schema import validate_protocol_data
from protocols.session import SessionSetup, preflight, run_session
from protocols.torque_hold import TorqueHoldFigures, TorqueHoldGenerator
from reports.session_data import session_input_from_recording
from reports.session_report import render_session_report
from rt.errors import ProtocolValidationError
from rt.model import RobotModel
from rt.model.ankle import AnkleSetup, ankle_torques
from rt.safety.limits import PatientLimits

MODEL = RobotModel.load()
RIGHT = AnkleSetup(side="right", height_above_sole_m=0.07, offset_x_m=0.01)
LEFT = AnkleSetup(side="left", height_above_sole_m=0.07)


def holds(*targets: tuple[str, float], hold_s: float = 2.0, pitch_deg: float = 0.0,
          limit_mm: float | None = None, **control) -> dict:
    doc = {"schema_version": 1, "kind": "isometric_hold", "name": "torque holds",
           "pose": {"z_m": 0.63},
           "holds": [{"roll_deg": 0.0, "pitch_deg": pitch_deg, "hold_s": hold_s,
                      "rest_s": 0.2, "torque": {"direction": d, "target_nm": t}}
                     for d, t in targets],
           "transition_speed_deg_s": 10.0}
    if control:
        doc["torque_control"] = control
    if limit_mm is not None:
        doc["ankle_displacement_limit_mm"] = limit_mm
    return doc


def generator(doc: dict, ankle: AnkleSetup | None = RIGHT) -> TorqueHoldGenerator:
    gen = make_generator(validate_protocol_data(doc), kinematics=MODEL.kin, ankle=ankle)
    assert isinstance(gen, TorqueHoldGenerator)
    return gen


@pytest.mark.parametrize("change, words", [
    ({"target_nm": 150.0}, "less than or equal to 100"),
    ({"direction": "flexion"}, "plantarflexion"),
    ({"target_nm": 0.0}, "greater than 0"),
])
def test_a_malformed_torque_target_is_refused_naming_the_field(change, words) -> None:
    doc = holds(("plantarflexion", 5.0))
    doc["holds"][0]["torque"].update(change)
    with pytest.raises(ProtocolValidationError, match=rf"holds\[0\]\.torque\.\w+: .*{words}"):
        validate_protocol_data(doc)


def test_a_return_too_fast_for_the_excursion_is_refused() -> None:
    # From 20° in (1.0 - 10/60) s: π·20/(2·0.833) = 37.7 deg/s > 10 deg/s.
    with pytest.raises(ProtocolValidationError,
                       match=r"torque_control\.return_s: 1 s is too short.*37\.7 deg/s"):
        validate_protocol_data(holds(("plantarflexion", 5.0), max_excursion_deg=20.0,
                                     return_s=1.0))


def test_a_torque_target_without_the_ankle_setup_is_refused() -> None:
    doc = holds(("plantarflexion", 5.0))
    doc["holds"].insert(0, {"roll_deg": 0.0, "pitch_deg": 0.0, "hold_s": 1.0})
    with pytest.raises(ProtocolValidationError,
                       match=r"holds\[1\]\.torque: .*no ankle setup was given"):
        make_generator(validate_protocol_data(doc), kinematics=MODEL.kin)


def test_the_target_ramps_in_holds_and_ramps_out() -> None:
    gen = generator(holds(("dorsiflexion", 6.0)))
    (w,) = gen.windows
    # Dorsiflexion is negative pitch torque; 1 s ramps at 1 kHz; hold 2 s.
    assert (w.axis, w.clinical_sign, w.platform_target_nm) == (1, -1.0, -6.0)
    assert w.k_full - w.k_arrive == 1000 and w.k_release - w.k_full == 2000
    assert w.target_at(w.k_arrive) == 0.0 and w.target_at(w.k_zero) == 0.0
    assert w.target_at((w.k_arrive + w.k_full) // 2) == pytest.approx(-3.0)
    assert w.target_at(w.k_full) == w.target_at(w.k_release) == -6.0
    ramp = [w.target_at(k) for k in range(w.k_arrive, w.k_full + 1)]
    assert all(b <= a for a, b in itertools.pairwise(ramp))


def _drive(gen: TorqueHoldGenerator, stiffness: float) -> np.ndarray:
    """Play the generator against a linear spring ankle about the pitch/roll it starts at:
    the torque about the ankle centre is -K (angle - angle at arrival) on the window's axis
    (the force is zero, so the sensor's moment is the ankle's). Rows: k, roll, pitch, vr, vp."""
    report = gen.validate()
    assert report.ok, report.violations
    out, inp = gen.new_output(), GeneratorInput()
    (w,) = gen.windows
    rows = []
    while True:
        k = gen.index
        status = gen.update(out, inp)
        assert status >= 0, status
        r, p = float(out.pose_ref[1]), float(out.pose_ref[2])
        rows.append((k, r, p, float(out.pose_dot_ref[1]), float(out.pose_dot_ref[2])))
        inp.tau_roll_nm = -stiffness * (r - w.roll_rad)
        inp.tau_pitch_nm = -stiffness * (p - w.pitch_rad)
        if status == GeneratorStatus.FINISHED:
            return np.array(rows)


def test_a_spring_ankle_settles_where_its_torque_meets_the_target() -> None:
    gen = generator(holds(("plantarflexion", 6.0), hold_s=3.0))
    (w,) = gen.windows
    k_stiff = 45.0
    rows = _drive(gen, k_stiff)
    at = {int(k): (p, vp) for k, _, p, _, vp in rows}
    # Hand statics: -K θ = τ* → θ = -6/45 rad = -7.64° (the foot dorsiflexed until its
    # plantarflexors' passive torque is the 6 N m plantarflexion target). With I = 0.2,
    # B = 20, K = 45 the slow pole is 2.4 /s: 3 s at full target leaves e^-7 ≈ 0.1 %.
    p_end, vp_end = at[w.k_release]
    assert math.degrees(p_end - w.pitch_rad) == pytest.approx(-math.degrees(6.0 / 45.0),
                                                              abs=0.05)
    assert abs(vp_end) < 1e-3
    # The torque the spring puts on the platform tracks the target at the end of the hold.
    assert -k_stiff * (p_end - w.pitch_rad) == pytest.approx(6.0, abs=0.05)
    # Back at the hold's angle after the return, at rest, and the program ends at neutral.
    assert at[w.k_back] == (pytest.approx(w.pitch_rad, abs=1e-9), pytest.approx(0.0, abs=1e-9))
    assert rows[-1, 2] == pytest.approx(0.0, abs=1e-12)
    # Never faster than the limit, never beyond the excursion; roll untouched.
    assert np.abs(rows[:, 4]).max() <= math.radians(10.0) + 1e-9
    assert np.abs(rows[:, 2] - w.pitch_rad).max() <= math.radians(10.0) + 1e-9
    assert np.abs(rows[:, 1]).max() == 0.0


def test_a_yielding_patient_is_turned_at_most_the_excursion_and_braked_there() -> None:
    # Inversion 5 N m on a left foot (inversion = -roll) with no resistance at all: the
    # platform turns the foot at the limits until it stops exactly at the excursion.
    gen = generator(holds(("inversion", 5.0), hold_s=3.0, max_excursion_deg=6.0),
                    ankle=LEFT)
    (w,) = gen.windows
    assert (w.axis, w.clinical_sign) == (0, -1.0)
    rows = _drive(gen, 0.0)
    roll = rows[:, 1]
    # The platform pushes against the inversion effort: eversion, i.e. +roll on a left foot.
    assert roll.max() == pytest.approx(math.radians(6.0), abs=1e-9)
    assert roll.min() >= -1e-12
    assert np.abs(rows[:, 3]).max() <= math.radians(10.0) + 1e-9
    # Arrives at the bound with its rate, not by the clamp: the rate before the bound falls.
    k_hit = int(np.argmax(roll >= math.radians(6.0) - 1e-12))
    assert abs(rows[k_hit - 1, 3]) < math.radians(1.0)


def test_validation_bounds_the_regulated_hold_for_any_patient() -> None:
    gen = generator(holds(("plantarflexion", 5.0), pitch_deg=8.0))
    # 18° about a centre 150 mm above the joint plane moves it ~46 mm: the comfort limit
    # (30 mm) is checked over the regulated range too, naming the angle.
    refused = gen.validate()
    assert any("ankle centre: at plantarflexion" in v for v in refused.violations)
    gen = generator(holds(("plantarflexion", 5.0), pitch_deg=8.0, limit_mm=60.0))
    report = gen.validate()
    assert report.ok, report.violations
    # The hold's angle ± the 10° excursion, and the admittance's speed limit.
    assert math.degrees(report.pitch_range_rad[1]) == pytest.approx(18.0)
    assert math.degrees(report.pitch_range_rad[0]) == pytest.approx(-2.0, abs=1e-9)
    assert math.degrees(report.peak_pitch_rate_rad_s) == pytest.approx(10.0)
    # A patient whose ROM ends at 15° plantarflexion: refused naming the pitch range.
    problems = report.check_against(PatientLimits(pitch_max_deg=15.0))
    assert problems and "pitch" in problems[0] and "18.00" in problems[0]


def test_per_hold_figures_match_hand_statics() -> None:
    gen = generator(holds(("inversion", 4.0)), ankle=LEFT)
    figures = TorqueHoldFigures(gen.info["torque_holds"], LEFT)
    (w,) = gen.windows
    n = w.k_back + 10
    wrench = np.zeros((n, 6))
    # A left foot's inversion effort presses its lateral border (-y) down: -mx about the
    # ankle. Sensor moment mx = -4 N m plus a 20 N push forward (fx) at the sole, whose
    # moment about the ankle centre 70 mm above is nil on x: the reported inversion is 4.
    wrench[:, 3] = -4.0
    wrench[:, 0] = 20.0
    truth = np.zeros((n, 2))
    truth[:, 0] = -4.1
    figures.add(wrench, truth)
    (h,) = figures.result()
    assert ankle_torques(wrench[0], LEFT)[1] == pytest.approx(4.0)
    assert h["direction"] == "inversion" and h["samples"] == w.k_release - w.k_full + 1
    assert h["reported_mean_nm"] == pytest.approx(4.0)
    assert h["rms_error_to_target_nm"] == pytest.approx(0.0, abs=1e-12)
    assert h["true_mean_nm"] == pytest.approx(4.1)
    assert h["rms_reported_vs_true_nm"] == pytest.approx(0.1)


def test_preflight_on_the_twin_reports_the_torque_against_target_and_truth() -> None:
    doc = holds(("plantarflexion", 6.0), hold_s=4.0)
    pre = preflight(SessionSetup(protocol=validate_protocol_data(doc), ankle=RIGHT), MODEL)
    (h,) = pre["predicted"]["ankle_torque_holds"]
    # The loop regulates the reported torque to the target: the twin's ankle (45 N m/rad,
    # rising towards 20°) settles at about 6.9° of dorsiflexion with the admittance's slow
    # pole K/B = 2.25 /s, so the torque still lags by ~2 N m when the ramp ends and meets the
    # target within 0.05 N m after 2 s (measured); the mean over the 4 s is ~0.3 N m low.
    assert h["reported_mean_nm"] == pytest.approx(6.0, abs=0.5)
    assert h["rms_error_to_target_nm"] < 1.0
    # What the product reports is the twin ankle's true joint torque within the sensor's
    # noise and filter lag (0.05 N m RMS measured at fixed angles: bench/ankle.py).
    assert h["true_mean_nm"] == pytest.approx(6.0, abs=0.4)
    assert h["rms_reported_vs_true_nm"] < 0.3


def test_the_session_and_its_report_give_each_hold_against_target_and_truth(tmp_path) -> None:
    out = tmp_path / "holds.mcap"
    doc = holds(("dorsiflexion", 5.0), hold_s=3.0)
    s = run_session(SessionSetup(protocol=validate_protocol_data(doc), ankle=RIGHT), out)
    assert s["completed"], s["stops"]
    (h,) = s["ankle"]["torque_holds"]
    assert h["direction"] == "dorsiflexion" and h["target_nm"] == 5.0
    assert h["reported_mean_nm"] == pytest.approx(5.0, abs=0.6)
    # In process the twin's truth is beside the rows: the reported torque is the true one.
    assert h["rms_reported_vs_true_nm"] < 0.3
    assert s["preflight"]["ankle_torque_holds"][0]["rms_reported_vs_true_nm"] < 0.3
    assert "source" not in s      # the holds' windows are not a replayed record's source
    inp = session_input_from_recording(out)
    inp.summary = s               # the RT process writes it into /session/summary
    pdf = tmp_path / "holds.pdf"
    render_session_report(inp, pdf, clock=lambda: dt.datetime(2026, 11, 25, tzinfo=dt.UTC))
    if shutil.which("pdftotext"):
        text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True,
                              text=True, check=True).stdout
        assert "Hold 1: dorsiflexion torque" in text and "target 5.0 N·m" in text
        assert "pre-flight (twin)" in text
