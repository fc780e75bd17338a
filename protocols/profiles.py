"""Smooth time laws sampled at the loop rate, and the sampled angular path of the exercises.

* :func:`rest_to_rest` — a move of a path coordinate s from 0 to L starting and ending at rest:
  ``"jerk_limited"`` (ruckig, time-optimal under speed/acceleration/jerk limits: velocity and
  acceleration continuous) or ``"cosine"`` (raised cosine s = L (1 - cos(π t/T))/2: velocity
  continuous, acceleration jumps to ±π² L/(2T²) at the ends; T long enough for both the speed
  and the acceleration limit). Durations are whole numbers of periods so every move starts and
  ends on a sample.
* :func:`cosine_ramp` — the raised-cosine envelope 0 → 1 of force ramps (zero slope at both
  ends, so a ramped force has a continuous derivative).
* :class:`AnglePath` — (roll, pitch) samples with their first two derivatives, built from holds,
  straight moves and elliptical circuits; plus an optional force-target column.
"""
from __future__ import annotations

import math

import numpy as np
from ruckig import DurationDiscretization, InputParameter, Result, Ruckig, Trajectory

from rt.errors import ProtocolValidationError

# Columns of an AnglePath chunk.
ROLL, PITCH, ROLL_D, PITCH_D, ROLL_DD, PITCH_DD, TARGET = range(7)
N_COLS = 7


def _periods(duration: float, dt: float) -> int:
    """Whole periods covering ``duration`` (s); 1e-9 relative slack absorbs round-off."""
    return max(1, math.ceil(duration / dt * (1.0 - 1e-12) - 1e-9))


def rest_to_rest(distance: float, v_max: float, a_max: float, j_max: float, profile: str,
                 dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample a rest-to-rest move of length ``distance`` ≥ 0 (any unit u: rad, m).

    Args:
        v_max, a_max, j_max: limits (u/s, u/s², u/s³); ``j_max`` is unused by ``"cosine"``.
        profile: ``"jerk_limited"`` or ``"cosine"``.
        dt: sample period (s).

    Returns:
        (s, ṡ, s̈) at t = k dt, k = 0 … n, both ends included (s[0] = 0, s[n] = distance).
    """
    if distance <= 0.0:
        z = np.zeros(1)
        return z, z.copy(), z.copy()
    if profile == "cosine":
        t_min = max(math.pi * distance / (2.0 * v_max),
                    math.pi * math.sqrt(distance / (2.0 * a_max)))
        n = _periods(t_min, dt)
        T = n * dt
        w = math.pi / T
        t = np.arange(n + 1) * dt
        s = 0.5 * distance * (1.0 - np.cos(w * t))
        sd = 0.5 * distance * w * np.sin(w * t)
        sdd = 0.5 * distance * w * w * np.cos(w * t)
        s[-1], sd[-1] = distance, 0.0
        return s, sd, sdd
    if profile != "jerk_limited":
        raise ValueError(f"unknown profile {profile!r}")
    otg = Ruckig(1, dt)
    inp = InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [0.0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [distance], [0.0], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v_max], [a_max], [j_max]
    # Discrete: the duration is a whole number of periods, so the move ends on a sample.
    inp.duration_discretization = DurationDiscretization.Discrete
    traj = Trajectory(1)
    result = otg.calculate(inp, traj)
    if result not in (Result.Working, Result.Finished):
        raise ProtocolValidationError(f"ruckig could not plan a {distance:g} move "
                                      f"(v {v_max:g}, a {a_max:g}, j {j_max:g}): {result}")
    n = round(traj.duration / dt)
    s, sd, sdd = np.empty(n + 1), np.empty(n + 1), np.empty(n + 1)
    for k in range(n + 1):
        p, v, a = traj.at_time(min(k * dt, traj.duration))
        s[k], sd[k], sdd[k] = p[0], v[0], a[0]
    s[-1], sd[-1], sdd[-1] = distance, 0.0, 0.0
    return s, sd, sdd


def cosine_ramp(t: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """Raised-cosine envelope w(t) = (1 - cos(π t/T))/2 on [0, T], clamped outside; and w'."""
    x = np.clip(t / duration, 0.0, 1.0)
    w = 0.5 * (1.0 - np.cos(math.pi * x))
    wd = np.where((t > 0.0) & (t < duration),
                  0.5 * math.pi / duration * np.sin(math.pi * x), 0.0)
    return w, wd


class AnglePath:
    """A sampled (roll, pitch) path (rad) built piece by piece; starts with one sample at rest.

    Chunks are (n, 7) arrays: roll, pitch, their rates (rad/s), accelerations (rad/s²), and a
    force-target column (N, NaN = none). Each piece appends samples k = 1 … n of its move (its
    sample 0 is the previous piece's last sample).
    """

    def __init__(self, dt: float, roll: float, pitch: float) -> None:
        self.dt = dt
        first = np.zeros((1, N_COLS))
        first[0, ROLL], first[0, PITCH], first[0, TARGET] = roll, pitch, math.nan
        self._chunks = [first]
        self.roll, self.pitch = roll, pitch

    def hold(self, duration: float, target_n: float = math.nan) -> None:
        """Stay still ``duration`` s (rounded to whole periods); ``target_n`` shown meanwhile."""
        n = round(duration / self.dt)
        if n <= 0:
            return
        chunk = np.zeros((n, N_COLS))
        chunk[:, ROLL], chunk[:, PITCH], chunk[:, TARGET] = self.roll, self.pitch, target_n
        self._chunks.append(chunk)

    def move_to(self, roll: float, pitch: float, speed: float, accel: float, jerk: float,
                profile: str) -> None:
        """Straight move at rest at both ends; limits apply along the path (rad/s, rad/s², …)."""
        dr, dp = roll - self.roll, pitch - self.pitch
        length = math.hypot(dr, dp)
        if length < 1e-12:
            return
        s, sd, sdd = rest_to_rest(length, speed, accel, jerk, profile, self.dt)
        ur, up = dr / length, dp / length
        chunk = np.empty((s.size - 1, N_COLS))
        chunk[:, ROLL] = self.roll + ur * s[1:]
        chunk[:, PITCH] = self.pitch + up * s[1:]
        chunk[:, ROLL_D], chunk[:, PITCH_D] = ur * sd[1:], up * sd[1:]
        chunk[:, ROLL_DD], chunk[:, PITCH_DD] = ur * sdd[1:], up * sdd[1:]
        chunk[:, TARGET] = math.nan
        chunk[-1, ROLL], chunk[-1, PITCH] = roll, pitch  # land exactly
        self._chunks.append(chunk)
        self.roll, self.pitch = roll, pitch

    def ellipse(self, roll_c: float, pitch_c: float, roll_r: float, pitch_r: float, turns: int,
                speed: float, accel: float, jerk: float, profile: str) -> None:
        """``turns`` laps of roll = c_r + r_r sin θ, pitch = c_p + r_p cos θ, θ: 0 → 2π·turns.

        Starts and ends at rest at θ = 0 (the path must be there). θ follows a rest-to-rest
        law whose limits are the path limits divided by the largest radius, so the speed along
        the path never exceeds ``speed`` (the centripetal acceleration r θ̇² adds to ``accel``).
        A negative radius mirrors that axis (a left foot's circuit).
        """
        r_max = max(abs(roll_r), abs(pitch_r))
        s, sd, sdd = rest_to_rest(2.0 * math.pi * turns, speed / r_max, accel / r_max,
                                  jerk / r_max, profile, self.dt)
        th, thd, thdd = s[1:], sd[1:], sdd[1:]
        sin, cos = np.sin(th), np.cos(th)
        chunk = np.empty((th.size, N_COLS))
        chunk[:, ROLL] = roll_c + roll_r * sin
        chunk[:, PITCH] = pitch_c + pitch_r * cos
        chunk[:, ROLL_D] = roll_r * cos * thd
        chunk[:, PITCH_D] = -pitch_r * sin * thd
        chunk[:, ROLL_DD] = roll_r * (cos * thdd - sin * thd * thd)
        chunk[:, PITCH_DD] = -pitch_r * (sin * thdd + cos * thd * thd)
        chunk[:, TARGET] = math.nan
        chunk[-1, ROLL], chunk[-1, PITCH] = roll_c, pitch_c + pitch_r
        self._chunks.append(chunk)
        self.roll, self.pitch = roll_c, pitch_c + pitch_r

    def samples(self) -> np.ndarray:
        """All samples, shape (n, 7)."""
        return np.concatenate(self._chunks, axis=0)

    @property
    def n_samples(self) -> int:
        return sum(c.shape[0] for c in self._chunks)
