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

import numpy as np
from numba import njit

from rt.model.kernels import TREE_MAPS_WORK, assemble, fk_solve, tree_maps_work
from rt.twin import physics
from rt.twin.physics import (
    B_C_PLAT,
    B_C_ROD,
    B_F_PER_A,
    B_G,
    B_I_PLAT,
    B_I_ROD,
    B_J_REFL_AXES,
    B_M_PLAT,
    B_M_ROD,
    B_M_SLIDER,
    N_BODY_PARAMS,
    N_FRICTION,
    N_REAL,
    R_AMP_DELAY_STEPS,
    R_BRAKE_ON,
    STATUS_FK_FAILED,
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
P_SIZE = _PX + 13

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
S_ENV_STATE = 30          # 4
S_WRENCH = 34             # 6, the environment's wrench at the sensor (sensor frame)
S_ROT = 40                # 9, R_BP row-major
S_TEMP = 49               # 3, temperature rise (K)
S_HEAT_ENERGY = 52        # 3, friction energy since the last temperature update (J)
S_ENC = 55                # 3, what the motor encoders hold (m)
S_W_FILTERED = 58         # 6, the ATI filter's state
S_W_SENSED = 64           # 6, wrench + tool weight (filter input)
S_W_MEAS = 70             # 6, what the gauges feel after the filter (the ATI model's input)
S_DELAY_LEFT = 76         # substeps the amplifiers still act on the previous command
S_HEAT_TIME = 77          # s since the last temperature update
S_DRIVES_ON = 78          # 1.0 while the amplifiers are enabled
S_DRIVES_CHANGED_T = 79   # s, when they were last switched
S_SIZE = 80

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
_W_WORK = _W_VISCOUS + N_FRICTION
W_SIZE = _W_WORK + WORK_SIZE


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
    env_state = S[S_ENV_STATE:S_ENV_STATE + 4]
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
            S[S_ROT:S_ROT + 9].reshape((3, 3)), W)
        S[S_DELAY_LEFT] = float(max(0, delay - n))
        _heat(P, S, dt)
    if status == STATUS_OK:
        _sensors(P, S, dt)
    return status


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
    rot = W[_W_ROT:_W_ROT + 9].reshape((3, 3))
    pos = W[_W_POS:_W_POS + 3]
    S = W[_W_S:_W_S + 36].reshape((12, 3))
    Sd = W[_W_SD:_W_SD + 36].reshape((12, 3))
    twist = W[_W_TWIST:_W_TWIST + 18].reshape((6, 3))
    M = W[_W_M:_W_M + 9].reshape((3, 3))
    hb = W[_W_HB:_W_HB + 3]
    tau_env = W[_W_TAU_ENV:_W_TAU_ENV + 3]
    fr = W[_W_FR:_W_FR + 3]
    frm = W[_W_FRM:_W_FRM + 3]
    for i in range(3):
        frm[i] = 0.0
    work = W[_W_WORK:_W_WORK + WORK_SIZE]
    viscous_only = W[_W_VISCOUS:_W_VISCOUS + N_FRICTION]
    for k in range(N_FRICTION):
        viscous_only[k] = friction[k]
    viscous_only[14:17] = 0.0
    fpa = bodies[B_F_PER_A]
    alpha = real[physics.R_AMP_ALPHA]
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
            current[i] += alpha * (target - current[i])
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
                force[i] = fpa * current[i] + cable_tau[i]
        st = acceleration_fast(geom, bodies, viscous_only if k > 0.0 else friction, env, q,
                                  qd, phi, force, env_state, qdd, wrench_s, rot, pos, S, Sd,
                                  twist, M, hb, tau_env, fr, work)
        if st != STATUS_OK:
            return st
        if k > 0.0:
            physics.friction_force(xm, vm, friction_motor, frm)
        for i in range(3):
            if k > 0.0:
                level = physics.coulomb_level(q[i], qd[i], friction, i)
                qd[i] = physics._toward_zero(qd[i] + h_step * qdd[i], h_step * level / M[i, i])
                q[i] += h_step * qd[i]
                jr = real[physics.R_JR + i]
                v = vm[i] + h_step * (fpa * current[i] - spring[i] - frm[i]) / jr
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


# ---- the substep with the mass matrix's products factored
@njit(cache=True)
def _congruence(r, bodies, offset, tmp, out):
    """out = R I Rᵀ for the inertia I = bodies[offset:offset+9] (row-major), via tmp = R I."""
    for a in range(3):
        for l in range(3):
            tmp[a, l] = (r[a, 0] * bodies[offset + l] + r[a, 1] * bodies[offset + 3 + l]
                         + r[a, 2] * bodies[offset + 6 + l])
    for a in range(3):
        for b in range(3):
            out[a, b] = tmp[a, 0] * r[b, 0] + tmp[a, 1] * r[b, 1] + tmp[a, 2] * r[b, 2]


@njit(cache=True)
def _add_mass(m, av, aw, iw, tmp, M):
    """M += m AvᵀAv + Awᵀ Iw Aw for one body's velocity maps (3×3 each), via tmp = Iw Aw."""
    for k in range(3):
        for b in range(3):
            tmp[k, b] = iw[k, 0] * aw[0, b] + iw[k, 1] * aw[1, b] + iw[k, 2] * aw[2, b]
    for a in range(3):
        for b in range(3):
            M[a, b] += (m * (av[0, a] * av[0, b] + av[1, a] * av[1, b] + av[2, a] * av[2, b])
                        + aw[0, a] * tmp[0, b] + aw[1, a] * tmp[1, b] + aw[2, a] * tmp[2, b])


@njit(cache=True)
def mass_and_bias_fast(geom, bodies, q, qd, phi, rot, pos, S, Sd, twist, M, h, work):
    """``physics.mass_and_bias_work`` with the congruences factored: R I Rᵀ as (R I) Rᵀ and
    Aᵀ I A as Aᵀ (I A), 54 multiplications per body instead of 162 and 729 (the same sums,
    reassociated: equal to round-off, ``tests/test_twin_compiled.py``)."""
    extra = work[TREE_MAPS_WORK:]
    spheres = extra[0:9].reshape((3, 3))
    iw = extra[9:18].reshape((3, 3))
    rr = extra[18:27].reshape((3, 3))
    av = extra[27:36].reshape((3, 3))
    aw = extra[36:45].reshape((3, 3))
    tmp = extra[45:54].reshape((3, 3))
    assemble(geom, q, phi, rot, pos, spheres)
    tree_maps_work(geom, q, phi, rot, qd, S, Sd, twist, work)
    g = bodies[B_G]
    ms = bodies[B_M_SLIDER]
    for a in range(3):
        h[a] = ms * g
        for b in range(3):
            M[a, b] = 0.0
        M[a, a] = bodies[B_J_REFL_AXES + a] + ms
    # ---- rods: rotation about the leg tangent t_i, pivot moving with the slider.
    mr = bodies[B_M_ROD]
    for i in range(3):
        ct = geom[3 + i]
        st = geom[6 + i]
        sp = math.sin(phi[i])
        cp = math.cos(phi[i])
        # R_rod = Rz(θ) Ry(φ); columns in the base frame.
        r00 = ct * cp
        r01 = -st
        r02 = ct * sp
        r10 = st * cp
        r11 = ct
        r12 = st * sp
        r20 = -sp
        r21 = 0.0
        r22 = cp
        cx = bodies[B_C_ROD]
        cy = bodies[B_C_ROD + 1]
        cz = bodies[B_C_ROD + 2]
        rhox = r00 * cx + r01 * cy + r02 * cz
        rhoy = r10 * cx + r11 * cy + r12 * cz
        rhoz = r20 * cx + r21 * cy + r22 * cz
        # World inertia I_w = R I Rᵀ.
        rr[0, 0] = r00
        rr[0, 1] = r01
        rr[0, 2] = r02
        rr[1, 0] = r10
        rr[1, 1] = r11
        rr[1, 2] = r12
        rr[2, 0] = r20
        rr[2, 1] = r21
        rr[2, 2] = r22
        _congruence(rr, bodies, B_I_ROD, tmp, iw)
        tx = -st
        ty = ct
        # Columns: v_k = δ_ik ẑ + ω_k × ρ, ω_k = φ̇_ik t.
        for k in range(3):
            pd = S[2 * i + 1, k]
            wx = pd * tx
            wy = pd * ty
            wz = 0.0
            vx, vy, vz = physics._cross(wx, wy, wz, rhox, rhoy, rhoz)
            if k == i:
                vz += 1.0
            av[0, k] = vx
            av[1, k] = vy
            av[2, k] = vz
            aw[0, k] = wx
            aw[1, k] = wy
            aw[2, k] = wz
        # Drift accelerations (q̈ = 0) for the actual q̇.
        phid = 0.0
        phidd = 0.0
        for k in range(3):
            phid += S[2 * i + 1, k] * qd[k]
            phidd += Sd[2 * i + 1, k] * qd[k]
        wx = phid * tx
        wy = phid * ty
        alx = phidd * tx
        aly = phidd * ty
        a1x, a1y, a1z = physics._cross(alx, aly, 0.0, rhox, rhoy, rhoz)
        w1x, w1y, w1z = physics._cross(wx, wy, 0.0, rhox, rhoy, rhoz)
        a2x, a2y, a2z = physics._cross(wx, wy, 0.0, w1x, w1y, w1z)
        ax0 = a1x + a2x
        ay0 = a1y + a2y
        az0 = a1z + a2z + g            # a⁰ − g_vec with g_vec = (0, 0, −g)
        iwx = iw[0, 0] * wx + iw[0, 1] * wy
        iwy = iw[1, 0] * wx + iw[1, 1] * wy
        iwz = iw[2, 0] * wx + iw[2, 1] * wy
        gx, gy, gz = physics._cross(wx, wy, 0.0, iwx, iwy, iwz)
        tqx = iw[0, 0] * alx + iw[0, 1] * aly + gx
        tqy = iw[1, 0] * alx + iw[1, 1] * aly + gy
        tqz = iw[2, 0] * alx + iw[2, 1] * aly + gz
        for a in range(3):
            h[a] += mr * (av[0, a] * ax0 + av[1, a] * ay0 + av[2, a] * az0) \
                + aw[0, a] * tqx + aw[1, a] * tqy + aw[2, a] * tqz
        _add_mass(mr, av, aw, iw, tmp, M)
    # ---- platform (with sensor and payload).
    mp = bodies[B_M_PLAT]
    cx = bodies[B_C_PLAT]
    cy = bodies[B_C_PLAT + 1]
    cz = bodies[B_C_PLAT + 2]
    rhox = rot[0, 0] * cx + rot[0, 1] * cy + rot[0, 2] * cz
    rhoy = rot[1, 0] * cx + rot[1, 1] * cy + rot[1, 2] * cz
    rhoz = rot[2, 0] * cx + rot[2, 1] * cy + rot[2, 2] * cz
    _congruence(rot, bodies, B_I_PLAT, tmp, iw)
    for k in range(3):
        wx = twist[3, k]
        wy = twist[4, k]
        wz = twist[5, k]
        vx, vy, vz = physics._cross(wx, wy, wz, rhox, rhoy, rhoz)
        av[0, k] = twist[0, k] + vx
        av[1, k] = twist[1, k] + vy
        av[2, k] = twist[2, k] + vz
        aw[0, k] = wx
        aw[1, k] = wy
        aw[2, k] = wz
    # Drift: origin acceleration from Ṡ, angular acceleration from the Euler-rate kinematics.
    pax = 0.0
    pay = 0.0
    paz = 0.0
    yd = 0.0
    pd = 0.0
    rd = 0.0
    ydd = 0.0
    pdd = 0.0
    rdd = 0.0
    wx = 0.0
    wy = 0.0
    wz = 0.0
    for k in range(3):
        pax += Sd[6, k] * qd[k]
        pay += Sd[7, k] * qd[k]
        paz += Sd[8, k] * qd[k]
        yd += S[9, k] * qd[k]
        pd += S[10, k] * qd[k]
        rd += S[11, k] * qd[k]
        ydd += Sd[9, k] * qd[k]
        pdd += Sd[10, k] * qd[k]
        rdd += Sd[11, k] * qd[k]
        wx += twist[3, k] * qd[k]
        wy += twist[4, k] * qd[k]
        wz += twist[5, k] * qd[k]
    yaw = math.atan2(rot[1, 0], rot[0, 0])
    sa = math.sin(yaw)
    ca = math.cos(yaw)
    sb = -rot[2, 0]
    cb = math.sqrt(max(0.0, 1.0 - sb * sb))
    ebx = -sa
    eby = ca
    egx = ca * cb
    egy = sa * cb
    egz = -sb
    # ω̇ = α̈ ẑ + β̈ e_β + γ̈ e_γ + β̇ α̇ (ẑ × e_β) + γ̇ (α̇ ẑ + β̇ e_β) × e_γ
    alx = pdd * ebx + rdd * egx + pd * yd * (-eby)
    aly = pdd * eby + rdd * egy + pd * yd * ebx
    alz = ydd + rdd * egz
    ox = pd * ebx
    oy = pd * eby
    oz = yd
    t1x, t1y, t1z = physics._cross(ox, oy, oz, egx, egy, egz)
    alx += rd * t1x
    aly += rd * t1y
    alz += rd * t1z
    a1x, a1y, a1z = physics._cross(alx, aly, alz, rhox, rhoy, rhoz)
    w1x, w1y, w1z = physics._cross(wx, wy, wz, rhox, rhoy, rhoz)
    a2x, a2y, a2z = physics._cross(wx, wy, wz, w1x, w1y, w1z)
    ax0 = pax + a1x + a2x
    ay0 = pay + a1y + a2y
    az0 = paz + a1z + a2z + g
    iwx = iw[0, 0] * wx + iw[0, 1] * wy + iw[0, 2] * wz
    iwy = iw[1, 0] * wx + iw[1, 1] * wy + iw[1, 2] * wz
    iwz = iw[2, 0] * wx + iw[2, 1] * wy + iw[2, 2] * wz
    gx, gy, gz = physics._cross(wx, wy, wz, iwx, iwy, iwz)
    tqx = iw[0, 0] * alx + iw[0, 1] * aly + iw[0, 2] * alz + gx
    tqy = iw[1, 0] * alx + iw[1, 1] * aly + iw[1, 2] * alz + gy
    tqz = iw[2, 0] * alx + iw[2, 1] * aly + iw[2, 2] * alz + gz
    for a in range(3):
        h[a] += mp * (av[0, a] * ax0 + av[1, a] * ay0 + av[2, a] * az0) \
            + aw[0, a] * tqx + aw[1, a] * tqy + aw[2, a] * tqz
    _add_mass(mp, av, aw, iw, tmp, M)


@njit(cache=True)
def acceleration_fast(geom, bodies, friction, env, q, qd, phi, force, env_state, qdd, wrench_s,
                 work_rot, work_pos, S, Sd, twist, M, h, tau_env, fr, work):
    """``physics.acceleration`` with ``mass_and_bias_fast``."""
    it = fk_solve(geom, q, phi, physics._FK_TOL, physics._FK_MAX_IT)
    if it < 0:
        return STATUS_FK_FAILED
    mass_and_bias_fast(geom, bodies, q, qd, phi, work_rot, work_pos, S, Sd, twist, M, h, work)
    physics.environment_wrench(env, bodies, work_rot, work_pos, twist, qd, env_state, wrench_s, tau_env)
    physics.friction_force(q, qd, friction, fr)
    r0 = force[0] - h[0] - fr[0] + tau_env[0] + physics.end_stop_force(q[0], qd[0], bodies)
    r1 = force[1] - h[1] - fr[1] + tau_env[1] + physics.end_stop_force(q[1], qd[1], bodies)
    r2 = force[2] - h[2] - fr[2] + tau_env[2] + physics.end_stop_force(q[2], qd[2], bodies)
    # M is symmetric positive definite and dominated by the reflected inertia: Cramer's rule.
    c00 = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
    c01 = M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]
    c02 = M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]
    det = M[0, 0] * c00 + M[0, 1] * c01 + M[0, 2] * c02
    qdd[0] = (r0 * c00 + r1 * (M[0, 2] * M[2, 1] - M[0, 1] * M[2, 2])
              + r2 * (M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1])) / det
    qdd[1] = (r0 * c01 + r1 * (M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0])
              + r2 * (M[0, 2] * M[1, 0] - M[0, 0] * M[1, 2])) / det
    qdd[2] = (r0 * c02 + r1 * (M[0, 1] * M[2, 0] - M[0, 0] * M[2, 1])
              + r2 * (M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0])) / det
    return STATUS_OK


def new_state() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zeroed (P, S, W) arrays of the right sizes."""
    return np.zeros(P_SIZE), np.zeros(S_SIZE), np.zeros(W_SIZE)
