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
is checked again (clamped to the stroke with an error status if it ever leaves it). The extrema
are computed by :func:`trajectory_position_extrema` from ruckig's phase profiles, because ruckig's
own ``position_extrema`` misses some (see there). Intermediate waypoints are never used (they
need ruckig's cloud service and raise).

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

**Planned once, played compiled** (issue 16, approach9). ``set_target``/``soft_stop`` plan the
move with ruckig (``calculate``), check it, and copy its phases into ``plan``; each ``update``
then evaluates them at ruckig's clock with ruckig's arithmetic (:mod:`rt.references.
approach_kernel`, numba: ruckig's online ``update`` bit for bit, ``tests/test_approach_kernel.
py``), so the sequencer's compiled cycle plays an approach or a return without Python. Every
command plans afresh from the current state (ruckig's ``update`` kept its old trajectory when
a command repeated the running input: a stop during a stop arrived early, see that test).

Costs (median, this VM, loaded: ``docs/worklog/2026-11-26f/approach9.md``): ``update`` ≈ 0.9 µs
from Python (the numba call; ≈ 0.1 µs inside the compiled cycle); ``set_target`` ≈ 41 µs
(planning, the extrema, the phases' copy ≈ 11 µs) — an event, not a per-cycle call. No
object is created per cycle.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from enum import IntEnum

import numpy as np
from ruckig import (
    ControlInterface,
    DurationDiscretization,
    InputParameter,
    Result,
    Ruckig,
    RuckigError,
    Synchronization,
    Trajectory,
)

from rt.errors import ConfigurationError
from rt.references import approach_kernel as ak

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

    UNSET = 0  # no current state yet
    IDLE = 1  # holding the reset position
    MOVING = 2  # position interface, towards a target state
    STOPPING = 3  # velocity interface, braking to rest
    HOLD = 4  # arrived (or stopped): holding the final position


def _per_axis(value: float | Sequence[float], name: str) -> list[float]:
    values = ([float(v) for v in value] if isinstance(value, Iterable)
              else [float(value)] * N_AXES)
    if len(values) != N_AXES or not all(math.isfinite(v) and v > 0.0 for v in values):
        raise ConfigurationError(f"{name} must be a positive finite number or {N_AXES} of them "
                                 f"(got {value!r})")
    return values


def _three(value: float | Sequence[float] | np.ndarray | None) -> list[float] | None:
    """3 finite floats, a scalar broadcast to 3, or None when malformed."""
    if value is None:
        return [0.0] * N_AXES
    try:
        values = ([float(v) for v in value] if isinstance(value, Iterable)
                  else [float(value)] * N_AXES)
    except (TypeError, ValueError):
        return None
    if len(values) != N_AXES or not all(math.isfinite(v) for v in values):
        return None
    return values


def _phase_extrema(p0: float, v0: float, a0: float, j: float, t: float,
                   lo: float, hi: float) -> tuple[float, float]:
    """Extend (lo, hi) by the positions of one constant-jerk phase of duration t (s)."""
    def pos(tau: float) -> float:
        return p0 + tau * (v0 + tau * (0.5 * a0 + tau * j / 6.0))

    p_end = pos(t)
    lo, hi = min(lo, p0, p_end), max(hi, p0, p_end)
    # interior extrema where v(τ) = v0 + a0 τ + j τ²/2 = 0
    roots: tuple[float, ...] = ()
    if j != 0.0:
        disc = a0 * a0 - 2.0 * j * v0
        if disc >= 0.0:
            sq = math.sqrt(disc)
            roots = ((-a0 + sq) / j, (-a0 - sq) / j)
    elif a0 != 0.0:
        roots = (-v0 / a0,)
    for tau in roots:
        if 0.0 < tau < t:
            x = pos(tau)
            lo, hi = min(lo, x), max(hi, x)
    return lo, hi


def trajectory_position_extrema(traj: Trajectory) -> list[tuple[float, float]]:
    """(min, max) position (m) per axis of a planned ruckig trajectory, from its profiles.

    ruckig 0.19.4's own ``Trajectory.position_extrema`` misses extrema inside constant-
    acceleration phases (e.g. from 0.0117 m at -0.094 m/s to 0.25 m it reports a minimum of
    +3.2 mm while the trajectory reaches -1.5 mm; ``tests/test_references.py`` keeps that case).
    This integrates each constant-jerk phase (the brake pre-phases, then the seven main ones)
    and checks where the velocity crosses zero. One section only: we never use waypoints.
    """
    out = []
    for prof in traj.profiles[0]:
        brake = prof.brake
        p = prof.p
        lo = hi = p[0]
        if brake.duration > 0.0:
            bp, bv, ba, bj, bt = brake.p, brake.v, brake.a, brake.j, brake.t
            lo = hi = bp[0]
            for k in range(2):
                if bt[k] > 0.0:
                    lo, hi = _phase_extrema(bp[k], bv[k], ba[k], bj[k], bt[k], lo, hi)
        v, a, j, t = prof.v, prof.a, prof.j, prof.t
        for k in range(7):
            if t[k] > 0.0:
                lo, hi = _phase_extrema(p[k], v[k], a[k], j[k], t[k], lo, hi)
        out.append((lo, hi))
    return out


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
                 max_jerk: float | Sequence[float] = DEFAULT_MAX_JERK_M_S3,
                 plan: np.ndarray | None = None) -> None:
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

        # One planner: it plans (and checks) each move when commanded; the cycle plays the
        # planned trajectory from ``plan`` (``rt.references.approach_kernel``: ruckig's own
        # sampling, compiled), so the running move is never touched by a refused candidate.
        self._chk_otg = Ruckig(N_AXES, dt)
        self._chk_inp = InputParameter(N_AXES)
        self._chk_traj = Trajectory(N_AXES)
        inp = self._chk_inp
        inp.max_velocity = self.max_velocity
        inp.max_acceleration = self.max_acceleration
        inp.max_jerk = self.max_jerk
        # Moves end on a cycle boundary, so the next phase (playback) starts on the next
        # cycle with no fractional-period seam (soft stops switch this off).
        inp.duration_discretization = DurationDiscretization.Discrete
        if plan is None:
            plan = np.zeros(ak.PLAN_SIZE)
        if plan.shape != (ak.PLAN_SIZE,) or plan.dtype != np.float64:
            raise ConfigurationError(f"plan must be float64[{ak.PLAN_SIZE}] (got "
                                     f"{plan.dtype}{list(plan.shape)})")
        #: The generator's whole state (``approach_kernel``'s layout): a caller may keep it in
        #: its own array (the sequencer: a view of its state, read by its compiled cycle).
        self.plan = plan
        plan[:] = 0.0
        plan[ak.P_MODE] = float(Mode.UNSET)
        plan[ak.P_DT] = dt
        plan[ak.P_LO], plan[ak.P_HI] = lo, hi
        plan[ak.P_HOLD_AT_REST] = 1.0
        self.last_checked_duration = 0.0  # of the last move planned by a check (s)
        self._extrema: list[tuple[float, float]] = [(lo, lo)] * N_AXES
        ak.warm_up()

    @property
    def mode(self) -> Mode:
        """What the generator is doing."""
        return Mode(int(self.plan[ak.P_MODE]))

    @property
    def duration(self) -> float:
        """Of the current move (s)."""
        return float(self.plan[ak.P_DURATION])

    def _current(self) -> tuple[list[float], list[float], list[float]]:
        """The current state (m, m/s, m/s²): where the next move starts."""
        c = self.plan[ak.P_CUR:ak.P_CUR + 3 * N_AXES].tolist()
        return c[0:3], c[3:6], c[6:9]

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
        plan = self.plan
        plan[ak.P_CUR:ak.P_CUR + 3 * N_AXES] = p + v + a
        plan[ak.P_HOLD:ak.P_HOLD + N_AXES] = p
        plan[ak.P_HOLD_AT_REST] = 0.0
        plan[ak.P_MODE] = float(Mode.IDLE)
        plan[ak.P_DURATION] = 0.0
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
        status = self._check(*self._current(), position, velocity, acceleration,
                             minimum_duration, ControlInterface.Position)
        if status != ApproachStatus.WORKING:
            return status
        chk = self._chk_inp
        self._play(Mode.MOVING, list(chk.target_position) + list(chk.target_velocity)
                   + list(chk.target_acceleration))
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
        status = self._check(*self._current(), None, None, None, None,
                             ControlInterface.Velocity)
        if status not in (ApproachStatus.WORKING, ApproachStatus.ERROR_OVERSHOOT):
            return status
        self._play(Mode.STOPPING, [0.0] * (3 * N_AXES))
        return status

    def _play(self, mode: Mode, target: list[float]) -> None:
        """Run the move just planned by ``_check`` (``_chk_traj``): its phases into the plan,
        ruckig's clock at 0 (as ruckig's ``update`` after it recalculates). ``target``: the
        move's target state (9: p, v, a), written on its arrival."""
        plan = self.plan
        for dof, prof in enumerate(self._chk_traj.profiles[0]):
            brake = prof.brake
            # ruckig's Profile::check: t_sum[0] = t[0], t_sum[i + 1] = t_sum[i] + t[i + 1]
            # (the binding does not expose t_sum; the same sums in the same order).
            t_sum = []
            acc = 0.0
            for i, ti in enumerate(prof.t):
                acc = ti if i == 0 else acc + ti
                t_sum.append(acc)
            # One assignment per axis, in ``approach_kernel``'s PR_* order.
            b = ak.P_PROFILES + dof * ak.PROFILE_SIZE
            plan[b:b + ak.PROFILE_SIZE] = ([brake.duration] + brake.t + brake.p + brake.v
                                           + brake.a + brake.j + t_sum + prof.p + prof.v
                                           + prof.a + prof.j)
        plan[ak.P_TARGET:ak.P_TARGET + 3 * N_AXES] = target
        plan[ak.P_DURATION] = self._chk_traj.duration
        plan[ak.P_TIME] = 0.0
        plan[ak.P_MODE] = float(mode)

    # -- the per-cycle call ----------------------------------------------------------------------
    def update(self, out_pos: np.ndarray, out_vel: np.ndarray,
               out_acc: np.ndarray) -> ApproachStatus:
        """Advance one cycle and write the reference into the (3,) output arrays (SI units).

        Returns ``WORKING`` while moving and ``FINISHED`` on the cycle whose sample is the target
        state (for a move) or rest (for a soft stop), and on every later cycle. After that cycle
        the output holds the final position with zero velocity and acceleration: a caller that
        must continue at a non-zero target velocity takes over on the ``FINISHED`` cycle (as
        ``ReferenceSequence`` does).
        """
        return ApproachStatus(ak.update(self.plan, out_pos, out_vel, out_acc))

    def still_hold(self, out: np.ndarray) -> bool:
        """True when every ``update`` until the next command only writes the held position
        (m) with zero velocity and acceleration (holding at rest, after a reset or an arrival);
        the held position is then written into ``out`` (3,). A compiled caller may then write
        the hold itself instead of calling ``update`` (``rt.references.sequencer_kernel``)."""
        plan = self.plan
        mode = plan[ak.P_MODE]
        if (mode == Mode.IDLE or mode == Mode.HOLD) and plan[ak.P_HOLD_AT_REST] != 0.0:
            out[:3] = plan[ak.P_HOLD:ak.P_HOLD + 3]
            return True
        return False

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
            chk.duration_discretization = DurationDiscretization.Discrete
            chk.target_position = tp
            chk.minimum_duration = minimum_duration
        else:
            # Continuous: with Discrete, ruckig 0.19 synchronises the axes even with
            # Synchronization.No, and the faster axes would brake later than they can.
            chk.synchronization = Synchronization.No
            chk.duration_discretization = DurationDiscretization.Continuous
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
        self._extrema = trajectory_position_extrema(traj)
        lo, hi = self.lo - POSITION_SLACK_M, self.hi + POSITION_SLACK_M
        for p_min, p_max in self._extrema:
            if p_min < lo or p_max > hi:
                return ApproachStatus.ERROR_OVERSHOOT
        return ApproachStatus.WORKING

    @property
    def position_extrema(self) -> list[tuple[float, float]]:
        """(min, max) position per axis (m) of the last planned/checked move."""
        return list(self._extrema)
