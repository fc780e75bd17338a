"""Slider velocity and acceleration from quantized encoder positions (DESIGN.md §5).

The encoders count 2e-5 m (20 µm). At 1 kHz one count per sample is already 0.02 m/s, so a first
difference ``(q_k - q_{k-1}) / dt`` jumps between multiples of 0.02 m/s: at 0.05 m/s it reads
0.04 or 0.06 m/s, and a slider at rest that toggles between two counts reads ±0.02 m/s. A
controller's derivative term (PD+G, Paden-Panja, computed torque) amplifies exactly that noise.

Default estimator: :class:`KalmanVelocityEstimator`, a Kalman filter per axis on a
*white-jerk* (constant-acceleration) model

    x = [q, q̇, q̈],  x_{k+1} = F(dt) x_k + w_k,  z_k = q_k + v_k,

with ``F = [[1, dt, dt²/2], [0, 1, dt], [0, 0, 1]]``, the exactly discretised process noise of a
continuous white jerk of spectral density ``S_j`` (m²/s⁵)

    Q = S_j [[dt⁵/20, dt⁴/8, dt³/6], [dt⁴/8, dt³/3, dt²/2], [dt³/6, dt²/2, dt]],

and the measurement noise of a uniform quantizer, ``R = Δ²/12`` (Δ = 2e-5 m → R = 3.3e-11 m²).

Why a constant-acceleration model: it tracks position ramps *and* parabolas without bias, so the
only velocity lag left comes from the (small) change of acceleration within the filter's memory;
a constant-velocity (α-β) model lags by a full time constant whenever the slider accelerates.

Tuning of ``S_j`` (numbers from ``python -m rt.estimation.characterize``, 1 kHz): ``S_j`` sets
the only trade-off, noise against transient tracking. The filter's characteristic frequency is
``ω_b ≈ (S_j / (R dt))^(1/6)``; the default ``S_j = 2 m²/s⁵`` gives ``ω_b ≈ 200 rad/s ≈ 30 Hz``
(steady gain K ≈ [0.33, 64 1/s, 6.4e3 1/s²]; the velocity estimate is within 3 dB of the true
velocity up to ≈ 14 Hz and peaks at 1.6× near 30 Hz):

* far above the motions it must follow — sinusoids up to ~1 Hz / 0.1 m/s (jerk ≈ 4 m/s³) and the
  benchmark trajectory (0.25 Hz + 0.6 Hz, jerk ≤ 0.9 m/s³): velocity lag 0.004 ms on the
  benchmark and 0.013 ms at 1 Hz, against 0.5 ms (dt/2) for first difference;
* fast enough for payload steps: after a 1 m/s² acceleration step the velocity error peaks at
  4.2 mm/s (first difference: 16 mm/s of quantization noise); a 4× smaller ``S_j`` gives 5.5 mm/s,
  a 5× larger one only 4.0 mm/s but 50 % more noise;
* slow enough to average ~10-20 counts: velocity RMS error 1.0 mm/s at rest with two-count
  dither, 0.19 mm/s at 0.05 m/s, 0.6 mm/s on the benchmark, against 14, 10 and 8 mm/s for first
  difference (a 12-50× reduction).

Raising ``S_j`` tenfold raises ``ω_b`` by only 10^(1/6) ≈ 1.5, so the tuning is forgiving.

Known limit: at speeds whose count pattern beats slowly (e.g. 1.95 counts per sample, a pattern
repeating every ~20 ms) the quantization error is a 15-40 Hz sawtooth inside the passband, which
no causal filter can tell from real motion; the worst case over 0-0.15 m/s is 1.45 mm/s RMS,
3.1 mm/s peak (first difference: 8-10 mm/s RMS).

Because the covariance recursion runs on-line (it is shared by the three axes, so it costs one
axis worth of plain-float arithmetic), a change of ``dt`` at run time is handled exactly: F and Q
are re-discretised with the new period and the gain follows. Once the gain has converged and the
period is unchanged the recursion is skipped (steady-state Kalman filter).

Statuses (:class:`EstimatorStatus`; non-negative = measurement used):

* ``OK`` — measurement fused.
* ``INITIALISED`` — first valid sample (or first after ``reset()``): q = measurement, q̇ = q̈ = 0.
* ``ERROR_NAN`` — a non-finite measurement; nothing fused, outputs keep the last estimate, and the
  elapsed time is carried to the next valid sample.
* ``ERROR_DT`` — dt not finite or outside (0, dt_max]; nothing changed.
* ``JUMP`` — an implausible jump: |innovation| above the gate (see :class:`KalmanConfig`). The
  sample is not fused (the filter coasts on its prediction; the outputs keep the last estimate).
  A single glitch passes (the next good sample is fused again); a real jump keeps being flagged
  until ``reset()``, because the gate stops widening with the coasting time once a jump has been
  flagged. The safety supervisor reacts to it (encoder-jump plausibility check, DESIGN.md §6).

Per-cycle cost (plain floats, the PLATFORM.md VM): ≈ 3 µs median with the steady gain, ≈ 4 µs
when the period changes every cycle (``tests/test_estimation.py`` checks < 15 µs).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from rt.errors import ConfigurationError

ENCODER_RESOLUTION_M = 2.0e-5
N_AXES = 3


class EstimatorStatus(IntEnum):
    """Result of one ``update``; negative values mean the measurement was not fused."""

    OK = 0
    INITIALISED = 1
    ERROR_NAN = -1
    ERROR_DT = -2
    JUMP = -3


@dataclass(frozen=True, slots=True)
class KalmanConfig:
    """Parameters of :class:`KalmanVelocityEstimator` (SI units).

    Attributes:
        dt_s: nominal sample period (s), used for the initial gain.
        resolution_m: encoder count size Δ (m); measurement variance Δ²/12.
        jerk_psd: spectral density S_j of the white jerk (m²/s⁵); see the module docstring.
        initial_velocity_std_m_s: prior std of q̇ at the first sample (m/s). 0.2 m/s covers any
            speed the sliders reach, so a start while moving converges in a few samples.
        initial_acceleration_std_m_s2: prior std of q̈ at the first sample (m/s²).
        jump_floor_m: fixed part of the jump gate (m). 0.2 mm = 10 counts.
        jump_velocity_m_s: the gate grows by this speed × dt (m/s). 0.5 m/s is several times the
            sliders' top speed: a prediction wrong by that much means the sensor, not the robot.
        jump_sigma: and by this many innovation standard deviations √S (widens while coasting or
            right after initialisation, when the filter's own prediction is uncertain).
        dt_max_s: largest accepted dt (s); beyond it the model's prediction is meaningless.
        steady_gain_tol: relative gain change under which the recursion is considered converged.
    """

    dt_s: float = 1.0e-3
    resolution_m: float = ENCODER_RESOLUTION_M
    jerk_psd: float = 2.0
    initial_velocity_std_m_s: float = 0.2
    initial_acceleration_std_m_s2: float = 2.0
    jump_floor_m: float = 2.0e-4
    jump_velocity_m_s: float = 0.5
    jump_sigma: float = 6.0
    dt_max_s: float = 0.1
    steady_gain_tol: float = 1.0e-9

    def check(self) -> None:
        """Raise ConfigurationError naming the first bad field."""
        for name in ("dt_s", "resolution_m", "jerk_psd", "initial_velocity_std_m_s",
                     "initial_acceleration_std_m_s2", "jump_floor_m", "jump_velocity_m_s",
                     "jump_sigma", "dt_max_s", "steady_gain_tol"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ConfigurationError(f"KalmanConfig.{name} must be a finite number > 0 "
                                         f"(got {value!r})")
        if self.dt_s > self.dt_max_s:
            raise ConfigurationError(f"KalmanConfig.dt_s {self.dt_s} s exceeds dt_max_s "
                                     f"{self.dt_max_s} s")


class KalmanVelocityEstimator:
    """Three-axis Kalman estimator of slider position, velocity and acceleration.

    Ports (preallocated, shape (3,), float64; read them after ``update``):
        q (m), qd (m/s), qdd (m/s²): the estimate.
        innovation (m): measurement minus prediction of the last processed sample.

    Allocate-once: ``update`` writes into these arrays in place and returns a status; it never
    raises on bad input (see the module docstring for the statuses).
    """

    def __init__(self, config: KalmanConfig | None = None) -> None:
        self.config = config if config is not None else KalmanConfig()
        self.config.check()
        self._r = self.config.resolution_m ** 2 / 12.0
        self.q = np.zeros(N_AXES)
        self.qd = np.zeros(N_AXES)
        self.qdd = np.zeros(N_AXES)
        self.innovation = np.zeros(N_AXES)
        self.reset()

    # -- lifecycle -----------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the state; the next valid sample re-initialises the filter."""
        self._initialised = False
        self._x = [[0.0, 0.0, 0.0] for _ in range(N_AXES)]  # per axis [q, qd, qdd]
        self._pending_dt = 0.0  # time elapsed since the last fused sample beyond the current dt
        self._dt_gain = -1.0  # dt of the current gain; -1 forces a recursion step
        self._steady = False
        self._k = (0.0, 0.0, 0.0)
        self._s = 0.0  # innovation variance of the current gain (m²)
        self._p = (0.0,) * 6
        self._jump_latched = False
        self._latched_gate = 0.0
        self.q[:] = 0.0
        self.qd[:] = 0.0
        self.qdd[:] = 0.0
        self.innovation[:] = 0.0

    def _init_covariance(self) -> None:
        c = self.config
        self._p = (self._r, 0.0, 0.0, c.initial_velocity_std_m_s ** 2, 0.0,
                   c.initial_acceleration_std_m_s2 ** 2)
        self._steady = False

    @property
    def gain(self) -> tuple[float, float, float]:
        """Current Kalman gain (position 1, velocity 1/s, acceleration 1/s²)."""
        return self._k

    @property
    def jump_latched(self) -> bool:
        """True from a ``JUMP`` until a sample is fused again (or ``reset()``)."""
        return self._jump_latched

    @property
    def converged(self) -> bool:
        """True once the gain is the steady-state gain for the current dt."""
        return self._steady

    # -- the per-cycle call --------------------------------------------------------------------
    def update(self, q_measured: np.ndarray, dt: float) -> EstimatorStatus:
        """Fuse one encoder sample.

        Args:
            q_measured: slider positions (m), shape (3,).
            dt: time since the previous call (s), the measured period.

        Returns:
            An :class:`EstimatorStatus`; ``q``, ``qd``, ``qdd`` hold the estimate.
        """
        if not (0.0 < dt <= self.config.dt_max_s):  # also rejects NaN
            return EstimatorStatus.ERROR_DT
        z0, z1, z2 = q_measured.tolist()
        if not (math.isfinite(z0) and math.isfinite(z1) and math.isfinite(z2)):
            self._pending_dt += dt
            return EstimatorStatus.ERROR_NAN
        if not self._initialised:
            self._x = [[z0, 0.0, 0.0], [z1, 0.0, 0.0], [z2, 0.0, 0.0]]
            self._init_covariance()
            self._initialised = True
            self._pending_dt = 0.0
            self._publish()
            self.innovation[:] = 0.0
            return EstimatorStatus.INITIALISED

        t = dt + self._pending_dt
        h = 0.5 * t * t
        # Covariance prediction P⁻ = F P Fᵀ + Q, symmetric, shared by the three axes. Skipped when
        # the gain has converged for this period (steady-state Kalman filter).
        if self._steady and t == self._dt_gain:
            k0, k1, k2 = self._k
            s = self._s
        else:
            p00, p01, p02, p11, p12, p22 = self._p
            a0 = p00 + t * p01 + h * p02
            a1 = p01 + t * p11 + h * p12
            a2 = p02 + t * p12 + h * p22
            b1 = p11 + t * p12
            b2 = p12 + t * p22
            sj = self.config.jerk_psd
            t2 = t * t
            t3 = t2 * t
            m00 = a0 + t * a1 + h * a2 + sj * t3 * t2 / 20.0
            m01 = a1 + t * a2 + sj * t2 * t2 / 8.0
            m02 = a2 + sj * t3 / 6.0
            m11 = b1 + t * b2 + sj * t3 / 3.0
            m12 = b2 + sj * h
            m22 = p22 + sj * t
            s = m00 + self._r
            k0, k1, k2 = m00 / s, m01 / s, m02 / s
            self._prior = (m00, m01, m02, m11, m12, m22)
            self._s = s
            # steady when the gain stopped moving and the period is the one it was computed for
            ok0, ok1, ok2 = self._k
            tol = self.config.steady_gain_tol
            self._steady = (t == self._dt_gain and abs(k0 - ok0) <= tol * abs(k0)
                            and abs(k1 - ok1) <= tol * abs(k1) and abs(k2 - ok2) <= tol * abs(k2))
            self._k = (k0, k1, k2)
            self._dt_gain = t

        # Innovation gate: fixed floor + implausible speed × dt + n σ of the innovation.
        c = self.config
        gate = c.jump_floor_m + c.jump_velocity_m_s * t + c.jump_sigma * math.sqrt(s)
        if self._jump_latched and gate > self._latched_gate:
            # While rejecting, the gate does not widen with the coasting time: a real jump stays
            # flagged until reset() instead of being swallowed after a few cycles.
            gate = self._latched_gate
        x0, x1, x2 = self._x
        r0 = z0 - (x0[0] + t * x0[1] + h * x0[2])
        r1 = z1 - (x1[0] + t * x1[1] + h * x1[2])
        r2 = z2 - (x2[0] + t * x2[1] + h * x2[2])
        if abs(r0) > gate or abs(r1) > gate or abs(r2) > gate:
            # Not fused: coast. Keep the outputs (the supervisor decides), carry the elapsed time.
            self._pending_dt = t
            self._steady = False
            self._dt_gain = -1.0
            if not self._jump_latched:
                self._jump_latched = True
                self._latched_gate = gate
            inn = self.innovation
            inn[0] = r0
            inn[1] = r1
            inn[2] = r2
            return EstimatorStatus.JUMP

        for x, r in ((x0, r0), (x1, r1), (x2, r2)):
            v = x[1] + t * x[2]
            x[0] = x[0] + t * x[1] + h * x[2] + k0 * r
            x[1] = v + k1 * r
            x[2] = x[2] + k2 * r
        if not self._steady:
            m00, m01, m02, m11, m12, m22 = self._prior
            # Joseph form is unnecessary here: P = P⁻ - K S Kᵀ stays symmetric by construction
            # and the scalar measurement keeps it well conditioned.
            self._p = (m00 - k0 * m00, m01 - k0 * m01, m02 - k0 * m02,
                       m11 - k1 * m01, m12 - k1 * m02, m22 - k2 * m02)
        self._pending_dt = 0.0
        self._jump_latched = False
        inn = self.innovation
        inn[0] = r0
        inn[1] = r1
        inn[2] = r2
        self._publish()
        return EstimatorStatus.OK

    def _publish(self) -> None:
        x0, x1, x2 = self._x
        q, qd, qdd = self.q, self.qd, self.qdd
        q[0] = x0[0]
        q[1] = x1[0]
        q[2] = x2[0]
        qd[0] = x0[1]
        qd[1] = x1[1]
        qd[2] = x2[1]
        qdd[0] = x0[2]
        qdd[1] = x1[2]
        qdd[2] = x2[2]


class FirstDifferenceEstimator:
    """Baseline: q̇ = (q_k - q_{k-1}) / dt, optionally through a first-order low-pass.

    Same ports and statuses as :class:`KalmanVelocityEstimator` (no jump gate: it never returns
    ``JUMP``). ``cutoff_hz=None`` is the raw first difference (lag dt/2); a cutoff f_c adds the
    low-pass's lag ≈ 1/(2π f_c). ``qdd`` is the first difference of the (filtered) velocity.
    """

    def __init__(self, cutoff_hz: float | None = None, dt_max_s: float = 0.1) -> None:
        if cutoff_hz is not None and not (math.isfinite(cutoff_hz) and cutoff_hz > 0.0):
            raise ConfigurationError(f"cutoff_hz must be > 0 or None (got {cutoff_hz!r})")
        self.cutoff_hz = cutoff_hz
        self.dt_max_s = dt_max_s
        self.q = np.zeros(N_AXES)
        self.qd = np.zeros(N_AXES)
        self.qdd = np.zeros(N_AXES)
        self.innovation = np.zeros(N_AXES)
        self.reset()

    def reset(self) -> None:
        """Forget the state; the next valid sample re-initialises."""
        self._initialised = False
        self._prev = [0.0, 0.0, 0.0]
        self._v = [0.0, 0.0, 0.0]
        self._pending_dt = 0.0
        self.q[:] = 0.0
        self.qd[:] = 0.0
        self.qdd[:] = 0.0

    def update(self, q_measured: np.ndarray, dt: float) -> EstimatorStatus:
        """Same contract as :meth:`KalmanVelocityEstimator.update`."""
        if not (0.0 < dt <= self.dt_max_s):
            return EstimatorStatus.ERROR_DT
        z = q_measured.tolist()
        if not (math.isfinite(z[0]) and math.isfinite(z[1]) and math.isfinite(z[2])):
            self._pending_dt += dt
            return EstimatorStatus.ERROR_NAN
        if not self._initialised:
            self._prev = z
            self._initialised = True
            self._pending_dt = 0.0
            self.q[:] = z
            self.qd[:] = 0.0
            self.qdd[:] = 0.0
            return EstimatorStatus.INITIALISED
        t = dt + self._pending_dt
        alpha = (1.0 if self.cutoff_hz is None
                 else 1.0 - math.exp(-2.0 * math.pi * self.cutoff_hz * t))
        for i in range(N_AXES):
            raw = (z[i] - self._prev[i]) / t
            v = self._v[i] + alpha * (raw - self._v[i])
            self.qdd[i] = (v - self._v[i]) / t
            self._v[i] = v
            self.qd[i] = v
            self.q[i] = z[i]
        self._prev = z
        self._pending_dt = 0.0
        return EstimatorStatus.OK
