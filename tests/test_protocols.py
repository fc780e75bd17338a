"""Protocols: the library, file validation, and the generators (sine Fz, ankle ROM, isometric
holds, active assist, position playback); gait replay is in test_protocols_gait.py.

Tolerances: references computed in float64 from closed forms are compared to 1e-9 relative
(round-off); limits are checked with 1e-9 relative slack. Slider velocities/accelerations are
compared with difference quotients of the slider positions, which differ from the exact values
by O(dt²·q''') — 1e-6 m/s and 1e-3 m/s² at 1 kHz for these gentle motions.
"""
from __future__ import annotations

import math
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from protocols import (
    GeneratorInput,
    GeneratorStatus,
    Mode,
    ReferenceOutput,
    list_library,
    load_protocol,
    make_generator,
)
from protocols.generators import (
    ActiveAssistGenerator,
    AnkleRomGenerator,
    PositionPlaybackGenerator,
    SineFzGenerator,
)
from protocols.library import LIBRARY_DIR, parse_protocol_text
from protocols.library_data import GAIT_CSV, PLAYBACK_CSV, playback_demo_q
from rt.errors import ConfigurationError, ProtocolValidationError
from rt.references.playback import load_csv
from rt.safety.limits import PatientLimits, RobotLimits

DT = 1e-3
RAD = math.radians


def gen_from(text: str, robot, tmp_path: Path | None = None, **kw):
    source = str(tmp_path / "p.yaml") if tmp_path is not None else "<test>"
    proto = parse_protocol_text(text, source)
    kw.setdefault("dt", DT)
    return make_generator(proto, kinematics=robot.kin, **kw)


def library_text(name: str) -> str:
    return (LIBRARY_DIR / name).read_text()


def run_all(gen, inp=None, n_max=None):
    """Step a generator to the end; returns the per-cycle buffers (n, 19) and statuses."""
    out = ReferenceOutput()
    rows, statuses = [], []
    for _ in range(n_max or gen.n_samples + 5):
        st = gen.update(out, inp)
        statuses.append(st)
        rows.append(out.buf.copy())
        if st == GeneratorStatus.FINISHED or st < 0:
            break
    return np.array(rows), statuses


# ------------------------------------------------------------------------------ library
def test_library_holds_the_required_protocols():
    names = {p.name for p in list_library()}
    assert {"sine_fz.yaml", "gait_replay.yaml", "ankle_rom.yaml", "isometric.yaml",
            "active_assist.yaml", "position_playback.yaml"} <= names
    assert (LIBRARY_DIR / GAIT_CSV).is_file() and (LIBRARY_DIR / PLAYBACK_CSV).is_file()


@pytest.mark.parametrize("path", list_library(), ids=lambda p: p.name)
def test_every_library_file_loads_and_validates(path, robot):
    proto = load_protocol(path)
    assert proto.loaded_from == path.resolve()
    gen = make_generator(proto, dt=DT, kinematics=robot.kin, patient_weight_kg=70.0)
    report = gen.validate()
    assert report.ok, report.summary()
    assert report.duration_s > 0.0 and report.n_samples == gen.n_samples
    # Within a default patient's limits and the robot's, as shipped.
    assert report.check_against(PatientLimits(), RobotLimits()) == []
    out = gen.new_output()
    assert gen.update(out) in (GeneratorStatus.RUNNING, GeneratorStatus.FINISHED)
    assert out.mode == gen.mode and out.index == 0


def test_library_data_files_are_reproducible(robot):
    """The shipped playback CSV is what protocols.library_data writes."""
    t, q, _ = load_csv(LIBRARY_DIR / PLAYBACK_CSV)
    t_ref, q_ref = playback_demo_q(robot.kin)
    np.testing.assert_allclose(t, t_ref, atol=1e-9)
    np.testing.assert_allclose(q, q_ref, atol=6e-8)  # written with 0.1 µm resolution


# ------------------------------------------------------------------------------ malformed files
SINE = library_text("sine_fz.yaml")
ROM = library_text("ankle_rom.yaml")
ASSIST = library_text("active_assist.yaml")
GAIT = library_text("gait_replay.yaml")

YAML_CASES = [
    # (id, text, expected fragments: line / field / reason)
    ("yaml syntax", SINE.replace("mean_n: 300.0", "mean_n: [300.0"),
     ["line 14, column", "YAML syntax error"]),
    ("duplicate key", SINE + "cycles: 3\n", ["duplicate key 'cycles' (first at line 16)"]),
    ("unknown kind", SINE.replace("kind: sine_fz", "kind: sine_fx"),
     ["line 4", "kind: unknown kind 'sine_fx' (known: sine_fz, gait_replay"]),
    ("missing kind", SINE.replace("kind: sine_fz\n", ""), ["kind: required field is missing"]),
    ("unknown key", SINE.replace("  roll_deg: 0.0", "  rol_deg: 0.0"),
     ["line 11", "pose.rol_deg: unknown key (allowed here: z_m, roll_deg, pitch_deg)"]),
    ("out of range", SINE.replace("frequency_hz: 1.0", "frequency_hz: -1.0"),
     ["line 15", "frequency_hz: Input should be greater than 0 (got -1.0)"]),
    ("amplitude above mean", SINE.replace("amplitude_n: 100.0", "amplitude_n: 400.0"),
     ["line 14", "amplitude_n: 400.0 N exceeds mean_n 300.0 N"]),
    ("schema_version 2", SINE.replace("schema_version: 1", "schema_version: 2"),
     ["line 3", "schema_version: unsupported version 2: this talus reads up to 1"]),
    ("schema_version missing", SINE.replace("schema_version: 1\n", ""),
     ["schema_version: required field is missing"]),
    ("field missing", SINE.replace("cycles: 20\n", ""), ["cycles: required field is missing"]),
    ("nan", SINE.replace("mean_n: 300.0", "mean_n: .nan"),
     ["line 13", "mean_n: Input should be a finite number"]),
    ("wrong type", SINE.replace("cycles: 20", "cycles: twenty"),
     ["line 16", "cycles: Input should be a valid integer"]),
    ("limits unordered",
     SINE.replace("  max_force_n: 500.0", "  roll_min_deg: 5\n  roll_max_deg: -5"),
     ["line 20", "limits.roll_min_deg: must be below roll_max_deg"]),
    ("unknown limit", SINE.replace("  max_force_n: 500.0", "  max_torque_nm: 5"),
     ["limits.max_torque_nm: unknown key (allowed here: roll_min_deg"]),
    ("not a mapping", "- sine_fz\n- 300\n", ["the file must hold a mapping"]),
    ("empty", "# nothing\n", ["the file is empty"]),
    ("rom direction missing", ROM.replace("  inversion: 8.0\n", ""),
     ["amplitude_deg.inversion: must be set and > 0 deg: the movement 'inversion_eversion'"]),
    ("rom sequence item", ROM.replace("[dorsi_plantar, inversion_eversion]", "[dorsi, eversion]"),
     ["sequence[0]: Input should be 'dorsi_plantar', 'inversion_eversion' or 'circuit'"]),
    ("assist ramp longer than protocol", ASSIST.replace("duration_s: 60.0", "duration_s: 3.0"),
     ["ramp_s: ramps in and out (4 s) are longer than the protocol (duration_s 3 s)"]),
    ("assist guide too fast", ASSIST.replace("guide_period_s: 8.0", "guide_period_s: 2.0"),
     ["guide_period_s: 2 s is too short", "39.3 deg/s, above max_speed_deg_s 20"]),
    ("assist admittance missing", ASSIST.replace("  pitch:\n", "  roll:\n"),
     ["admittance.pitch: is required: the exercise moves 'dorsi_plantar'"]),
    ("gait source format", GAIT.replace("gait_walk_70kg.csv", "gait.txt"),
     ["source: must name a .c3d or .csv file (got 'gait.txt')"]),
    ("gait plate on csv", GAIT.replace("stance:", "plate_index: 1\nstance:"),
     ["plate_index: applies to C3D sources only"]),
    ("gait plate missing for c3d", GAIT.replace("gait_walk_70kg.csv", "walk.c3d"),
     ["plate_index: is required for a C3D source"]),
    ("gait stance window reversed", GAIT.replace(
        "  select: auto\n  threshold_n: 20.0", "  select: explicit\n  start_s: 0.5\n  end_s: 0.2"),
     ["stance.end_s: must be after start_s"]),
    ("gait stance unknown selection", GAIT.replace("select: auto", "select: best"),
     ["stance", "'auto', 'explicit'"]),
]


@pytest.mark.parametrize("case,text,fragments", YAML_CASES, ids=[c[0] for c in YAML_CASES])
def test_malformed_protocol_files_are_refused_naming_file_field_and_reason(tmp_path, case, text,
                                                                          fragments):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ProtocolValidationError) as exc:
        load_protocol(path)
    msg = str(exc.value)
    assert msg.startswith(str(path)), msg
    for fragment in fragments:
        assert fragment in msg, msg


def test_unreadable_and_binary_files_are_refused(tmp_path):
    with pytest.raises(ProtocolValidationError, match="cannot read protocol .*missing.yaml"):
        load_protocol(tmp_path / "missing.yaml")
    path = tmp_path / "binary.yaml"
    path.write_bytes(b"\xff\xfe\x00kind")
    with pytest.raises(ProtocolValidationError, match="not UTF-8 text"):
        load_protocol(path)


def test_every_problem_of_a_file_is_listed():
    text = SINE.replace("frequency_hz: 1.0", "frequency_hz: 0").replace("cycles: 20", "cycles: 0")
    with pytest.raises(ProtocolValidationError) as exc:
        parse_protocol_text(text, "two.yaml")
    lines = str(exc.value).splitlines()
    assert len(lines) == 2 and "frequency_hz" in lines[0] and "cycles" in lines[1]


def test_a_protocol_beyond_its_own_limits_is_reported_and_not_run(robot):
    gen = gen_from(SINE.replace("max_force_n: 500.0", "max_force_n: 350.0"), robot)
    report = gen.validate()
    assert not report.ok
    assert report.violations == [("limits.max_force_n: the force reaches 400.0 N, above the "
                                 "protocol's 350.0 N")]
    assert gen.update(ReferenceOutput()) == GeneratorStatus.ERROR_NOT_VALIDATED
    with pytest.raises(ProtocolValidationError, match="protocol 'Sine Fz.*' refused: limits"):
        report.raise_if_failed()


def test_a_pose_outside_the_workspace_is_reported(robot):
    report = gen_from(SINE.replace("z_m: 0.63", "z_m: 0.30"), robot).validate()
    assert not report.ok and "pose: outside the workspace: slider 1" in report.violations[0]


def test_update_before_validate_is_refused(robot):
    gen = gen_from(SINE, robot)
    out = ReferenceOutput()
    assert gen.update(out) == GeneratorStatus.ERROR_NOT_VALIDATED
    assert np.isnan(out.fz_ref)  # untouched


def test_make_generator_refuses_bad_arguments(robot):
    proto = parse_protocol_text(SINE)
    with pytest.raises(ConfigurationError, match="dt must be"):
        make_generator(proto, dt=0.5, kinematics=robot.kin)
    with pytest.raises(ConfigurationError, match="side must be"):
        make_generator(proto, kinematics=robot.kin, side="both")


# ------------------------------------------------------------------------------ sine Fz
def sine_text(mean=300.0, amp=100.0, f=1.0, cycles=20, ramp_in=2.0, ramp_out=2.0) -> str:
    return (f"schema_version: 1\nkind: sine_fz\nname: s\npose: {{z_m: 0.63}}\nmean_n: {mean}\n"
            f"amplitude_n: {amp}\nfrequency_hz: {f}\ncycles: {cycles}\nramp_in_s: {ramp_in}\n"
            f"ramp_out_s: {ramp_out}\n")


def test_sine_mean_amplitude_frequency_are_exact_by_fft(robot):
    gen = gen_from(SINE, robot)
    assert isinstance(gen, SineFzGenerator) and gen.mode == Mode.FORCE
    assert gen.validate().ok
    fz = gen.samples()["fz"]
    i0, n = 2000, 20_000  # the 20 full-amplitude cycles
    spectrum = np.fft.rfft(fz[i0:i0 + n]) / n
    freqs = np.fft.rfftfreq(n, DT)
    assert spectrum[0].real == pytest.approx(300.0, rel=1e-12)
    k = int(np.argmax(np.abs(spectrum[1:]))) + 1
    assert freqs[k] == pytest.approx(1.0, rel=1e-12)
    assert 2.0 * abs(spectrum[k]) == pytest.approx(100.0, rel=1e-12)
    others = np.delete(np.abs(spectrum[1:]), k - 1)
    assert others.max() < 1e-9  # a pure sine: no other component


def test_sine_fit_on_an_off_grid_frequency(robot):
    """Least-squares fit of mean + a sin + b cos at 2.7 Hz (period not a multiple of dt)."""
    gen = gen_from(sine_text(mean=250.0, amp=80.0, f=2.7, cycles=9, ramp_in=1.3, ramp_out=0.7),
                   robot)
    assert gen.validate().ok
    s = gen.samples()
    t, fz = s["t"], s["fz"]
    steady = (t >= 1.3) & (t <= 1.3 + 9 / 2.7)
    w = 2 * math.pi * 2.7
    a = np.column_stack([np.ones(steady.sum()), np.sin(w * (t[steady] - 1.3)),
                         np.cos(w * (t[steady] - 1.3))])
    coef, *_ = np.linalg.lstsq(a, fz[steady], rcond=None)
    assert coef[0] == pytest.approx(250.0, rel=1e-12)
    assert math.hypot(coef[1], coef[2]) == pytest.approx(80.0, rel=1e-12)
    assert abs(coef[2]) < 1e-9  # phase 0 at the end of the ramp in
    assert gen.duration_s == pytest.approx(1.3 + 9 / 2.7 + 0.7, abs=DT)


def test_sine_ramps_start_and_end_at_zero_with_continuous_rate(robot):
    steps = []
    for dt in (1e-3, 5e-4):
        gen = gen_from(SINE, robot, dt=dt)
        assert gen.validate().ok
        s = gen.samples()
        fz, fzd = s["fz"], s["fz_dot"]
        assert fz[0] == 0.0 and fzd[0] == 0.0 and fz[-1] == 0.0 and fzd[-1] == 0.0
        assert fz.min() >= 0.0 and fz.max() == pytest.approx(400.0, rel=1e-9)
        # No step anywhere: consecutive samples differ by at most the peak rate × dt.
        assert np.max(np.abs(np.diff(fz))) <= np.max(np.abs(fzd)) * dt * (1 + 1e-4)
        mid = 0.5 * (fzd[1:] + fzd[:-1])
        assert np.max(np.abs(np.diff(fz) / dt - mid)) < 1e-3 * np.max(np.abs(fzd))
        steps.append(np.max(np.abs(np.diff(fzd))))
    assert steps[1] / steps[0] == pytest.approx(0.5, rel=0.05)  # C¹: the rate never jumps


def test_force_mode_holds_the_pose(robot):
    gen = gen_from(SINE.replace("roll_deg: 0.0", "roll_deg: 3.0"), robot)
    assert gen.validate().ok
    out = ReferenceOutput()
    gen.update(out)
    assert out.mode == Mode.FORCE and out.fz_ref == 0.0
    np.testing.assert_allclose(out.pose_ref, [0.63, RAD(3.0), 0.0], atol=1e-15)
    np.testing.assert_allclose(out.q_ref, robot.kin.ik(0.63, RAD(3.0), 0.0).q, atol=1e-15)
    assert np.all(out.qd_ref == 0.0) and np.all(out.shear_ref == 0.0)


def test_run_to_the_end_finishes_and_holds(robot):
    gen = gen_from(sine_text(cycles=1, ramp_in=0.1, ramp_out=0.1), robot)
    gen.validate()
    _rows, statuses = run_all(gen)
    assert statuses[-1] == GeneratorStatus.FINISHED and len(statuses) == gen.n_samples
    assert all(s == GeneratorStatus.RUNNING for s in statuses[:-1])
    out = ReferenceOutput()
    assert gen.update(out) == GeneratorStatus.FINISHED and out.done
    gen.reset()
    assert gen.update(out) == GeneratorStatus.RUNNING and not out.done and out.index == 0


# ------------------------------------------------------------------------------ ankle ROM
def check_slider_references(s, robot, z, every=97):
    """q = ik(pose); q̇, q̈ agree with difference quotients of q."""
    for k in range(0, s["t"].size, every):
        _, roll, pitch = s["pose"][k]
        np.testing.assert_allclose(s["q"][k], robot.kin.ik(z, roll, pitch).q, atol=1e-15)
    q, qd, qdd = s["q"], s["qd"], s["qdd"]
    np.testing.assert_allclose(np.diff(q, axis=0) / DT, 0.5 * (qd[1:] + qd[:-1]), atol=1e-6)
    np.testing.assert_allclose(np.diff(qd, axis=0) / DT, 0.5 * (qdd[1:] + qdd[:-1]), atol=2e-3)


def test_ankle_rom_reaches_the_amplitudes_within_the_speed_with_smooth_velocity(robot):
    gen = load_and_make("ankle_rom.yaml", robot)
    assert isinstance(gen, AnkleRomGenerator) and gen.mode == Mode.POSITION
    report = gen.validate()
    assert report.ok
    s = gen.samples()
    roll, pitch = s["pose"][:, 1], s["pose"][:, 2]
    assert pitch.min() == pytest.approx(-RAD(10.0), abs=1e-12)  # dorsiflexion
    assert pitch.max() == pytest.approx(RAD(10.0), abs=1e-12)  # plantarflexion
    assert roll.max() == pytest.approx(RAD(8.0), abs=1e-12)  # inversion (right foot)
    assert roll.min() == pytest.approx(-RAD(8.0), abs=1e-12)  # eversion
    rate = np.hypot(s["pose_dot"][:, 1], s["pose_dot"][:, 2])
    assert rate.max() <= RAD(10.0) * (1 + 1e-9)
    assert rate.max() == pytest.approx(RAD(10.0), rel=1e-6)  # it does cruise at the speed
    # Continuous velocity: jerk-limited, so the rate changes by ≤ a_max·dt per sample.
    assert np.max(np.abs(np.diff(s["pose_dot"][:, 1:], axis=0))) <= RAD(40.0) * DT * (1 + 1e-9)
    # 1 s holds at each end: 3 reps × 1 hold per end and axis.
    for target, series in ((RAD(10.0), pitch), (-RAD(10.0), pitch), (RAD(8.0), roll)):
        at_end = np.isclose(series, target, atol=1e-12)
        assert at_end.sum() >= 3 * 1000
    # Starts and ends at neutral, at rest.
    assert s["pose_dot"][0].tolist() == [0, 0, 0] and s["pose_dot"][-1].tolist() == [0, 0, 0]
    assert s["pose"][-1, 1:].tolist() == [0.0, 0.0]
    check_slider_references(s, robot, 0.63)
    assert report.peak_pitch_rate_rad_s <= RAD(10.0) * (1 + 1e-9)


def load_and_make(name: str, robot, **kw):
    kw.setdefault("patient_weight_kg", 70.0)
    return make_generator(load_protocol(LIBRARY_DIR / name), dt=DT, kinematics=robot.kin, **kw)


def test_ankle_rom_cosine_profile_and_left_foot(robot):
    text = ROM.replace("profile: jerk_limited", "profile: cosine").replace(
        "repetitions: 3", "repetitions: 1")
    right = gen_from(text, robot)
    left = gen_from(text, robot, side="left")
    assert right.validate().ok and left.validate().ok
    sr, sl = right.samples(), left.samples()
    np.testing.assert_allclose(sl["pose"][:, 1], -sr["pose"][:, 1], atol=1e-15)  # mirrored roll
    np.testing.assert_allclose(sl["pose"][:, 2], sr["pose"][:, 2], atol=1e-15)
    rate = np.hypot(sr["pose_dot"][:, 1], sr["pose_dot"][:, 2])
    assert rate.max() <= RAD(10.0) * (1 + 1e-9)
    # Raised cosine: velocity continuous (it starts from 0), acceleration bounded.
    assert np.max(np.abs(np.diff(sr["pose_dot"][:, 1:], axis=0))) <= RAD(40.0) * DT * 1.0001


def test_ankle_rom_circuit_goes_through_the_four_ends(robot):
    text = (ROM.replace("[dorsi_plantar, inversion_eversion]", "[circuit]")
            .replace("plantarflexion: 10.0", "plantarflexion: 14.0")
            .replace("pitch_max_deg: 12.0", "pitch_max_deg: 15.0"))
    gen = gen_from(text, robot)
    report = gen.validate()
    assert report.ok, report.violations
    s = gen.samples()
    roll, pitch = s["pose"][:, 1], s["pose"][:, 2]
    assert pitch.min() == pytest.approx(-RAD(10.0), abs=1e-9)
    assert pitch.max() == pytest.approx(RAD(14.0), abs=1e-12)
    assert roll.min() == pytest.approx(-RAD(8.0), abs=1e-9)
    assert roll.max() == pytest.approx(RAD(8.0), abs=1e-9)
    rate = np.hypot(s["pose_dot"][:, 1], s["pose_dot"][:, 2])
    assert rate.max() <= RAD(10.0) * (1 + 1e-9)
    check_slider_references(s, robot, 0.63)


def test_rom_beyond_the_protocol_limits_is_a_violation(robot):
    report = gen_from(ROM.replace("pitch_max_deg: 12.0", "pitch_max_deg: 9.0"), robot).validate()
    assert report.violations == [("limits.pitch_max_deg: the reference reaches pitch 10.00 deg, "
                                 "above the protocol's 9.0 deg")]
    report = gen_from(ROM.replace("max_angular_speed_deg_s: 12.0", "max_angular_speed_deg_s: 8"),
                      robot).validate()
    assert report.violations == [
        ("limits.max_angular_speed_deg_s: the roll rate reaches 10.00 deg/s, above the protocol's "
        "8.0 deg/s"), ("limits.max_angular_speed_deg_s: the pitch rate reaches 10.00 deg/s, above "
        "the protocol's 8.0 deg/s")]


# ------------------------------------------------------------------------------ isometric
def test_isometric_holds_reach_the_angles_and_show_the_target_only_while_holding(robot):
    gen = load_and_make("isometric.yaml", robot)
    report = gen.validate()
    assert report.ok and report.peak_fz_n == 150.0
    s = gen.samples()
    pitch, fz = s["pose"][:, 2], s["fz"]
    shown = ~np.isnan(fz)
    assert shown.sum() == 3 * 5000  # three 5 s holds
    assert np.all(s["pose_dot"][shown] == 0.0)  # still while the patient pushes
    held = np.unique(np.round(np.degrees(pitch[shown]), 12))
    np.testing.assert_allclose(held, [-8.0, 0.0, 8.0], atol=1e-12)
    assert np.all(s["fz_dot"][shown] == 0.0)
    rate = np.abs(s["pose_dot"][:, 2])
    assert rate.max() <= RAD(8.0) * (1 + 1e-9)
    assert pitch[-1] == 0.0


# ------------------------------------------------------------------------------ playback
def test_position_playback_plays_the_file_through_trajectory_playback(robot):
    gen = load_and_make("position_playback.yaml", robot)
    assert isinstance(gen, PositionPlaybackGenerator)
    assert gen.validate().ok
    s = gen.samples()
    t, q, _ = load_csv(LIBRARY_DIR / PLAYBACK_CSV)
    k = np.arange(0, t.size) * 10  # 100 Hz file → every 10th loop sample is a file sample
    np.testing.assert_allclose(s["q"][k], q, atol=1e-12)  # the cubic spline interpolates
    pos, vel, acc = np.zeros(3), np.zeros(3), np.zeros(3)
    gen.playback.state_at(1234, pos, vel, acc)
    np.testing.assert_allclose(s["qd"][1234], vel, atol=0.0)
    # The pose comes from FK of every sample.
    c = robot.kin.fk(s["q"][5000])
    np.testing.assert_allclose(s["pose"][5000], c.pose, atol=1e-12)
    assert gen.duration_s == pytest.approx(12.0, abs=1e-9)


def test_position_playback_refuses_a_malformed_csv_naming_both_files(tmp_path, robot):
    (tmp_path / "traj.csv").write_text("t,q0,q1,q2\n0,0.2,0.2,0.2\n0.01,0.2,0.2\n")
    text = ("schema_version: 1\nkind: position_playback\nname: p\nfile: traj.csv\n")
    with pytest.raises(ProtocolValidationError) as exc:
        gen_from(text, robot, tmp_path)
    msg = str(exc.value)
    assert msg.startswith(f"{tmp_path / 'p.yaml'}: file: {tmp_path / 'traj.csv'}, line 3")
    assert "expected 4 columns" in msg


def test_position_playback_beyond_the_protocol_angles_is_a_violation(robot):
    text = library_text("position_playback.yaml").replace("roll_max_deg: 8.0", "roll_max_deg: 5")
    gen = make_generator(parse_protocol_text(text, str(LIBRARY_DIR / "x.yaml")), dt=DT,
                         kinematics=robot.kin)
    report = gen.validate()
    assert len(report.violations) == 1 and "limits.roll_max_deg" in report.violations[0]


# ------------------------------------------------------------------------------ active assist
def assist_text(gain=0.5, **repl: str) -> str:
    text = ASSIST.replace("assistance_gain: 0.5", f"assistance_gain: {gain}")
    for old, new in repl.items():
        text = text.replace(old, new)
    return text


def test_active_assist_guides_a_passive_foot_through_its_rom(robot):
    gen = gen_from(assist_text(gain=1.0, **{"duration_s: 60.0": "duration_s: 20.0"}), robot)
    assert isinstance(gen, ActiveAssistGenerator)
    report = gen.validate()
    assert report.ok, report.violations
    rows, statuses = run_all(gen)  # no input: a passive patient
    assert statuses[-1] == GeneratorStatus.FINISHED and len(rows) == gen.n_samples
    pitch = rows[:, 11]
    guide = np.array([gen.guide(k * DT)[1] for k in range(len(rows))])
    # Pulled towards the guide's angle and rate: the error is ≈ I·θ̈_guide/K, ≤ 0.3 deg here
    # (largest during the 2 s fade-in, where the guide accelerates most).
    assert np.max(np.abs(pitch - guide)) < RAD(0.5)
    assert pitch.max() > RAD(12.0) and pitch.min() < -RAD(8.0)
    assert np.all(rows[:, 10] == 0.0)  # roll unused
    # Slider references consistent with the pose, as in the precomputed kinds.
    for k in range(0, len(rows), 499):
        np.testing.assert_allclose(rows[k, 0:3], robot.kin.ik(0.63, 0.0, pitch[k]).q, atol=1e-15)
    # Semi-implicit Euler moves the angle by the *new* rate, θ[k+1] - θ[k] = θ̇[k+1]·dt; the
    # sliders follow up to the curvature of q(θ): ½·|q̈|·dt ≤ 5e-6 m/s.
    np.testing.assert_allclose(np.diff(rows[:, 0:3], axis=0) / DT, rows[1:, 3:6], atol=5e-6)


def test_active_assist_never_leaves_the_rom_or_the_speed_whatever_the_patient_does(robot):
    gen = gen_from(assist_text(gain=0.0, **{"duration_s: 60.0": "duration_s: 6.0"}), robot)
    assert gen.validate().ok
    inp = GeneratorInput()
    out = ReferenceOutput()
    rows = []
    rng = np.random.default_rng(7)
    for k in range(gen.n_samples):
        # Violent patient: ±200 N·m pushes switching every 1.5 s, plus noise.
        inp.tau_pitch_nm = (200.0 if (k // 1500) % 2 == 0 else -200.0) + rng.normal(0, 20)
        assert gen.update(out, inp) >= 0
        rows.append(out.buf.copy())
    rows = np.array(rows)
    pitch, rate = rows[:, 11], rows[:, 14]
    assert pitch.max() == pytest.approx(RAD(15.0), abs=1e-12)  # reaches the plantar end ...
    assert pitch.min() == pytest.approx(-RAD(10.0), abs=1e-12)  # ... and the dorsal end
    assert pitch.max() <= RAD(15.0) and pitch.min() >= -RAD(10.0)
    assert np.max(np.abs(rate)) <= RAD(20.0) * (1 + 1e-12)
    accel = np.diff(rate) / DT
    assert np.max(np.abs(accel)) <= RAD(100.0) * (1 + 1e-9)  # braking at the ends included
    report = gen.last_report  # worst-case bounds hold for this patient
    assert np.max(np.abs(rows[:, 3:6])) <= report.peak_slider_speed_m_s * (1 + 1e-9)
    assert np.max(np.abs(rows[:, 6:9])) <= report.peak_slider_accel_m_s2 * (1 + 1e-6)


def test_active_assist_refuses_non_finite_input_and_too_stiff_admittance(robot):
    gen = gen_from(ASSIST, robot)
    assert gen.validate().ok
    inp = GeneratorInput()
    inp.tau_pitch_nm = math.nan
    assert gen.update(ReferenceOutput(), inp) == GeneratorStatus.ERROR_INPUT
    stiff = gen_from(assist_text(gain=1.0, **{"virtual_mass_kg_m2: 0.5": "virtual_mass_kg_m2: 0.1",
                                               "stiffness_n_m_rad: 40.0":
                                               "stiffness_n_m_rad: 20000"}), robot)
    report = stiff.validate()
    assert not report.ok and report.violations[0].startswith("admittance.pitch: sqrt(g·K/I)·dt")


# ------------------------------------------------------------------------------ allocation
def measure(gen, cycles: int) -> tuple[int, int]:
    """(retained, peak above start) bytes over ``cycles`` updates after a warm-up."""
    out, inp = ReferenceOutput(), GeneratorInput()
    for _ in range(100):  # warm up first-call caches
        gen.update(out, inp)
    gen.reset()
    # No gc.collect() here: it releases the allocator's arenas and makes every traced
    # allocation afterwards ~4x slower (measured), for no difference in what is counted.
    tracemalloc.start()
    try:
        base, _ = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        for _ in range(cycles):
            status = gen.update(out, inp)
        current, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert status >= 0
    return current - base, peak - base


@pytest.mark.parametrize("name", ["sine_fz.yaml", "ankle_rom.yaml", "gait_replay.yaml",
                                  "position_playback.yaml"])
def test_update_allocates_nothing_over_10000_cycles(robot, name):
    """Precomputed kinds: nothing retained and a peak of a few hundred bytes — only the cycle's
    transient int/view exist, never a per-cycle array or list (one would cost ≥ 100 B each
    cycle, ≥ 1 MB over the run)."""
    gen = load_and_make(name, robot)
    assert gen.validate().ok
    retained, peak = measure(gen, 10_000)
    assert retained < 1024, f"{retained} B retained"
    assert peak < 4096, f"peak {peak} B above the start"


def test_active_assist_update_keeps_no_memory_over_10000_cycles(robot):
    """Active assist calls kinematics.ik three times a cycle, which builds a Configuration and
    a few tuples that die at once. What tracemalloc still sees afterwards is the interpreter's
    free lists (a constant ≈ 3 KB, the same after 2 000 or 10 000 cycles), not per-cycle
    retention (≥ 240 kB for one float a cycle)."""
    gen = load_and_make("active_assist.yaml", robot)
    assert gen.validate().ok
    r2, _p2 = measure(gen, 2_000)
    r1, p1 = measure(gen, 10_000)
    assert r1 < 8192 and p1 < 16384, (r1, p1)
    assert abs(r2 - r1) < 1024, f"retention grows with the cycles: {r1} B, then {r2} B"
