"""The compiled twin (issue 16) equals the interpreted reference: a recorded input stream —
DAC codes every 1 ms period from a closed-loop run, drive switching, environment changes and
payload steps — replayed through ``Twin(compiled=True)`` and ``Twin(compiled=False)`` gives the
same state, sensor readings and ATI samples within 1e-12 (relative to the quantity's size, at
least 1: metres, newtons and kelvins alike), period by period."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.ati.twin_sensor import AtiSensorParams, TwinAtiSensorModel
from rt.drivers.pci1720 import volts_to_code
from rt.model.kernels import TREE_MAPS_WORK, tree_maps, tree_maps_drift_sc
from rt.twin import kernels, physics
from rt.twin.environment import CompliantAnkle, FreeMotion, PayloadStep, parse_environment
from rt.twin.realism import RigImperfections
from rt.twin.serve import holding_volts
from rt.twin.twin import Twin

TOL = 1e-12
DT = 0.001

#: Plant quantities compared every period (encoder_q and the filtered/measured wrench are
#: sensor-stage quantities: compared through what the encoders count and the ATI reports).
_PLANT = ("q", "qd", "qdd", "phi", "xm", "vm", "current", "cable_tau", "wrench_s", "rot",
          "env_state", "temperature_rise_k", "friction", "friction_slider", "friction_motor",
          "real", "bodies")


def _record(env: str, ideal: bool, seconds: float, integrator: str = "symplectic_euler",
            seed: int = 3) -> list[tuple[float, tuple[int, int, int], bool]]:
    """A closed-loop run on the interpreted twin (PD on the true slider positions towards
    sines, a drive switch-off and back): its DAC codes per period are the recorded stream."""
    kwargs = {"environment": parse_environment(env), "seed": seed, "integrator": integrator,
              "compiled": False}
    twin = Twin.ideal(**kwargs) if ideal else Twin(**kwargs)
    twin.set_card_enabled(0, True)
    hold = holding_volts(twin)
    q0 = twin.plant.q.copy()
    stream = []
    for k in range(round(seconds / DT)):
        t = (k + 1) * DT
        enabled = not 0.30 <= t < 0.36       # off long enough for the brakes to engage
        codes = []
        for i in range(3):
            ref = q0[i] + 0.004 * math.sin(2.0 * math.pi * 2.0 * t + 2.0944 * i)
            v = hold[i] + 300.0 * (ref - twin.plant.q[i]) - 3.0 * twin.plant.qd[i]
            codes.append(volts_to_code(max(-6.0, min(6.0, v)) if enabled else 0.0))
        stream.append((t, (codes[0], codes[1], codes[2]), enabled))
        _apply(twin, codes, enabled)
        twin.sync(t)
    return stream


def _apply(twin: Twin, codes, enabled: bool) -> None:
    if twin.card_enabled[0] != enabled:
        twin.set_card_enabled(0, enabled)
    for ch in range(3):
        twin.dac_libs[0].last_code[ch] = codes[ch]


def _close(a, b, what: str, k: int) -> None:
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    scale = np.maximum(1.0, np.abs(a))
    err = np.abs(a - b) / scale
    assert np.all(err <= TOL), f"period {k}: {what} differs by {err.max():.3g} (relative)"


def _replay(stream, make, switch=None) -> None:
    """Feed the stream to an interpreted and a compiled twin and compare every period."""
    ref, fast = make(False), make(True)
    assert fast.plant.compiled and not ref.plant.compiled
    contacts = 0
    for k, (t, codes, enabled) in enumerate(stream):
        for twin in (ref, fast):
            if switch is not None:
                switch(twin, t)
            _apply(twin, codes, enabled)
            twin.sync(t)
        for name in _PLANT:
            _close(getattr(ref.plant, name), getattr(fast.plant, name), name, k)
        assert ref.plant.t == fast.plant.t
        assert ref.plant.brakes_engaged == fast.plant.brakes_engaged
        counts = [ref.encoder_port.count(i) for i in range(3)]
        assert counts == [fast.encoder_port.count(i) for i in range(3)], f"period {k}"
        a, b = ref.ati_sample, fast.ati_sample
        assert a is not None and b is not None
        _close(a.wrench, b.wrench, "ATI wrench", k)
        assert (a.status, a.ft_sequence) == (b.status, b.ft_sequence)
        contacts += ref.plant.in_contact
    return ref, fast, contacts


@pytest.mark.parametrize("env", ["free", "plate:0.7128", "ankle"])
def test_realistic_twin_replay_equals_the_interpreted_reference(env):
    stream = _record(env, ideal=False, seconds=0.6)
    ref, _, contacts = _replay(stream, lambda c: Twin(environment=parse_environment(env),
                                                      seed=3, compiled=c))
    # The stream exercised what it claims: brakes engaged while off, the heat model updated.
    assert ref.plant.temperature_rise_k.max() > 0.0
    assert np.ptp(ref.plant.q) > 1e-4
    if env.startswith("plate"):
        assert 0 < contacts < len(stream)          # the contact opened and closed


def test_brakes_engage_in_the_replay_on_both_paths():
    stream = _record("free", ideal=False, seconds=0.4)
    seen = []

    def watch(twin, t):
        if not twin.compiled and abs(t - 0.35) < 1e-9:
            seen.append(twin.plant.brakes_engaged)
    _replay(stream, lambda c: Twin(seed=3, compiled=c), switch=watch)
    assert seen == [True]


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4"])
def test_ideal_twin_replay_equals_the_interpreted_reference(integrator):
    stream = _record("ankle", ideal=True, seconds=0.3, integrator=integrator)
    _replay(stream, lambda c: Twin.ideal(environment=CompliantAnkle(), seed=3,
                                         integrator=integrator, compiled=c))


def test_environment_changes_and_payload_step_replay_equal():
    stream = _record("free", ideal=False, seconds=0.4)

    def switch(twin, t):
        if abs(t - 0.101) < 1e-9:
            twin.set_environment(PayloadStep(mass_kg=20.0, at_s=0.15))
        elif abs(t - 0.251) < 1e-9:
            twin.set_environment(CompliantAnkle(neutral_z_m=0.72))
        elif abs(t - 0.351) < 1e-9:
            twin.set_environment(FreeMotion())
    _replay(stream, lambda c: Twin(seed=3, compiled=c), switch=switch)


def test_plant_advance_accepts_a_list_and_equals_the_reference():
    ref, fast = Twin(compiled=False).plant, Twin(compiled=True).plant
    for plant in (ref, fast):
        plant.set_drives_enabled(True)
    for k in range(50):
        volts = [0.5 * math.sin(0.1 * k), -0.2, 0.1 * k / 50]
        ref.advance(DT, volts)
        fast.advance(DT, volts)
        for name in _PLANT:
            _close(getattr(ref, name), getattr(fast, name), name, k)


def test_packed_state_is_shared_with_the_named_arrays():
    plant = Twin().plant
    plant.set_state([0.30, 0.31, 0.32])
    assert plant.S[kernels.S_Q:kernels.S_Q + 3].tolist() == [0.30, 0.31, 0.32]
    plant.set_drives_enabled(True)
    assert plant.S[kernels.S_DRIVES_ON] == 1.0
    plant.friction[0] = 123.0
    assert plant.P[kernels.P_FRICTION] == 123.0


def test_the_block_period_is_the_17_argument_period_to_the_bit():
    """``kernels.period_block`` (one block, the scalars read from it, the time advanced in
    it) against ``kernels.period`` with every argument passed, on two twins fed the same
    codes under a strapped foot: the whole block, the encoder card and the ATI sample
    equal as bits, and ``plant.t`` the same float."""
    twins = [Twin(environment=parse_environment("ankle"), seed=3) for _ in range(2)]
    for tw in twins:
        tw.set_card_enabled(0, True)
        tw.plant.set_encoder_card(tw.encoder_port.sign, tw.encoder_port.m_per_count)
    hold = holding_volts(twins[0])
    draws = np.random.default_rng(1).standard_normal((400, 12))
    old, new = (tw.plant for tw in twins)
    for k in range(300):
        for tw in twins:
            codes = tw.dac_libs[0].codes3
            for i in range(3):
                codes[i] = volts_to_code(hold[i] + 0.4 * math.sin(0.02 * k + i))
        a, b = twins
        bits_old = kernels.period(old.geom, old.P, old.env, old.S, old.W, a.encoder_port._st,
                                  a.dac_libs[0].codes3, a.ati._packed, draws, 1e-3, 5, old.t,
                                  old.realistic, old.integrator, k, 1e-3,
                                  kernels.OVERLOAD_BITS)
        old.t = old.t + 1e-3
        bits_new = kernels.period_block(new.B, b.encoder_port._st, b.dac_libs[0].codes3,
                                        b.ati._packed, draws, 1e-3, 5, k, 1e-3)
        assert bits_old == bits_new
    assert old.B.view(np.int64).tolist() == new.B.view(np.int64).tolist()
    assert twins[0].encoder_port._st.tolist() == twins[1].encoder_port._st.tolist()
    assert twins[0].ati._packed.view(np.int64).tolist() == twins[1].ati._packed.view(
        np.int64).tolist()
    assert old.t == new.t == new.B[kernels.B_X + kernels.X_T] and 0.299 < new.t < 0.301
    assert np.ptp(new.q) > 0.0                       # it moved


def test_the_plant_time_and_a_sim_clock_live_in_arrays():
    """Groundwork of a compiled pre-flight driver: what it advances is in arrays Python
    reads (``TwinPlant.t`` in the block, ``SimClock.t`` in its cell), and ``sync()`` follows
    a clock advanced through its cell."""
    from rt.twin.twin import SimClock
    clock = SimClock(0.25)
    assert clock() == clock.t == clock.cell[0] == 0.25
    twin = Twin(clock=clock)
    twin.plant.t = 0.125
    assert twin.plant.B[kernels.B_X + kernels.X_T] == 0.125 and twin.t == 0.125
    clock.cell[0] = 0.130
    twin.sync()
    assert twin.t == pytest.approx(0.130, abs=1e-12)
    clock.t = 0.131
    twin.sync()
    assert twin.t == pytest.approx(0.131, abs=1e-12)
    twin.clock = None                       # no clock: sync() without a time does nothing
    twin.sync()
    assert twin.t == pytest.approx(0.131, abs=1e-12)


@pytest.mark.parametrize("faults", [(), ("stale",), ("saturate",), ("dropout",)])
def test_compiled_ati_model_gives_the_interpreted_samples(faults):
    params = AtiSensorParams(ranges=(50.0, 50.0, 150.0, 5.0, 5.0, 5.0))
    ref, fast = TwinAtiSensorModel(params, seed=7), TwinAtiSensorModel(params, seed=7,
                                                                       compiled=True)
    for name in faults:
        for model in (ref, fast):
            model.schedule_fault(name, 0.5, 0.8)
    for k in range(2100):            # more than two blocks of random numbers
        t = k * DT
        wrench = (60.0 * math.sin(t), 5.0, 100.0 + 80.0 * math.cos(3 * t), 0.1, -6.0 * t, 0.0)
        a = ref.measure(wrench, t)
        b = fast.measure(np.array(wrench), t)
        if a is None or b is None:
            assert a is b is None
            continue
        assert (a.status, a.ft_sequence) == (b.status, b.ft_sequence)
        _close(a.wrench, b.wrench, "wrench", k)
    _close(ref.drift, fast.drift, "drift", -1)
    ref.reset()
    fast.reset()
    a, b = ref.measure((1.0,) * 6, 0.0), fast.measure((1.0,) * 6, 0.0)
    assert a is not None and b is not None
    assert a.wrench == b.wrench


@pytest.mark.parametrize("seed", range(4))
def test_twin_physics_takes_s_s_dot_and_the_twist_from_the_model_kernel(seed):
    """One S/twist helper (issue 16): the twin's mass and bias fill S, Ṡ and the twist map
    with the model's ``tree_maps_work``, bit for bit."""
    rng = np.random.default_rng(seed)
    plant = Twin.ideal().plant
    cfg = plant.kin.ik(rng.uniform(0.55, 0.75), rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2))
    q, qd, phi = np.array(cfg.q), rng.normal(0.0, 0.2, 3), np.array(cfg.phi)
    s, sd, tw = np.zeros((12, 3)), np.zeros((12, 3)), np.zeros((6, 3))
    m, h, rot = np.zeros((3, 3)), np.zeros(3), np.zeros((3, 3))
    physics.mass_and_bias(plant.geom, plant.bodies, q, qd, phi, rot, np.zeros(3), s, sd, tw, m,
                          h)
    # At the rotation the twin assembled from (q, φ) (within round-off of the IK's).
    assert np.allclose(rot, np.reshape(cfg.rotation, (3, 3)), rtol=0.0, atol=1e-14)
    s_ref, sd_ref, tw_ref = np.zeros((12, 3)), np.zeros((12, 3)), np.zeros((6, 3))
    tree_maps(plant.geom, q, phi, rot, qd, s_ref, sd_ref, tw_ref)
    assert np.array_equal(s, s_ref) and np.array_equal(sd, sd_ref) and np.array_equal(tw, tw_ref)


@pytest.mark.parametrize("seed", range(4))
def test_the_drift_evaluated_once_is_the_maps_drift_to_round_off(seed):
    """The twin's substep takes Ṡ q̇ as H(q̇, q̇) evaluated once (``tree_maps_drift_sc``,
    issue 16) where ``tree_maps`` gives Ṡ's columns H(q̇, e_k): the same bilinear form, so
    Ṡ q̇ to round-off (entries ~1 m/s² and rad/s² at 0.2 m/s; a wrong term is ≥ 1e-3 of
    that), with S and the twist map bit for bit."""
    rng = np.random.default_rng(seed)
    plant = Twin.ideal().plant
    cfg = plant.kin.ik(rng.uniform(0.55, 0.75), rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2))
    q, qd, phi = np.array(cfg.q), rng.normal(0.0, 0.2, 3), np.array(cfg.phi)
    rot = np.reshape(np.array(cfg.rotation, dtype=float), (3, 3))
    s_ref, sd_ref, tw_ref = np.zeros((12, 3)), np.zeros((12, 3)), np.zeros((6, 3))
    tree_maps(plant.geom, q, phi, rot, qd, s_ref, sd_ref, tw_ref)
    s, tw, sdq = np.zeros((12, 3)), np.zeros((6, 3)), np.zeros(12)
    work = np.zeros(TREE_MAPS_WORK)
    work[0:3], work[3:6] = np.sin(phi), np.cos(phi)
    tree_maps_drift_sc(plant.geom, q, rot, qd, s, sdq, tw, work)
    assert np.array_equal(s, s_ref) and np.array_equal(tw, tw_ref)
    expected = sd_ref @ qd
    assert np.max(np.abs(expected)) > 1e-3                       # the drift is not trivial
    assert np.allclose(sdq, expected, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("env,offset_v", [("free", 0.0), ("plate:0.7128", 0.0),
                                           ("ankle", 0.0), ("ankle", 0.015)])
def test_fused_period_equals_the_general_compiled_path_bit_for_bit(env, offset_v):
    """``Twin._sync_fused`` (the physics, encoder index and ATI sample in one compiled call)
    against the general compiled path (``plant.advance`` then ``_update_sensors``): the same
    state, counters and samples exactly, every period, with a drive switch-off; also with
    the amplifiers' input offsets on (issue 15 turns them on by default)."""
    stream = _record(env, ideal=False, seconds=0.6)
    imp = RigImperfections(amplifier_offset_v=offset_v)
    general = Twin(environment=parse_environment(env), seed=3, imperfections=imp)
    general.fused_period = False
    fused = Twin(environment=parse_environment(env), seed=3, imperfections=imp)
    assert fused.plant._with_offset == (offset_v > 0.0)
    assert fused.fused_period
    for k, (t, codes, enabled) in enumerate(stream):
        for twin in (general, fused):
            _apply(twin, codes, enabled)
            twin.sync(t)
        assert general.plant.S.tolist() == fused.plant.S.tolist(), f"period {k}"
        assert general.plant.t == fused.plant.t
        assert list(general.encoder_port._count) == list(fused.encoder_port._count), \
            f"period {k}"
        assert list(general.encoder_port._encoder_index) == \
            list(fused.encoder_port._encoder_index)
        assert general.ati_sample == fused.ati_sample, f"period {k}"


def test_a_fault_plan_takes_the_general_path():
    """With a fault scheduled the twin runs the general path (the fused period models none)."""
    twin = Twin()
    twin.set_card_enabled(0, True)
    called = []
    twin._sync_fused = lambda t: called.append(t)      # type: ignore[method-assign]
    twin.sync(0.001)
    assert called == [0.001]
    twin.faults.schedule("encoder_freeze", 0.5, axis=0)
    twin.sync(0.002)
    assert called == [0.001] and twin.plant.t == pytest.approx(0.002)


@pytest.mark.parametrize("kind", ["ati_dropout", "ati_stale"])
def test_an_ati_fault_after_fused_periods_sees_their_last_sample(kind):
    """The fused period leaves its ATI sample in the model's array and builds the
    ``AtiSample`` only when asked (``Twin.ati_sample``, ``TwinForceTorque``'s reading): a
    dropout or a stale sensor scheduled after fused periods must hold the same last sample as
    on the general path, and the force reader must read the same numbers on both."""
    from rt.devices.interfaces import FT_READ_SIZE
    from rt.twin.backends import TwinForceTorque

    stream = _record("plate:0.7128", ideal=False, seconds=0.3)
    general = Twin(environment=parse_environment("plate:0.7128"), seed=3)
    general.fused_period = False
    fused = Twin(environment=parse_environment("plate:0.7128"), seed=3)
    readers = [TwinForceTorque(general), TwinForceTorque(fused)]
    for r in readers:
        r.start()
    reads = [np.zeros(FT_READ_SIZE), np.zeros(FT_READ_SIZE)]
    for k, (t, codes, enabled) in enumerate(stream):
        if k == 150:                     # 150 fused periods, then the fault from the next
            for twin in (general, fused):
                twin.faults.schedule(kind, t - 0.0005, t + 0.05)
        for twin, reader, out in zip((general, fused), readers, reads):
            _apply(twin, codes, enabled)
            twin.sync(t)
            reader.read_array(out)
        assert reads[0].tolist() == reads[1].tolist(), f"period {k}"
        assert general.ati_sample == fused.ati_sample, f"period {k}"
    assert general.ati_sample is not None


def test_the_atis_bookkeeping_lives_in_its_packed_array_on_both_paths():
    """Issue 16 (a compiled pre-flight driver advances the twin without Python): the ATI's
    bookkeeping — the random block's next row, the last sample's time and counter, its status
    word — is in the model's packed array, advanced there by the fused period's kernel
    (``kernels.period_ati``) and by the general path's Python alike. Over 1.3 s (past the
    first random block of 1024 rows: the refill between two kernel calls) both paths leave
    the same array to the bit, every period; only the object-not-built flag differs (the
    general path builds every sample's object)."""
    from rt.ati.twin_sensor import _A_PENDING, _A_ROW, _A_SEQ, _A_STATUS, _A_T_LAST, _State

    assert not {"block_pos", "t_last", "ft_sequence"} & set(_State.__dataclass_fields__)
    stream = _record("plate:0.7128", ideal=False, seconds=1.3)
    general = Twin(environment=parse_environment("plate:0.7128"), seed=3)
    general.fused_period = False
    fused = Twin(environment=parse_environment("plate:0.7128"), seed=3)
    for twin in (general, fused):
        pk = twin.ati._packed
        assert pk[_A_SEQ] == 0.0 and pk[_A_ROW] == 0.0 and math.isnan(pk[_A_T_LAST])
        assert twin.ati.t_last is None and twin.ati.ft_sequence == 0
    keep = np.ones(len(fused.ati._packed), dtype=bool)
    keep[_A_PENDING] = False
    overloads = 0
    for k, (t, codes, enabled) in enumerate(stream):
        for twin in (general, fused):
            _apply(twin, codes, enabled)
            twin.sync(t)
        g, f = general.ati._packed, fused.ati._packed
        assert g[keep].view(np.int64).tolist() == f[keep].view(np.int64).tolist(), f"period {k}"
        assert f[_A_PENDING] == 1.0 and g[_A_PENDING] == 0.0
        assert f[_A_SEQ] == k + 1 and f[_A_ROW] == (k % 1024) + 1
        assert f[_A_T_LAST] == fused.t
        overloads += f[_A_STATUS] != 0.0
        if k % 97 == 0:                 # the object built on demand from the array
            assert fused.ati_sample == general.ati_sample, f"period {k}"
            assert f[_A_PENDING] == 0.0
    assert len(stream) > 1024
    assert fused.ati.ft_sequence == len(stream) and fused.ati.t_last == fused.t


def test_the_twins_period_draws_the_next_random_block_in_python():
    """``kernels.period_ati`` does nothing and answers ``NEED_DRAWS`` when the ATI's random
    block is used up; the twin then draws the next one (``_next_block_row``) and repeats the
    call: the period's state is the same as if the block had been there."""
    twin = Twin(seed=5)
    twin.set_card_enabled(0, True)
    ati = twin.ati
    before = twin.plant.B.copy()
    empty = np.empty((0, 12))
    bits = kernels.period_ati(twin.plant.B, twin.encoder_port._st, twin.dac_libs[0].codes3,
                              ati._packed, empty, 1e-3, twin._n_chunk)
    assert bits == kernels.NEED_DRAWS
    assert twin.plant.B.view(np.int64).tolist() == before.view(np.int64).tolist()
    twin.sync(0.001)
    assert ati.ft_sequence == 1 and ati._packed[kernels.ATI_ROW] == 1.0
    assert len(ati._state.block) == 1024
