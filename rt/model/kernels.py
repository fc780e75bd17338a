"""Velocity and acceleration maps of the closed chains, compiled with numba.

The dynamics project a Pinocchio tree (3 legs + a free platform, 12 scalar joints) onto the
three slider coordinates. That needs, every cycle, the tree velocity map S(q) = ∂Q/∂q (12×3)
and its time derivative Ṡ(q, q̇) (12×3). Both are a few hundred floating-point operations that
cost tens of µs in interpreted Python (PLATFORM.md), so they are compiled; the maths is
documented in ``docs/dynamics.md``.

Tree coordinate order Q: [q0, φ0, q1, φ1, q2, φ2, x, y, z, α (yaw), β (pitch), γ (roll)].
``geom`` packs the geometry: [R_b, R_p, L, cos θ0..2, sin θ0..2, cos(θ_i - θ_j) for the pairs
(0,1), (1,2), (2,0)].
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rt.model import rigid_body as rb
from rt.model.small_linalg import cross3, dot3, roll_pitch, unit3
from rt.pointers import f64_view

TREE_DOF = 12
IX_X, IX_Y, IX_Z, IX_YAW, IX_PITCH, IX_ROLL = 6, 7, 8, 9, 10, 11
_PAIR_I = (0, 1, 2)
_PAIR_J = (1, 2, 0)


def pack_geometry(base_radius: float, platform_radius: float, rod_length: float,
                  cos_theta, sin_theta, cos_pair) -> np.ndarray:
    """The ``geom`` array the kernels read (see module docstring)."""
    return np.array([base_radius, platform_radius, rod_length, *cos_theta, *sin_theta,
                     *cos_pair], dtype=np.float64)


@njit(cache=True)
def constraint_terms(geom, q, p0, p1, p2):
    """Residuals f_p = |B_i - B_j|² - 3 R_p² (m²) for the pairs (0,1), (1,2), (2,0) and the
    non-zero entries of ∂f/∂φ (m²/rad), returned as (f0, f1, f2, a00, a01, a11, a12, a22, a20):
    row p of the Jacobian has its two entries in the columns of its pair."""
    return constraint_terms_sc(geom, q, math.sin(p0), math.cos(p0), math.sin(p1),
                               math.cos(p1), math.sin(p2), math.cos(p2))


@njit(cache=True, inline="always")
def constraint_terms_sc(geom, q, s0, c0, s1, c1, s2, c2):
    """:func:`constraint_terms` from the rod angles' sines and cosines (the same arithmetic:
    callers that already hold them, e.g. the twin's substep, skip the six transcendental
    calls)."""
    rb = geom[0]
    rp = geom[1]
    ln = geom[2]
    ca = geom[9]
    cb = geom[10]
    cc = geom[11]
    r0 = rb + ln * s0
    r1 = rb + ln * s1
    r2 = rb + ln * s2
    h0 = q[0] + ln * c0
    h1 = q[1] + ln * c1
    h2 = q[2] + ln * c2
    d01 = h0 - h1
    d12 = h1 - h2
    d20 = h2 - h0
    side_sq = 3.0 * rp * rp
    f0 = r0 * r0 + r1 * r1 - 2.0 * ca * r0 * r1 + d01 * d01 - side_sq
    f1 = r1 * r1 + r2 * r2 - 2.0 * cb * r1 * r2 + d12 * d12 - side_sq
    f2 = r2 * r2 + r0 * r0 - 2.0 * cc * r2 * r0 + d20 * d20 - side_sq
    # ∂ρ/∂φ = L cos φ and ∂h/∂φ = -L sin φ.
    a00 = 2.0 * (r0 - ca * r1) * ln * c0 - 2.0 * d01 * ln * s0
    a01 = 2.0 * (r1 - ca * r0) * ln * c1 + 2.0 * d01 * ln * s1
    a11 = 2.0 * (r1 - cb * r2) * ln * c1 - 2.0 * d12 * ln * s1
    a12 = 2.0 * (r2 - cb * r1) * ln * c2 + 2.0 * d12 * ln * s2
    a22 = 2.0 * (r2 - cc * r0) * ln * c2 - 2.0 * d20 * ln * s2
    a20 = 2.0 * (r0 - cc * r2) * ln * c0 + 2.0 * d20 * ln * s0
    return f0, f1, f2, a00, a01, a11, a12, a22, a20


@njit(cache=True)
def inv3(a, out):
    """out = a⁻¹ for a 3×3 ``a`` by cofactors; returns det(a)."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    out[0, 0] = c00 / det
    out[1, 0] = c01 / det
    out[2, 0] = c02 / det
    out[0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) / det
    out[1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) / det
    out[2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) / det
    out[0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) / det
    out[1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) / det
    out[2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) / det
    return det


@njit(cache=True, inline="always")
def _centroid_and_moment(r, ct, st, rho_d, h_d):
    """The centroid's rate (x, y, z) of the spheres moving radially at ``rho_d`` and
    vertically at ``h_d`` (leg i along (cos θ_i, sin θ_i, 0), m/s or m/s²), and the moment
    Σ r_i × (d_i − centroid) of their rates about it (``r``: sphere offsets, one per row)."""
    cx = 0.0
    cy = 0.0
    cz = 0.0
    for i in range(3):
        cx += rho_d[i] * ct[i] / 3.0
        cy += rho_d[i] * st[i] / 3.0
        cz += h_d[i] / 3.0
    mx = 0.0
    my = 0.0
    mz = 0.0
    for i in range(3):
        m0, m1, m2 = cross3(r[i, 0], r[i, 1], r[i, 2], rho_d[i] * ct[i] - cx,
                            rho_d[i] * st[i] - cy, h_d[i] - cz)
        mx += m0
        my += m1
        mz += m2
    return cx, cy, cz, mx, my, mz


@njit(cache=True, inline="always")
def _from_moment(ginv, nx, ny, nz, mx, my, mz):
    """The platform's angular rate from the moment of its spheres' rates: G⁻¹ m with
    G = (3 R_p²/2)(I + n nᵀ) (``ginv`` = 2 / (3 R_p²)), i.e. ginv (m − ½ n (n · m))."""
    nm = dot3(nx, ny, nz, mx, my, mz)
    return ginv * (mx - 0.5 * nx * nm), ginv * (my - 0.5 * ny * nm), ginv * (mz - 0.5 * nz * nm)


@njit(cache=True, inline="always")
def _euler_rates(wx, wy, wz, ca, sa, cb, sb):
    """(yaw, pitch, roll) rates of the ZYX angles for the angular rate ω (base frame), at
    yaw cos/sin (ca, sa) and pitch cos/sin (cb, sb)."""
    roll_d = (wx * ca + wy * sa) / cb
    return wz + roll_d * sb, -wx * sa + wy * ca, roll_d


@njit(cache=True)
def rod_cone_angle(geom, i, sin_phi, cos_phi, nx, ny, nz):
    """The angle (rad) between leg i's rod, at rod angle φ (its sine and cosine), and the
    platform normal n: what the spherical joint's cone limit bounds."""
    dot = sin_phi * (geom[3 + i] * nx + geom[6 + i] * ny) + cos_phi * nz
    return math.acos(max(-1.0, min(1.0, dot)))


TREE_MAPS_WORK = 160


@njit(cache=True)
def tree_maps(geom, q, phi, rot, qd, S, Sd, twist):
    """Fill S = ∂Q/∂q, Ṡ (for slider velocity ``qd``) and the platform twist map.

    ``rot`` is R_BP (3×3). ``twist`` (6×3) maps q̇ to the platform's (v_P, ω) in the base frame,
    v_P being the velocity of the platform origin. Returns det(∂f/∂φ), the forward-kinematics
    constraint Jacobian's determinant (0 at a forward singularity).
    """
    return tree_maps_work(geom, q, phi, rot, qd, S, Sd, twist, np.empty(TREE_MAPS_WORK))


@njit(cache=True)
def tree_maps_work(geom, q, phi, rot, qd, S, Sd, twist, work):
    """``tree_maps`` with caller-provided scratch (float64[TREE_MAPS_WORK]): no allocation,
    for the twin's inner loop."""
    for i in range(3):
        work[i] = math.sin(phi[i])
        work[3 + i] = math.cos(phi[i])
    return tree_maps_sc(geom, q, rot, qd, S, Sd, twist, work)


@njit(cache=True)
def tree_maps_sc(geom, q, rot, qd, S, Sd, twist, work):
    """:func:`tree_maps_work` with the rod angles' sines and cosines already in
    ``work[0:3]`` and ``work[3:6]`` (the same arithmetic: the twin's substep computes them
    once for the assembly, these maps and its mass matrix)."""
    return _tree_maps(geom, q, rot, qd, S, Sd, twist, work, False)


@njit(cache=True)
def tree_maps_drift_sc(geom, q, rot, qd, S, sdq, twist, work):
    """:func:`tree_maps_sc` with the drift Ṡ q̇ (float64[12], ``sdq``) in place of Ṡ: the
    second-order term H(q̇, q̇) evaluated once, where Ṡ is its three columns H(q̇, e_k) (the
    twin's substep needs only Ṡ q̇: a third of the second-order work, issue 16). The same
    bilinear form, so equal to Ṡ q̇ = Σ_k Ṡ e_k q̇_k to round-off (not bit for bit: the
    sums run in another order)."""
    return _tree_maps(geom, q, rot, qd, S, f64_view(sdq, 0, (12, 1)), twist, work, True)


@njit(cache=True, inline="always")
def _tree_maps(geom, q, rot, qd, S, Sd, twist, work, drift):
    """:func:`tree_maps_sc`'s body; ``drift``: ``Sd`` is (12, 1) and receives H(q̇, q̇)
    (:func:`tree_maps_drift_sc`), else (12, 3) with H(q̇, e_k) in column k."""
    rb = geom[0]
    rp = geom[1]
    ln = geom[2]
    ct = geom[3:6]
    st = geom[6:9]
    cpair = geom[9:12]
    sphi = work[0:3]
    cphi = work[3:6]
    rho = work[6:9]
    h = work[9:12]
    for i in range(3):
        rho[i] = rb + ln * sphi[i]
        h[i] = q[i] + ln * cphi[i]
    # Constraint Jacobians of f_p = |B_i - B_j|² - 3 R_p² for the pairs p = (i, j).
    _, _, _, a00, a01, a11, a12, a22, a20 = constraint_terms_sc(
        geom, q, sphi[0], cphi[0], sphi[1], cphi[1], sphi[2], cphi[2])
    f_phi = f64_view(work, 12, (3, 3))
    f_phi[:, :] = 0.0
    f_phi[0, 0] = a00
    f_phi[0, 1] = a01
    f_phi[1, 1] = a11
    f_phi[1, 2] = a12
    f_phi[2, 2] = a22
    f_phi[2, 0] = a20
    f_q = f64_view(work, 21, (3, 3))
    f_q[:, :] = 0.0
    for p in range(3):
        i = (0, 1, 2)[p]
        j = (1, 2, 0)[p]
        d = h[i] - h[j]
        f_q[p, i] = 2.0 * d
        f_q[p, j] = -2.0 * d
    f_phi_inv = f64_view(work, 30, (3, 3))
    det = inv3(f_phi, f_phi_inv)
    # Platform geometry: sphere offsets r_i = B_i - p (p is the centroid), normal n.
    nx = rot[0, 2]
    ny = rot[1, 2]
    nz = rot[2, 2]
    r = f64_view(work, 39, (3, 3))
    for i in range(3):
        r[i, 0] = rot[0, 0] * ct[i] * rp + rot[0, 1] * st[i] * rp
        r[i, 1] = rot[1, 0] * ct[i] * rp + rot[1, 1] * st[i] * rp
        r[i, 2] = rot[2, 0] * ct[i] * rp + rot[2, 1] * st[i] * rp
    sa = rot[1, 0]
    ca = rot[0, 0]
    nrm = math.hypot(ca, sa)
    ca /= nrm
    sa /= nrm
    sb = -rot[2, 0]
    cb = math.sqrt(max(0.0, 1.0 - sb * sb))
    ginv = 2.0 / (3.0 * rp * rp)
    half_p = 1.5 * rp * rp

    # Velocity-level quantities for m = 4 velocity vectors: the three unit vectors e_k and qd.
    m = 4
    phid = f64_view(work, 48, (m, 3))
    rhod = f64_view(work, 60, (m, 3))
    hd = f64_view(work, 72, (m, 3))
    w = f64_view(work, 84, (m, 3))
    ang = f64_view(work, 96, (m, 3))     # (yaw rate, pitch rate, roll rate)
    for k in range(3 if drift else m):
        for i in range(3):
            acc = 0.0
            if k < 3:
                # u = e_k: only j = k contributes (the other terms are exact zeros, and
                # (a b) 1 = a b: the same floats as the general sum, a third of its work).
                for p in range(3):
                    acc -= f_phi_inv[i, p] * f_q[p, k]
            else:
                for j in range(3):
                    u = qd[j]
                    for p in range(3):
                        acc -= f_phi_inv[i, p] * f_q[p, j] * u
            phid[k, i] = acc
        for i in range(3):
            u = qd[i] if k == 3 else (1.0 if i == k else 0.0)
            rhod[k, i] = ln * cphi[i] * phid[k, i]
            hd[k, i] = u - ln * sphi[i] * phid[k, i]
        vx, vy, vz, mx, my, mz = _centroid_and_moment(r, ct, st, rhod[k], hd[k])
        wx, wy, wz = _from_moment(ginv, nx, ny, nz, mx, my, mz)
        w[k, 0] = wx
        w[k, 1] = wy
        w[k, 2] = wz
        yaw_d, pitch_d, roll_d = _euler_rates(wx, wy, wz, ca, sa, cb, sb)
        ang[k, 0] = yaw_d
        ang[k, 1] = pitch_d
        ang[k, 2] = roll_d
        if k < 3:
            for i in range(3):
                S[2 * i, k] = 1.0 if i == k else 0.0
                S[2 * i + 1, k] = phid[k, i]
            S[IX_X, k] = vx
            S[IX_Y, k] = vy
            S[IX_Z, k] = vz
            S[IX_YAW, k] = yaw_d
            S[IX_PITCH, k] = pitch_d
            S[IX_ROLL, k] = roll_d
            twist[0, k] = vx
            twist[1, k] = vy
            twist[2, k] = vz
            twist[3, k] = wx
            twist[4, k] = wy
            twist[5, k] = wz
    if drift:
        # Row 3 (u = q̇): every rate above is linear in u, so Σ_j q̇_j (row j) (the same to
        # round-off, a fraction of the work).
        for c in range(3):
            for arr in (phid, rhod, hd, w, ang):
                arr[3, c] = qd[0] * arr[0, c] + qd[1] * arr[1, c] + qd[2] * arr[2, c]

    # Ṡ e_k = H(qd, e_k): the symmetric bilinear second-order term of Q(q) (q̈ = 0).
    eb_x = -sa
    eb_y = ca
    eg_x = ca * cb
    eg_y = sa * cb
    eg_z = -sb
    u_ = 3
    kappa = work[108:111]
    phidd = work[111:114]
    for col in range(1 if drift else 3):
        k = 3 if drift else col           # the second argument's row: e_k, or q̇ itself
        pp = work[114:117]
        for i in range(3):
            pp[i] = phid[u_, i] * phid[k, i]
        for p in range(3):
            i = (0, 1, 2)[p]
            j = (1, 2, 0)[p]
            c = cpair[p]
            d = h[i] - h[j]
            rho0_i = -ln * sphi[i] * pp[i]
            rho0_j = -ln * sphi[j] * pp[j]
            h0_i = -ln * cphi[i] * pp[i]
            h0_j = -ln * cphi[j] * pp[j]
            dd_u = hd[u_, i] - hd[u_, j]
            dd_w = hd[k, i] - hd[k, j]
            kappa[p] = (2.0 * rhod[u_, i] * rhod[k, i] + 2.0 * rho[i] * rho0_i
                        + 2.0 * rhod[u_, j] * rhod[k, j] + 2.0 * rho[j] * rho0_j
                        - 2.0 * c * (rho0_i * rho[j] + rhod[u_, i] * rhod[k, j]
                                     + rhod[k, i] * rhod[u_, j] + rho[i] * rho0_j)
                        + 2.0 * dd_u * dd_w + 2.0 * d * (h0_i - h0_j))
        for i in range(3):
            acc = 0.0
            for p in range(3):
                acc -= f_phi_inv[i, p] * kappa[p]
            phidd[i] = acc
        rdd = work[117:120]
        hdd = work[120:123]
        for i in range(3):
            rdd[i] = ln * cphi[i] * phidd[i] - ln * sphi[i] * pp[i]
            hdd[i] = -ln * sphi[i] * phidd[i] - ln * cphi[i] * pp[i]
        ax, ay, az, mx, my, mz = _centroid_and_moment(r, ct, st, rdd, hdd)
        # Subtract ½[(P ω_u) × ω_w + (P ω_w) × ω_u], P = (3 R_p²/2)(I - n nᵀ).
        wu0, wu1, wu2 = w[u_, 0], w[u_, 1], w[u_, 2]
        ww0, ww1, ww2 = w[k, 0], w[k, 1], w[k, 2]
        nwu = dot3(nx, ny, nz, wu0, wu1, wu2)
        nww = dot3(nx, ny, nz, ww0, ww1, ww2)
        pu0 = half_p * (wu0 - nx * nwu)
        pu1 = half_p * (wu1 - ny * nwu)
        pu2 = half_p * (wu2 - nz * nwu)
        pw0 = half_p * (ww0 - nx * nww)
        pw1 = half_p * (ww1 - ny * nww)
        pw2 = half_p * (ww2 - nz * nww)
        c0, c1, c2 = cross3(pu0, pu1, pu2, ww0, ww1, ww2)
        d0, d1, d2 = cross3(pw0, pw1, pw2, wu0, wu1, wu2)
        mx -= 0.5 * (c0 + d0)
        my -= 0.5 * (c1 + d1)
        mz -= 0.5 * (c2 + d2)
        dwx, dwy, dwz = _from_moment(ginv, nx, ny, nz, mx, my, mz)
        # Remove the Euler-rate terms: β̇ ė_β + γ̇ ė_γ, symmetrised.
        ya_u, pi_u, ro_u = ang[u_, 0], ang[u_, 1], ang[u_, 2]
        ya_w, pi_w, ro_w = ang[k, 0], ang[k, 1], ang[k, 2]
        cb_coef = 0.5 * (pi_u * ya_w + pi_w * ya_u)
        # ẑ × e_β = (-e_β,y, e_β,x, 0)
        tx = cb_coef * (-eb_y)
        ty = cb_coef * eb_x
        tz = 0.0
        # ½[γ̇_u (α̇_w ẑ + β̇_w e_β) + γ̇_w (α̇_u ẑ + β̇_u e_β)] × e_γ
        ox = 0.5 * (ro_u * pi_w + ro_w * pi_u) * eb_x
        oy = 0.5 * (ro_u * pi_w + ro_w * pi_u) * eb_y
        oz = 0.5 * (ro_u * ya_w + ro_w * ya_u)
        c0, c1, c2 = cross3(ox, oy, oz, eg_x, eg_y, eg_z)
        tx += c0
        ty += c1
        tz += c2
        yaw_dd, pitch_dd, roll_dd = _euler_rates(dwx - tx, dwy - ty, dwz - tz, ca, sa, cb, sb)
        for i in range(3):
            Sd[2 * i, col] = 0.0
            Sd[2 * i + 1, col] = phidd[i]
        Sd[IX_X, col] = ax
        Sd[IX_Y, col] = ay
        Sd[IX_Z, col] = az
        Sd[IX_YAW, col] = yaw_dd
        Sd[IX_PITCH, col] = pitch_dd
        Sd[IX_ROLL, col] = roll_dd
    return det


FK_SINGULAR = -1
FK_NO_CONVERGENCE = -2


@njit(cache=True)
def fk_solve(geom, q, phi, step_tol, max_iterations):
    """Newton-Raphson on the rod angles ``phi`` (rad, in/out: warm start in, solution out).

    Solves the thesis's rigid-triangle equations f_p = |B_i - B_j|² - 3 R_p² = 0 for the pairs
    (0,1), (1,2), (2,0). Returns the number of iterations, or ``FK_SINGULAR`` /
    ``FK_NO_CONVERGENCE`` (``phi`` then holds the last iterate).
    """
    p0 = phi[0]
    p1 = phi[1]
    p2 = phi[2]
    it = 0
    while True:
        f0, f1, f2, a00, a01, a11, a12, a22, a20 = constraint_terms(geom, q, p0, p1, p2)
        det = a00 * a11 * a22 + a01 * a12 * a20
        if det == 0.0 or not math.isfinite(det):
            phi[0] = p0
            phi[1] = p1
            phi[2] = p2
            return FK_SINGULAR
        # A = [[a00, a01, 0], [0, a11, a12], [a20, 0, a22]]; Cramer's rule for A Δ = f.
        x0 = (f0 * a11 * a22 - a01 * (f1 * a22 - a12 * f2)) / det
        x1 = (a00 * (f1 * a22 - a12 * f2) + f0 * a12 * a20) / det
        x2 = (a00 * a11 * f2 + a01 * f1 * a20 - f0 * a11 * a20) / det
        p0 -= x0
        p1 -= x1
        p2 -= x2
        it += 1
        step = max(abs(x0), abs(x1), abs(x2))
        if step < step_tol:
            break
        if it >= max_iterations or not math.isfinite(step) or step > 10.0:
            phi[0] = p0
            phi[1] = p1
            phi[2] = p2
            return FK_NO_CONVERGENCE
    phi[0] = p0
    phi[1] = p1
    phi[2] = p2
    return it


@njit(cache=True)
def assemble(geom, q, phi, rot, pos, spheres):
    """Platform frame from the three sphere centres (thesis eq. 7).

    Writes R_BP into ``rot`` (3×3), the platform origin (centroid of the spheres) into ``pos``
    and the sphere centres into ``spheres`` (3×3, one per row), all in the base frame (m).
    """
    assemble_sc(geom, q, math.sin(phi[0]), math.cos(phi[0]), math.sin(phi[1]),
                math.cos(phi[1]), math.sin(phi[2]), math.cos(phi[2]), rot, pos, spheres)


@njit(cache=True)
def fk_rows(geom, qs, phi_guess, step_tol, max_iterations, rot_z, status):
    """``Kinematics.fk(q, check=False)`` for each row of ``qs`` (m, finite) in order: Newton
    (:func:`fk_solve`) warm-started from ``phi_guess`` (rad, in/out: the last solution; a row
    that fails leaves it, as ``fk`` does), then :func:`assemble`. Writes each row's
    iterations or ``FK_SINGULAR``/``FK_NO_CONVERGENCE`` to ``status`` and R_BP's third row
    (what roll and pitch are read from) to ``rot_z``: the same floats as that many ``fk``
    calls, without their Python (issue 16: the pre-flight figures' ROM, ≈ 15 µs a row)."""
    q = np.empty(3)
    phi = np.empty(3)
    rot = np.empty((3, 3))
    pos = np.empty(3)
    spheres = np.empty((3, 3))
    for r in range(qs.shape[0]):
        for i in range(3):
            q[i] = qs[r, i]
            phi[i] = phi_guess[i]
        it = fk_solve(geom, q, phi, step_tol, max_iterations)
        status[r] = it
        if it < 0:
            continue
        assemble(geom, q, phi, rot, pos, spheres)
        for c in range(3):
            rot_z[r, c] = rot[2, c]
            phi_guess[c] = phi[c]


@njit(cache=True)
def assemble_sc(geom, q, s0, c0, s1, c1, s2, c2, rot, pos, spheres):
    """:func:`assemble` from the rod angles' sines and cosines (the same arithmetic)."""
    rb = geom[0]
    ln = geom[2]
    for i in range(3):
        s = s0 if i == 0 else (s1 if i == 1 else s2)
        c = c0 if i == 0 else (c1 if i == 1 else c2)
        rad = rb + ln * s
        spheres[i, 0] = rad * geom[3 + i]
        spheres[i, 1] = rad * geom[6 + i]
        spheres[i, 2] = q[i] + ln * c
    for c in range(3):
        pos[c] = (spheres[0, c] + spheres[1, c] + spheres[2, c]) / 3.0
    # Platform z axis: normal of the sphere triangle (legs counter-clockwise -> points up).
    ux = spheres[1, 0] - spheres[0, 0]
    uy = spheres[1, 1] - spheres[0, 1]
    uz = spheres[1, 2] - spheres[0, 2]
    vx = spheres[2, 0] - spheres[0, 0]
    vy = spheres[2, 1] - spheres[0, 1]
    vz = spheres[2, 2] - spheres[0, 2]
    nx, ny, nz = cross3(ux, uy, uz, vx, vy, vz)
    nx, ny, nz = unit3(nx, ny, nz)
    # f1: unit vector towards sphere 0 in the base frame; e1 the same in the platform frame.
    fx, fy, fz = unit3(spheres[0, 0] - pos[0], spheres[0, 1] - pos[1], spheres[0, 2] - pos[2])
    gx, gy, gz = cross3(nx, ny, nz, fx, fy, fz)     # n × f1
    e1x = geom[3]
    e1y = geom[6]
    e2x = -e1y                              # ẑ × e1
    e2y = e1x
    # R = f1 e1ᵀ + (n × f1) e2ᵀ + n ẑᵀ
    rot[0, 0] = fx * e1x + gx * e2x
    rot[0, 1] = fx * e1y + gx * e2y
    rot[0, 2] = nx
    rot[1, 0] = fy * e1x + gy * e2x
    rot[1, 1] = fy * e1y + gy * e2y
    rot[1, 2] = ny
    rot[2, 0] = fz * e1x + gz * e2x
    rot[2, 1] = fz * e1y + gz * e2y
    rot[2, 2] = nz


# ---------------------------------------------------------------------------- the model block
FK_OUTSIDE = -3
#: ``limits`` layout for :func:`model_state`.
LIMIT_STROKE_LO, LIMIT_STROKE_HI, LIMIT_ROD, LIMIT_CONE, LIMIT_ROLL, LIMIT_PITCH = range(6)
MODEL_STATE_WORK = 27 + TREE_MAPS_WORK


@njit(cache=True)
def model_state(geom, limits, phi_guess, q_meas, qd, stb, step_tol, max_iterations, work):
    """The model block's cycle, compiled: FK warm-started from ``phi_guess`` (updated on
    success), the workspace check, S, Ṡ and the twist map for ``qd``, written into the State
    buffer ``stb`` (layout ``rt.model.rigid_body.STATE_*``).

    Returns the Newton iterations (≥ 0), or ``FK_SINGULAR`` / ``FK_NO_CONVERGENCE`` /
    ``FK_OUTSIDE`` (non-finite q, outside the stroke or the workspace); then ``stb`` and
    ``phi_guess`` are untouched, as when ``Kinematics.fk`` raises. Same arithmetic as
    ``Kinematics.fk`` + ``Dynamics.state``; ``work`` is float64[MODEL_STATE_WORK].
    """
    q0 = q_meas[0]
    q1 = q_meas[1]
    q2 = q_meas[2]
    if not (math.isfinite(q0) and math.isfinite(q1) and math.isfinite(q2)):
        return FK_OUTSIDE
    lo = limits[LIMIT_STROKE_LO]
    hi = limits[LIMIT_STROKE_HI]
    if not (lo <= q0 <= hi and lo <= q1 <= hi and lo <= q2 <= hi):
        return FK_OUTSIDE
    q = work[0:3]
    phi = work[3:6]
    rot = f64_view(work, 6, (3, 3))
    pos = work[15:18]
    q[0] = q0
    q[1] = q1
    q[2] = q2
    phi[0] = phi_guess[0]
    phi[1] = phi_guess[1]
    phi[2] = phi_guess[2]
    iterations = fk_solve(geom, q, phi, step_tol, max_iterations)
    if iterations < 0:
        return iterations
    spheres = f64_view(stb, rb.STATE_SPHERES, (3, 3))
    sph = f64_view(work, 18, (3, 3))
    assemble(geom, q, phi, rot, pos, sph)
    roll, pitch = roll_pitch(rot)
    yaw = math.atan2(rot[1, 0], rot[0, 0])
    # Workspace (Kinematics.workspace_violations): rods, spherical cones, roll, pitch.
    nx = rot[0, 2]
    ny = rot[1, 2]
    nz = rot[2, 2]
    for i in range(3):
        p = phi[i]
        if abs(p) > limits[LIMIT_ROD]:
            return FK_OUTSIDE
        if rod_cone_angle(geom, i, math.sin(p), math.cos(p), nx, ny, nz) > limits[LIMIT_CONE]:
            return FK_OUTSIDE
    if abs(roll) > limits[LIMIT_ROLL] or abs(pitch) > limits[LIMIT_PITCH]:
        return FK_OUTSIDE
    phi_guess[0] = phi[0]
    phi_guess[1] = phi[1]
    phi_guess[2] = phi[2]
    Q, Qd, qd_s, S, Sd, twist, rot_s, q_s, phi_s = rb.unpack_state(stb)
    for i in range(3):
        q_s[i] = q[i]
        phi_s[i] = phi[i]
        qd_s[i] = qd[i]
        for c in range(3):
            rot_s[i, c] = rot[i, c]
            spheres[i, c] = sph[i, c]
    stb[rb.STATE_ITERATIONS] = iterations
    stb[rb.STATE_DET] = tree_maps_work(geom, q_s, phi_s, rot_s, qd_s, S, Sd, twist,
                                       work[27:27 + TREE_MAPS_WORK])
    Q[0] = q0
    Q[1] = phi[0]
    Q[2] = q1
    Q[3] = phi[1]
    Q[4] = q2
    Q[5] = phi[2]
    Q[6] = pos[0]
    Q[7] = pos[1]
    Q[8] = pos[2]
    Q[9] = yaw
    Q[10] = pitch
    Q[11] = roll
    for j in range(TREE_DOF):
        Qd[j] = S[j, 0] * qd_s[0] + S[j, 1] * qd_s[1] + S[j, 2] * qd_s[2]
    return iterations
