"""The twin's ATI sensor model: noise, bias, drift, overload, faults, reproducibility."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.ati.rdt import (
    STATUS_ANY_ERROR,
    STATUS_FT_OUT_OF_RANGE,
    STATUS_GAGE_OUT_OF_RANGE,
    is_saturated,
)
from rt.ati.twin_sensor import (
    DELTA_SI_660_60_RANGES,
    AtiSample,
    AtiSensorParams,
    SourceReader,
    TwinAtiSensorModel,
)
from rt.errors import InputError

ZERO6 = (0.0,) * 6
LOAD = (10.0, -20.0, -50.0, 1.0, -2.0, 3.0)


def quiet_params(**overrides) -> AtiSensorParams:
    """No noise, no drift, no bias unless overridden: outputs are exactly predictable."""
    base = {"noise_sigma": ZERO6, "bias": ZERO6, "drift_rate": ZERO6, "drift_limit": ZERO6}
    base.update(overrides)
    return AtiSensorParams(**base)


def run(model: TwinAtiSensorModel, n: int, dt: float = 1e-3, wrench=LOAD) -> np.ndarray:
    return np.array([model.measure(wrench, i * dt).wrench for i in range(n)])


def test_same_seed_same_samples_different_seed_different():
    a, b, c = (TwinAtiSensorModel(seed=s) for s in (7, 7, 8))
    ra, rb, rc = run(a, 200), run(b, 200), run(c, 200)
    assert np.array_equal(ra, rb)  # bit-for-bit: one seeded Generator drives everything
    assert not np.array_equal(ra, rc)


def test_reset_replays_the_run():
    m = TwinAtiSensorModel(seed=3)
    first = run(m, 50)
    m.reset()
    assert np.array_equal(run(m, 50), first)


def test_quiet_model_reports_the_true_wrench_exactly():
    m = TwinAtiSensorModel(quiet_params())
    s = m.measure(LOAD, 0.0)
    assert s.wrench == LOAD and s.status == 0 and s.ft_sequence == 1


def test_noise_statistics_match_sigma_and_bias():
    sigma = (0.5, 0.5, 1.0, 0.01, 0.02, 0.03)
    bias = (1.0, -2.0, 3.0, 0.1, -0.2, 0.3)
    m = TwinAtiSensorModel(quiet_params(noise_sigma=sigma, bias=bias), seed=11)
    n = 20_000
    x = run(m, n) - np.array(LOAD)
    # Mean: standard error sigma/sqrt(n) = 0.7 % of sigma; 5 standard errors cannot fail by chance.
    assert np.all(np.abs(x.mean(axis=0) - bias) < 5 * np.array(sigma) / math.sqrt(n))
    # Std: relative standard error 1/sqrt(2n) = 0.5 %; 5 % is 10 standard errors.
    assert np.allclose(x.std(axis=0), sigma, rtol=0.05)


def test_drift_is_a_bounded_random_walk_with_the_documented_intensity():
    rate = (0.5, 0.5, 0.5, 0.05, 0.05, 0.05)
    m = TwinAtiSensorModel(quiet_params(drift_rate=rate, drift_limit=(1e9,) * 6), seed=5)
    dt, n = 0.01, 4000
    drift = []
    for i in range(n):
        m.measure(ZERO6, i * dt)
        drift.append(m.drift)
    increments = np.diff(np.array(drift), axis=0)
    # Increment variance = rate^2 dt; with 4000 increments the relative standard error of the
    # variance is sqrt(2/4000) = 2.2 %, so 15 % is ~7 standard errors.
    assert np.allclose(increments.var(axis=0), np.square(rate) * dt, rtol=0.15)

    limit = (0.3, 0.3, 0.3, 0.01, 0.01, 0.01)
    bounded = TwinAtiSensorModel(quiet_params(drift_rate=rate, drift_limit=limit), seed=5)
    seen = []
    for i in range(n):
        s = bounded.measure(ZERO6, i * dt)
        assert np.all(np.abs(s.wrench) <= np.array(limit) + 1e-12)
        seen.append(s.wrench)
    # Over 40 s the walk (sigma 0.5*sqrt(40) = 3 N) reaches its 0.3 N bound: it is clipped.
    assert np.isclose(np.max(np.abs(np.array(seen)[:, 0])), 0.3)


def test_drift_does_not_advance_without_time():
    m = TwinAtiSensorModel(quiet_params(drift_rate=(1.0,) * 6, drift_limit=(10.0,) * 6))
    m.measure(ZERO6, 1.0)
    d = m.drift
    m.measure(ZERO6, 1.0)
    assert m.drift == d


@pytest.mark.parametrize("axis", range(6))
def test_overload_clips_each_axis_and_sets_status(axis):
    m = TwinAtiSensorModel(quiet_params())
    ranges = DELTA_SI_660_60_RANGES
    w = [0.0] * 6
    w[axis] = -1.5 * ranges[axis]
    s = m.measure(w, 0.0)
    assert s.wrench[axis] == -ranges[axis]
    assert s.status == STATUS_ANY_ERROR | STATUS_FT_OUT_OF_RANGE and is_saturated(s.status)
    w[axis] = 0.99 * ranges[axis]
    s = m.measure(w, 0.001)
    assert s.wrench[axis] == pytest.approx(0.99 * ranges[axis]) and s.status == 0


def test_dropout_stale_saturate_switches():
    m = TwinAtiSensorModel(seed=1)
    first = m.measure(LOAD, 0.0)
    m.set_fault("dropout")
    assert m.measure(LOAD, 0.001) is None
    m.set_fault("dropout", False)
    m.set_fault("stale")
    repeated = m.measure((0.0,) * 6, 0.002)
    assert repeated == first  # same values, same status, same ft_sequence
    m.set_fault("stale", False)
    fresh = m.measure(LOAD, 0.003)
    assert fresh.ft_sequence == first.ft_sequence + 1
    m.set_fault("saturate")
    sat = m.measure(LOAD, 0.004)
    assert sat.status == STATUS_ANY_ERROR | STATUS_GAGE_OUT_OF_RANGE
    assert sat.wrench[2] == pytest.approx(-50.0, abs=2.0)  # values pass through (noise only)


def test_schedule_fault_windows_are_half_open():
    m = TwinAtiSensorModel(quiet_params())
    m.schedule_fault("dropout", 1.0, 2.0)
    m.schedule_fault("saturate", 3.0)
    assert m.measure(LOAD, 0.999) is not None
    assert m.measure(LOAD, 1.0) is None
    assert m.measure(LOAD, 1.999) is None
    assert m.measure(LOAD, 2.0) is not None
    assert m.measure(LOAD, 2.5).status == 0
    assert m.measure(LOAD, 1e6).status & STATUS_GAGE_OUT_OF_RANGE
    m.clear_faults()
    assert m.measure(LOAD, 1e6 + 1).status == 0


def test_bad_fault_and_param_requests_are_refused():
    m = TwinAtiSensorModel()
    with pytest.raises(InputError, match="unknown ATI sensor fault 'freeze'"):
        m.set_fault("freeze")
    with pytest.raises(InputError, match="t_end"):
        m.schedule_fault("stale", 2.0, 1.0)
    with pytest.raises(InputError, match="noise_sigma needs 6 values"):
        AtiSensorParams(noise_sigma=(1.0, 2.0))
    with pytest.raises(InputError, match="ranges must be > 0"):
        AtiSensorParams(ranges=(1.0, 1.0, 1.0, 1.0, 1.0, 0.0))
    with pytest.raises(InputError, match="drift_rate must be >= 0"):
        AtiSensorParams(drift_rate=(-1.0, 0, 0, 0, 0, 0))


def test_make_source_uses_the_clock_relative_to_the_first_call():
    now = [100.0]
    m = TwinAtiSensorModel(quiet_params())
    m.schedule_fault("dropout", 0.5)
    src = m.make_source(LOAD, clock=lambda: now[0])
    assert src() == AtiSample(LOAD, 0, 1)
    now[0] = 100.4
    assert src() is not None
    now[0] = 100.5
    assert src() is None


def test_source_reader_numbers_biases_and_passes_sequences_through():
    values = iter([((1.0, 2, 3, 4, 5, 6), 0), None, ((2.0, 2, 3, 4, 5, 6), 9),
                   ((3.0, 0, 0, 0, 0, 0), 0, 77)])
    r = SourceReader(lambda: next(values))
    assert r.poll() and r.ft_sequence == 1 and r.value == [1.0, 2, 3, 4, 5, 6]
    assert not r.poll() and r.ft_sequence == 1  # dropout: nothing changes
    assert r.set_bias(samples=1)  # pulls a fresh sample, then zeroes at it
    assert r.value == [0.0] * 6 and r.bias == [2.0, 2, 3, 4, 5, 6] and r.status == 9
    assert r.poll() and r.ft_sequence == 77 and r.value == [1.0, -2, -3, -4, -5, -6]
    with pytest.raises(InputError, match="3 wrench values"):
        SourceReader(lambda: ((1.0, 2.0, 3.0), 0)).poll()
