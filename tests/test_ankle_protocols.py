"""Ankle exercises about the patient's ankle centre: the heave that keeps it at its height, the
pre-flight's residual displacement and its refusal naming the ankle angle."""
from __future__ import annotations

import math

import numpy as np
import pytest

from protocols.generators import make_generator
from protocols.library import LIBRARY_DIR, load_protocol
from protocols.schema import validate_protocol_data
from rt.errors import ProtocolValidationError
from rt.model import RobotModel
from rt.model.ankle import AnkleSetup

MODEL = RobotModel.load()
SETUP = AnkleSetup(side="right", height_above_sole_m=0.07)
H_P = MODEL.description.sensor.offset_m[2] + 0.07           # 0.150 m above P's origin
RP = MODEL.description.geometry.platform_radius_m


def rom(plantar: float, dorsi: float = 0.0, **extra) -> dict:
    return {"schema_version": 1, "kind": "ankle_rom", "name": "rom", "pose": {"z_m": 0.63},
            "sequence": ["dorsi_plantar"],
            "amplitude_deg": {"dorsiflexion": dorsi or plantar, "plantarflexion": plantar},
            "speed_deg_s": 20.0, "hold_s": 0.2, "max_acceleration_deg_s2": 200.0,
            "max_jerk_deg_s3": 4000.0, **extra}


def build(doc: dict, ankle: AnkleSetup | None = SETUP):
    return make_generator(validate_protocol_data(doc), kinematics=MODEL.kin, ankle=ankle)


def test_rom_about_the_ankle_raises_the_platform_as_the_hand_formula_says() -> None:
    """Every sample's heave is z0 + h_P (1 - cos β) (pitch only): the ankle keeps its height;
    the report's peak displacement is h_P sin 10° plus the parasitic y, about 26.1 mm."""
    gen = build(rom(10.0))
    report = gen.validate()
    assert report.ok, report.violations
    s = gen.samples()
    pitch, z = s["pose"][:, 2], s["pose"][:, 0]
    assert max(pitch) == pytest.approx(math.radians(10.0), abs=1e-9)
    assert np.allclose(z, 0.63 + H_P * (1.0 - np.cos(pitch)), atol=1e-12)
    b = math.radians(10.0)
    expected = math.hypot(H_P * math.sin(b), RP * (1.0 - math.cos(b)) / 2.0)
    assert report.ankle_peak_displacement_m == pytest.approx(expected, abs=1e-6)
    assert 0.0 < report.ankle_rms_displacement_m < report.ankle_peak_displacement_m


def test_the_slider_velocities_follow_the_heave() -> None:
    """q̇ integrates to q: the heave's contribution is in the slider references."""
    gen = build(rom(10.0))
    assert gen.validate().ok
    s = gen.samples()
    dq = np.diff(s["q"], axis=0) / gen.dt
    mid = 0.5 * (s["qd"][1:] + s["qd"][:-1])
    assert np.max(np.abs(dq - mid)) < 1e-5


def test_preflight_refuses_naming_the_angle_where_the_displacement_exceeds_the_limit() -> None:
    """±20° DF/PF with a 30 mm limit: h_P sin β = 30 mm at β = 11.5°: refused at the first
    angle past that (the sequence starts with dorsiflexion), with the narrowed range to use."""
    gen = build(rom(20.0))
    report = gen.validate()
    assert not report.ok
    (msg,) = [v for v in report.violations if v.startswith("ankle centre")]
    assert msg.startswith("ankle centre: at dorsiflexion") and "comfort limit 30 mm" in msg
    assert "narrow the range in that direction to dorsiflexion 11.5 deg" in msg
    # The named angle is the first beyond the limit (100 Hz evaluation at 20 deg/s: < 0.3°).
    named = float(msg.split("dorsiflexion ")[1].split(" deg")[0])
    limit_deg = math.degrees(math.asin(0.030 / H_P))
    assert limit_deg < named < limit_deg + 0.5
    assert report.ankle_peak_displacement_m > 0.05


def test_the_limit_is_configurable_per_exercise() -> None:
    report = build(rom(20.0, ankle_displacement_limit_mm=60.0)).validate()
    assert report.ok, report.violations
    assert report.ankle_displacement_limit_m == pytest.approx(0.060)


def test_plantarflexion_beyond_the_limit_is_named_as_plantarflexion() -> None:
    report = build(rom(18.0, dorsi=5.0)).validate()
    (msg,) = [v for v in report.violations if v.startswith("ankle centre")]
    assert "at plantarflexion" in msg and "to plantarflexion 11.5 deg" in msg


def test_centre_ankle_without_a_setup_is_refused() -> None:
    with pytest.raises(ProtocolValidationError, match="centre: 'ankle' needs the patient's ankle "
                                                      "setup"):
        build(rom(10.0, centre="ankle"), ankle=None)


def test_without_a_setup_the_exercise_turns_about_the_platform_as_before() -> None:
    gen = build(rom(10.0), ankle=None)
    report = gen.validate()
    assert report.ok and math.isnan(report.ankle_peak_displacement_m)
    assert set(gen.samples()["pose"][:, 0]) == {0.63}


def test_centre_platform_holds_the_heave_and_still_checks_the_displacement() -> None:
    gen = build(rom(10.0, centre="platform"))
    report = gen.validate()
    assert set(gen.samples()["pose"][:, 0]) == {0.63}
    b = math.radians(10.0)
    assert report.ankle_peak_displacement_m == pytest.approx(
        math.hypot(H_P * math.sin(b), RP * (1.0 - math.cos(b)) / 2.0), abs=1e-6)


def test_a_setup_for_the_other_foot_is_refused() -> None:
    with pytest.raises(ProtocolValidationError, match="left foot but the session is for the "
                                                      "right"):
        make_generator(validate_protocol_data(rom(10.0)), kinematics=MODEL.kin, side="right",
                       ankle=AnkleSetup(side="left", height_above_sole_m=0.07))


def test_library_isometric_holds_keep_the_ankle_height() -> None:
    gen = make_generator(load_protocol(LIBRARY_DIR / "isometric.yaml"), kinematics=MODEL.kin,
                         ankle=SETUP)
    assert gen.validate().ok
    s = gen.samples()
    assert np.allclose(s["pose"][:, 0], 0.63 + H_P * (1.0 - np.cos(s["pose"][:, 2])),
                       atol=1e-12)


def test_active_assist_follows_the_ankle_and_bounds_its_displacement() -> None:
    doc = load_protocol(LIBRARY_DIR / "active_assist.yaml").model_dump(mode="json")
    # Its +15° plantarflexion moves the centre 38.9 mm: beyond the default 30 mm limit.
    doc["ankle_displacement_limit_mm"] = 45.0
    gen = make_generator(validate_protocol_data(doc), kinematics=MODEL.kin, ankle=SETUP)
    report = gen.validate()
    assert report.ok, report.violations
    assert report.ankle_peak_displacement_m > 0.0
    out = gen.new_output()
    for _ in range(3000):
        gen.update(out)
    z, roll, pitch = (float(x) for x in out.pose_ref)
    assert z == pytest.approx(gen.ankle.kinematics.z_for(roll, pitch), abs=1e-12)
    wide = {**doc, "rom_deg": {**doc["rom_deg"], "dorsiflexion": 25.0, "plantarflexion": 25.0},
            "guide_period_s": 20.0}
    report = make_generator(validate_protocol_data(wide), kinematics=MODEL.kin,
                            ankle=SETUP).validate()
    assert any(v.startswith("ankle centre") for v in report.violations)


def test_active_assist_takes_the_patients_torque_about_the_ankle() -> None:
    """A 50 N forward push through the ankle centre is no ankle torque: the sensor reads
    m_y = h·f_x about its origin (h = 70 mm), and the generator, moving it to the ankle,
    behaves exactly as with no push; without the setup the same reading is a 3.5 N m effort."""
    from protocols.output import GeneratorInput

    doc = load_protocol(LIBRARY_DIR / "active_assist.yaml").model_dump(mode="json")
    doc["ankle_displacement_limit_mm"] = 45.0

    def run(ankle: AnkleSetup | None, push: bool) -> float:
        gen = make_generator(validate_protocol_data(doc), kinematics=MODEL.kin, ankle=ankle)
        assert gen.validate().ok
        inp, out = GeneratorInput(), gen.new_output()
        if push:
            inp.force_x_n, inp.tau_pitch_nm = 50.0, 0.07 * 50.0
        for _ in range(1500):
            gen.update(out, inp)
        return float(out.pose_ref[2])

    assert run(SETUP, True) == run(SETUP, False)
    assert abs(run(None, True) - run(None, False)) > math.radians(0.5)
