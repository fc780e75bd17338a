"""A campaign folder end to end through the command line: plan, run, fit, export, verify; the
record's contract; refusals (missing trial, clocks that do not align, existing outputs); the
exported C3D read back by ezc3d."""
from __future__ import annotations

import json
import shutil
from datetime import UTC, datetime
from pathlib import Path

import ezc3d
import numpy as np
import pytest

from calibration import c3d_export, campaign
from calibration.metrics import Thresholds
from calibration.plate import KISTLER_CHANNELS, PlateKind
from calibration.trial import CAMPAIGN_FILE, TRIALS_DIR, TrialData
from rt.errors import ConfigurationError, InputError
from talus.cli import main

SHORT_PLAN = """schema_version: 1
name: short test plan
loads_n: [200.0, 800.0, 1500.0]
grid: {nx: 2, ny: 2, margin_m: 0.08}
sine_sites: none
gait_sites: centre
registration: nominal
"""

#: The keys the calibration record contract (docs/calibration_record.md) requires.
CONTRACT = {
    "": ["schema_version", "kind", "id", "created_utc", "operator", "software_version", "plate",
         "reference_sensor", "registration", "plan", "thresholds", "metrics", "verdict",
         "cop_error_map", "matrix", "nonlinear_correction", "uncertainty", "exports"],
    "plate": ["name", "manufacturer", "model", "serial", "kind", "size_m", "corners_m",
              "origin_m", "force_range_n", "description_sha256"],
    "reference_sensor": ["model", "serial", "calibration_certificate", "calibration_date",
                         "accuracy_pct_fs", "full_scale"],
    "registration": ["method", "T_robot_plate", "sigma_translation_mm", "sigma_rotation_deg"],
    "plan": ["grid_m", "loads_n", "trials"],
    "thresholds": ["cop_rms_mm", "cop_max_mm", "force_pct_fs", "crosstalk_pct"],
    "verdict": ["pass", "stage", "failed"],
    "cop_error_map": ["x_m", "y_m", "before_mm", "after_mm"],
    "matrix": ["cal_matrix", "standard_error", "identified", "channel_order", "moment_unit"],
    "uncertainty": ["k", "force_n", "moment_nm", "cop_mm", "budget"],
}
METRIC_KEYS = ["force_pct_fs", "force_pct_applied", "cop_rms_mm", "cop_max_mm", "crosstalk_pct",
               "linearity_pct_fs", "hysteresis_pct_fs", "repeatability_pct_fs"]


def _cli(capsys, *argv: str) -> tuple[int, dict]:
    code = main(["calibrate", *argv])
    out = capsys.readouterr().out
    return code, json.loads(out)


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("cal")
    (root / "plan.yaml").write_text(SHORT_PLAN)
    assert main(["calibrate", "run", "--plan", str(root / "plan.yaml"), "--out",
                 str(root / "campaign"), "--backend", "direct"]) == 0
    return root / "campaign"


def test_plan_command_writes_the_default_plan(tmp_path: Path, capsys) -> None:
    code, out = _cli(capsys, "plan", "--out", str(tmp_path / "plan.yaml"))
    assert code == 0 and out["trials"] == 33 and out["held_out_trials"] == 9
    assert out["sites"] == 21
    code, again = _cli(capsys, "plan", "--plan", str(tmp_path / "plan.yaml"))
    assert code == 0 and again["trial_ids"] == out["trial_ids"]
    code, err = _cli(capsys, "plan", "--out", str(tmp_path / "plan.yaml"))
    assert code == 2 and "exists" in err["error"]
    (tmp_path / "bad.yaml").write_text("schema_version: 1\nloads_n: [500, 200]\n")
    code, err = _cli(capsys, "plan", "--plan", str(tmp_path / "bad.yaml"))
    assert code == 2 and "bad.yaml, line 2: loads_n: must be strictly increasing" in err["error"]


def test_fit_writes_a_record_following_the_contract(campaign_dir: Path, tmp_path: Path,
                                                    capsys) -> None:
    record_path = tmp_path / "cal.json"
    code, out = _cli(capsys, "fit", "--campaign", str(campaign_dir), "--record",
                     str(record_path), "--operator", "engineer-1")
    assert code == 0, out
    text = record_path.read_text()
    assert "NaN" not in text and "Infinity" not in text
    record = json.loads(text)
    for block, keys in CONTRACT.items():
        where = record[block] if block else record
        assert set(keys) <= set(where), (block, set(keys) - set(where))
    for stage in ("before", "linear", "nonlinear"):
        assert set(METRIC_KEYS) <= set(record["metrics"][stage])
        assert len(record["metrics"][stage]["force_pct_fs"]) == 6
    assert record["schema_version"] == 1 and record["kind"] == "talus.calibration_record"
    assert record["operator"] == "engineer-1"
    assert np.array(record["matrix"]["cal_matrix"]).shape == (6, 6)
    assert np.array(record["registration"]["T_robot_plate"]).shape == (4, 4)
    assert record["uncertainty"]["k"] == 2
    assert len(record["uncertainty"]["force_n"]) == 6 and len(record["uncertainty"]["moment_nm"]) == 3
    assert record["verdict"]["stage"] == "nonlinear"
    assert out["cop_rms_mm"]["nonlinear"] < out["cop_rms_mm"]["before"]
    # The Mz channel is never excited: its column is not claimed.
    assert "Fz<-Mz" in out["not_identified"]
    # An existing record is not overwritten.
    code, err = _cli(capsys, "fit", "--campaign", str(campaign_dir), "--record",
                     str(record_path))
    assert code == 2 and "exists" in err["error"]


def test_record_date_comes_from_the_injected_clock(campaign_dir: Path) -> None:
    p = campaign.process(campaign_dir)
    fixed = datetime(2026, 11, 23, 17, 0, 0, tzinfo=UTC)
    record = campaign.build_record(campaign_dir, p, Thresholds(), campaign.ReferenceSensor(),
                                   "op", now=lambda: fixed)
    assert record["created_utc"] == "2026-11-23T17:00:00Z"
    assert record["id"].startswith("CAL-20261123-170000-")


def test_a_campaign_with_a_missing_trial_is_refused(campaign_dir: Path, tmp_path: Path,
                                                    capsys) -> None:
    broken = tmp_path / "broken"
    shutil.copytree(campaign_dir, broken)
    victim = next((broken / TRIALS_DIR).glob("G00-steps.npz"))
    victim.unlink()
    code, err = _cli(capsys, "fit", "--campaign", str(broken))
    assert code == 2 and "trial G00-steps is missing" in err["error"]
    # Dropped from the index as well: the plan still lists it.
    index = json.loads((broken / CAMPAIGN_FILE).read_text())
    index["trials"] = [e for e in index["trials"] if e["id"] != "G00-steps"]
    (broken / CAMPAIGN_FILE).write_text(json.dumps(index))
    with pytest.raises(ConfigurationError, match="missing planned trial.*G00-steps"):
        campaign.process(broken)
    assert not (broken / "calibration_record.json").exists()
    # A changed trial file is refused too.
    other = next((broken / TRIALS_DIR).glob("G10-steps.npz"))
    other.write_bytes(other.read_bytes()[:-10])
    with pytest.raises(ConfigurationError, match="changed since it was recorded"):
        campaign.read_campaign(broken)


def test_clocks_that_do_not_align_are_refused(campaign_dir: Path, tmp_path: Path,
                                              capsys) -> None:
    broken = tmp_path / "clock"
    shutil.copytree(campaign_dir, broken)
    index = json.loads((broken / CAMPAIGN_FILE).read_text())
    entry = next(e for e in index["trials"] if e["id"] == "G10-steps")
    path = broken / TRIALS_DIR / "G10-steps.npz"
    d = TrialData.load(path)
    d.t_plate = d.t_plate + 0.050            # this trial's plate clock jumped 50 ms
    entry["sha256"] = d.save(path)
    (broken / CAMPAIGN_FILE).write_text(json.dumps(index))
    code, err = _cli(capsys, "fit", "--campaign", str(broken))
    assert code == 2 and "the clocks do not align" in err["error"]
    # A plate that recorded another trial's loads: no correlation.
    d = TrialData.load(path)
    d.channels = d.channels[::-1].copy()
    entry["sha256"] = d.save(path)
    (broken / CAMPAIGN_FILE).write_text(json.dumps(index))
    code, err = _cli(capsys, "fit", "--campaign", str(broken))
    assert code == 2 and ("do not line up" in err["error"]
                          or "the clocks do not align" in err["error"])


def test_export_c3d_read_back_by_ezc3d_gives_the_fitted_forces(campaign_dir: Path,
                                                               tmp_path: Path, capsys) -> None:
    record_path = tmp_path / "cal.json"
    assert _cli(capsys, "fit", "--campaign", str(campaign_dir), "--record",
                str(record_path))[0] == 0
    c3d_path, csv_path = tmp_path / "plate.c3d", tmp_path / "ref.csv"
    code, out = _cli(capsys, "export", "--campaign", str(campaign_dir), "--c3d", str(c3d_path),
                     "--reference-csv", str(csv_path), "--record", str(record_path))
    assert code == 0, out
    record = json.loads(record_path.read_text())
    assert {e["kind"] for e in record["exports"]} == {"c3d", "reference_csv"}
    C = np.array(record["matrix"]["cal_matrix"])
    c = ezc3d.c3d(str(c3d_path), extract_forceplat_data=True)
    fp = c["parameters"]["FORCE_PLATFORM"]
    assert int(fp["TYPE"]["value"][0]) == 4
    assert np.allclose(fp["CAL_MATRIX"]["value"][:, :, 0], C, rtol=1e-6)
    platform = c["data"]["platform"][0]
    raw = c["data"]["analogs"][0]                     # 6 × n, the raw channels (V)
    expected = c3d_export.R_GF @ (C @ raw)[:3]
    # float32 storage of the channels: 1e-6 relative.
    assert np.allclose(platform["force"], expected, atol=1e-5 * np.abs(expected).max())
    moments_c = (C @ raw)[3:] + np.cross(np.array(record["plate"]["origin_m"]),
                                         (C @ raw)[:3].T).T
    assert np.allclose(platform["moment"], c3d_export.R_GF @ moments_c,
                       atol=1e-5 * np.abs(moments_c).max())
    # The reference CSV: same instants, same frame; the plate agrees within its calibration.
    header = csv_path.read_text().splitlines()[0]
    assert header == "t,Fx,Fy,Fz,Mx,My,Mz,COPx,COPy"
    ref = np.loadtxt(csv_path, delimiter=",", skiprows=1)
    assert ref.shape[0] == platform["force"].shape[1]
    loaded = ref[:, 3] < -300.0                       # G's Z is up: pressing is negative
    assert loaded.sum() > 100
    err = np.abs(platform["force"].T[loaded] - ref[loaded, 1:4])
    assert np.max(err) < 0.01 * 4000.0
    cop_err = np.linalg.norm(platform["center_of_pressure"][:2].T[loaded] - ref[loaded, 7:9],
                             axis=1)
    assert np.sqrt(np.mean(cop_err ** 2)) < 3e-3     # linear stage only in C3D
    # Existing outputs are refused.
    code, err = _cli(capsys, "export", "--campaign", str(campaign_dir), "--c3d", str(c3d_path),
                     "--reference-csv", str(tmp_path / "other.csv"))
    assert code == 2 and "exists" in err["error"]


def test_verify_checks_a_record_without_fitting(campaign_dir: Path, tmp_path: Path,
                                                capsys) -> None:
    record_path = tmp_path / "cal.json"
    assert _cli(capsys, "fit", "--campaign", str(campaign_dir), "--record",
                str(record_path))[0] == 0
    code, out = _cli(capsys, "verify", "--record", str(record_path), "--out",
                     str(tmp_path / "check"), "--backend", "direct")
    assert code == 0, out
    assert out["metrics"]["nonlinear"]["cop_rms_mm"] < out["metrics"]["before"]["cop_rms_mm"]
    assert len(out["sites"]) == 9
    assert (tmp_path / "check" / "verification.json").is_file()
    code, err = _cli(capsys, "verify", "--record", str(record_path), "--out",
                     str(tmp_path / "check2"), "--backend", "direct", "--load", "100")
    assert code == 2 and "at least 200 N" in err["error"]


def test_run_refuses_a_used_folder_and_an_absent_rt_process(campaign_dir: Path, capsys) -> None:
    code, err = _cli(capsys, "run", "--out", str(campaign_dir), "--backend", "direct")
    assert code == 2 and "not empty" in err["error"]
    code, err = _cli(capsys, "run", "--out", str(campaign_dir.parent / "x"), "--backend", "rt",
                     "--endpoint", "tcp://127.0.0.1:9")
    assert code == 2 and "no RT process answers at tcp://127.0.0.1:9" in err["error"]
    assert not (campaign_dir.parent / "x").exists()


def test_export_refuses_a_kistler_plate_without_its_sensor_offsets(campaign_dir: Path,
                                                                  tmp_path: Path) -> None:
    p = campaign.process(campaign_dir)
    kistler = p.plate.model_copy(update={"kind": PlateKind.KISTLER8})
    object.__setattr__(kistler, "channels", list(p.plate.channels) * 2)
    p.plate = kistler
    with pytest.raises(InputError, match="TYPE 3 needs the Kistler sensor offsets"):
        c3d_export.export(campaign_dir, p, tmp_path / "x.c3d", tmp_path / "x.csv")
    assert not (tmp_path / "x.c3d").exists()


KISTLER_PLATE = """schema_version: 1
name: Kistler 9260AA
kind: kistler8
channels: [{label: fx12}, {label: fx34}, {label: fy14}, {label: fy23},
           {label: fz1}, {label: fz2}, {label: fz3}, {label: fz4}]
size_m: [0.6, 0.5]
origin_m: [0.004, -0.003, 0.041]
force_range_n: [5000, 5000, 10000]
moment_range_nm: [2000, 2000, 1000]
kistler: {a_m: 0.21, b_m: 0.16, az0_m: 0.041}
"""


def test_kistler_type3_export_reproduces_the_fitted_forces(tmp_path: Path) -> None:
    """An eight-channel Kistler calibration (a 6×8 matrix with sensitivity and crosstalk errors
    the Kistler formulas cannot express) exported as TYPE 3: ezc3d and the project's own C3D
    reader (protocols.gait, which the gait replay uses) give back C v, the fitted forces."""
    from calibration.plate import load_plate
    from protocols.gait import read_grf_c3d

    (tmp_path / "k.yaml").write_text(KISTLER_PLATE)
    plate = load_plate(tmp_path / "k.yaml")
    rng = np.random.default_rng(7)
    C = plate.nominal_C() @ (np.eye(8) + rng.normal(0.0, 0.02, (8, 8)))
    n = 2000                                            # 2 s at 1 kHz: quiet, then a push
    t = np.arange(n) / plate.sample_rate_hz
    load = 800.0 * np.clip((t - 0.6) / 0.3, 0.0, 1.0)
    v = np.column_stack([0.02 * load, 0.01 * load, -0.03 * load, 0.0 * load,
                         0.2 * load, 0.3 * load, 0.25 * load, 0.25 * load]) \
        * np.array([ch.scale for ch in plate.channels]) ** -1     # the raw channels
    w = v @ C.T                                         # the fitted wrench about O
    corners = plate.corners_F() @ c3d_export.R_GF.T
    path = tmp_path / "kistler.c3d"
    c3d_export.write_c3d(path, plate, C, v, corners)
    c = ezc3d.c3d(str(path), extract_forceplat_data=True)
    fp = c["parameters"]["FORCE_PLATFORM"]
    assert int(fp["TYPE"]["value"][0]) == 3
    assert list(c["parameters"]["ANALOG"]["LABELS"]["value"]) == list(KISTLER_CHANNELS)
    platform = c["data"]["platform"][0]
    expected_f = c3d_export.R_GF @ w[:, :3].T
    # float32 channels: 1e-5 of the peak.
    assert np.allclose(platform["force"], expected_f, atol=1e-5 * np.abs(expected_f).max())
    origin = np.array(plate.origin_m)
    m_c = (w[:, 3:] + np.cross(origin, w[:, :3])).T     # about the surface centre, as TYPE 4
    assert np.allclose(platform["moment"], c3d_export.R_GF @ m_c,
                       atol=1e-5 * np.abs(m_c).max())
    grf = read_grf_c3d(path, 0)
    assert grf.fz.max() == pytest.approx(w[:, 2].max(), rel=1e-5)
    # The reader flips so that loading is positive: Fz up to 800 N, shear in the same frame.
    assert np.allclose(np.abs(grf.fx), np.abs(expected_f[0]), atol=1e-4 * 800.0)
    assert np.allclose(np.abs(grf.fy), np.abs(expected_f[1]), atol=1e-4 * 800.0)
