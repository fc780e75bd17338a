"""The sequencer's steady cycle compiled (issue 16): one numba call per cycle.

:class:`rt.references.sequencer.ProgramReference` keeps its state in one float64 array
(``seq``, layout below) and its outputs in one arena (``io``: its ports are views of it), so
a cycle is ``cycle(io, seq, q_meas, mode, table, dt)``. The kernel runs every *steady*
cycle — a table program playing (the sample's row, the force reference and its smoothed F̈,
the progress), a hold at rest, a hard stop following the measured position — and answers
:data:`NEED_PYTHON` without writing anything when the cycle is an event: the supervisor's
mode changed this cycle, a program is requested or aborted, an approach, a return or a brake
is planned, arrives or leaves the stroke (each move is planned once with ruckig, in Python;
its plain samples are played here: ``rt.references.approach_kernel``), a tare asked for,
granted or refused, a force ramp's end, an exhausted compliant hold, the PLAY of a force
program read ahead by the program's own Python (``force_preview``).
The interpreted sequencer then runs that cycle exactly as it always did; its PLAY step goes
through :func:`play_table` / :func:`emit` too, so a program's samples are produced by one
code path whichever side runs the cycle. So do the force program's tare wait
(:func:`tare_progress`), the force reference's ramp-down (:func:`ramp_force`) and a
force-control soft stop's compliant hold (:func:`yield_step`, on the wrench and its flags):
the interpreted sequencer calls the same functions (hold9). A table program's last sample answers
:data:`PLAY_DONE`: Python plans the return (ruckig) on that same cycle.

Every operation is the interpreted sequencer's, in its order (``tests/test_compiled_cycle.py``
replays recorded inputs through both and compares every output bit for bit).

``cycle(io, seq, q_meas, mode, table, dt, wrench, flags, tare)``: ``wrench`` (6, N and N·m,
sensor frame), ``flags`` (the force reader's [stale, saturated]; empty: unbound, always valid)
and ``tare`` (the force reader's tare port: state, count, refusal, mean; empty: unbound, a
tare wait is then Python's) are the sequencer's input ports.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rt.references import approach_kernel as ak
from rt.references.program import FZ, FZ_DOT, N_FIELDS, POSE
from rt.safety.supervisor_kernel import CONTACT_HELD_N

#: First-order smoothing of F̈_d per cycle (≈ 35 Hz at 1 kHz).
F_DDOT_SMOOTHING = 0.2

# ---- the outputs' arena (ProgramReference's ports are views of it)
IO_Q, IO_QD, IO_QDD, IO_FORCE, IO_POSE = 0, 3, 6, 9, 12
IO_CTRL_MODE, IO_PHASE, IO_PROGRESS, IO_TARE_REQUEST = 15, 16, 17, 18
IO_FORCE_PREVIEW = 19  # 3: the force reference read ahead (= the force without a preview)
IO_SIZE = 22

# ---- the sequencer's state (``seq``)
S_PHASE = 0            # Phase
S_MODE = 1             # SupervisorMode last seen
S_STARTED = 2          # 1 once the first cycle ran
S_K = 3                # samples played of the current program
S_TARING = 4           # holding at the first sample while the sensor is tared
S_TARE_MEASURING = 5   # the force reader has started this tare
S_TARES_BEFORE = 6     # the force reader's tare count when the tare began
S_N = 7                # the program's length in cycles (progress = k / n)
S_HOLDING = 8          # 1 while the approach holds still at rest (its output is S_HOLD)
S_HOLD = 9             # 3: where it holds (m)
S_TABLE = 12           # 1 while the current program plays from a table
S_COL0 = 13            # first column of a ReferenceOutput row the table's columns fill
S_PROGRAM_MODE = 14    # the table program's Mode (0 position, 1 force)
S_LAST = 15            # the table's last sample index
S_CONST = 16           # N_FIELDS: the row's columns outside the table's
S_ROW = S_CONST + N_FIELDS   # N_FIELDS: scratch, the row of this cycle's sample
S_PREVIEW = S_ROW + N_FIELDS  # 1 while the program is a ForcePreview read ahead (preview
                              # steps > 0): its PLAY cycles are Python's unless S_AHEAD
S_AHEAD = S_PREVIEW + 1       # 1: the read-ahead is the table's (``read_ahead``), compiled
S_AHEAD_STEPS = S_AHEAD + 1   # how far ahead (samples)
S_YIELD = S_AHEAD_STEPS + 1   # 1 while a force-control soft stop's hold yields to a pull
                              # (``ProgramReference._yield_step``: Python's, on the wrench)
S_PLAN = S_YIELD + 1          # ak.PLAN_SIZE: the approach's state (``Approach.plan``, a view:
                              # the move it plays, ``approach_kernel``'s layout)
S_Y = S_PLAN + ak.PLAN_SIZE   # YIELD_SIZE: the compliant hold's state and settings (``Y_*``);
                              # after the plan: a new start does not zero it (the last stop's
                              # figures stay readable, as the Python attributes did)
# within S_Y: how far the current (or last) stop's hold rose (m), its reference rose last
# cycle, a pull beyond YIELD_START_PULL_N was seen, the yield ended with the pull still there;
# the settings: speed (m/s), distance (m), the top (m), the lead on a measured slider (m);
# then the force reference's ramp-down time constant (s).
(Y_YIELDED, Y_STEPPED, Y_PULLED, Y_EXHAUSTED, Y_SPEED, Y_MAX, Y_TOP, Y_LEAD,
 Y_RAMP_S, YIELD_SIZE) = range(10)
SEQ_SIZE = S_Y + YIELD_SIZE

#: The compliant hold starts rising only on a pull beyond this (N): what the force sensor reads
#: with nothing on it (the supervisor's CONTACT_HELD_N, 10 N). After a lost contact an offset
#: sensor (−3 N, a drift since the tare) otherwise raised the platform its whole 20 mm towards
#: where the foot had been (watch9, 2026-11-26f). Once a real pull started it, it yields to any
#: pull (push < 0 N) for the rest of the stop, so the foot still ends unpulled.
YIELD_START_PULL_N = CONTACT_HELD_N

# ``rt.components.tare.TareState`` values, and :func:`tare_progress`'s answers.
TARE_MEASURING, TARE_DONE, TARE_REFUSED = 1, 2, 3
TARE_WAIT, TARE_GRANTED, TARE_DENIED = 0, 1, 2
#: :func:`yield_step`'s answers: the hold's cycle written; or the yield is exhausted with the
#: pull still there, nothing written (Python ends it: ``ProgramReference._yield_step``).
YIELD_DONE, YIELD_EXHAUSTED = 0, 1

#: Half-width (samples) of the centred difference that gives the previewed F̈_d: the table is
#: known on both sides of the sample read ahead, so the derivative is smoothed without lag
#: (a recorded gait force's 1 kHz noise through a one-sample difference asks metres per
#: second squared of the platform; ±5 samples at 1 kHz: first zero at 100 Hz).
PREVIEW_F_DDOT_HALF_WIDTH = 5

# Phase and SupervisorMode values (rt.references.sequencer.Phase, rt.safety.events).
APPROACH, PLAY, RETURN, STOPPED, REST = 0.0, 1.0, 2.0, 3.0, 4.0
RUN, SOFT_STOP, HARD_STOP = 0.0, 2.0, 3.0

#: ``cycle`` results: the cycle is done; or nothing was written and Python runs the cycle;
#: or a table program wrote its last sample and Python ends it (the return's planning).
DONE, NEED_PYTHON, PLAY_DONE = 0, 1, 2


@njit(cache=True)
def emit(io, seq, row, mode, dt):
    """A PLAY cycle's outputs from the program's sample ``row`` (a ``ReferenceOutput.buf``) in
    ``mode`` (0 position, 1 force): the sample count, q, q̇, q̈, pose, the control mode and the
    force reference (F_d, Ḟ_d, and F̈_d as a low-passed first difference of Ḟ_d: only the
    small inertia feedforward uses it, and recorded gait forces are not smooth to second
    order)."""
    k = seq[S_K] + 1.0
    seq[S_K] = k
    for i in range(9):
        io[IO_Q + i] = row[i]
    for i in range(3):
        io[IO_POSE + i] = row[POSE.start + i]
    io[IO_CTRL_MODE] = mode
    fz = row[FZ]
    if mode == 1.0 and not math.isnan(fz):
        f_dot = row[FZ_DOT]
        raw = (f_dot - io[IO_FORCE + 1]) / dt if k > 1.0 else 0.0
        io[IO_FORCE + 2] += F_DDOT_SMOOTHING * (raw - io[IO_FORCE + 2])
        io[IO_FORCE] = fz
        io[IO_FORCE + 1] = f_dot
    else:
        io[IO_FORCE] = 0.0
        io[IO_FORCE + 1] = 0.0
        io[IO_FORCE + 2] = 0.0


@njit(cache=True)
def play_table(io, seq, table, dt):
    """Play the table program's next sample (its row over the program's constant columns, as
    ``protocols.base.TableGenerator.update`` writes it) and emit it; returns 1 on the last
    sample (the program is done), else 0."""
    k = int(seq[S_K])
    last = int(seq[S_LAST])
    k = min(k, last)
    for i in range(N_FIELDS):
        seq[S_ROW + i] = seq[S_CONST + i]
    col0 = int(seq[S_COL0])
    for j in range(table.shape[1]):
        seq[S_ROW + col0 + j] = table[k, j]
    emit(io, seq, seq[S_ROW:S_ROW + N_FIELDS], seq[S_PROGRAM_MODE], dt)
    return 1 if k >= last else 0


@njit(cache=True)
def read_ahead(io, seq, table, index, dt):
    """``force_preview`` = the program's force ``S_AHEAD_STEPS`` samples after ``index`` (the
    sample just played), read from its table as ``ForcePreview.force_at`` reads it (the index
    clamped to the table) with F̈_d the centred difference of Ḟ_d over ±
    :data:`PREVIEW_F_DDOT_HALF_WIDTH` samples (``ProgramReference._read_ahead``, the
    interpreted reference: the same operations)."""
    k = index + int(seq[S_AHEAD_STEPS])
    h = PREVIEW_F_DDOT_HALF_WIDTH
    last = int(seq[S_LAST])
    c = FZ - int(seq[S_COL0])
    f_dot_next = table[min(max(k + h, 0), last), c + 1]
    f_dot_prev = table[min(max(k - h, 0), last), c + 1]
    ka = min(max(k, 0), last)
    io[IO_FORCE_PREVIEW] = table[ka, c]
    io[IO_FORCE_PREVIEW + 1] = table[ka, c + 1]
    io[IO_FORCE_PREVIEW + 2] = (f_dot_next - f_dot_prev) / (2.0 * h * dt)


@njit(cache=True)
def finish(io, seq, emitted, ahead=False):
    """Every cycle's last outputs: no tare request outside APPROACH (a stop or an abort ends a
    tare in progress), the force preview (the force itself: the compiled cycle never reads
    ahead, a previewed program's PLAY is Python's, or ``ahead``: :func:`read_ahead` wrote it),
    the phase (the one that produced this
    cycle's reference while approaching or playing) and the progress."""
    phase = seq[S_PHASE]
    if phase != APPROACH:
        io[IO_TARE_REQUEST] = 0.0
    if not ahead:
        for i in range(3):
            io[IO_FORCE_PREVIEW + i] = io[IO_FORCE + i]
    io[IO_PHASE] = emitted if (emitted == APPROACH or emitted == PLAY) else phase
    p = seq[S_K] / seq[S_N]
    io[IO_PROGRESS] = min(1.0, p)


@njit(cache=True)
def tare_progress(tare, measuring, before):
    """Where the force program's tare wait stands, on a cycle after the one that asked for
    the tare (``ProgramReference._tare_step``): ``tare`` the force reader's tare port (state,
    count, ...), ``measuring`` whether the reader has started this tare, ``before`` its tare
    count when the tare was asked for. Returns (TARE_WAIT, TARE_GRANTED or TARE_DENIED, the
    new ``measuring``); writes nothing."""
    state = int(tare[0])
    if state == TARE_MEASURING:
        measuring = True
    if not measuring:                  # the port still shows an earlier tare's outcome
        return TARE_WAIT, measuring
    if state == TARE_DONE and tare[1] > before:
        return TARE_GRANTED, measuring
    if state == TARE_REFUSED:
        return TARE_DENIED, measuring
    return TARE_WAIT, measuring


@njit(cache=True)
def ramp_force(io, ramp_s, dt):
    """One cycle of the force reference's ramp-down in force mode (RETURN, STOPPED, REST:
    ``ProgramReference._ramp_force``): F_d decays with time constant ``ramp_s`` (s), zero at
    or below 1 N; Ḟ_d = F̈_d = 0. Returns True when F_d reaches zero: the caller then leaves
    force control (``_hold_here``, Python: it re-plans the approach) — a compiled caller
    checks :func:`ramp_ends` first and writes nothing on that cycle."""
    f0 = io[IO_FORCE]
    io[IO_FORCE] = max(0.0, f0 - (abs(f0) + 1.0) * dt / ramp_s) if f0 > 1.0 else 0.0
    io[IO_FORCE + 1] = 0.0
    io[IO_FORCE + 2] = 0.0
    return io[IO_FORCE] == 0.0


@njit(cache=True)
def ramp_ends(io, ramp_s, dt):
    """Whether this cycle's :func:`ramp_force` brings F_d to zero (nothing written)."""
    f0 = io[IO_FORCE]
    return (max(0.0, f0 - (abs(f0) + 1.0) * dt / ramp_s) if f0 > 1.0 else 0.0) == 0.0


@njit(cache=True)
def _max_nan(x):
    """``x.max()`` as numpy gives it (a NaN anywhere: NaN), without allocating."""
    m = x[0]
    for i in range(x.shape[0]):
        if math.isnan(x[i]):
            return x[i]
        m = max(m, x[i])
    return m


@njit(cache=True)
def yield_step(io, ys, q_meas, wrench, flags, dt):
    """One cycle of a force-control soft stop's compliant hold (``ProgramReference.
    _yield_step`` documents it: the behaviour, the limits and why), on the reference's arena
    ``io``, the hold's state and settings ``ys`` (``seq[S_Y:]``, ``Y_*``), the measured
    sliders, the wrench and its flags (empty: always valid). Returns YIELD_DONE, or
    YIELD_EXHAUSTED with nothing written: the room is used up with the pull still there
    (the caller ends the yield)."""
    push = -wrench[2]
    if flags.shape[0] >= 2 and (flags[0] > 0.5 or flags[1] > 0.5):
        push = math.nan              # a stale or saturated sensor moves nothing
    pulled = ys[Y_PULLED] != 0.0 or push < -YIELD_START_PULL_N
    q = io[IO_Q:IO_Q + 3]
    room = 0.0
    if push < 0.0 and pulled:
        room = min(ys[Y_MAX] - ys[Y_YIELDED], ys[Y_TOP] - _max_nan(q))
        if not room > 0.0:
            return YIELD_EXHAUSTED
    stepped = ys[Y_STEPPED] != 0.0
    ys[Y_STEPPED] = 0.0
    ys[Y_PULLED] = 1.0 if pulled else 0.0
    for i in range(3):
        io[IO_QDD + i] = 0.0
    if push < 0.0 and pulled:
        lead = q[0] - q_meas[0]
        for i in range(1, 3):
            d = q[i] - q_meas[i]
            if math.isnan(d) or math.isnan(lead):
                lead = math.nan
            elif d > lead:
                lead = d
        if not lead < ys[Y_LEAD]:
            # The platform does not follow (the drives at their limit under a load they
            # cannot lift): wait for it rather than run away into the tracking hard stop.
            for i in range(3):
                io[IO_QD + i] = 0.0
            return YIELD_DONE
        step = ys[Y_SPEED] * dt
        d = step if step < room else room  # noqa: FURB136 (as the interpreted hold wrote it)
        # The rise's speed as the law's feedforward once it goes on, not on its first step
        # (a single noise sample must not kick the drives through the law's damping).
        v = d / dt if stepped else 0.0
        for i in range(3):
            q[i] += d
            io[IO_QD + i] = v
        ys[Y_YIELDED] += d
        ys[Y_STEPPED] = 1.0
        return YIELD_DONE
    for i in range(3):
        io[IO_QD + i] = 0.0
    return YIELD_DONE


@njit(cache=True)
def cycle(io, seq, q_meas, mode, table, dt, wrench, flags, tare):
    """One steady cycle (module docstring); ``mode`` the supervisor's mode port (one cycle
    late). Returns DONE, NEED_PYTHON (nothing written) or PLAY_DONE."""
    if seq[S_STARTED] == 0.0 or mode[0] != seq[S_MODE]:
        return NEED_PYTHON
    phase = seq[S_PHASE]
    result = DONE
    ahead = False
    if mode[0] == HARD_STOP:
        for i in range(3):
            io[IO_Q + i] = q_meas[i]
            io[IO_QD + i] = 0.0
            io[IO_QDD + i] = 0.0
            io[IO_FORCE + i] = 0.0
        io[IO_CTRL_MODE] = 0.0
    elif seq[S_YIELD] != 0.0:
        # A force-control soft stop's compliant hold; its end (exhausted) is Python's.
        if wrench.shape[0] < 3 or yield_step(io, seq[S_Y:S_Y + YIELD_SIZE], q_meas, wrench,
                                             flags, dt) != YIELD_DONE:
            return NEED_PYTHON
    elif phase == STOPPED or phase == REST or phase == RETURN:
        # The approach holds still (its update writes the hold) or plays a move's plain
        # sample (a brake, the return), and a force reference ramps down; the ramp's end is
        # Python's (it re-plans the approach), and so are the move's arrival (RETURN ends at
        # rest) and a sample outside the stroke.
        ramping = io[IO_CTRL_MODE] > 0.5
        if ramping and ramp_ends(io, seq[S_Y + Y_RAMP_S], dt):
            return NEED_PYTHON
        # (RETURN's hold is its arrival, Python's, unless the force still ramps down: RETURN
        # then ends with the ramp.)
        if seq[S_HOLDING] != 0.0 and (phase != RETURN or ramping):
            for i in range(3):
                io[IO_Q + i] = seq[S_HOLD + i]
                io[IO_QD + i] = 0.0
                io[IO_QDD + i] = 0.0
        elif not ak.working_sample(seq[S_PLAN:S_PLAN + ak.PLAN_SIZE], io[IO_Q:IO_Q + 3],
                                   io[IO_QD:IO_QD + 3], io[IO_QDD:IO_QDD + 3]):
            return NEED_PYTHON
        if ramping:
            ramp_force(io, seq[S_Y + Y_RAMP_S], dt)
    elif phase == APPROACH:
        if seq[S_TARING] != 0.0:
            # A force program's first sample held while the force reader tares: its wait
            # (the approach's hold, tare_progress); the tare's outcome is Python's.
            if tare.shape[0] < 2 or seq[S_PLAN + ak.P_MODE] != ak.HOLD:
                return NEED_PYTHON
            answer, measuring = tare_progress(tare, seq[S_TARE_MEASURING] != 0.0,
                                              seq[S_TARES_BEFORE])
            if answer != TARE_WAIT:
                return NEED_PYTHON
            ak.update(seq[S_PLAN:S_PLAN + ak.PLAN_SIZE], io[IO_Q:IO_Q + 3],
                      io[IO_QD:IO_QD + 3], io[IO_QDD:IO_QDD + 3])
            seq[S_TARE_MEASURING] = 1.0 if measuring else 0.0
        # The approach's plain samples; its arrival (the program's first sample, a tare
        # asked for) is Python's.
        elif not ak.working_sample(seq[S_PLAN:S_PLAN + ak.PLAN_SIZE], io[IO_Q:IO_Q + 3],
                                   io[IO_QD:IO_QD + 3], io[IO_QDD:IO_QDD + 3]):
            return NEED_PYTHON
    elif phase == PLAY and seq[S_TABLE] != 0.0 and (seq[S_PREVIEW] == 0.0
                                                    or seq[S_AHEAD] != 0.0):
        if play_table(io, seq, table, dt):
            result = PLAY_DONE
        elif (seq[S_PREVIEW] != 0.0 and io[IO_CTRL_MODE] > 0.5
              and not math.isnan(seq[S_ROW + FZ])):
            # The sample just played: k counts the samples played (ProgramReference._play).
            read_ahead(io, seq, table, int(seq[S_K]) - 1, dt)
            ahead = True
    else:
        return NEED_PYTHON
    finish(io, seq, phase, ahead)
    return result


def warm_up() -> None:
    """Compile (or load from numba's cache) for the argument types the loop passes — the mode
    and q_meas as read-only port views — at construction, never in a cycle."""
    ak.warm_up()
    io = np.zeros(IO_SIZE)
    seq = np.zeros(SEQ_SIZE)
    seq[S_N] = 1.0
    q = np.zeros(3)
    m = np.zeros(1)
    q.flags.writeable = m.flags.writeable = False
    # A table may be read-only too: a prepared session's arrays arrive through shared memory.
    table_ro = np.zeros((1, 9))
    table_ro.flags.writeable = False
    w, f, t = np.zeros(6), np.zeros(2), np.zeros(10)
    w.flags.writeable = f.flags.writeable = t.flags.writeable = False
    for ro in (False, True):
        qq, mm = (q, m) if ro else (q.copy(), m.copy())
        ww, ff, tt = (w, f, t) if ro else (w.copy(), f.copy(), t.copy())
        for table in (np.zeros((1, 9)), table_ro):
            cycle(io, seq, qq, mm, table, 1e-3, ww, ff, tt)
        yield_step(io, seq[S_Y:S_Y + YIELD_SIZE], qq, ww, ff, 1e-3)
        tare_progress(tt, False, 0.0)
    ramp_force(io, 0.3, 1e-3)
    for table in (np.zeros((1, 9)), table_ro):
        seq[S_K] = 0.0
        play_table(io, seq, table, 1e-3)
    emit(io, seq, np.zeros(N_FIELDS), 0.0, 1e-3)
    finish(io, seq, REST)
    for table in (np.zeros((1, 9)), table_ro):
        read_ahead(io, seq, table, 0, 1e-3)
