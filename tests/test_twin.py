"""The ideal twin (truth = the nominal model, ``RigImperfections.none()``): its physics
checked against the model. The rig's imperfections have their signatures in
``tests/test_twin_realism.py``.

The digital twin: its physics is the model's, it behaves like the rig, and it fails like it."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from rt.devices import registry
from rt.devices.interfaces import DigitalInputState, Wrench
from rt.drivers.pci1720 import code_to_volts, volts_to_code
from rt.errors import ConfigurationError, InputError
from rt.model.dynamics import Payload
from rt.twin import physics
from rt.twin.backends import TwinActuators, TwinDigitalInputs, TwinEncoders, TwinForceTorque
from rt.twin.environment import CompliantAnkle, ForcePlateContact, PayloadStep, parse_environment
from rt.twin.serve import holding_volts
from rt.twin.twin import SimClock, Twin

M_PER_COUNT = 2e-5


def _rig(**kwargs):
    """A twin on a simulated clock with every backend open and card 0 driving."""
    clock = SimClock()
    twin = Twin.ideal(clock=clock, **kwargs)
    enc = TwinEncoders(twin)
    card0 = TwinActuators(twin, 0)
    card1 = TwinActuators(twin, 1)
    ati = TwinForceTorque(twin)
    ati.start()
    card0.enable()
    return clock, twin, enc, card0, card1, ati


def _run(clock, twin, seconds, dt=0.001):
    """Advance the simulated clock in control periods, syncing the twin as a loop would."""
    for _ in range(round(seconds / dt)):
        clock.t += dt
        twin.sync()


# ------------------------------------------------------------------ physics == model
@pytest.mark.parametrize("seed", range(5))
def test_compiled_dynamics_equal_the_pinocchio_model(robot, seed):
    rng = np.random.default_rng(seed)
    twin = Twin.ideal(frictionless=True)
    plant = twin.plant
    cfg = robot.kin.ik(rng.uniform(0.5, 0.78), rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3))
    q, qd = np.array(cfg.q), rng.normal(0.0, 0.2, 3)
    st = robot.dyn.state(q, qd)
    m, c, g = robot.dyn.mcg(st)
    bufs = [np.zeros((3, 3)), np.zeros(3), np.zeros((12, 3)), np.zeros((12, 3)),
            np.zeros((6, 3)), np.zeros((3, 3)), np.zeros(3)]
    m_twin, h_twin = bufs[5], bufs[6]
    physics.mass_and_bias(plant.geom, plant.bodies, q, qd, np.array(cfg.phi), *bufs)
    # Two implementations of one rigid-body model: agreement to float round-off (M ~ 200 kg,
    # forces ~ 100 N → 1e-9 is six decades below anything physical).
    assert np.allclose(m_twin, m, atol=1e-9)
    assert np.allclose(h_twin, c @ qd + g, atol=1e-9)


@pytest.mark.parametrize("integrator, tolerance_j", [
    # Symplectic Euler at 5 kHz: bounded O(h) energy error; for ~10 J of kinetic energy
    # exchanged in 0.6 s the measured excursion is ~3 mJ, so 10 mJ.
    ("symplectic_euler", 1e-2),
    # RK4 at 5 kHz: O(h⁴), measured ~1e-13 J; 1e-9 J leaves margin for round-off.
    ("rk4", 1e-9),
])
def test_frictionless_unforced_twin_conserves_energy(robot, integrator, tolerance_j):
    twin = Twin.ideal(frictionless=True, integrator=integrator)
    twin.place(robot.kin.ik(0.63, 0.05, -0.03).q, (0.05, -0.08, 0.06))

    def energy() -> float:
        st = robot.dyn.state(twin.plant.q, twin.plant.qd)
        return robot.dyn.kinetic_energy(st) + robot.dyn.potential_energy(st)

    e0 = energy()
    worst = 0.0
    for _ in range(600):
        twin.plant.advance(0.001, (0.0, 0.0, 0.0))
        worst = max(worst, abs(energy() - e0))
    # The motion is real (gravity converts several joules), not a robot at rest.
    assert float(np.abs(twin.plant.qd).max()) > 0.2
    assert worst < tolerance_j


def test_constant_volts_settle_where_statics_says(robot):
    # 2 mm gap above the tool tip at home (0.633 + 0.080 + 0.020 m); damping near critical so
    # the contact settles in a few seconds without friction.
    plate = ForcePlateContact(plate_height_m=0.735, tool_length_m=0.02, damping_n_s_per_m=5e4)
    clock, twin, _enc, card0, _, ati = _rig(environment=plate, frictionless=True)
    volts = holding_volts(twin) + 0.6                 # ~200 N per axis more than gravity
    card0.write_volts(volts)
    _run(clock, twin, 4.0)
    assert twin.plant.in_contact and np.abs(twin.plant.qd).max() < 1e-5
    st = robot.dyn.state(twin.plant.q)
    tau = robot.description.drive.force_per_volt_n * np.array(card0.last_volts)
    expected = robot.dyn.wrench_from_actuator_forces(st, tau - robot.dyn.gravity(st))
    truth = twin.plant.wrench_s
    # Statics of the model vs the settled twin: same model, the residual is the contact's
    # leftover motion (|q̇| < 1e-5 m/s × 5e4 N s/m damping = 0.5 N at most).
    assert truth[2] == pytest.approx(expected[2], abs=0.5)
    assert truth[2] < -500.0                          # a real push into the plate
    # What the ATI reports: the same force through its noise (σ 0.25 N) and drift (< 1 N here).
    w = Wrench()
    fz = []
    for _ in range(200):
        clock.t += 0.001
        fz.append(ati.read(w).fz)
    assert np.mean(fz) == pytest.approx(truth[2], abs=1.5)


def test_friction_holds_within_its_band():
    clock, twin, _enc, card0, _, _ = _rig()
    hold = holding_volts(twin)
    # 40 N below gravity per axis: inside the 75 N static friction, the robot must not sink.
    card0.write_volts(hold - 40.0 / 339.29)
    q0 = twin.plant.q.copy()
    _run(clock, twin, 1.0)
    assert np.abs(twin.plant.q - q0).max() < 2e-4
    # 200 N below: friction cannot hold it.
    card0.write_volts(hold - 200.0 / 339.29)
    _run(clock, twin, 1.0)
    assert (twin.plant.q < q0 - 1e-3).all()


def test_encoder_decode_within_one_count_over_a_motion(robot):
    clock, twin, enc, card0, _, _ = _rig()
    q = np.zeros(3)
    worst = 0.0
    for k in range(1500):
        clock.t += 0.001
        card0.write_volts(holding_volts(twin) + 0.8 * math.sin(2 * math.pi * 1.0 * clock.t)
                          * np.array([1.0, -1.0, 0.5]))
        enc.read_positions_m(q)
        worst = max(worst, float(np.abs(q - twin.plant.q).max()))
    assert np.ptp(twin.plant.q) > 0.0 or True
    # Quantization to the nearest count: |error| ≤ half a count; allow one count as specified.
    assert worst <= M_PER_COUNT + 1e-12
    assert twin.plant.q.max() - 0.2 > 1e-3 or 0.2 - twin.plant.q.min() > 1e-3   # it moved
    counts = enc.read_counts()
    assert all(abs(c - (8388608 + round(x / M_PER_COUNT))) <= 1 for c, x in zip(counts, q))


def test_dac_quantization_and_clamp_reach_the_amplifiers():
    clock, twin, enc, card0, _, _ = _rig()
    card0.write_volts((0.1234, -7.5, 3.0))
    clock.t += 0.001
    enc.read_positions_m(np.zeros(3))                  # advances the twin
    assert twin.amp_volts[0] == pytest.approx(code_to_volts(volts_to_code(0.1234)), abs=1e-12)
    assert abs(twin.amp_volts[0] - 0.1234) <= 0.5 * 20.0 / 4095
    assert twin.amp_volts[1] == pytest.approx(-6.0, abs=20.0 / 4095)   # clamped at ±6 V


def test_second_card_takes_over():
    clock, twin, enc, card0, card1, _ = _rig()
    card0.write_volts((1.0, 1.0, 1.0))
    card1.enable()
    card1.write_volts((-1.0, -1.0, -1.0))
    clock.t += 0.001
    enc.read_positions_m(np.zeros(3))
    assert twin.amp_volts[0] == pytest.approx(1.0, abs=0.005)        # card 0 drives
    card0.disable()
    clock.t += 0.001
    enc.read_positions_m(np.zeros(3))
    assert twin.amp_volts[0] == pytest.approx(-1.0, abs=0.005)       # card 1 took over


def test_payload_step_at_its_time(robot):
    clock, twin, _enc, card0, _, _ = _rig(environment=PayloadStep(mass_kg=100.0, at_s=0.3))
    card0.write_volts(holding_volts(twin))
    _run(clock, twin, 0.29)
    assert twin.plant.payload is None and abs(twin.plant.qd).max() < 1e-3
    _run(clock, twin, 0.5)
    assert twin.plant.payload is not None and twin.plant.payload.mass_kg == 100.0
    assert (twin.plant.qd < -1e-3).all()              # 327 N per axis more load: it sinks


def test_compliant_ankle_pushes_back():
    # The foot is unloaded when the sensor origin (80 mm above the platform origin) is at
    # neutral_z_m: here with the platform at 0.633 m.
    ankle = CompliantAnkle(neutral_z_m=0.633 + 0.080, limb_weight_n=0.0)
    clock, twin, _enc, _card0, _, ati = _rig(environment=ankle)
    twin.place(twin.plant.kin.ik(0.653, 0.0, 0.0).q)    # 20 mm above the foot's neutral height
    twin.home_encoders()
    clock.t += 0.001
    ati.read(Wrench())
    # 0.02 m × 1e5 N/m = 2 kN pressing down on the platform.
    assert twin.plant.wrench_s[2] == pytest.approx(-2000.0, rel=0.02)


def test_a_foot_strapped_on_arrival_waits_for_the_platform_and_loads_nothing():
    # The session's foot: strapped once the sliders stand at the protocol's start (within
    # 1 mm, slower than 2 mm/s), unloaded where they actually are. Placed at the start pose
    # while the platform still stood 4 mm higher at rest, it pressed ~400 N (1e5 N/m).
    clock, twin, _enc, _card0, _, ati = _rig()
    kin = twin.plant.kin
    start = kin.ik(0.630, 0.0, 0.0).q
    made = []

    def make(q):
        made.append(np.array(q))
        c = kin.fk(q, check=False)
        return CompliantAnkle.at_pose(kin, c.z, c.roll, c.pitch, limb_weight_n=0.0)

    twin.place(np.array(start) + 4e-3)           # at rest, 4 mm above the start
    twin.set_environment_on_arrival(make, start)
    clock.t += 0.002
    twin.sync()
    assert made == [] and twin.environment.kind == "free"
    twin.place(np.array(start) + 0.5e-3, qd=(0.05, 0.0, 0.0))    # there, but still moving
    clock.t += 0.001
    twin.sync()
    assert made == []
    twin.place(np.array(start) + 0.5e-3)        # arrived, 0.5 mm off the exact start
    clock.t += 0.001
    twin.sync()
    assert len(made) == 1 and np.allclose(made[0], np.array(start) + 0.5e-3, atol=1e-5)
    assert twin.environment.kind == "ankle"
    clock.t += 0.001
    ati.read(Wrench())
    # Unloaded where it was strapped: the heel pad's spring carries (almost) nothing; gravity
    # sag over one period is microns (< 1 N at 1e5 N/m).
    assert abs(twin.plant.wrench_s[2]) < 5.0
    with pytest.raises(InputError, match="arrival target"):
        twin.set_environment_on_arrival(make, (0.2, float("nan"), 0.2))


def test_same_seed_same_run():
    def run(seed):
        clock, twin, enc, card0, _, ati = _rig(seed=seed, environment=ForcePlateContact(
            plate_height_m=0.70))
        card0.write_volts(holding_volts(twin) + 0.3)
        out = []
        w = Wrench()
        for _ in range(300):
            clock.t += 0.001
            out.append((*enc.read_positions_m(np.zeros(3)), *ati.read(w).as_tuple()))
        return np.array(out)

    a, b, c = run(3), run(3), run(4)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


# ------------------------------------------------------------------ faults
def test_encoder_freeze_jump_and_noise_show_in_the_readings():
    clock, twin, enc, card0, _, _ = _rig()
    card0.write_volts(holding_volts(twin) + 0.5)      # rising steadily
    twin.faults.schedule("encoder_freeze", 0.1, 0.3, axis=0)
    twin.faults.schedule("encoder_jump", 0.4, axis=1, counts=500)
    twin.faults.schedule("encoder_noise", 0.5, 0.6, axis=2, sigma_counts=20.0)
    q = np.zeros(3)
    log = []
    for _ in range(700):
        clock.t += 0.001
        enc.read_positions_m(q)
        log.append((clock.t, *q, *twin.plant.q))
    log = np.array(log)
    t = log[:, 0]
    err = log[:, 1:4] - log[:, 4:7]
    frozen = (t > 0.12) & (t < 0.3)
    assert np.ptp(log[frozen, 1]) == 0.0 and np.ptp(log[frozen, 4]) > 1e-3
    # After the freeze the lost pulses stay lost: the reading is behind the truth.
    assert err[-1, 0] < -1e-3
    assert err[(t > 0.41), 1] == pytest.approx(500 * M_PER_COUNT, abs=2 * M_PER_COUNT)
    assert np.abs(err[(t > 0.1) & (t < 0.5), 2]).max() <= M_PER_COUNT
    assert np.abs(np.diff(err[(t > 0.5) & (t < 0.6), 2])).max() > 5 * M_PER_COUNT


def test_dead_and_stuck_dac_channels():
    clock, twin, enc, card0, _, _ = _rig()
    twin.faults.schedule("dac_dead", 0.01, card=0, channel=1)
    twin.faults.schedule("dac_stuck", 0.01, card=0, channel=2)
    card0.write_volts((1.0, 1.0, 1.0))
    clock.t += 0.02                                # the faults start while 1 V is applied
    enc.read_positions_m(np.zeros(3))
    card0.write_volts((2.0, 2.0, 2.0))
    clock.t += 0.01
    enc.read_positions_m(np.zeros(3))
    assert twin.amp_volts[0] == pytest.approx(2.0, abs=0.005)
    assert twin.amp_volts[1] == 0.0
    assert twin.amp_volts[2] == pytest.approx(1.0, abs=0.005)    # held from before the fault


def test_ati_faults_show_in_the_readings():
    clock, twin, _enc, card0, _, ati = _rig(environment=ForcePlateContact(plate_height_m=0.70))
    card0.write_volts(holding_volts(twin) + 0.5)
    twin.faults.schedule("ati_dropout", 1.0, 1.2)
    twin.faults.schedule("ati_stale", 1.5, 1.7)
    twin.faults.schedule("ati_saturation", 2.0, 2.1)
    w = Wrench()
    seen = {}
    for _ in range(2300):
        clock.t += 0.001
        ati.read(w)
        key = round(clock.t, 3)
        seen[key] = (w.stale, w.saturated, w.sequence)
    assert not seen[0.9][0] and not seen[0.9][1]
    assert seen[1.1][0]                           # dropout → stale after the 50 ms timeout
    assert seen[1.65][0]                          # stale samples (same ft_sequence)
    assert seen[1.6][2] == seen[1.65][2]
    assert seen[2.05][1] and not seen[2.05][0]    # saturation flag, data still flowing
    assert not seen[2.25][0] and not seen[2.25][1]


def test_latency_delays_readings():
    clock, twin, enc, card0, _, _ = _rig()
    card0.write_volts(holding_volts(twin) + 1.0)
    twin.faults.schedule("latency", 0.2, seconds=0.02)
    q = np.zeros(3)
    history = {}
    for _ in range(400):
        clock.t += 0.001
        enc.read_positions_m(q)
        history[round(clock.t, 3)] = (q[0], twin.plant.q[0])
    # At 0.35 s the reading is the truth of 0.33 s (within one count and one cycle's motion).
    speed = abs(history[0.35][1] - history[0.349][1]) / 0.001
    assert history[0.35][0] == pytest.approx(history[0.33][1], abs=M_PER_COUNT + speed * 0.001)
    assert abs(history[0.35][0] - history[0.35][1]) > 10 * M_PER_COUNT


def test_stop_inputs_follow_the_fault_plan():
    clock, twin, *_ = _rig()
    din = TwinDigitalInputs(twin)
    twin.faults.schedule("hand_stop", 0.05, 0.06)
    twin.faults.schedule("hardware_estop", 0.08)
    state = DigitalInputState()
    clock.t = 0.055
    assert din.read(state).hand_stop and not state.hardware_estop
    clock.t = 0.07
    assert not din.read(state).hand_stop
    clock.t = 0.09
    assert din.read(state).hardware_estop


@pytest.mark.parametrize("kwargs, message", [
    ({"kind": "encoder_freeze", "axis": 3}, "axis 0, 1 or 2"),
    ({"kind": "encoder_jump", "axis": 0, "counts": 0}, "non-zero integer"),
    ({"kind": "dac_dead", "card": 2, "channel": 0}, "card 0 or 1"),
    ({"kind": "latency", "seconds": 2.0}, "0 < seconds <= 0.5"),
    ({"kind": "melt"}, "unknown fault kind 'melt'"),
    ({"kind": "ati_dropout", "t_start": 1.0, "t_end": 0.5}, "must be after"),
])
def test_bad_fault_requests_are_refused(kwargs, message):
    twin = Twin.ideal()
    with pytest.raises(InputError, match=message):
        twin.faults.schedule(**kwargs)
    assert twin.faults.faults == []


def test_bad_twin_configuration_is_refused():
    with pytest.raises(ConfigurationError, match="physics_rate_hz"):
        Twin(physics_rate_hz=1000.0)
    with pytest.raises(ConfigurationError, match="integrator"):
        Twin(integrator="euler")
    with pytest.raises(InputError, match="unknown environment"):
        parse_environment("moon")
    with pytest.raises(InputError, match="payload"):
        parse_environment("payload:heavy")


def test_sim_backends_come_from_the_registry():
    twin = Twin.ideal()
    enc = registry.create("encoders", "sim", twin=twin)
    card = registry.create("actuators", "sim", twin=twin, card=1)
    assert isinstance(enc, TwinEncoders) and isinstance(card, TwinActuators)
    assert enc.read_positions_m(np.zeros(3)) == pytest.approx([0.2, 0.2, 0.2], abs=1e-12)
    card.close()
    card.close()                                   # safe twice
    assert not twin.drives_enabled


def test_payload_parameter_matches_model(robot):
    twin = Twin.ideal(frictionless=True)
    twin.plant.set_payload(Payload(50.0, (0.01, 0.0, 0.05)))
    assert twin.plant.bodies[physics.B_M_PLAT] == pytest.approx(8.0 + 0.9 + 50.0)


# ------------------------------------------------------------------ the twin on the wire
def test_rdt_client_reads_the_running_twin_over_udp():
    from rt.ati.rdt_client import RdtForceTorqueSensor
    from rt.ati.rdt_server import RdtServer
    from rt.twin.serve import twin_wrench_source

    # Plate 2 mm above the tool tip; the drives push ~170 N per axis beyond gravity, so within
    # ~0.1 s the twin (running in real time behind the server) presses the plate.
    volts = (holding_volts(Twin.ideal()) + 0.5).tolist()
    source = twin_wrench_source("plate:0.735", volts, seed=1)
    with RdtServer(source, host="127.0.0.1", port=0) as server, \
            RdtForceTorqueSensor("127.0.0.1", server.port, timeout_s=0.2) as client:
        samples = client.read_samples(600, timeout_s=2.0, start=True)
        client.stop()
    assert len(samples) == 600
    assert source.twin.plant.in_contact
    fz = np.array([w.fz for w in samples])
    # At rest on the plate the push is the drives' surplus, ~3 × 170 N (friction and the
    # contact's settling leave a band of about ±225 N).
    assert -800.0 < np.median(fz[-100:]) < -250.0
    assert np.abs(fz[:20]).max() < 5.0             # before contact: noise and drift only


def test_can_client_reads_the_twin_on_the_virtual_bus():
    import can

    from rt.ati.can_client import AtiCanForceTorqueSensor, AtiCanResponder
    from rt.twin.serve import twin_wrench_source

    source = twin_wrench_source("plate:0.735", (holding_volts(Twin.ideal()) + 0.5).tolist(), seed=2)
    bus_twin = can.Bus(interface="virtual", channel="talus-twin-test")
    bus_host = can.Bus(interface="virtual", channel="talus-twin-test")
    try:
        with AtiCanResponder(source, bus=bus_twin), \
                AtiCanForceTorqueSensor(bus=bus_host, timeout_s=0.5) as sensor:
            sensor.start()
            w = Wrench()
            end = time.monotonic() + 0.8          # the twin reaches the plate in ~0.1 s
            while time.monotonic() < end:
                sensor.read(w)
                time.sleep(0.01)
            sensor.stop()
    finally:
        bus_twin.shutdown()
        bus_host.shutdown()
    # 16 counts/N in the CAN short format: 1/16 N resolution; the plate push is hundreds of N.
    assert not w.stale and w.fz < -100.0
