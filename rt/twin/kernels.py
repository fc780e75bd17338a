"""The twin's whole control period compiled: one numba call per held command.

``rt.twin.physics`` compiles the substep (dynamics, friction, contact, integrators), but until
issue 16 everything around it ran in interpreted Python once per 1 ms chunk: the amplifier
delay bookkeeping, the brakes' timing, the thermal model and its friction scales, the encoders'
latency and the ATI's tool weight and low-pass filter, and the ATI's noise/drift/clip model.
Those cost more than the physics (``bench/twin.py``), so they are compiled here on
preallocated state, with the same arithmetic in the same order as the interpreted reference
(``TwinPlant(compiled=False)``: ``tests/test_twin_compiled.py`` replays a recorded input
stream through both and requires 1e-12 agreement).

State and parameters are packed in two float64 arrays owned by ``rt.twin.plant.TwinPlant``
(the plant's arrays — ``q``, ``bodies``, ``friction`` … — are views into them), so a chunk is
one dispatch with five array arguments instead of ~25 (numba unboxes every array argument:
≈ 0.2 µs each):

* ``P`` (parameters): ``P_BODIES`` (``physics.N_BODY_PARAMS``), ``P_FRICTION``,
  ``P_FRICTION_SLIDER``, ``P_FRICTION_MOTOR`` (``physics.N_FRICTION`` each), ``P_REAL``
  (``physics.N_REAL``), then the scalars ``P_*`` below (thermal model, brakes, sensors).
* ``S`` (state): ``S_*`` below; the scalars (delay left, heat time, drives on, time of the last
  drive change) are floats.
* ``W`` (scratch): ``W_SIZE`` floats the substeps use, so the period allocates nothing.
"""
from __future__ import annotations

import math
from array import array

import numpy as np
from numba import njit

from rt.ati import twin_sensor as _ati
from rt.ati.rdt import STATUS_ANY_ERROR, STATUS_FT_OUT_OF_RANGE
from rt.ati.twin_sensor import _measure_kernel
from rt.drivers.kernels import dac_code_volts, fake_pcl833_move
from rt.pointers import f64_view
from rt.twin import physics
from rt.twin.physics import (
    B_F_PER_A,
    ENV_STATE_SIZE,
    N_BODY_PARAMS,
    N_FRICTION,
    N_REAL,
    R_AMP_DELAY_STEPS,
    R_BRAKE_ON,
    STATUS_OK,
    WORK_SIZE,
)

# ---- parameter array P
P_BODIES = 0
P_FRICTION = P_BODIES + N_BODY_PARAMS
P_FRICTION_SLIDER = P_FRICTION + N_FRICTION
P_FRICTION_MOTOR = P_FRICTION_SLIDER + N_FRICTION
P_REAL = P_FRICTION_MOTOR + N_FRICTION
_PX = P_REAL + N_REAL
P_VISCOUS_PER_K = _PX + 0         # friction scale per kelvin (1/K)
P_COULOMB_PER_K = _PX + 1
P_HEAT_CAPACITY = _PX + 2         # J/K
P_THERMAL_RES = _PX + 3           # K/W
P_SPLIT = _PX + 4                 # motor-side share of the friction (compliant screw)
P_HEAT_PERIOD = _PX + 5           # s between temperature updates
P_BRAKE_HOLD_N = _PX + 6          # the imperfection's holding force (0: no brakes)
P_BRAKE_RELEASE = _PX + 7         # s
P_BRAKE_ENGAGE = _PX + 8          # s
P_ENC_LATENCY = _PX + 9           # s
P_ATI_TAU = _PX + 10              # s (0: no filter)
P_TOOL_MG = _PX + 11              # N
P_TOOL_COM = _PX + 12             # m
P_CMD_LIMIT = _PX + 13            # V, the amplifiers' input clamp (``command_limit_v``)
P_WITH_OFFSET = _PX + 14          # 1.0 when an amplifier input offset is set
P_AMP_OFFSET = _PX + 15           # 3, V, the amplifiers' input offsets
P_PORT_SIGN = _PX + 18            # 3, the encoder card's count direction per axis
P_PORT_MPC = _PX + 21             # 3, m per count per axis
P_REALISTIC = _PX + 24            # 1.0 with the rig's imperfections (``TwinPlant.realistic``)
P_INTEGRATOR = _PX + 25           # ``physics.INTEGRATOR_*`` (``TwinPlant.integrator``)
P_SIZE = _PX + 26

# ---- state array S
S_Q = 0
S_QD = 3
S_QDD = 6
S_PHI = 9
S_XM = 12
S_VM = 15
S_CURRENT = 18
S_CABLE_TAU = 21
S_VOLTS = 24
S_VOLTS_PREV = 27
S_ENV_STATE = 30          # ENV_STATE_SIZE (8)
S_WRENCH = 38             # 6, the environment's wrench at the sensor (sensor frame)
S_ROT = 44                # 9, R_BP row-major
S_TEMP = 53               # 3, temperature rise (K)
S_HEAT_ENERGY = 56        # 3, friction energy since the last temperature update (J)
S_ENC = 59                # 3, what the motor encoders hold (m)
S_W_FILTERED = 62         # 6, the ATI filter's state
S_W_SENSED = 68           # 6, wrench + tool weight (filter input)
S_W_MEAS = 74             # 6, what the gauges feel after the filter (the ATI model's input)
S_DELAY_LEFT = 80         # substeps the amplifiers still act on the previous command
S_HEAT_TIME = 81          # s since the last temperature update
S_DRIVES_ON = 82          # 1.0 while the amplifiers are enabled
S_DRIVES_CHANGED_T = 83   # s, when they were last switched
S_AMP = 84                # 3, V: the amplifier inputs the DAC codes make (``Twin.amp_volts``)
S_VOLTS_IN = 87           # 3, V: what the amplifiers integrate (inputs + offsets, drives on)
S_SIZE = 90

# ---- scratch array W
_W_FORCE = 0
_W_SPRING = 3
_W_ROT = 6
_W_POS = 15
_W_S = 18
_W_SD = 54
_W_TWIST = 90
_W_M = 108
_W_HB = 117
_W_TAU_ENV = 120
_W_FR = 123
_W_FRM = 126
_W_CMD_NEW = 129
_W_CMD_OLD = 132
_W_VISCOUS = 135
_W_APPLIED = _W_VISCOUS + N_FRICTION
_W_WORK = _W_APPLIED + 3
_W_PORT_INDEX = _W_WORK + WORK_SIZE     # 3, the encoder card's new index (floats)
W_SIZE = _W_PORT_INDEX + 3

#: Length of the closed-chain geometry array (``rt.model.kernels.pack_geometry``).
GEOM_SIZE = 12

# ---- the period's one block ``B`` (float64[B_SIZE]): everything :func:`period_block` touches
# but the devices' and the ATI's arrays, contiguous, so a period unboxes one array instead of
# five and its memory is a few adjacent cache lines (issue 16: between two periods the loop's
# other blocks evict the twin's state). ``S`` comes first, so the ``S_*`` offsets index ``B``
# too. ``TwinPlant``'s ``S``, ``P``, ``W``, ``env`` and ``geom`` are views of it.
B_S = 0
B_P = B_S + S_SIZE
B_W = B_P + P_SIZE
B_ENV = B_W + W_SIZE
B_GEOM = B_ENV + physics.ENV_SIZE
B_X = B_GEOM + GEOM_SIZE
# ``X``: the plant's Python-side state a compiled period advances (a compiled pre-flight
# driver advances it too, between Python's events), read by Python through ``TwinPlant``.
X_T = 0                   # s, the plant's time (``TwinPlant.t``)
X_SIZE = 2                # (one spare: the block ends on an even number of floats)
B_SIZE = B_X + X_SIZE


@njit(cache=True)
def _temperature_scales(P, S):
    """``TwinPlant._update_temperature_scales``: friction scales from the temperatures, split
    between the slider's and the motor's share."""
    split = P[P_SPLIT]
    f = P_FRICTION
    for i in range(3):
        dt_k = S[S_TEMP + i]
        P[f + 11 + i] = max(0.2, 1.0 + P[P_VISCOUS_PER_K] * dt_k)
        P[f + 14 + i] = max(0.2, 1.0 + P[P_COULOMB_PER_K] * dt_k)
    keep = 1.0 - split
    for k in range(N_FRICTION):
        v = P[f + k]
        if 11 <= k < 17:
            P[P_FRICTION_SLIDER + k] = v * keep
            P[P_FRICTION_MOTOR + k] = v * split
        else:
            P[P_FRICTION_SLIDER + k] = v
            P[P_FRICTION_MOTOR + k] = v


@njit(cache=True)
def _heat(P, S, dt):
    """``TwinPlant._heat``: friction power in, convection out, scales every heat period."""
    if P[P_VISCOUS_PER_K] == 0.0 and P[P_COULOMB_PER_K] == 0.0:
        return
    f = P_FRICTION
    for i in range(3):
        v = S[S_QD + i]
        S[S_HEAT_ENERGY + i] += dt * (P[f + 11 + i] * P[f + i] * v * v
                                      + P[f + 14 + i] * P[f + 3 + i] * abs(v))
    S[S_HEAT_TIME] += dt
    if S[S_HEAT_TIME] < P[P_HEAT_PERIOD]:
        return
    cap = P[P_HEAT_CAPACITY]
    res = P[P_THERMAL_RES]
    span = S[S_HEAT_TIME]
    for i in range(3):
        S[S_TEMP + i] += (S[S_HEAT_ENERGY + i] - span * S[S_TEMP + i] / res) / cap
        S[S_HEAT_ENERGY + i] = 0.0
    S[S_HEAT_TIME] = 0.0
    _temperature_scales(P, S)


@njit(cache=True)
def _update_brakes(P, S, t):
    """``TwinPlant._update_brakes``: engaged ``brake_engage_s`` after the drives went off,
    released ``brake_release_s`` after they came back on."""
    if P[P_BRAKE_HOLD_N] <= 0.0:
        return
    since = t - S[S_DRIVES_CHANGED_T]
    on = P[P_REAL + R_BRAKE_ON] > 0.5
    drives_on = S[S_DRIVES_ON] > 0.5
    if drives_on and on and since >= P[P_BRAKE_RELEASE]:
        on = False
    elif not drives_on and not on and since >= P[P_BRAKE_ENGAGE]:
        on = True
    P[P_REAL + R_BRAKE_ON] = 1.0 if on else 0.0


@njit(cache=True)
def _sensors(P, S, dt):
    """The encoders' reading (motor position a latency ago) and the ATI's filtered input
    (``Twin._encoder_positions`` and ``Twin._filtered_wrench``)."""
    lat = P[P_ENC_LATENCY]
    for i in range(3):
        if lat == 0.0:
            S[S_ENC + i] = S[S_XM + i]
        else:
            S[S_ENC + i] = S[S_XM + i] - S[S_VM + i] * lat
    src = S_WRENCH
    mg = P[P_TOOL_MG]
    if mg != 0.0:
        for k in range(6):
            S[S_W_SENSED + k] = S[S_WRENCH + k]
        fx = -mg * S[S_ROT + 6]
        fy = -mg * S[S_ROT + 7]
        fz = -mg * S[S_ROT + 8]
        h = P[P_TOOL_COM]
        S[S_W_SENSED + 0] += fx
        S[S_W_SENSED + 1] += fy
        S[S_W_SENSED + 2] += fz
        S[S_W_SENSED + 3] += -h * fy
        S[S_W_SENSED + 4] += h * fx
        src = S_W_SENSED
    tau = P[P_ATI_TAU]
    if tau == 0.0:
        for k in range(6):
            S[S_W_MEAS + k] = S[src + k]
        return
    a = 1.0 - math.exp(-dt / tau)
    for k in range(6):
        w = S[S_W_FILTERED + k]
        w += a * (S[src + k] - w)
        S[S_W_FILTERED + k] = w
        S[S_W_MEAS + k] = w


@njit(cache=True)
def advance(geom, P, env, S, W, volts, dt, n, t, realistic, integrator):
    """One held command: ``TwinPlant.advance(dt, volts)`` at time ``t`` (s) with ``n``
    substeps, then the sensor stage. Returns the physics' status (0 ok)."""
    bodies = P[P_BODIES:P_BODIES + N_BODY_PARAMS]
    env_state = S[S_ENV_STATE:S_ENV_STATE + ENV_STATE_SIZE]
    qdd = S[S_QDD:S_QDD + 3]
    wrench = S[S_WRENCH:S_WRENCH + 6]
    q = S[S_Q:S_Q + 3]
    qd = S[S_QD:S_QD + 3]
    phi = S[S_PHI:S_PHI + 3]
    h = dt / n
    if not realistic:
        v = S[S_VOLTS:S_VOLTS + 3]
        for i in range(3):
            v[i] = volts[i]
        status = physics.integrate(geom, bodies, P[P_FRICTION:P_FRICTION + N_FRICTION], env,
                                   q, qd, phi, v, n, h, integrator, env_state, qdd, wrench)
        for i in range(3):
            S[S_XM + i] = S[S_Q + i]
            S[S_VM + i] = S[S_QD + i]
    else:
        if (S[S_VOLTS] != volts[0] or S[S_VOLTS + 1] != volts[1]
                or S[S_VOLTS + 2] != volts[2]):
            # A new command: the amplifiers keep acting on the old one for the delay.
            for i in range(3):
                S[S_VOLTS_PREV + i] = S[S_VOLTS + i]
                S[S_VOLTS + i] = volts[i]
            S[S_DELAY_LEFT] = float(int(P[P_REAL + R_AMP_DELAY_STEPS]))
        _update_brakes(P, S, t)
        delay = int(S[S_DELAY_LEFT])
        status = integrate_real_work(
            geom, bodies, P[P_FRICTION_SLIDER:P_FRICTION_SLIDER + N_FRICTION],
            P[P_FRICTION_MOTOR:P_FRICTION_MOTOR + N_FRICTION], env, P[P_REAL:P_REAL + N_REAL],
            q, qd, phi, S[S_XM:S_XM + 3], S[S_VM:S_VM + 3], S[S_CURRENT:S_CURRENT + 3],
            S[S_CABLE_TAU:S_CABLE_TAU + 3], S[S_VOLTS:S_VOLTS + 3],
            S[S_VOLTS_PREV:S_VOLTS_PREV + 3], delay, n, h, env_state, qdd, wrench,
            f64_view(S, S_ROT, (3, 3)), W)
        if delay < n:
            # The delay has ended (its fractional substep included): from now on the
            # amplifiers' previous command is the present one.
            for i in range(3):
                S[S_VOLTS_PREV + i] = S[S_VOLTS + i]
        S[S_DELAY_LEFT] = float(max(0, delay - n))
        _heat(P, S, dt)
    if status == STATUS_OK:
        _sensors(P, S, dt)
    return status


#: ``ati`` layout of :func:`period` (``TwinAtiSensorModel``'s packed array, ``_A_*`` there):
#: the model's parameters (``_measure_kernel``'s ``params``), its drift, the sample it writes
#: (wrench, then its counter and status word), then the bookkeeping :func:`period_ati`
#: advances (the object-not-built flag, the random block's next row, the last sample's time,
#: NaN before the first).
(ATI_PARAMS, ATI_DRIFT, ATI_OUT, ATI_OUT_END, ATI_SEQ, ATI_STATUS, ATI_PENDING, ATI_ROW,
 ATI_T_LAST, ATI_SIZE) = (_ati._A_PARAMS, _ati._A_DRIFT, _ati._A_OUT, _ati._A_OUT_END,
                          _ati._A_SEQ, _ati._A_STATUS, _ati._A_PENDING, _ati._A_ROW,
                          _ati._A_T_LAST, _ati._A_SIZE)
#: :func:`period_ati`'s answer when the ATI's random block is used up (nothing was done:
#: Python draws the next block, ``TwinAtiSensorModel._next_block_row``, and calls again).
NEED_DRAWS = -2
#: DAC codes meaning "no code written" (a channel never written, or no card enabled).
NO_CODE = -1


@njit(cache=True)
def amplifier_input(P, S, codes):
    """``Twin._update_amplifier_input`` without DAC faults: the enabled card's codes (``codes``
    int64[3], ``NO_CODE`` for none) → volts (``pci1720.code_to_volts`` on ±10 V, 12 bit),
    clamped at the amplifiers' limit, into ``S[S_AMP:]``; then the input held over the period
    (``TwinPlant._held_input``): plus the offsets while the drives are on. Returns the offset
    of the held input in ``S``."""
    lim = P[P_CMD_LIMIT]
    for ch in range(3):
        v = 0.0
        code = codes[ch]
        if code != NO_CODE:
            v = dac_code_volts(code, -10.0, 10.0, 4095.0)    # the one DAC quantizer's inverse
        S[S_AMP + ch] = max(-lim, min(lim, v))
    if P[P_WITH_OFFSET] > 0.5 and S[S_DRIVES_ON] > 0.5:
        for ch in range(3):
            S[S_VOLTS_IN + ch] = S[S_AMP + ch] + P[P_AMP_OFFSET + ch]
        return S_VOLTS_IN
    return S_AMP


@njit(cache=True)
def period(geom, P, env, S, W, port, codes, ati, ati_block, dt, n, t, realistic, integrator,
           ati_row, ati_dt, overload_bits):
    """The twin's fault-free period in one dispatch (issue 16: pre-flight's twin; each
    dispatch and its Python cost as much as a physics substep, and numba unboxes every array
    argument, so the state lives in few arrays):

    * the amplifier input from the enabled card's DAC ``codes`` (:func:`amplifier_input`);
    * :func:`advance` (physics, brakes, heat, encoder latency, the ATI's filter);
    * the encoder card's counters (``port``: ``FakePcl833Port``'s int64 state) moved to the
      index ``floor(sign·x/mpc + 0.5)`` of the encoder reading
      (``rt.drivers.kernels.fake_pcl833_move``);
    * the ATI sample (``rt.ati.twin_sensor._measure_kernel`` on the filtered wrench, from row
      ``ati_row`` of the random block) into ``ati[ATI_OUT:]``.

    The same arithmetic in the same order as the general path (``_update_amplifier_input``,
    ``plant.advance``, ``_update_sensors``). Returns the ATI overload bits (≥ 0), or −1 when
    the physics failed (then nothing is read, as when the general path raises).
    """
    vin = amplifier_input(P, S, codes)
    status = advance(geom, P, env, S, W, S[vin:vin + 3], dt, n, t, realistic, integrator)
    if status != STATUS_OK:
        return -1
    index = W[_W_PORT_INDEX:_W_PORT_INDEX + 3]
    for i in range(3):
        index[i] = math.floor(P[P_PORT_SIGN + i] * S[S_ENC + i] / P[P_PORT_MPC + i] + 0.5)
    fake_pcl833_move(port, index)
    return _measure_kernel(S[S_W_MEAS:S_W_MEAS + 6], ati_block, ati_row,
                           ati[ATI_PARAMS:ATI_DRIFT], ati[ATI_DRIFT:ATI_OUT],
                           ati[ATI_OUT:ATI_OUT_END], ati_dt, overload_bits)


#: The ATI's status bits for an overloaded axis in a fault-free period (``Twin``'s
#: ``_ATI_OVERLOAD``, a constant of the compiled period since issue 16's twin7).
OVERLOAD_BITS = STATUS_ANY_ERROR | STATUS_FT_OUT_OF_RANGE


@njit(cache=True)
def period_block(B, port, codes, ati, ati_block, dt, n, ati_row, ati_dt):
    """:func:`period` on the plant's one block ``B`` (``B_*``): the same call with the same
    arguments, read from the block (``realistic`` and ``integrator`` from ``P``, the time
    from ``X``; the overload bits are :data:`OVERLOAD_BITS`), so the arithmetic is the same
    to the bit. Advances the plant's time ``X_T`` by ``dt`` when the physics succeeded (the
    float ``t + dt`` Python computed before). Returns :func:`period`'s result."""
    P = B[B_P:B_P + P_SIZE]
    t = B[B_X + X_T]
    bits = period(B[B_GEOM:B_GEOM + GEOM_SIZE], P, B[B_ENV:B_ENV + physics.ENV_SIZE],
                  B[B_S:B_S + S_SIZE], B[B_W:B_W + W_SIZE], port, codes, ati, ati_block, dt, n,
                  t, P[P_REALISTIC] > 0.5, int(P[P_INTEGRATOR]), ati_row, ati_dt,
                  OVERLOAD_BITS)
    if bits >= 0:
        B[B_X + X_T] = t + dt
    return bits


@njit(cache=True)
def period_ati(B, port, codes, ati, ati_block, dt, n):
    """:func:`period_block` with the ATI's bookkeeping in its packed array (``ATI_*``): the
    row of the random block and the drift's step (the sample's time ``t + dt`` minus the
    last one's; 0 before the first) read there, and after a sample the row, the last time,
    the counter (mod 2**32), the status word and the object-not-built flag written there:
    ``TwinAtiSensorModel._commit_compiled``'s bookkeeping without a fault's bits (the
    caller checked none can be on), in the same floats. Returns :func:`period_block`'s
    result, or :data:`NEED_DRAWS` (nothing done) when the block is used up."""
    row = int(ati[ATI_ROW])
    if row >= ati_block.shape[0]:
        return NEED_DRAWS
    t_end = B[B_X + X_T] + dt
    t_last = ati[ATI_T_LAST]
    nan = math.isnan(t_last)
    bits = period_block(B, port, codes, ati, ati_block, dt, n, row,
                        0.0 if nan else t_end - t_last)
    if bits >= 0:
        ati[ATI_ROW] = row + 1
        if nan or t_end > t_last:
            ati[ATI_T_LAST] = t_end
        ati[ATI_SEQ] = (int(ati[ATI_SEQ]) + 1) & 0xFFFF_FFFF
        ati[ATI_STATUS] = bits
        ati[ATI_PENDING] = 1.0
    return bits


@njit(cache=True)
def integrate_real_work(geom, bodies, friction, friction_motor, env, real, q, qd, phi, xm, vm,
                        current, cable_tau, volts, volts_prev, delay_steps, n_steps, h_step,
                        env_state, qdd, wrench_s, rot_out, W):
    """``physics.integrate_real`` on the scratch ``W`` (float64[W_SIZE]): no allocation.

    The same statements in the same order (the twin's results must not depend on which path
    ran); ``physics.integrate_real`` stays the interpreted path's kernel.
    """
    cmd_new = W[_W_CMD_NEW:_W_CMD_NEW + 3]
    cmd_old = W[_W_CMD_OLD:_W_CMD_OLD + 3]
    physics.drive_current(volts, bodies, cmd_new)
    physics.drive_current(volts_prev, bodies, cmd_old)
    force = W[_W_FORCE:_W_FORCE + 3]
    spring = W[_W_SPRING:_W_SPRING + 3]
    for i in range(3):
        spring[i] = 0.0
    rot = f64_view(W, _W_ROT, (3, 3))
    pos = W[_W_POS:_W_POS + 3]
    S = f64_view(W, _W_S, (12, 3))
    Sd = f64_view(W, _W_SD, (12, 3))
    twist = f64_view(W, _W_TWIST, (6, 3))
    M = f64_view(W, _W_M, (3, 3))
    hb = W[_W_HB:_W_HB + 3]
    tau_env = W[_W_TAU_ENV:_W_TAU_ENV + 3]
    fr = W[_W_FR:_W_FR + 3]
    frm = W[_W_FRM:_W_FRM + 3]
    for i in range(3):
        frm[i] = 0.0
    applied = W[_W_APPLIED:_W_APPLIED + 3]
    work = W[_W_WORK:_W_WORK + WORK_SIZE]
    viscous_only = W[_W_VISCOUS:_W_VISCOUS + N_FRICTION]
    for k in range(N_FRICTION):
        viscous_only[k] = friction[k]
    viscous_only[14:17] = 0.0
    fpa = bodies[B_F_PER_A]
    decay = 1.0 - real[physics.R_AMP_ALPHA]
    mean = real[physics.R_AMP_MEAN]
    frac = real[physics.R_AMP_DELAY_FRAC]
    k = real[physics.R_SCREW_K]
    c = real[physics.R_SCREW_C]
    half_b = 0.5 * real[physics.R_BACKLASH]
    brake = real[R_BRAKE_ON] > 0.5
    hold = real[physics.R_BRAKE_HOLD]
    cable_w = real[physics.R_CABLE_W]
    cable_k = real[physics.R_CABLE_K]
    cable = cable_w != 0.0 or cable_k != 0.0
    for s in range(n_steps):
        for i in range(3):
            target = cmd_old[i] if s < delay_steps else cmd_new[i]
            if s == delay_steps and frac > 0.0:
                target = frac * cmd_old[i] + (1.0 - frac) * cmd_new[i]
            gap = current[i] - target
            applied[i] = target + mean * gap
            current[i] = target + decay * gap
        if k > 0.0:
            for i in range(3):
                d = xm[i] - q[i]
                e = 0.0
                if d > half_b:
                    e = d - half_b
                elif d < -half_b:
                    e = d + half_b
                fs = 0.0
                if e != 0.0:
                    fs = k * e + c * (vm[i] - qd[i])
                spring[i] = fs
                force[i] = fs + cable_tau[i]
        else:
            for i in range(3):
                force[i] = fpa * applied[i] + cable_tau[i]
        st = physics.acceleration(geom, bodies, viscous_only if k > 0.0 else friction, env, q,
                                  qd, phi, force, env_state, qdd, wrench_s, rot, pos, S, Sd,
                                  twist, M, hb, tau_env, fr, work)
        if st != STATUS_OK:
            return st
        if k > 0.0:
            physics.friction_force(xm, vm, friction_motor, frm)
            physics.coulomb_step(M, qd, qdd, h_step,
                                 physics.coulomb_level(q[0], qd[0], friction, 0),
                                 physics.coulomb_level(q[1], qd[1], friction, 1),
                                 physics.coulomb_level(q[2], qd[2], friction, 2))
        for i in range(3):
            if k > 0.0:
                q[i] += h_step * qd[i]
                jr = real[physics.R_JR + i]
                v = vm[i] + h_step * (fpa * applied[i] - spring[i] - frm[i]) / jr
                if brake:
                    v = physics._toward_zero(v, h_step * hold / jr)
                vm[i] = v
                xm[i] += h_step * v
            else:
                v = qd[i] + h_step * qdd[i]
                if brake:
                    v = physics._toward_zero(v, h_step * hold / M[i, i])
                qd[i] = v
                q[i] += h_step * v
                xm[i] = q[i]
                vm[i] = v
        if cable:
            fz = -(cable_w + cable_k * (pos[2] - real[physics.R_CABLE_Z]))
            for j in range(3):
                cable_tau[j] = twist[2, j] * fz
    for a in range(3):
        for b in range(3):
            rot_out[a, b] = rot[a, b]
    return STATUS_OK


def new_state() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zeroed (P, S, W) arrays of the right sizes."""
    return np.zeros(P_SIZE), np.zeros(S_SIZE), np.zeros(W_SIZE)


def new_block() -> tuple[array, np.ndarray]:
    """A zeroed block: its store (``array('d')``: Python reads a float from it faster than
    from numpy, for the plant's time) and the float64 view of it the kernels take."""
    store = array("d", bytes(8 * B_SIZE))
    return store, np.frombuffer(store, dtype=np.float64)


def block_views(B: np.ndarray) -> tuple[np.ndarray, ...]:
    """The (P, S, W, env, geom) views of a block."""
    return (B[B_P:B_P + P_SIZE], B[B_S:B_S + S_SIZE], B[B_W:B_W + W_SIZE],
            B[B_ENV:B_ENV + physics.ENV_SIZE], B[B_GEOM:B_GEOM + GEOM_SIZE])
