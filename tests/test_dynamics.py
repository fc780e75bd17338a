"""Actuator-space dynamics: the properties of DESIGN section 4, checked over the workspace."""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from rt.errors import InputError, WorkspaceError
from rt.model.dynamics import Payload
from rt.model.regressor import Regressor

Z = st.floats(0.46, 0.80)
ANGLE = st.floats(-math.radians(20.0), math.radians(20.0))
VEL = st.tuples(*[st.floats(-0.4, 0.4)] * 3)
ACC = st.tuples(*[st.floats(-5.0, 5.0)] * 3)


def _state(robot, z, roll, pitch, qd=(0.0, 0.0, 0.0)):
    try:
        cfg = robot.kin.ik(z, roll, pitch)
    except WorkspaceError:
        assume(False)
    return robot.dyn.state(cfg.q, qd, cfg=cfg)


@given(Z, ANGLE, ANGLE, VEL)
def test_mass_matrix_symmetric_positive_definite(robot, z, roll, pitch, qd):
    m, _, _ = robot.dyn.mcg(_state(robot, z, roll, pitch, qd))
    assert np.allclose(m, m.T, atol=1e-12)
    eig = np.linalg.eigvalsh(m)
    # Each slider carries at least its reflected rotor inertia (205 kg) plus its own 2 kg.
    assert eig[0] > robot.description.drive.reflected_inertia_kg


@given(Z, ANGLE, ANGLE, VEL)
def test_mdot_minus_2c_is_skew_symmetric(robot, z, roll, pitch, qd):
    dyn = robot.dyn
    st_ = _state(robot, z, roll, pitch, qd)
    q, v = np.array(st_.cfg.q), np.array(qd)
    _, c, _ = dyn.mcg(st_)
    h = 1e-6
    m_plus = dyn.mass_matrix(dyn.state(q + h * v, v))
    m_minus = dyn.mass_matrix(dyn.state(q - h * v, v))
    n = (m_plus - m_minus) / (2 * h) - 2.0 * c
    # Ṁ by central differences: error ~h²·|M'''|·|q̇|³ + 1e-16·|M|/h ≈ 2e-8 kg/s; entries of Ṁ
    # and C reach a few kg/s, so 1e-6 is a tight bound that a wrong C (off by any term) fails.
    assert np.allclose(n, -n.T, atol=1e-6)


@given(Z, ANGLE, ANGLE, VEL, ACC)
def test_matrices_reproduce_rnea(robot, z, roll, pitch, qd, qdd):
    dyn = robot.dyn
    st_ = _state(robot, z, roll, pitch, qd)
    m, c, g = dyn.mcg(st_)
    tau = m @ np.array(qdd) + c @ st_.qd + g + dyn.friction(st_.qd)
    # Two independent routes (CRBA/Coriolis matrices vs recursive Newton-Euler): agree to
    # round-off of forces of ~1e3 N.
    assert np.allclose(tau, dyn.inverse_dynamics(st_, qdd), atol=1e-9)


@given(Z, ANGLE, ANGLE, VEL)
def test_kinetic_energy_matches_pinocchio_tree(robot, z, roll, pitch, qd):
    dyn = robot.dyn
    st_ = _state(robot, z, roll, pitch, qd)
    tree = pin.computeKineticEnergy(dyn.model, dyn.data, st_.Q, st_.Qd)
    rotor = 0.5 * dyn.reflected_inertia * float(st_.qd @ st_.qd)
    assert dyn.kinetic_energy(st_) == pytest.approx(tree + rotor, rel=1e-12)


@given(Z, ANGLE, ANGLE, st.integers(0, 2))
def test_gravity_is_the_gradient_of_potential_energy(robot, z, roll, pitch, k):
    dyn = robot.dyn
    st_ = _state(robot, z, roll, pitch)
    g = dyn.gravity(st_).copy()
    q = np.array(st_.cfg.q)
    h = 1e-6
    e = np.zeros(3)
    e[k] = h
    fd = (dyn.potential_energy(dyn.state(q + e)) - dyn.potential_energy(dyn.state(q - e))) / (2 * h)
    # V ~ 100 J: round-off 1e-14·100/1e-6 = 1e-6 N; truncation h²·V''' negligible.
    assert g[k] == pytest.approx(fd, abs=1e-5)


def test_centred_payload_by_hand_statics(fresh_robot):
    dyn, kin = fresh_robot.dyn, fresh_robot.kin
    home = kin.ik(0.63, 0.0, 0.0)
    g0 = dyn.gravity(dyn.state(home.q)).copy()
    dyn.set_payload(Payload(100.0))
    g1 = dyn.gravity(dyn.state(home.q))
    # A vertical load at the centre of a level platform: each rod transmits m g / 3 vertically,
    # the guides take the horizontal part, so each actuator carries m g / 3.
    assert np.allclose(g1 - g0, 100.0 * 9.81 / 3.0, atol=1e-9)


@given(st.floats(-0.12, 0.12), st.floats(-0.12, 0.12), st.floats(1.0, 150.0))
def test_offset_payload_by_hand_statics(scratch_robot, dx, dy, mass):
    dyn, kin = scratch_robot.dyn, scratch_robot.kin
    home = kin.ik(0.63, 0.0, 0.0)
    dyn.set_payload(None)
    g0 = dyn.gravity(dyn.state(home.q)).copy()
    dyn.set_payload(Payload(mass, (dx, dy, 0.0)))
    g1 = dyn.gravity(dyn.state(home.q))
    # Load in the plane of the spheres on a level platform: horizontal joint forces act at the
    # load's height and give no moment about horizontal axes, so the vertical forces f_i at the
    # spheres satisfy Σ f_i = m g and Σ f_i (x_i, y_i) = m g (dx, dy); rods pass them to sliders.
    a = np.array([[1.0, 1.0, 1.0], [s[0] for s in home.spheres], [s[1] for s in home.spheres]])
    f = np.linalg.solve(a, mass * 9.81 * np.array([1.0, dx, dy]))
    assert np.allclose(g1 - g0, f, atol=1e-8)


@given(Z, ANGLE, ANGLE, st.floats(1.0, 100.0))
def test_wrench_map_equals_payload_statics(scratch_robot, z, roll, pitch, mass):
    dyn = scratch_robot.dyn
    st_ = _state(scratch_robot, z, roll, pitch)
    q = st_.cfg.q
    offset = tuple(scratch_robot.description.sensor.offset_m)
    dyn.set_payload(None)
    g0 = dyn.gravity(dyn.state(q)).copy()
    dyn.set_payload(Payload(mass, offset))
    st1 = dyn.state(q)
    g1 = dyn.gravity(st1).copy()
    # The payload's weight as a wrench at the sensor origin, in the sensor frame S ∥ P.
    force_s = st1.rot.T @ np.array([0.0, 0.0, -mass * 9.81])
    w = np.concatenate([force_s, np.zeros(3)])
    assert np.allclose(dyn.actuator_forces_for_wrench(st1, w), g1 - g0, atol=1e-8)


@given(Z, ANGLE, ANGLE, st.tuples(*[st.floats(-500.0, 500.0)] * 3),
       st.tuples(*[st.floats(-30.0, 30.0)] * 3))
def test_wrench_round_trip(robot, z, roll, pitch, force, torque):
    dyn = robot.dyn
    st_ = _state(robot, z, roll, pitch)
    w = np.array([*force, *torque])
    tau = dyn.actuator_forces_for_wrench(st_, w)
    back = dyn.wrench_from_actuator_forces(st_, tau, fx=w[0], fy=w[1], tz=w[5])
    assert np.allclose(back, w, atol=1e-8)


@given(Z, ANGLE, ANGLE, VEL, ACC)
def test_regressor_reproduces_model_forces(robot, z, roll, pitch, qd, qdd):
    reg = _regressor(robot)
    st_ = _state(robot, z, roll, pitch, qd)
    tau = robot.dyn.inverse_dynamics(st_, qdd)
    assert np.allclose(reg(st_, qdd) @ reg.theta_base(), tau, atol=1e-8)
    assert np.allclose(reg.standard(st_, qdd) @ reg.theta_standard(), tau, atol=1e-8)


def test_regressor_follows_a_payload(fresh_robot):
    reg = Regressor(fresh_robot.dyn)
    theta0 = reg.theta_base().copy()
    fresh_robot.dyn.set_payload(Payload(100.0, (0.02, -0.01, 0.10)))
    theta1 = reg.theta_base()
    st_ = fresh_robot.dyn.state(fresh_robot.kin.ik(0.6, 0.1, -0.1).q, (0.1, -0.2, 0.05))
    qdd = np.array([1.0, -2.0, 0.5])
    assert np.allclose(reg(st_, qdd) @ theta1, fresh_robot.dyn.inverse_dynamics(st_, qdd),
                       atol=1e-8)
    assert not np.allclose(theta0, theta1)
    # Base set: 79 standard parameters fold into fewer; the 9 drive parameters stay base.
    assert len(reg.base.names) < 79
    assert {f"{p}{i}" for p in ("Jr", "fv", "fc") for i in range(3)} <= set(reg.base.names)


_REGRESSORS: dict[int, Regressor] = {}


def _regressor(robot) -> Regressor:
    if id(robot) not in _REGRESSORS:
        _REGRESSORS[id(robot)] = Regressor(robot.dyn)
    return _REGRESSORS[id(robot)]


def test_bad_payloads_are_refused():
    with pytest.raises(InputError, match="mass_kg"):
        Payload(-1.0)
    with pytest.raises(InputError, match="com_m"):
        Payload(1.0, (0.0, 0.0))
    with pytest.raises(InputError, match="symmetric"):
        Payload(1.0, (0, 0, 0), ((1, 2, 0), (0, 1, 0), (0, 0, 1)))


def test_friction_is_viscous_plus_smooth_coulomb(robot):
    f = robot.dyn.friction([0.1, -0.1, 0.0])
    # 800 N s/m · 0.1 m/s + 60 N · tanh(100) = 140 N; zero at rest.
    assert f == pytest.approx([140.0, -140.0, 0.0], abs=1e-9)
