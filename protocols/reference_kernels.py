"""Compiled reference generation: slider references of a whole angle path in one numba call.

``protocols.base.joint_references`` (the interpreted reference implementation, kept) costs three
``Kinematics.ik`` per sample: ≈ 2 s for a 60 s exercise at 1 kHz. :func:`path_references` does
the same arithmetic in the same order through ``rt.model.ik_kernels`` (q = IK at the sample,
q̇ and q̈ by central differences along the local quadratic path, holds reusing the previous
sample, the heave that keeps the ankle centre at its height when asked), in milliseconds.

It reports problems by index only; the caller then runs the interpreted implementation, which
words the refusal (and raises where it raises): refusals are rare, and their wording stays in
one place.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rt.model.ik_kernels import (
    COL_PHI,
    COL_Q,
    COL_ROT,
    COL_X,
    COL_Y,
    IK_OK,
    IK_ROW,
    ik_pose,
    ik_three,
    in_workspace,
)
from rt.model.kernels import assemble, fk_solve
from rt.model.small_linalg import dot3, roll_pitch

#: ``path_references`` packs the ankle's heave law as [on (0/1), A0_z, a_x, a_y, a_z].
HEAVE_PARAMS = 5


@njit(cache=True)
def _heave(z, heave, r, p):
    """``AnkleKinematics.z_for`` (heave[0] = 1) or the constant ``z``."""
    if heave[0] == 0.0:
        return z
    cb = math.cos(p)
    return heave[1] - (-math.sin(p) * heave[2] + cb * math.sin(r) * heave[3]
                       + cb * math.cos(r) * heave[4])


@njit(cache=True)
def path_references(geom, limits, z, heave, path, h, q, qd, qdd, z_out):
    """Fill q, q̇, q̈ (n×3) and the heave ``z_out`` (n) from an angle path (n×7, columns of
    ``protocols.profiles``). Returns -1, or the first sample whose pose is outside the
    workspace or whose difference points are unreachable (outputs from there on unfilled)."""
    hh = 0.5 * h * h
    row = np.empty(IK_ROW)
    rowp = np.empty(IK_ROW)
    rowm = np.empty(IK_ROW)
    n = path.shape[0]
    for k in range(n):
        r = path[k, 0]
        p = path[k, 1]
        vr = path[k, 2]
        vp = path[k, 3]
        ar = path[k, 4]
        ap = path[k, 5]
        zk = _heave(z, heave, r, p)
        z_out[k] = zk
        still = vr == 0.0 and vp == 0.0 and ar == 0.0 and ap == 0.0
        if still and k > 0 and r == path[k - 1, 0] and p == path[k - 1, 1]:
            for i in range(3):
                q[k, i] = q[k - 1, i]
                qd[k, i] = 0.0
                qdd[k, i] = 0.0
            continue
        if ik_pose(geom, zk, r, p, row) != IK_OK or not in_workspace(geom, limits, r, p, row):
            return k
        for i in range(3):
            q[k, i] = row[COL_Q + i]
        if still:
            for i in range(3):
                qd[k, i] = 0.0
                qdd[k, i] = 0.0
            continue
        rp_, pp_ = r + h * vr + hh * ar, p + h * vp + hh * ap
        rm_, pm_ = r - h * vr + hh * ar, p - h * vp + hh * ap
        if ik_pose(geom, _heave(z, heave, rp_, pp_), rp_, pp_, rowp) != IK_OK:
            return k
        if ik_pose(geom, _heave(z, heave, rm_, pm_), rm_, pm_, rowm) != IK_OK:
            return k
        for i in range(3):
            qd[k, i] = (rowp[COL_Q + i] - rowm[COL_Q + i]) / (2.0 * h)
            qdd[k, i] = (rowp[COL_Q + i] - 2.0 * row[COL_Q + i] + rowm[COL_Q + i]) / (h * h)
    return -1


@njit(cache=True)
def ankle_horizontal(geom, z_neutral, start, centre, roll, pitch, out):
    """Horizontal displacement (m) of the ankle centre at every (roll, pitch) (rad) into
    ``out``: ``AnkleKinematics.pose_for_platform_angles(...).horizontal_m`` sample by sample
    (IK at the neutral heave for the rotation and the parasitic x, y; the heave changes only
    the centre's height, so compensating or not gives the same horizontal displacement; numba's
    ``hypot`` may differ from CPython's by an ulp). Returns -1, or the first unreachable
    sample."""
    row = np.empty(IK_ROW)
    ax, ay, az = centre[0], centre[1], centre[2]
    for k in range(roll.shape[0]):
        if ik_pose(geom, z_neutral, roll[k], pitch[k], row) != IK_OK:
            return k
        rx = dot3(row[COL_ROT], row[COL_ROT + 1], row[COL_ROT + 2], ax, ay, az)
        ry = dot3(row[COL_ROT + 3], row[COL_ROT + 4], row[COL_ROT + 5], ax, ay, az)
        dx = row[COL_X] + rx - start[0]
        dy = row[COL_Y] + ry - start[1]
        out[k] = math.hypot(dx, dy)
    return -1


@njit(cache=True)
def fk_path(geom, limits, q, phi, step_tol, max_iterations, pose):
    """``Kinematics.fk(q[k], check=True)`` for every row of ``q`` (n×3), each warm-started
    from the previous solution (``phi``: the warm start in, the last solution out), the pose
    (z, roll, pitch) into ``pose`` (n×3). Returns -1, or the first row outside the stroke, whose
    Newton iteration fails or whose pose is outside the workspace (``phi`` then unchanged)."""
    work = np.empty(3)
    work[:] = phi
    rot = np.empty((3, 3))
    pos = np.empty(3)
    spheres = np.empty((3, 3))
    row = np.empty(IK_ROW)
    lo = limits[0]
    hi = limits[1]
    for k in range(q.shape[0]):
        qk = q[k]
        for i in range(3):
            if not (lo <= qk[i] <= hi):
                return k
        if fk_solve(geom, qk, work, step_tol, max_iterations) < 0:
            return k
        assemble(geom, qk, work, rot, pos, spheres)
        roll, pitch = roll_pitch(rot)
        for i in range(3):
            row[COL_Q + i] = qk[i]
            row[COL_PHI + i] = work[i]
        for a in range(3):
            for b in range(3):
                row[COL_ROT + 3 * a + b] = rot[a, b]
        if not in_workspace(geom, limits, roll, pitch, row):
            return k
        pose[k, 0] = pos[2]
        pose[k, 1] = roll
        pose[k, 2] = pitch
    phi[:] = work
    return -1


def warm_up(geom: np.ndarray, limits: np.ndarray) -> None:
    """Load these kernels from numba's cache (compile them on a cold cache) now, with the
    argument types the generators pass: a pre-flight worker calls it when it starts, so the
    first protocol does not pay it."""
    n = 2
    path = np.zeros((n, 7))
    q, qd, qdd = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    path_references(geom, limits, 0.63, np.zeros(HEAVE_PARAMS), path, 1e-3, q, qd, qdd,
                    np.zeros(n))
    ankle_horizontal(geom, 0.63, np.zeros(3), np.zeros(3), np.zeros(n), np.zeros(n),
                     np.zeros(n))
    fk_path(geom, limits, np.full((n, 3), 0.2), np.zeros(3), 1e-12, 25, np.zeros((n, 3)))
    rows = np.zeros((3, IK_ROW))
    ik_three(geom, np.full(3, 0.63), np.zeros(3), np.zeros(3), rows)
