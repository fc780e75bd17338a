"""The real C3D files of ../shared/data/c3d (README there): every plate type loads, units by
physics, offsets removed, traceability, broken variants refused; a replay on the twin.

The files are never edited: broken variants are written with ezc3d into a temporary folder.
"""
from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from protocols import gait
from protocols.generators import make_generator
from protocols.library import parse_protocol_text
from rt.errors import ProtocolValidationError

ezc3d = pytest.importorskip("ezc3d")


def _data_dir() -> Path | None:
    for d in (os.environ.get("TALUS_C3D_DIR"), Path(__file__).parents[2] / "shared/data/c3d"):
        if d and (Path(d) / "functional_walk.c3d").is_file():
            return Path(d)
    return None


DATA = _data_dir()
pytestmark = pytest.mark.skipif(DATA is None, reason="the real C3D files (../shared/data/c3d "
                                "beside the repository, or $TALUS_C3D_DIR) are not present")


def _proto(tmp_path: Path, source: Path, plate: int, extra: str = "") -> str:
    return (f"schema_version: 1\nkind: gait_replay\nname: real\npose: {{z_m: 0.63}}\n"
            f"source: {source}\nplate_index: {plate}\npercent_body_weight: 60\n{extra}")


def _gen(tmp_path: Path, robot, source: Path, plate: int, extra: str = ""):
    proto = parse_protocol_text(_proto(tmp_path, source, plate, extra), str(tmp_path / "g.yaml"))
    return make_generator(proto, dt=1e-3, kinematics=robot.kin, patient_weight_kg=75.0,
                          base_dir=tmp_path)


def test_type4_cal_matrix_gives_the_type2_forces():
    """Same plate data stored as type 2 (scaled) and type 4 (CAL_MATRIX applied to the
    pre-calibration channels): the vertical forces agree to 1 % of the peak RMS and 2.5 % at
    the peak (Vicon's type-2 gain for Fz is 1.2 % above the matrix's diagonal)."""
    t2 = gait.read_grf_c3d(DATA / "type2_vicon.c3d", 0)
    t4 = gait.read_grf_c3d(DATA / "type4_vicon.c3d", 0)
    peak = t2.fz.max()
    assert 380.0 < peak < 410.0
    assert np.sqrt(np.mean((t2.fz - t4.fz) ** 2)) < 0.01 * peak
    assert t4.fz.max() == pytest.approx(peak, rel=0.025)
    assert t2.sha256 != t4.sha256 and len(t2.sha256) == 64


def test_kistler_type3_loads_with_its_newtons_labels():
    rec = gait.read_grf_c3d(DATA / "type3_kistler_fp1.c3d", 0)
    assert 270.0 < rec.fz.max() < 300.0 and rec.units == "Newtons"
    assert not rec.offset_measured            # loaded from its first sample: no quiet stretch


def test_functional_walk_body_mass_and_units_from_physics(tmp_path, robot):
    """Labelled 'V', the data are N: the stance peaks at 1.18 BW of the file's 60 kg."""
    gen = _gen(tmp_path, robot, DATA / "functional_walk.c3d", 0)
    assert gen.validate().ok
    info = gen.info
    assert info["source_body_mass_kg"] == 60.0
    assert info["source_body_mass_from"] == "PROCESSING:Bodymass"
    assert 1.1 < info["source_peak_bw"] < 1.25
    assert info["scale_factor"] == pytest.approx(0.60 * 75.0 / 60.0, rel=1e-12)
    assert info["source_sha256"] == hashlib.sha256(
        (DATA / "functional_walk.c3d").read_bytes()).hexdigest()
    with pytest.raises(ProtocolValidationError, match="states PROCESSING:Bodymass = 60 kg"):
        _gen(tmp_path, robot, DATA / "functional_walk.c3d", 0, "source_body_weight_kg: 80\n")


def test_unloaded_offset_is_removed_and_reported():
    """eb015pi's unloaded plates read tens of N; after removal they read 0 within their noise."""
    for plate, expected in ((0, 21.6), (1, 31.3)):
        rec = gait.read_grf_c3d(DATA / "eb015pi_offset.c3d", plate)
        assert rec.offset_measured and rec.offset_n[2] == pytest.approx(expected, abs=1.0)
        before_contact = rec.fz[: int(2.0 * 200)]
        assert abs(float(np.median(before_contact))) < 1.0


def test_heel_strike_transient_is_replayed(tmp_path, robot):
    """functional_walk plate 0: ~0.5 BW within 10 ms of contact; the replay keeps it (the old
    20 ms taper after a 20 N threshold erased it)."""
    gen = _gen(tmp_path, robot, DATA / "functional_walk.c3d", 0)
    assert gen.validate().ok
    st, fz = gen.stance, gen.samples()["fz"]
    contact = gen.info["contact_s"][0] - st.start_s       # s into the replay
    k = round(contact * 1000.0)
    spike = fz[k:k + 10].max() / gen.scale               # N of the record
    assert spike > 0.45 * 60.0 * gait.STANDARD_GRAVITY_M_S2
    assert fz[:k].max() < 0.05 * fz.max()                 # the lead-in is unloaded


def test_broken_variants_are_refused(tmp_path):
    c = ezc3d.c3d(str(DATA / "type2_vicon.c3d"))
    c["parameters"]["FORCE_PLATFORM"]["TYPE"]["value"] = np.array([1])
    c.write(str(tmp_path / "type1.c3d"))
    with pytest.raises(ProtocolValidationError, match="type 1 is not supported"):
        gait.read_grf_c3d(tmp_path / "type1.c3d", 0)
    for name in ("type2_vicon.c3d", "functional_walk.c3d"):
        data = (DATA / name).read_bytes()
        (tmp_path / name).write_bytes(data[: len(data) // 2])
        with pytest.raises(ProtocolValidationError, match="the file is truncated"):
            gait.read_grf_c3d(tmp_path / name, 0)


def test_relabelled_units_change_nothing_but_a_wrong_scale_is_refused(tmp_path, robot):
    c = ezc3d.c3d(str(DATA / "functional_walk.c3d"))
    c["parameters"]["ANALOG"]["UNITS"]["value"] = ["kN"] * len(
        c["parameters"]["ANALOG"]["UNITS"]["value"])
    c.write(str(tmp_path / "relabelled.c3d"))
    gen = _gen(tmp_path, robot, tmp_path / "relabelled.c3d", 0)
    assert gen.validate().ok and 1.1 < gen.info["source_peak_bw"] < 1.25
    c = ezc3d.c3d(str(DATA / "functional_walk.c3d"))
    c["data"]["analogs"] = c["data"]["analogs"] / 4.448   # the same forces in lbf
    c.write(str(tmp_path / "lbf.c3d"))
    with pytest.raises(ProtocolValidationError) as exc:
        _gen(tmp_path, robot, tmp_path / "lbf.c3d", 0)
    assert "body weights of the 60 kg subject (PROCESSING:Bodymass)" in str(exc.value)
    assert "a stance peaks at 0.5-3 BW, 294-1765 N" in str(exc.value)


def _bench():
    """bench/gait_files.py: the protocols the figures are measured with (one table)."""
    import importlib.util

    path = Path(__file__).parents[1] / "bench" / "gait_files.py"
    spec = importlib.util.spec_from_file_location("bench_gait_files", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


#: Each file's (first plate's) force RMS error bound, % of the peak: the figure measured on the
#: twin (type2 2.39, type4 2.39, type3 0.35, functional_walk 2.60, eb015pi 0.33) with margin;
#: functional_walk's is DESIGN's 3 % itself (it was 3.22 % before the unloading governor
#: allowed for the force loop's lag and braked at 1 m/s² instead of 0.5).
RMS_BOUND_PCT = {"type2_vicon.c3d": 2.8, "type4_vicon.c3d": 2.8, "type3_kistler_fp1.c3d": 0.6,
                 "functional_walk.c3d": 3.0, "eb015pi_offset.c3d": 0.6}
HEEL_STRIKES = {"type2_vicon.c3d", "type4_vicon.c3d", "functional_walk.c3d"}


@pytest.mark.parametrize("name", ["type2_vicon.c3d", "type4_vicon.c3d", "type3_kistler_fp1.c3d",
                                  "functional_walk.c3d", "eb015pi_offset.c3d"])
def test_each_real_file_replays_on_the_twin_without_pulling(tmp_path, name):
    """Pre-flight and the run on the twin, recorded: completed without a stop, the force in
    contact never below 0 N, the source's traceability in the summary and the recording."""
    from protocols.session import SessionSetup, run_session
    from rt.recording.reader import read_recording

    bench = _bench()
    case = next(c for c in bench.CASES if c.file == name)
    path = tmp_path / "gait.yaml"
    path.write_text(bench.protocol_text(case, DATA))
    s = run_session(SessionSetup(path, patient_weight_kg=bench.PATIENT_KG), tmp_path / "g.mcap")
    assert s["completed"] and s["stops"] == [], s["stops"]
    assert s["min_force_n"] >= 0.0
    # Twin figures (bench/gait_files.py --in-process; deterministic): heel strikes rise by
    # 0.5 BW in ~5 ms, beyond what the actuators can follow. The force law's preview and its
    # integral held through such a rise took them from 3.9-4.5 % to 2.4-3.2 % of the peak,
    # the unloading governor's lag allowance to 2.3-2.6 % (functional_walk plate 0's toe off
    # was the one above the 3 % target); the slow 200 Hz and quasi-static records track
    # within 0.4 %.
    assert s["rms_error_pct"] <= RMS_BOUND_PCT[name], s["rms_error_pct"]
    # Where the protocol was beyond the robot is reported, not hidden: the heel strikes ask
    # the drives more than their ≈ 2 kN for a few ms (allowed: under 20 ms).
    beyond = {b["what"]: b for b in s["preflight"]["at_robot_limit"]}
    # And how close that came to the supervisor's sustained-saturation stop (more than half of
    # any 0.5 s window at the drives' limit): a heel strike's few ms per window, far from it.
    sat = s["preflight"]["drive_saturation"]
    assert sat["window_s"] == 0.5 and sat["stops_beyond_s"] == 0.25
    assert sat["peak_s"] == max(sat["per_axis_s"])
    if name in HEEL_STRIKES:
        hit = beyond["actuator force"]
        assert hit["peak"] > hit["limit"] == 2000.0 and 0.0 < hit["longest_s"] <= 0.02
        assert 0.0 < hit["from_s"] < s["duration_s"]
        assert 0.0 < sat["peak_s"] <= 0.05, sat
    else:
        assert beyond == {}
        assert sat["peak_s"] == 0.0, sat
    src = s["source"]
    assert src["source_sha256"] == hashlib.sha256((DATA / name).read_bytes()).hexdigest()
    assert src["plate_index"] == case.plate and src["scale_factor"] > 0.0
    meta = read_recording(tmp_path / "g.mcap")["/protocol/metadata"][0]
    assert meta["source"]["source_sha256"] == src["source_sha256"]
    assert meta["source"]["stance_window_s"] == src["stance_window_s"]
    assert meta["source"]["offset_removed_n"] == src["offset_removed_n"]
