"""The hybrid controller's force-mode cycle as one numba kernel (issue 16): the reference the
explicit-force law tracks (``HybridController._lead``: the read-ahead while the program asks
more than the robot follows; the bumpless entry's decaying offset; ``_govern``: the preload
floor and the braked unloading, allowing for the platform's lag; the pose's rate), then the
law's own kernel (``rt.control.kernels.explicit_force``, called with the arguments
``ExplicitForce.update`` passes).

``rt.components.protocol_blocks.HybridController`` keeps the interpreted cycle: it is the
reference, and it runs every cycle the kernel does not cover (a mode switch, a supervisor mode
change, a patched law). Its per-cycle state lives in one float64 array (``H_*`` below) that both
read and write, so a cycle may run either way and the next one continues from it. The float
operations here are the interpreted ones in the same order (``tests/test_fused_cycle.py``
compares the two byte for byte, every cycle); Python's ``max(a, b)``/``min(a, b)`` are spelled
out (they return ``a`` unless ``b`` is strictly beyond it, NaN included).

Kept apart from the Python side so that editing it does not invalidate numba's on-disk cache.
"""
from __future__ import annotations

import math

from numba import njit

from rt.control import kernels as ck

# The hybrid controller's state and parameters (``HybridController._hs``).
(H_OFFSET,          # the bumpless entry's offset still to fade (N)
 H_AHEAD_WEIGHT,    # weight of the read-ahead reference (1 during a transient, then fading)
 H_RISING,          # 1.0: the transient under way is a rise (the integral holds)
 H_F_GOV,           # the governed reference of the previous cycle (N; NaN: none yet)
 H_ENTRY_TIME,      # ``entry_time_s``: the entry offset's time constant (s)
 H_ENTRY_TIME_SQ,   # its square (computed in Python, as the interpreted cycle does)
 H_DECAY_PER_S,     # exp(−1/entry_time_s), fixed at construction as the block does
 H_UNLOAD_DECEL,    # ``unload_decel_m_s2`` (m/s²)
 H_RELEASE_S,       # ``preview_release_s`` (s)
 H_REF_F,           # the reference the law got this cycle (N, F_d; read by benches)
 H_UNLOAD_LAG,      # ``unload_lag_s``: how late the platform follows the unloading (s)
 H_ROLL_PREV,       # the pose reference's roll one cycle earlier (rad; NaN: none yet)
 H_PITCH_PREV,      # its pitch one cycle earlier (rad; NaN: none yet)
 H_K_PENDING,       # a remembered contact stiffness for the first loaded cycle (N/m; NaN: none)
 H_SIZE) = range(15)

# ExplicitForce's gains (``ExplicitForce._pack_gains``) this cycle reads.
_FG_PRELOAD, _FG_VMAX = 9, 10


@njit(cache=True, inline="always")
def _pymax(a, b):
    return b if b > a else a  # noqa: FURB136 - max() may differ on NaN in numba


@njit(cache=True, inline="always")
def _pymin(a, b):
    return b if b < a else a  # noqa: FURB136 - as _pymax


@njit(cache=True)
def force_reference(hs, fg, fs, force, preview, dt, fr):
    """The reference the law tracks this cycle into ``fr`` (f, ḟ, f̈, transient as 0/1):
    ``HybridController._lead``, the entry offset, ``_govern`` (their docstrings say why)."""
    limit = fg[_FG_VMAX] * fs[ck.FS_K]          # HybridController._beyond's threshold
    if abs(preview[1]) > limit:
        rate = preview[1]
    elif abs(force[1]) > limit:
        rate = force[1]
    else:
        rate = 0.0
    if rate != 0.0:
        if hs[H_AHEAD_WEIGHT] == 0.0:
            hs[H_RISING] = 1.0 if rate > 0.0 else 0.0
        w = 1.0
    else:
        w = _pymax(0.0, hs[H_AHEAD_WEIGHT] - dt / hs[H_RELEASE_S])
    hs[H_AHEAD_WEIGHT] = w
    transient = w > 0.0 and hs[H_RISING] != 0.0
    f = force[0] + w * (preview[0] - force[0])
    f_dot = force[1] + w * (preview[1] - force[1])
    f_ddot = force[2] + w * (preview[2] - force[2])
    # The bumpless entry's offset, fading with time constant entry_time_s.
    off = hs[H_OFFSET]
    hs[H_OFFSET] = off * hs[H_DECAY_PER_S] ** dt
    f += off
    f_dot -= off / hs[H_ENTRY_TIME]
    f_ddot += off / hs[H_ENTRY_TIME_SQ]
    # _govern: never below the preload; falling to it no faster than the platform brakes.
    floor = fg[_FG_PRELOAD]
    target = _pymax(floor, f)
    g = hs[H_F_GOV]
    if math.isnan(g) or target >= g:
        hs[H_F_GOV] = target
        if target == floor:
            f_dot = 0.0
            f_ddot = 0.0
        f = target
    else:
        k = fs[ck.FS_K]
        a = hs[H_UNLOAD_DECEL]
        lag = hs[H_UNLOAD_LAG]
        if lag > 0.0:
            # The platform follows ``lag`` late: v²/(2a) + v·lag ≤ (F − F_min)/k.
            al = a * lag
            max_rate = k * (math.sqrt(al * al + 2.0 * a * (g - floor) / k) - al)
        else:
            max_rate = math.sqrt(2.0 * a * k * (g - floor))
        step = _pymin(g - target, max_rate * dt)
        hs[H_F_GOV] = g - step
        f = hs[H_F_GOV]
        f_dot = -step / dt
        f_ddot = 0.0
    hs[H_REF_F] = f
    fr[0] = f
    fr[1] = f_dot
    fr[2] = f_ddot
    fr[3] = 1.0 if transient else 0.0


@njit(cache=True)
def force_cycle(hs, force, preview, pose, wrench, ti, tf, stb, fg, fs, work, out, law_tau,
                fr, dt):
    """One force-mode cycle of the hybrid controller (steady: no switch this cycle): the
    reference (:func:`force_reference`), then the law's kernel as ``ExplicitForce.update``
    calls it (the measured F = −w_S.fz; roll and pitch held at the program's pose with its rate), the
    command copied to the law's ``tau`` as it does. A remembered contact stiffness waiting
    for the contact's first loaded cycle (``H_K_PENDING``) is applied first, as the block
    does."""
    measured = -wrench[2]
    pending = hs[H_K_PENDING]
    if not math.isnan(pending) and measured > ck.CONTACT_LOADED_N:
        ck.prime_stiffness(fg, fs, pending)
        hs[H_K_PENDING] = math.nan
    force_reference(hs, fg, fs, force, preview, dt, fr)
    # The pose's rate: the backward difference of its reference (0 on the first force-mode
    # cycle), as the interpreted block computes it.
    roll = pose[1]
    pitch = pose[2]
    prev = hs[H_ROLL_PREV]
    roll_rate = 0.0 if math.isnan(prev) else (roll - prev) / dt
    prev = hs[H_PITCH_PREV]
    pitch_rate = 0.0 if math.isnan(prev) else (pitch - prev) / dt
    hs[H_ROLL_PREV] = roll
    hs[H_PITCH_PREV] = pitch
    ck.explicit_force(ti, tf, stb, fg, fs, measured, fr[0], fr[1], fr[2], roll, pitch,
                      roll_rate, pitch_rate, fr[3], dt, work, out)
    for i in range(3):
        law_tau[i] = out[i]
