"""Plate description files, the twin plate's truth, the plate DAQ through comedi."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from calibration.plate import (
    TWIN_PLATE_FILE,
    PlateKind,
    cop_F,
    kistler_matrix,
    load_plate,
    wrench_at_point,
)
from calibration.twin_plate import TruthSettings, TwinPlate, draw_truth, expected_matrix, quantize
from rt.drivers.comedi_plate import ComediForcePlate
from rt.drivers.fake_comedi_ai import FakeComediAnalogInput
from rt.errors import ConfigurationError, HardwareError

GOOD = TWIN_PLATE_FILE.read_text()


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "plate.yaml"
    p.write_text(text)
    return p


def test_twin_plate_file_loads() -> None:
    plate = load_plate(TWIN_PLATE_FILE)
    assert plate.kind == PlateKind.SIX_CHANNEL
    assert np.allclose(np.diag(plate.nominal_C()), [200, 200, 400, 120, 80, 40])
    assert len(plate.sha256) == 64
    # C3D corner order: x = c1 - c2, y = c1 - c4 give the plate's axes.
    c = plate.corners_F()
    assert np.allclose((c[0] - c[1]) / np.linalg.norm(c[0] - c[1]), [1, 0, 0])
    assert np.allclose((c[0] - c[3]) / np.linalg.norm(c[0] - c[3]), [0, 1, 0])


@pytest.mark.parametrize("old, new, expected", [
    ("  - [0, 0, 0, 0, 0, 1]\n", "  - [0, 0, 0, 0, 1]\n", "nominal_matrix: must be 6 rows of 6"),
    ("kind: six_channel", "kind: eight_channel", "line 10: kind:"),
    ("size_m: [0.600, 0.400]", "size_m: [0.600, -0.400]", "line 18: size_m[1]: Input should be greater than 0"),
    ("serial: TWIN-0001", "serial: TWIN-0001\ncolour: blue", "colour: unknown key"),
    ("serial: TWIN-0001", "serial: TWIN-0001\nserial: TWIN-0002", "duplicate key 'serial'"),
    ("force_range_n: [2000.0, 2000.0, 4000.0]\n", "", "force_range_n: required field"),
    ("  - {label: Mz, unit: V, scale: 40.0, range: 10.0}\n", "", "line 11: channels: List should have at least 6 items"),
    ("  - [0, 0, 0, 0, 0, 1]\n", "  - [0, 0, 0, 0, 1, 0]\n", "rank < 6"),
    ("origin_m: [0.0, 0.0, 0.042]", "origin_m: [0.5, 0.0, 0.042]", "outside the plate"),
])
def test_malformed_plate_files_are_refused_with_the_place(tmp_path: Path, old: str, new: str,
                                                           expected: str) -> None:
    assert old in GOOD
    path = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ConfigurationError) as err:
        load_plate(path)
    assert str(path) in str(err.value)
    assert expected in str(err.value)


def test_empty_and_unreadable_plate_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigurationError, match="empty"):
        load_plate(_write(tmp_path, ""))
    with pytest.raises(ConfigurationError, match="no-such.yaml: cannot read"):
        load_plate(tmp_path / "no-such.yaml")
    with pytest.raises(ConfigurationError, match="line 3: YAML syntax error"):
        load_plate(_write(tmp_path, "schema_version: 1\nname: [unclosed\n"))


def test_kistler_plate_gets_its_matrix_from_the_sensor_offsets(tmp_path: Path) -> None:
    text = """schema_version: 1
name: Kistler 9260AA
kind: kistler8
channels: [{label: fx12}, {label: fx34}, {label: fy14}, {label: fy23},
           {label: fz1}, {label: fz2}, {label: fz3}, {label: fz4}]
size_m: [0.6, 0.5]
origin_m: [0.0, 0.0, 0.041]
force_range_n: [5000, 5000, 10000]
moment_range_nm: [2000, 2000, 1000]
kistler: {a_m: 0.21, b_m: 0.16, az0_m: 0.041}
"""
    plate = load_plate(_write(tmp_path, text))
    C = plate.nominal_C()
    assert C.shape == (6, 8)
    # A vertical load at (x, y) on the sensor plane: fz_i shared so that M = r × F.
    fz = np.array([1.0, 2.0, 3.0, 4.0])
    w = C @ np.r_[0, 0, 0, 0, fz]
    assert w[2] == pytest.approx(10.0)
    assert w[3] == pytest.approx(0.16 * (1 + 2 - 3 - 4))
    assert np.allclose(kistler_matrix(plate.kistler), plate.matrix_without_scales())


@given(st.floats(-0.29, 0.29), st.floats(-0.19, 0.19), st.floats(50.0, 3000.0),
       st.floats(-200.0, 200.0), st.floats(-200.0, 200.0), st.floats(-20.0, 20.0))
def test_cop_of_a_load_is_its_point(x: float, y: float, fz: float, fx: float, fy: float,
                                    tz: float) -> None:
    origin = np.array([0.003, -0.002, 0.042])
    w = wrench_at_point(np.array([fx, fy, fz]), np.array([x, y, 0.0]), origin, tz)
    cop, free = cop_F(w, origin)
    assert np.allclose(cop, [x, y], atol=1e-12)
    assert free == pytest.approx(tz, abs=1e-9)


def test_ideal_twin_plate_is_its_expected_matrix() -> None:
    """A plate with no bending, noise or nonlinearity is exactly linear: the expected matrix
    (C_true with its moments moved to the stated origin) maps its channels to the load."""
    plate = load_plate(TWIN_PLATE_FILE)
    truth = draw_truth(plate, TruthSettings.ideal(), seed=3)
    twin = TwinPlate(plate, truth)
    rng = np.random.default_rng(0)
    f = rng.uniform([-200, -200, 50], [200, 200, 2000], (50, 3))
    p = np.column_stack([rng.uniform(-0.3, 0.3, 50), rng.uniform(-0.2, 0.2, 50), np.zeros(50)])
    v = twin.channels(f, p, np.zeros(50))
    w = v @ expected_matrix(plate, truth).T
    assert np.allclose(w, wrench_at_point(f, p, plate.origin_m), atol=1e-9)


def test_twin_plate_truth_magnitudes() -> None:
    plate = load_plate(TWIN_PLATE_FILE)
    truth = draw_truth(plate)
    assert np.all(np.abs(np.diag(truth.E)) <= 0.03)
    off = truth.E - np.diag(np.diag(truth.E))
    assert np.all(np.abs(off) <= 0.02)
    corner = truth.bending_F(plate, np.array([[0.3, 0.2, 0.0]]))[0]
    assert np.linalg.norm(corner) * 1e3 == pytest.approx(10.0, rel=1e-9)
    assert np.linalg.norm(truth.bending_F(plate, np.zeros((1, 3)))) == 0.0
    # The plate's clock runs apart from the robot's.
    twin = TwinPlate(plate, truth)
    assert twin.plate_time(100.0) - 100.0 == pytest.approx(0.2371 + 80e-6 * 100.0)


def test_quantization_is_16_bit_over_the_range() -> None:
    ranges = np.array([10.0])
    lsb = 20.0 / 65535
    v = np.linspace(-9.9, 9.9, 1001)[:, None]
    q = quantize(v, ranges)
    assert np.max(np.abs(q - v)) <= lsb / 2 + 1e-12
    assert quantize(np.array([[12.0]]), ranges)[0, 0] == pytest.approx(10.0)


# ---------------------------------------------------------------------- the plate's DAQ
def test_comedi_plate_reads_volts_within_one_code() -> None:
    lib = FakeComediAnalogInput()
    lib.volts = {0: 1.2345, 1: -3.0, 2: 9.5, 3: 0.0, 4: -9.99, 5: 4.4}
    with ComediForcePlate(device="/dev/comedi1", channels=(0, 1, 2, 3, 4, 5), lib=lib) as plate:
        out = plate.read_channels(np.zeros(6))
    lsb = 20.0 / 65535
    assert np.allclose(out, [1.2345, -3.0, 9.5, 0.0, -9.99, 4.4], atol=lsb)
    assert not plate.saturated
    assert lib.opened == [b"/dev/comedi1"] and lib.closed == 1
    assert all(r[3] == 2 for r in lib.reads)         # differential inputs
    plate.close()                                    # safe twice
    assert lib.closed == 1


def test_comedi_plate_faults() -> None:
    lib = FakeComediAnalogInput()
    lib.volts = {2: 11.0}
    plate = ComediForcePlate(lib=lib)
    plate.read_channels(np.zeros(6))
    assert plate.saturated
    lib.fail_reads = True
    with pytest.raises(HardwareError, match="AI channel 0: read failed: fake comedi error 5"):
        plate.read_channels(np.zeros(6))
    plate.close()
    with pytest.raises(HardwareError, match="closed"):
        plate.read_channels(np.zeros(6))
    lib.fail_open = True
    with pytest.raises(HardwareError, match="cannot open"):
        ComediForcePlate(lib=lib)
    lib.fail_open = False
    with pytest.raises(ConfigurationError, match="AI channel 16 does not exist"):
        ComediForcePlate(channels=(0, 16), lib=lib)
    with pytest.raises(ConfigurationError, match="range 7 does not exist"):
        ComediForcePlate(range_index=7, lib=lib)
    with pytest.raises(ConfigurationError, match="distinct"):
        ComediForcePlate(channels=(0, 0), lib=lib)
