"""Excitation trajectories for identification: a finite Fourier series per slider (Swevers et
al. 1997), periodic so the data can be averaged and filtered without edge effects, with its
coefficients chosen to minimise the condition number of the stacked base regressor while
staying inside the robot's position, velocity and acceleration limits.

The condition number of the column-scaled regressor says how well the parameters are
*separated*, not how large their signal is: it barely changes when the same path is played
faster, so optimising it alone (with the limits only as penalties) settled on a 10 s period
with 47 mm/s and 0.08 m/s² at most. On such a path the rotor inertias' force (205 kg ×
0.08 m/s² ≈ 16 N) is below the friction ripple and the Coulomb level, the viscous term spans
only 20-47 mm/s above the Stribeck cut-off, and the realistic twin's unmodelled forces (a few
newtons: friction ripple with position, thermal drift) bent the estimates: fv −3…−20 %, the
rotor inertias ±30 % (issue 15). The path is therefore played as fast as the limits allow
(:func:`to_limits`: the same positions in less time, speed ∝ s, acceleration ∝ s²), and the
optimiser scores each candidate *as played*: time-scaled to the limits, and over the equations
the estimator keeps (axes sliding faster than ``estimate.MIN_SPEED_M_S``).

    q_i(t) = q0 + Σ_k a_ik/(k ω) sin(k ω t) − b_ik/(k ω) cos(k ω t)   (m)

A ``FourierExcitation`` is a reference ``f(t, out)`` like ``benchmark_reference``: the RT
process can register it as a program; here it runs through the position loop on the twin.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from rt.control.base import Reference
from rt.errors import ConfigurationError, KinematicsError
from rt.model import RobotModel
from rt.model.regressor import Regressor

N_HARMONICS = 4
BASE_FREQUENCY_HZ = 0.1
Q0_M = 0.20
#: Excursion, speed and acceleration the excitation may use (m, m/s, m/s²): inside the stroke
#: and the robot limits (0.2 m/s, 5 m/s²) with margin, and inside the platform's tilt limits
#: (opposite excursions of ±0.035 m tilt the platform ≈ 15°, inside the default ROM of 20°).
MAX_EXCURSION_M = 0.035
MAX_SPEED_M_S = 0.15
MAX_ACCEL_M_S2 = 1.5
#: Share of the speed and acceleration limits :func:`to_limits` plays the path at: the
#: position loop's tracking error adds a few per cent of speed on top of the reference.
LIMIT_SHARE = 0.95
#: The platform's tilt range and angular speed the excitation may use (rad, rad/s): the
#: default patient limits (``rt.safety.limits.PatientLimits``: ±20°, 60°/s).
MAX_TILT_RAD = math.radians(20.0)
MAX_ANGULAR_SPEED_RAD_S = math.radians(60.0)
#: The supervisor's soft stop (``rt.safety.supervisor.Supervisor`` defaults: 0.5 m/s², jerk
#: 5 m/s³, lever 1.5 × platform radius, one cycle of reaction, 25 % margin): it stops the
#: platform once its tilt plus the angle it still turns while braking from the current angular
#: rate would pass the ROM end. A path played fast must leave that cushion — the first path
#: scaled to the speed limit tilted 15° at 0.5 rad/s, i.e. 15° + 6.7° of cushion, and was
#: stopped at once ("roll reaching the patient's ROM end").
SOFT_STOP_ACCEL_M_S2 = 0.5
SOFT_STOP_JERK_M_S3 = 5.0
REACTION_S = 1.0e-3
BRAKING_MARGIN = 1.25
#: Tilt samples per period for the ROM cushion (the path's highest harmonic: 4 per period).
TILT_SAMPLES = 200


@dataclass(frozen=True)
class FourierExcitation:
    """Coefficients a, b (3 × N_HARMONICS, m/s) of the series above; period 1/f0 s."""

    a: np.ndarray
    b: np.ndarray
    q0: float = Q0_M
    f0_hz: float = BASE_FREQUENCY_HZ

    @property
    def period_s(self) -> float:
        return 1.0 / self.f0_hz

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, q̇, q̈ at times t (s), each (len(t), 3)."""
        w = 2.0 * math.pi * self.f0_hz
        k = np.arange(1, self.a.shape[1] + 1)
        ph = np.outer(np.asarray(t, float), k * w)          # (n, K)
        s, c = np.sin(ph), np.cos(ph)
        q = self.q0 + (s @ (self.a / (k * w)).T) - (c @ (self.b / (k * w)).T)
        qd = c @ self.a.T + s @ self.b.T
        qdd = -(s @ (self.a * k * w).T) + c @ (self.b * k * w).T
        return q, qd, qdd

    def __call__(self, t: float, out: Reference) -> None:
        q, qd, qdd = self.evaluate(np.array([t]))
        out.q[:] = q[0]
        out.qd[:] = qd[0]
        out.qdd[:] = qdd[0]

    def peaks(self) -> tuple[float, float, float]:
        """Largest |q − q0|, |q̇|, |q̈| over one period (m, m/s, m/s²)."""
        q, qd, qdd = self.evaluate(np.linspace(0.0, self.period_s, 2001))
        return (float(np.abs(q - self.q0).max()), float(np.abs(qd).max()),
                float(np.abs(qdd).max()))

    def within_limits(self) -> bool:
        e, v, a = self.peaks()
        return e <= MAX_EXCURSION_M and v <= MAX_SPEED_M_S and a <= MAX_ACCEL_M_S2


def stacked_regressor(reg: Regressor, q: np.ndarray, qd: np.ndarray,
                      qdd: np.ndarray) -> np.ndarray:
    """Base regressor rows stacked over samples: (3n × n_base)."""
    st = None
    rows = np.empty((3 * len(q), len(reg.base.base_index)))
    for j in range(len(q)):
        st = reg.dyn.state(q[j], qd[j], out=st)
        rows[3 * j:3 * j + 3] = reg(st, qdd[j])
    return rows


def braking_angle_rad(rate_rad_s: np.ndarray | float, lever_m_per_rad: float) -> np.ndarray:
    """The supervisor's soft-stop cushion (``Supervisor.braking_angle``): the angle (rad) the
    platform still turns from ``rate_rad_s`` before it is at rest."""
    w = np.abs(np.asarray(rate_rad_s, float))
    alpha = SOFT_STOP_ACCEL_M_S2 / lever_m_per_rad
    jerk_time = SOFT_STOP_ACCEL_M_S2 / SOFT_STOP_JERK_M_S3
    return BRAKING_MARGIN * (w * (REACTION_S + 0.5 * jerk_time) + w * w / (2.0 * alpha))


def tilt_path(exc: FourierExcitation, model: RobotModel,
              samples: int = TILT_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch (rad, (samples, 2)) over one period and their rates (rad/s), by forward
    kinematics (KinematicsError outside the assembly range)."""
    t = np.linspace(0.0, exc.period_s, samples + 1)
    q, _qd, _qdd = exc.evaluate(t)
    ang = np.empty((len(t), 2))
    for j in range(len(t)):
        cfg = model.kin.fk(q[j], check=False)
        ang[j] = (cfg.roll, cfg.pitch)
    rate = np.asarray(np.gradient(ang, t, axis=0))
    return ang[:-1], rate[:-1]


def to_limits(exc: FourierExcitation, model: RobotModel | None = None,
              share: float = LIMIT_SHARE) -> FourierExcitation:
    """The same positions played with the time scaled by s, as fast as the limits allow:
    q(t) → q(s t), i.e. ω → s ω and the velocity coefficients a, b → s a, s b (speed and
    angular rate ∝ s, acceleration ∝ s²). s is the largest that keeps the peak slider speed
    and acceleration within ``share`` of theirs, the platform's angular speed within ``share``
    of ``MAX_ANGULAR_SPEED_RAD_S``, and at every sample the tilt plus the supervisor's braking
    cushion at the played rate within ``share`` of ``MAX_TILT_RAD``."""
    model = model or RobotModel.load()
    _e, v, a = exc.peaks()
    if not (v > 0.0 and a > 0.0):
        raise ConfigurationError("the excitation does not move: nothing to scale")
    s = min(share * MAX_SPEED_M_S / v, math.sqrt(share * MAX_ACCEL_M_S2 / a))
    ang, rate = tilt_path(exc, model)
    w_peak = float(np.abs(rate).max())
    if w_peak > 0.0:
        s = min(s, share * MAX_ANGULAR_SPEED_RAD_S / w_peak)
        # Largest w with |angle| + cushion(w) ≤ share × MAX_TILT per sample: the cushion is
        # c1 w + c2 w², so w is the positive root of c2 w² + c1 w − room = 0.
        from rt.safety.supervisor import LEVER_PER_PLATFORM_RADIUS

        lever = LEVER_PER_PLATFORM_RADIUS * model.description.geometry.platform_radius_m
        c1 = BRAKING_MARGIN * (REACTION_S + 0.5 * SOFT_STOP_ACCEL_M_S2 / SOFT_STOP_JERK_M_S3)
        c2 = BRAKING_MARGIN * lever / (2.0 * SOFT_STOP_ACCEL_M_S2)
        room = share * MAX_TILT_RAD - np.abs(ang)
        if np.any(room <= 0.0):
            raise ConfigurationError(f"the excitation tilts the platform "
                                     f"{math.degrees(float(np.abs(ang).max())):.1f}°, beyond "
                                     f"{math.degrees(share * MAX_TILT_RAD):.1f}°")
        w_ok = (-c1 + np.sqrt(c1 * c1 + 4.0 * c2 * room)) / (2.0 * c2)
        moving = np.abs(rate) > 1e-9
        if np.any(moving):
            s = min(s, float((w_ok[moving] / np.abs(rate[moving])).min()))
    return FourierExcitation(exc.a * s, exc.b * s, exc.q0, exc.f0_hz * s)


def _unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = 3 * N_HARMONICS
    return x[:n].reshape(3, N_HARMONICS), x[n:].reshape(3, N_HARMONICS)


def optimize_excitation(model: RobotModel | None = None, seed: int = 0,
                        evaluations: int = 300, samples: int = 60) -> FourierExcitation:
    """Coefficients minimising cond(W) of the column-scaled base regressor over ``samples``
    points of one period of the path *as played* (:func:`to_limits`), keeping only the
    equations of axes sliding faster than the estimator's ``MIN_SPEED_M_S``; a penalty outside
    the excursion; the result, time-scaled to the limits, is checked."""
    from rt.identification.estimate import MIN_SPEED_M_S

    model = model or RobotModel.load()
    reg = Regressor(model.dyn)
    rng = np.random.default_rng(seed)
    phase = np.linspace(0.0, 1.0, samples, endpoint=False)    # of one period

    def cost(x: np.ndarray) -> float:
        exc = FourierExcitation(*_unpack(x))
        e, v, a = exc.peaks()
        if e > MAX_EXCURSION_M:
            return 1e6 * e / MAX_EXCURSION_M
        if not (v > 1e-6 and a > 1e-6):
            return 1e7
        try:
            played = to_limits(exc, model)
        except (KinematicsError, ConfigurationError):   # outside the assembly range or ROM
            return 1e7
        q, qd, qdd = played.evaluate(phase * played.period_s)
        try:
            w = stacked_regressor(reg, q, qd, qdd)
        except KinematicsError:           # a pose outside the assembly range: not admissible
            return 1e7
        w = w[np.abs(qd).reshape(-1) >= MIN_SPEED_M_S]
        if len(w) < 2 * w.shape[1]:
            return 1e7
        w = w / np.maximum(np.linalg.norm(w, axis=0), 1e-12)
        return float(np.linalg.cond(w))

    x0 = rng.uniform(-1.0, 1.0, 6 * N_HARMONICS) * 0.02
    while cost(x0) >= 1e6:
        x0 *= 0.7
    res = scipy.optimize.minimize(cost, x0, method="Powell",
                                  options={"maxfev": evaluations, "xtol": 1e-4})
    exc = to_limits(FourierExcitation(*_unpack(res.x if res.fun < cost(x0) else x0)), model)
    if not exc.within_limits():
        raise ConfigurationError("excitation optimisation left the robot's limits")
    return exc


def benchmark_excitation(q0: float = Q0_M) -> FourierExcitation:
    """The tracking benchmark's trajectory (``rt.control.experiment.benchmark_reference``:
    0.030 m at 0.25 Hz plus 0.015 m at 0.6 Hz per slider, phases 0, 2π/3, 4π/3) as a Fourier
    excitation of base frequency 0.05 Hz (harmonics 5 and 12): the validation trajectory, unlike
    the optimised excitation, that the RT process plays as the same kind of program."""
    f0 = 0.05
    w = 2.0 * math.pi * f0
    a = np.zeros((3, 12))
    b = np.zeros((3, 12))
    for i in range(3):
        ph = 2.0 * math.pi * i / 3.0
        for k, amp in ((5, 0.030), (12, 0.015)):
            # amp sin(kωt + φ) = amp cos φ sin kωt + amp sin φ cos kωt
            a[i, k - 1] = amp * math.cos(ph) * k * w
            b[i, k - 1] = -amp * math.sin(ph) * k * w
    return FourierExcitation(a, b, q0, f0)
