"""Closed-form inverse kinematics compiled with numba: one pose, or a whole path at once.

``rt.model.kinematics.Kinematics.ik`` is the reference: it builds a ``Configuration`` per call
(≈ 6 µs interpreted), which is what made a 60 s protocol's references cost seconds (three IK
per sample for q, q̇, q̈). These kernels do the same arithmetic, in the same order, on
preallocated rows, so a path of 60 000 samples costs milliseconds; the workspace check is the
same numeric test as ``Kinematics.workspace_violations`` (its sentences are produced by the
interpreted IK for the one sample a caller reports).

A row of ``out`` (float64[IK_ROW]) holds: q (3, m), φ (3, rad), x, y (m), yaw (rad), R (9,
row-major, R = Rz(yaw) Ry(pitch) Rx(roll)). ``geom`` is ``Kinematics.geom``
(``rt.model.kernels.pack_geometry``); ``limits`` is ``Kinematics.limits_array``.
"""
from __future__ import annotations

import math

from numba import njit

from rt.model.kernels import (
    LIMIT_CONE,
    LIMIT_PITCH,
    LIMIT_ROD,
    LIMIT_ROLL,
    LIMIT_STROKE_HI,
    LIMIT_STROKE_LO,
    rod_cone_angle,
)

IK_ROW = 18
COL_Q, COL_PHI, COL_X, COL_Y, COL_YAW, COL_ROT = 0, 3, 6, 7, 8, 9
#: ``ik_pose`` results.
IK_OK = 0
IK_NONFINITE = 1          # z, roll or pitch is NaN or infinite
IK_UNREACHABLE = 2        # a sphere is farther from its guide than the rod's length


@njit(cache=True)
def ik_pose(geom, z, roll, pitch, row):
    """IK of one pose (z m, roll γ rad, pitch β rad) into ``row`` (float64[IK_ROW]);
    returns ``IK_OK``, ``IK_NONFINITE`` or ``IK_UNREACHABLE`` (then ``row`` is partial)."""
    if not (math.isfinite(z) and math.isfinite(roll) and math.isfinite(pitch)):
        return IK_NONFINITE
    rp = geom[1]
    rb = geom[0]
    length = geom[2]
    # parasitic_yaw and rotation_zyx of rt.model.kinematics, term for term.
    yaw = math.atan2(math.sin(pitch) * math.sin(roll), math.cos(pitch) + math.cos(roll))
    ca, sa = math.cos(yaw), math.sin(yaw)
    cb, sb = math.cos(pitch), math.sin(pitch)
    cg, sg = math.cos(roll), math.sin(roll)
    r0 = ca * cb
    r1 = ca * sb * sg - sa * cg
    r2 = ca * sb * cg + sa * sg
    r3 = sa * cb
    r4 = sa * sb * sg + ca * cg
    r5 = sa * sb * cg - ca * sg
    r6 = -sb
    r7 = cb * sg
    r8 = cb * cg
    rt_sum_x = 0.0
    rt_sum_y = 0.0
    # The sphere offsets R r_i (x, y, z of leg i) wait in row[i], row[3 + i], row[6 + i]:
    # leg i's q and φ overwrite only its own slots, after reading them.
    for i in range(3):
        c = geom[3 + i]
        s = geom[6 + i]
        row[i] = rp * (r0 * c + r1 * s)
        row[3 + i] = rp * (r3 * c + r4 * s)
        row[6 + i] = rp * (r6 * c + r7 * s)
        along_t = -s * row[i] + c * row[3 + i]
        rt_sum_x += -s * along_t
        rt_sum_y += c * along_t
    x = -2.0 / 3.0 * rt_sum_x
    y = -2.0 / 3.0 * rt_sum_y
    for i in range(3):
        c = geom[3 + i]
        s = geom[6 + i]
        bx = x + row[i]
        by = y + row[3 + i]
        bz = z + row[6 + i]
        radial = bx * c + by * s
        sin_phi = (radial - rb) / length
        if abs(sin_phi) >= 1.0:
            return IK_UNREACHABLE
        phi = math.asin(sin_phi)
        row[COL_PHI + i] = phi
        row[COL_Q + i] = bz - length * math.cos(phi)
    row[COL_X] = x
    row[COL_Y] = y
    row[COL_YAW] = yaw
    row[COL_ROT + 0] = r0
    row[COL_ROT + 1] = r1
    row[COL_ROT + 2] = r2
    row[COL_ROT + 3] = r3
    row[COL_ROT + 4] = r4
    row[COL_ROT + 5] = r5
    row[COL_ROT + 6] = r6
    row[COL_ROT + 7] = r7
    row[COL_ROT + 8] = r8
    return IK_OK


@njit(cache=True)
def in_workspace(geom, limits, roll, pitch, row):
    """The numeric test of ``Kinematics.workspace_violations`` on an IK row (True: inside)."""
    lo = limits[LIMIT_STROKE_LO]
    hi = limits[LIMIT_STROKE_HI]
    nx = row[COL_ROT + 2]
    ny = row[COL_ROT + 5]
    nz = row[COL_ROT + 8]
    for i in range(3):
        qi = row[COL_Q + i]
        if not (lo <= qi <= hi):
            return False
        phi = row[COL_PHI + i]
        if abs(phi) > limits[LIMIT_ROD]:
            return False
        if rod_cone_angle(geom, i, math.sin(phi), math.cos(phi), nx, ny, nz) > limits[LIMIT_CONE]:
            return False
    return abs(roll) <= limits[LIMIT_ROLL] and abs(pitch) <= limits[LIMIT_PITCH]


@njit(cache=True)
def ik_path(geom, limits, z, roll, pitch, check, out):
    """IK of every pose k of the arrays ``z``, ``roll``, ``pitch`` into ``out[k]`` (n×IK_ROW).

    Returns the first index whose pose is not finite, unreachable or (``check[k]``) outside
    the workspace, else -1; rows after it are not computed. ``Kinematics.ik(..., check=True)``
    also refuses |roll| or |pitch| beyond the limits before computing; that is part of the
    workspace test here."""
    n = z.shape[0]
    for k in range(n):
        status = ik_pose(geom, z[k], roll[k], pitch[k], out[k])
        if status != IK_OK:
            return k
        if check[k] and not in_workspace(geom, limits, roll[k], pitch[k], out[k]):
            return k
    return -1


@njit(cache=True)
def ik_three(geom, z, roll, pitch, out):
    """IK of three poses (the centre of a central difference and its two neighbours) into
    ``out`` (3×IK_ROW): one call per cycle for an online generator; returns the first index
    that fails (``ik_pose``), else -1. No workspace test."""
    for k in range(3):
        if ik_pose(geom, z[k], roll[k], pitch[k], out[k]) != IK_OK:
            return k
    return -1
