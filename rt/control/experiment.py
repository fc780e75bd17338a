"""Closed-loop tracking experiments on the twin (thesis 4.1), in lockstep as fast as possible.

One cycle, as on the rig: read the encoders (PCL-833 path), estimate q̇ (Kalman), compute the
model state (FK + closed-chain maps), run the controller, convert forces to volts (saturated at
the command limit), write the DAC (PCI-1720 path). Errors are measured q − q_d, as the thesis
plots them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from rt.control.base import Reference, create
from rt.estimation.velocity import KalmanVelocityEstimator
from rt.model import RobotModel
from rt.model.dynamics import State
from rt.twin.backends import TwinActuators, TwinEncoders
from rt.twin.environment import FreeMotion
from rt.twin.twin import SimClock, Twin

RefFn = Callable[[float, Reference], None]


@dataclass
class TrackingLog:
    t: np.ndarray           # s
    q: np.ndarray           # measured (m), (n, 3)
    q_ref: np.ndarray       # (n, 3)
    tau: np.ndarray         # commanded (N), (n, 3)
    volts: np.ndarray       # (n, 3)
    controller: object

    @property
    def error(self) -> np.ndarray:
        return self.q - self.q_ref


def benchmark_reference(q0: float = 0.20) -> RefFn:
    """The issue's fixed trajectory: q_i = q0 + 0.030 sin(2π·0.25 t + φ_i) + 0.015 sin(2π·0.6 t
    + ψ_i) m with φ_i = ψ_i = 0, 2π/3, 4π/3."""
    w1, w2 = 2 * math.pi * 0.25, 2 * math.pi * 0.6
    phases = (0.0, 2 * math.pi / 3, 4 * math.pi / 3)

    def ref(t: float, out: Reference) -> None:
        for i, ph in enumerate(phases):
            out.q[i] = q0 + 0.030 * math.sin(w1 * t + ph) + 0.015 * math.sin(w2 * t + ph)
            out.qd[i] = 0.030 * w1 * math.cos(w1 * t + ph) + 0.015 * w2 * math.cos(w2 * t + ph)
            out.qdd[i] = -0.030 * w1 ** 2 * math.sin(w1 * t + ph) - 0.015 * w2 ** 2 * math.sin(
                w2 * t + ph)

    return ref


def run_tracking(controller: str, seconds: float, reference: RefFn, environment=None,
                 gains: dict | None = None, rate_hz: float = 1000.0, seed: int = 0,
                 model: RobotModel | None = None, twin_kwargs: dict | None = None) -> TrackingLog:
    """Run ``controller`` on the twin for ``seconds`` following ``reference``."""
    model = model or RobotModel.load()
    clock = SimClock()
    twin = Twin(model.description, environment or FreeMotion(), seed=seed, clock=clock,
                **(twin_kwargs or {}))
    ref = Reference()
    reference(0.0, ref)
    twin.place(ref.q, ref.qd)
    enc = TwinEncoders(twin)
    card = TwinActuators(twin, 0)
    card.enable()
    ctrl = create(controller, model, gains)
    est = KalmanVelocityEstimator()
    st = State()
    dt = 1.0 / rate_hz
    n = int(round(seconds * rate_hz))
    per_volt = model.description.drive.force_per_volt_n
    limit = model.description.drive.command_limit_v
    q = np.zeros(3)
    tau = np.zeros(3)
    volts = np.zeros(3)
    log_t = np.empty(n)
    log_q = np.empty((n, 3))
    log_r = np.empty((n, 3))
    log_tau = np.empty((n, 3))
    log_v = np.empty((n, 3))
    for k in range(n):
        t = k * dt
        clock.t = t
        enc.read_positions_m(q)
        est.update(q, dt)
        reference(t, ref)
        model.dyn.state(q, est.qd, out=st)
        ctrl.update(st, ref, dt, tau)
        np.clip(tau / per_volt, -limit, limit, out=volts)
        card.write_volts(volts)
        log_t[k] = t
        log_q[k] = q
        log_r[k] = ref.q
        log_tau[k] = tau
        log_v[k] = volts
    card.close()
    return TrackingLog(log_t, log_q, log_r, log_tau, log_v, ctrl)
