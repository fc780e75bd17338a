"""Kinematics: IK∘FK identity, constraint geometry, Jacobians vs finite differences, workspace."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from rt.errors import ConvergenceError, KinematicsError, WorkspaceError
from rt.model.kinematics import Kinematics
from rt.model.workspace import conditioning, heave_range

# Poses drawn over the workspace: heave over the level-platform range, tilts up to the limits.
Z = st.floats(0.45, 0.82)
ANGLE = st.floats(-math.radians(24.0), math.radians(24.0))


def tree_coordinates(cfg) -> np.ndarray:
    return np.array([cfg.q[0], cfg.phi[0], cfg.q[1], cfg.phi[1], cfg.q[2], cfg.phi[2],
                     cfg.x, cfg.y, cfg.z, cfg.yaw, cfg.pitch, cfg.roll])


def _ik_or_reject(kin, z, roll, pitch):
    try:
        return kin.ik(z, roll, pitch)
    except WorkspaceError:
        assume(False)


@given(Z, ANGLE, ANGLE)
def test_fk_inverts_ik(robot, z, roll, pitch):
    kin = robot.kin
    cfg = _ik_or_reject(kin, z, roll, pitch)
    back = kin.fk(cfg.q, guess=(kin.phi_nominal,) * 3)      # cold start: the hardest case
    # Newton stops at a step < 1e-12 rad; with quadratic convergence the pose error is then at
    # float round-off of trig on O(1) numbers: 1e-11 m / rad leaves two decades of margin.
    assert back.z == pytest.approx(z, abs=1e-11)
    assert back.roll == pytest.approx(roll, abs=1e-11)
    assert back.pitch == pytest.approx(pitch, abs=1e-11)
    for a, b in zip((back.x, back.y, back.yaw), (cfg.x, cfg.y, cfg.yaw)):
        assert a == pytest.approx(b, abs=1e-11)
    assert back.iterations <= 8          # quadratic convergence from the nominal rod angle


@given(Z, ANGLE, ANGLE)
def test_ik_satisfies_every_constraint(robot, z, roll, pitch):
    kin = robot.kin
    cfg = _ik_or_reject(kin, z, roll, pitch)
    rot = np.array(cfg.rotation).reshape(3, 3)
    # Parasitic yaw from thesis eq. 9 is exactly the condition R[1,0] == R[0,1].
    assert rot[1, 0] == pytest.approx(rot[0, 1], abs=1e-14)
    p = np.array([cfg.x, cfg.y, cfg.z])
    for i in range(3):
        c, s = kin.cos_theta[i], kin.sin_theta[i]
        sphere = p + rot @ (kin.platform_radius * np.array([c, s, 0.0]))
        assert np.allclose(sphere, cfg.spheres[i], atol=1e-14)
        # Sphere i stays in its leg's vertical plane (normal = tangent t_i).
        assert sphere @ np.array([-s, c, 0.0]) == pytest.approx(0.0, abs=1e-14)
        slider = np.array([kin.base_radius * c, kin.base_radius * s, cfg.q[i]])
        assert np.linalg.norm(sphere - slider) == pytest.approx(kin.rod_length, abs=1e-14)


@given(st.floats(0.05, 0.35), st.floats(-0.06, 0.06), st.floats(-0.06, 0.06))
def test_ik_inverts_fk(robot, q0, d1, d2):
    kin = robot.kin
    q = (q0, q0 + d1, q0 + d2)
    assume(all(kin.stroke[0] <= v <= kin.stroke[1] for v in q))
    cfg = kin.fk(q)
    back = kin.ik(cfg.z, cfg.roll, cfg.pitch)
    assert np.allclose(back.q, q, atol=1e-11)


@given(Z, ANGLE, ANGLE, st.integers(0, 2))
def test_velocity_map_matches_finite_differences(robot, z, roll, pitch, k):
    kin, dyn = robot.kin, robot.dyn
    cfg = _ik_or_reject(kin, z, roll, pitch)
    q = np.array(cfg.q)
    h = 1e-6
    e = np.zeros(3)
    e[k] = h
    fd = (tree_coordinates(kin.fk(q + e, check=False))
          - tree_coordinates(kin.fk(q - e, check=False))) / (2 * h)
    st_ = dyn.state(q)
    # Central differences: truncation ~h² |Q'''| ≈ 1e-12, round-off ~1e-16/h = 1e-10 (FK solved to
    # 1e-12 rad); 1e-7 is three decades above both.
    assert np.allclose(st_.S[:, k], fd, atol=1e-7)


@given(Z, ANGLE, ANGLE)
def test_jacobians_inverse_of_each_other_and_ik_differences(robot, z, roll, pitch):
    kin, dyn = robot.kin, robot.dyn
    cfg = _ik_or_reject(kin, z, roll, pitch)
    st_ = dyn.state(cfg.q)
    j_ik = st_.inverse_jacobian()
    assert np.allclose(st_.forward_jacobian() @ j_ik, np.eye(3), atol=1e-10)
    h = 1e-6
    pose = np.array([z, roll, pitch])
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        fd = (np.array(kin.ik(*(pose + d), check=False).q)
              - np.array(kin.ik(*(pose - d), check=False).q)) / (2 * h)
        assert np.allclose(j_ik[:, k], fd, atol=1e-7)


@given(Z, ANGLE, ANGLE, st.tuples(*[st.floats(-0.3, 0.3)] * 3))
def test_velocity_map_derivative_matches_finite_differences(robot, z, roll, pitch, qd):
    kin, dyn = robot.kin, robot.dyn
    cfg = _ik_or_reject(kin, z, roll, pitch)
    q, qd = np.array(cfg.q), np.array(qd)
    h = 1e-6
    s_plus = dyn.state(q + h * qd, qd, out=None).S.copy()
    s_minus = dyn.state(q - h * qd, qd).S.copy()
    sd = dyn.state(q, qd).Sd
    assert np.allclose(sd, (s_plus - s_minus) / (2 * h), atol=1e-7)


def test_home_pose_is_symmetric(robot):
    kin = robot.kin
    z_lo, z_hi = heave_range(kin)
    # Level heave range by hand: rods lean so the spheres sit R_b - R_p = 0.12 m inward;
    # z = q + sqrt(L² - 0.12²) over the stroke 0..0.40 m.
    rise = math.sqrt(0.45 ** 2 - 0.12 ** 2)
    assert z_lo == pytest.approx(rise, abs=1e-3)          # scan step 1 mm
    assert z_hi == pytest.approx(0.40 + rise, abs=1e-3)
    cfg = kin.ik(0.63, 0.0, 0.0)
    assert cfg.q[0] == pytest.approx(0.63 - rise, abs=1e-12)
    assert np.allclose(cfg.q, cfg.q[0]) and abs(cfg.x) < 1e-15 and abs(cfg.yaw) < 1e-15
    cond = conditioning(robot.dyn, cfg)
    assert 0.5 < cond["inverse"] <= 1.0 and 0.0 < cond["forward"] <= 1.0


def test_roll_moves_the_platform_sideways_as_the_constraints_demand(robot):
    # Pure roll γ: yaw stays 0 (sβ = 0) and x stays 0 by symmetry about the y-z plane, y shifts.
    cfg = robot.kin.ik(0.63, math.radians(10.0), 0.0)
    assert cfg.yaw == pytest.approx(0.0, abs=1e-15) and cfg.x == pytest.approx(0.0, abs=1e-15)
    assert abs(cfg.y) > 1e-4


@pytest.mark.parametrize("pose, message", [
    ((0.63, math.radians(40.0), 0.0), "roll 40.00 deg exceeds"),
    ((0.63, 0.0, math.radians(-30.0)), "pitch -30.00 deg exceeds"),
    ((0.95, 0.0, 0.0), "outside the stroke"),
    ((0.30, 0.0, 0.0), "outside the stroke"),
    ((1.5, 0.0, 0.0), "outside the stroke"),
    ((float("nan"), 0.0, 0.0), "z must be a finite number"),
])
def test_ik_refuses_poses_outside_the_workspace(robot, pose, message):
    with pytest.raises(WorkspaceError, match=message):
        robot.kin.ik(*pose)


def test_ik_refuses_unreachable_pose(robot):
    # With a rod barely longer than R_b - R_p = 0.12 m, tilting pulls a sphere out of reach.
    geometry = robot.description.geometry.model_copy(update={"rod_length_m": 0.125})
    short = Kinematics(robot.description.model_copy(update={"geometry": geometry}))
    with pytest.raises(WorkspaceError, match="unreachable: sphere 1"):
        short.ik(0.3, 0.5, 0.0, check=False)


def test_fk_errors_are_clear(robot):
    kin = robot.kin
    with pytest.raises(WorkspaceError, match="slider 2 at 0.4500 m is outside the stroke"):
        kin.fk((0.2, 0.45, 0.2))
    with pytest.raises(WorkspaceError, match="finite"):
        kin.fk((0.2, float("inf"), 0.2))
    # Sliders 0.4 m apart cannot hold a platform whose spheres are 0.31 m apart.
    with pytest.raises(KinematicsError) as info:
        kin.fk((0.0, 0.40, 0.0), guess=(kin.phi_nominal,) * 3)
    assert isinstance(info.value, (ConvergenceError, WorkspaceError))
    # The warm start is untouched by a failure: a good request still converges at once.
    cfg = kin.fk((0.2, 0.2, 0.2))
    assert cfg.roll == pytest.approx(0.0, abs=1e-12)


def test_fk_warm_start_converges_in_few_steps(robot):
    kin = robot.kin
    a = kin.ik(0.63, 0.10, -0.05)
    b = kin.ik(0.6301, 0.1001, -0.0501)      # one 1 kHz cycle away
    kin.fk(a.q)
    assert kin.fk(b.q).iterations <= 3


def test_fk_roll_pitch_is_fk_row_by_row_bit_for_bit(robot):
    """The figures' batch FK (compiled, issue 16) gives the floats of one ``fk(q,
    check=False)`` per row, in order, with the same warm starts: a row FK cannot solve (far
    outside the assembly range) gets NaN angles and leaves the warm start, as ``fk`` raising
    does; both objects end with the same warm start."""
    rng = np.random.default_rng(3)
    rows = [robot.kin.ik(rng.uniform(0.55, 0.75), rng.uniform(-0.2, 0.2),
                         rng.uniform(-0.2, 0.2)).q for _ in range(40)]
    qs = np.array(rows)
    qs[17] = (0.0, 5.0, -5.0)                               # no assembly
    one, batch = Kinematics(robot.kin.description), Kinematics(robot.kin.description)
    expected = []
    for q in qs:
        try:
            cfg = one.fk(q, check=False)
            expected.append((cfg.roll, cfg.pitch))
        except KinematicsError:
            expected.append(None)
    roll, pitch, ok = batch.fk_roll_pitch(qs)
    assert ok.tolist() == [e is not None for e in expected] and not ok[17]
    assert [(r, p) for r, p, k in zip(roll.tolist(), pitch.tolist(), ok) if k] == \
        [e for e in expected if e is not None]
    assert np.isnan(roll[17]) and np.isnan(pitch[17])
    assert one._phi_guess.tolist() == batch._phi_guess.tolist()
    with pytest.raises(WorkspaceError, match="finite"):
        batch.fk_roll_pitch([(0.6, np.inf, 0.6)])
