"""The realistic twin: truth apart from the model, and each unmodelled effect's signature."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.model import RobotModel
from rt.model.description import RobotDescription, load_description
from rt.model.dynamics import Payload
from rt.twin.plant import TwinPlant
from rt.twin.realism import RigImperfections, default_truth, perturbed_truth
from rt.twin.twin import Twin

NONE = RigImperfections.none()


def only(**effects) -> RigImperfections:
    """Every effect off except the named ones."""
    return NONE.model_copy(update=effects)


def test_truth_differs_from_the_model_by_default():
    nominal = load_description()
    twin = Twin()
    assert twin.description == default_truth()
    assert twin.description.bodies.platform.mass_kg != nominal.bodies.platform.mass_kg
    assert len(set(twin.description.friction.viscous_axes)) == 3      # per axis
    # Seeded: the same seed gives the same rig, another seed another one.
    assert perturbed_truth(nominal, 7) == perturbed_truth(nominal, 7)
    assert perturbed_truth(nominal, 7) != perturbed_truth(nominal, 8)
    assert Twin.ideal().description == nominal


def _static_deflection(imp: RigImperfections, payload: Payload | None) -> np.ndarray:
    # Drives off, brakes on: the rotors are locked, the sliders hang on the screws.
    # Frictionless, so the sliders settle on the springs alone.
    plant = TwinPlant(load_description(), imperfections=imp, frictionless=True)
    plant.set_state((0.2, 0.2, 0.2))
    plant.set_payload(payload)
    for _ in range(400):
        plant.advance(0.001, (0.0, 0.0, 0.0))
    return plant.xm - plant.q


def test_screw_compliance_gives_a_deflection_matching_its_stiffness():
    k = 6.0e7
    imp = only(screw_stiffness_n_per_m=k, brake_holding_force_n=2500.0)
    extra = _static_deflection(imp, Payload(100.0, (0.0, 0.0, 0.0))) - _static_deflection(imp,
                                                                                          None)
    model = RobotModel.load()
    st = model.dyn.state((0.2, 0.2, 0.2))
    g0 = model.dyn.gravity(st).copy()
    model.dyn.set_payload(Payload(100.0, (0.0, 0.0, 0.0)))
    dg = model.dyn.gravity(model.dyn.state((0.2, 0.2, 0.2))) - g0
    # The loaded slider sinks ΔG/k below the locked motor (327 N / 6e7 N/m ≈ 5.5 µm).
    np.testing.assert_allclose(extra, dg / k, rtol=0.05)


def test_backlash_adds_half_its_width_to_the_deflection():
    base = only(screw_stiffness_n_per_m=6.0e7, brake_holding_force_n=2500.0)
    lash = base.model_copy(update={"backlash_m": 2.0e-5})
    diff = _static_deflection(lash, None) - _static_deflection(base, None)
    np.testing.assert_allclose(diff, 1.0e-5, rtol=0.02)    # gravity takes up one side


def _with_amplifier(bandwidth_hz: float, delay_s: float):
    data = load_description().model_dump()
    data["drive"].update(current_loop_bandwidth_hz=bandwidth_hz, amplifier_delay_s=delay_s)
    return RobotDescription.model_validate(data)


def test_current_loop_lags_and_is_delayed():
    # The amplifier is the truth description's (its datasheet), switched on by the twin.
    imp = only(amplifier_dynamics=True)
    plant = TwinPlant(_with_amplifier(1000.0, 2.0e-4), physics_rate_hz=50_000.0,
                      imperfections=imp)
    plant.set_state((0.2, 0.2, 0.2))
    plant.advance(2.0e-4, (1.0, 1.0, 1.0))                  # within the transport delay
    assert np.all(plant.current == 0.0)
    tau = 1.0 / (2.0 * math.pi * 1000.0)
    plant.advance(tau, (1.0, 1.0, 1.0))                     # one time constant later
    np.testing.assert_allclose(plant.current, 1.0 - math.exp(-1.0), rtol=0.02)


def test_friction_falls_with_temperature_and_ripples_with_position():
    warm = TwinPlant(load_description(), imperfections=only(viscous_per_k=-0.015,
                                                            initial_temperature_rise_k=20.0))
    np.testing.assert_allclose(warm.friction[11:14], 0.7)
    # Sliding heats the screws.
    plant = TwinPlant(load_description(), imperfections=only(viscous_per_k=-0.015))
    plant.set_state((0.2, 0.2, 0.2), (0.1, 0.1, 0.1))
    plant._heat(10.0)
    assert np.all(plant.temperature_rise_k > 0.0)
    from rt.twin.physics import friction_force
    ripple = TwinPlant(load_description(), imperfections=only(friction_ripple=0.08))
    out = np.zeros(3)
    levels = []
    for q in np.linspace(0.2, 0.205, 11):
        friction_force(np.full(3, q), np.full(3, 0.05), ripple.friction, out)
        levels.append(out[0])
    # Coulomb (60 N) ± 8 % over one screw lead: ≈ ±4.8 N about the mean.
    assert max(levels) - min(levels) == pytest.approx(2 * 0.08 * 60.0, rel=0.05)


def test_encoders_count_the_motor_a_latency_late():
    twin = Twin(load_description(), imperfections=only(encoder_latency_s=5.0e-4))
    twin.place((0.2, 0.2, 0.2), (0.1, 0.1, 0.1))
    read = twin._encoder_positions()
    np.testing.assert_allclose(read, 0.2 - 0.1 * 5.0e-4)


def test_ati_reading_passes_its_low_pass_filter():
    twin = Twin(load_description(), imperfections=only(ati_filter_hz=150.0))
    twin.plant.wrench_s[:] = (0.0, 0.0, 100.0, 0.0, 0.0, 0.0)
    w = twin._filtered_wrench(0.001)
    tau = 1.0 / (2.0 * math.pi * 150.0)
    assert w[2] == pytest.approx(100.0 * (1.0 - math.exp(-0.001 / tau)))


def _sink_after_disable(imp: RigImperfections) -> float:
    from rt.twin.backends import TwinActuators
    from rt.twin.twin import SimClock

    clock = SimClock()
    twin = Twin(load_description(), imperfections=imp, clock=clock)
    twin.place((0.2, 0.2, 0.2))
    twin.plant.set_payload(Payload(100.0, (0.0, 0.0, 0.0)))
    card = TwinActuators(twin, 0)
    card.enable()
    model = RobotModel.load()
    model.dyn.set_payload(Payload(100.0, (0.0, 0.0, 0.0)))
    hold = model.dyn.gravity(model.dyn.state((0.2, 0.2, 0.2)))
    card.write_volts(hold / model.description.drive.force_per_volt_n)
    clock.t = 0.2
    twin.sync()
    before = twin.plant.q.copy()
    card.disable()                                          # hard stop: outputs off
    clock.t = 0.7
    twin.sync()
    return float(np.max(before - twin.plant.q))


def test_holding_brake_stops_the_loaded_platform_sinking():
    with_brake = _sink_after_disable(only(brake_holding_force_n=2500.0, brake_engage_s=0.02))
    without = _sink_after_disable(NONE)
    # 20 ms of free sinking under 100 kg before the brake bites: well under a millimetre;
    # without a brake the platform falls onto the end stops.
    assert with_brake < 1.0e-3
    assert without > 0.05


def test_ati_cable_pulls_the_platform_down():
    plant = TwinPlant(load_description(), imperfections=only(cable_weight_n=2.0))
    home = plant.q.copy()
    plant.set_state(home)
    plant.advance(0.001, (0.0, 0.0, 0.0))
    # Level platform: each slider carries a third of the cable's pull.
    np.testing.assert_allclose(plant.cable_tau, -2.0 / 3.0, rtol=0.01)


def test_a_failover_card_switch_does_not_close_the_brakes():
    plant = TwinPlant(load_description(), imperfections=only(brake_holding_force_n=2500.0))
    plant.set_drives_enabled(True)
    for _ in range(50):                                     # brakes open after 30 ms
        plant.advance(0.001, (0.0, 0.0, 0.0))
    assert not plant.brakes_engaged
    plant.set_drives_enabled(False)                         # card 0 off, card 1 on: same instant
    plant.set_drives_enabled(True)
    for _ in range(50):
        plant.advance(0.001, (0.0, 0.0, 0.0))
        assert not plant.brakes_engaged
    plant.set_drives_enabled(False)                         # a real stop: closed after 20 ms
    plant.advance(0.015, (0.0, 0.0, 0.0))
    plant.advance(0.001, (0.0, 0.0, 0.0))
    assert not plant.brakes_engaged
    plant.advance(0.010, (0.0, 0.0, 0.0))
    plant.advance(0.001, (0.0, 0.0, 0.0))
    assert plant.brakes_engaged


def _frozen_trip_time(sup, t0: float, seconds: float, qd_ref: float = 0.01) -> float | None:
    """Feed a still encoder and a reference moving at ``qd_ref`` (m/s) from t0; time of the
    frozen-encoder trip."""
    dt = sup.period_s
    z3 = (0.0, 0.0, 0.0)
    for k in range(int(seconds / dt)):
        t = t0 + (k + 1) * dt
        sup.check(t, dt, (0.2, 0.2, 0.2), 0, z3, z3, True, 0.0, 0.0, 0.0, 0.0,
                  (0.2, 0.2, 0.2), (qd_ref,) * 3, z3, 0.0, False, False, False, False,
                  False)
        if any(c.startswith("encoder_frozen") for c in sup.causes):
            return t
    return None


def test_supervisor_waits_for_the_brakes_before_judging_a_frozen_encoder():
    from rt.safety.limits import PatientLimits, RobotLimits, effective
    from rt.safety.supervisor import Supervisor

    lim = effective((0.0, 0.4), RobotLimits(), PatientLimits())
    sup = Supervisor(lim, 0.001)
    # At start the drives were just enabled: the brakes hold the axes for brake_release_s,
    # then the 50 ms frozen window runs.
    t = _frozen_trip_time(sup, 0.0, 0.3)
    assert t == pytest.approx(sup.brake_release_s + RobotLimits().frozen_encoder_s, abs=2e-3)
    # After a hard stop and its reset the same wait applies again.
    sup = Supervisor(lim, 0.001)
    sup.request_estop("cli")
    _frozen_trip_time(sup, 1.0, 0.01, qd_ref=0.0)    # stopped: the reference follows the robot
    sup.request_reset()
    t = _frozen_trip_time(sup, 2.0, 0.3)
    assert t == pytest.approx(2.0 + sup.brake_release_s + RobotLimits().frozen_encoder_s,
                              abs=3e-3)


def test_ati_reading_carries_its_tool_side_weight_turning_with_the_tilt():
    imp = only(ati_tool_mass_kg=0.4, ati_tool_com_m=0.03)
    twin = Twin(load_description(), imperfections=imp)
    mg = 0.4 * 9.81
    level = twin._filtered_wrench(0.001).copy()
    np.testing.assert_allclose(level[:3], (0.0, 0.0, -mg), atol=1e-9)
    cfg = twin.plant.kin.ik(0.633, 0.2, 0.0)                 # 0.2 rad roll
    twin.place(cfg.q)
    tilted = twin._filtered_wrench(0.001)
    # The weight seen in S: |F| unchanged, a component along y_S of m g sin(roll).
    assert np.linalg.norm(tilted[:3]) == pytest.approx(mg)
    assert abs(tilted[1]) == pytest.approx(mg * math.sin(0.2), rel=1e-3)
    assert tilted[3] == pytest.approx(-0.03 * tilted[1])    # M = c × F, c = (0, 0, h)


def _slider_side_mass(q=(0.2, 0.23, 0.17)) -> np.ndarray:
    """The slider side's mass matrix (no rotor: behind the compliant screw the rotors are
    separate bodies): strongly coupled through the rods and the platform."""
    data = default_truth().model_dump()
    data["drive"]["rotor_inertia_per_axis_kg_m2"] = [1e-12] * 3
    from rt.model.description import description_from_dict

    model = RobotModel.from_description(description_from_dict(data, "slider side"))
    return model.dyn.mass_matrix(model.dyn.state(q))


def test_slider_coulomb_friction_acts_on_its_own_axis_only():
    """The compliant screw's implicit Coulomb step applies each slider's friction through the
    coupled mass matrix: the generalised force it adds is exactly −level_i sign(q̇_i) on axis i
    and nothing on the others (the first step used M_ii alone and put 7-8 % of every other
    axis's Coulomb force on each axis, a friction no rig has: issue 15's fv bias)."""
    from rt.twin.physics import coulomb_step

    m = _slider_side_mass()
    off = m - np.diag(np.diag(m))
    assert np.abs(off).max() > 0.05 * np.diag(m).min()        # the coupling is real
    h = 2.0e-4
    levels = np.array([32.0, 31.0, 36.0])
    qdd = np.array([0.4, -0.7, 0.2])
    for qd0 in (np.array([0.10, -0.06, 0.03]), np.array([-0.12, 0.02, -0.09])):
        qd = qd0.copy()
        coulomb_step(m, qd, qdd, h, *levels)
        force = m @ (qd - (qd0 + h * qdd)) / h
        np.testing.assert_allclose(force, -levels * np.sign(qd), rtol=1e-9, atol=1e-9)


def test_slider_coulomb_step_sticks_exactly_within_the_friction_cone():
    from rt.twin.physics import _toward_zero, coulomb_step

    m = _slider_side_mass()
    h = 2.0e-4
    levels = np.array([32.0, 31.0, 36.0])
    # Axis 1 nearly at rest with a small push: it sticks (exactly 0) while 0 and 2 slide with
    # their full friction; the impulse holding axis 1 is inside its bound.
    qd0 = np.array([0.05, 1.0e-4, -0.04])
    qdd = np.zeros(3)
    qd = qd0.copy()
    coulomb_step(m, qd, qdd, h, *levels)
    assert qd[1] == 0.0
    impulse = m @ (qd0 - qd)                   # p = M Δv (N s)
    assert abs(impulse[1]) < h * levels[1]
    np.testing.assert_allclose(impulse[[0, 2]], h * levels[[0, 2]] * np.sign(qd[[0, 2]]),
                               rtol=1e-9)
    # A diagonal mass matrix gives the per-axis step exactly.
    d = np.diag(np.diag(m))
    for qd0 in (np.array([0.05, 1.0e-4, -0.04]), np.array([-0.2, 0.3, 2.0e-4])):
        qd = qd0.copy()
        coulomb_step(d, qd, qdd, h, *levels)
        want = [_toward_zero(qd0[i], h * levels[i] / d[i, i]) for i in range(3)]
        np.testing.assert_allclose(qd, want, rtol=1e-12, atol=1e-15)
