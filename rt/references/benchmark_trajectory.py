"""The fixed benchmark trajectory (the issue's tracking benchmark), as a per-cycle source.

Each slider i follows, about a mid-stroke position q0 (default 0.20 m),

    q_i(t) = q0 + 0.030 sin(2π 0.25 t + φ_i) + 0.015 sin(2π 0.6 t + ψ_i)   (m),
    φ_i = ψ_i = 0, 2π/3, 4π/3,

for 26 s, with analytic velocity and acceleration. Peaks (slider 0 at t = 0 has both cosines at
1): |q̇| ≤ 0.030·2π·0.25 + 0.015·2π·0.6 = 0.104 m/s, |q̈| ≤ 0.287 m/s², |q⃛| ≤ 0.92 m/s³; the
position stays within q0 ± 0.045 m.

Same API as :class:`rt.references.playback.TrajectoryPlayback` (a ``CycleSource``): samples at
k·dt, k = 0 … n_samples - 1, the last one at t = duration. ``update`` evaluates the sines on plain
floats (≈ 2-3 µs); nothing is precomputed.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from rt.errors import ConfigurationError, ProtocolValidationError
from rt.references.approach import (
    DEFAULT_MAX_ACCELERATION_M_S2,
    DEFAULT_MAX_VELOCITY_M_S,
    N_AXES,
    STROKE_M,
)
from rt.references.playback import LIMIT_SLACK, ReferenceStatus

PHASES_RAD = (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)


class BenchmarkTrajectory:
    """Sum of two sinusoids per slider, with analytic derivatives (a ``CycleSource``).

    Ports (per cycle): ``update(out_pos, out_vel, out_acc)`` writes position (m), velocity (m/s),
    acceleration (m/s²) into the caller's (3,) arrays.

    Args:
        dt: loop period (s).
        q0: centre position (m).
        duration: length (s); must be a whole number of periods dt.
        amplitudes: (A1, A2) (m). frequencies: (f1, f2) (Hz).
        phases1, phases2: φ_i and ψ_i (rad) per slider.
        stroke, max_velocity, max_acceleration: what ``validate`` checks the peaks against.
    """

    def __init__(self, dt: float = 1.0e-3, q0: float = 0.20, duration: float = 26.0,
                 amplitudes: tuple[float, float] = (0.030, 0.015),
                 frequencies: tuple[float, float] = (0.25, 0.6),
                 phases1: Sequence[float] = PHASES_RAD, phases2: Sequence[float] = PHASES_RAD,
                 stroke: tuple[float, float] = STROKE_M,
                 max_velocity: float = DEFAULT_MAX_VELOCITY_M_S,
                 max_acceleration: float = DEFAULT_MAX_ACCELERATION_M_S2) -> None:
        if not (math.isfinite(dt) and dt > 0.0):
            raise ConfigurationError(f"dt must be > 0 s (got {dt!r})")
        steps = duration / dt
        if not (math.isfinite(steps) and steps >= 1.0 and abs(steps - round(steps)) < 1e-6):
            raise ConfigurationError(f"duration {duration!r} s must be a positive multiple of "
                                     f"dt {dt!r} s")
        if len(phases1) != N_AXES or len(phases2) != N_AXES:
            raise ConfigurationError(f"phases1 and phases2 need {N_AXES} values each")
        self.dt = dt
        self.q0 = float(q0)
        self.duration = float(duration)
        self.amplitudes = (float(amplitudes[0]), float(amplitudes[1]))
        self.frequencies = (float(frequencies[0]), float(frequencies[1]))
        self.phases1 = tuple(float(p) for p in phases1)
        self.phases2 = tuple(float(p) for p in phases2)
        self.stroke = (float(stroke[0]), float(stroke[1]))
        self.max_velocity = float(max_velocity)
        self.max_acceleration = float(max_acceleration)
        self.n_samples = round(steps) + 1
        self.index = 0
        self._validated = False
        self._w = (2.0 * math.pi * self.frequencies[0], 2.0 * math.pi * self.frequencies[1])

    def validate(self) -> None:
        """Check peaks against the stroke and limits; raises ProtocolValidationError."""
        self._validated = False
        a1, a2 = abs(self.amplitudes[0]), abs(self.amplitudes[1])
        w1, w2 = self._w
        lo, hi = self.stroke
        # Upper bounds of |q - q0|, |q̇|, |q̈| (reached or nearly reached over 26 s).
        if self.q0 - a1 - a2 < lo or self.q0 + a1 + a2 > hi:
            raise ProtocolValidationError(
                f"benchmark trajectory: q0 {self.q0} m ± {a1 + a2} m leaves the stroke "
                f"[{lo}, {hi}] m")
        v_peak, a_peak = a1 * w1 + a2 * w2, a1 * w1 ** 2 + a2 * w2 ** 2
        if v_peak > self.max_velocity * (1.0 + LIMIT_SLACK):
            raise ProtocolValidationError(f"benchmark trajectory: peak velocity {v_peak:.4g} m/s "
                                          f"exceeds the limit {self.max_velocity} m/s")
        if a_peak > self.max_acceleration * (1.0 + LIMIT_SLACK):
            raise ProtocolValidationError(f"benchmark trajectory: peak acceleration "
                                          f"{a_peak:.4g} m/s² exceeds the limit "
                                          f"{self.max_acceleration} m/s²")
        self._validated = True
        self.index = 0

    def evaluate(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vectorised q, q̇, q̈ (m, m/s, m/s²) at times t (s); shape t.shape + (3,)."""
        tt = np.asarray(t, dtype=float)[..., None]
        (a1, a2), (w1, w2) = self.amplitudes, self._w
        s1 = w1 * tt + np.asarray(self.phases1)
        s2 = w2 * tt + np.asarray(self.phases2)
        q = self.q0 + a1 * np.sin(s1) + a2 * np.sin(s2)
        v = a1 * w1 * np.cos(s1) + a2 * w2 * np.cos(s2)
        a = -a1 * w1 * w1 * np.sin(s1) - a2 * w2 * w2 * np.sin(s2)
        return q, v, a

    def reset(self, start_index: int = 0) -> None:
        """Make ``start_index`` the next sample emitted."""
        self.index = min(max(int(start_index), 0), self.n_samples - 1)

    def state_at(self, index: int, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> None:
        """Write sample ``index``'s state (m, m/s, m/s²) into the arrays (-1 = the last)."""
        if index < 0:
            index += self.n_samples
        self._write(index * self.dt, pos, vel, acc)

    def update(self, out_pos: np.ndarray, out_vel: np.ndarray,
               out_acc: np.ndarray) -> ReferenceStatus:
        """Emit the next sample; ``FINISHED`` on the last one (held afterwards)."""
        if not self._validated:
            return ReferenceStatus.ERROR_NOT_VALIDATED
        k = self.index
        self._write(k * self.dt, out_pos, out_vel, out_acc)
        if k >= self.n_samples - 1:
            return ReferenceStatus.FINISHED
        self.index = k + 1
        return ReferenceStatus.PLAYING

    def _write(self, t: float, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> None:
        (a1, a2), (w1, w2) = self.amplitudes, self._w
        q0, p1, p2 = self.q0, self.phases1, self.phases2
        sin, cos = math.sin, math.cos
        for i in range(N_AXES):
            x1 = w1 * t + p1[i]
            x2 = w2 * t + p2[i]
            s1, c1, s2, c2 = sin(x1), cos(x1), sin(x2), cos(x2)
            pos[i] = q0 + a1 * s1 + a2 * s2
            vel[i] = a1 * w1 * c1 + a2 * w2 * c2
            acc[i] = -(a1 * w1 * w1 * s1 + a2 * w2 * w2 * s2)
