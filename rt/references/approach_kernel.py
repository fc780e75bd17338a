"""The approach's per-cycle sample compiled (issue 16): ruckig's trajectory played by numba.

:class:`rt.references.approach.Approach` plans every move once, with ruckig, when it is
commanded (``set_target``, ``soft_stop``: events, in Python) and copies the planned
trajectory's phases into its state array (``plan``, layout below). Each cycle then evaluates
that trajectory at ruckig's clock exactly as ruckig's own online ``update`` does — the same
clock (``time += dt`` from 0 at the plan), the same phase lookup and the same constant-jerk
integration (ruckig 0.19 ``Trajectory::state_to_integrate_from`` and ``integrate``), operation
for operation — so the samples are ruckig's bit for bit (``tests/test_approach_kernel.py``
drives ruckig's ``Ruckig.update`` beside it on random moves, soft stops and brake
pre-phases). Being numba, the same :func:`update` runs in the interpreted cycle (``Approach.
update``) and in the compiled sequencer (:func:`working_sample`, from
``rt.references.sequencer_kernel.cycle``), so an approach or a return needs no Python per
cycle and both paths are one code.

Position limits stay ours (ruckig's community edition ignores them): every sample is checked
against the stroke; a sample outside it is clamped with ``ERROR_POSITION_LIMIT``.
:func:`working_sample` only ever commits a plain in-stroke sample before the move's end; the
arrival, a clamped sample, a hold to settle are answered "not mine" with nothing written, and
the caller runs :func:`update` (the interpreted cycle) for them.
"""
from __future__ import annotations

import numpy as np
from numba import njit

N_AXES = 3
#: Slack on the stroke check (m): as ``rt.references.approach.POSITION_SLACK_M``.
POSITION_SLACK_M = 1e-9

# ---- Mode values (``rt.references.approach.Mode``)
UNSET, IDLE, MOVING, STOPPING, HOLD = 0.0, 1.0, 2.0, 3.0, 4.0
# ---- ApproachStatus values (``rt.references.approach.ApproachStatus``)
WORKING, FINISHED, ST_IDLE, ERROR_NOT_READY, ERROR_POSITION_LIMIT = 0, 1, 2, -1, -6

# ---- the plan (float64 array)
P_MODE = 0             # Mode
P_TIME = 1             # ruckig's clock: s since the move was planned (+= dt per sample)
P_DURATION = 2         # the move's duration (s)
P_DT = 3               # the cycle period (s)
P_LO, P_HI = 4, 5      # the stroke (m)
P_HOLD_AT_REST = 6     # 1: holding at rest (the hold's v and a already zeroed)
P_HOLD = 7             # 3: the held (last emitted) position (m)
P_CUR = 10             # 9: the current state p, v, a (ruckig's input's current_*)
P_TARGET = 19          # 9: the move's target state p, v, a
P_NEW = 28             # 9: scratch, the sample being evaluated p, v, a
P_PROFILES = 37        # N_AXES × PROFILE_SIZE: each axis' planned phases
# within one axis' profile: ruckig's Profile (7 constant-jerk phases; t_sum is the cumulative
# phase time as ruckig's Profile::check sums it) and its brake pre-phases (BrakeProfile)
PR_BRAKE_DURATION = 0
PR_BRAKE_T, PR_BRAKE_P, PR_BRAKE_V, PR_BRAKE_A, PR_BRAKE_J = 1, 3, 5, 7, 9   # 2 each
PR_T_SUM = 11          # 7
PR_P, PR_V, PR_A = 18, 26, 34                                                # 8 each
PR_J = 42              # 7
PROFILE_SIZE = 49
PLAN_SIZE = P_PROFILES + N_AXES * PROFILE_SIZE


@njit(cache=True, inline="always")
def _integrate_p(t, p0, v0, a0, j):
    # ruckig's integrate(), the same operations in the same order (no FMA: numba does not
    # contract without fastmath, nor does the wheel's C++ on generic x86-64).
    return p0 + t * (v0 + t * (a0 / 2 + t * j / 6))


@njit(cache=True, inline="always")
def _integrate_v(t, v0, a0, j):
    return v0 + t * (a0 + t * j / 2)


@njit(cache=True, inline="always")
def _integrate_a(t, a0, j):
    return a0 + t * j


@njit(cache=True)
def at_time(plan, time, new):
    """The planned move's state at ``time`` (s) into ``new`` (9: p, v, a) as ruckig's
    ``Trajectory::at_time`` computes it (one section: we never use waypoints)."""
    duration = plan[P_DURATION]
    for dof in range(N_AXES):
        b = P_PROFILES + dof * PROFILE_SIZE
        if time >= duration:
            # Past the end: keep constant acceleration from the profile's final state.
            t_diff = time - (plan[b + PR_BRAKE_DURATION] + plan[b + PR_T_SUM + 6])
            p0, v0, a0, j = (plan[b + PR_P + 7], plan[b + PR_V + 7], plan[b + PR_A + 7], 0.0)
        else:
            t_diff = time
            brake = plan[b + PR_BRAKE_DURATION]
            in_brake = False
            if brake > 0.0:
                if t_diff < brake:
                    index = 0 if t_diff < plan[b + PR_BRAKE_T] else 1
                    if index > 0:
                        t_diff -= plan[b + PR_BRAKE_T + index - 1]
                    p0 = plan[b + PR_BRAKE_P + index]
                    v0 = plan[b + PR_BRAKE_V + index]
                    a0 = plan[b + PR_BRAKE_A + index]
                    j = plan[b + PR_BRAKE_J + index]
                    in_brake = True
                else:
                    t_diff -= brake
            if not in_brake:
                t_end = plan[b + PR_T_SUM + 6]
                if t_diff >= t_end:
                    # This axis finished before the others (no synchronisation): keep its
                    # constant acceleration.
                    t_diff = t_diff - t_end
                    p0, v0, a0, j = (plan[b + PR_P + 7], plan[b + PR_V + 7],
                                     plan[b + PR_A + 7], 0.0)
                else:
                    # std::upper_bound: the first phase whose cumulative end is > t_diff.
                    index = 0
                    while index < 7 and not t_diff < plan[b + PR_T_SUM + index]:
                        index += 1
                    if index > 0:
                        t_diff -= plan[b + PR_T_SUM + index - 1]
                    p0 = plan[b + PR_P + index]
                    v0 = plan[b + PR_V + index]
                    a0 = plan[b + PR_A + index]
                    j = plan[b + PR_J + index]
        new[dof] = _integrate_p(t_diff, p0, v0, a0, j)
        new[N_AXES + dof] = _integrate_v(t_diff, v0, a0, j)
        new[2 * N_AXES + dof] = _integrate_a(t_diff, a0, j)


@njit(cache=True, inline="always")
def _arrives(plan, time):
    """Whether the sample at ``time`` ends the move. ruckig reports Finished only once its
    clock has passed the duration, possibly one cycle after the end's sample; a move's
    duration is discretised to the cycle, so its arrival is detected by time (half a period
    early); a soft stop's is not (each axis brakes time-optimally): it has arrived on the
    first sample at or past its end."""
    duration = plan[P_DURATION]
    margin = 0.5 * plan[P_DT] if plan[P_MODE] == MOVING else 1e-9
    return time > duration or time >= duration - margin


@njit(cache=True)
def update(plan, out_pos, out_vel, out_acc):
    """One cycle of ``Approach.update`` (its docstring): the held position, or the move's
    next sample; returns the ApproachStatus value."""
    mode = plan[P_MODE]
    if mode == IDLE or mode == HOLD:
        if plan[P_HOLD_AT_REST] == 0.0:
            for i in range(N_AXES):           # the next move starts from rest here
                plan[P_CUR + N_AXES + i] = 0.0
                plan[P_CUR + 2 * N_AXES + i] = 0.0
            plan[P_HOLD_AT_REST] = 1.0
        for i in range(N_AXES):
            out_pos[i] = plan[P_HOLD + i]
            out_vel[i] = 0.0
            out_acc[i] = 0.0
        return ST_IDLE if mode == IDLE else FINISHED
    if mode == UNSET:
        return ERROR_NOT_READY
    time = plan[P_TIME] + plan[P_DT]
    plan[P_TIME] = time
    new = plan[P_NEW:P_NEW + 3 * N_AXES]
    at_time(plan, time, new)
    for i in range(3 * N_AXES):               # ruckig's pass_to_input: the sample is current
        plan[P_CUR + i] = new[i]
    arrived = _arrives(plan, time)
    src = P_NEW
    if arrived and mode == MOVING:
        src = P_TARGET                        # exactly the target state
    status = FINISHED if arrived else WORKING
    lo, hi = plan[P_LO] - POSITION_SLACK_M, plan[P_HI] + POSITION_SLACK_M
    for i in range(N_AXES):
        pi = plan[src + i]
        if arrived and mode != MOVING:        # stopped: exactly at rest (ruckig leaves
            vi = 0.0                          # ~1e-17 m/s of round-off)
            ai = 0.0
        else:
            vi = plan[src + N_AXES + i]
            ai = plan[src + 2 * N_AXES + i]
        if lo <= pi <= hi:
            out_pos[i] = pi
            out_vel[i] = vi
            out_acc[i] = ai
        else:  # never expected after the extrema check, except in an overshooting stop
            pi = plan[P_LO] if pi < lo else plan[P_HI]
            out_pos[i] = pi
            out_vel[i] = 0.0
            out_acc[i] = 0.0
            status = ERROR_POSITION_LIMIT
        plan[P_HOLD + i] = pi
    if arrived:
        # The next move starts from the state just emitted (continuous retargeting on the
        # FINISHED cycle); from the next held cycle on, from rest at the held position.
        plan[P_MODE] = HOLD
        for i in range(N_AXES):
            plan[P_CUR + i] = plan[P_HOLD + i]
            if status == ERROR_POSITION_LIMIT or mode != MOVING:
                plan[P_CUR + N_AXES + i] = 0.0
                plan[P_CUR + 2 * N_AXES + i] = 0.0
            else:
                plan[P_CUR + N_AXES + i] = plan[P_TARGET + N_AXES + i]
                plan[P_CUR + 2 * N_AXES + i] = plan[P_TARGET + 2 * N_AXES + i]
        plan[P_HOLD_AT_REST] = 0.0
    return status


@njit(cache=True)
def working_sample(plan, out_pos, out_vel, out_acc):
    """The compiled sequencer's approach and return cycles: when this cycle's sample is a
    plain one (moving, not the move's end, inside the stroke) write it as :func:`update`
    would and return True; otherwise return False with nothing written (not even the
    clock): the caller runs :func:`update` for that cycle (the interpreted path)."""
    mode = plan[P_MODE]
    if mode != MOVING and mode != STOPPING:
        return False
    time = plan[P_TIME] + plan[P_DT]
    if _arrives(plan, time):
        return False
    new = plan[P_NEW:P_NEW + 3 * N_AXES]
    at_time(plan, time, new)
    lo, hi = plan[P_LO] - POSITION_SLACK_M, plan[P_HI] + POSITION_SLACK_M
    for i in range(N_AXES):
        if not (lo <= new[i] <= hi):
            return False
    plan[P_TIME] = time
    for i in range(3 * N_AXES):
        plan[P_CUR + i] = new[i]
    for i in range(N_AXES):
        out_pos[i] = new[i]
        out_vel[i] = new[N_AXES + i]
        out_acc[i] = new[2 * N_AXES + i]
        plan[P_HOLD + i] = new[i]
    return True


def warm_up() -> None:
    """Compile (or load from numba's cache) for the argument types the cycle passes (the
    plan and the outputs: writable float64 views), at construction, never in a cycle."""
    plan = np.zeros(PLAN_SIZE)
    out = np.zeros(3)
    update(plan, out, out, out)
    working_sample(plan, out, out, out)
    at_time(plan, 0.0, plan[P_NEW:P_NEW + 9])
