"""Jerk-limited point-to-point moves and the soft stop, with ruckig (DESIGN.md §5-6).

The thesis brought the robot from rest to a trajectory's first point (and back) with an 8 s
natural cubic spline (thesis 3.7.4). Here ruckig computes the time-optimal jerk-limited move from
the current state (position, velocity, acceleration) to a target *state*, so a playback can start
on its first sample with that sample's velocity, and the move can be retargeted while running.
``minimum_duration`` slows a move down (e.g. 8 s as in the thesis) without changing limits.

**Position limits are ours.** ruckig 0.19 community edition silently ignores
``min_position``/``max_position`` (PLATFORM.md; ``tests/test_references.py`` shows it overshooting
a limit and reporting ``Finished``). So every target is checked against the stroke before it is
accepted, the whole trajectory is computed first and its position extrema checked (a target
inside the stroke can still be overshot when the slider arrives fast), and every produced sample
is checked again (clamped to the stroke with an error status if it ever leaves it). Intermediate
waypoints are never used (they need ruckig's cloud service and raise).

Default limits (per axis, SI): max velocity 0.15 m/s, max acceleration 0.5 m/s², max jerk 5 m/s³.

* 0.15 m/s: the benchmark trajectory starts at 0.104 m/s on slider 0, and the approach must
  arrive at that velocity; 0.15 m/s leaves margin and is 1800 rpm at the 5 mm screw lead.
* 0.5 m/s² (0.05 g): gentle for a patient's foot on the platform, above the benchmark's
  0.29 m/s² peak so the approach can match its acceleration.
* 5 m/s³: the acceleration ramps to its maximum in 0.1 s, a smooth feel; the soft stop from
  0.1 m/s then takes v/a + a/j = 0.3 s over v·T/2 = 15 mm.

Statuses (:class:`ApproachStatus`; negative = error). ``set_target``/``soft_stop``/``reset``
return one instead of raising, so the supervisor can call them inside the cycle; a refused target
changes nothing (a running move continues).

Per-cycle cost: ``update`` ≈ 3-4 µs (ruckig sampling ≈ 0.5 µs plus reading its Python lists);
the cycle after a new target ≈ 10 µs. ``set_target`` (≈ 20 µs: it plans the move twice, once to
check it) is an event, not a per-cycle call. The ruckig binding returns new 3-element Python
lists when its outputs are read; apart from those no object is created per cycle.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from enum import IntEnum

import numpy as np
from ruckig import (ControlInterface, DurationDiscretization, InputParameter, OutputParameter,
                    Result, Ruckig, RuckigError, Synchronization, Trajectory)

from rt.errors import ConfigurationError

N_AXES = 3
# Nominal stroke of the sliders (m), as rt/data/robot_nominal.yaml limits.stroke_m.
STROKE_M = (0.0, 0.40)
DEFAULT_MAX_VELOCITY_M_S = 0.15
DEFAULT_MAX_ACCELERATION_M_S2 = 0.5
DEFAULT_MAX_JERK_M_S3 = 5.0
# Slack on the stroke check (m): ruckig's arithmetic lands on a target exactly at the limit within
# ~1e-15 m; 1e-9 m is far below one encoder count (2e-5 m).
POSITION_SLACK_M = 1e-9


class ApproachStatus(IntEnum):
    """Result of :class:`Approach` calls; negative values are errors."""

    WORKING = 0  # moving; the output is the next sample of the trajectory
    FINISHED = 1  # at the target state (or at rest after a soft stop), holding it
    IDLE = 2  # no move since reset(): holding the reset position, zero velocity
    ERROR_NOT_READY = -1  # reset() was never called (no current state)
    ERROR_INVALID_INPUT = -2  # non-finite value, or not 3 values
    ERROR_OUTSIDE_STROKE = -3  # a target (or reset) position outside [lo, hi]
    ERROR_LIMITS = -4  # target velocity/acceleration beyond the limits (or unreachable state)
    ERROR_OVERSHOOT = -5  # the move would leave the stroke on its way: refused
    ERROR_POSITION_LIMIT = -6  # a produced sample left the stroke: output clamped
    ERROR_RUCKIG = -7  # ruckig failed (should not happen after our checks)


class Mode(IntEnum):
    """What the generator is doing."""

    UNSET = 0
    IDLE = 1
    MOVING = 2
    STOPPING = 3


def _per_axis(value: float | Sequence[float], name: str) -> list[float]:
    values = [float(value)] * N_AXES if np.isscalar(value) else [float(v) for v in value]
    if len(values) != N_AXES or not all(math.isfinite(v) and v > 0.0 for v in values):
        raise ConfigurationError(f"{name} must be a positive finite number or {N_AXES} of them "
                                 f"(got {value!r})")
    return values


def _three(value: float | Sequence[float] | np.ndarray | None) -> list[float] | None:
    """3 finite floats, a scalar broadcast to 3, or None when malformed."""
    if value is None:
        return [0.0] * N_AXES
    try:
        values = ([float(value)] * N_AXES if np.isscalar(value)
                  else [float(v) for v in value])  # type: ignore[union-attr]
    except (TypeError, ValueError):
        return None
    if len(values) != N_AXES or not all(math.isfinite(v) for v in values):
        return None
    return values


class Approach:
    """Jerk-limited three-axis move generator with online retargeting and a soft stop.

    Ports (per cycle): ``update(out_pos, out_vel, out_acc)`` writes the reference position (m),
    velocity (m/s) and acceleration (m/s²) into the caller's preallocated (3,) arrays.

    Commands (events): ``reset(...)`` sets the current state (the measured or last reference
    state); ``set_target(...)`` starts or retargets a move; ``soft_stop()`` brakes to rest.

    Args:
        dt: cycle period (s); ruckig steps exactly this much per ``update``.
        stroke: (lo, hi) slider stroke (m) every target and sample must stay within.
        max_velocity, max_acceleration, max_jerk: limits (m/s, m/s², m/s³), one or per axis.
    """

    def __init__(self, dt: float = 1.0e-3, stroke: tuple[float, float] = STROKE_M,
                 max_velocity: float | Sequence[float] = DEFAULT_MAX_VELOCITY_M_S,
                 max_acceleration: float | Sequence[float] = DEFAULT_MAX_ACCELERATION_M_S2,
                 max_jerk: float | Sequence[float] = DEFAULT_MAX_JERK_M_S3) -> None:
        if not (math.isfinite(dt) and 0.0 < dt <= 0.1):
            raise ConfigurationError(f"dt must be in (0, 0.1] s (got {dt!r})")
        lo, hi = float(stroke[0]), float(stroke[1])
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ConfigurationError(f"stroke must be (lo, hi) with lo < hi (got {stroke!r})")
        self.dt = dt
        self.lo, self.hi = lo, hi
        self.max_velocity = _per_axis(max_velocity, "max_velocity")
        self.max_acceleration = _per_axis(max_acceleration, "max_acceleration")
        self.max_jerk = _per_axis(max_jerk, "max_jerk")

        # Two planners: the one that runs, and one that plans a candidate move so it can be
        # checked (extrema) before the running one is touched.
        self._otg = Ruckig(N_AXES, dt)
        self._inp = InputParameter(N_AXES)
        self._out = OutputParameter(N_AXES)
        self._chk_otg = Ruckig(N_AXES, dt)
        self._chk_inp = InputParameter(N_AXES)
        self._chk_traj = Trajectory(N_AXES)
        for inp in (self._inp, self._chk_inp):
            inp.max_velocity = self.max_velocity
            inp.max_acceleration = self.max_acceleration
            inp.max_jerk = self.max_jerk
            # Moves end on a cycle boundary, so the next phase (playback) starts on the next
            # cycle with no fractional-period seam.
            inp.duration_discretization = DurationDiscretization.Discrete
        self._lo3 = [lo] * N_AXES
        self._hi3 = [hi] * N_AXES
        self.mode = Mode.UNSET
        self.duration = 0.0  # of the current move (s)
        self.last_checked_duration = 0.0  # of the last move planned by a check (s)
        self._hold = [0.0] * N_AXES

    # -- commands --------------------------------------------------------------------------------
    def reset(self, position: Sequence[float] | np.ndarray,
              velocity: Sequence[float] | np.ndarray | None = None,
              acceleration: Sequence[float] | np.ndarray | None = None) -> ApproachStatus:
        """Set the current state (m, m/s, m/s²) and stop any move; the output holds ``position``.

        Call ``set_target`` or ``soft_stop`` next when the state is moving.
        """
        p, v, a = _three(position), _three(velocity), _three(acceleration)
        if p is None or v is None or a is None:
            return ApproachStatus.ERROR_INVALID_INPUT
        if not self._in_stroke(p):
            return ApproachStatus.ERROR_OUTSIDE_STROKE
        self._inp.current_position = p
        self._inp.current_velocity = v
        self._inp.current_acceleration = a
        self._hold = p
        self.mode = Mode.IDLE
        self.duration = 0.0
        return ApproachStatus.IDLE

    def check_move(self, position: Sequence[float] | np.ndarray,
                   velocity: Sequence[float] | np.ndarray | None,
                   acceleration: Sequence[float] | np.ndarray | None,
                   target_position: Sequence[float] | np.ndarray,
                   target_velocity: Sequence[float] | np.ndarray | None = None,
                   target_acceleration: Sequence[float] | np.ndarray | None = None,
                   minimum_duration: float | None = None) -> ApproachStatus:
        """Plan a move between two given states without touching the running one.

        Returns ``WORKING`` when the move is acceptable (or its error status). ``duration``
        of the candidate is in ``last_checked_duration`` (s).
        """
        p, v, a = _three(position), _three(velocity), _three(acceleration)
        if p is None or v is None or a is None:
            return ApproachStatus.ERROR_INVALID_INPUT
        return self._check(p, v, a, target_position, target_velocity, target_acceleration,
                           minimum_duration, ControlInterface.Position)

    def set_target(self, position: Sequence[float] | np.ndarray,
                   velocity: Sequence[float] | np.ndarray | None = None,
                   acceleration: Sequence[float] | np.ndarray | None = None,
                   minimum_duration: float | None = None) -> ApproachStatus:
        """Move (or retarget, continuously from the current reference) to a target state.

        Args:
            position: target positions (m), within the stroke.
            velocity: target velocities (m/s), default 0; |v| ≤ max_velocity.
            acceleration: target accelerations (m/s²), default 0; |a| ≤ max_acceleration.
            minimum_duration: the move takes at least this long (s); None = time-optimal.

        Returns:
            ``WORKING`` if accepted, else an error status and nothing changed.
        """
        if self.mode == Mode.UNSET:
            return ApproachStatus.ERROR_NOT_READY
        inp = self._inp
        status = self._check(inp.current_position, inp.current_velocity,
                             inp.current_acceleration, position, velocity, acceleration,
                             minimum_duration, ControlInterface.Position)
        if status != ApproachStatus.WORKING:
            return status
        chk = self._chk_inp
        inp.control_interface = ControlInterface.Position
        inp.synchronization = Synchronization.Time  # all axes arrive together, on one state
        inp.target_position = chk.target_position
        inp.target_velocity = chk.target_velocity
        inp.target_acceleration = chk.target_acceleration
        inp.minimum_duration = chk.minimum_duration
        self.mode = Mode.MOVING
        self.duration = self.last_checked_duration
        return ApproachStatus.WORKING

    def soft_stop(self) -> ApproachStatus:
        """Brake every axis to rest (velocity 0, acceleration 0) within the jerk limits.

        Each axis stops as fast as it can (no synchronisation: shortest stopping distance). A
        stop is never refused: if braking would carry a slider beyond the stroke the stop still
        runs, this returns ``ERROR_OVERSHOOT`` and ``update`` clamps the samples at the limit
        with ``ERROR_POSITION_LIMIT`` — the supervisor should escalate to a hard stop.
        """
        if self.mode == Mode.UNSET:
            return ApproachStatus.ERROR_NOT_READY
        inp = self._inp
        status = self._check(inp.current_position, inp.current_velocity,
                             inp.current_acceleration, None, None, None, None,
                             ControlInterface.Velocity)
        if status not in (ApproachStatus.WORKING, ApproachStatus.ERROR_OVERSHOOT):
            return status
        inp.control_interface = ControlInterface.Velocity
        inp.synchronization = Synchronization.No
        inp.target_velocity = [0.0] * N_AXES
        inp.target_acceleration = [0.0] * N_AXES
        inp.minimum_duration = None
        self.mode = Mode.STOPPING
        self.duration = self.last_checked_duration
        return status

    # -- the per-cycle call ----------------------------------------------------------------------
    def update(self, out_pos: np.ndarray, out_vel: np.ndarray,
               out_acc: np.ndarray) -> ApproachStatus:
        """Advance one cycle and write the reference into the (3,) output arrays (SI units)."""
        mode = self.mode
        if mode == Mode.UNSET:
            return ApproachStatus.ERROR_NOT_READY
        if mode == Mode.IDLE:
            h = self._hold
            for i in range(N_AXES):
                out_pos[i] = h[i]
                out_vel[i] = 0.0
                out_acc[i] = 0.0
            return ApproachStatus.IDLE
        try:
            result = self._otg.update(self._inp, self._out)
        except RuckigError:
            return ApproachStatus.ERROR_RUCKIG
        if result != Result.Working and result != Result.Finished:
            return ApproachStatus.ERROR_RUCKIG
        out = self._out
        out.pass_to_input(self._inp)
        p = out.new_position
        v = out.new_velocity
        a = out.new_acceleration
        status = ApproachStatus.WORKING if result == Result.Working else ApproachStatus.FINISHED
        lo, hi = self.lo - POSITION_SLACK_M, self.hi + POSITION_SLACK_M
        for i in range(N_AXES):
            pi = p[i]
            if lo <= pi <= hi:
                out_pos[i] = pi
                out_vel[i] = v[i]
                out_acc[i] = a[i]
            else:  # never expected after the extrema check, except in an overshooting stop
                out_pos[i] = self.lo if pi < lo else self.hi
                out_vel[i] = 0.0
                out_acc[i] = 0.0
                status = ApproachStatus.ERROR_POSITION_LIMIT
        return status

    # -- helpers ---------------------------------------------------------------------------------
    def _in_stroke(self, p: Sequence[float]) -> bool:
        lo, hi = self.lo - POSITION_SLACK_M, self.hi + POSITION_SLACK_M
        return all(lo <= x <= hi for x in p)

    def _check(self, p: Sequence[float], v: Sequence[float], a: Sequence[float],
               target_position: Sequence[float] | np.ndarray | None,
               target_velocity: Sequence[float] | np.ndarray | None,
               target_acceleration: Sequence[float] | np.ndarray | None,
               minimum_duration: float | None,
               interface: ControlInterface) -> ApproachStatus:
        """Validate a target and plan the move from (p, v, a) on the checking planner."""
        chk = self._chk_inp
        chk.current_position = list(p)
        chk.current_velocity = list(v)
        chk.current_acceleration = list(a)
        chk.control_interface = interface
        tv, ta = _three(target_velocity), _three(target_acceleration)
        if tv is None or ta is None:
            return ApproachStatus.ERROR_INVALID_INPUT
        if interface == ControlInterface.Position:
            tp = _three(target_position)
            if tp is None or target_position is None:
                return ApproachStatus.ERROR_INVALID_INPUT
            if minimum_duration is not None and not (math.isfinite(minimum_duration)
                                                     and minimum_duration >= 0.0):
                return ApproachStatus.ERROR_INVALID_INPUT
            if not self._in_stroke(tp):
                return ApproachStatus.ERROR_OUTSIDE_STROKE
            for i in range(N_AXES):
                if (abs(tv[i]) > self.max_velocity[i]
                        or abs(ta[i]) > self.max_acceleration[i]):
                    return ApproachStatus.ERROR_LIMITS
            chk.synchronization = Synchronization.Time
            chk.target_position = tp
            chk.minimum_duration = minimum_duration
        else:
            chk.synchronization = Synchronization.No
            chk.minimum_duration = None
        chk.target_velocity = tv
        chk.target_acceleration = ta
        try:
            result = self._chk_otg.calculate(chk, self._chk_traj)
        except RuckigError:
            # e.g. a target velocity+acceleration pair that cannot be held within the limits
            return ApproachStatus.ERROR_LIMITS
        if result != Result.Working:
            return ApproachStatus.ERROR_RUCKIG
        traj = self._chk_traj
        self.last_checked_duration = traj.duration
        lo, hi = self.lo - POSITION_SLACK_M, self.hi + POSITION_SLACK_M
        for ext in traj.position_extrema:
            if ext.min < lo or ext.max > hi:
                return ApproachStatus.ERROR_OVERSHOOT
        return ApproachStatus.WORKING

    @property
    def position_extrema(self) -> list[tuple[float, float]]:
        """(min, max) position per axis (m) of the last planned/checked move."""
        return [(e.min, e.max) for e in self._chk_traj.position_extrema]
