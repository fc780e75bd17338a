"""The twin's plate contact with static friction (rt.twin.physics.environment_wrench, plate
branch): the tool tip sticks where it touched, a tangential displacement loads a spring to that
point, and the shear never exceeds μ times the normal force (the tip slips, the stuck point
follows). Without tangential stiffness the contact is the viscous drag it always was."""
from __future__ import annotations

import numpy as np
import pytest

from rt.twin import physics
from rt.twin.environment import ForcePlateContact

K_N, K_T, MU = 2.0e6, 1.0e6, 0.4
SENSOR_Z = 0.08
TOOL = 0.02


def _wrench(env: np.ndarray, state: np.ndarray, x: float, y: float, depth: float) -> np.ndarray:
    """Environment wrench on a level platform whose origin is at (x, y) with the tip ``depth``
    into the plate (at rest: no damping)."""
    bodies = np.zeros(physics.N_BODY_PARAMS)
    bodies[physics.B_SENSOR:physics.B_SENSOR + 3] = (0.0, 0.0, SENSOR_Z)
    z_plate = env[1]
    pos = np.array([x, y, z_plate - SENSOR_Z - TOOL + depth])
    wrench, tau = np.zeros(6), np.zeros(3)
    physics.environment_wrench(env, bodies, np.eye(3), pos, np.zeros((6, 3)), np.zeros(3), state,
                               wrench, tau)
    return wrench


def test_the_tip_sticks_then_slips_at_the_friction_cone() -> None:
    env = ForcePlateContact(plate_height_m=0.75, stiffness_n_per_m=K_N, damping_n_s_per_m=0.0,
                            tangential_damping_n_s_per_m=0.0, tool_length_m=TOOL,
                            tangential_stiffness_n_per_m=K_T, friction_coefficient=MU).pack()
    state = np.zeros(4)
    depth = 0.5e-3                                   # 1000 N normal
    w = _wrench(env, state, 0.0, 0.0, depth)
    assert w[2] == pytest.approx(-K_N * depth) and w[0] == 0.0 and w[1] == 0.0
    # Stuck: 0.1 mm sideways is 100 N of shear against the motion, within μ N = 400 N.
    w = _wrench(env, state, 1e-4, 0.0, depth)
    assert w[0] == pytest.approx(-K_T * 1e-4) and w[1] == pytest.approx(0.0, abs=1e-9)
    # The moment about the sensor origin of a shear at the tip (TOOL above it).
    assert w[4] == pytest.approx(TOOL * w[0], rel=1e-9)
    # 2 mm sideways: beyond the cone, the shear is μ N and the stuck point follows the tip.
    w = _wrench(env, state, 2e-3, 1e-3, depth)
    assert np.hypot(w[0], w[1]) == pytest.approx(MU * K_N * depth)
    assert np.degrees(np.arctan2(w[1], w[0])) == pytest.approx(
        np.degrees(np.arctan2(-1e-3, -2e-3)))
    # Back by 0.1 mm from there: the spring unloads (stick again), no longer at the cone.
    w = _wrench(env, state, 2e-3 - 1e-4, 1e-3, depth)
    assert np.hypot(w[0], w[1]) < MU * K_N * depth - 50.0
    # Lifting off forgets the stuck point: the next touch sticks where it lands.
    _wrench(env, state, 0.0, 0.0, -1e-3)
    w = _wrench(env, state, 5e-3, 0.0, depth)
    assert w[0] == pytest.approx(0.0) and w[1] == pytest.approx(0.0)


def test_without_tangential_stiffness_only_the_drag_remains() -> None:
    env = ForcePlateContact(plate_height_m=0.75, damping_n_s_per_m=0.0,
                            tool_length_m=TOOL).pack()
    state = np.zeros(4)
    _wrench(env, state, 0.0, 0.0, 0.5e-3)
    w = _wrench(env, state, 2e-3, 0.0, 0.5e-3)      # at rest: no drag, no friction spring
    assert w[0] == 0.0 and w[1] == 0.0
