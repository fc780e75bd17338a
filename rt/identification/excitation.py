"""Excitation trajectories for identification: a finite Fourier series per slider (Swevers et
al. 1997), periodic so the data can be averaged and filtered without edge effects, with its
coefficients chosen to minimise the condition number of the stacked base regressor while
staying inside the robot's position, velocity and acceleration limits.

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


def _unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = 3 * N_HARMONICS
    return x[:n].reshape(3, N_HARMONICS), x[n:].reshape(3, N_HARMONICS)


def optimize_excitation(model: RobotModel | None = None, seed: int = 0,
                        evaluations: int = 300, samples: int = 60) -> FourierExcitation:
    """Coefficients minimising cond(W) of the column-scaled base regressor over ``samples``
    points of one period, with a penalty outside the limits; the result is checked."""
    model = model or RobotModel.load()
    reg = Regressor(model.dyn)
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0 / BASE_FREQUENCY_HZ, samples, endpoint=False)

    def cost(x: np.ndarray) -> float:
        exc = FourierExcitation(*_unpack(x))
        e, v, a = exc.peaks()
        over = (max(0.0, e / MAX_EXCURSION_M - 1.0) + max(0.0, v / MAX_SPEED_M_S - 1.0)
                + max(0.0, a / MAX_ACCEL_M_S2 - 1.0))
        if over > 0.0:
            return 1e6 * (1.0 + over)
        try:
            w = stacked_regressor(reg, *exc.evaluate(t))
        except KinematicsError:           # a pose outside the assembly range: not admissible
            return 1e7
        w = w / np.maximum(np.linalg.norm(w, axis=0), 1e-12)
        return float(np.linalg.cond(w))

    x0 = rng.uniform(-1.0, 1.0, 6 * N_HARMONICS) * 0.02
    while cost(x0) >= 1e6:
        x0 *= 0.7
    res = scipy.optimize.minimize(cost, x0, method="Powell",
                                  options={"maxfev": evaluations, "xtol": 1e-4})
    exc = FourierExcitation(*_unpack(res.x if res.fun < cost(x0) else x0))
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
