"""3-vector and 3 × 3 arithmetic for the compiled kernels, on scalars (numba).

The kernels (``rt.model.rigid_body``, ``rt.model.kernels``, ``protocols.reference_kernels``)
keep their vectors in scalars and array rows rather than allocating small arrays in the
cycle; these helpers are the one spelling of the products they repeat. Each is inlined into
its caller (``inline="always"``) and evaluates its terms in the order written here, so a
kernel that used to spell a product out gets the same bits from the helper (checked before
and after the change that introduced them: docs/worklog, tidy3).

Vectors are passed as three scalars and returned as 3-tuples; matrices as 3 × 3 arrays
(views such as ``R[j]`` of an n × 3 × 3 stack cost nothing once inlined).
"""
from __future__ import annotations

import math

from numba import njit


@njit(cache=True, inline="always")
def cross3(ax, ay, az, bx, by, bz):
    """a × b."""
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@njit(cache=True, inline="always")
def dot3(ax, ay, az, bx, by, bz):
    """a · b, summed x, y, z in that order."""
    return ax * bx + ay * by + az * bz


@njit(cache=True, inline="always")
def mat_vec3(M, x, y, z):
    """M v for a 3 × 3 ``M``."""
    return (M[0, 0] * x + M[0, 1] * y + M[0, 2] * z,
            M[1, 0] * x + M[1, 1] * y + M[1, 2] * z,
            M[2, 0] * x + M[2, 1] * y + M[2, 2] * z)


@njit(cache=True, inline="always")
def mat_t_vec3(M, x, y, z):
    """Mᵀ v for a 3 × 3 ``M`` (a rotation's inverse applied without forming it)."""
    return (M[0, 0] * x + M[1, 0] * y + M[2, 0] * z,
            M[0, 1] * x + M[1, 1] * y + M[2, 1] * z,
            M[0, 2] * x + M[1, 2] * y + M[2, 2] * z)


@njit(cache=True, inline="always")
def unit3(x, y, z):
    """v / |v| (a zero vector gives NaN: the callers' geometry never has one)."""
    n = math.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


@njit(cache=True, inline="always")
def roll_pitch(R):
    """(roll γ, pitch β) in rad of R = Rz(yaw) Ry(β) Rx(γ), read off its last row (β in
    [−π/2, π/2]); ``rt.model.kinematics`` convention."""
    return (math.atan2(R[2, 1], R[2, 2]),
            math.atan2(-R[2, 0], math.hypot(R[2, 1], R[2, 2])))
