"""The plate's DAQ acquired by the calibration client (calibration.plate_daq) and the twin plate
behind the real comedi driver (calibration.twin_plate_daq): scans on the plate's own clock,
refusals of a failed, clipping or overflowing acquisition, and the twin plate's channels read
through ComediForcePlate equal to the twin plate's model of the published contact."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from calibration import registration as reg
from calibration.plate import TWIN_PLATE_FILE, load_plate
from calibration.plate_daq import DaqConfig, PlateAcquisition, load_daq_config, open_plate_device
from calibration.push import TOOL_LENGTH_M
from calibration.twin_plate import TruthSettings, TwinPlate, draw_truth
from calibration.twin_plate_daq import TwinPlateDaq, WirePublisher
from rt.devices.interfaces import ForcePlate
from rt.errors import ConfigurationError, HardwareError, InputError
from rt.model import RobotModel


class FakeTime:
    """A clock the acquisition reads and sleeps on: each read costs 2 µs; after ``hold_at`` the
    sleeps also wait 1 ms of real time so that the test can stop the thread."""

    def __init__(self, hold_at: float = 0.5) -> None:
        self.now = 100.0
        self.hold_at = 100.0 + hold_at

    def clock(self) -> float:
        self.now += 2e-6
        return self.now

    def sleep(self, s: float) -> None:
        self.now += s
        if self.now > self.hold_at:
            time.sleep(0.001)


class CountingPlate(ForcePlate):
    """Scan k reads (k, 2k, -k); ``fail_at`` raises on that scan; ``stall_at`` makes that scan
    take 10 ms of the fake clock (a late scan)."""

    n_channels = 3

    def __init__(self, fake: FakeTime, fail_at: int | None = None,
                 stall_at: int | None = None, saturate_at: int | None = None) -> None:
        self.fake = fake
        self.k = 0
        self.fail_at, self.stall_at, self.saturate_at = fail_at, stall_at, saturate_at
        self.saturated = False

    def read_channels(self, out: np.ndarray) -> np.ndarray:
        self.k += 1
        if self.k == self.fail_at:
            raise HardwareError("/dev/comedi1: AI channel 2: read failed: fake error 5")
        if self.k == self.stall_at:
            self.fake.now += 0.010
        self.saturated = self.k == self.saturate_at
        out[:] = (self.k, 2 * self.k, -self.k)
        return out

    def _close(self) -> None:
        pass


def _acquire(device: CountingPlate, fake: FakeTime) -> PlateAcquisition:
    acq = PlateAcquisition(device, 3, 1000.0, fake.clock, fake.sleep)
    acq.start(5.0)
    deadline = time.monotonic() + 10.0
    while fake.now < fake.hold_at and time.monotonic() < deadline:
        time.sleep(0.01)
    return acq


def test_scans_are_stamped_on_the_plate_clock_and_a_late_one_rephases() -> None:
    fake = FakeTime()
    device = CountingPlate(fake, stall_at=200)
    acq = _acquire(device, fake)
    t, v = acq.stop()
    assert not acq.running
    n = len(t)
    assert n >= 450
    # Every scan kept, in order, with its own values; stamps strictly increasing.
    assert np.array_equal(v[:, 0], np.arange(1, n + 1))
    assert np.array_equal(v[:, 1], 2 * v[:, 0]) and np.array_equal(v[:, 2], -v[:, 0])
    dt = np.diff(t)
    assert np.all(dt > 0)
    assert np.median(dt) == pytest.approx(1e-3, abs=1e-5)
    # The stalled scan (10 ms, stamped mid-scan): the gaps around it add up to 11 ms, the
    # next one is counted late, and no burst of catch-up scans follows (the schedule
    # re-phases: the next gaps are one period again).
    k = int(np.argmax(dt))
    assert dt[k] + dt[k + 1] == pytest.approx(0.011, abs=2e-4) and acq.late_scans == 1
    assert np.all(np.abs(dt[k + 2:k + 20] - 1e-3) < 1e-4)


def test_a_failed_read_a_clipping_amplifier_and_a_full_buffer_are_refused() -> None:
    fake = FakeTime()
    acq = _acquire(CountingPlate(fake, fail_at=7), fake)
    with pytest.raises(HardwareError, match="plate DAQ: .*AI channel 2: read failed"):
        acq.stop()
    fake = FakeTime()
    acq = _acquire(CountingPlate(fake, saturate_at=30), fake)
    with pytest.raises(HardwareError, match="1 scans at the end of the input range"):
        acq.stop()
    fake = FakeTime(hold_at=5.0)
    acq = PlateAcquisition(CountingPlate(fake), 3, 1000.0, fake.clock, fake.sleep)
    acq.start(0.1)
    time.sleep(0.2)
    with pytest.raises(HardwareError, match="filled its 116 scans"):
        acq.stop()
    with pytest.raises(InputError, match="not running"):
        acq.stop()
    with pytest.raises(InputError, match="duration"):
        acq.start(float("nan"))


def test_daq_file_is_validated_and_wiring_must_match_the_plate(tmp_path: Path) -> None:
    path = tmp_path / "daq.yaml"
    path.write_text("schema_version: 1\nbackend: comedi\nchannels: [0, 1, 2]\naref: diff\n")
    with pytest.raises(ConfigurationError, match="aref"):
        load_daq_config(path)
    cfg = DaqConfig(schema_version=1, backend="comedi", channels=[0, 1, 2])
    with pytest.raises(ConfigurationError, match="3 AI channels wired for a plate of 6"):
        open_plate_device(cfg, 6)


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


def test_twin_plate_read_through_the_comedi_driver(model: RobotModel) -> None:
    """A contact published on the wire (as the RT process's program does) is read by the real
    ComediForcePlate driver as the twin plate's channels of that load, to the 16-bit code."""
    plate = load_plate(TWIN_PLATE_FILE)
    settings = TruthSettings(noise_v=0.0, drift_v_per_s=0.0, hysteresis=0.0)
    truth = draw_truth(plate, settings, seed=3)
    daq = TwinPlateDaq(plate, TwinPlate(plate, truth, seed=4), model, TOOL_LENGTH_M)
    pub = WirePublisher(daq.wire_name)
    try:
        q = np.array(model.kin.ik(0.63, 0.0, 0.0).q)
        cfg = model.kin.fk(q, check=False)
        R = np.array(cfg.rotation).reshape(3, 3)
        tip_B = (np.array([cfg.x, cfg.y, cfg.z]) + R @ np.array(model.description.sensor.offset_m)
                 + TOOL_LENGTH_M * R[:, 2])
        site = (0.12, -0.08)
        T_BF = reg.nominal_T_BF(tip_B, site) @ reg.transform(reg.rot_z(0.004),
                                                             np.array([0.002, -0.001, 0.0]))
        daq.place(T_BF)
        v = np.zeros(plate.n_channels)
        # Nothing published yet: no load, the channels are the plate's zero offsets.
        daq.device.read_channels(v)
        lsb = 20.0 / 65535
        assert np.allclose(v, truth.zero_offset_v, atol=lsb)
        # 900 N pressing the plate, a little shear: the environment's wrench on the platform.
        load_B = np.array([25.0, -40.0, 900.0])
        wrench_s = np.r_[-(R.T @ load_B), 0.0, 0.0, 0.0]
        pub.publish(12.5, wrench_s, q)
        daq.device.read_channels(v)
        R_FB = T_BF[:3, :3].T
        point_F = R_FB @ (tip_B - T_BF[:3, 3])
        assert point_F[:2] == pytest.approx(site, abs=3e-3)
        point_F[2] = 0.0
        expected = TwinPlate(plate, truth).channels((R_FB @ load_B)[None], point_F[None],
                                                    np.zeros(1))[0]
        assert np.allclose(v, expected, atol=1.01 * lsb)
        # Through the nominal matrix: ≈ the load (the twin plate's errors are a few %).
        w = plate.nominal_C() @ (v - truth.zero_offset_v)
        assert w[2] == pytest.approx(900.0, rel=0.06)
    finally:
        pub.close()
        daq.close()
        daq.close()                          # closing twice is safe
    assert not Path(f"/dev/shm/{daq.wire_name}").exists()


def test_the_rt_side_refuses_a_wire_that_does_not_exist() -> None:
    with pytest.raises(InputError, match="no such shared memory"):
        WirePublisher("talus-plate-none-00000000")
    with pytest.raises(InputError, match="malformed"):
        WirePublisher("../etc/passwd")


def test_blocks_across_a_gap_in_the_plate_scans_are_not_fitted(monkeypatch) -> None:
    """A software-timed DAQ on a loaded host leaves gaps (127 ms measured); interpolated across
    a ramp they are tens of N off, so their blocks are dropped (dataset.MAX_PLATE_GAP_S)."""
    import dataclasses

    from calibration import dataset
    from calibration.plan import ProfileKind, default_plan, expand, force_profile
    from calibration.twin_runner import DirectTrialRunner

    plate = load_plate(TWIN_PLATE_FILE)
    truth = draw_truth(plate, TruthSettings.ideal(), seed=2)
    runner = DirectTrialRunner(plate, TwinPlate(plate, truth, seed=1), ati_noise=(0.0,) * 6)
    plan = default_plan()
    trial = next(t for t in expand(plan, plate.size_m) if t.profile == ProfileKind.STEPS)
    d = runner.run(trial.id, trial.site_xy_m, (0.63, 0.0, 0.0), force_profile(plan, trial, 1e-3),
                   1e-3)
    clock = dataset.align_clocks(plate, [d])
    # A 120 ms hole in the plate's scans where the ramp from 1000 to 1500 N bends away from
    # the hold (ideal plate: its clock is the robot's).
    t_mid = plan.baseline_s + 3 * (plan.steps.ramp_s + plan.steps.hold_s) + 0.03
    keep = np.abs(d.t_plate - t_mid) > 0.06
    gappy = dataclasses.replace(d, t_plate=d.t_plate[keep], channels=d.channels[keep])

    def worst_fz_error(data) -> tuple[int, float]:
        s = dataset.build_samples(plate, [data], [trial.site], clock)
        fz = s.v @ truth.C_true[2]
        return len(s), float(np.max(np.abs(fz - s.w_ref[:, 2])))

    n_full, err_full = worst_fz_error(d)
    n_gap, err_gap = worst_fz_error(gappy)
    assert err_full < 1.0 and err_gap < 1.0
    assert 5 <= n_full - n_gap <= 8                  # 120 ms of 20 ms blocks, and the edges
    monkeypatch.setattr(dataset, "MAX_PLATE_GAP_S", 1.0)
    n_all, err_all = worst_fz_error(gappy)
    assert n_all == n_full and err_all > 10.0        # what the interpolated blocks would cost


def test_blocks_across_a_stall_of_the_rt_loop_are_not_fitted() -> None:
    """A late RT loop skips cycles (92 ms seen at a load of 14): blocks spanning the hole in the
    robot's rows are dropped (dataset.MAX_ROBOT_GAP_S), the others kept as they were."""
    import dataclasses

    from calibration import dataset
    from calibration.plan import ProfileKind, default_plan, expand, force_profile
    from calibration.twin_runner import DirectTrialRunner

    plate = load_plate(TWIN_PLATE_FILE)
    truth = draw_truth(plate, TruthSettings.ideal(), seed=2)
    runner = DirectTrialRunner(plate, TwinPlate(plate, truth, seed=1), ati_noise=(0.0,) * 6)
    plan = default_plan()
    trial = next(t for t in expand(plan, plate.size_m) if t.profile == ProfileKind.STEPS)
    d = runner.run(trial.id, trial.site_xy_m, (0.63, 0.0, 0.0), force_profile(plan, trial, 1e-3),
                   1e-3)
    clock = dataset.align_clocks(plate, [d])
    keep = np.abs(d.t_robot - (plan.baseline_s + 2.0)) > 0.046          # a 92 ms stall
    stalled = dataclasses.replace(d, t_robot=d.t_robot[keep], ati=d.ati[keep],
                                  p_BS=d.p_BS[keep], R_BS=d.R_BS[keep],
                                  force_ref=d.force_ref[keep])
    full = dataset.build_samples(plate, [d], [trial.site], clock)
    cut = dataset.build_samples(plate, [stalled], [trial.site], clock)
    assert 4 <= len(full) - len(cut) <= 7
    assert np.max(np.abs(cut.v @ truth.C_true[2] - cut.w_ref[:, 2])) < 1.0
