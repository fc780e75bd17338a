"""The twin's physics, compiled with numba: actuated dynamics, drives, friction, environments,
and the fixed-step integrators.

Why not call Pinocchio here: the twin must run ≥ 20× real time with ≥ 5 kHz substeps, i.e.
≤ 10 µs per substep for everything, and one Pinocchio evaluation from Python costs ~25 µs. The
same rigid-body model (same description, same tree, same closed-chain maps from
``rt.model.kernels``) is therefore evaluated here body by body — M = Σ (m AᵀA + Ωᵀ I Ω) and the
bias forces from the bodies' drift accelerations — and ``tests/test_twin_physics.py`` checks it
against the Pinocchio model to round-off at random states.

Parameter arrays (packed by ``rt.twin.plant``):

* ``bodies`` (float64[40]): [m_slider, m_rod, c_rod(3), I_rod(9), m_plat, c_plat(3), I_plat(9),
  sensor offset s(3), gravity g, J_reflected, force_per_amp, current_limit, amp_gain,
  end-stop low, end-stop high (m), end-stop stiffness (N/m) and damping (N s/m), spare];
  rod quantities in the rod frame, platform ones in P (payload and sensor included), inertias
  about the COM.
  ``B_J_REFL`` holds axis 0's reflected inertia, ``B_J_REFL_AXES`` (3) every axis's.
* ``friction`` (float64[N_FRICTION]): per axis f_v (N s/m) [0:3], f_c (N) [3:6], f_s static
  (N) [6:9]; v_stribeck (m/s) [9], v_smooth (m/s) [10]; the multipliers of the rig's
  imperfections: viscous scale [11:14], Coulomb scale [14:17] (temperature), ripple amplitude
  [17] and period (m) [18].
  F_i = s_v f_v v + s_c (f_c + (f_s − f_c) exp(−(v/v_st)²)) (1 + r sin(2π q / p + 2πi/3))
  tanh(v/v_smooth).
* ``real`` (float64[N_REAL]): the unmodelled effects of ``rt.twin.realism`` (``R_*`` below);
  used by ``integrate_real`` only.
* ``env`` (float64[ENV_SIZE]): env[0] selects the environment (see ``ENV_*``), the rest its
  parameters (documented in ``rt.twin.environment``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rt.model.kernels import (
    TREE_MAPS_WORK,
    assemble_sc,
    fk_solve,
    tree_maps_drift_sc,
    tree_maps_work,
)
from rt.pointers import f64_view

ENV_FREE = 0.0
ENV_PLATE = 1.0
ENV_ANKLE = 2.0
#: Length of the environment parameter array.
ENV_SIZE = 24
#: Length of the environment's state array: [0] plate contact (1/0); ankle: [1:4] the joint's
#: moment on the foot about the ankle centre, [4:7] the shank's reaction force at the centre
#: (base frame, N m and N; limb weight not included).
ENV_STATE_SIZE = 8

B_M_SLIDER = 0
B_M_ROD = 1
B_C_ROD = 2
B_I_ROD = 5
B_M_PLAT = 14
B_C_PLAT = 15
B_I_PLAT = 18
B_SENSOR = 27
B_G = 30
B_J_REFL = 31
B_F_PER_A = 32
B_I_LIMIT = 33
B_AMP_GAIN = 34
B_STOP_LO = 35
B_STOP_HI = 36
B_STOP_K = 37
B_STOP_C = 38
B_J_REFL_AXES = 40
N_BODY_PARAMS = 44

N_FRICTION = 19

# The rig's imperfections (``real`` array), see rt.twin.realism.
R_AMP_ALPHA = 0          # current-loop lag per substep: 1 − exp(−h/τ) (1 = instantaneous)
R_AMP_DELAY_STEPS = 1    # transport delay: whole substeps (the fraction is R_AMP_DELAY_FRAC)
R_SCREW_K = 2            # screw stiffness (N/m); 0 = rigid (rotor lumped with the slider)
R_SCREW_C = 3            # screw damping (N s/m)
R_BACKLASH = 4           # total backlash (m)
R_BRAKE_ON = 5           # 1 while the holding brakes are engaged
R_BRAKE_HOLD = 6         # holding force at the slider (N)
R_CABLE_W = 7            # cable weight share on the platform at z_ref (N)
R_CABLE_K = 8            # cable stiffness (N/m of platform heave)
R_CABLE_Z = 9            # z_ref (m)
R_JR = 10                # per-axis rotor inertia at the slider (kg), 3 slots (compliant case)
R_AMP_MEAN = 13          # the lag's mean over a substep: (τ/h)(1 − exp(−h/τ)) (0 = instantaneous)
R_AMP_DELAY_FRAC = 14    # the transport delay's fraction of a substep beyond R_AMP_DELAY_STEPS
N_REAL = 15

STATUS_OK = 0
STATUS_FK_FAILED = 1

_FK_TOL = 1e-12
_FK_MAX_IT = 25


@njit(cache=True)
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True)
def drive_force(volts, bodies, out):
    """Screw force (N) per axis for amplifier command volts: current mode, current-limited."""
    gain = bodies[B_AMP_GAIN]
    limit = bodies[B_I_LIMIT]
    fpa = bodies[B_F_PER_A]
    for i in range(3):
        current = gain * volts[i]
        if current > limit:
            current = limit
        elif current < -limit:
            current = -limit
        out[i] = fpa * current


@njit(cache=True)
def friction_force(q, qd, friction, out):
    """Stribeck friction (N) per axis, smooth through zero velocity, with the temperature
    scales and the position ripple of the rig's imperfections (see module docstring)."""
    vst = friction[9]
    vsm = friction[10]
    ripple = friction[17]
    period = friction[18]
    for i in range(3):
        v = qd[i]
        viscous = friction[11 + i] * friction[i] * v
        if friction[14 + i] == 0.0:
            # No Coulomb part (the slider's share with a compliant screw: ``integrate_real``
            # applies it implicitly, every substep): 0 · level · tanh(v/v_smooth) is a zero
            # of v's sign, and so is ``viscous`` when v = ±0, so the sum is ``viscous`` to
            # the bit, without the exp, sin and tanh (issue 16).
            out[i] = viscous
            continue
        x = v / vst
        level = friction[3 + i] + (friction[6 + i] - friction[3 + i]) * math.exp(-x * x)
        if ripple != 0.0:
            level *= 1.0 + ripple * math.sin(2.0 * math.pi * q[i] / period
                                             + 2.0 * math.pi * i / 3.0)
        out[i] = viscous + friction[14 + i] * level * math.tanh(v / vsm)


@njit(cache=True)
def end_stop_force(q, qd, bodies):
    """Force (N) of the mechanical end stops at the ends of the ball-screw stroke: stiff,
    damped, one-sided (they push the slider back, never pull)."""
    lo = bodies[B_STOP_LO]
    hi = bodies[B_STOP_HI]
    f = 0.0
    if q > hi:
        f = -bodies[B_STOP_K] * (q - hi) - bodies[B_STOP_C] * qd
        f = min(f, 0.0)
    elif q < lo:
        f = -bodies[B_STOP_K] * (q - lo) - bodies[B_STOP_C] * qd
        f = max(f, 0.0)
    return f


WORK_SIZE = TREE_MAPS_WORK + 72


@njit(cache=True)
def mass_and_bias(geom, bodies, q, qd, phi, rot, pos, S, Sd, twist, M, h):
    """Actuated mass matrix M (kg) and bias forces h = C q̇ + G (N) at (q, q̇).

    ``phi`` must hold the solved rod angles; S, Ṡ and the twist map are filled here (Ṡ by
    ``tree_maps_work``: the bias takes Ṡ q̇ from ``tree_maps_drift_sc``).
    """
    mass_and_bias_work(geom, bodies, q, qd, phi, rot, pos, S, Sd, twist, M, h,
                       np.empty(WORK_SIZE))
    tree_maps_work(geom, q, phi, rot, qd, S, Sd, twist, np.empty(TREE_MAPS_WORK))


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
def mass_and_bias_work(geom, bodies, q, qd, phi, rot, pos, S, Sd, twist, M, h, work):
    """``mass_and_bias`` with caller-provided scratch (float64[WORK_SIZE]): no allocation.

    The congruences are factored — R I Rᵀ as (R I) Rᵀ, Aᵀ I A as Aᵀ (I A): 54 multiplications
    per body instead of ~900 (issue 16; the substep's largest cost before)."""
    extra = work[TREE_MAPS_WORK:]
    x = TREE_MAPS_WORK                  # the 3 × 3 views below: f64_view, not reshape
    spheres = f64_view(work, x, (3, 3))
    iw = f64_view(work, x + 9, (3, 3))
    av = f64_view(work, x + 27, (3, 3))
    aw = f64_view(work, x + 36, (3, 3))
    tmp = f64_view(work, x + 45, (3, 3))
    # The rod angles' sines and cosines once per substep, where the tree maps keep them
    # (work[0:6]): the assembly, the maps and the rods' inertia below all read them (the same
    # values as each computing its own: issue 16, 24 transcendental calls per substep → 6).
    for i in range(3):
        work[i] = math.sin(phi[i])
        work[3 + i] = math.cos(phi[i])
    assemble_sc(geom, q, work[0], work[3], work[1], work[4], work[2], work[5], rot, pos,
                spheres)
    sdq = extra[54:66]
    # S, the twist map and the drift Ṡ q̇ (all the bias needs of Ṡ) from the model's one
    # kernel (``rt.model.kernels``): Ṡ q̇ as the second-order term H(q̇, q̇) itself, not as
    # Ṡ's three columns dotted with q̇ (issue 16: a third of that work; equal to round-off).
    # ``Sd`` is not written (``mass_and_bias`` fills it for its callers).
    tree_maps_drift_sc(geom, q, rot, qd, S, sdq, twist, work)
    g = bodies[B_G]
    ms = bodies[B_M_SLIDER]
    for a in range(3):
        h[a] = ms * g
        for b in range(3):
            M[a, b] = 0.0
        M[a, a] = bodies[B_J_REFL_AXES + a] + ms
    # ---- rods: rotation about the leg tangent t_i, pivot moving with the slider.
    # R_rod = Rz(θ) Ry(φ) turns the rod about t = R ŷ, fixed in the base frame: every
    # angular velocity and acceleration of the rod lies along t. So its rotational share is
    # that of one scalar inertia, tᵀ (R I Rᵀ) t = ŷᵀ I ŷ = I_yy (about the COM): M += I_yy s sᵀ
    # and h += I_yy φ̈⁰ s, with s the row of φ̇ in S, and no gyroscopic term (t · (ω × I_w ω)
    # = 0 for ω ∥ t). The same dynamics as the full R I Rᵀ congruence, without it (issue 16:
    # equal to round-off, ``tests/test_twin.py`` against Pinocchio).
    mr = bodies[B_M_ROD]
    iyy = bodies[B_I_ROD + 4]
    cx = bodies[B_C_ROD]
    cy = bodies[B_C_ROD + 1]
    cz = bodies[B_C_ROD + 2]
    for i in range(3):
        ct = geom[3 + i]
        st = geom[6 + i]
        sp = work[i]
        cp = work[3 + i]
        # ρ = R c, with R's columns (ct cp, st cp, −sp), (−st, ct, 0), (ct sp, st sp, cp).
        rhox = ct * cp * cx - st * cy + ct * sp * cz
        rhoy = st * cp * cx + ct * cy + st * sp * cz
        rhoz = -sp * cx + cp * cz
        tx = -st
        ty = ct
        s0 = S[2 * i + 1, 0]
        s1 = S[2 * i + 1, 1]
        s2 = S[2 * i + 1, 2]
        # Columns: v_k = δ_ik ẑ + ω_k × ρ, ω_k = φ̇_ik t.
        for k in range(3):
            pd = S[2 * i + 1, k]
            vx, vy, vz = _cross(pd * tx, pd * ty, 0.0, rhox, rhoy, rhoz)
            if k == i:
                vz += 1.0
            av[0, k] = vx
            av[1, k] = vy
            av[2, k] = vz
        # Drift accelerations (q̈ = 0) for the actual q̇.
        phid = s0 * qd[0] + s1 * qd[1] + s2 * qd[2]
        phidd = sdq[2 * i + 1]
        wx = phid * tx
        wy = phid * ty
        a1x, a1y, a1z = _cross(phidd * tx, phidd * ty, 0.0, rhox, rhoy, rhoz)
        w1x, w1y, w1z = _cross(wx, wy, 0.0, rhox, rhoy, rhoz)
        a2x, a2y, a2z = _cross(wx, wy, 0.0, w1x, w1y, w1z)
        ax0 = a1x + a2x
        ay0 = a1y + a2y
        az0 = a1z + a2z + g            # a⁰ − g_vec with g_vec = (0, 0, −g)
        spin = iyy * phidd
        for a in range(3):
            sa_ = S[2 * i + 1, a]
            h[a] += mr * (av[0, a] * ax0 + av[1, a] * ay0 + av[2, a] * az0) + spin * sa_
            for b in range(3):
                M[a, b] += (mr * (av[0, a] * av[0, b] + av[1, a] * av[1, b]
                                  + av[2, a] * av[2, b]) + iyy * sa_ * S[2 * i + 1, b])
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
        vx, vy, vz = _cross(wx, wy, wz, rhox, rhoy, rhoz)
        av[0, k] = twist[0, k] + vx
        av[1, k] = twist[1, k] + vy
        av[2, k] = twist[2, k] + vz
        aw[0, k] = wx
        aw[1, k] = wy
        aw[2, k] = wz
    # Drift: origin acceleration from Ṡ, angular acceleration from the Euler-rate kinematics.
    pax = sdq[6]
    pay = sdq[7]
    paz = sdq[8]
    yd = 0.0
    pd = 0.0
    rd = 0.0
    ydd = sdq[9]
    pdd = sdq[10]
    rdd = sdq[11]
    wx = 0.0
    wy = 0.0
    wz = 0.0
    for k in range(3):
        yd += S[9, k] * qd[k]
        pd += S[10, k] * qd[k]
        rd += S[11, k] * qd[k]
        wx += twist[3, k] * qd[k]
        wy += twist[4, k] * qd[k]
        wz += twist[5, k] * qd[k]
    # The yaw's cosine and sine from R's first column, as ``tree_maps_sc`` takes them (not
    # through atan2, sin and cos: issue 16; the same angles to round-off).
    ca = rot[0, 0]
    sa = rot[1, 0]
    nrm = math.hypot(ca, sa)
    ca /= nrm
    sa /= nrm
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
    t1x, t1y, t1z = _cross(ox, oy, oz, egx, egy, egz)
    alx += rd * t1x
    aly += rd * t1y
    alz += rd * t1z
    a1x, a1y, a1z = _cross(alx, aly, alz, rhox, rhoy, rhoz)
    w1x, w1y, w1z = _cross(wx, wy, wz, rhox, rhoy, rhoz)
    a2x, a2y, a2z = _cross(wx, wy, wz, w1x, w1y, w1z)
    ax0 = pax + a1x + a2x
    ay0 = pay + a1y + a2y
    az0 = paz + a1z + a2z + g
    iwx = iw[0, 0] * wx + iw[0, 1] * wy + iw[0, 2] * wz
    iwy = iw[1, 0] * wx + iw[1, 1] * wy + iw[1, 2] * wz
    iwz = iw[2, 0] * wx + iw[2, 1] * wy + iw[2, 2] * wz
    gx, gy, gz = _cross(wx, wy, wz, iwx, iwy, iwz)
    tqx = iw[0, 0] * alx + iw[0, 1] * aly + iw[0, 2] * alz + gx
    tqy = iw[1, 0] * alx + iw[1, 1] * aly + iw[1, 2] * alz + gy
    tqz = iw[2, 0] * alx + iw[2, 1] * aly + iw[2, 2] * alz + gz
    for a in range(3):
        h[a] += mp * (av[0, a] * ax0 + av[1, a] * ay0 + av[2, a] * az0) \
            + aw[0, a] * tqx + aw[1, a] * tqy + aw[2, a] * tqz
    _add_mass(mp, av, aw, iw, tmp, M)


@njit(cache=True)
def environment_wrench(env, bodies, rot, pos, twist, qd, env_state, wrench_s, tau_env):
    """Wrench of the environment on the platform at the sensor origin, in the sensor frame
    (``wrench_s``: N, N m) and its actuator-space image τ_env = J_Sᵀ w_S (N)."""
    for k in range(6):
        wrench_s[k] = 0.0
    for k in range(3):
        tau_env[k] = 0.0
    kind = env[0]
    if kind == ENV_FREE:
        return
    # Sensor origin and its velocity in the base frame.
    sx = bodies[B_SENSOR]
    sy = bodies[B_SENSOR + 1]
    sz = bodies[B_SENSOR + 2]
    obx = rot[0, 0] * sx + rot[0, 1] * sy + rot[0, 2] * sz
    oby = rot[1, 0] * sx + rot[1, 1] * sy + rot[1, 2] * sz
    obz = rot[2, 0] * sx + rot[2, 1] * sy + rot[2, 2] * sz
    vx = 0.0
    vy = 0.0
    vz = 0.0
    wx = 0.0
    wy = 0.0
    wz = 0.0
    for k in range(3):
        vx += twist[0, k] * qd[k]
        vy += twist[1, k] * qd[k]
        vz += twist[2, k] * qd[k]
        wx += twist[3, k] * qd[k]
        wy += twist[4, k] * qd[k]
        wz += twist[5, k] * qd[k]
    ex, ey, ez = _cross(wx, wy, wz, obx, oby, obz)
    vox = vx + ex
    voy = vy + ey
    voz = vz + ez
    oz = pos[2] + obz
    fx = 0.0
    fy = 0.0
    fz = 0.0
    mx = 0.0
    my = 0.0
    mz = 0.0
    if kind == ENV_PLATE:
        # env: [1, z_plate, k_n, c_n, c_t, tool_length, k_t, mu]: the tool tip, ``tool_length``
        # along the sensor z axis above its origin, presses a horizontal rigidly-mounted plate
        # from below. Tangentially: viscous drag c_t, and with k_t > 0 static friction — a
        # spring k_t to where the tip stuck (env_state[1:3], base x, y), slipping when its force
        # exceeds mu times the normal force (the anchor is dragged to the friction cone's edge).
        tool = env[5]
        tipx = rot[0, 2] * tool
        tipy = rot[1, 2] * tool
        tipz = rot[2, 2] * tool
        depth = oz + tipz - env[1]
        if depth > 0.0:
            tvx, tvy, tvz = _cross(wx, wy, wz, tipx, tipy, tipz)
            vtz = voz + tvz
            fn = env[2] * depth + env[3] * vtz
            fn = max(fn, 0.0)                       # the contact pushes, never pulls
            fx = -env[4] * (vox + tvx)
            fy = -env[4] * (voy + tvy)
            k_t = env[6]
            if k_t > 0.0:
                px = pos[0] + obx + tipx
                py = pos[1] + oby + tipy
                if env_state[0] == 0.0:             # contact begins: the tip sticks here
                    env_state[1] = px
                    env_state[2] = py
                sx_ = -k_t * (px - env_state[1])
                sy_ = -k_t * (py - env_state[2])
                cone = env[7] * fn
                mag = math.sqrt(sx_ * sx_ + sy_ * sy_)
                if mag > cone:                      # slip: the anchor follows the tip
                    scale = cone / mag
                    sx_ *= scale
                    sy_ *= scale
                    env_state[1] = px + sx_ / k_t
                    env_state[2] = py + sy_ / k_t
                fx += sx_
                fy += sy_
            fz = -fn
            mx, my, mz = _cross(tipx, tipy, tipz, fx, fy, fz)
            env_state[0] = 1.0
        else:
            env_state[0] = 0.0
    elif kind == ENV_ANKLE:
        # env (rt.twin.environment.CompliantAnkle.pack): [2, A0(3), c(3), k_h, k_z, c_h, c_z,
        # K(3), D(3), roll0, pitch0, yaw0, end_roll, end_pitch, limb_weight]. A strapped foot
        # turning about its ankle joint centre A, ``c`` from the sensor origin (P axes); the
        # shank holds A near A0 (base frame) through translational springs-dampers, and the
        # joint resists rotation from neutral with a stiffness that rises towards the end of
        # range, τ = K θ (1 + (θ/θ_end)²), and viscous damping. Bilateral (strapped).
        cx = rot[0, 0] * env[4] + rot[0, 1] * env[5] + rot[0, 2] * env[6]
        cy = rot[1, 0] * env[4] + rot[1, 1] * env[5] + rot[1, 2] * env[6]
        cz = rot[2, 0] * env[4] + rot[2, 1] * env[5] + rot[2, 2] * env[6]
        dx = pos[0] + obx + cx - env[1]
        dy = pos[1] + oby + cy - env[2]
        dz = oz + cz - env[3]
        ax_, ay_, az_ = _cross(wx, wy, wz, cx, cy, cz)
        fx = -env[7] * dx - env[9] * (vox + ax_)
        fy = -env[7] * dy - env[9] * (voy + ay_)
        fz = -env[8] * dz - env[10] * (voz + az_)
        roll = math.atan2(rot[2, 1], rot[2, 2])
        pitch = math.atan2(-rot[2, 0], math.sqrt(rot[2, 1] ** 2 + rot[2, 2] ** 2))
        yaw = math.atan2(rot[1, 0], rot[0, 0])
        tr = roll - env[17]
        tp = pitch - env[18]
        ty = yaw - env[19]
        er = tr / env[20] if env[20] > 0.0 else 0.0
        ep = tp / env[21] if env[21] > 0.0 else 0.0
        ma_x = -env[11] * tr * (1.0 + er * er) - env[14] * wx
        ma_y = -env[12] * tp * (1.0 + ep * ep) - env[15] * wy
        ma_z = -env[13] * ty - env[16] * wz
        env_state[1] = ma_x
        env_state[2] = ma_y
        env_state[3] = ma_z
        env_state[4] = fx
        env_state[5] = fy
        env_state[6] = fz
        fz -= env[22]
        # The same wrench about the sensor origin O: m_O = m_A + (A - O) × f.
        mcx, mcy, mcz = _cross(cx, cy, cz, fx, fy, fz)
        mx = ma_x + mcx
        my = ma_y + mcy
        mz = ma_z + mcz
    # Express in the sensor frame (axes of P).
    for a in range(3):
        wrench_s[a] = rot[0, a] * fx + rot[1, a] * fy + rot[2, a] * fz
        wrench_s[3 + a] = rot[0, a] * mx + rot[1, a] * my + rot[2, a] * mz
    # τ_env,k = (v_k + ω_k × s_B) · f + ω_k · m  (power of the wrench for q̇ = e_k).
    for k in range(3):
        cx_, cy_, cz_ = _cross(twist[3, k], twist[4, k], twist[5, k], obx, oby, obz)
        tau_env[k] = ((twist[0, k] + cx_) * fx + (twist[1, k] + cy_) * fy
                      + (twist[2, k] + cz_) * fz
                      + twist[3, k] * mx + twist[4, k] * my + twist[5, k] * mz)


@njit(cache=True)
def acceleration(geom, bodies, friction, env, q, qd, phi, force, env_state, qdd, wrench_s,
                 work_rot, work_pos, S, Sd, twist, M, h, tau_env, fr, work):
    """q̈ (m/s²) for screw forces ``force`` (N); returns a status (FK failure -> 1)."""
    it = fk_solve(geom, q, phi, _FK_TOL, _FK_MAX_IT)
    if it < 0:
        return STATUS_FK_FAILED
    mass_and_bias_work(geom, bodies, q, qd, phi, work_rot, work_pos, S, Sd, twist, M, h, work)
    environment_wrench(env, bodies, work_rot, work_pos, twist, qd, env_state, wrench_s, tau_env)
    friction_force(q, qd, friction, fr)
    r0 = force[0] - h[0] - fr[0] + tau_env[0] + end_stop_force(q[0], qd[0], bodies)
    r1 = force[1] - h[1] - fr[1] + tau_env[1] + end_stop_force(q[1], qd[1], bodies)
    r2 = force[2] - h[2] - fr[2] + tau_env[2] + end_stop_force(q[2], qd[2], bodies)
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


INTEGRATOR_SYMPLECTIC_EULER = 0
INTEGRATOR_RK4 = 1


@njit(cache=True)
def integrate(geom, bodies, friction, env, q, qd, phi, volts, n_steps, h_step, integrator,
              env_state, qdd, wrench_s):
    """Advance (q, q̇) by ``n_steps`` substeps of ``h_step`` s with the drives held at ``volts``.

    ``integrator`` 0: semi-implicit (symplectic) Euler, q̇ += h q̈ then q += h q̇ — one dynamics
    evaluation per substep, energy error bounded (no drift) for the conservative part.
    1: classical Runge-Kutta 4 — four evaluations, O(h⁴) for accuracy checks.
    ``qdd`` and ``wrench_s`` are left as evaluated at the start of the last substep (Euler) or at
    the final state (RK4). Returns a status (0 ok, 1 forward kinematics failed).
    """
    force = np.empty(3)
    drive_force(volts, bodies, force)
    rot = np.empty((3, 3))
    pos = np.empty(3)
    S = np.empty((12, 3))
    Sd = np.empty((12, 3))
    twist = np.empty((6, 3))
    M = np.empty((3, 3))
    hb = np.empty(3)
    tau_env = np.empty(3)
    fr = np.empty(3)
    work = np.empty(WORK_SIZE)
    if integrator == INTEGRATOR_SYMPLECTIC_EULER:
        for _ in range(n_steps):
            st = acceleration(geom, bodies, friction, env, q, qd, phi, force, env_state, qdd,
                              wrench_s, rot, pos, S, Sd, twist, M, hb, tau_env, fr, work)
            if st != STATUS_OK:
                return st
            for i in range(3):
                qd[i] += h_step * qdd[i]
                q[i] += h_step * qd[i]
    else:
        q0 = np.empty(3)
        v0 = np.empty(3)
        qs = np.empty(3)
        vs = np.empty(3)
        k1 = np.empty(3)
        k2 = np.empty(3)
        k3 = np.empty(3)
        k4 = np.empty(3)
        for _ in range(n_steps):
            for i in range(3):
                q0[i] = q[i]
                v0[i] = qd[i]
            st = acceleration(geom, bodies, friction, env, q0, v0, phi, force, env_state, k1,
                              wrench_s, rot, pos, S, Sd, twist, M, hb, tau_env, fr, work)
            for i in range(3):
                qs[i] = q0[i] + 0.5 * h_step * v0[i]
                vs[i] = v0[i] + 0.5 * h_step * k1[i]
            st += acceleration(geom, bodies, friction, env, qs, vs, phi, force, env_state, k2,
                               wrench_s, rot, pos, S, Sd, twist, M, hb, tau_env, fr, work)
            v2 = vs.copy()
            for i in range(3):
                qs[i] = q0[i] + 0.5 * h_step * v2[i]
                vs[i] = v0[i] + 0.5 * h_step * k2[i]
            st += acceleration(geom, bodies, friction, env, qs, vs, phi, force, env_state, k3,
                               wrench_s, rot, pos, S, Sd, twist, M, hb, tau_env, fr, work)
            v3 = vs.copy()
            for i in range(3):
                qs[i] = q0[i] + h_step * v3[i]
                vs[i] = v0[i] + h_step * k3[i]
            st += acceleration(geom, bodies, friction, env, qs, vs, phi, force, env_state, k4,
                               wrench_s, rot, pos, S, Sd, twist, M, hb, tau_env, fr, work)
            if st != STATUS_OK:
                return STATUS_FK_FAILED
            v4 = vs
            for i in range(3):
                q[i] = q0[i] + h_step / 6.0 * (v0[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i])
                qd[i] = v0[i] + h_step / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        # Leave q̈ and the wrench consistent with the final state.
        return acceleration(geom, bodies, friction, env, q, qd, phi, force, env_state, qdd,
                            wrench_s, rot, pos, S, Sd, twist, M, hb, tau_env, fr, work)
    return STATUS_OK


@njit(cache=True)
def drive_current(volts, bodies, out):
    """Current command (A) per axis for amplifier inputs ``volts``: gain, current-limited."""
    gain = bodies[B_AMP_GAIN]
    limit = bodies[B_I_LIMIT]
    for i in range(3):
        c = gain * volts[i]
        out[i] = limit if c > limit else (max(c, -limit))


@njit(cache=True)
def coulomb_level(q, v, friction, i):
    """Axis i's Coulomb/Stribeck friction level (N, ≥ 0) at position q and velocity v."""
    x = v / friction[9]
    level = friction[3 + i] + (friction[6 + i] - friction[3 + i]) * math.exp(-x * x)
    ripple = friction[17]
    if ripple != 0.0:
        level *= 1.0 + ripple * math.sin(2.0 * math.pi * q / friction[18]
                                         + 2.0 * math.pi * i / 3.0)
    return friction[14 + i] * level


#: Projected Gauss-Seidel sweeps of :func:`coulomb_step` at most (the 3 × 3 problem converges
#: by ≈ 10× per sweep: the slider side's mass matrix is diagonally dominant, off-diagonal ≤ 10 %).
COULOMB_SWEEPS = 30


@njit(cache=True)
def _clamp(x, lim):
    return lim if x > lim else max(x, -lim)


@njit(cache=True)
def coulomb_step(M, qd, qdd, h_step, l0, l1, l2):
    """q̇ ← q̇ + h q̈ with the Coulomb/Stribeck friction of levels ``l0..l2`` (N) applied
    implicitly, through the **coupled** mass matrix M: the friction impulses p (|p_i| ≤ h l_i)
    change the velocities by M⁻¹ p, and an axis either slides with p_i = h l_i sign(q̇_i) or
    sticks (q̇_i = 0 exactly, |p_i| < h l_i). A box-constrained problem with M⁻¹ symmetric
    positive definite, solved by projected Gauss-Seidel.

    Why coupled: a force on one slider accelerates all three through the rods and the platform
    (M⁻¹ is not diagonal; the slider side alone, without the rotors behind the compliant screw,
    has off-diagonal terms of 7-8 % of the diagonal). Applying axis i's impulse as p_i / M_ii to
    axis i alone — what this step did first — is the generalised force M diag(1/M_ii) F: it
    added 7-8 % of each *other* axis's slider-side Coulomb force to every axis, a cross-coupled
    friction no rig has (it biased identification, issue 15: ``bench/identification.py``)."""
    c00 = M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]
    c01 = M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]
    c02 = M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]
    det = M[0, 0] * c00 + M[0, 1] * c01 + M[0, 2] * c02
    a00 = c00 / det
    a01 = (M[0, 2] * M[2, 1] - M[0, 1] * M[2, 2]) / det
    a02 = (M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1]) / det
    a11 = (M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]) / det
    a12 = (M[0, 2] * M[1, 0] - M[0, 0] * M[1, 2]) / det
    a22 = (M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]) / det
    v0 = qd[0] + h_step * qdd[0]
    v1 = qd[1] + h_step * qdd[1]
    v2 = qd[2] + h_step * qdd[2]
    b0 = h_step * l0
    b1 = h_step * l1
    b2 = h_step * l2
    p0 = 0.0
    p1 = 0.0
    p2 = 0.0
    tol = 1e-12 * (b0 + b1 + b2)
    for _ in range(COULOMB_SWEEPS):
        n0 = _clamp((v0 - a01 * p1 - a02 * p2) / a00, b0)
        n1 = _clamp((v1 - a01 * n0 - a12 * p2) / a11, b1)
        n2 = _clamp((v2 - a02 * n0 - a12 * n1) / a22, b2)
        change = abs(n0 - p0) + abs(n1 - p1) + abs(n2 - p2)
        p0 = n0
        p1 = n1
        p2 = n2
        if change <= tol:
            break
    # An axis whose impulse is inside its bound sticks: exactly at rest.
    qd[0] = 0.0 if abs(p0) < b0 else v0 - a00 * p0 - a01 * p1 - a02 * p2
    qd[1] = 0.0 if abs(p1) < b1 else v1 - a01 * p0 - a11 * p1 - a12 * p2
    qd[2] = 0.0 if abs(p2) < b2 else v2 - a02 * p0 - a12 * p1 - a22 * p2


@njit(cache=True)
def _toward_zero(v, dv):
    """A Coulomb force that can remove at most ``dv`` of velocity this step: sticks at 0."""
    if v > dv:
        return v - dv
    if v < -dv:
        return v + dv
    return 0.0


@njit(cache=True)
def integrate_real(geom, bodies, friction, friction_motor, env, real, q, qd, phi, xm, vm, current,
                   cable_tau, volts, volts_prev, delay_steps, n_steps, h_step, env_state, qdd,
                   wrench_s, rot_out):
    """Semi-implicit Euler with the rig's imperfections (``real``, see ``R_*``).

    State beyond (q, q̇): motor positions/velocities at the slider ``xm``, ``vm`` (m, m/s; equal
    to q, q̇ when the screw is rigid), motor currents ``current`` (A), and the cable's actuator
    forces ``cable_tau`` (N, from the previous substep's pose: the cable changes slowly).
    The amplifiers see ``volts_prev`` for the first ``delay_steps`` substeps, then ``volts``
    (the substep in which the delay ends sees both, weighted by ``R_AMP_DELAY_FRAC``: the
    fraction of a substep the delay lasts beyond ``delay_steps``). The current loop is the
    exact first-order lag over each substep of constant input: the drive applies the current's
    *mean* over the substep and ``current`` ends at its value at the substep's end (applying
    the value at the substep's start, as before, realised half the loop's lag).
    With a compliant screw, ``bodies`` must carry zero rotor inertia (the rotors are integrated
    here with ``real[R_JR:R_JR+3]``), ``friction`` is the slider side's share (guides, seals)
    and ``friction_motor`` the motor side's (screw bearings, nut drag), acting on v_m. The
    slider is light (a few kg) and its stiction is sharp (≈ 1e5-1e6 N s/m near zero), beyond
    what an explicit step can integrate at 5 kHz: its Coulomb/Stribeck part is applied
    implicitly through the coupled mass matrix (:func:`coulomb_step`, with exact stick), its
    viscous part explicitly. Brakes remove at most hold·h/m of velocity per substep
    (exact stick when the net force is below the holding force).
    """
    cmd_new = np.empty(3)
    cmd_old = np.empty(3)
    drive_current(volts, bodies, cmd_new)
    drive_current(volts_prev, bodies, cmd_old)
    force = np.empty(3)
    spring = np.zeros(3)
    rot = np.empty((3, 3))
    pos = np.empty(3)
    S = np.empty((12, 3))
    Sd = np.empty((12, 3))
    twist = np.empty((6, 3))
    M = np.empty((3, 3))
    hb = np.empty(3)
    tau_env = np.empty(3)
    fr = np.empty(3)
    frm = np.zeros(3)
    applied = np.empty(3)
    work = np.empty(WORK_SIZE)
    viscous_only = friction.copy()
    viscous_only[14:17] = 0.0
    fpa = bodies[B_F_PER_A]
    decay = 1.0 - real[R_AMP_ALPHA]
    mean = real[R_AMP_MEAN]
    frac = real[R_AMP_DELAY_FRAC]
    k = real[R_SCREW_K]
    c = real[R_SCREW_C]
    half_b = 0.5 * real[R_BACKLASH]
    brake = real[R_BRAKE_ON] > 0.5
    hold = real[R_BRAKE_HOLD]
    cable_w = real[R_CABLE_W]
    cable_k = real[R_CABLE_K]
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
        st = acceleration(geom, bodies, viscous_only if k > 0.0 else friction, env, q, qd, phi,
                          force, env_state, qdd, wrench_s, rot, pos, S, Sd, twist, M, hb,
                          tau_env, fr, work)
        if st != STATUS_OK:
            return st
        if k > 0.0:
            friction_force(xm, vm, friction_motor, frm)
            coulomb_step(M, qd, qdd, h_step, coulomb_level(q[0], qd[0], friction, 0),
                         coulomb_level(q[1], qd[1], friction, 1),
                         coulomb_level(q[2], qd[2], friction, 2))
        for i in range(3):
            if k > 0.0:
                q[i] += h_step * qd[i]
                jr = real[R_JR + i]
                v = vm[i] + h_step * (fpa * applied[i] - spring[i] - frm[i]) / jr
                if brake:
                    v = _toward_zero(v, h_step * hold / jr)
                vm[i] = v
                xm[i] += h_step * v
            else:
                v = qd[i] + h_step * qdd[i]
                if brake:
                    v = _toward_zero(v, h_step * hold / M[i, i])
                qd[i] = v
                q[i] += h_step * v
                xm[i] = q[i]
                vm[i] = v
        if cable:
            # Vertical pull at the platform origin: weight share plus the loop's stiffness.
            fz = -(cable_w + cable_k * (pos[2] - real[R_CABLE_Z]))
            for j in range(3):
                cable_tau[j] = twist[2, j] * fz
    for a in range(3):
        for b in range(3):
            rot_out[a, b] = rot[a, b]
    return STATUS_OK
