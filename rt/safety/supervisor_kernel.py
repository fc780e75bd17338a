"""The supervisor's numeric checks compiled with numba: one call per cycle, no Python objects.

Division follows numpy's error model (no zero check in the cycle): every divisor is a validated
positive physical constant (axis mass, braking deceleration, τ + dt).

The kernel is the compiled twin of the checks in :meth:`rt.safety.supervisor.Supervisor.check`
(the interpreted reference, ``Supervisor(..., compiled=False)``; ``tests/test_supervisor_
compiled.py`` replays recorded cycle streams through both and requires the same events and
outputs). It owns only numbers: which causes are present this cycle and with which reaction
(``react``), the values that tripped them (``vals``), the latched reaction of each cause and
whether a warning was already reported. Naming a cause, building its :class:`SafetyEvent`,
latching it in the ``causes`` dict users read, the e-stop and stop requests of clients, the
heartbeat callable and the reset tickets stay in Python: the kernel returns how many *new*
events the cycle needs, so the steady-state cycle allocates nothing and Python does nothing.

Cause indices follow the order in which the interpreted check tests them, so events of one
cycle are logged in the same order (their ids are what a reset acknowledges).

Buffers (float64, one each so the call takes few arguments; numba's dispatcher pays per array):

* ``par`` — the effective limits and the supervisor's physics (layout ``P_*``), repacked by
  the supervisor whenever one of them is assigned;
* ``mem`` — the running state (``M_*``), the per-cause reaction of this cycle (``M_REACT``),
  the latched reaction and reported flag per cause (``M_LATCHED``, ``M_REPORTED``), the cycle's
  new-event flags (``M_NEW``) and the values per cause (``M_VALS``, ``N_VALUES`` each).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rt.model.rigid_body import STATE_Q, STATE_QD, STATE_ROT, STATE_S, STATE_TWIST

# ------------------------------------------------------------------------- causes
C_ESTOP_HW = 0
C_HAND = 1
C_DRIVE = 2
C_FK = 3
C_JUMP = 4
C_AXIS = 5          # per axis i: C_AXIS + AXIS_SLOTS * i + one of the offsets below
A_FROZEN, A_STROKE, A_MARGIN, A_SPEED, A_ACCEL, A_TRACKING, A_ACTUATOR = range(7)
AXIS_SLOTS = 7
C_ROM_ROLL = C_AXIS + 3 * AXIS_SLOTS          # 26
C_ANG_ROLL = C_ROM_ROLL + 1
C_ROM_PITCH = C_ROM_ROLL + 2
C_ANG_PITCH = C_ROM_ROLL + 3
C_FORCE_SAT = C_ROM_ROLL + 4                  # 30
C_FORCE_STALE = C_FORCE_SAT + 1
C_FORCE_IMPL = C_FORCE_SAT + 2
C_FORCE_LIMIT = C_FORCE_SAT + 3
C_PULL = C_FORCE_SAT + 4
C_DEADLINE = C_FORCE_SAT + 5                  # 35
C_DRIVE_SAT = C_DEADLINE + 1                  # per axis i: C_DRIVE_SAT + i (36-38)
C_PULL_STOP = C_DRIVE_SAT + 3                 # 39: a pull that persists in a stop (an alarm)
C_CONTACT_LOST = C_PULL_STOP + 1              # 40
N_CAUSES = C_CONTACT_LOST + 1
N_VALUES = 3

# Reactions as the kernel's numbers (rt.safety.events.Reaction).
R_NONE, R_WARN, R_SOFT, R_HARD = 0, 1, 2, 3
JUMP_STATUS = -3
CARRY_TAU_S = 0.02
QUASI_STATIC_ACCEL = 0.5
QUASI_STATIC_S = 0.01
FROZEN_COUNTS = 4
FORCE_CUSHION = 0.9
#: The pull check is stall-aware: one cycle adds at most this many loop periods to the pull's
#: duration. A realtime loop's dt after a host stall is the stall (``Loop``: dt = now − prev),
#: while the force port then holds one ATI sample: a 20 ms stall while the sensor reads its
#: noise about 0 N is one sample of pull, not 20 ms of it. A real pull is seen on every cycle
#: (at 1 kHz the 20 ms of ``max_pull_s`` are 20 cycles of ≤ 1.5 periods), so it is counted in
#: full; a pull that spans a stall is judged on the samples seen (its stop late by at most
#: the stall, as every other check of that cycle).
PULL_DT_PERIODS = 2.0
#: The ``pulling`` check's threshold (N): the platform's measured push Fz below it is a pull
#: (the contact is unilateral: any measured pull is the strap's).
PULL_FZ_N = 0.0
#: ``pull_in_stop``: how long a pull may last once a stop is latched before the staff are
#: alarmed (s). The stop's compliant hold (``ProgramReference._yield_step``) ends a pull within
#: ``pull_yield_max_m / pull_yield_speed_m_s`` = 20 mm / 20 mm/s = 1 s of the stop whenever the
#: drives can lift the load (measured 0.26-0.28 s at 565-580 kg); a pull still there after
#: that bound is one the robot cannot end (beyond the drives: the brakes or the saturated
#: drives hold it), so only a person can (support the limb, release the strap).
PULL_IN_STOP_S = 1.0
#: ``contact_lost``: in force control the contact counts as held while the measured push Fz
#: exceeds this (N): above what the ATI reads with nothing on it (its drift bound 4 N plus
#: 6 σ of its 0.25 N noise, 5.5 N; ``rt.ati.twin_sensor``), and on the foot's 1e5 N/m heel pad
#: 0.1 mm of compression, so the height where it was last held is the contact's own.
CONTACT_HELD_N = 10.0
#: ``pull_in_stop``: a reading counts as the strap's pull below this (N): beyond what the ATI
#: reads with nothing on it (CONTACT_HELD_N's bound), so an offset sensor on an empty platform
#: after a lost contact (−3 N: a drift since the tare, within the twin's ±4 N) does not tell the
#: staff to release a strap that pulls nothing. The pulls it exists for are hundreds of N.
PULL_IN_STOP_FZ_N = -CONTACT_HELD_N
#: ``contact_lost``: the contact is lost when, with Fz at or below CONTACT_HELD_N, the sliders'
#: mean position has risen this far (m) above where the contact was last held. The force law
#: rises only while it reads less than it is asked (at F_d ≈ 0, between gait stances, it does
#: not follow a foot up), so a legitimate rise with the contact under 10 N is bounded by: the
#: foot's compression between 10 N and 0 (0.1 mm on its 1e5 N/m heel pad; 5 µm on the
#: 2e6 N/m plate); the sensor's lag (FORCE_LAG_S, 3 ms) at the slider-speed limit (0.2 m/s),
#: 0.6 mm travelled before a re-touch shows; an encoder count (20 µm). A rebound after an
#: impact, an overload's sink and an unloading all move the platform *down*. 1 mm above the
#: last loaded height the foot would be pressed 100 N more (the plate 2 kN): reading under
#: 10 N there, nothing is there. Measured on the twin (200 N hold, the foot removed): the
#: platform is 1 mm up 17 ms after the removal, 6 ms before the slider-speed soft stop, which
#: was the only net before. Caveat: a tilt moves the sliders' mean to second order (0.9 mm
#: at 15°, 3.3 mm at 20° roll and pitch together): only a force entry that tilts far while
#: reading under 10 N and asking more could trip on it (none in the library).
CONTACT_LOST_RISE_M = 0.001
#: The sustained-saturation window is kept as this many buckets of saturated time per axis
#: (a bucketed sliding window: the saturated time of the last ``window`` ± one bucket, 2 % of
#: it; the state is fixed whatever the loop's rate).
SAT_BUCKETS = 50

# ------------------------------------------------------------------------- par layout
(P_STROKE_LO, P_STROKE_HI, P_STROKE_MARGIN, P_MAX_SPEED, P_MAX_ACCEL, P_MAX_COMMAND_V,
 P_MAX_ACTUATOR, P_MAX_TRACKING, P_MAX_FORCE, P_ROLL_MIN, P_ROLL_MAX, P_PITCH_MIN,
 P_PITCH_MAX, P_MAX_ANGULAR, P_ROM_TOL, P_DEADLINE_OVERRUNS, P_FROZEN_S, P_FROZEN_MIN_REF,
 P_MAX_PULL_S, P_PERIOD, P_ALPHA_STOP, P_JERK_TIME, P_AXIS_MASS, P_HOLDING, P_COUNT_M,
 P_CONTACT, P_GRACE, P_FORCE_CONTROL, P_SENSOR_X, P_SENSOR_Y, P_SENSOR_Z, P_FORCE_LAG,
 P_CONTACT_RELEASE, P_APPLIED_MAX, P_SAT_WINDOW, P_SAT_FRACTION) = range(36)
#: Each axis' believed amplifier input offset (V, ``drive.amplifier_offset_v``): 3 slots,
#: subtracted from the commands by :func:`outputs` while the drives are enabled.
P_AMP_OFFSET = 36
PAR_SIZE = P_AMP_OFFSET + 3

# ------------------------------------------------------------------------- mem layout
M_FROZEN_TIME = 0
M_IMPULSE = 3
M_IMPULSE_TIME = 6
M_LAST_Q = 9
M_CARRY = 12
M_OVERRUNS = 15
M_PULL_TIME = 16
M_BRAKES_OPEN_AT = 17
M_REACTION = 18      # the latched reaction (Python's ``Supervisor.reaction``): the outputs' verdict
M_CONTACT_UNTIL = 19  # loop time until which the platform counts as touched (contact hysteresis)
M_SHARE = 20         # last cycle's contact share per axis (N): its rate sizes the sensor-lag allowance
M_SHARE_IN = 23      # this cycle's contact share (N), computed by ``block_cycle`` (scratch)
M_QUIET = 26         # per axis: how long its estimated |q̈| has been quasi-static (s)
M_SAT_K = 29         # the sustained-saturation window's current bucket: floor(t / bucket)
M_SAT_PAST = 30      # per axis: saturated time in the window's completed buckets (s)
M_SAT_PEAK = 33      # per axis: the most saturated time any window held since the reset (s)
M_STOP_SINCE = 36    # since when a soft (or hard) stop is latched (loop time, s; NaN: none)
M_STILL_LO = 37      # per axis: the least load (N) since its count stopped (NaN: moving)
M_STILL_HI = 40      # per axis: the largest load (N) since its count stopped (NaN: moving)
M_PULL_STOP_TIME = 43   # how long the pull has lasted in the stop (s, stall-aware)
M_PULL_STOP_SINCE = 44  # loop time the pull in the stop began (s; NaN: no pull)
M_PULL_STOP_ON = 45     # 1 while the pull_in_stop alarm is raised (the RT status shows it)
M_PULL_STOP_FZ = 46     # the latest valid Fz while the alarm is raised (N)
M_PULL_STOP_END = 47    # this cycle ended the alarm: 1 the pull ended, 2 the stop was reset
M_TOUCH_Z = 48          # force control: the sliders' mean where contact was last held (m; NaN)
M_SAT_BUCKETS = 49   # per axis SAT_BUCKETS buckets of saturated time (s), a ring
M_REACT = M_SAT_BUCKETS + 3 * SAT_BUCKETS
M_LATCHED = M_REACT + N_CAUSES
M_REPORTED = M_LATCHED + N_CAUSES
M_NEW = M_REPORTED + N_CAUSES
M_VALS = M_NEW + N_CAUSES
MEM_SIZE = M_VALS + N_CAUSES * N_VALUES


def new_mem() -> np.ndarray:
    """A fresh running state (as ``Supervisor.reset_state`` leaves it, brakes aside)."""
    mem = np.zeros(MEM_SIZE)
    mem[M_LAST_Q:M_LAST_Q + 3] = math.nan
    mem[M_CARRY:M_CARRY + 3] = math.nan
    mem[M_SHARE:M_SHARE + 3] = math.nan
    mem[M_SAT_K] = math.nan
    mem[M_STOP_SINCE] = math.nan
    mem[M_STILL_LO:M_STILL_LO + 3] = math.nan
    mem[M_STILL_HI:M_STILL_HI + 3] = math.nan
    mem[M_PULL_STOP_SINCE] = math.nan
    mem[M_TOUCH_Z] = math.nan
    return mem


@njit(cache=True, inline="always", error_model="numpy")
def _trip(mem, c, reaction, v0, v1, v2):
    """Cause ``c`` is present with ``reaction``; flags a new event when it needs one (a warning
    not yet reported; a fault above what is latched for it), latching it."""
    mem[M_REACT + c] = reaction
    if reaction == R_WARN:
        if mem[M_REPORTED + c] == 0.0:
            mem[M_REPORTED + c] = 1.0
            mem[M_NEW + c] = 1.0
        else:
            return 0
    elif mem[M_LATCHED + c] < reaction:
        mem[M_LATCHED + c] = reaction
        mem[M_NEW + c] = 1.0
    else:
        return 0
    k = M_VALS + N_VALUES * c
    mem[k] = v0
    mem[k + 1] = v1
    mem[k + 2] = v2
    return 1


@njit(cache=True, error_model="numpy")
def contact_share(stb, wrench, par, out):
    """The contact's share of each actuator force (N): what the drives must supply to hold the
    wrench the ATI measures, ``out = −J_Sᵀ w_S`` (the dynamics' ``τ + J_Sᵀ w_S`` term, the
    statics the force law uses). ``wrench`` is what touches the platform applies to it, at the
    sensor's origin in the sensor frame S (axes parallel to P); it is carried to P's origin and
    the base axes with the state's R_BP, then through the platform twist map (q̇ → v_P, ω, base
    frame). A non-finite wrench (no sensor, a dropout) contributes nothing. Written so the
    interpreted supervisor's ``contact_share.py_func`` gives the same bits."""
    for i in range(3):
        out[i] = 0.0
    for k in range(6):
        if not math.isfinite(wrench[k]):
            return
    r = STATE_ROT
    ox, oy, oz = par[P_SENSOR_X], par[P_SENSOR_Y], par[P_SENSOR_Z]
    fx = stb[r] * wrench[0] + stb[r + 1] * wrench[1] + stb[r + 2] * wrench[2]
    fy = stb[r + 3] * wrench[0] + stb[r + 4] * wrench[1] + stb[r + 5] * wrench[2]
    fz = stb[r + 6] * wrench[0] + stb[r + 7] * wrench[1] + stb[r + 8] * wrench[2]
    mx = stb[r] * wrench[3] + stb[r + 1] * wrench[4] + stb[r + 2] * wrench[5]
    my = stb[r + 3] * wrench[3] + stb[r + 4] * wrench[4] + stb[r + 5] * wrench[5]
    mz = stb[r + 6] * wrench[3] + stb[r + 7] * wrench[4] + stb[r + 8] * wrench[5]
    # The sensor's origin from P's, in the base axes; the moment carried to P: m + r × f.
    rx = stb[r] * ox + stb[r + 1] * oy + stb[r + 2] * oz
    ry = stb[r + 3] * ox + stb[r + 4] * oy + stb[r + 5] * oz
    rz = stb[r + 6] * ox + stb[r + 7] * oy + stb[r + 8] * oz
    mx = mx + (ry * fz - rz * fy)
    my = my + (rz * fx - rx * fz)
    mz = mz + (rx * fy - ry * fx)
    w = STATE_TWIST                     # 6×3, row-major: (v_P, ω) per unit q̇_i
    for i in range(3):
        out[i] = -(stb[w + i] * fx + stb[w + 3 + i] * fy + stb[w + 6 + i] * fz
                   + stb[w + 9 + i] * mx + stb[w + 12 + i] * my + stb[w + 15 + i] * mz)


@njit(cache=True, inline="always", error_model="numpy")
def _carry(par, mem, i, load, dt):
    """Axis ``i``'s carried (static) load follows ``load`` first-order (CARRY_TAU_S) while
    quasi-static, by at most the friction band per CARRY_TAU_S (the interpreted
    ``_track_carry_force``'s arithmetic)."""
    c = mem[M_CARRY + i]
    if math.isnan(c):
        mem[M_CARRY + i] = load
    elif mem[M_QUIET + i] >= QUASI_STATIC_S:
        step = (load - c) * dt / (CARRY_TAU_S + dt)
        cap = par[P_HOLDING] * dt / CARRY_TAU_S
        mem[M_CARRY + i] = c + (cap if step > cap else (-cap if -cap > step else step))  # noqa: FURB136


@njit(cache=True, inline="always", error_model="numpy")
def applied_force(tau, limit):
    """The force a drive applies for the command ``tau`` (N): the command saturated at the
    force of the DAC's command limit, ``limit`` (N; inf: none), as :func:`outputs` saturates
    the volts. Spelled out so a NaN command stays NaN (as the interpreted check's)."""
    return limit if tau > limit else (-limit if -limit > tau else tau)  # noqa: FURB136


@njit(cache=True, inline="always", error_model="numpy")
def _saturation(par, mem, t, dt, tau):
    """The sustained-saturation check (the interpreted ``Supervisor._check_saturation``'s
    arithmetic): each axis' time with its command at the drive's limit (``|τ| ≥``
    ``P_APPLIED_MAX``, the force of the DAC's command limit) in the last ``P_SAT_WINDOW``
    seconds, kept in SAT_BUCKETS buckets of loop time; more than ``P_SAT_FRACTION`` of the
    window → soft stop; so while a soft stop has been latched for a whole window (whatever
    latched it: the window's saturation is then the stop's own, an unstable force law ramping
    its force down goes on shaking) → hard stop. Counted only while the drives are on (not in
    a hard stop). Returns the number of new events."""
    if mem[M_REACTION] < R_SOFT:
        mem[M_STOP_SINCE] = math.nan
    elif math.isnan(mem[M_STOP_SINCE]):
        mem[M_STOP_SINCE] = t
    window = par[P_SAT_WINDOW]
    k = math.floor(t / (window / SAT_BUCKETS))
    kf = float(k)
    last = mem[M_SAT_K]
    if kf != last:
        # Buckets the window left since the last cycle are emptied: all of them after a gap
        # longer than the window, on the first cycle (NaN) or if time went back.
        if kf > last and kf - last < SAT_BUCKETS:
            for j in range(int(last) + 1, k + 1):
                s = j % SAT_BUCKETS
                for i in range(3):
                    mem[M_SAT_BUCKETS + SAT_BUCKETS * i + s] = 0.0
        else:
            for j in range(3 * SAT_BUCKETS):
                mem[M_SAT_BUCKETS + j] = 0.0
        mem[M_SAT_K] = kf
        cur = k % SAT_BUCKETS
        for i in range(3):
            past = 0.0
            for s in range(SAT_BUCKETS):
                if s != cur:
                    past += mem[M_SAT_BUCKETS + SAT_BUCKETS * i + s]
            mem[M_SAT_PAST + i] = past
    cur = k % SAT_BUCKETS
    limit = par[P_APPLIED_MAX]
    drives_on = mem[M_REACTION] < R_HARD
    new = 0
    for i in range(3):
        b = M_SAT_BUCKETS + SAT_BUCKETS * i + cur
        if drives_on and abs(tau[i]) >= limit:
            mem[b] += dt
        saturated = mem[M_SAT_PAST + i] + mem[b]
        mem[M_SAT_PEAK + i] = max(mem[M_SAT_PEAK + i], saturated)
        if saturated > par[P_SAT_FRACTION] * window:
            stopped = t - mem[M_STOP_SINCE] >= window          # NaN (no stop): False
            new += _trip(mem, C_DRIVE_SAT + i, R_HARD if stopped else R_SOFT, saturated,
                         window, limit)
    return new


@njit(cache=True, error_model="numpy")
def check(par, mem, t, dt, q, est_status, qd, qdd, fk_ok, roll, pitch, roll_rate, pitch_rate,
          q_ref, qd_ref, tau, force_n, wrench_stale, wrench_saturated, hw_estop, hand_stop,
          drive_failed, fz_n, share):
    """Every numeric check of one cycle (the interpreted ``Supervisor.check``'s, same order,
    same arithmetic). Writes ``mem``; returns the number of new events (0: nothing for Python
    to do). Units as the interpreted check's: m, m/s, m/s², rad, rad/s, N, s; ``share`` is the
    measured contact's share of each actuator force (:func:`contact_share`, N)."""
    for c in range(N_CAUSES):
        mem[M_REACT + c] = 0.0
        mem[M_NEW + c] = 0.0
    new = 0
    nan = math.nan
    force_control = par[P_FORCE_CONTROL] != 0.0
    # -- stop inputs
    if hw_estop:
        new += _trip(mem, C_ESTOP_HW, R_HARD, nan, nan, nan)
    if hand_stop:
        new += _trip(mem, C_HAND, R_SOFT, nan, nan, nan)
    if drive_failed:
        new += _trip(mem, C_DRIVE, R_HARD, nan, nan, nan)
    # -- sensors and kinematics
    if not fk_ok:
        new += _trip(mem, C_FK, R_HARD, nan, nan, nan)
    if est_status == JUMP_STATUS:
        new += _trip(mem, C_JUMP, R_HARD, q[0], q[1], q[2])
    free = not (force_n > par[P_CONTACT])          # NaN (no sensor) counts as free
    if not free:
        mem[M_CONTACT_UNTIL] = t + par[P_CONTACT_RELEASE]
    # Free for the reference-speed criterion: nothing measured for the release time (contact
    # hysteresis: the sensor's lag and the contact's unloading).
    untouched = free and t >= mem[M_CONTACT_UNTIL]
    # Drives off in a hard stop: no frozen-encoder judgement (as the interpreted check).
    brakes_open = t >= mem[M_BRAKES_OPEN_AT] and mem[M_REACTION] < R_HARD
    for i in range(3):
        qi = q[i]
        base = C_AXIS + AXIS_SLOTS * i
        # The axis' own load: the force its drive applies (the command, saturated at the DAC's
        # limit) less what the measured contact takes of it.
        load = applied_force(tau[i], par[P_APPLIED_MAX]) - share[i]
        # Quasi-static: the estimated acceleration small for QUASI_STATIC_S (the estimate
        # lags, so a brief zero crossing between an acceleration and a braking is not).
        if abs(qdd[i]) <= QUASI_STATIC_ACCEL:
            mem[M_QUIET + i] += dt
        else:
            mem[M_QUIET + i] = 0.0
        last_share = mem[M_SHARE + i]
        if math.isnan(last_share):
            last_share = share[i]
        # The sensor reads the contact late: the true share may be ahead of the measured one by
        # its rate times the sensor's lag (impact onset), which the axis then holds unseen.
        lag_allowance = abs(share[i] - last_share) / dt * par[P_FORCE_LAG]
        mem[M_SHARE + i] = share[i]
        if qi == mem[M_LAST_Q + i] and brakes_open:
            if abs(qd_ref[i]) >= par[P_FROZEN_MIN_REF] and untouched:
                mem[M_FROZEN_TIME + i] += dt
            else:
                mem[M_FROZEN_TIME + i] = 0.0
            carry = mem[M_CARRY + i]
            if math.isnan(carry):
                carry = 0.0
            # The load's range since the count stopped (the interpreted ``_still_range``;
            # spelled out as it is there, so a NaN load gives the same NaN).
            lo = mem[M_STILL_LO + i]
            hi = mem[M_STILL_HI + i]
            if math.isnan(lo):
                lo = load
                hi = load
            else:
                lo = load if load < lo else lo  # noqa: FURB136
                hi = load if load > hi else hi  # noqa: FURB136
            mem[M_STILL_LO + i] = lo
            mem[M_STILL_HI + i] = hi
            # What must move the axis: its load's distance from the carried one, or, if an
            # unmeasured load changed as the count stopped, from every load it held since;
            # the smaller (the interpreted ``_frozen_net_force``).
            off = abs(load - carry)
            spread = hi - load if hi - load > load - lo else load - lo  # noqa: FURB136
            off = off if off < spread else spread  # noqa: FURB136
            net = off - par[P_HOLDING] - lag_allowance
            if net > 0.0:
                mem[M_IMPULSE + i] += net * dt
                mem[M_IMPULSE_TIME + i] += dt
            else:
                mem[M_IMPULSE + i] = 0.0
                mem[M_IMPULSE_TIME + i] = 0.0
            moved = mem[M_IMPULSE + i] * mem[M_IMPULSE_TIME + i] / (2.0 * par[P_AXIS_MASS])
            if moved >= FROZEN_COUNTS * par[P_COUNT_M] or \
                    mem[M_FROZEN_TIME + i] >= par[P_FROZEN_S]:
                new += _trip(mem, base + A_FROZEN, R_HARD, mem[M_FROZEN_TIME + i], moved,
                             qd_ref[i])
        else:
            mem[M_FROZEN_TIME + i] = 0.0
            mem[M_IMPULSE + i] = 0.0
            mem[M_IMPULSE_TIME + i] = 0.0
            mem[M_STILL_LO + i] = nan
            mem[M_STILL_HI + i] = nan
            # The carried load is the static one (what holds the axis once it stops): the
            # inertia's m·q̈ taken out, and learnt only while quasi-static.
            _carry(par, mem, i, load - par[P_AXIS_MASS] * qdd[i], dt)
        mem[M_LAST_Q + i] = qi
        # -- stroke, speed, acceleration, tracking, actuator force
        if qi < par[P_STROKE_LO] or qi > par[P_STROKE_HI]:
            new += _trip(mem, base + A_STROKE, R_HARD, qi, nan, nan)
        elif qi < par[P_STROKE_LO] + par[P_STROKE_MARGIN] or \
                qi > par[P_STROKE_HI] - par[P_STROKE_MARGIN]:
            new += _trip(mem, base + A_MARGIN, R_SOFT, qi, nan, nan)
        if abs(qd[i]) > par[P_MAX_SPEED]:
            new += _trip(mem, base + A_SPEED, R_SOFT, qd[i], nan, nan)
        if abs(qdd[i]) > par[P_MAX_ACCEL]:
            new += _trip(mem, base + A_ACCEL, R_WARN, qdd[i], nan, nan)
        err = 0.0 if force_control else abs(qi - q_ref[i])
        if err > 3.0 * par[P_MAX_TRACKING]:
            new += _trip(mem, base + A_TRACKING, R_HARD, err, nan, nan)
        elif err > par[P_MAX_TRACKING]:
            new += _trip(mem, base + A_TRACKING, R_SOFT, err, nan, nan)
        if abs(tau[i]) > par[P_MAX_ACTUATOR]:
            new += _trip(mem, base + A_ACTUATOR, R_WARN, tau[i], nan, nan)
    # -- patient ROM with the braking cushion, angular speed
    if fk_ok:
        for axis in range(2):
            if axis == 0:
                angle, rate = roll, roll_rate
                lo, hi = par[P_ROLL_MIN], par[P_ROLL_MAX]
                c_rom, c_ang = C_ROM_ROLL, C_ANG_ROLL
            else:
                angle, rate = pitch, pitch_rate
                lo, hi = par[P_PITCH_MIN], par[P_PITCH_MAX]
                c_rom, c_ang = C_ROM_PITCH, C_ANG_PITCH
            w = abs(rate)
            # Supervisor.braking_angle
            braking = 1.25 * (w * (dt + 0.5 * par[P_JERK_TIME])
                              + w * w / (2.0 * par[P_ALPHA_STOP]))
            tol = par[P_ROM_TOL]
            if angle > hi + tol or angle < lo - tol:
                new += _trip(mem, c_rom, R_HARD, angle, nan, nan)
            elif (rate >= 0.0 and angle + braking >= hi) or \
                    (rate <= 0.0 and angle - braking <= lo):
                new += _trip(mem, c_rom, R_SOFT, angle, rate, nan)
            if w > par[P_MAX_ANGULAR]:
                new += _trip(mem, c_ang, R_SOFT, rate, nan, nan)
    # -- force sensor
    if wrench_saturated:
        new += _trip(mem, C_FORCE_SAT, R_SOFT, nan, nan, nan)
    if wrench_stale and t >= par[P_GRACE]:
        new += _trip(mem, C_FORCE_STALE, R_SOFT if force_control else R_WARN, nan, nan, nan)
    elif not wrench_saturated:
        if math.isnan(force_n) and force_control:
            new += _trip(mem, C_FORCE_IMPL, R_SOFT, nan, nan, nan)
        elif force_n > par[P_MAX_FORCE]:
            new += _trip(mem, C_FORCE_LIMIT, R_HARD, force_n, nan, nan)
        elif force_n > FORCE_CUSHION * par[P_MAX_FORCE]:
            new += _trip(mem, C_FORCE_LIMIT, R_SOFT, force_n, nan, nan)
    if force_control and fz_n < PULL_FZ_N:
        # Stall-aware: a cycle adds at most PULL_DT_PERIODS periods (a stall is one sample).
        cap = PULL_DT_PERIODS * par[P_PERIOD]
        mem[M_PULL_TIME] += dt if dt < cap else cap  # noqa: FURB136
        if mem[M_PULL_TIME] >= par[P_MAX_PULL_S]:
            new += _trip(mem, C_PULL, R_SOFT, fz_n, mem[M_PULL_TIME], nan)
    else:
        mem[M_PULL_TIME] = 0.0
    # -- timing
    if dt > 1.5 * par[P_PERIOD]:
        mem[M_OVERRUNS] += 1.0
        if mem[M_OVERRUNS] >= par[P_DEADLINE_OVERRUNS]:
            new += _trip(mem, C_DEADLINE, R_SOFT, mem[M_OVERRUNS], dt, nan)
    else:
        mem[M_OVERRUNS] = 0.0
    # -- sustained drive saturation
    new += _saturation(par, mem, t, dt, tau)
    new += _pull_in_stop(par, mem, t, dt, fz_n, wrench_stale)
    new += _contact_lost(mem, q, force_control, fz_n, wrench_stale, wrench_saturated)
    return new


@njit(cache=True, inline="always", error_model="numpy")
def _pull_in_stop(par, mem, t, dt, fz_n, wrench_stale):
    """The ``pull_in_stop`` alarm (the interpreted ``Supervisor._check_pull_in_stop``'s
    arithmetic): once a stop is latched (soft or hard), a pull (Fz below PULL_IN_STOP_FZ_N) read on
    every sample for PULL_IN_STOP_S (stall-aware, as ``pulling``) raises it once, a warning:
    no escalation, the brakes or the drives already hold, and releasing them would drop the
    platform. It stays raised (``M_PULL_STOP_ON``, the RT status's ``alarms``) until a sample
    reads no pull or the stop is reset, which ends it (``M_PULL_STOP_END``, an event of its
    own). A stale or NaN sample neither counts nor ends it; a saturated one counts (the sensor
    is overloaded: the pull is at least what it reads). Returns the number of new events."""
    mem[M_PULL_STOP_END] = 0.0
    on = mem[M_PULL_STOP_ON] != 0.0
    k = M_VALS + N_VALUES * C_PULL_STOP
    if mem[M_REACTION] < R_SOFT:
        if on:
            # The end's values in the cause's slots: the last pull, since when, how.
            mem[M_PULL_STOP_ON] = 0.0
            mem[M_PULL_STOP_END] = 2.0
            mem[k] = mem[M_PULL_STOP_FZ]
            mem[k + 1] = mem[M_PULL_STOP_SINCE]
            mem[k + 2] = 2.0
        mem[M_PULL_STOP_TIME] = 0.0
        mem[M_PULL_STOP_SINCE] = math.nan
        return 1 if on else 0
    if wrench_stale or math.isnan(fz_n):
        if on:
            mem[M_REACT + C_PULL_STOP] = R_WARN
        return 0
    if not fz_n < PULL_IN_STOP_FZ_N:
        if on:
            mem[M_PULL_STOP_ON] = 0.0
            mem[M_PULL_STOP_END] = 1.0
            mem[M_PULL_STOP_FZ] = fz_n
            mem[k] = fz_n
            mem[k + 1] = mem[M_PULL_STOP_SINCE]
            mem[k + 2] = 1.0
        mem[M_PULL_STOP_TIME] = 0.0
        mem[M_PULL_STOP_SINCE] = math.nan
        return 1 if on else 0
    if math.isnan(mem[M_PULL_STOP_SINCE]):
        mem[M_PULL_STOP_SINCE] = t
    cap = PULL_DT_PERIODS * par[P_PERIOD]
    mem[M_PULL_STOP_TIME] += dt if dt < cap else cap  # noqa: FURB136
    if on:
        mem[M_REACT + C_PULL_STOP] = R_WARN
        mem[M_PULL_STOP_FZ] = fz_n
        return 0
    if mem[M_PULL_STOP_TIME] >= PULL_IN_STOP_S:
        mem[M_REACT + C_PULL_STOP] = R_WARN
        mem[M_PULL_STOP_ON] = 1.0
        mem[M_PULL_STOP_FZ] = fz_n
        mem[M_NEW + C_PULL_STOP] = 1.0
        mem[k] = fz_n
        mem[k + 1] = mem[M_PULL_STOP_SINCE]
        mem[k + 2] = mem[M_PULL_STOP_TIME]
        return 1
    return 0


@njit(cache=True, inline="always", error_model="numpy")
def _contact_lost(mem, q, force_control, fz_n, wrench_stale, wrench_saturated):
    """The ``contact_lost`` soft stop (the interpreted ``Supervisor._check_contact_lost``'s
    arithmetic): in force control, the sliders' mean position where the contact was last held
    (a valid Fz above CONTACT_HELD_N) is remembered; a valid Fz at or below it with the mean
    risen more than CONTACT_LOST_RISE_M above that height means the foot or the plate went
    away while the force law searches upwards for it. Forgotten outside force control (each
    entry arms it at its own first contact). An invalid sample judges nothing (the sensor's
    own checks name it). Returns the number of new events."""
    if not force_control:
        mem[M_TOUCH_Z] = math.nan
        return 0
    if wrench_stale or wrench_saturated or math.isnan(fz_n):
        return 0
    h = (q[0] + q[1] + q[2]) / 3.0
    if fz_n > CONTACT_HELD_N:
        mem[M_TOUCH_Z] = h
        return 0
    rise = h - mem[M_TOUCH_Z]                        # NaN (never held): no trip
    if rise > CONTACT_LOST_RISE_M:
        return _trip(mem, C_CONTACT_LOST, R_SOFT, fz_n, rise, mem[M_TOUCH_Z])
    return 0


@njit(cache=True, error_model="numpy")
def outputs(par, reaction, tau, volts_per_n, volts, enable, mode):
    """The supervisor block's outputs for a latched ``reaction``: hard stop → 0 V, drives
    disabled; otherwise τ (N) times ``volts_per_n`` less the axis' believed amplifier offset
    (``par[P_AMP_OFFSET + i]``, V) saturated at ± max_command_v, drives enabled, the mode
    (:class:`SupervisorMode` value: soft stop 2, else run 0).

    The offset compensation. An amplifier adds its input offset o to every command while the
    drives are enabled, so it delivers (V + o) × force per volt: writing V = τ·k − o makes
    it deliver the commanded τ. Only while enabled: a hard stop writes exactly 0 V (the DAC
    refuses a non-zero command on disabled drives, and a disabled amplifier adds nothing).
    The clamp is on the written volts: ``max_command_v`` bounds what reaches the DAC (the
    driver clamps there too), so the compensation never writes beyond it. Every check stays
    on the commanded force τ (``check``: actuator force, sustained saturation at
    ``P_APPLIED_MAX`` = max_command_v / k, the frozen-encoder force balance): compensated,
    the force the drive applies *is* τ (up to the clamp, which moves by o/k — 5 N of 2 kN
    at the twin's 15 mV — so a check on the volts would only put the offset back into the
    supervisor's physics). With zero offsets x − 0.0 is x, bit for bit (−0.0 and NaN too)."""
    if reaction >= R_HARD:
        volts[0] = 0.0
        volts[1] = 0.0
        volts[2] = 0.0
        enable[0] = 0.0
        mode[0] = float(R_HARD)
        return
    limit = par[P_MAX_COMMAND_V]
    for i in range(3):
        x = tau[i] * volts_per_n - par[P_AMP_OFFSET + i]
        # Spelled out as Python's max(x, -limit) behaves (numba's max may differ on NaN): a
        # NaN command stays NaN (the drive refuses it).
        volts[i] = limit if x > limit else (-limit if -limit > x else x)  # noqa: FURB136
    enable[0] = 1.0
    mode[0] = float(R_SOFT) if reaction == R_SOFT else 0.0


@njit(cache=True, error_model="numpy")
def block_cycle(par, mem, t, dt, q, est_status, qd, qdd, stb, fk_ok_in, filled, q_ref, qd_ref,
                tau, wrench, wrench_flags, inputs, drive_failed, volts_per_n, volts, enable, mode):
    """The supervisor block's whole cycle on its port buffers: the pose and its rates from the
    model state (``State.buf``: Q[11] roll, Q[10] pitch, rates through S), the force's
    magnitude and the platform's push, every check, then the outputs for the latched reaction
    in ``mem[M_REACTION]``. Returns the number of new events (Python then names and logs them
    and recomputes the outputs if the latched reaction changed)."""
    fk_ok = fk_ok_in[0] > 0.5 and filled
    roll = 0.0
    pitch = 0.0
    roll_rate = 0.0
    pitch_rate = 0.0
    if fk_ok:
        roll = stb[STATE_Q + 11]              # Q: ..., yaw, pitch, roll
        pitch = stb[STATE_Q + 10]
        s = STATE_S                           # S (12×3), row-major
        v = STATE_QD
        roll_rate = stb[s + 33] * stb[v] + stb[s + 34] * stb[v + 1] + stb[s + 35] * stb[v + 2]
        pitch_rate = stb[s + 30] * stb[v] + stb[s + 31] * stb[v + 1] + stb[s + 32] * stb[v + 2]
    force = math.sqrt(wrench[0] * wrench[0] + wrench[1] * wrench[1] + wrench[2] * wrench[2])
    # The force at the DAC's command limit: what a saturated drive applies (the balance's τ).
    par[P_APPLIED_MAX] = par[P_MAX_COMMAND_V] / volts_per_n
    share = mem[M_SHARE_IN:M_SHARE_IN + 3]        # a view: nothing allocated
    if fk_ok:                              # the twist map and R_BP are this cycle's
        contact_share(stb, wrench, par, share)
    else:
        share[:] = 0.0
    new = check(par, mem, t, dt, q, int(est_status[0]), qd, qdd, fk_ok, roll, pitch, roll_rate,
                pitch_rate, q_ref, qd_ref, tau, force, wrench_flags[0] > 0.5,
                wrench_flags[1] > 0.5, inputs[0] > 0.5, inputs[1] > 0.5, drive_failed[0] > 0.5,
                -wrench[2], share)
    outputs(par, int(mem[M_REACTION]), tau, volts_per_n, volts, enable, mode)
    return new


_warm = False


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels now, never in a cycle: for the array
    flavours they meet — the block's inputs are read-only port views, its outputs, the model
    state and the supervisor's own buffers writable; ``Supervisor.check`` passes fresh arrays."""
    global _warm
    if _warm:
        return
    from rt.model.rigid_body import STATE_SIZE

    par = np.ones(PAR_SIZE)
    mem = new_mem()

    def ro(n: int) -> np.ndarray:
        a = np.zeros(n)
        a.flags.writeable = False
        return a

    z3 = np.zeros(3)
    check(par, mem, 0.0, 1e-3, z3, 0, z3, z3, True, 0.0, 0.0, 0.0, 0.0, z3, z3, z3, 0.0, False,
          False, False, False, False, 0.0, z3)
    contact_share(np.zeros(STATE_SIZE), ro(6), par, np.zeros(3))
    block_cycle(par, new_mem(), 0.0, 1e-3, ro(3), ro(1), ro(3), ro(3), np.zeros(STATE_SIZE),
                ro(1), True, ro(3), ro(3), ro(3), ro(6), ro(2), ro(2), ro(1), 1.0, np.zeros(3),
                np.zeros(1), np.zeros(1))
    outputs(par, 0, ro(3), 1.0, np.zeros(3), np.zeros(1), np.zeros(1))
    _warm = True
