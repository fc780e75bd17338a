"""The fused cycle (``rt.components.fused``) against the per-block cycle, bit for bit (issue 16).

Two loops are built alike on their own twins; one runs the estimator → supervisor chain as one
compiled call per cycle, the other runs the five blocks' ``update`` (``Graph.fused = False``,
the reference). They are stepped in lockstep through a position session with controller swaps
(each swap's bumpless fade runs the controller block), a hand-stop trip with its reset, and an
e-stop; and through a force protocol with its tare (force mode runs the hybrid controller's
Python) followed by a position protocol. After every cycle every output port of every slot is
compared byte for byte, as are the safety events, the graph's faults and the twin's state;
the fused run must also actually have fused (and have stopped part-way on the events).
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable

import numpy as np
import pytest

from rt.components import fused, hybrid_kernel
from rt.engine import STATUS_EXCEPTION, Array, Component, GraphBuilder
from rt.errors import ConfigurationError
from rt.model import RobotModel
from rt.model.dynamics import Payload
from rt.position_loop import (
    PositionLoop,
    build_protocol_loop,
    build_sim_position_loop,
    sim_devices,
    swap_controller,
)
from rt.safety.events import Reaction


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


def _events(pl: PositionLoop) -> list[tuple]:
    return [(e.t, e.kind, e.cause, int(e.reaction), e.message, repr(e.values))
            for e in pl.events.snapshot()]


class _Lockstep:
    """A fused loop and a per-block loop built by ``build``, stepped together. The per-block
    loop is the interpreted reference of everything the fused one compiles beyond the blocks'
    own kernels: its sequencer reads a previewed force program ahead in Python
    (``compiled_read_ahead = False``) and its hybrid controller runs its interpreted force
    mode (``HybridController.update``)."""

    def __init__(self, build: Callable[[], PositionLoop]):
        self.f, self.p = build(), build()
        self.p.graph.fused = False
        self.p.reference.compiled_read_ahead = False
        assert self.f.graph.fused and self.f.graph.segment.why_not == ""
        self.ran: Counter[int] = Counter()
        #: Cycles the fused kernel ran whole with the hybrid controller in force mode.
        self.force_fused = 0
        seg = self.f.graph.segment
        run = seg.run
        ctl = self.f.graph.component("controller")

        #: Cycles whose drive stage / recorder stage ran in the kernel too.
        self.drive_fused = self.recorder_fused = 0

        #: Cycles each sensor ran in the kernel (``fused.HEAD`` order).
        self.sensors_fused = [0, 0, 0]
        head = len(fused.HEAD) if seg.slots[0] == fused.HEAD[0] else 0

        #: Cycles that took the steady fast path (a plan, still valid after the cycle).
        self.planned = 0

        def counted(t: float, dt: float, idx: int) -> int:
            planned = seg._plan_ok
            n = run(t, dt, idx)
            self.planned += int(planned and seg._plan_ok)
            m = n - head              # stages of the middle chain and the tail
            # ``ran[5]``: the middle chain ran whole (and the tail's stages maybe too).
            self.ran[max(0, min(m, 5))] += 1
            self.drive_fused += int(m >= 6 and seg.pending is None)
            self.recorder_fused += int(m == 7)
            self.force_fused += int(m >= 5 and bool(getattr(ctl, "_in_force", False)))
            if n:
                for k in range(head):
                    self.sensors_fused[k] += int(seg.why_not_sensor[k] == "")
            return n

        seg.run = counted
        self.cycles = 0
        self.expect_fused = True

    def both(self, act: Callable[[PositionLoop], object]) -> None:
        act(self.f)
        act(self.p)

    def run(self, cycles: int) -> None:
        for _ in range(cycles):
            self.f.loop.run(cycles=1)
            self.p.loop.run(cycles=1)
            self.cycles += 1
            self.compare()

    def compare(self) -> None:
        gf, gp = self.f.graph, self.p.graph
        # An exception in the segment would turn fusion off (and rerun the blocks): never
        # (unless a test turned it off: ``expect_fused``).
        assert gf.fused or not self.expect_fused, (self.cycles, repr(gf.last_exception))
        for slot in gf.order:
            cf, cp = gf.component(slot), gp.component(slot)
            assert cf.name == cp.name, (self.cycles, slot)
            for name, port in cf.outputs.items():
                a = np.asarray(port.data.buf if hasattr(port.data, "buf") else port.data)
                o = cp.outputs[name].data
                b = np.asarray(o.buf if hasattr(o, "buf") else o)
                assert a.tobytes() == b.tobytes(), (self.cycles, slot, name, a, b)
        assert _events(self.f) == _events(self.p), self.cycles
        assert [(x.cycle, x.slot, x.code, x.reason) for x in gf.faults()] == \
            [(x.cycle, x.slot, x.code, x.reason) for x in gp.faults()], self.cycles
        tf, tp = self.f.twin, self.p.twin
        assert tf is not None and tp is not None
        assert repr(tf.true_state()) == repr(tp.true_state()), self.cycles
        # The device stages' own state: both cards' codes, the drive's numbers, the
        # recorder's rows (the last one written, and how many).
        for c in (0, 1):
            assert tf.dac_libs[c].ao.tobytes() == tp.dac_libs[c].ao.tobytes(), (self.cycles, c)
        df, dp = gf.component("drive"), gp.component("drive")
        assert df._st.tobytes() == dp._st.tobytes() and df._card == dp._card, self.cycles
        assert df._enabled == dp._enabled, self.cycles
        rf, rp = self.f.recorder, self.p.recorder
        assert rf.written == rp.written, self.cycles
        row = (rf.written - 1) % rf.capacity
        assert rf.ring[row].tobytes() == rp.ring[row].tobytes(), self.cycles


def test_a_position_session_with_swaps_and_trips_is_the_per_block_cycle_bit_for_bit(model):
    # Each loop its own model: the FK warm start lives in the model's kinematics.
    h = _Lockstep(lambda: build_sim_position_loop("paden_panja", duration_s=2.5,
                                                  model=RobotModel.load()))
    h.run(400)                                          # approach, play (Paden-Panja)
    for law in ("pd_g0", "adaptive", "pid", "computed_torque"):
        h.both(lambda pl, law=law: swap_controller(pl, law))
        h.run(250)                                      # the swap, its fade, then fused
        if law == "adaptive":                           # new gains replace its estimate
            lam = h.f.controller.gains.lambda_per_s
            h.both(lambda pl, lam=lam: pl.loop.set_params("controller", lambda_per_s=1.2 * lam))
            h.run(100)
    h.both(lambda pl: setattr(pl.twin.inputs, "hand_stop", True))   # a trip in the kernel
    h.run(60)
    h.both(lambda pl: setattr(pl.twin.inputs, "hand_stop", False))
    h.run(20)
    h.both(lambda pl: pl.supervisor.request_reset())
    h.run(200)
    h.both(lambda pl: pl.supervisor.request_estop("operator"))      # Python's trip
    h.run(50)
    h.both(lambda pl: pl.supervisor.request_reset())
    h.run(300)
    assert h.f.events.first("hand_stop") is not None
    assert h.f.events.first("estop_operator") is not None
    # Fused whole on steady cycles, stopped part-way on the others: before the reference
    # (approach and return: ruckig; events) and before the controller (the fades).
    assert h.ran[5] > 0.2 * h.cycles and h.ran[2] > 0 and h.ran[3] > 0, h.ran


def test_an_approach_and_a_return_take_the_fast_path_bit_for_bit(model):
    """The approach and the return (issue 16, approach9): each move planned once with ruckig
    on its event's cycle, its samples then played by the fused kernel's reference stage; in
    lockstep with the per-block cycle byte for byte, and nearly all of their cycles on the
    steady fast path (before: every one of them ran the sequencer's Python)."""
    from rt.references.sequencer import Phase

    h = _Lockstep(lambda: build_sim_position_loop("paden_panja", duration_s=0.2,
                                                  model=RobotModel.load()))
    ref = h.f.reference
    seg = h.f.graph.segment
    run = seg.run
    by_phase: Counter[tuple[Phase, bool]] = Counter()

    def classed(t: float, dt: float, idx: int) -> int:
        planned = seg._plan_ok
        n = run(t, dt, idx)
        by_phase[(Phase(int(ref.phase.data[0])), planned and seg._plan_ok)] += 1
        return n

    seg.run = classed
    for _ in range(4000):
        h.run(1)
        if by_phase[(Phase.RETURN, True)] and Phase(int(ref.phase.data[0])) == Phase.REST:
            break
    h.run(20)
    approach = by_phase[(Phase.APPROACH, True)] + by_phase[(Phase.APPROACH, False)]
    back = by_phase[(Phase.RETURN, True)] + by_phase[(Phase.RETURN, False)]
    assert approach > 500 and back > 200, by_phase
    # The approach's first cycle, its arrival and the cycle after each (the general path
    # that re-makes the plan); the same for the return.
    assert by_phase[(Phase.APPROACH, False)] <= 4, by_phase
    assert by_phase[(Phase.RETURN, False)] <= 4, by_phase


def test_the_drive_stage_fails_over_and_stops_as_the_drive_block_bit_for_bit(model):
    """The drive as a fused stage (the twin's compiled double): a DAC channel of card 0 dies
    (its amplifier input disagrees: the kernel's monitor check confirms it, Python fails over
    to card 1 in the same cycle), card 1's stage runs fused after it; then a write on card 1
    fails (the list stops part-way: EIO, last card: the hard stop, every card off). Every
    cycle compared with the per-block drive, codes of both cards included."""
    h = _Lockstep(lambda: build_sim_position_loop("paden_panja", duration_s=2.5,
                                                  model=RobotModel.load()))
    seg = h.f.graph.segment
    assert seg.slots[-2:] == fused.TAIL and seg.why_not_drive == "" \
        and seg.why_not_recorder == ""
    h.run(1100)                                         # the approach, then play
    before = h.drive_fused
    assert before > 100 and h.recorder_fused > 100, (h.drive_fused, h.ran)
    assert seg._plan_ok and h.planned > 100, h.planned  # the fault arrives on the fast path
    planned = h.planned
    h.both(lambda pl: pl.twin.faults.schedule("dac_dead", pl.twin.t, card=0, channel=1))
    h.run(30)
    assert h.f.events.first("dac_card_0") is not None
    assert h.f.graph.component("drive")._card == 1
    h.run(200)
    assert h.drive_fused > before + 150, (h.drive_fused, h.ran)   # card 1 fused after it
    # (No fast path on card 1: the twin's fault plan keeps the encoders' block running.)
    assert h.planned == planned, h.planned
    h.both(lambda pl: pl.twin.dac_libs[1].fail_channels.add(2))
    h.run(60)
    assert h.f.graph.component("drive").failed.data[0] == 1.0
    assert h.f.events.first("drive_channel") is not None
    assert h.f.supervisor.latched() != []


def test_the_sensor_stages_hand_their_faults_to_their_blocks_bit_for_bit(model):
    """The sensors as fused stages on the twin's memory: a frozen encoder and a jump (a twin
    fault: the encoder block decodes), the ATI's stale and lost samples (its blocks read
    them), a hand stop read by the stops' stage; fused again when the faults clear. Every
    cycle compared with the per-block sensors."""
    h = _Lockstep(lambda: build_sim_position_loop("paden_panja", duration_s=2.5,
                                                  model=RobotModel.load()))
    seg = h.f.graph.segment
    assert seg.slots[:3] == fused.HEAD and seg.slots[-2:] == fused.TAIL
    h.run(1100)
    assert min(h.sensors_fused) > 1000, h.sensors_fused
    # The steady cycles took the fast path (the plan), and the faults below arrive while it
    # is in force: its checks must send each cycle they change to the general path.
    assert h.planned > 0.9 * h.recorder_fused > 200 and seg._plan_ok, (h.planned, h.recorder_fused)
    h.both(lambda pl: pl.twin.faults.schedule("encoder_jump", pl.twin.t, axis=1, counts=3))
    h.both(lambda pl: pl.twin.faults.schedule("encoder_freeze", pl.twin.t + 0.01,
                                              pl.twin.t + 0.03, axis=0))
    before = list(h.sensors_fused)
    h.run(40)
    assert seg.why_not_sensor[0] != "" and h.sensors_fused[0] == before[0]
    h.both(lambda pl: pl.twin.faults.faults.clear())
    h.run(20)
    assert h.sensors_fused[0] > before[0]
    h.both(lambda pl: pl.twin.ati.set_fault("stale"))
    before = list(h.sensors_fused)
    h.run(120)                                          # stale beyond the 50 ms timeout
    assert h.sensors_fused[1] == before[1] and h.sensors_fused[0] > before[0] + 100
    assert h.f.graph.component("force").flags.data[0] == 1.0          # flagged stale
    h.both(lambda pl: pl.twin.ati.set_fault("stale", False))
    h.both(lambda pl: pl.twin.ati.set_fault("dropout"))
    h.run(80)
    h.both(lambda pl: pl.twin.ati.clear_faults())
    h.run(100)
    h.both(lambda pl: setattr(pl.twin.inputs, "hand_stop", True))   # read by the stage
    h.run(30)
    assert h.f.events.first("hand_stop") is not None
    assert h.sensors_fused[2] > 1300, h.sensors_fused


def _library_protocol(model: RobotModel, name: str, *replace: tuple[str, str]):
    from protocols.generators import make_generator
    from protocols.library import LIBRARY_DIR, parse_protocol_text

    text = (LIBRARY_DIR / name).read_text()
    for old, new in replace:
        assert old in text
        text = text.replace(old, new)
    gen = make_generator(parse_protocol_text(text), dt=1e-3, kinematics=model.kin)
    assert gen.validate().ok
    return gen


def _short_sine(model: RobotModel):
    return _library_protocol(model, "sine_fz.yaml", ("cycles: 20", "cycles: 1"),
                             ("ramp_in_s: 2.0", "ramp_in_s: 0.3"),
                             ("ramp_out_s: 2.0", "ramp_out_s: 0.3"))


def _sine_loop(model: RobotModel) -> PositionLoop:
    """A protocol loop on a twin foot (compliant ankle) with a one-cycle sine Fz requested."""
    from protocols.library import LIBRARY_DIR, parse_protocol_text
    from rt.twin.environment import CompliantAnkle
    from rt.twin.twin import SimClock, Twin

    proto_z = parse_protocol_text((LIBRARY_DIR / "sine_fz.yaml").read_text()).pose.z_m
    sensor_z = proto_z + model.description.sensor.offset_m[2]
    clock = SimClock()
    twin = Twin(model.description, CompliantAnkle(neutral_z_m=sensor_z, limb_weight_n=0.0),
                clock=clock)
    twin.place(model.kin.ik(proto_z, 0.0, 0.0).q)
    return build_protocol_loop(sim_devices(twin, clock), _short_sine(model), RobotModel.load())


def _to_play(h: _Lockstep) -> None:
    from rt.references.sequencer import Phase

    for _ in range(60):                                 # approach, tare, then PLAY
        h.run(100)
        if h.f.reference.current_phase == Phase.PLAY:
            return
    raise AssertionError("never reached PLAY")


def _to_rest(h: _Lockstep, cycles: int = 100, most: int = 200) -> None:
    for _ in range(most):
        if not h.f.reference.busy:
            return
        h.run(cycles)
    raise AssertionError("the program never ended")


def test_a_force_then_a_position_protocol_are_the_per_block_cycle_bit_for_bit(model):
    h = _Lockstep(lambda: _sine_loop(model))
    _to_play(h)
    h.run(1500)
    _to_rest(h)                                         # to its end and the return
    # The hybrid controller's steady force mode ran in the kernel (read-ahead included).
    assert h.force_fused > 1000, (h.force_fused, h.ran)
    assert h.f.graph.segment.why_not_force == ""
    rom = ("ankle_rom.yaml", ("repetitions: 3", "repetitions: 1"),
           ("sequence: [dorsi_plantar, inversion_eversion]", "sequence: [dorsi_plantar]"),
           ("dorsiflexion: 10.0", "dorsiflexion: 3.0"),
           ("plantarflexion: 10.0", "plantarflexion: 3.0"), ("hold_s: 1.0", "hold_s: 0.1"))
    h.both(lambda pl: pl.reference.request(_library_protocol(model, *rom)))
    h.run(1500)
    assert h.f.reference.epoch == 2
    assert h.ran[5] > 0.3 * h.cycles and h.ran[2] + h.ran[3] > 0, h.ran


def test_a_force_programs_tare_ramp_and_hold_run_in_the_kernel_bit_for_bit(model):
    """hold9 (issue 16): against the per-block loop with its sequencer interpreted
    (``compiled=False``), a force program's tare wait, the force ramp-down after an abort in
    force, then a 565 kg landing mid-sine (the ``pulling`` soft stop and the compliant hold
    rising under it) are byte for byte every cycle, and the fused kernel ran their cycles
    whole: only their events (the tare's grant, the ramp's end and the brake's arrival before
    it, the stop itself) left it."""
    from rt.references.sequencer import Phase

    h = _Lockstep(lambda: _sine_loop(model))
    h.p.reference.compiled = False
    cycles: Counter[str] = Counter()
    whole: Counter[str] = Counter()

    def step(n: int) -> None:
        for _ in range(n):
            kind = h.f.reference.steady_kind()
            before = h.ran[5]
            h.run(1)
            cycles[kind] += 1
            whole[kind] += h.ran[5] - before

    def until(done: Callable[[], bool], most: int = 20_000) -> None:
        for _ in range(most):
            if done():
                return
            step(1)
        raise AssertionError("never happened")

    until(lambda: h.f.reference.current_phase == Phase.PLAY)
    assert cycles["tare"] > 50 and cycles["tare"] - whole["tare"] <= 2, (cycles, whole)
    step(50)
    h.both(lambda pl: setattr(pl.reference, "force_ramp_s", 0.1))    # 0.3 s: 3 × longer
    h.both(lambda pl: pl.reference.request_abort())
    until(lambda: not h.f.reference.busy)
    assert cycles["ramp"] > 150 and cycles["ramp"] - whole["ramp"] <= 4, (cycles, whole)
    h.both(lambda pl: pl.reference.request(_short_sine(model)))
    until(lambda: h.f.reference.current_phase == Phase.PLAY)
    step(300)
    h.both(lambda pl: pl.twin.plant.set_payload(Payload(565.0, (0.0, 0.0, 0.10))))
    step(700)
    ref = h.f.reference
    assert ref.yielded_m > 0.002 and ref.yielded_m == h.p.reference.yielded_m
    assert cycles["yield"] > 300 and cycles["yield"] - whole["yield"] <= 2, (cycles, whole)
    assert cycles["tare"] > 100                    # both programs' tares


@pytest.mark.parametrize("stop", ["soft", "estop"])
def test_a_stop_in_force_mode_is_the_per_block_cycle_bit_for_bit(model, stop):
    """Mid-sine, in force mode: the operator's soft stop (the reference hands over to the
    position law's hold where the loaded platform is, at once: force6) or an e-stop (drives
    off, the hard stop's hand-over); then its reset and the hold. Every cycle compared."""
    h = _Lockstep(lambda: _sine_loop(model))
    _to_play(h)
    h.run(700)
    ctl = h.f.graph.component("controller")
    assert ctl._in_force and h.force_fused > 600, (h.force_fused, h.ran)
    if stop == "soft":
        h.both(lambda pl: pl.supervisor.request_stop())
        h.run(40)
        assert not ctl._in_force                        # holding in position already
    else:
        h.both(lambda pl: pl.supervisor.request_estop("operator"))
        h.run(40)
        assert h.f.events.first("estop_operator") is not None
    h.run(600)
    assert not ctl._in_force
    reactions = [e[3] for e in _events(h.f)]
    assert int(Reaction.SOFT_STOP if stop == "soft" else Reaction.HARD_STOP) in reactions
    h.both(lambda pl: pl.supervisor.request_reset())
    h.run(300)
    assert h.f.supervisor.latched() == []
    assert h.ran[5] > 0 and h.ran[2] > 0, h.ran


def test_a_real_gait_file_replay_is_the_per_block_cycle_bit_for_bit(tmp_path):
    """A real C3D record (heel strikes beyond the drives: the preview's transients, the
    integral held, the unloading governor) replayed through the pre-flight's own loop
    (``protocols.session.build_twin_session``, the patient's foot on the twin)."""
    import importlib.util
    import os
    import sys
    from pathlib import Path

    from protocols.session import SessionSetup, build_twin_session

    pytest.importorskip("ezc3d")
    data = None
    for d in (os.environ.get("TALUS_C3D_DIR"),
              Path(__file__).parents[2] / "shared/data/c3d"):
        if d and (Path(d) / "type2_vicon.c3d").is_file():
            data = Path(d)
    if data is None:
        pytest.skip("the real C3D files ($TALUS_C3D_DIR) are not present")
    spec = importlib.util.spec_from_file_location(
        "bench_gait_files_fused", Path(__file__).parents[1] / "bench" / "gait_files.py")
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = bench                      # its dataclasses look it up
    spec.loader.exec_module(bench)
    case = next(c for c in bench.CASES if c.file == "type2_vicon.c3d")
    path = tmp_path / "gait.yaml"
    path.write_text(bench.protocol_text(case, data))
    setup = SessionSetup(path, patient_weight_kg=bench.PATIENT_KG)
    h = _Lockstep(lambda: build_twin_session(setup, RobotModel.load(), "fast")[3])
    _to_play(h)
    ctl = h.f.graph.component("controller")
    transient = 0
    for _ in range(40):
        h.run(50)
        weight = ctl._hs[hybrid_kernel.H_AHEAD_WEIGHT] if ctl._hs_live else ctl._ahead_weight
        transient += int(weight > 0.0)
    _to_rest(h)
    assert h.force_fused > 600 and transient > 0, (h.force_fused, transient, h.ran)


def test_a_calibration_push_on_the_stiff_plate_is_the_per_block_cycle_bit_for_bit():
    """The calibration's shear push (600 N through the tool tip on the twin plate, 2e6 N/m,
    then a 2° roll under load): the gain schedule on the stiffness engaged (k̂ above k_s),
    the angle integral at work, every cycle compared."""
    from calibration.plan import (
        ProfileKind,
        default_plan,
        expand,
        force_profile,
        tilt_profile,
        trial_pose,
    )
    from calibration.plate import TWIN_PLATE_FILE, load_plate
    from calibration.push import (
        ForceTableGenerator,
    )
    from calibration.twin_runner import plate_above_tool_tip
    from rt.safety.limits import PatientLimits, RobotLimits
    from rt.twin.twin import SimClock, Twin

    dt = 1e-3
    plan = default_plan(shear=[{"roll_deg": 2.0, "load_n": 600.0, "tilt_ramp_s": 0.5,
                                "hold_s": 0.2}], registration="nominal", baseline_s=0.3)
    plate = load_plate(TWIN_PLATE_FILE)
    trial = next(t for t in expand(plan, plate.size_m) if t.profile == ProfileKind.SHEAR)
    pose = trial_pose(plan, trial)

    def build() -> PositionLoop:
        m = RobotModel.load()
        z0, roll, pitch = pose
        env = plate_above_tool_tip(m, z0)
        clock = SimClock()
        twin = Twin(m.description, env, seed=7, clock=clock)
        twin.place(np.array(m.kin.ik(z0, roll, pitch).q))
        gen = ForceTableGenerator(trial.id, force_profile(plan, trial, dt), pose, dt, m.kin,
                                  tilt_profile(plan, trial, dt))
        assert gen.validate().ok
        limits = PatientLimits(max_force_n=RobotLimits().max_platform_force_n,
                               roll_min_deg=-10.0, roll_max_deg=10.0, pitch_min_deg=-10.0,
                               pitch_max_deg=10.0)
        return build_protocol_loop(sim_devices(twin, clock), gen, m, 1.0 / dt, "fast",
                                   patient_limits=limits)

    # The trial's table (what the compiled sequencer plays) is its ``update``, row by row.
    from rt.references.program import ReferenceOutput

    m = RobotModel.load()
    gen = ForceTableGenerator(trial.id, force_profile(plan, trial, dt), pose, dt, m.kin,
                              tilt_profile(plan, trial, dt))
    assert gen.validate().ok
    view = gen.table_view()
    assert view is not None and view.col0 == 0
    out = ReferenceOutput()
    rows = []
    while True:
        status = gen.update(out)
        rows.append(out.buf.copy())
        if out.done:
            break
    assert status >= 0 and np.array_equal(np.array(rows), view.table)

    h = _Lockstep(build)
    _to_play(h)
    law = h.f.graph.component("controller").force_law
    k_s = law.gains.schedule_stiffness_n_per_m
    scheduled = 0
    for _ in range(30):
        h.run(50)
        scheduled += int(law.k_est > k_s > 0.0)
    _to_rest(h)
    assert scheduled > 5 and h.force_fused > 800, (scheduled, h.force_fused, h.ran)
    assert not [e for e in _events(h.f) if e[3] >= int(Reaction.SOFT_STOP)], _events(h.f)


def test_a_remembered_contact_is_the_per_block_cycle_bit_for_bit():
    """Two 400 N pushes on the twin plate with the contact remembered
    (``HybridController.remember_contact``): the second push's remembered stiffness is applied
    on its first loaded cycle by the compiled force cycle (``hybrid_kernel.force_cycle``,
    ``H_K_PENDING``) in the fused loop and by the interpreted block in the per-block one,
    every cycle compared."""
    from calibration.push import (
        ForceTableGenerator,
    )
    from calibration.twin_runner import plate_above_tool_tip
    from rt.safety.limits import PatientLimits, RobotLimits
    from rt.twin.twin import SimClock, Twin

    dt, pose = 1e-3, (0.633, 0.0, 0.0)
    up = np.linspace(0.0, 400.0, 300)
    profile = np.concatenate([up, np.full(200, 400.0), up[::-1]])

    def build() -> PositionLoop:
        m = RobotModel.load()
        q0 = np.array(m.kin.ik(*pose).q)
        env = plate_above_tool_tip(m, pose[0])
        clock = SimClock()
        twin = Twin(m.description, env, seed=5, clock=clock)
        twin.place(q0)
        pl = build_protocol_loop(sim_devices(twin, clock), None, m, 1.0 / dt, "fast",
                                 patient_limits=PatientLimits(
                                     max_force_n=RobotLimits().max_platform_force_n))
        pl.graph.component("controller").remember_contact = True
        return pl

    m = RobotModel.load()

    def push_program() -> ForceTableGenerator:
        gen = ForceTableGenerator("push", profile, pose, dt, m.kin)
        assert gen.validate().ok             # (which also prepares its table)
        return gen

    h = _Lockstep(build)
    ctl = h.f.graph.component("controller")
    primed_compiled = 0
    for push in range(2):
        h.both(lambda pl: pl.reference.request(push_program()))
        for n in range(4000):
            waiting = ctl._hs_live and not np.isnan(ctl._hs[hybrid_kernel.H_K_PENDING])
            h.run(1)
            if waiting and ctl._hs_live and np.isnan(ctl._hs[hybrid_kernel.H_K_PENDING]):
                primed_compiled += 1
            if n > 100 and not h.f.reference.busy:
                break
        assert not h.f.reference.busy
        if push == 0:
            assert ctl._k_contact >= 1e6
    assert primed_compiled == 1
    assert h.force_fused > 800, (h.force_fused, h.ran)
    assert not [e for e in _events(h.f) if e[3] >= int(Reaction.SOFT_STOP)], _events(h.f)


def test_the_fused_chain_refuses_what_it_does_not_cover(model):
    """A non-standard law in the controller slot keeps the per-block cycle (named), and the
    environment flag turns fusion off."""
    from rt.control.base import Controller

    class MyPid(type(__import__("rt.control.laws", fromlist=["Pid"]).Pid(model))):
        pass

    pl = build_sim_position_loop("paden_panja", duration_s=1.0, model=model)
    assert pl.graph.fused and pl.graph.segment.why_not == ""
    from rt.components.blocks import ControllerBlock
    law = MyPid(model)
    assert isinstance(law, Controller)
    pl.loop.swap("controller", ControllerBlock("controller_mine", law))
    pl.loop.run(cycles=5)
    assert "no fused path" in pl.graph.segment.why_not
    ran = []
    run = pl.graph.segment.run
    pl.graph.segment.run = lambda t, dt, idx: ran.append(run(t, dt, idx)) or ran[-1]
    pl.loop.run(cycles=5)
    assert ran == [0] * 5
    stats = pl.graph.stats().components
    assert all(stats[s].count > 0 for s in fused.CHAIN)


def test_the_environment_flag_turns_fusion_off(model, monkeypatch):
    monkeypatch.setenv(fused.ENV_FLAG, "0")
    pl = build_sim_position_loop("paden_panja", duration_s=1.0, model=model)
    assert pl.graph.segment is not None and not pl.graph.fused


class _Count(Component):
    """Ports: out ``y``: float64[1] — how many times its ``update`` ran."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.y = self.declare_output("y", Array(1))

    def update(self, t: float, dt: float) -> int:
        self.y.data[0] += 1.0
        return 0


class _Segment:
    """A fake fused segment over b, c, d: runs ``n`` of them (by hand), then ``pending``."""

    slots = ("b", "c", "d")

    def __init__(self) -> None:
        self.n = 0
        self.pending = None
        self.others_ns = 0
        self.prepared = 0

    def attach(self, graph, rings) -> None:
        self.graph = graph
        self.rings = rings

    def prepare(self) -> None:
        self.prepared += 1

    def prepare_swap(self, slot, new) -> None:
        pass

    def run(self, t: float, dt: float, idx: int) -> int:
        for s in self.slots[:self.n]:
            self.graph.component(s).y.data[0] += 10.0
        return self.n


def _counting_graph():
    """Five counting blocks a-e in a chain, configured."""
    b = GraphBuilder()
    for s in "abcde":
        b.add(_Count(s))
    g = b.build()
    g.configure()
    return g


def test_the_graph_runs_a_fused_segment_then_the_blocks_it_left():
    g = _counting_graph()
    seg = _Segment()
    with pytest.raises(ConfigurationError, match="not consecutive"):
        bad = _Segment()
        bad.slots = ("b", "d")
        g.fuse(bad)
    g.fuse(seg)
    g.start()
    assert g.fused and seg.prepared == 1

    def counts() -> list[float]:
        return [float(g.component(s).y.data[0]) for s in "abcde"]

    g.step(0.0, 1e-3)                             # the segment runs none: every block
    assert counts() == [1, 1, 1, 1, 1]
    seg.n = 2
    g.step(0.0, 1e-3)                             # b, c by the segment, d its own update
    assert counts() == [2, 11, 11, 2, 2]
    seg.n = 3

    def refuse(t: float, dt: float) -> int:
        raise RuntimeError("no FK there")

    seg.pending = refuse                          # d's completion raises: d's fault
    g.step(0.0, 1e-3)
    assert counts() == [3, 21, 21, 12, 3]
    assert [(f.slot, f.code, f.reason) for f in g.faults()] == [
        ("d", STATUS_EXCEPTION, "update raised RuntimeError: no FK there")]
    seg.pending = lambda t, dt: 10               # a status: the slot's fault, as update's
    g.step(0.0, 1e-3)
    assert g.faults()[-1].reason == "update returned status 10"
    g.fused = False                               # the per-block reference
    g.step(0.0, 1e-3)
    assert counts() == [5, 32, 32, 22, 5]
    assert all(g.stats().components[s].count == 5 for s in "abce")


def test_a_segment_that_raises_leaves_the_blocks_to_run():
    g = _counting_graph()
    seg = _Segment()

    def broken(t: float, dt: float, idx: int) -> int:
        raise RuntimeError("bug")

    seg.run = broken  # type: ignore[method-assign]
    g.fuse(seg)
    g.start()
    assert g.step(0.0, 1e-3) == 0
    assert [float(g.component(s).y.data[0]) for s in "abcde"] == [1, 1, 1, 1, 1]
    assert not g.fused and isinstance(g.last_exception, RuntimeError)
