"""The real-time blocks of the position loop, in the thesis's modular layout (3.7.2):
sensors → estimation → model → reference → controller → drive, each a ``Component`` with
typed ports, triggered in dependency order by one periodic activity.

Each block's ports are documented first thing in its docstring; units are SI.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import carray, njit

from rt.control.base import Controller, Reference
from rt.devices.interfaces import EncoderBank
from rt.engine import Array, Component, Struct
from rt.errors import InputError, KinematicsError, TalusError
from rt.estimation.compiled import CompiledKalmanEstimator
from rt.estimation.velocity import KalmanVelocityEstimator
from rt.model import RobotModel
from rt.model.dynamics import State
from rt.model.kernels import MODEL_STATE_WORK, model_state
from rt.model.kinematics import FK_MAX_ITERATIONS, FK_STEP_TOL_RAD
from rt.pointers import f64_at
from rt.safety.events import SupervisorMode

STATUS_SENSOR = 10
STATUS_REFERENCE = 12


class EncoderReader(Component):
    """Ports: out ``q``: float64[3], m — slider positions read from the encoder card."""

    def __init__(self, name: str, encoders: EncoderBank):
        super().__init__(name)
        self.encoders = encoders
        self.q = self.declare_output("q", Array(3), "slider positions (m)")

    def update(self, t: float, dt: float) -> int:
        self.encoders.read_positions_m(self.q.data)
        return 0


class VelocityEstimation(Component):
    """Ports: in ``q_meas``: float64[3], m; out ``q``, ``qd``, ``qdd``: float64[3] (m, m/s,
    m/s²) — the Kalman estimate from the quantized encoders; out ``status``: float64[1] — the
    estimator's status (−3 = implausible jump, for the supervisor).

    The filter runs compiled (``rt.estimation.compiled``: one call writes the four outputs,
    views of one arena); ``compiled=False`` runs the interpreted ``KalmanVelocityEstimator``,
    its reference."""

    def __init__(self, name: str, compiled: bool = True):
        super().__init__(name)
        self.compiled = compiled
        self._io = io = np.zeros(10)
        self.q_meas = self.declare_input("q_meas", Array(3))
        self.q = self.declare_output("q", Array(3), buffer=io[0:3])
        self.qd = self.declare_output("qd", Array(3), buffer=io[3:6])
        self.qdd = self.declare_output("qdd", Array(3), buffer=io[6:9])
        self.status = self.declare_output("status", Array(1), buffer=io[9:10])
        self._step: Callable[[np.ndarray, float, np.ndarray], int] | None = None

    def make_state(self) -> KalmanVelocityEstimator | CompiledKalmanEstimator:
        est = CompiledKalmanEstimator() if self.compiled else KalmanVelocityEstimator()
        self._step = est.update_into if isinstance(est, CompiledKalmanEstimator) else None
        return est

    def update(self, t: float, dt: float) -> int:
        step = self._step
        if step is not None:
            status = step(self.q_meas.data, dt, self._io)
            return STATUS_SENSOR if (status < 0 and status != -3) else 0
        est = self.state
        status = est.update(self.q_meas.data, dt)
        self.status.data[0] = status
        if status < 0 and status != -3:            # a flagged jump is the supervisor's business
            return STATUS_SENSOR
        self.q.data[:] = est.q
        self.qd.data[:] = est.qd
        self.qdd.data[:] = est.qdd
        return 0


class ModelState(Component):
    """Ports: in ``q_meas``: float64[3], m (measured positions), in ``qd``: float64[3], m/s
    (estimated velocities); out ``state``: model ``State`` — forward kinematics (warm-started),
    the closed-chain maps S, Ṡ and the platform pose for this cycle; out ``fk_ok``: float64[1]
    — 0 when FK failed this cycle (the state then keeps the last good pose; the supervisor
    stops the robot: the block itself keeps running, so the loop can still hold it safely).

    The cycle runs compiled (``rt.model.kernels.model_state``: one call, no Python objects);
    ``compiled=False`` runs the interpreted ``Dynamics.state``, the reference it is tested
    against. Both share the kinematics' FK warm start."""

    def __init__(self, name: str, model: RobotModel, compiled: bool = True):
        super().__init__(name)
        self.model = model
        self.compiled = compiled
        self._work = np.zeros(MODEL_STATE_WORK)
        self._args: tuple | None = None
        if compiled:
            # Compile (or load from numba's cache) now, not in the first cycle; on a copy of
            # the warm start, so the model's own is untouched.
            # Inputs as the loop passes them: read-only port views (numba types them apart).
            kin = model.kin
            q = np.full(3, 0.5 * (kin.stroke[0] + kin.stroke[1]))
            qd = np.zeros(3)
            q.flags.writeable = qd.flags.writeable = False
            model_state(kin.geom, kin.limits_array, kin._phi_guess.copy(), q, qd, State().buf,
                        FK_STEP_TOL_RAD, FK_MAX_ITERATIONS, self._work)
        self.q_meas = self.declare_input("q_meas", Array(3))
        self.qd = self.declare_input("qd", Array(3))
        self.state_out = self.declare_output("state", Struct(State))
        self.fk_ok = self.declare_output("fk_ok", Array(1))

    def on_start(self) -> None:
        self._args = None              # bound again at the first cycle (ports may be rebound)

    def update(self, t: float, dt: float) -> int:
        if self.compiled:
            args = self._args
            if args is None:
                # The kernel's arguments are the same objects every cycle: bound once.
                kin = self.model.kin
                args = self._args = (kin.geom, kin.limits_array, kin._phi_guess,
                                     self.q_meas.data, self.qd.data, self.state_out.data.buf,
                                     FK_STEP_TOL_RAD, FK_MAX_ITERATIONS, self._work)
            st = self.state_out.data
            status = model_state(*args)
            if status >= 0:
                st.buffer_filled()
                self.fk_ok.data[0] = 1.0
            else:
                self.fk_ok.data[0] = 0.0
            return 0
        try:
            self.model.dyn.state(self.q_meas.data, self.qd.data, out=self.state_out.data)
            self.fk_ok.data[0] = 1.0
        except KinematicsError:
            self.fk_ok.data[0] = 0.0
        return 0


class ControllerBlock(Component):
    """Ports: in ``state``: model ``State``; in ``q_ref``, ``qd_ref``, ``qdd_ref``: float64[3];
    out ``tau``: float64[3], N — the hosted control law's actuator forces.

    Swapping this block for another ``ControllerBlock`` at a cycle boundary is bumpless: the new
    law takes over from the old one's last force (``Controller.handover``).
    """

    def __init__(self, name: str, controller: Controller):
        super().__init__(name)
        self.controller = controller
        self.state_in = self.declare_input("state", Struct(State))
        self.q_ref = self.declare_input("q_ref", Array(3))
        self.qd_ref = self.declare_input("qd_ref", Array(3))
        self.qdd_ref = self.declare_input("qdd_ref", Array(3))
        self.mode = self.declare_input("mode", Array(1))
        self.tau = self.declare_output("tau", Array(3))
        self._ref = Reference()
        self._dt = 1e-3
        self._mode = SupervisorMode.RUN
        self._mode_raw = float(SupervisorMode.RUN)

    def _bind_reference(self) -> Reference:
        self._ref.q = self.q_ref.data
        self._ref.qd = self.qd_ref.data
        self._ref.qdd = self.qdd_ref.data
        return self._ref

    def set_params(self, **values) -> None:
        """Gains change at a cycle boundary (``loop.set_param("controller", name, value)``);
        invalid gains are refused with ``InputError`` and nothing changes."""
        try:
            self.controller.set_gains(**values)
        except TalusError as exc:
            raise InputError(f"component {self.name!r}: rejected {values!r}: {exc}") from exc

    def on_start(self) -> None:
        # The law's compiled cycle on this block's buffers (bound now: a swap has bound the
        # inputs and adopted the outputs before it starts the new block).
        self.controller.bind_cycle(self.state_in.data, self._bind_reference(), self.tau.data)

    def handover(self, old: Component) -> None:
        # The outputs already hold the old law's last force (the engine adopts its buffers).
        self.controller.handover(self.tau.data.copy(), self.state_in.data,
                                 self._bind_reference(), self._dt)

    def update(self, t: float, dt: float) -> int:
        self._dt = dt
        raw = self.mode.data[0]
        # The enum is built only when the mode changed (it costs more than the compiled law).
        if raw != self._mode_raw:
            self._mode_raw = raw
            self._mode_changed(SupervisorMode.from_port(raw))
        cycle = self.controller.cycle
        if cycle is not None:                 # one compiled call (``Controller.bind_cycle``)
            return cycle(dt)
        return self.controller.update(self.state_in.data, self._ref, dt, self.tau.data)

    def _mode_changed(self, mode: SupervisorMode) -> None:
        if mode != self._mode:
            if self._mode == SupervisorMode.HARD_STOP:
                # Drives back after a hard stop: integrators and estimates start afresh.
                self.controller.reset()
            self._mode = mode


@njit(cache=True)
def tap_row(ring, row, t, addr, lens):
    """Row ``row`` of ``ring`` = [t, every signal in order], the signals given by their
    addresses (``addr``, int64[n]: float64 C arrays) and lengths (``lens``). Not a tuple of
    the arrays: numba types a tuple element by element at every call (≈ 3 µs for the session
    tap's signals, more than the copy); two int64 arrays dispatch as fast as one."""
    r = ring[row]
    r[0] = t
    k = 1
    for j in range(addr.shape[0]):
        n = lens[j]
        a = carray(f64_at(addr[j]), n)
        for i in range(n):
            r[k + i] = a[i]
        k += n


class SignalTap(Component):
    """Ports: one float64[n] input per declared signal; no outputs.

    Copies the cycle's signals (after the loop time) into a preallocated ring that a
    non-real-time thread drains — like ``RecorderTap``, for any set of signals.
    """

    def __init__(self, name: str, signals: list[tuple[str, int]], capacity: int = 65536):
        super().__init__(name)
        self.layout = [("t", 1), *signals]
        self.ports = [self.declare_input(n, Array(w)) for n, w in signals]
        self.width = 1 + sum(w for _, w in signals)
        self.capacity = capacity
        self.ring = np.zeros((capacity, self.width))
        self.written = 0
        self._signals: tuple[np.ndarray, ...] | None = None
        self._addr = self._lens = np.zeros(0, dtype=np.int64)

    def on_start(self) -> None:
        # The inputs are bound now (and stay so while the graph runs): the row is then one
        # compiled call on them (``tap_row``), compiled here rather than in a cycle. Inputs of
        # mixed array kinds (not a graph's read-only views) keep the interpreted copy.
        signals = tuple(p.data for p in self.ports)
        kinds = {(type(a), a.dtype, a.ndim, a.flags.c_contiguous, a.flags.writeable)
                 for a in signals}
        self._signals = signals if len(kinds) == 1 and next(iter(kinds))[:4] == (
            np.ndarray, np.float64, 1, True) else None
        if self._signals is not None:
            # The row copies from the inputs' addresses: ``_signals`` keeps the arrays alive.
            self._addr = np.array([a.ctypes.data for a in self._signals], dtype=np.int64)
            self._lens = np.array([a.shape[0] for a in self._signals], dtype=np.int64)
            tap_row(np.zeros((1, self.width)), 0, 0.0, self._addr, self._lens)

    def update(self, t: float, dt: float) -> int:
        if self._signals is not None:
            tap_row(self.ring, self.written % self.capacity, t, self._addr, self._lens)
            self.written += 1
            return 0
        row = self.ring[self.written % self.capacity]
        row[0] = t
        k = 1
        for port in self.ports:
            n = port.data.shape[0]
            row[k:k + n] = port.data
            k += n
        self.written += 1
        return 0

    def drain(self, start: int) -> tuple[np.ndarray, int]:
        """Rows written since ``start`` (a copy, oldest first) and the new start index."""
        end = self.written
        start = max(start, end - self.capacity)
        first, n = start % self.capacity, max(0, end - start)
        if first + n <= self.capacity:          # not wrapped: one slice, no index array
            return self.ring[first:first + n].copy(), end
        idx = np.arange(start, end) % self.capacity
        return self.ring[idx].copy(), end


class RecorderTap(SignalTap):
    """Ports: in ``q``, ``qd``, ``q_ref``, ``tau``, ``volts``: float64[3]; no outputs.

    The recording hand-off of the loop's state (``rt.recording`` drains it into /robot/state):
    rows of t, q, q̇, q_ref, τ, V in a preallocated ring; the oldest rows are overwritten when
    nobody drains it.
    """

    WIDTH = 1 + 5 * 3

    def __init__(self, name: str, capacity: int = 65536):
        super().__init__(name, [("q", 3), ("qd", 3), ("q_ref", 3), ("tau", 3), ("volts", 3)],
                         capacity)
