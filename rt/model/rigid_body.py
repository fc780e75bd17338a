"""The tree's rigid-body dynamics compiled with numba: RNEA and its parameter gradient.

Why not call Pinocchio every cycle: each binding call (crba, Coriolis, gravity, three joint
torque regressors for the adaptive law) costs several µs of argument conversion around a
sub-µs computation, and the projections onto the sliders add a dozen small numpy calls; the
interpreted Paden-Panja block spent ≈ 100 µs per cycle there. The tree here is fixed and small
(12 one-DOF joints, depth ≤ 6), so a recursive Newton-Euler pass in plain loops is ≈ 1 µs.

Conventions are Pinocchio's (``rt.model.dynamics.build_tree_model`` is the source of truth and
:func:`tree_arrays` reads everything off the built ``pin.Model``): spatial motion (v, ω) with the
linear part first, every quantity in the joint's own frame, inertial parameters per body as
Pinocchio's ``toDynamicParameters`` — π = [m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]
with the inertia about the joint-frame origin. The RNEA is linear in π, which the adaptive law
uses: τ = Y θ is an RNEA with θ's parameters as the bodies' π, and Yᵀ s is, per body,
A(v, a)ᵀ u with u the body's velocity for joint rates S s (no 12 × 70 regressor is formed).

Christoffel form: for v, w the symmetric bilinear Γ(v, w) = C(q, v) w of the tree is
¼ [h(v + w) − h(v − w)] with h(v) = RNEA(q, v, 0) without gravity; Pinocchio's
``computeCoriolisMatrix`` is this factorization (Ṁ − 2C skew; checked in the tests).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rt.model.small_linalg import cross3, mat_t_vec3, mat_vec3
from rt.pointers import f64_view

#: Joint kinds (one DOF each).
PRISMATIC = 0
REVOLUTE = 1
N_PARAMS = 10


def tree_arrays(model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                np.ndarray, np.ndarray]:
    """(parent, kind, axis, placement rotations, placement translations, π per joint, gravity)
    of a Pinocchio model made of one-DOF prismatic/revolute joints along x, y or z.

    Joint j of the arrays is Pinocchio's joint j + 1; ``parent`` is −1 for the universe.
    Raises ``ValueError`` naming a joint of another kind.
    """
    n = model.njoints - 1
    parent = np.empty(n, dtype=np.int64)
    kind = np.empty(n, dtype=np.int64)
    axis = np.empty(n, dtype=np.int64)
    rot = np.empty((n, 3, 3))
    trans = np.empty((n, 3))
    pi = np.empty((n, N_PARAMS))
    for j in range(n):
        jid = j + 1
        short = model.joints[jid].shortname()
        if short[:-1] not in ("JointModelP", "JointModelR") or short[-1] not in "XYZ":
            raise ValueError(f"joint {model.names[jid]!r} is a {short}: the compiled dynamics "
                             "take one-DOF prismatic/revolute joints along x, y or z")
        parent[j] = model.parents[jid] - 1
        kind[j] = PRISMATIC if short[-2] == "P" else REVOLUTE
        axis[j] = "XYZ".index(short[-1])
        placement = model.jointPlacements[jid]
        rot[j] = placement.rotation
        trans[j] = placement.translation
        pi[j] = model.inertias[jid].toDynamicParameters()
    gravity = np.array(model.gravity.linear, dtype=float)
    return parent, kind, axis, rot, trans, pi, gravity


@njit(cache=True, fastmath=False)
def tree_kinematics(parent, kind, axis, prot, ptrans, Q, R, p):
    """Joint frames relative to their parents: R[j] (3×3) and p[j] (m) with
    x_parent = R[j] x_j + p[j], for tree configuration ``Q``."""
    n = parent.shape[0]
    for j in range(n):
        a = axis[j]
        qj = Q[j]
        if kind[j] == PRISMATIC:
            for r in range(3):
                for c in range(3):
                    R[j, r, c] = prot[j, r, c]
                p[j, r] = ptrans[j, r] + prot[j, r, a] * qj
        else:
            c_ = math.cos(qj)
            s_ = math.sin(qj)
            # Columns of the elementary rotation about axis a (right-handed).
            b = (a + 1) % 3
            d = (a + 2) % 3
            for r in range(3):
                R[j, r, a] = prot[j, r, a]
                R[j, r, b] = prot[j, r, b] * c_ + prot[j, r, d] * s_
                R[j, r, d] = -prot[j, r, b] * s_ + prot[j, r, d] * c_
                p[j, r] = ptrans[j, r]


@njit(cache=True, inline="always")
def _inertia_times(pi, j, vl0, vl1, vl2, w0, w1, w2):
    """Spatial inertia (parameters ``pi[j]``) times motion (v, ω): returns (f, n)."""
    m = pi[j, 0]
    h0 = pi[j, 1]
    h1 = pi[j, 2]
    h2 = pi[j, 3]
    ixx = pi[j, 4]
    ixy = pi[j, 5]
    iyy = pi[j, 6]
    ixz = pi[j, 7]
    iyz = pi[j, 8]
    izz = pi[j, 9]
    # f = m v + ω × h ; n = h × v + Ī ω
    wh0, wh1, wh2 = cross3(w0, w1, w2, h0, h1, h2)
    hv0, hv1, hv2 = cross3(h0, h1, h2, vl0, vl1, vl2)
    f0 = m * vl0 + wh0
    f1 = m * vl1 + wh1
    f2 = m * vl2 + wh2
    # Ī ω summed after h × v, term by term (not dot3: that would sum Ī ω first).
    n0 = hv0 + ixx * w0 + ixy * w1 + ixz * w2
    n1 = hv1 + ixy * w0 + iyy * w1 + iyz * w2
    n2 = hv2 + ixz * w0 + iyz * w1 + izz * w2
    return f0, f1, f2, n0, n1, n2


@njit(cache=True, inline="always")
def body_force(pi, j, v, a):
    """f = I a + v ×* (I v) for body j (``v``, ``a``: n × 6, linear first)."""
    a0, a1, a2, a3, a4, a5 = _inertia_times(pi, j, a[j, 0], a[j, 1], a[j, 2], a[j, 3],
                                            a[j, 4], a[j, 5])
    vl0, vl1, vl2, w0, w1, w2 = v[j, 0], v[j, 1], v[j, 2], v[j, 3], v[j, 4], v[j, 5]
    p0, p1, p2, p3, p4, p5 = _inertia_times(pi, j, vl0, vl1, vl2, w0, w1, w2)
    # (v, ω) ×* (p, L) = (ω × p, ω × L + v × p)
    wp0, wp1, wp2 = cross3(w0, w1, w2, p0, p1, p2)
    wl0, wl1, wl2 = cross3(w0, w1, w2, p3, p4, p5)
    vp0, vp1, vp2 = cross3(vl0, vl1, vl2, p0, p1, p2)
    return a0 + wp0, a1 + wp1, a2 + wp2, a3 + wl0 + vp0, a4 + wl1 + vp1, a5 + wl2 + vp2


@njit(cache=True)
def forward_pass(parent, kind, axis, R, p, V, A, g_lin, v, a):
    """Body velocities ``v`` and accelerations ``a`` (n × 6, own frames) for joint rates ``V``
    and accelerations ``A``; the base accelerates by −g (``g_lin``, zero for no gravity)."""
    n = parent.shape[0]
    for j in range(n):
        par = parent[j]
        if par < 0:
            pv0 = pv1 = pv2 = pw0 = pw1 = pw2 = 0.0
            pa0 = -g_lin[0]
            pa1 = -g_lin[1]
            pa2 = -g_lin[2]
            paw0 = paw1 = paw2 = 0.0
        else:
            pv0, pv1, pv2 = v[par, 0], v[par, 1], v[par, 2]
            pw0, pw1, pw2 = v[par, 3], v[par, 4], v[par, 5]
            pa0, pa1, pa2 = a[par, 0], a[par, 1], a[par, 2]
            paw0, paw1, paw2 = a[par, 3], a[par, 4], a[par, 5]
        px, py, pz = p[j, 0], p[j, 1], p[j, 2]
        # Motion from parent to child frame: ω' = Rᵀ ω, v' = Rᵀ (v + ω × p).
        c0, c1, c2 = cross3(pw0, pw1, pw2, px, py, pz)
        v[j, 0], v[j, 1], v[j, 2] = mat_t_vec3(R[j], pv0 + c0, pv1 + c1, pv2 + c2)
        v[j, 3], v[j, 4], v[j, 5] = mat_t_vec3(R[j], pw0, pw1, pw2)
        c0, c1, c2 = cross3(paw0, paw1, paw2, px, py, pz)
        a[j, 0], a[j, 1], a[j, 2] = mat_t_vec3(R[j], pa0 + c0, pa1 + c1, pa2 + c2)
        a[j, 3], a[j, 4], a[j, 5] = mat_t_vec3(R[j], paw0, paw1, paw2)
        # Joint contribution S q̇ and S q̈ + v × (S q̇).
        k = axis[j] if kind[j] == PRISMATIC else 3 + axis[j]
        qd = V[j]
        # v × (S q̇) with S q̇ = qd e_k, computed before adding S q̇ to v (v × v = 0 anyway).
        wl0 = v[j, 0]
        wl1 = v[j, 1]
        wl2 = v[j, 2]
        ww0 = v[j, 3]
        ww1 = v[j, 4]
        ww2 = v[j, 5]
        s0 = s1 = s2 = s3 = s4 = s5 = 0.0
        if k == 0:
            s0 = qd
        elif k == 1:
            s1 = qd
        elif k == 2:
            s2 = qd
        elif k == 3:
            s3 = qd
        elif k == 4:
            s4 = qd
        else:
            s5 = qd
        # (v, ω) × (s, σ) = (ω × s + v × σ, ω × σ)
        ws0, ws1, ws2 = cross3(ww0, ww1, ww2, s0, s1, s2)
        vs0, vs1, vs2 = cross3(wl0, wl1, wl2, s3, s4, s5)
        wo0, wo1, wo2 = cross3(ww0, ww1, ww2, s3, s4, s5)
        a[j, 0] += ws0 + vs0
        a[j, 1] += ws1 + vs1
        a[j, 2] += ws2 + vs2
        a[j, 3] += wo0
        a[j, 4] += wo1
        a[j, 5] += wo2
        a[j, k] += A[j]
        v[j, k] += qd


@njit(cache=True)
def backward_pass(parent, kind, axis, R, p, pi, v, a, f, tau):
    """Joint forces τ (N or N m) from the forward pass; ``f`` (n × 6) is scratch."""
    n = parent.shape[0]
    for j in range(n):
        f[j, 0], f[j, 1], f[j, 2], f[j, 3], f[j, 4], f[j, 5] = body_force(pi, j, v, a)
    for j in range(n - 1, -1, -1):
        k = axis[j] if kind[j] == PRISMATIC else 3 + axis[j]
        tau[j] = f[j, k]
        par = parent[j]
        if par >= 0:
            # Force to the parent frame: f_p = R f, n_p = R n + p × (R f).
            rf0, rf1, rf2 = mat_vec3(R[j], f[j, 0], f[j, 1], f[j, 2])
            rn0, rn1, rn2 = mat_vec3(R[j], f[j, 3], f[j, 4], f[j, 5])
            c0, c1, c2 = cross3(p[j, 0], p[j, 1], p[j, 2], rf0, rf1, rf2)
            f[par, 0] += rf0
            f[par, 1] += rf1
            f[par, 2] += rf2
            f[par, 3] += rn0 + c0
            f[par, 4] += rn1 + c1
            f[par, 5] += rn2 + c2


@njit(cache=True)
def rnea(parent, kind, axis, R, p, pi, V, A, g_lin, v, a, f, tau):
    """τ = M(Q) A + C(Q, V) V + g(Q) on the tree (``g_lin`` zero: no gravity term)."""
    forward_pass(parent, kind, axis, R, p, V, A, g_lin, v, a)
    backward_pass(parent, kind, axis, R, p, pi, v, a, f, tau)


@njit(cache=True)
def param_gradient(v, a, u, coef, grad, e):
    """grad[j, :] += coef · A_j(v_j, a_j)ᵀ u_j: the derivative of Σ_j u_jᵀ f_j with respect to
    every body's π (f_j = A_j π_j = I(π_j) a_j + v_j ×* I(π_j) v_j is linear in π_j).

    In closed form (the adaptive law's Yᵀ s every cycle; evaluating ``body_force`` once per
    unit π, ten per body, cost ~3 µs a pass): with the triple product,
    uᵀ (v ×* I v) = b_vᵀ I v for b_v = (u_l × ω + u_a × v_l, u_a × ω), so
    uᵀ f = uᵀ I a + b_vᵀ I v, and for a weight y and a motion x = (x_l, x_w),
    yᵀ I(π) x = m y_l·x_l + h·(y_l × x_w + x_l × y_a) + y_aᵀ Ī x_w: its π-gradient is
    (y_l·x_l, y_l × x_w + x_l × y_a, the six products of y_a and x_w in Ī's order
    ixx, ixy, iyy, ixz, iyz, izz). ``e`` (float64[1, N_PARAMS]) is no longer used; the
    argument stays for the callers."""
    n = v.shape[0]
    for j in range(n):
        vl0, vl1, vl2, w0, w1, w2 = v[j, 0], v[j, 1], v[j, 2], v[j, 3], v[j, 4], v[j, 5]
        al0, al1, al2, aw0, aw1, aw2 = a[j, 0], a[j, 1], a[j, 2], a[j, 3], a[j, 4], a[j, 5]
        ul0, ul1, ul2, ua0, ua1, ua2 = u[j, 0], u[j, 1], u[j, 2], u[j, 3], u[j, 4], u[j, 5]
        c0, c1, c2 = cross3(ul0, ul1, ul2, w0, w1, w2)
        d0, d1, d2 = cross3(ua0, ua1, ua2, vl0, vl1, vl2)
        bl0 = c0 + d0
        bl1 = c1 + d1
        bl2 = c2 + d2
        ba0, ba1, ba2 = cross3(ua0, ua1, ua2, w0, w1, w2)
        # h: (u_l × a_w + a_l × u_a) + (b_l × ω + v_l × b_a)
        h0a, h1a, h2a = cross3(ul0, ul1, ul2, aw0, aw1, aw2)
        h0b, h1b, h2b = cross3(al0, al1, al2, ua0, ua1, ua2)
        h0c, h1c, h2c = cross3(bl0, bl1, bl2, w0, w1, w2)
        h0d, h1d, h2d = cross3(vl0, vl1, vl2, ba0, ba1, ba2)
        g = grad[j]
        g[0] += coef * (ul0 * al0 + ul1 * al1 + ul2 * al2 + bl0 * vl0 + bl1 * vl1 + bl2 * vl2)
        g[1] += coef * (h0a + h0b + h0c + h0d)
        g[2] += coef * (h1a + h1b + h1c + h1d)
        g[3] += coef * (h2a + h2b + h2c + h2d)
        g[4] += coef * (ua0 * aw0 + ba0 * w0)
        g[5] += coef * (ua0 * aw1 + ua1 * aw0 + ba0 * w1 + ba1 * w0)
        g[6] += coef * (ua1 * aw1 + ba1 * w1)
        g[7] += coef * (ua0 * aw2 + ua2 * aw0 + ba0 * w2 + ba2 * w0)
        g[8] += coef * (ua1 * aw2 + ua2 * aw1 + ba1 * w2 + ba2 * w1)
        g[9] += coef * (ua2 * aw2 + ba2 * w2)


# ---------------------------------------------------------------------------- packed parameters
# The kernels take the model as two flat arrays (numba's dispatcher costs ≈ 0.25 µs per array
# argument on this VM, so a dozen separate arrays would cost more than the arithmetic):
#   ti = [parent(n), kind(n), axis(n)]
#   tf = [placement rotations (9n), translations (3n), π (10n), g (3), J_r (3), f_v (3),
#         f_c (3), v_s (1)]
N_DRIVE = 10


def pack_tree(model, reflected_inertia, viscous, coulomb,
              coulomb_v: float) -> tuple[np.ndarray, np.ndarray]:
    """(ti, tf) for the kernels; see the layout above."""
    parent, kind, axis, prot, ptrans, pi, gravity = tree_arrays(model)
    ti = np.concatenate((parent, kind, axis)).astype(np.int64)
    tf = np.concatenate((prot.ravel(), ptrans.ravel(), pi.ravel(), gravity,
                         np.asarray(reflected_inertia, dtype=float),
                         np.asarray(viscous, dtype=float), np.asarray(coulomb, dtype=float),
                         [float(coulomb_v)]))
    return ti, tf


def pi_slice(n: int, joint: int) -> slice:
    """Where joint ``joint``'s (0-based) π lives in ``tf``."""
    start = 12 * n + N_PARAMS * joint
    return slice(start, start + N_PARAMS)


@njit(cache=True)
def unpack_tree(ti, tf):
    """Views (parent, kind, axis, prot, ptrans, pi, g, jr, fv, fc, vs) of the packed model."""
    n = ti.shape[0] // 3
    parent = ti[0:n]
    kind = ti[n:2 * n]
    axis = ti[2 * n:3 * n]
    o = 0
    prot = f64_view(tf, o, (n, 3, 3))
    o += 9 * n
    ptrans = f64_view(tf, o, (n, 3))
    o += 3 * n
    pi = f64_view(tf, o, (n, N_PARAMS))
    o += N_PARAMS * n
    g = tf[o:o + 3]
    jr = tf[o + 3:o + 6]
    fv = tf[o + 6:o + 9]
    fc = tf[o + 9:o + 12]
    vs = tf[o + 12]
    return parent, kind, axis, prot, ptrans, pi, g, jr, fv, fc, vs


def work_size(n: int) -> int:
    """float64 scratch the dynamics kernels need for an n-joint tree."""
    return 9 * n + 3 * n + 3 * 6 * n + 4 * n + 3 * 6 * n + N_PARAMS * n + N_PARAMS + 3


@njit(cache=True)
def unpack_work(work, n):
    """Views (R, p, v, a, f, tau, V, A, tmp, u, ua, grad, e, zero3) of the scratch array."""
    o = 0
    R = f64_view(work, o, (n, 3, 3))
    o += 9 * n
    p = f64_view(work, o, (n, 3))
    o += 3 * n
    v = f64_view(work, o, (n, 6))
    o += 6 * n
    a = f64_view(work, o, (n, 6))
    o += 6 * n
    f = f64_view(work, o, (n, 6))
    o += 6 * n
    tau = work[o:o + n]
    o += n
    V = work[o:o + n]
    o += n
    A = work[o:o + n]
    o += n
    tmp = work[o:o + n]
    o += n
    u = f64_view(work, o, (n, 6))
    o += 6 * n
    ua = f64_view(work, o, (n, 6))
    o += 6 * n
    uf = f64_view(work, o, (n, 6))
    o += 6 * n
    grad = f64_view(work, o, (n, N_PARAMS))
    o += N_PARAMS * n
    e = f64_view(work, o, (1, N_PARAMS))
    o += N_PARAMS
    zero3 = work[o:o + 3]
    return R, p, v, a, f, tau, V, A, tmp, u, ua, uf, grad, e, zero3


# ---------------------------------------------------------------------------- the State buffer
# ``rt.model.dynamics.State`` keeps its arrays as views of one float64 buffer so a kernel takes
# the whole cycle state as one argument. Offsets (tree of 12 joints):
STATE_Q = 0            # Q (12): tree coordinates
STATE_QD_TREE = 12     # Q̇ = S q̇ (12)
STATE_QD = 24          # q̇ (3), m/s
STATE_S = 27           # S (12×3)
STATE_SD = 63          # Ṡ (12×3)
STATE_TWIST = 99       # platform twist map (6×3)
STATE_ROT = 117        # R_BP (3×3)
STATE_Q_ACT = 126      # q (3), m
STATE_PHI = 129        # rod angles φ (3), rad
STATE_SPHERES = 132    # sphere centres B_i (3×3), m
STATE_ITERATIONS = 141  # Newton iterations of this cycle's FK
STATE_DET = 142        # det(∂f/∂φ), 0 at a forward singularity
STATE_SIZE = 143


@njit(cache=True)
def unpack_state(stb):
    """Views (Q, Qd, qd, S, Sd, twist, rot, q, phi) of a State buffer."""
    return (stb[STATE_Q:STATE_Q + 12], stb[STATE_QD_TREE:STATE_QD_TREE + 12],
            stb[STATE_QD:STATE_QD + 3], f64_view(stb, STATE_S, (12, 3)),
            f64_view(stb, STATE_SD, (12, 3)),
            f64_view(stb, STATE_TWIST, (6, 3)),
            f64_view(stb, STATE_ROT, (3, 3)), stb[STATE_Q_ACT:STATE_Q_ACT + 3],
            stb[STATE_PHI:STATE_PHI + 3])


# ---------------------------------------------------------------------------- actuator space
@njit(cache=True)
def mixed_torque(ti, tf, pi, stb, u_acc, u_vel, gravity, work, out):
    """out = Sᵀ [M_t (S u_acc + Ṡ u_vel) + Γ_t(S q̇, S u_vel) + g_t] + J_r ∘ u_acc (N);
    ``work`` is float64[work_size(n)] scratch.

    With (u_acc, u_vel) = (q̈_d, q̇_d) this is M q̈_d + C(q, q̇) q̇_d + G, with (v, q̇) the
    computed-torque M v + C q̇ + G and with zeros G alone; the tree's inertial parameters are
    ``pi`` (n × 10: the model's own, or the adaptive law's estimate). No friction. ``gravity``
    False drops g_t. Three RNEA passes (one when u_vel is zero)."""
    parent, kind, axis, prot, ptrans, _, g, jr, _, _, _ = unpack_tree(ti, tf)
    n = parent.shape[0]
    R, p, v, a, f, tau, V, A, tmp, _, _, _, _, _, zero3 = unpack_work(work, n)
    Q, Qd, _, S, Sd, _, _, _, _ = unpack_state(stb)
    tree_kinematics(parent, kind, axis, prot, ptrans, Q, R, p)
    moving = u_vel[0] != 0.0 or u_vel[1] != 0.0 or u_vel[2] != 0.0
    for j in range(n):
        V[j] = 0.0
        A[j] = (S[j, 0] * u_acc[0] + S[j, 1] * u_acc[1] + S[j, 2] * u_acc[2]
                + Sd[j, 0] * u_vel[0] + Sd[j, 1] * u_vel[1] + Sd[j, 2] * u_vel[2])
    zero3[0] = 0.0
    zero3[1] = 0.0
    zero3[2] = 0.0
    rnea(parent, kind, axis, R, p, pi, V, A, g if gravity else zero3, v, a, f, tmp)
    for j in range(n):
        tau[j] = tmp[j]
    if moving:
        # Γ(v, w) = ¼ [h(v + w) − h(v − w)], h the velocity terms alone.
        for j in range(n):
            w = S[j, 0] * u_vel[0] + S[j, 1] * u_vel[1] + S[j, 2] * u_vel[2]
            V[j] = Qd[j] + w
            A[j] = 0.0
        rnea(parent, kind, axis, R, p, pi, V, A, zero3, v, a, f, tmp)
        for j in range(n):
            tau[j] += 0.25 * tmp[j]
        for j in range(n):
            w = S[j, 0] * u_vel[0] + S[j, 1] * u_vel[1] + S[j, 2] * u_vel[2]
            V[j] = Qd[j] - w
        rnea(parent, kind, axis, R, p, pi, V, A, zero3, v, a, f, tmp)
        for j in range(n):
            tau[j] -= 0.25 * tmp[j]
    for i in range(3):
        acc = 0.0
        for j in range(n):
            acc += S[j, i] * tau[j]
        out[i] = acc + jr[i] * u_acc[i]


@njit(cache=True)
def inverse_dynamics(ti, tf, pi, stb, u_acc, work, out):
    """out = Sᵀ [M_t (S u_acc + Ṡ q̇) + h_t(S q̇) + g_t] + J_r ∘ u_acc (N): M u_acc + C q̇ + G
    in one RNEA pass at the state's own tree velocity Q̇ = S q̇.

    ``mixed_torque(..., u_acc, q̇, True, ...)`` computes the same, with C q̇ as the polarized
    ¼ [h(Q̇ + S q̇) − h(Q̇ − S q̇)] in two more passes: with u_vel = q̇ that is ¼ [h(2 Q̇) −
    h(0)] = h(Q̇) (h is quadratic), which one pass at Q̇ already gives. The computed-torque
    laws call this (three passes → one); results agree to rounding. No friction."""
    parent, kind, axis, prot, ptrans, _, g, jr, _, _, _ = unpack_tree(ti, tf)
    n = parent.shape[0]
    R, p, v, a, f, tau, V, A, _, _, _, _, _, _, _ = unpack_work(work, n)
    Q, Qd, qd, S, Sd, _, _, _, _ = unpack_state(stb)
    tree_kinematics(parent, kind, axis, prot, ptrans, Q, R, p)
    for j in range(n):
        V[j] = Qd[j]
        A[j] = (S[j, 0] * u_acc[0] + S[j, 1] * u_acc[1] + S[j, 2] * u_acc[2]
                + Sd[j, 0] * qd[0] + Sd[j, 1] * qd[1] + Sd[j, 2] * qd[2])
    rnea(parent, kind, axis, R, p, pi, V, A, g, v, a, f, tau)
    for i in range(3):
        acc = 0.0
        for j in range(n):
            acc += S[j, i] * tau[j]
        out[i] = acc + jr[i] * u_acc[i]


@njit(cache=True)
def friction(ti, tf, qd, out):
    """out += f_v q̇ + f_c tanh(q̇ / v_s) (N)."""
    _, _, _, _, _, _, _, _, fv, fc, vs = unpack_tree(ti, tf)
    for i in range(3):
        out[i] += fv[i] * qd[i] + fc[i] * math.tanh(qd[i] / vs)
