"""The position laws' arithmetic compiled with numba (one call per cycle and law).

Each kernel is the compiled twin of a law's interpreted ``_law`` in ``rt.control.laws`` /
``rt.control.adaptive``, which stay as the reference implementation
(``create(..., compiled=False)``); ``tests/test_compiled_cycle.py`` replays recorded cycles
through both and holds them within 1e-12 (relative to the force's scale). The model terms come
from ``rt.model.rigid_body`` (RNEA on the tree, projected with S): M q̈ + C q̇ + G is formed as
products, never as matrices. Arguments are the packed model (``ti``, ``tf``), the cycle's
``State.buf``, the reference's q, q̇, q̈ (m, m/s, m/s²) and a float64 ``gains`` array; τ (N) is
written into ``out``; nothing is allocated.
"""
from __future__ import annotations

import math

from numba import njit

from rt.model import rigid_body as rb
from rt.model.kernels import MODEL_STATE_WORK, inv3, model_state
from rt.pointers import f64_view

#: ``gains`` layouts: PD-family [Kp (N/m), Kd (N s/m)]; computed torque [Kp (1/s²), Kd (1/s)];
#: PID [Kp, Kd, Ki (N/(m s)), integral limit (N)]; adaptive [Λ (1/s), K_D (N s/m)].


@njit(cache=True)
def pd(stb, rq, rqd, kp, kd, out):
    """out = −Kp e − Kd ė (N), e = q − q_d."""
    q = stb[rb.STATE_Q_ACT:rb.STATE_Q_ACT + 3]
    qd = stb[rb.STATE_QD:rb.STATE_QD + 3]
    for i in range(3):
        e = q[i] - rq[i]
        out[i] = -kp * e - kd * (qd[i] - rqd[i])


@njit(cache=True)
def paden_panja(ti, tf, stb, rq, rqd, rqdd, gains, work, out):
    """τ = M q̈_d + C(q, q̇) q̇_d + G + F(q̇_d) − Kp e − Kd ė (thesis eq. 19)."""
    pi = rb.unpack_tree(ti, tf)[5]
    ff = work[0:3]
    rb.mixed_torque(ti, tf, pi, stb, rqdd, rqd, True, work[3:], ff)
    rb.friction(ti, tf, rqd, ff)
    pd(stb, rq, rqd, gains[0], gains[1], out)
    for i in range(3):
        out[i] += ff[i]


@njit(cache=True)
def pd_gravity(ti, tf, stb, rq, rqd, gains, work, out):
    """τ = −Kp e − Kd ė + G(q) (PD+G)."""
    pi = rb.unpack_tree(ti, tf)[5]
    g = work[0:3]
    zero = work[3:6]
    zero[0] = 0.0
    zero[1] = 0.0
    zero[2] = 0.0
    rb.mixed_torque(ti, tf, pi, stb, zero, zero, True, work[6:], g)
    pd(stb, rq, rqd, gains[0], gains[1], out)
    for i in range(3):
        out[i] += g[i]


#: PD+G0's state ``g0`` (float64): the q_d of the cached G (3), 1 when it is valid, G (3, N),
#: the FK step tolerance (rad) and iteration limit, zeros (3, q̇ = 0 for the FK at q_d).
G0_QD, G0_VALID, G0_G, G0_TOL, G0_MAXIT, G0_ZERO = 0, 3, 4, 7, 8, 9
G0_SIZE = 12


def g0_scratch_size(work_size: int) -> int:
    """float64 scratch of :func:`pd_gravity_desired`: a State buffer for q_d, the FK's work
    and the dynamics' ``work_size``."""
    return rb.STATE_SIZE + MODEL_STATE_WORK + work_size


@njit(cache=True)
def pd_gravity_desired(ti, tf, geom, limits, phi, stb, rq, rqd, gains, g0, scratch, out):
    """τ = −Kp e − Kd ė + G(q_d) (PD+G0). G at the desired position is cached in ``g0``
    (layout ``G0_*``) while q_d holds; a new q_d solves FK there into a State buffer at the
    head of ``scratch`` (``model_state`` with the model's shared warm start ``phi``, q̇ = 0) and
    computes G. Returns the FK status (< 0: no FK at q_d; τ is not written). Twelve arguments
    (was eighteen): numba's dispatch costs per argument, more than this law's arithmetic."""
    if not (g0[G0_VALID] != 0.0 and rq[0] == g0[G0_QD] and rq[1] == g0[G0_QD + 1]
            and rq[2] == g0[G0_QD + 2]):
        std = scratch[0:rb.STATE_SIZE]
        mwork = scratch[rb.STATE_SIZE:rb.STATE_SIZE + MODEL_STATE_WORK]
        work = scratch[rb.STATE_SIZE + MODEL_STATE_WORK:]
        status = model_state(geom, limits, phi, rq, g0[G0_ZERO:G0_ZERO + 3], std,
                             g0[G0_TOL], int(g0[G0_MAXIT]), mwork)
        if status < 0:
            return status
        gravity(ti, tf, std, work, g0[G0_G:G0_G + 3])
        g0[G0_QD] = rq[0]
        g0[G0_QD + 1] = rq[1]
        g0[G0_QD + 2] = rq[2]
        g0[G0_VALID] = 1.0
    pd(stb, rq, rqd, gains[0], gains[1], out)
    for i in range(3):
        out[i] += g0[G0_G + i]
    return 0


@njit(cache=True)
def gravity(ti, tf, stb, work, out):
    """out = G(q) (N) at the state's configuration."""
    pi = rb.unpack_tree(ti, tf)[5]
    zero = work[0:3]
    zero[0] = 0.0
    zero[1] = 0.0
    zero[2] = 0.0
    rb.mixed_torque(ti, tf, pi, stb, zero, zero, True, work[3:], out)


@njit(cache=True)
def computed_torque(ti, tf, stb, rq, rqd, rqdd, gains, trajectory, work, out):
    """τ = M v + C q̇ + G + F(q̇) with v = q̈_d − Kd ė − Kp e (``trajectory``, eq. 31) or
    v = −Kd q̇ − Kp e (regulation, eq. 29)."""
    pi = rb.unpack_tree(ti, tf)[5]
    q = stb[rb.STATE_Q_ACT:rb.STATE_Q_ACT + 3]
    qd = stb[rb.STATE_QD:rb.STATE_QD + 3]
    v = work[0:3]
    kp = gains[0]
    kd = gains[1]
    for i in range(3):
        if trajectory:
            v[i] = rqdd[i] - kd * (qd[i] - rqd[i]) - kp * (q[i] - rq[i])
        else:
            v[i] = -kd * qd[i] - kp * (q[i] - rq[i])
    # M v + C(q, q̇) q̇ + G: one RNEA pass at the state's velocity (``rb.inverse_dynamics``).
    rb.inverse_dynamics(ti, tf, pi, stb, v, work[3:], out)
    rb.friction(ti, tf, qd, out)


@njit(cache=True)
def pid(stb, rq, rqd, gains, integral, dt, dry_run, out):
    """τ = −Kp e − Kd ė − Ki ∫e, the integral clamped to ±limit/Ki (anti-windup)."""
    pd(stb, rq, rqd, gains[0], gains[1], out)
    ki = gains[2]
    limit = gains[3] / ki if ki > 0 else 0.0
    q = stb[rb.STATE_Q_ACT:rb.STATE_Q_ACT + 3]
    for i in range(3):
        integ = integral[i] + (q[i] - rq[i]) * dt
        integ = max(-limit, min(limit, integ))
        if not dry_run:
            integral[i] = integ
        out[i] -= ki * integ


# Adaptive law: ``amap`` (int64) = [n_base, n_rigid, n_drive, rigid_pos, rigid_joint,
# rigid_param, drive_pos, drive_kind (0 J_r, 1 f_v, 2 f_c), drive_axis]; ``est`` (float64) =
# [θ̂, Γ, θ_lo, θ_hi, Yᵀ s] (n_base each), the n × 10 tree parameters of θ̂, s, q̇_r, q̈_r (3
# each), the gains [Λ (1/s), K_D (N s/m)], then the dynamics' scratch (``adaptive_est_size``).
# Two arrays for everything the law keeps: numba's dispatch costs per argument.
AMAP_HEAD = 3


def adaptive_est_size(nb: int, n: int) -> int:
    """Length of the adaptive law's ``est`` array for ``nb`` base parameters on an n-joint
    tree."""
    return 5 * nb + rb.N_PARAMS * n + 9 + 2 + 8 + rb.work_size(n)


@njit(cache=True)
def adaptive(ti, tf, stb, rq, rqd, rqdd, amap, est, dt, dry_run, out):
    """Slotine-Li with projection: τ = Y θ̂ − K_D s; θ̂ −= Γ Yᵀ s dt, clipped to its box.

    Y θ̂ is an RNEA with θ̂'s parameters on the bodies (three passes, the mixed regressor's
    Christoffel form) and Yᵀ s the parameter gradient of those passes against the bodies'
    velocities for joint rates S s (``rb.param_gradient``, in closed form)."""
    parent, kind, axis, prot, ptrans, _, g, _, _, _, vs = rb.unpack_tree(ti, tf)
    n = parent.shape[0]
    nb = amap[0]
    theta = est[0:nb]
    gamma = est[nb:2 * nb]
    lo = est[2 * nb:3 * nb]
    hi = est[3 * nb:4 * nb]
    ys = est[4 * nb:5 * nb]
    o = 5 * nb
    pith = f64_view(est, o, (n, rb.N_PARAMS))
    o += rb.N_PARAMS * n
    s = est[o:o + 3]
    qd_r = est[o + 3:o + 6]
    qdd_r = est[o + 6:o + 9]
    lam = est[o + 9]
    kd = est[o + 10]
    work = est[o + 11:]
    R, p, v, a, f, tau, V, A, tmp, u, ua, _, grad, e, zero3 = rb.unpack_work(work, n)
    Q, Qd, qd, S, Sd, _, _, q, _ = rb.unpack_state(stb)
    for i in range(3):
        ei = q[i] - rq[i]
        edi = qd[i] - rqd[i]
        s[i] = edi + lam * ei
        qd_r[i] = rqd[i] - lam * ei
        qdd_r[i] = rqdd[i] - lam * edi
    n_rigid = amap[1]
    n_drive = amap[2]
    o = AMAP_HEAD
    for k in range(n * rb.N_PARAMS):
        pith[k // rb.N_PARAMS, k % rb.N_PARAMS] = 0.0
    for r in range(n_rigid):
        pith[amap[o + n_rigid + r], amap[o + 2 * n_rigid + r]] = theta[amap[o + r]]
    zero3[0] = 0.0
    zero3[1] = 0.0
    zero3[2] = 0.0
    rb.tree_kinematics(parent, kind, axis, prot, ptrans, Q, R, p)
    # u: the bodies' velocities for joint rates S s (the virtual displacement of Yᵀ s).
    for j in range(n):
        V[j] = S[j, 0] * s[0] + S[j, 1] * s[1] + S[j, 2] * s[2]
        A[j] = 0.0
    rb.forward_pass(parent, kind, axis, R, p, V, A, zero3, u, ua)
    for j in range(n):
        for k in range(rb.N_PARAMS):
            grad[j, k] = 0.0
    # Pass 1: M_t (S q̈_r + Ṡ q̇_r) + g_t.
    for j in range(n):
        V[j] = 0.0
        A[j] = (S[j, 0] * qdd_r[0] + S[j, 1] * qdd_r[1] + S[j, 2] * qdd_r[2]
                + Sd[j, 0] * qd_r[0] + Sd[j, 1] * qd_r[1] + Sd[j, 2] * qd_r[2])
    rb.rnea(parent, kind, axis, R, p, pith, V, A, g, v, a, f, tmp)
    rb.param_gradient(v, a, u, 1.0, grad, e)
    for j in range(n):
        tau[j] = tmp[j]
        A[j] = 0.0
    # Passes 2, 3: ¼ [h(S(q̇ + q̇_r)) − h(S(q̇ − q̇_r))] = Γ_t(S q̇, S q̇_r).
    for sign in (1.0, -1.0):
        for j in range(n):
            V[j] = Qd[j] + sign * (S[j, 0] * qd_r[0] + S[j, 1] * qd_r[1] + S[j, 2] * qd_r[2])
        rb.rnea(parent, kind, axis, R, p, pith, V, A, zero3, v, a, f, tmp)
        rb.param_gradient(v, a, u, 0.25 * sign, grad, e)
        for j in range(n):
            tau[j] += 0.25 * sign * tmp[j]
    for i in range(3):
        acc = 0.0
        for j in range(n):
            acc += S[j, i] * tau[j]
        out[i] = acc
    for r in range(n_rigid):
        ys[amap[o + r]] = grad[amap[o + n_rigid + r], amap[o + 2 * n_rigid + r]]
    o += 3 * n_rigid
    for r in range(n_drive):
        pos = amap[o + r]
        kind_d = amap[o + n_drive + r]
        ax = amap[o + 2 * n_drive + r]
        if kind_d == 0:
            value = qdd_r[ax]
        elif kind_d == 1:
            value = qd_r[ax]
        else:
            value = math.tanh(qd_r[ax] / vs)
        out[ax] += theta[pos] * value
        ys[pos] = s[ax] * value
    for i in range(3):
        out[i] -= kd * s[i]
    if not dry_run and dt > 0.0:
        for k in range(nb):
            theta[k] -= ys[k] * gamma[k] * dt
            theta[k] = min(max(theta[k], lo[k]), hi[k])


_warm = False


def warm_up(dyn) -> None:
    """Compile (or load from numba's cache) every law's kernel now, at construction, never in
    a cycle: a first call compiles for seconds. Runs once per process on a state built from IK
    at the home pose (the model's FK warm start is not touched)."""
    global _warm
    if _warm:
        return
    import numpy as np

    from rt.model.dynamics import State
    from rt.model.kernels import TREE_DOF

    kin = dyn.kin
    cfg = kin.ik(0.5 * (kin.stroke[0] + kin.stroke[1]) + 0.45, 0.0, 0.0, check=False)
    st = dyn.state(np.array(cfg.q), np.zeros(3), out=State(), cfg=cfg)
    out = np.zeros(3)
    gains = np.ones(4)
    work = np.zeros(8 + rb.work_size(TREE_DOF))
    ti, tf = dyn.tree_i, dyn.tree_f
    amap = np.array([0, 0, 0], dtype=np.int64)
    est = np.zeros(adaptive_est_size(0, TREE_DOF))
    writable = np.zeros(3)
    read_only = np.zeros(3)
    read_only.flags.writeable = False
    # Both array flavours numba types apart: the loop's references are read-only port views,
    # a law hosted by another (the hybrid force law) may pass writable arrays.
    for z3 in (read_only, writable):
        paden_panja(ti, tf, st.buf, z3, z3, z3, gains, work, out)
        pd_gravity(ti, tf, st.buf, z3, z3, gains, work, out)
        computed_torque(ti, tf, st.buf, z3, z3, z3, gains, True, work, out)
        pid(st.buf, z3, z3, gains, np.zeros(3), 1e-3, True, out)
        adaptive(ti, tf, st.buf, z3, z3, z3, amap, est, 1e-3, True, out)
    gravity(ti, tf, st.buf, work, out)
    for z3 in (read_only, writable):
        g0 = np.zeros(G0_SIZE)
        g0[G0_TOL] = 1e-12
        g0[G0_MAXIT] = 50
        pd_gravity_desired(ti, tf, kin.geom, kin.limits_array, kin._phi_guess.copy(), st.buf,
                           np.array(cfg.q) if z3 is writable else _ro(np.array(cfg.q)), z3,
                           gains, g0, np.zeros(g0_scratch_size(work.shape[0])), out)
    fg = np.ones(FG_SIZE)
    fs = np.ones(FS_SIZE)
    explicit_force(ti, tf, st.buf, fg, fs, 100.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                   1e-3, np.zeros(30 + rb.work_size(TREE_DOF)), out)
    _warm = True


def _ro(a):
    """A read-only view of ``a`` (as the loop's port views)."""
    v = a.view()
    v.flags.writeable = False
    return v


# Explicit force law (``rt.control.force.ExplicitForce``). ``fg`` (float64) = [Kp, Ki, D,
# integral limit, angle Kp, angle Kd, stiffness guess, estimate stiffness (0/1), forgetting,
# preload, max ż_ff, max z̈_ff, axis inertia, drive force limit (N; ≤ 0: none), gain-schedule
# stiffness k_s (N/m), angle Ki (N m/(rad s)), angle integral limit (N m), friction
# compensation (fraction of the believed Coulomb level), its deadband (N), approach force
# margin (N; ≤ 0: the approach unbounded)]; ``fs`` (float64) = [∫e, last z, k̂, RLS θ (2),
# RLS P (2×2 row-major), ∫ roll error, ∫ pitch error, the stiffness the approach expects
# (N/m), touched (1: the contact was made since the force-mode entry, the approach's bound
# is off until the next entry; 0: armed)]; the reference as scalars.
FS_INTEGRAL, FS_LAST_Z, FS_K, FS_THETA, FS_P, FS_ANGLE_I, FS_K_APPROACH = 0, 1, 2, 3, 5, 9, 11
FS_TOUCHED = 12
FS_SIZE = 13
FG_SIZE = 20
#: The measured force (N) past which the contact counts as loaded: the stiffness estimate
#: learns only there (F ≈ k z + c holds once the tool or the heel pad is pressed, not while it
#: still closes a gap on sensor noise), and a remembered stiffness is applied from there
#: (``rt.components.protocol_blocks.HybridController``).
CONTACT_LOADED_N = 50.0
#: The measured force (N) past which the tool (or the foot) touches: until the first cycle
#: above it after a force-mode entry the approach is bounded (:func:`approach_speed`), never
#: again within that entry (the latch ``FS_TOUCHED``). 8σ of the ATI's z noise (0.25 N), so
#: noise alone does not release the bound while a gap closes; well under the preload (10 N)
#: a gait's swing holds, so a foot resting on the platform at the preload is not bounded
#: (bounding at the preload slowed the heel strikes: real-C3D RMS +3.5-6 %).
CONTACT_TOUCH_N = 2.0


@njit(cache=True)
def explicit_force(ti, tf, stb, fg, fs, force_n, f_ref, f_dot_ref, f_ddot_ref, roll_ref,
                   pitch_ref, roll_rate_ref, pitch_rate_ref, hold, dt, work, out):
    """Hybrid explicit force in z, PD on roll and pitch, G and the motion feedforward.
    ``hold`` ≠ 0: the reference is a transient beyond the robot; the integral holds."""
    Q, _, qd, S, _, _, _, _, _ = rb.unpack_state(stb)
    z = Q[8]
    pitch = Q[10]
    roll = Q[11]
    zd = S[8, 0] * qd[0] + S[8, 1] * qd[1] + S[8, 2] * qd[2]
    rd = S[11, 0] * qd[0] + S[11, 1] * qd[1] + S[11, 2] * qd[2]
    pd_ = S[10, 0] * qd[0] + S[10, 1] * qd[1] + S[10, 2] * qd[2]
    floor = fg[9]
    f_d = f_ref
    f_dot = f_dot_ref
    f_ddot = f_ddot_ref
    if not f_d > floor:
        f_d = floor
        f_dot = 0.0
        f_ddot = 0.0
    k = fs[FS_K]
    vmax = fg[10]
    z_dot_ff = max(-vmax, min(vmax, f_dot / k))
    amax = fg[11]
    z_ddot_ff = max(-amax, min(amax, f_ddot / k)) if abs(f_dot / k) < vmax else 0.0
    integral = fs[FS_INTEGRAL]
    ki = fg[1]
    sched = gain_schedule(fg[14], k)
    kp = (1.0 + fg[0]) * sched - 1.0 if sched < 1.0 else fg[0]
    kp = max(0.0, kp)
    if not math.isnan(force_n):
        e = f_d - force_n
        limit = fg[3] / ki if ki > 0 else 0.0
        if hold == 0.0:
            integral = max(-limit, min(limit, integral + sched * e * dt))
        if fg[7] != 0.0 and force_n > CONTACT_LOADED_N:
            last_z = fs[FS_LAST_Z]
            if not math.isnan(last_z) and abs(z - last_z) > 1e-7:
                # RLS of F ≈ k z + c with forgetting (``rt.control.force._Rls.update``).
                lam = fg[8]
                phi0 = z
                phi1 = 1.0
                p00 = fs[FS_P]
                p01 = fs[FS_P + 1]
                p10 = fs[FS_P + 2]
                p11 = fs[FS_P + 3]
                a0 = p00 * phi0 + p01 * phi1
                a1 = p10 * phi0 + p11 * phi1
                denom = lam + phi0 * a0 + phi1 * a1
                k0 = a0 / denom
                k1 = a1 / denom
                err = force_n - (fs[FS_THETA] * phi0 + fs[FS_THETA + 1] * phi1)
                fs[FS_THETA] += k0 * err
                fs[FS_THETA + 1] += k1 * err
                fs[FS_P] = (p00 - k0 * a0) / lam
                fs[FS_P + 1] = (p01 - k0 * a1) / lam
                fs[FS_P + 2] = (p10 - k1 * a0) / lam
                fs[FS_P + 3] = (p11 - k1 * a1) / lam
                guess = fg[6]
                fs[FS_K] = min(20.0 * guess, max(0.2 * guess, fs[FS_THETA]))
            fs[FS_LAST_Z] = z
    else:
        e = 0.0
    ki_a = fg[15]
    a_lim = fg[16] / ki_a if ki_a > 0 else 0.0
    i_roll = max(-a_lim, min(a_lim, fs[FS_ANGLE_I] + (roll_ref - roll) * dt))
    i_pitch = max(-a_lim, min(a_lim, fs[FS_ANGLE_I + 1] + (pitch_ref - pitch) * dt))
    fs[FS_ANGLE_I] = i_roll
    fs[FS_ANGLE_I + 1] = i_pitch
    q_roll = -fg[4] * (roll - roll_ref) - fg[5] * (rd - roll_rate_ref) + ki_a * i_roll
    q_pitch = -fg[4] * (pitch - pitch_ref) - fg[5] * (pd_ - pitch_rate_ref) + ki_a * i_pitch
    grav = work[0:3]
    zero = work[3:6]
    zero[0] = 0.0
    zero[1] = 0.0
    zero[2] = 0.0
    pi = rb.unpack_tree(ti, tf)[5]
    rb.mixed_torque(ti, tf, pi, stb, zero, zero, True, work[30:], grav)
    # J_ik = (rows z, roll, pitch of S)⁻¹; its first column maps ż to the sliders.
    jfk = f64_view(work, 6, (3, 3))
    jik = f64_view(work, 15, (3, 3))
    for c in range(3):
        jfk[0, c] = S[8, c]
        jfk[1, c] = S[11, c]
        jfk[2, c] = S[10, c]
    inv3(jfk, jik)
    qd_ff = work[24:27]
    for i in range(3):
        qd_ff[i] = jik[i, 0] * z_dot_ff
    fric = work[27:30]
    fric[0] = 0.0
    fric[1] = 0.0
    fric[2] = 0.0
    rb.friction(ti, tf, qd_ff, fric)
    # Everything but the z task force: G, the angle PDs and the motion feedforward.
    for i in range(3):
        out[i] = (grav[i] + S[11, i] * q_roll + S[10, i] * q_pitch
                  + fric[i] + fg[12] * (jik[i, 0] * z_ddot_ff))
    if not math.isnan(force_n):
        tree = rb.unpack_tree(ti, tf)
        error_friction(tree[9], tree[10], jik, z_dot_ff, roll_rate_ref, pitch_rate_ref, e,
                       sched, fg[17], fg[18], out)
    held = fs[FS_INTEGRAL]
    fz = _task_fz(fg, kp, f_d, e, integral, zd, z_dot_ff)
    if force_n > CONTACT_TOUCH_N:
        fs[FS_TOUCHED] = 1.0
    if fs[FS_TOUCHED] == 0.0 and fg[19] > 0.0:
        # Before the entry's first touch: the approach no faster than the contact it expects
        # takes (approach_speed; why there, and why it is latched off after the touch).
        m_z = 0.0
        for i in range(3):
            m_z += jik[i, 0] * jik[i, 0]
        cap = fg[2] * (approach_speed(fg[19], fs[FS_K_APPROACH], fg[12] * m_z) - zd)
        if fz > cap:
            fz = cap
            integral = held
    if fz < floor and not force_n > floor:
        fz = floor
        integral = max(held, integral)
    elif _winds_up(out, S, fz, e, fg[13]):
        # A drive at its limit in the direction the integral pushes: hold the integral
        # (conditional integration), so a heel strike the drives cannot follow does not
        # leave ∫e wound up to overshoot for tens of ms once they catch up.
        integral = held
        fz = _task_fz(fg, kp, f_d, e, integral, zd, z_dot_ff)
    fs[FS_INTEGRAL] = integral
    for i in range(3):
        out[i] += S[8, i] * fz


#: The gain schedule's factor at and below which :func:`error_friction` compensates the whole
#: believed Coulomb level (k̂ ≥ 2 k_s).
ERROR_FRICTION_FULL_S = 0.5


@njit(cache=True)
def error_friction(fc, vs, jik, z_dot_ff, roll_rate, pitch_rate, e, sched, fraction,
                   deadband, out):
    """Add to ``out`` (N per slider) the believed Coulomb friction ``fc`` (N per axis; the
    model's, never the rig's truth) in the direction the force error ``e`` (N) asks the
    platform to move, where the gain schedule ``sched`` (< 1 against a contact stiffer than
    k_s) has taken the feedback's authority over the friction away.

    Why: the sliders' static friction (≈ 3 × 75 N in z) holds the platform until the force
    loop's command changes by that much. The unscheduled loop does it within (1 + Kp) e =
    225 N, e ≈ 5 N; scheduled for the plate (s ≈ 1/8) it needs 44 N of error or the
    integral's windup (0.3-0.5 s at a few N), then slips past the reference: a hunting limit
    cycle (hold spread 1.1-1.5 N, a 20 N step 0.5 s on the twin). The compensation is none
    where the loop is not scheduled (s = 1: the foot, its figures unchanged), full once the
    schedule has halved the gains (s ≤ ``ERROR_FRICTION_FULL_S``; the plate's s ≈ 1/8), linear
    between so nothing jumps as k̂ crosses k_s (weighting by 1 − s alone left the 20 N step
    at 0.115 s against a twin whose friction is 6-21 % above the believed). Further weights:
    ``fraction`` (1: the believed Coulomb level; static friction above it is left to the
    feedback), and per slider the share ``1 − |tanh(q̇_r / v_s)|`` (``vs`` the model's
    smoothing) its commanded motion leaves: q̇_r = J_ik (ż_ff, roll rate, pitch rate) (m/s,
    rad/s), the motion the law's feedforward and the pose's rate ask. A slider that is
    commanded to move has its friction in that motion's direction (the feedforward's own term
    for ż_ff; the angle loop's for a tilt): the error's compensation must not fight it (a 2°
    tilt under 600 N dropped to 519 N when it did). Deadband:
    none within ``deadband`` (N: 3σ of the sensor's z noise, so noise does not flip it),
    ramping to full over a second ``deadband``. The slider's direction for an upward platform
    motion is the sign of J_ik's first column (``jik``, 3×3)."""
    if fraction <= 0.0 or not sched < 1.0:
        return
    a = abs(e)
    if not a > deadband:
        return
    w = 1.0 if deadband <= 0.0 else min(1.0, (a - deadband) / deadband)
    w *= fraction * min(1.0, (1.0 - sched) / (1.0 - ERROR_FRICTION_FULL_S))
    for i in range(3):
        d = jik[i, 0] * e
        if d == 0.0:
            continue
        qd_r = jik[i, 0] * z_dot_ff + jik[i, 1] * roll_rate + jik[i, 2] * pitch_rate
        free = 1.0 - abs(math.tanh(qd_r / vs))
        out[i] += (w * free * fc[i]) if d > 0.0 else -(w * free * fc[i])


@njit(cache=True)
def prime_stiffness(fg, fs, k):
    """Start the stiffness estimate from a known contact's ``k`` (N/m), held within the
    estimate's own bounds (1/5..20× the guess ``fg[6]``): k̂ and the RLS prior of F ≈ k z + c
    as ``rt.control.force.ExplicitForce.reset`` sets them for a given stiffness, the
    integrals untouched. Called on the first loaded cycle of a contact (before it the RLS has
    not moved from its prior), so the gains are scheduled for that contact from there on."""
    guess = fg[6]
    k0 = min(20.0 * guess, max(0.2 * guess, k))
    half = 0.5 * k0
    fs[FS_K] = k0
    fs[FS_THETA] = k0
    fs[FS_THETA + 1] = -k0 * 0.7
    fs[FS_P] = half * half / 1e-4
    fs[FS_P + 1] = 0.0
    fs[FS_P + 2] = 0.0
    fs[FS_P + 3] = 1e10
    fs[FS_LAST_Z] = math.nan
    fs[FS_K_APPROACH] = k0


@njit(cache=True)
def approach_speed(margin, k, m):
    """The speed (m/s) at which the force law may close a gap onto a contact of stiffness
    ``k`` (N/m) with the moving mass ``m`` (kg along z) so that the impact overshoots by no
    more than ``margin`` (N): a mass at speed v meeting a spring k peaks at v √(k m).

    Why: in free space the law is a velocity loop, ż ≈ ż_ff + ((1 + Kp) e + Ki ∫e) / D, and
    reached the calibration plate at 45 mm/s (≈ 1.6 kN of impact through 2e6 N/m and the
    ≈ 630 kg the drives reflect in z): the drives saturated braking it and the tip rebounded
    for tens of ms; with a remembered (scheduled, softer) loop the rebound was longer still.
    Below the margin's speed the scheduled loop takes the contact without a rebound. The
    law applies it as a bound on its z task force, Q_z ≤ D (v_a − ż) (the damping D is the
    free-space velocity loop's gain), its integral held there (the gap's error would wind it
    up for the contact), from the force-mode entry until the first cycle whose measured F
    exceeds ``CONTACT_TOUCH_N`` (before it: not touching, or no reading).

    Latched off after that touch until the next entry (``fs[FS_TOUCHED]``; the entry's
    ``rt.control.force.ExplicitForce.reset`` re-arms it): within a hold, F falling to ≈ 0 is
    not told apart from a gap by the sensor alone, and the case that matters is the one the
    law must answer with all it has: an unmeasured load landing on the platform sinks it away
    from the strapped foot, which unloads and then pulls; a bound re-engaged there capped the
    push-back at 0.6-1.1 kN per drive exactly when the drives must carry the load at their
    limit (700 kg, ``tests/test_force_hold_payload.py``). A genuine loss of contact
    (the foot lifted, the plate removed) ends or pauses the exercise, and the next push or
    hold is a new entry, armed again; a lifted strapped foot pulls (F < 0), which the
    supervisor's ``pulling`` check stops."""
    return margin / math.sqrt(k * m)


@njit(cache=True)
def gain_schedule(k_s, k_est):
    """The force loop's gain scale s = min(1, k_s / k̂) against a contact stiffer than ``k_s``
    (N/m; ≤ 0: none). Through a contact of stiffness k the force error acts on the platform's
    height with the gain (1 + Kp) k: scaling (1 + Kp) and the integral's rate by s keeps the
    loop's poles where they are at k_s (``rt.control.force`` explains why)."""
    if k_s <= 0.0 or not k_est > k_s:
        return 1.0
    return k_s / k_est


@njit(cache=True)
def _task_fz(fg, kp, f_d, e, integral, zd, z_dot_ff):
    """Q_z = F_d + Kp e + Ki ∫e − D (ż − ż_ff) (N), Kp the scheduled gain."""
    return f_d + kp * e + fg[1] * integral - fg[2] * (zd - z_dot_ff)


@njit(cache=True)
def _winds_up(base, S, fz, e, tau_max):
    """True when a drive would be at its force limit ``tau_max`` (N) with τ = base + S_z fz
    and the integral's action (sign of S_z e on that axis) pushes it further (``tau_max`` ≤ 0:
    never)."""
    if tau_max <= 0.0 or e == 0.0:
        return False
    for i in range(3):
        tau = base[i] + S[8, i] * fz
        push = S[8, i] * e
        if (tau >= tau_max and push > 0.0) or (tau <= -tau_max and push < 0.0):
            return True
    return False
