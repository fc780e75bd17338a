"""PDF reports: session (from recordings made on the twin), progress, calibration certificate.

Every report is rendered for real and checked the way a reader meets it: pages turned into
PNGs with pdftoppm, the text layer read with pdftotext (the summary's numbers, formatted as
the report formats them), fonts embedded (pdffonts). Figures computed from a recording must
equal the session summary's (computed from the loop's tap): same samples, same definitions
(protocols.session_figures), so the tolerance is float rounding (1e-9 relative).
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

import protocols.session as session_mod
from protocols.library import list_library
from protocols.session import SessionSetup, run_session
from reports.certificate import (
    calibration_record_from_dict,
    load_calibration_record,
    render_certificate,
)
from reports.decimate import EnvelopeDecimator
from reports.document import ReportError, fmt
from reports.progress import (
    adherence,
    load_progress_input,
    progress_input_from_dict,
    render_progress_report,
    trend_per_week,
)
from reports.session_data import (
    ReportInputError,
    session_input_from_record,
    session_input_from_recording,
)
from reports.session_report import render_session_report
from reports.settings import PageSize, ReportSettings, load_settings
from rt.errors import ConfigurationError
from rt.recording.writer import SessionRecorder
from rt.safety.limits import PatientLimits

LIB = {p.name: p for p in list_library()}
DATA = Path(__file__).parents[1] / "reports" / "data"
DEMO_PROGRESS = DATA / "demo_progress.json"
CAL_RECORD = DATA / "example_calibration_record.json"
T0 = datetime(2026, 11, 23, 17, 0, tzinfo=UTC)
#: Figures from a recording against the session's own (float64) summary. The recording's
#: 1 kHz channels are fixed point (rt.recording.channels): a force is stored within 0.5 mN,
#: a measured slider position exactly (whole encoder counts); a 2 % RMS error of a 100 N
#: amplitude (2 N) then moves by ~1e-5 relative (the quantisation errors average out over the
#: samples), a ROM angle not at all. 1e-4 leaves a margin.
REL = 1e-4
#: talus.v4 records forces in 1/16 N (the ATI's CAN count, rt.recording.channels): a peak
#: force moves by up to half a quantum, an RMS force error by at most one (the reference and
#: the measured force each rounded by half); in % of the sine's 100 N amplitude, 0.0625.
FORCE_QUANTUM_N = 1 / 16
ABS = {"peak_force_n": FORCE_QUANTUM_N / 2, "rms_error_pct": FORCE_QUANTUM_N / 100.0 * 100}

pytestmark = pytest.mark.skipif(shutil.which("pdftotext") is None,
                                reason="poppler-utils missing (make setup installs it)")


def clock():
    return T0


def pdftext(pdf: Path) -> str:
    return subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True,
                          text=True, check=True).stdout


def assert_fonts_embedded(pdf: Path) -> None:
    out = subprocess.run(["pdffonts", str(pdf)], capture_output=True, text=True,
                         check=True).stdout.splitlines()[2:]
    assert out, "no fonts at all"
    for line in out:
        # name type encoding emb sub uni object ID: 'emb' is the 4th field from the end - 2.
        assert line.split()[-5] == "yes", line


def pages_to_png(pdf: Path, tmp: Path, pages: int) -> list[Path]:
    subprocess.run(["pdftoppm", "-r", "50", "-png", str(pdf), str(tmp / pdf.stem)], check=True)
    pngs = sorted(tmp.glob(f"{pdf.stem}-*.png"))
    assert len(pngs) == pages
    for png in pngs:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 2000
    return pngs


def page_size(pdf: Path) -> str:
    out = subprocess.run(["pdfinfo", str(pdf)], capture_output=True, text=True,
                         check=True).stdout
    return next(line for line in out.splitlines() if line.startswith("Page size"))


# ------------------------------------------------------------------------------ sessions

SHORT_ROM = """schema_version: 1
kind: ankle_rom
name: Short ROM for reports
pose:
  z_m: 0.63
sequence: [dorsi_plantar, inversion_eversion]
amplitude_deg:
  dorsiflexion: 8.0
  plantarflexion: 10.0
  inversion: 6.0
  eversion: 5.0
speed_deg_s: 15.0
repetitions: 1
hold_s: 0.3
profile: jerk_limited
max_acceleration_deg_s2: 60.0
max_jerk_deg_s3: 600.0
"""


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    """Recorded sessions on the twin (fast): sine Fz, a short ankle ROM, a stopped sine."""
    d = tmp_path_factory.mktemp("sessions")
    out = {}
    out["sine"] = (run_session(SessionSetup(LIB["sine_fz.yaml"]), d / "sine.mcap"),
                   d / "sine.mcap")
    rom = d / "short_rom.yaml"
    rom.write_text(SHORT_ROM)
    out["rom"] = (run_session(SessionSetup(rom), d / "rom.mcap"),
                  d / "rom.mcap")
    return out


@pytest.fixture(scope="module")
def stopped_session(tmp_path_factory):
    """A sine Fz whose force passes the patient's limit: pre-flight is bypassed (it would
    refuse), so the supervisor stops the real run and the summary lists the stop."""
    d = tmp_path_factory.mktemp("stopped")
    mp = pytest.MonkeyPatch()
    mp.setattr(session_mod, "preflight", lambda setup, model=None: {
        "ok": True, "predicted": {"duration_s": 24.0, "peak_actuator_force_n": 270.0,
                                  "peak_slider_speed_m_s": 0.008,
                                  "platform_angles_deg": {"roll": [0, 0], "pitch": [0, 0]},
                                  "peak_platform_force_n": 398.6, "rms_error_pct": 1.6}})
    try:
        s = run_session(SessionSetup(LIB["sine_fz.yaml"],
                                     patient_limits=PatientLimits(max_force_n=350.0)),
                        d / "stopped.mcap")
    finally:
        mp.undo()
    return s, d / "stopped.mcap"


def _same(a, b, abs_tol=1e-12):
    if a is None or b is None:
        return a is b
    return a == pytest.approx(b, rel=REL, abs=abs_tol)


@pytest.mark.parametrize("name", ["sine", "rom"])
def test_recording_figures_equal_the_sessions_summary(sessions, name):
    summary, path = sessions[name]
    f = session_input_from_recording(path).figures
    for key in ("rms_error_pct", "peak_force_n"):
        assert _same(f[key], summary[key], ABS[key]), key
    for axis in ("roll", "pitch"):
        assert f["rom_deg"][axis] == pytest.approx(summary["rom_deg"][axis], rel=REL, abs=1e-12)
    assert f["stops"] == summary["stops"] and f["completed"] == summary["completed"]


def test_time_per_phase_matches_the_protocol(sessions):
    f = session_input_from_recording(sessions["sine"][1]).figures
    # 2 s ramp in + 20 cycles at 1 Hz + 2 s ramp out = 24 s of play, ± one cycle.
    assert f["phase_time_s"]["play"] == pytest.approx(24.0, abs=0.0015)
    assert sum(f["phase_time_s"].values()) == pytest.approx(f["duration_s"], abs=1e-9)


def test_rom_session_reaches_its_prescribed_directions(sessions):
    f = session_input_from_recording(sessions["rom"][1]).figures
    # Plantarflexion is +pitch, inversion +roll (right foot): 10/8 and 6/5 degrees, ± 0.2°.
    assert f["rom_deg"]["pitch"] == pytest.approx([-8.0, 10.0], abs=0.2)
    assert f["rom_deg"]["roll"] == pytest.approx([-5.0, 6.0], abs=0.2)
    assert f["rms_error_pct"] is None


def test_stopped_session_figures_and_report(stopped_session, tmp_path):
    summary, path = stopped_session
    assert summary["stops"], "the force limit should have stopped the session"
    inp = session_input_from_recording(path)
    assert inp.figures["stops"] == summary["stops"]
    assert not inp.figures["completed"]
    assert inp.figures["phase_time_s"]["stopped"] > 0.0
    pdf = tmp_path / "stopped.pdf"
    render_session_report(inp, pdf, clock=clock)
    text = pdftext(pdf)
    first = summary["stops"][0]
    assert f"STOPPED at {fmt(first['t'], 1, 's')}" in text
    assert "force above the patient's limit" in text
    assert first["cause"] in text and "supervisor" in text      # who/what triggered it


def test_session_report_renders_with_the_summarys_numbers(sessions, tmp_path):
    summary, path = sessions["sine"]
    pdf = tmp_path / "sine.pdf"
    pages = render_session_report(session_input_from_recording(path), pdf, clock=clock,
                                  software_version="9.9.9")
    assert pages >= 3
    pages_to_png(pdf, tmp_path, pages)
    assert_fonts_embedded(pdf)
    text = pdftext(pdf)
    assert "COMPLETED" in text
    assert fmt(summary["rms_error_pct"], 2, "%") in text
    assert fmt(summary["peak_force_n"], 1, "N") in text
    assert summary["recording"]["sha256"] in text and "sine.mcap" in text
    assert "Generated 2026-11-23 17:00 UTC" in text and "talus 9.9.9" in text
    assert f"page 1 of {pages}" in text and f"page {pages} of {pages}" in text
    # Missing pieces are said, not skipped: this recording has no summary message or limits.
    assert "no session summary" in text and "limits in force" in text


def test_rom_report_in_clinical_terms(sessions, tmp_path):
    summary, path = sessions["rom"]
    pdf = tmp_path / "rom.pdf"
    render_session_report(session_input_from_recording(path), pdf, clock=clock)
    text = pdftext(pdf)
    pitch, roll = summary["rom_deg"]["pitch"], summary["rom_deg"]["roll"]
    assert f"Plantarflexion reached    {fmt(pitch[1], 1, '°')}" in " ".join(text.split("  ")) \
        or fmt(pitch[1], 1, "°") in text
    for value in (-pitch[0], pitch[1], roll[1], -roll[0]):
        assert fmt(value, 1, "°") in text


def test_summary_and_metadata_from_the_rt_process_are_used(tmp_path):
    """A recording carrying the lead's /session/summary and metadata keys (written here with
    the recorder API): limits, clinician, pre-flight and the RT figures reach the report."""
    path = tmp_path / "with_summary.mcap"
    limits = PatientLimits(roll_min_deg=-9, roll_max_deg=7, pitch_min_deg=-11,
                           pitch_max_deg=13, max_force_n=420).model_dump()
    from rt.recording.channels import ChannelSpec
    extra = {"/session/summary": ChannelSpec("/session/summary", "talus.SessionSummary",
                                             {"type": "object"})}
    meta = {"protocol_name": "Sine", "protocol_version": "1",
            "parameters": {"kind": "sine_fz", "amplitude_n": 100.0},
            "patient_id": "P-0042", "robot_description": "nominal",
            "clinician": "Dra. Begoña Núñez", "limits": limits, "side": "left"}
    rec = SessionRecorder(path, meta, extra_channels=extra, start_wall_ns=1_790_000_000 * 10**9)
    rng = np.random.default_rng(1)
    for k in range(3000):
        t = k * 1e-3
        phase = "approach" if k < 100 else "play" if k < 2900 else "done"
        ref = 300.0 + 100.0 * np.sin(2 * np.pi * t) if phase == "play" else 0.0
        rec.publish("/robot/state", {"t": t, "q": [0.2, 0.2, 0.2], "qd": [0.0] * 3,
                                     "q_ref": [0.2] * 3, "tau": [100.0] * 3, "volts": [0.0] * 3})
        rec.wrench(t, 0.0, 0.0, -(ref + rng.normal(0, 2.0)), 0.0, 0.0, 0.0)
        rec.reference(t, [0.0, 0.0, ref], phase=phase)
        if k % 500 == 0:
            import time
            time.sleep(0.05)     # let the writer thread drain its bounded queue
    rec.publish("/session/summary", {"t": 3.0, "rms_error_pct": 2.0, "peak_force_n": 405.0,
                                     "stops": [], "preflight": {"peak_platform_force_n": 401.5,
                                                                "duration_s": 2.8},
                                     "rt": {"deadline_misses": 3, "cycle_p99_us": 187.0}})
    info = rec.close()
    assert info["dropped_total"] == 0
    inp = session_input_from_recording(path)
    assert inp.summary is not None and inp.limits == limits
    pdf = tmp_path / "with_summary.pdf"
    render_session_report(inp, pdf, clock=clock)
    text = pdftext(pdf)
    assert "P-0042" in text and "Dra. Begoña Núñez" in text and "left" in text
    assert "401.5 N" in text and "deadline_misses" in text
    assert "420 N" in text                       # the patient's force limit
    assert "no session summary" not in text


# ------------------------------------------------------------------------------ bad input

def test_corrupt_and_missing_recordings_are_clear_errors(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"this is not a recording at all")
    with pytest.raises(ReportInputError, match="not an MCAP recording"):
        session_input_from_recording(bad)
    with pytest.raises(ReportInputError, match="no such recording"):
        session_input_from_recording(tmp_path / "nope.mcap")
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(ReportInputError, match="empty file"):
        session_input_from_recording(empty)


def test_a_recording_without_state_is_refused(tmp_path):
    path = tmp_path / "meta_only.mcap"
    SessionRecorder(path, {"protocol_name": "x", "protocol_version": "1", "parameters": {},
                           "patient_id": "p", "robot_description": "r"}).close()
    with pytest.raises(ReportInputError, match="no robot state"):
        session_input_from_recording(path)


def test_truncated_recording_gives_a_report_that_says_so(sessions, tmp_path):
    _, path = sessions["sine"]
    cut = tmp_path / "cut.mcap"
    data = path.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    inp = session_input_from_recording(cut)
    assert inp.recording is not None and not inp.recording.complete
    assert 2.0 < inp.figures["duration_s"] < 24.0
    pdf = tmp_path / "cut.pdf"
    render_session_report(inp, pdf, clock=clock)
    text = pdftext(pdf)
    assert "RECORDING INCOMPLETE" in text and "incomplete" in text


def test_session_without_recording_reports_from_the_stored_summary(sessions, tmp_path):
    summary, _ = sessions["sine"]
    inp = session_input_from_record({"id": "S-17", "metadata": {"patient_id": "P-1"},
                                     "summary": summary}, tmp_path / "lost.mcap")
    pdf = tmp_path / "no_rec.pdf"
    render_session_report(inp, pdf, clock=clock)
    text = pdftext(pdf)
    assert "recording is missing" in text and fmt(summary["peak_force_n"], 1, "N") in text
    with pytest.raises(ReportInputError, match="nothing to report"):
        session_input_from_record({"id": "S-18"}, None)


def test_stored_hash_mismatch_is_reported(sessions):
    _, path = sessions["sine"]
    inp = session_input_from_record({"id": "S-1", "recording_sha256": "0" * 64}, path)
    assert "differs from the one stored" in inp.notes[0]


def test_existing_output_is_refused_and_kept(sessions, tmp_path):
    pdf = tmp_path / "keep.pdf"
    pdf.write_bytes(b"precious")
    inp = session_input_from_recording(sessions["sine"][1])
    with pytest.raises(ReportError, match="already exists"):
        render_session_report(inp, pdf, clock=clock)
    assert pdf.read_bytes() == b"precious"
    assert list(tmp_path.glob(".keep.pdf.*")) == []       # no temporary left behind


# ------------------------------------------------------------------------------ reproducible

def test_same_inputs_same_pdf_bytes_and_letter_paper(sessions, tmp_path):
    inp = session_input_from_recording(sessions["rom"][1])
    a, b = tmp_path / "a.pdf", tmp_path / "b.pdf"
    render_session_report(inp, a, clock=clock)
    render_session_report(session_input_from_recording(sessions["rom"][1]), b, clock=clock)
    assert a.read_bytes() == b.read_bytes()
    letter = tmp_path / "letter.pdf"
    render_session_report(inp, letter, ReportSettings(page_size=PageSize.LETTER), clock=clock)
    assert "612 x 792" in page_size(letter) and "595" in page_size(a)


# ------------------------------------------------------------------------------ progress

def test_progress_report_numbers(tmp_path):
    inp = load_progress_input(DEMO_PROGRESS)
    pdf = tmp_path / "progress.pdf"
    pages = render_progress_report(inp, pdf, clock=clock)
    pages_to_png(pdf, tmp_path, pages)
    assert_fonts_embedded(pdf)
    text = pdftext(pdf)
    adh = adherence(inp, inp.plan.start, inp.plan.end)
    assert adh == {"attended": 16, "planned": 18, "pct": pytest.approx(16 / 18 * 100)}
    assert "16 of 18 planned sessions attended (89 %)" in text
    rom = [s for s in inp.sessions if s.kind == "ankle_rom" and s.outcome == "completed"]
    days = [s.date for s in rom]
    plantar = [s.summary["rom_deg"]["pitch"][1] for s in rom]
    assert fmt(trend_per_week(days, plantar), 2, "°/week") in text
    assert fmt(max(plantar), 1, "°") in text and "twin-demo" in text
    letter = tmp_path / "letter.pdf"
    render_progress_report(inp, letter, ReportSettings(page_size=PageSize.LETTER), clock=clock)
    render_progress_report(inp, tmp_path / "again.pdf",
                           ReportSettings(page_size=PageSize.LETTER), clock=clock)
    assert letter.read_bytes() == (tmp_path / "again.pdf").read_bytes()
    assert "612 x 792" in page_size(letter)


def test_trend_is_the_least_squares_slope():
    from datetime import date, timedelta
    days = [date(2026, 1, 1) + timedelta(days=d) for d in (0, 7, 14, 21)]
    assert trend_per_week(days, [1.0, 2.0, 3.0, 4.0]) == pytest.approx(1.0)
    assert trend_per_week(days[:1], [1.0]) is None
    assert trend_per_week(days, [None, 2.0, None, None]) is None


def test_progress_without_sessions_says_so(tmp_path):
    inp = progress_input_from_dict({"patient_code": "P-9", "prescribed_rom_deg": {},
                                    "sessions": []})
    pdf = tmp_path / "empty.pdf"
    assert render_progress_report(inp, pdf, clock=clock) == 1
    assert "NO SESSIONS" in pdftext(pdf)
    full = load_progress_input(DEMO_PROGRESS)
    render_progress_report(full, tmp_path / "range.pdf", clock=clock, date_from="2027-01-01")
    assert "no session in the period asked" in pdftext(tmp_path / "range.pdf")


def test_progress_input_errors_name_the_field(tmp_path):
    with pytest.raises(ReportInputError, match=r"sessions\.0\.outcome"):
        progress_input_from_dict({"patient_code": "P", "prescribed_rom_deg": {},
                                  "sessions": [{"id": "1", "date": "2026-01-01",
                                                "protocol": "x", "outcome": "great"}]})
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ReportInputError, match="not valid JSON"):
        load_progress_input(bad)
    with pytest.raises(ReportInputError, match="before --from"):
        render_progress_report(load_progress_input(DEMO_PROGRESS), tmp_path / "x.pdf",
                               date_from="2026-11-01", date_to="2026-10-01")
    assert not (tmp_path / "x.pdf").exists()


# ------------------------------------------------------------------------------ certificate

def test_certificate_renders_the_record(tmp_path):
    rec = load_calibration_record(CAL_RECORD)
    pdf = tmp_path / "cert.pdf"
    pages = render_certificate(rec, pdf, clock=clock)
    pages_to_png(pdf, tmp_path, pages)
    assert_fonts_embedded(pdf)
    text = pdftext(pdf)
    assert "PASS" in text and rec.id in text and "Iñaki Núñez Gómez" in text
    assert rec.exports[0].sha256 in text.replace("\n", "").replace(" ", "") or \
        rec.exports[0].sha256[:40] in text
    m = rec.metrics["nonlinear"]
    assert fmt(m.cop_rms_mm, 2) in text and fmt(rec.thresholds["cop_rms_mm"], 2) in text
    assert fmt(rec.uncertainty.cop_mm, 2, "mm") in text
    assert "34 of 36 entries are identifiable" in text
    assert rec.model_extra == {"lab_notes": "added by the calibration engineer: room 21.5 °C"}
    again = tmp_path / "again.pdf"
    render_certificate(load_calibration_record(CAL_RECORD), again, clock=clock)
    assert again.read_bytes() == pdf.read_bytes()         # reproducible


def test_certificate_fail_verdict_and_bad_records(tmp_path):
    data = json.loads((CAL_RECORD).read_text())
    data["verdict"] = {"pass": False, "stage": "linear", "failed": ["cop_rms_mm"]}
    pdf = tmp_path / "fail.pdf"
    render_certificate(calibration_record_from_dict(data), pdf, clock=clock)
    text = pdftext(pdf)
    assert "FAIL" in text and "cop_rms_mm" in text and "PASS" not in text
    broken = json.loads((CAL_RECORD).read_text())
    del broken["plate"]["serial"]
    with pytest.raises(ReportInputError, match=r"plate\.serial"):
        calibration_record_from_dict(broken)
    broken = json.loads((CAL_RECORD).read_text())
    broken["cop_error_map"]["after_mm"] = broken["cop_error_map"]["after_mm"][:1]
    with pytest.raises(ReportInputError, match="cop_error_map.after_mm"):
        calibration_record_from_dict(broken)
    broken = json.loads((CAL_RECORD).read_text())
    broken["schema_version"] = 2
    with pytest.raises(ReportInputError, match="version 1"):
        calibration_record_from_dict(broken)


# ------------------------------------------------------------------------------ pieces

def test_envelope_keeps_extremes_within_budget():
    d = EnvelopeDecimator(target=100)
    t = np.arange(0, 600.0, 1e-3)
    y = np.sin(t) + (t == 123.456) * 5.0              # one spike must survive
    for i in range(0, len(t), 4096):
        d.add(t[i:i + 4096], y[i:i + 4096])
    e = d.envelope()
    assert 100 <= len(e) <= 200
    assert e.hi.max() == pytest.approx(y.max()) and e.lo.min() == pytest.approx(y.min())
    assert np.all(np.diff(e.t) > 0)


def test_settings_file_and_errors(tmp_path):
    logo = tmp_path / "logo.png"
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=(2, 1))
    fig.savefig(logo)
    plt.close(fig)
    f = tmp_path / "reports.yaml"
    f.write_text("schema_version: 1\nclinic_name: Clínica Peñalara\nlogo_path: logo.png\n"
                 "page_size: Letter\n")
    s = load_settings(f)
    assert s.clinic_name == "Clínica Peñalara" and s.logo_path == logo
    f.write_text("clinic_name: x\npage_size: A5\n")
    with pytest.raises(ConfigurationError, match="page_size"):
        load_settings(f)
    f.write_text("logo_path: missing.png\n")
    with pytest.raises(ConfigurationError, match="no such file"):
        load_settings(f)
    with pytest.raises(ConfigurationError, match="no such file"):
        load_settings(tmp_path / "absent.yaml")


def test_report_with_logo_and_accents(sessions, tmp_path):
    logo = tmp_path / "logo.png"
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=(2, 1))
    fig.savefig(logo)
    plt.close(fig)
    settings = ReportSettings(clinic_name="Hospital Núñez Gómez", logo_path=logo)
    pdf = tmp_path / "logo.pdf"
    render_session_report(session_input_from_recording(sessions["rom"][1]), pdf, settings,
                          clock=clock)
    assert "Hospital Núñez Gómez" in pdftext(pdf)


# ------------------------------------------------------------------------------ CLI

def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "talus", "report", *args],
                          check=False, capture_output=True, text=True, timeout=300)


def test_cli_calibration_and_refusals(tmp_path):
    out = tmp_path / "c.pdf"
    proc = _cli("calibration", "--record", str(CAL_RECORD), "--out",
                str(out), "--generated-at", "2026-11-23T17:00:00Z")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert res["pass"] is True and res["pages"] >= 2 and out.exists()
    before = out.read_bytes()
    proc = _cli("calibration", "--record", str(CAL_RECORD), "--out",
                str(out))
    assert proc.returncode == 2 and "already exists" in json.loads(proc.stdout)["error"]
    assert out.read_bytes() == before
    proc = _cli("session", "--recording", str(tmp_path / "none.mcap"), "--out",
                str(tmp_path / "s.pdf"))
    assert proc.returncode == 2 and "no such recording" in json.loads(proc.stdout)["error"]
    missing = tmp_path / "no-clinic.db"
    proc = _cli("progress", "--patient", "P-1", "--out", str(tmp_path / "p.pdf"), "--db",
                f"sqlite:///{missing}", "--user", "ana")
    assert proc.returncode == 2 and "no database" in json.loads(proc.stdout)["error"]
    assert not missing.exists()


def test_cli_session_is_reproducible(sessions, tmp_path):
    rec = sessions["rom"][1]
    outs = []
    for name in ("one.pdf", "two.pdf"):
        proc = _cli("session", "--recording", str(rec), "--out", str(tmp_path / name),
                    "--generated-at", "2026-11-23T17:00:00Z", "--page-size", "Letter")
        assert proc.returncode == 0, proc.stderr
        outs.append((tmp_path / name).read_bytes())
    assert outs[0] == outs[1]


def test_a_file_appearing_during_the_render_is_left_as_it_is(tmp_path, monkeypatch) -> None:
    """The existence check happens before the render; a file created meanwhile (another user,
    another report) must survive: the final step links, it does not rename over."""
    from reportlab.lib.styles import getSampleStyleSheet
    from reportlab.platypus import BaseDocTemplate, Paragraph

    from reports.document import ReportContext, write_pdf

    out = tmp_path / "r.pdf"
    build = BaseDocTemplate.build

    def build_then_someone_writes(self, *args, **kwargs):
        build(self, *args, **kwargs)
        out.write_bytes(b"someone else's file")

    monkeypatch.setattr(BaseDocTemplate, "build", build_then_someone_writes)
    ctx = ReportContext(title="t", settings=ReportSettings(),
                        generated_at=datetime(2026, 1, 1, tzinfo=UTC), software_version="x")
    with pytest.raises(ReportError, match="appeared while the report was rendered"):
        write_pdf(out, [Paragraph("hello", getSampleStyleSheet()["Normal"])], ctx)
    assert out.read_bytes() == b"someone else's file"
    assert [p.name for p in tmp_path.iterdir()] == ["r.pdf"]     # no temporary file left
