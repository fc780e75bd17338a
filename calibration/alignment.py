"""Putting the plate's samples on the robot's clock.

The plate's DAQ and the robot have separate clocks: ``t_plate = offset + (1 + drift) t_robot``.
Per trial, the lag between the reference vertical force (robot clock) and the plate's
vertical force through its nominal matrix (plate clock) is the peak of their cross-correlation
(FFT, refined by a parabola through the peak), searched within ``max_offset_s`` of the
recordings' starts. Over the campaign a straight line through the trials' lags gives offset and
drift. Refused, with the reason: a trial whose correlation peak is below ``min_correlation``
(the plate recorded something else, or nothing), and per-trial lags that scatter around the line
by more than ``max_scatter_s`` (a clock that jumped, or a trial mixed up).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from rt.errors import InputError

MIN_CORRELATION = 0.95
MAX_SCATTER_S = 2.0e-3


class ClockAlignmentError(InputError):
    """The two recordings could not be put on one clock; nothing was fitted."""


@dataclass(frozen=True)
class TrialLag:
    trial_id: str
    t_robot_mid_s: float
    lag_s: float            # t_plate - t_robot for this trial
    correlation: float


@dataclass(frozen=True)
class ClockModel:
    """``t_plate = offset_s + (1 + drift) t_robot``, from the per-trial lags."""

    offset_s: float
    drift: float
    scatter_s: float
    lags: tuple[TrialLag, ...]

    def to_robot(self, t_plate: np.ndarray) -> np.ndarray:
        return (np.asarray(t_plate) - self.offset_s) / (1.0 + self.drift)

    def record_entry(self) -> dict:
        return {"offset_s": self.offset_s, "drift_ppm": self.drift * 1e6,
                "scatter_ms": self.scatter_s * 1e3,
                "min_correlation": min((lag.correlation for lag in self.lags), default=None)}


def trial_lag(trial_id: str, t_robot: np.ndarray, a: np.ndarray, t_plate: np.ndarray,
              b: np.ndarray, max_offset_s: float = 2.0,
              min_correlation: float = MIN_CORRELATION) -> TrialLag:
    """Lag t_plate - t_robot that best overlays b (plate clock) on a (robot clock)."""
    fs = 1.0 / float(np.median(np.diff(t_plate)))
    ta = np.arange(t_robot[0], t_robot[-1], 1.0 / fs)
    a_u = np.interp(ta, t_robot, a)
    b_u = np.interp(np.arange(t_plate[0], t_plate[-1], 1.0 / fs), t_plate, b)
    a0, b0 = a_u - a_u.mean(), b_u - b_u.mean()
    if np.std(a0) < 1e-9 or np.std(b0) < 1e-9:
        raise ClockAlignmentError(f"trial {trial_id}: the {'plate' if np.std(b0) < 1e-9 else 'reference'} "
                                  "force does not vary: nothing to align the clocks on")
    corr = signal.correlate(b0, a0, mode="full", method="fft")
    lags = signal.correlation_lags(len(b0), len(a0), mode="full")
    # lag L: b[k + L] ~ a[k]  =>  t_plate = t_plate[0] + (k + L)/fs for t_robot[0] + k/fs
    base = t_plate[0] - t_robot[0]
    window = np.abs(lags / fs) <= max_offset_s
    k = int(np.argmax(np.where(window, corr, -np.inf)))
    frac = 0.0
    if 0 < k < len(corr) - 1:
        y0, y1, y2 = corr[k - 1], corr[k], corr[k + 1]
        den = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / den if den != 0 else 0.0
    L = int(lags[k])
    # Pearson correlation at the integer lag, on the overlap.
    if L >= 0:
        n = min(len(a0), len(b0) - L)
        x, y = a0[:n], b0[L:L + n]
    else:
        n = min(len(a0) + L, len(b0))
        x, y = a0[-L:-L + n], b0[:n]
    r = float(np.corrcoef(x, y)[0, 1]) if n > 10 else 0.0
    if not r >= min_correlation:
        raise ClockAlignmentError(
            f"trial {trial_id}: the plate's and the reference's forces do not line up (best "
            f"correlation {r:.3f} < {min_correlation}); check that the plate recorded this "
            "trial and that its channels are wired as its description says")
    return TrialLag(trial_id, float(np.mean(t_robot)), base + (L + frac) / fs, r)


def clock_model(lags: list[TrialLag], max_scatter_s: float = MAX_SCATTER_S) -> ClockModel:
    """Offset and drift through the trials' lags (one trial: offset only)."""
    if not lags:
        raise ClockAlignmentError("no trial to align the clocks on")
    t = np.array([lag.t_robot_mid_s for lag in lags])
    y = np.array([lag.lag_s for lag in lags])
    if len(lags) >= 3 and np.ptp(t) > 0:
        slope, intercept = np.polyfit(t, y, 1)
    else:
        slope, intercept = 0.0, float(np.mean(y))
    resid = y - (intercept + slope * t)
    scatter = float(np.max(np.abs(resid)))
    if scatter > max_scatter_s:
        worst = lags[int(np.argmax(np.abs(resid)))]
        raise ClockAlignmentError(
            f"the clocks do not align: trial {worst.trial_id}'s lag is "
            f"{resid[int(np.argmax(np.abs(resid)))] * 1e3:+.1f} ms off the line through the "
            f"others (tolerance {max_scatter_s * 1e3:.1f} ms): a clock jumped or trials are "
            "mixed up")
    # lag = offset + drift t  with lag = t_plate - t_robot
    return ClockModel(float(intercept), float(slope), scatter, tuple(lags))
