"""Noise and lag of a velocity estimator on synthetic quantized encoder signals (DESIGN.md §5).

Signals (three axes, sampled every ``dt``, quantized to the nearest 2e-5 m count — a mid-tread
quantizer, so the position error is zero-mean and only the velocity error is compared):

* ``rest``: a slider held exactly at a count boundary with 2 µm RMS white vibration, so the reading
  toggles between two counts — the worst case at rest. The true velocity is taken as 0.
* ``constant_velocity``: ramps at 0.05 m/s (2.5 counts per ms: first difference reads 0.04 or
  0.06 m/s).
* ``benchmark``: the benchmark trajectory, q_i = q0 + 0.030 sin(2π 0.25 t + φ_i)
  + 0.015 sin(2π 0.6 t + φ_i), φ_i = 0, 2π/3, 4π/3.
* ``sine_1hz``: 1 Hz sinusoid of 0.1 m/s peak speed, the fastest therapy motion expected.
* ``acceleration_step``: rest, then a 1 m/s² acceleration step for 0.1 s (a payload step or a
  push), then constant speed: the estimator's transient.

Metrics, all SI, computed after a settling time (so the first-sample initialisation is excluded):
RMS and peak velocity error (m/s), RMS acceleration error (m/s²), the lag (s) that maximises the
cross-correlation between estimated and true velocity (sub-sample by parabolic interpolation of
the peak), and the phase lag (s) of the 0.6 Hz component of the benchmark velocity (least-squares
fit at that frequency).

``python -m rt.estimation.characterize`` prints the table for the default estimator and first
difference.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np

from rt.estimation.velocity import (
    ENCODER_RESOLUTION_M,
    EstimatorStatus,
    FirstDifferenceEstimator,
    KalmanVelocityEstimator,
)

BENCHMARK_PHASES_RAD = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)
# Lag windows (s): whole periods of the periodic signals (0.25 Hz and 0.6 Hz repeat every 20 s).
_PERIOD_S = {"benchmark": 20.0, "sine_1hz": 3.0}


class Estimator(Protocol):
    """What characterize needs: the estimator ports and update contract of ``velocity.py``."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    def update(self, q_measured: np.ndarray, dt: float) -> EstimatorStatus: ...

    def reset(self) -> None: ...


def quantize(q_m: np.ndarray, resolution_m: float = ENCODER_RESOLUTION_M) -> np.ndarray:
    """Round positions (m) to the nearest encoder count (m)."""
    return np.round(q_m / resolution_m) * resolution_m


def _benchmark(t: np.ndarray, q0: float = 0.20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w1, w2 = 2.0 * math.pi * 0.25, 2.0 * math.pi * 0.6
    ph = np.asarray(BENCHMARK_PHASES_RAD)[None, :]
    tt = t[:, None]
    q = q0 + 0.030 * np.sin(w1 * tt + ph) + 0.015 * np.sin(w2 * tt + ph)
    v = 0.030 * w1 * np.cos(w1 * tt + ph) + 0.015 * w2 * np.cos(w2 * tt + ph)
    a = -0.030 * w1 ** 2 * np.sin(w1 * tt + ph) - 0.015 * w2 ** 2 * np.sin(w2 * tt + ph)
    return q, v, a


def _signals(dt: float, seed: int) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray,
                                                     np.ndarray, float]]:
    """name -> (t, q_true, v_true, a_true, settle_s); arrays (n, 3)."""
    rng = np.random.default_rng(seed)
    out = {}
    # rest: at a count boundary (round-half point), 2 µm RMS vibration -> two-count toggling
    t = np.arange(round(2.0 / dt)) * dt
    q = 0.2 + 0.5 * ENCODER_RESOLUTION_M + rng.normal(0.0, 2.0e-6, (t.size, 3))
    out["rest"] = (t, q, np.zeros_like(q), np.zeros_like(q), 0.5)
    # constant velocity, random sub-count offsets per axis
    t = np.arange(round(2.0 / dt)) * dt
    off = rng.uniform(0.0, ENCODER_RESOLUTION_M, 3)[None, :]
    v = np.full((t.size, 3), 0.05)
    out["constant_velocity"] = (t, 0.1 + off + 0.05 * t[:, None], v, np.zeros_like(v), 0.5)
    # benchmark trajectory
    t = np.arange(round(26.0 / dt)) * dt
    q, v, a = _benchmark(t)
    out["benchmark"] = (t, q, v, a, 1.0)
    # 1 Hz, 0.1 m/s peak
    t = np.arange(round(5.0 / dt)) * dt
    w = 2.0 * math.pi
    ph = np.asarray(BENCHMARK_PHASES_RAD)[None, :]
    amp = 0.1 / w
    q = 0.2 + amp * np.sin(w * t[:, None] + ph)
    out["sine_1hz"] = (t, q, amp * w * np.cos(w * t[:, None] + ph),
                       -amp * w * w * np.sin(w * t[:, None] + ph), 1.0)
    # acceleration step: rest 0.2 s, 1 m/s² for 0.1 s, then 0.1 m/s
    t = np.arange(round(0.6 / dt)) * dt
    t1, t2, acc = 0.2, 0.3, 1.0
    tau = np.clip(t - t1, 0.0, t2 - t1)
    v1 = acc * tau
    q1 = 0.5 * acc * tau ** 2 + acc * (t2 - t1) * np.clip(t - t2, 0.0, None)
    a1 = np.where((t >= t1) & (t < t2), acc, 0.0)
    rep = lambda x: np.repeat(x[:, None], 3, axis=1)
    out["acceleration_step"] = (t, 0.2 + rep(q1), rep(v1), rep(a1), 0.1)
    return out


def _run(est: Estimator, t: np.ndarray, q_meas: np.ndarray, dt: float
         ) -> tuple[np.ndarray, np.ndarray]:
    est.reset()
    vel = np.empty_like(q_meas)
    acc = np.empty_like(q_meas)
    for k in range(t.size):
        est.update(q_meas[k], dt)
        vel[k] = est.qd
        acc[k] = est.qdd
    return vel, acc


def _xcorr_lag(est: np.ndarray, true: np.ndarray, lo: int, hi: int, dt: float,
               max_shift: int = 50) -> float:
    """Delay (s) of ``est`` behind ``true`` maximising their cross-correlation, over all axes.

    ``est[lo:hi]`` is correlated with ``true[lo - s:hi - s]`` for every shift s, so each shift
    sums the same number of terms, and ``hi - lo`` must span whole periods of the signal:
    otherwise the window edges add a term linear in the shift that, on slow sinusoids, moves the
    peak by milliseconds (more than the lags being measured).
    """
    if lo < max_shift or hi + max_shift > est.shape[0]:
        raise ValueError("window too close to the ends of the record for the shift range")
    window = est[lo:hi]
    shifts = np.arange(-max_shift, max_shift + 1)
    corr = np.empty(shifts.size)
    for j, s in enumerate(shifts):
        corr[j] = np.sum(window * true[lo - s:hi - s])
    j = int(np.argmax(corr))
    frac = 0.0
    if 0 < j < shifts.size - 1:  # parabolic interpolation of the peak
        c0, c1, c2 = corr[j - 1], corr[j], corr[j + 1]
        den = c0 - 2.0 * c1 + c2
        frac = 0.5 * (c0 - c2) / den if den != 0.0 else 0.0
    return float((shifts[j] + frac) * dt)


def _phase_lag(est: np.ndarray, true: np.ndarray, t: np.ndarray, freq_hz: float) -> float:
    """Time lag (s) of ``est`` behind ``true`` at ``freq_hz`` (mean over axes)."""
    w = 2.0 * math.pi * freq_hz
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    lags = []
    for i in range(est.shape[1]):
        ce = np.linalg.lstsq(basis, est[:, i], rcond=None)[0]
        ct = np.linalg.lstsq(basis, true[:, i], rcond=None)[0]
        dphi = math.atan2(ct[1], ct[0]) - math.atan2(ce[1], ce[0])
        dphi = (dphi + math.pi) % (2.0 * math.pi) - math.pi
        lags.append(dphi / w)
    return float(np.mean(lags))


def characterize(estimators: Mapping[str, Callable[[], Estimator]] | None = None,
                 dt: float = 1.0e-3, seed: int = 0) -> dict[str, Any]:
    """Quantify noise and lag of velocity estimators on synthetic quantized signals.

    Args:
        estimators: name -> factory of a fresh estimator. Default: ``"kalman"`` (the default
            :class:`KalmanVelocityEstimator`) and ``"first_difference"``.
        dt: sample period (s).
        seed: seed of the vibration noise and offsets (the run is deterministic).

    Returns:
        ``{name: {signal: {metric: value}}, "settings": {...}}`` with metrics
        ``v_rms_m_s``, ``v_peak_m_s``, ``a_rms_m_s2``, ``lag_xcorr_s`` (not for ``rest``), and
        ``lag_phase_0p6hz_s`` for ``benchmark``. SI units throughout.
    """
    if estimators is None:
        estimators = {
            "kalman": lambda: KalmanVelocityEstimator(),
            "first_difference": lambda: FirstDifferenceEstimator(),
        }
    signals = _signals(dt, seed)
    result: dict[str, Any] = {"settings": {"dt_s": dt, "resolution_m": ENCODER_RESOLUTION_M,
                                           "seed": seed}}
    for name, factory in estimators.items():
        est = factory()
        per_signal: dict[str, dict[str, float]] = {}
        for sig, (t, q, v, a, settle) in signals.items():
            vel, acc = _run(est, t, quantize(q), dt)
            m = t >= settle
            ev = vel[m] - v[m]
            metrics = {
                "v_rms_m_s": float(np.sqrt(np.mean(ev ** 2))),
                "v_peak_m_s": float(np.max(np.abs(ev))),
                "a_rms_m_s2": float(np.sqrt(np.mean((acc[m] - a[m]) ** 2))),
            }
            if sig in _PERIOD_S:  # lag over a whole number of periods after settling
                lo = round(settle / dt)
                hi = lo + round(_PERIOD_S[sig] / dt)
                metrics["lag_xcorr_s"] = _xcorr_lag(vel, v, lo, hi, dt)
            if sig == "benchmark":
                metrics["lag_phase_0p6hz_s"] = _phase_lag(vel[m], v[m], t[m], 0.6)
            per_signal[sig] = metrics
        result[name] = per_signal
    return result


def format_table(result: Mapping[str, Any]) -> str:
    """The ``characterize`` result as a plain-text table (one row per estimator and signal)."""
    lines = [(f"{'estimator':<18}{'signal':<20}{'v_rms m/s':>12}{'v_peak m/s':>12}"
             f"{'a_rms m/s2':>12}{'lag ms':>9}")]
    for name, per_signal in result.items():
        if name == "settings":
            continue
        for sig, m in per_signal.items():
            lag = m.get("lag_xcorr_s")
            lag_s = f"{lag * 1e3:9.3f}" if lag is not None else f"{'-':>9}"
            lines.append(f"{name:<18}{sig:<20}{m['v_rms_m_s']:12.2e}{m['v_peak_m_s']:12.2e}"
                         f"{m['a_rms_m_s2']:12.2e}{lag_s}")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover - manual tool
    print(format_table(characterize()))
