"""The real-time blocks of the position loop, in the thesis's modular layout (3.7.2):
sensors → estimation → model → reference → controller → drive, each a ``Component`` with
typed ports, triggered in dependency order by one periodic activity.

Each block's ports are documented first thing in its docstring; units are SI.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from rt.control.base import Controller, Reference
from rt.devices.interfaces import ActuatorOutputs, EncoderBank
from rt.engine import Array, Component, Struct
from rt.errors import InputError, KinematicsError, TalusError
from rt.estimation.velocity import KalmanVelocityEstimator
from rt.model import RobotModel
from rt.model.dynamics import State
from rt.references.approach import Approach, ApproachStatus

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
    estimator's status (−3 = implausible jump, for the supervisor)."""

    def __init__(self, name: str):
        super().__init__(name)
        self.q_meas = self.declare_input("q_meas", Array(3))
        self.q = self.declare_output("q", Array(3))
        self.qd = self.declare_output("qd", Array(3))
        self.qdd = self.declare_output("qdd", Array(3))
        self.status = self.declare_output("status", Array(1))

    def make_state(self):
        return KalmanVelocityEstimator()

    def update(self, t: float, dt: float) -> int:
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
    stops the robot: the block itself keeps running, so the loop can still hold it safely)."""

    def __init__(self, name: str, model: RobotModel):
        super().__init__(name)
        self.model = model
        self.q_meas = self.declare_input("q_meas", Array(3))
        self.qd = self.declare_input("qd", Array(3))
        self.state_out = self.declare_output("state", Struct(State))
        self.fk_ok = self.declare_output("fk_ok", Array(1))

    def update(self, t: float, dt: float) -> int:
        try:
            self.model.dyn.state(self.q_meas.data, self.qd.data, out=self.state_out.data)
            self.fk_ok.data[0] = 1.0
        except KinematicsError:
            self.fk_ok.data[0] = 0.0
        return 0


@dataclass
class _RefState:
    phase: int = 0            # 0 approach, 1 trajectory, 2 back to rest, 3 stopped, 4 hold
    t0: float = math.nan      # loop time at which the trajectory started (s)
    mode: float = 0.0         # the supervisor's mode seen last cycle
    started: bool = False


class TrajectoryReference(Component):
    """Ports: in ``q_meas``: float64[3], m; in ``mode``: float64[1] (the supervisor's, one cycle
    late); out ``q_ref``, ``qd_ref``, ``qdd_ref``: float64[3] (m, m/s, m/s²) and ``phase``:
    float64[1] — 0 approach, 1 trajectory, 2 back to rest, 3 stopped by the supervisor,
    4 holding (no program).

    A program is a trajectory ``f(t, out)`` with a duration: a ruckig approach brings the
    reference from where it is to the program's first state (position, velocity, acceleration),
    the program plays, then a jerk-limited stop brings it back to rest. Position limits are
    checked by the approach generator (our code, not ruckig's). ``request(...)`` starts a
    program from any thread; it is taken at the next cycle boundary.

    On a soft stop the reference brakes to a hold with the jerk-limited soft stop; during a hard
    stop it follows the measured position (so nothing jumps when the drives come back); after a
    reset it holds where the robot is until a new program is requested.
    """

    def __init__(self, name: str, trajectory: Callable[[float, Reference], None] | None,
                 duration_s: float, stroke: tuple[float, float], rate_hz: float = 1000.0):
        super().__init__(name)
        self.approach = Approach(dt=1.0 / rate_hz, stroke=stroke)
        self.q_meas = self.declare_input("q_meas", Array(3))
        self.mode = self.declare_input("mode", Array(1))
        self.q_ref = self.declare_output("q_ref", Array(3))
        self.qd_ref = self.declare_output("qd_ref", Array(3))
        self.qdd_ref = self.declare_output("qdd_ref", Array(3))
        self.phase = self.declare_output("phase", Array(1), initial=np.full(1, 4.0))
        self._ref = Reference(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
        self._first = Reference()
        self._initial = None if trajectory is None else (trajectory, duration_s)
        self._pending: tuple | None = None
        self.trajectory: Callable[[float, Reference], None] | None = None
        self.duration_s = 0.0
        self.last_error = ""

    def make_state(self):
        return _RefState(phase=4)

    def on_start(self) -> None:
        self.state = _RefState(phase=4)
        self._pending = self._initial

    def request(self, trajectory: Callable[[float, Reference], None], duration_s: float) -> None:
        """Start a program at the next cycle boundary (any thread)."""
        self._pending = (trajectory, duration_s)

    @property
    def busy(self) -> bool:
        return self.state is not None and self.state.phase in (0, 1, 2)

    def _begin(self, trajectory, duration_s: float, from_hold: bool) -> bool:
        """Plan the approach from the current reference (or the measured position at start)."""
        if from_hold:
            self.approach.reset(self.q_meas.data)
        else:
            self.approach.reset(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
        trajectory(0.0, self._first)
        status = self.approach.set_target(self._first.q, self._first.qd, self._first.qdd)
        if status != ApproachStatus.WORKING:
            self.last_error = f"approach to the program refused: {status.name}"
            self.approach.reset(self.q_meas.data if from_hold else self.q_ref.data)
            self.state.phase = 4
            return False
        self.trajectory, self.duration_s = trajectory, duration_s
        self.state.phase = 0
        self.state.started = True
        return True

    def update(self, t: float, dt: float) -> int:
        st = self.state
        mode = self.mode.data[0]
        if not st.started and self._pending is None:
            # Nothing to play yet: hold where the robot is.
            self.approach.reset(self.q_meas.data)
            st.started = True
        if self._pending is not None and mode < 2.0:
            trajectory, duration = self._pending
            self._pending = None
            self._begin(trajectory, duration, from_hold=not st.started or st.phase == 4)
        if mode != st.mode:
            if mode >= 3.0:
                pass                                        # follow (below)
            elif mode >= 2.0:
                self.approach.reset(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
                self.approach.soft_stop()
                st.phase = 3
            else:                                           # reset: hold where the robot is
                self.approach.reset(self.q_meas.data)
                st.phase = 4
            st.mode = mode
        if mode >= 3.0:
            self.q_ref.data[:] = self.q_meas.data
            self.qd_ref.data[:] = 0.0
            self.qdd_ref.data[:] = 0.0
            self.phase.data[0] = 3
            return 0
        if st.phase >= 3:
            self.approach.update(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
            self.phase.data[0] = st.phase
            return 0
        if st.phase == 0:
            status = self.approach.update(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
            if status < 0:
                return STATUS_REFERENCE
            if status == ApproachStatus.FINISHED:
                st.phase = 1
                st.t0 = t
        if st.phase == 1:
            tt = t - st.t0
            if tt > self.duration_s:
                # Back to rest, jerk-limited, from the trajectory's last state.
                self.approach.reset(self.q_ref.data, self.qd_ref.data, self.qdd_ref.data)
                self.approach.soft_stop()
                st.phase = 2
            else:
                self.trajectory(tt, self._ref)
        if st.phase == 2:
            if self.approach.update(self.q_ref.data, self.qd_ref.data,
                                    self.qdd_ref.data) == ApproachStatus.FINISHED:
                st.phase = 4
        self.phase.data[0] = st.phase
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
        self._mode = 0.0

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

    def handover(self, old: "ControllerBlock") -> None:
        # The outputs already hold the old law's last force (the engine adopts its buffers).
        self.controller.handover(self.tau.data.copy(), self.state_in.data,
                                 self._bind_reference(), self._dt)

    def update(self, t: float, dt: float) -> int:
        self._dt = dt
        mode = self.mode.data[0]
        if mode != self._mode:
            if self._mode >= 3.0 and mode < 3.0:
                # Drives back after a hard stop: integrators and estimates start afresh.
                self.controller.reset()
            self._mode = mode
        return self.controller.update(self.state_in.data, self._bind_reference(), dt,
                                      self.tau.data)


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

    def update(self, t: float, dt: float) -> int:
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
