"""The compiled kernels' 3-vector and 3 × 3 helpers (rt.model.small_linalg): each gives the
bits of the expression it replaced (the same products summed in the same order), agrees with
numpy, and has the properties its callers rely on."""
from __future__ import annotations

import itertools
import math

import numpy as np

from rt.model.kinematics import rotation_zyx
from rt.model.small_linalg import cross3, dot3, mat_t_vec3, mat_vec3, roll_pitch, unit3

RNG = np.random.default_rng(3)
#: Vectors over several magnitudes, as the kernels see (m, rad/s, N, N m).
VECTORS = [RNG.normal(0.0, 10.0 ** RNG.integers(-3, 3), 3) for _ in range(200)]


def test_cross_and_dot_are_the_spelled_out_expressions_bit_for_bit() -> None:
    for a, b in itertools.pairwise(VECTORS):
        ax, ay, az = (float(x) for x in a)
        bx, by, bz = (float(x) for x in b)
        assert cross3(ax, ay, az, bx, by, bz) == (ay * bz - az * by, az * bx - ax * bz,
                                                  ax * by - ay * bx)
        # numpy's cross multiplies and subtracts the same pairs: the same bits too.
        assert np.array_equal(cross3(ax, ay, az, bx, by, bz), np.cross(a, b))
        assert dot3(ax, ay, az, bx, by, bz) == ax * bx + ay * by + az * bz
        c = cross3(ax, ay, az, bx, by, bz)
        # a × b is orthogonal to both (to round-off of the products' size).
        scale = np.linalg.norm(a) * np.linalg.norm(b)
        assert abs(dot3(*c, ax, ay, az)) <= 1e-14 * scale * np.linalg.norm(a)
        assert abs(dot3(*c, bx, by, bz)) <= 1e-14 * scale * np.linalg.norm(b)


def test_matrix_products_agree_with_numpy_and_with_each_other() -> None:
    for k in range(50):
        M = RNG.normal(0.0, 1.0, (3, 3))
        x, y, z = (float(v) for v in VECTORS[k])
        got = np.array(mat_vec3(M, x, y, z))
        row_by_row = [M[r, 0] * x + M[r, 1] * y + M[r, 2] * z for r in range(3)]
        assert got.tolist() == row_by_row
        np.testing.assert_allclose(got, M @ VECTORS[k], rtol=1e-14, atol=1e-300)
        # Mᵀ v is the transpose's product, the same bits (the same terms in the same order).
        assert mat_t_vec3(M, x, y, z) == mat_vec3(np.ascontiguousarray(M.T), x, y, z)
        # A stack's slice (how the RNEA passes R[j]) reads the same matrix.
        stack = np.stack([M * 0.5, M])
        assert mat_vec3(stack[1], x, y, z) == mat_vec3(M, x, y, z)


def test_unit_vectors_and_roll_pitch_round_trip() -> None:
    for v in VECTORS[:50]:
        u = np.array(unit3(*(float(x) for x in v)))
        assert abs(np.linalg.norm(u) - 1.0) <= 2e-16 * 4
        np.testing.assert_allclose(u * np.linalg.norm(v), v, rtol=1e-15, atol=1e-15 * max(
            np.abs(v)))
    for _ in range(200):
        yaw, pitch, roll = RNG.uniform(-math.pi, math.pi), RNG.uniform(-1.5, 1.5), \
            RNG.uniform(-math.pi, math.pi)
        R = np.array(rotation_zyx(yaw, pitch, roll)).reshape(3, 3)
        got_roll, got_pitch = roll_pitch(R)
        assert abs(got_roll - roll) < 1e-12 and abs(got_pitch - pitch) < 1e-12
