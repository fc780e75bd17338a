"""Gait replay: force records (CSV, C3D via ezc3d), stance selection, the published walking
shape, and the gait generator (body-weight scaling, resampling, repetitions and rests).

Tolerances: C3D stores analog samples as float32 (7 significant digits), so forces read back
from a synthetic C3D match the written ones to 1e-6 relative; everything computed in float64
is compared to 1e-9 relative or tighter.
"""
from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from protocols import gait
from protocols.generators import GaitReplayGenerator, make_generator
from protocols.library import LIBRARY_DIR, load_protocol, parse_protocol_text
from protocols.library_data import GAIT_CSV
from rt.errors import ProtocolValidationError

ezc3d = pytest.importorskip("ezc3d")

DT = 1e-3
BW70 = 70.0 * gait.STANDARD_GRAVITY_M_S2


# ------------------------------------------------------------------------------ helpers
def write_c3d(path: Path, fz: np.ndarray, *, fx: np.ndarray | None = None,
              fy: np.ndarray | None = None, rate_hz: float = 1000.0, scale: float = 0.5,
              n_plates: int = 1, force_unit: str = "N") -> Path:
    """A minimal C3D with ``n_plates`` type-2 force platforms (6 channels each) at ``rate_hz``
    analog rate and one marker at rate/10. ``fz`` is the force *on* the plate (negative down in
    the lab frame, as labs record it); the raw channels are stored divided by ANALOG:SCALE."""
    n = fz.size
    ratio = 10
    assert n % ratio == 0
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = np.array([rate_hz / ratio])
    c["parameters"]["POINT"]["LABELS"]["value"] = ["heel"]
    pts = np.zeros((4, 1, n // ratio))
    pts[3] = 1.0
    c["data"]["points"] = pts
    labels, units, rows = [], [], []
    zeros = np.zeros(n)
    for p in range(n_plates):
        chans = (fx if fx is not None else zeros, fy if fy is not None else zeros, fz,
                 zeros, zeros, zeros)
        for name, unit, ch in zip(("Fx", "Fy", "Fz", "Mx", "My", "Mz"),
                                  (force_unit,) * 3 + ("Nmm",) * 3, chans):
            labels.append(f"{name}{p + 1}")
            units.append(unit)
            rows.append(ch)
    c["parameters"]["ANALOG"]["RATE"]["value"] = np.array([rate_hz])
    c["parameters"]["ANALOG"]["LABELS"]["value"] = labels
    c["parameters"]["ANALOG"]["UNITS"]["value"] = units
    c["parameters"]["ANALOG"]["SCALE"]["value"] = np.full(len(labels), scale)
    c["data"]["analogs"] = np.array(rows)[None, :, :]
    fp = c["parameters"]["FORCE_PLATFORM"]
    fp["USED"]["value"] = np.array([n_plates])
    fp["TYPE"]["value"] = np.full(n_plates, 2)
    fp["CHANNEL"]["value"] = np.arange(1, 6 * n_plates + 1).reshape(n_plates, 6).T
    corners = np.array([[200.0, 300, 0], [-200, 300, 0], [-200, -300, 0], [200, -300, 0]]).T
    fp["CORNERS"]["value"] = np.repeat(corners[:, :, None], n_plates, axis=2)
    fp["ORIGIN"]["value"] = np.tile(np.array([[0.0], [0.0], [-40.0]]), (1, n_plates))
    fp["CAL_MATRIX"]["value"] = np.zeros((6, 6, 0))
    c.write(str(path))
    return path


def shape_record(rate_hz: float, bw_kg: float = 70.0, stance_s: float = gait.WALKING_STANCE_S,
                 pad_s: float = 0.1) -> gait.GroundReactionForce:
    return gait.walking_grf(bw_kg, stance_s, rate_hz, pad_s)


def gait_yaml(source: str, **fields: object) -> str:
    base = {"schema_version": 1, "kind": "gait_replay", "name": "test gait",
            "pose": "{z_m: 0.63}", "source": source, "source_body_weight_kg": 70.0,
            "percent_body_weight": 60.0, "repetitions": 1, "rest_between_s": 0.5,
            "ramp_s": 0.02}
    if source.endswith(".c3d"):
        base["plate_index"] = 0
    base.update(fields)
    return "".join(f"{k}: {v}\n" for k, v in base.items())


#: The published stance's samples with Fz > 0 (pad 0.1 s): the stance without its lead-in.
EXPLICIT = "{select: explicit, start_s: 0.1, end_s: 0.74}"


def make_gait(tmp_path: Path, robot, text: str, weight: float | None = 70.0):
    proto = parse_protocol_text(text, str(tmp_path / "gait.yaml"))
    return make_generator(proto, dt=DT, kinematics=robot.kin, patient_weight_kg=weight,
                          base_dir=tmp_path)


# ------------------------------------------------------------------------------ published shape
def test_published_shape_hits_its_textbook_landmarks_and_is_smooth():
    s = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    fz, fx, fy = gait.walking_grf_bw(s)
    np.testing.assert_allclose(fz, [0.0, 1.15, 0.75, 1.15, 0.0], atol=1e-15)
    fine = np.linspace(0.0, 1.0, 100_001)
    fz, fx, fy = gait.walking_grf_bw(fine)
    # The landmarks are the extrema: peaks at 25 % and 75 %, valley at 50 %.
    first, second = fine < 0.5, fine >= 0.5
    assert fine[first][np.argmax(fz[first])] == pytest.approx(0.25, abs=1e-5)
    assert fine[second][np.argmax(fz[second])] == pytest.approx(0.75, abs=1e-5)
    mid = (fine > 0.3) & (fine < 0.7)
    assert fz[mid].min() == pytest.approx(0.75, abs=1e-12)
    # C¹: the slope changes by at most |f''|·h between neighbours (no kink).
    slope = np.diff(fz) / np.diff(fine)
    assert np.max(np.abs(np.diff(slope))) < 30.0 * 1e-5 * 10
    assert fx.min() == pytest.approx(-0.20, abs=1e-6) and fx.max() == pytest.approx(0.20, abs=1e-6)
    assert fx[fine < 0.5].max() <= 1e-15  # braking first, propulsion second
    assert fy.max() == pytest.approx(0.05, abs=1e-9)


def test_shipped_gait_csv_is_the_published_shape():
    rec = gait.read_grf_csv(LIBRARY_DIR / GAIT_CSV)
    ref = shape_record(500.0)
    np.testing.assert_allclose(rec.t, ref.t, atol=1e-9)
    np.testing.assert_allclose(rec.fz, ref.fz, atol=6e-5)  # written with 0.1 mN resolution
    assert rec.has_shear
    assert rec.fz.max() == pytest.approx(1.15 * BW70, rel=1e-6)


# ------------------------------------------------------------------------------ CSV reading
def test_csv_round_trip_with_and_without_shear(tmp_path):
    rec = shape_record(200.0)
    gait.write_grf_csv(tmp_path / "a.csv", rec)
    back = gait.read_grf_csv(tmp_path / "a.csv")
    np.testing.assert_allclose(back.fz, rec.fz, atol=6e-5)
    assert back.has_shear
    only_fz = gait.GroundReactionForce(rec.t, rec.fz, None, None, "x")
    gait.write_grf_csv(tmp_path / "b.csv", only_fz, comments=("just fz",))
    back = gait.read_grf_csv(tmp_path / "b.csv")
    assert not back.has_shear and back.fx is None


CSV_CASES = [
    ("wrong header", "t,fz,fy\n0,0,0\n", "the header must be 't,fz' or 't,fz,fx,fy'"),
    ("wrong columns", "t,fz\n0,0\n0.001,1\n0.002,2,3\n0.003,0\n0.004,0\n",
     "line 4: expected 2 columns"),
    ("nan", "t,fz\n0,0\n0.001,nan\n0.002,1\n0.003,0\n", "line 3: column 'fz': nan is not a finite"),
    ("non monotonic time", "t,fz\n0,0\n0.002,1\n0.001,1\n0.003,0\n",
     "line 4: time 0.001 s is not after the previous sample's 0.002 s"),
    ("text", "t,fz\n0,0\n0.001,heavy\n0.002,1\n0.003,0\n", "'heavy' is not a number"),
    ("too few", "t,fz\n0,0\n0.001,1\n", "at least 4 samples"),
    ("empty", "# only a comment\n\n", "the file is empty"),
]


@pytest.mark.parametrize("case,text,reason", CSV_CASES, ids=[c[0] for c in CSV_CASES])
def test_malformed_csv_records_are_refused_naming_file_and_reason(tmp_path, case, text, reason):
    path = tmp_path / "rec.csv"
    path.write_text(text)
    with pytest.raises(ProtocolValidationError) as exc:
        gait.read_grf_csv(path)
    assert str(path) in str(exc.value) and reason in str(exc.value)


def test_missing_csv_is_refused_with_the_protocol_file_and_field(tmp_path, robot):
    with pytest.raises(ProtocolValidationError) as exc:
        make_gait(tmp_path, robot, gait_yaml("nowhere.csv"))
    msg = str(exc.value)
    assert "gait.yaml: source:" in msg and "nowhere.csv" in msg and "cannot read" in msg


# ------------------------------------------------------------------------------ stance
def test_stance_selection_by_threshold_and_window():
    rec = shape_record(1000.0)
    st = gait.select_stance(rec, threshold_n=20.0)
    # Widened from the threshold to the true contact (Fz above CONTACT_LEVEL_N).
    assert st.t[0] == 0.0 and st.fz.min() > gait.CONTACT_LEVEL_N
    assert 0.60 < st.duration_s < 0.64
    assert st.fz[0] < 20.0 and st.contact_s == (st.start_s, st.start_s + st.duration_s)
    # With a lead, the stance starts before contact and ends after toe off, on unloaded record.
    lead = gait.select_stance(rec, threshold_n=20.0, lead_s=0.04)
    assert lead.start_s == pytest.approx(st.start_s - 0.04, abs=1e-9)
    assert lead.duration_s == pytest.approx(st.duration_s + 0.08, abs=1e-9)
    assert lead.fz[:30].max() == 0.0 and lead.contact_s == st.contact_s
    win = gait.select_stance(rec, start_s=0.1, end_s=0.74)
    assert win.duration_s == pytest.approx(0.64, abs=1e-9)
    np.testing.assert_allclose(win.fz.max(), 1.15 * BW70, rtol=1e-12)


@pytest.mark.parametrize("kwargs,reason", [
    ({"threshold_n": 2000.0}, "empty stance: no sample of Fz exceeds the threshold 2000 N"),
    ({"threshold_n": 20.0, "occurrence": 1}, "has only 1 stance(s)"),
    ({"start_s": 0.5, "end_s": 2.0}, "outside the record"),
    ({"start_s": 0.1, "end_s": 0.1015}, "at least 4 are needed"),
], ids=["threshold above peak", "no second stance", "window outside", "window too short"])
def test_bad_stance_selections_are_refused(kwargs, reason):
    with pytest.raises(ProtocolValidationError, match=re_escape(reason)):
        gait.select_stance(shape_record(1000.0), **kwargs)


def test_a_stance_cut_by_the_record_is_refused_as_incomplete():
    rec = shape_record(1000.0)
    cut = gait.GroundReactionForce(rec.t[200:] - rec.t[200], rec.fz[200:], None, None, "cut.csv")
    with pytest.raises(ProtocolValidationError, match="touches the start of the record"):
        gait.select_stance(cut, threshold_n=20.0)


def re_escape(text: str) -> str:
    import re
    return re.escape(text)


# ------------------------------------------------------------------------------ C3D
def test_c3d_round_trip_reads_the_plate_in_newtons(tmp_path):
    rec = shape_record(1000.0, pad_s=0.1075)  # 870 samples → padded to a multiple of 10
    n = rec.fz.size - rec.fz.size % 10
    path = write_c3d(tmp_path / "walk.c3d", -rec.fz[:n], fx=-rec.fx[:n], fy=-rec.fy[:n])
    back = gait.read_grf_c3d(path, 0)
    # Force on the plate (negative) comes back as loading (positive), scaled by ANALOG:SCALE.
    np.testing.assert_allclose(back.fz, rec.fz[:n], rtol=1e-6, atol=1e-4)
    np.testing.assert_allclose(back.fx, rec.fx[:n], rtol=1e-6, atol=1e-4)
    np.testing.assert_allclose(back.t, np.arange(n) / 1000.0, atol=1e-12)


def test_c3d_analog_scale_is_applied(tmp_path):
    """The reader uses the file's ANALOG:SCALE: patching the six SCALE floats of the parameter
    section from 0.5 to 1.0 (raw samples untouched) doubles the force read."""
    fz = -np.linspace(0.0, 800.0, 200)
    path = write_c3d(tmp_path / "a.c3d", fz, scale=0.5)
    np.testing.assert_allclose(gait.read_grf_c3d(path, 0).fz, -fz, rtol=1e-6)
    data = path.read_bytes()
    half, one = struct.pack("<6f", *[0.5] * 6), struct.pack("<6f", *[1.0] * 6)
    assert data.count(half) == 1
    patched = tmp_path / "b.c3d"
    patched.write_bytes(data.replace(half, one))
    np.testing.assert_allclose(gait.read_grf_c3d(patched, 0).fz, -2.0 * fz, rtol=1e-6)


def test_c3d_second_plate_is_picked_by_index(tmp_path):
    rec = shape_record(1000.0, pad_s=0.1075)
    n = rec.fz.size - rec.fz.size % 10
    path = write_c3d(tmp_path / "two.c3d", -rec.fz[:n], n_plates=2)
    assert gait.read_grf_c3d(path, 1).fz.max() == pytest.approx(rec.fz.max(), rel=1e-6)
    with pytest.raises(ProtocolValidationError, match="plate_index 2: the file has 2 force"):
        gait.read_grf_c3d(path, 2)


def test_c3d_gait_replay_end_to_end(tmp_path, robot):
    rec = shape_record(1000.0)
    write_c3d(tmp_path / "walk.c3d", -rec.fz[:840])
    gen = make_gait(tmp_path, robot, gait_yaml("walk.c3d", repetitions=2), weight=80.0)
    report = gen.validate()
    assert report.ok, report.violations
    assert report.peak_fz_n == pytest.approx(0.6 * 80.0 / 70.0 * 1.15 * BW70, rel=1e-6)


def test_c3d_without_plates_is_refused(tmp_path):
    path = write_c3d(tmp_path / "none.c3d", np.zeros(100))
    c = ezc3d.c3d(str(path))
    c["parameters"]["FORCE_PLATFORM"]["USED"]["value"] = np.array([0])
    c["parameters"]["FORCE_PLATFORM"]["TYPE"]["value"] = np.zeros(0, dtype=int)
    c["parameters"]["FORCE_PLATFORM"]["CHANNEL"]["value"] = np.zeros((6, 0), dtype=int)
    c["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"] = np.zeros((3, 4, 0))
    c["parameters"]["FORCE_PLATFORM"]["ORIGIN"]["value"] = np.zeros((3, 0))
    c.write(str(tmp_path / "none2.c3d"))
    with pytest.raises(ProtocolValidationError, match="no force platform"):
        gait.read_grf_c3d(tmp_path / "none2.c3d", 0)


def test_c3d_with_nan_samples_is_refused(tmp_path):
    fz = -np.full(100, 500.0)
    fz[37] = math.nan
    path = write_c3d(tmp_path / "nan.c3d", fz)
    reason = "is not a finite number at analog sample 37 (t = 0.0370 s)"
    with pytest.raises(ProtocolValidationError, match=re_escape(reason)):
        gait.read_grf_c3d(path, 0)


def test_units_are_decided_by_physics_not_labels(tmp_path, robot):
    """Data in N labelled 'V' load; data in kN labelled 'N' are refused by the body-mass check,
    naming the measured peak and the expected range."""
    rec = shape_record(1000.0)
    write_c3d(tmp_path / "v.c3d", -rec.fz[:840], force_unit="V")
    gen = make_gait(tmp_path, robot, gait_yaml("v.c3d"))
    assert gen.validate().ok and gen.info["source_peak_bw"] == pytest.approx(1.15, rel=1e-6)
    write_c3d(tmp_path / "kn.c3d", -rec.fz[:840] / 1000.0, force_unit="N")
    with pytest.raises(ProtocolValidationError) as exc:
        make_gait(tmp_path, robot, gait_yaml("kn.c3d", stance=EXPLICIT))
    msg = str(exc.value)
    assert "kn.c3d: force platform 0: the stance peaks at 0." in msg
    assert "body weights of the 70 kg subject (source_body_weight_kg)" in msg
    assert "a stance peaks at 0.5-3 BW, 343-2059 N" in msg and "labelled 'N'" in msg


def test_truncated_c3d_is_refused(tmp_path):
    path = write_c3d(tmp_path / "full.c3d", -np.full(2000, 500.0))
    data = path.read_bytes()
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(data[:len(data) * 2 // 5])
    with pytest.raises(ProtocolValidationError, match="truncated: its header declares 200 frames"):
        gait.read_grf_c3d(cut, 0)


@pytest.mark.parametrize("content,reason", [
    (b"t,fz\n0,0\n" * 100, "not a C3D file: byte 2 is 0x2C"),
    (b"\x02\x50" + bytes(100), "shorter than the 512-byte C3D header"),
    (bytes([2, 0x50]) + bytes(range(256)) * 8, "ezc3d cannot read it as C3D"),
], ids=["csv bytes", "too short", "garbage after the magic"])
def test_non_c3d_bytes_are_refused(tmp_path, content, reason):
    path = tmp_path / "fake.c3d"
    path.write_bytes(content)
    with pytest.raises(ProtocolValidationError) as exc:
        gait.read_grf_c3d(path, 0)
    assert str(path) in str(exc.value) and reason in str(exc.value)


# ------------------------------------------------------------------------------ generator
def test_library_gait_scales_to_body_weight_exactly(robot):
    proto = load_protocol(LIBRARY_DIR / "gait_replay.yaml")
    gen = make_generator(proto, dt=DT, kinematics=robot.kin, patient_weight_kg=82.5)
    assert isinstance(gen, GaitReplayGenerator)
    assert gen.validate().ok
    s = gen.samples()
    scale = 0.60 * 82.5 / 70.0
    assert gen.scale == pytest.approx(scale, rel=1e-15)
    # The record is at 500 Hz and the loop at 1 kHz: every other played sample is a record
    # sample, which the interpolant reproduces exactly; compare away from the 20 ms tapers.
    rec = gait.read_grf_csv(LIBRARY_DIR / GAIT_CSV)
    st = gen.stance
    i0 = int(round(st.start_s * 500.0))  # the stance's first record sample (lead-in included)
    k = np.arange(40, gen._n_stance - 40, 2)  # played samples on record samples, no taper
    np.testing.assert_allclose(s["fz"][k], scale * rec.fz[i0 + k // 2], rtol=1e-12)
    np.testing.assert_allclose(s["fz"][k], scale * st.fz[k // 2], rtol=1e-12)
    assert s["fz"].max() == pytest.approx(scale * 1.15 * BW70, rel=1e-4)
    assert np.all(s["shear"] == 0.0)  # include_shear: false


def test_gait_needs_the_patients_weight(robot):
    proto = load_protocol(LIBRARY_DIR / "gait_replay.yaml")
    with pytest.raises(ProtocolValidationError, match="needs the patient's weight"):
        make_generator(proto, dt=DT, kinematics=robot.kin)


@pytest.mark.parametrize("rate_hz,interp,tol", [(120.0, "cubic", 5e-3), (120.0, "linear", 5e-3),
                                                (333.0, "cubic", 1e-3), (1000.0, "cubic", 1e-9)])
def test_resampling_preserves_the_peak(tmp_path, robot, rate_hz, interp, tol):
    """Stated tolerance: the resampled peak is within 0.5 % of the record's largest sample for
    records ≥ 100 Hz (PCHIP never exceeds it; the 1 ms grid misses its time by ≤ 0.5 ms), and
    exact when the record is at the loop rate."""
    rec = shape_record(rate_hz, pad_s=0.1)
    gait.write_grf_csv(tmp_path / "r.csv", rec)
    written = gait.read_grf_csv(tmp_path / "r.csv")
    gen = make_gait(tmp_path, robot, gait_yaml("r.csv", percent_body_weight=100.0,
                                               interpolation=interp))
    assert gen.validate().ok
    peak = gen.samples()["fz"].max()
    assert peak <= written.fz.max() * (1 + 1e-12)  # no overshoot
    assert peak == pytest.approx(written.fz.max(), rel=tol)


def test_repetitions_and_rests_are_timed_right(tmp_path, robot):
    gait.write_grf_csv(tmp_path / "r.csv", shape_record(1000.0))
    gen = make_gait(tmp_path, robot, gait_yaml("r.csv", repetitions=4, rest_between_s=0.75,
                                               time_scale=1.5, stance=EXPLICIT))
    assert gen.validate().ok
    fz = gen.samples()["fz"]
    loaded = np.concatenate(([0], (fz > 0.0).astype(np.int8), [0]))
    starts = np.flatnonzero(np.diff(loaded) == 1)  # first loaded sample of each stance
    ends = np.flatnonzero(np.diff(loaded) == -1)  # first unloaded sample after it
    assert starts.size == 4
    played = gen.stance.duration_s * 1.5
    # Each stance: from its zero sample (start - 1) to its zero end sample, ≈ stance × scale.
    for s0, e0 in zip(starts, ends):
        assert (e0 - (s0 - 1)) * DT == pytest.approx(played, abs=DT)
    # Between stances: 0 N for rest_between_s.
    gaps = (starts[1:] - 1 - ends[:-1]) * DT
    np.testing.assert_allclose(gaps, 0.75, atol=1e-12)
    np.testing.assert_array_equal(gen.repetition_starts(), starts - 1)
    assert gen.duration_s == pytest.approx(4 * played + 3 * 0.75, abs=4 * DT)


def test_time_scale_slows_the_replay_and_divides_the_rate(tmp_path, robot):
    gait.write_grf_csv(tmp_path / "r.csv", shape_record(1000.0))
    real = make_gait(tmp_path, robot, gait_yaml("r.csv", stance=EXPLICIT))
    slow = make_gait(tmp_path, robot, gait_yaml("r.csv", time_scale=2.0, stance=EXPLICIT))
    r1, r2 = real.validate(), slow.validate()
    assert r2.peak_fz_n == pytest.approx(r1.peak_fz_n, rel=1e-9)
    assert slow._n_stance - 1 == pytest.approx(2 * (real._n_stance - 1), abs=1)
    # Away from the tapers the rate halves (tapers are in played time, so they differ).
    f1, f2 = real.samples()["fz_dot"], slow.samples()["fz_dot"]
    k = np.arange(100, real._n_stance - 100)
    np.testing.assert_allclose(f2[2 * k], 0.5 * f1[k], rtol=1e-9, atol=1e-9)


def test_gait_force_starts_and_ends_at_zero_with_continuous_rate(tmp_path, robot):
    """Continuity test that can fail: a C¹ reference's largest per-sample change of its rate is
    |F''|·dt, so it halves when dt halves; a jump in the rate would not shrink."""
    gait.write_grf_csv(tmp_path / "r.csv", shape_record(500.0))
    steps = []
    for dt in (1e-3, 5e-4):
        proto = parse_protocol_text(gait_yaml("r.csv", repetitions=2), str(tmp_path / "g.yaml"))
        gen = make_generator(proto, dt=dt, kinematics=robot.kin, patient_weight_kg=70.0)
        assert gen.validate().ok
        s = gen.samples()
        fz, fzd = s["fz"], s["fz_dot"]
        assert fz[0] == 0.0 and fz[-1] == 0.0 and fzd[0] == 0.0 and fzd[-1] == 0.0
        assert fz.min() >= 0.0
        # The rate is the derivative of the force (the reference is self-consistent).
        mid = 0.5 * (fzd[1:] + fzd[:-1])
        assert np.max(np.abs(np.diff(fz) / dt - mid)) < 0.01 * np.max(np.abs(fzd))
        steps.append(np.max(np.abs(np.diff(fzd))))
    assert steps[1] / steps[0] < 0.6


def test_shear_is_carried_when_asked_and_refused_when_absent(tmp_path, robot):
    rec = shape_record(1000.0)
    gait.write_grf_csv(tmp_path / "with.csv", rec)
    gen = make_gait(tmp_path, robot, gait_yaml("with.csv", include_shear="true",
                                               percent_body_weight=100.0))
    assert gen.validate().ok
    shear = gen.samples()["shear"]
    assert shear[:, 0].min() == pytest.approx(-0.20 * BW70, rel=2e-3)
    gait.write_grf_csv(tmp_path / "without.csv",
                       gait.GroundReactionForce(rec.t, rec.fz, None, None, "x"))
    with pytest.raises(ProtocolValidationError, match="include_shear: the record .* has no fx"):
        make_gait(tmp_path, robot, gait_yaml("without.csv", include_shear="true"))


def test_ramps_longer_than_the_stance_are_refused(tmp_path, robot):
    gait.write_grf_csv(tmp_path / "r.csv", shape_record(1000.0))
    with pytest.raises(ProtocolValidationError) as exc:
        make_gait(tmp_path, robot, gait_yaml("r.csv", ramp_s=0.4))
    # Automatic selection: the ramps need unloaded record before contact.
    assert "gait.yaml: source:" in str(exc.value) and "shorten ramp_s" in str(exc.value)
    with pytest.raises(ProtocolValidationError) as exc:
        make_gait(tmp_path, robot, gait_yaml("r.csv", ramp_s=0.4, stance=EXPLICIT))
    assert "gait.yaml: ramp_s: ramps of 0.4 s at both ends do not fit" in str(exc.value)
