"""Closed-loop tracking experiments on the twin (thesis 4.1), in lockstep as fast as possible.

One cycle, as on the rig: read the encoders (PCL-833 path), estimate q̇ (Kalman), compute the
model state (FK + closed-chain maps), run the controller, convert forces to volts (saturated at
the command limit), write the DAC (PCI-1720 path). Errors are measured q − q_d, as the thesis
plots them.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from rt.control.base import Reference, create
from rt.errors import ConfigurationError
from rt.estimation.velocity import KalmanVelocityEstimator
from rt.model import RobotModel
from rt.model.dynamics import State
from rt.references.approach import Approach, ApproachStatus
from rt.twin.backends import TwinActuators, TwinEncoders
from rt.twin.environment import FreeMotion, PayloadStep
from rt.twin.twin import SimClock, Twin

RefFn = Callable[[float, Reference], None]


@dataclass
class TrackingLog:
    """Samples of the trajectory phase (the approach, if any, is in ``approach_s`` only)."""

    t: np.ndarray           # trajectory time (s)
    q: np.ndarray           # measured (m), (n, 3)
    q_ref: np.ndarray       # (n, 3)
    tau: np.ndarray         # commanded (N), (n, 3)
    volts: np.ndarray       # (n, 3)
    controller: object
    approach_s: float = 0.0

    @property
    def error(self) -> np.ndarray:
        return self.q - self.q_ref


def benchmark_reference(q0: float = 0.20) -> RefFn:
    """The issue's fixed trajectory: q_i = q0 + 0.030 sin(2π·0.25 t + φ_i) + 0.015 sin(2π·0.6 t
    + ψ_i) m with φ_i = ψ_i = 0, 2π/3, 4π/3.

    Sampled by a compiled kernel (the loop calls it every cycle); the arithmetic is
    :func:`benchmark_reference_interpreted`'s, its reference, operation for operation."""
    _warm_benchmark()
    return _BenchmarkReference(float(q0))


class _BenchmarkReference:
    """The compiled benchmark trajectory: called per sample as any ``RefFn``, and
    ``tabulate(dt, n)`` samples it at k·dt, k < n, in one compiled call (the same arithmetic:
    the sequencer's table of a ``TrajectoryProgram``)."""

    def __init__(self, q0: float) -> None:
        self.q0 = q0
        self.w1, self.w2 = 2 * math.pi * 0.25, 2 * math.pi * 0.6
        self._interpreted = benchmark_reference_interpreted(q0)

    def __call__(self, t: float, out: Reference) -> None:
        q, qd, qdd = out.q, out.qd, out.qdd
        if type(q) is np.ndarray and type(qd) is np.ndarray and type(qdd) is np.ndarray:
            _benchmark_sample(float(t), self.q0, self.w1, self.w2, q, qd, qdd)
        else:                         # lists or other sequences: the interpreted sampler
            self._interpreted(t, out)

    def tabulate(self, dt: float, n: int) -> np.ndarray:
        """(n, 9) rows of q, q̇, q̈ (m, m/s, m/s²) at t = k·dt."""
        table = np.empty((n, 9))
        _benchmark_table(self.q0, self.w1, self.w2, float(dt), table)
        return table


def benchmark_reference_interpreted(q0: float = 0.20) -> RefFn:
    """:func:`benchmark_reference` in Python (the reference of its compiled sampler)."""
    w1, w2 = 2 * math.pi * 0.25, 2 * math.pi * 0.6
    phases = (0.0, 2 * math.pi / 3, 4 * math.pi / 3)

    def ref(t: float, out: Reference) -> None:
        for i, ph in enumerate(phases):
            out.q[i] = q0 + 0.030 * math.sin(w1 * t + ph) + 0.015 * math.sin(w2 * t + ph)
            out.qd[i] = 0.030 * w1 * math.cos(w1 * t + ph) + 0.015 * w2 * math.cos(w2 * t + ph)
            out.qdd[i] = -0.030 * w1 ** 2 * math.sin(w1 * t + ph) - 0.015 * w2 ** 2 * math.sin(
                w2 * t + ph)

    return ref


@njit(cache=True)
def _benchmark_sample(t, q0, w1, w2, q, qd, qdd):
    """One sample of the benchmark trajectory at ``t`` (s) into q, q̇, q̈ (m, m/s, m/s²)."""
    for i in range(3):
        ph = 0.0 if i == 0 else (2 * math.pi / 3 if i == 1 else 4 * math.pi / 3)
        q[i] = q0 + 0.030 * math.sin(w1 * t + ph) + 0.015 * math.sin(w2 * t + ph)
        qd[i] = 0.030 * w1 * math.cos(w1 * t + ph) + 0.015 * w2 * math.cos(w2 * t + ph)
        qdd[i] = -0.030 * w1 ** 2 * math.sin(w1 * t + ph) - 0.015 * w2 ** 2 * math.sin(
            w2 * t + ph)


@njit(cache=True)
def _benchmark_table(q0, w1, w2, dt, table):
    """Rows k of ``table`` = the sample at t = k·dt (as ``_benchmark_sample`` at float(k·dt))."""
    for k in range(table.shape[0]):
        _benchmark_sample(k * dt, q0, w1, w2, table[k, 0:3], table[k, 3:6], table[k, 6:9])


def _warm_benchmark() -> None:
    """Compile (or load from numba's cache) the sampler when a trajectory is built, not in
    the first cycle that samples it."""
    z = np.zeros(3)
    _benchmark_sample(0.0, 0.2, 1.0, 1.0, z, z, z)
    _benchmark_table(0.2, 1.0, 1.0, 1e-3, np.zeros((1, 9)))


def run_tracking(controller: str, seconds: float, reference: RefFn, environment=None,
                 gains: dict | None = None, rate_hz: float = 1000.0, seed: int = 0,
                 model: RobotModel | None = None, twin_kwargs: dict | None = None,
                 approach_from: tuple[float, float, float] | None = None) -> TrackingLog:
    """Run ``controller`` on the twin for ``seconds`` of ``reference``.

    With ``approach_from`` (slider positions, m) the robot starts there at rest and a ruckig
    jerk-limited approach brings the reference to the trajectory's first state (position,
    velocity, acceleration) before trajectory time 0; otherwise the robot starts on the
    trajectory. Environment times (e.g. a payload step) count from trajectory time 0.
    """
    model = model or RobotModel.load()
    ref = Reference()
    reference(0.0, ref)
    approach = None
    if approach_from is not None:
        approach = Approach(dt=1.0 / rate_hz, stroke=model.description.limits.stroke)
        approach.reset(approach_from)
        status = approach.set_target(ref.q, ref.qd, ref.qdd)
        if status != ApproachStatus.WORKING:
            raise ConfigurationError(f"approach to the trajectory's first point refused: "
                                     f"{status.name}")
        t_offset = approach.duration
    else:
        t_offset = 0.0
    if environment is not None and isinstance(environment, PayloadStep):
        environment = environment.model_copy(update={"at_s": environment.at_s + t_offset})
    clock = SimClock()
    # The twin is "the real rig" (default truth and imperfections) unless twin_kwargs say
    # otherwise (e.g. {"imperfections": RigImperfections.none(), "description": ...}).
    kwargs = dict(twin_kwargs or {})
    twin = Twin(kwargs.pop("description", None), environment or FreeMotion(), seed=seed,
                clock=clock, **kwargs)
    if approach is not None:
        twin.place(approach_from)
    else:
        twin.place(ref.q, ref.qd)
    enc = TwinEncoders(twin)
    card = TwinActuators(twin, 0)
    card.enable()
    ctrl = create(controller, model, gains)
    est = KalmanVelocityEstimator()
    st = State()
    dt = 1.0 / rate_hz
    n = round(seconds * rate_hz)
    n_approach = round(t_offset * rate_hz)
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
    for k in range(-n_approach, n):
        t = k * dt
        clock.t = t + t_offset
        enc.read_positions_m(q)
        est.update(q, dt)
        if approach is not None and k < 0:
            approach.update(ref.q, ref.qd, ref.qdd)
        else:
            reference(t, ref)
        model.dyn.state(q, est.qd, out=st)
        ctrl.update(st, ref, dt, tau)
        np.clip(tau / per_volt, -limit, limit, out=volts)
        card.write_volts(volts)
        if k < 0:
            continue
        log_t[k] = t
        log_q[k] = q
        log_r[k] = ref.q
        log_tau[k] = tau
        log_v[k] = volts
    card.close()
    return TrackingLog(log_t, log_q, log_r, log_tau, log_v, ctrl, t_offset)
