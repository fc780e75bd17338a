"""The compiled cycle against the interpreted blocks it replaced (issue 16).

A cycle stream is recorded from the position loop on the twin (measured positions and the
reference each cycle), with an encoder glitch, a NaN and an out-of-stroke reading spliced in,
and replayed through both implementations of the estimator, the model block and every position
law. The estimator must be bit-identical; the model state and the forces within 1e-12 relative
to their scale (the compiled RNEA sums in another order than Pinocchio: ~1e-16 observed).
"""
from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

import rt.control.adaptive
import rt.control.laws  # noqa: F401  (registers the laws for the parametrization)
from rt.components.blocks import ModelState, VelocityEstimation
from rt.components.tare import TareState
from rt.control.base import CONTROLLERS, Reference, create
from rt.model import RobotModel
from rt.model import rigid_body as rb
from rt.model.dynamics import State
from rt.position_loop import build_sim_position_loop

RTOL = 1e-12
CYCLES = 600
DT = 1e-3


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


@pytest.fixture(scope="module")
def stream(model) -> dict[str, np.ndarray]:
    """q_meas, q_ref, qd_ref, qdd_ref per cycle, recorded from the loop (fast mode, twin)."""
    pl = build_sim_position_loop("paden_panja", duration_s=5.0, model=model)
    enc = pl.graph.component("encoders").q
    ref = pl.graph.component("reference")
    rows = []
    for _ in range(CYCLES):
        pl.loop.run(cycles=1)
        rows.append(np.concatenate((enc.data, ref.q_ref.data, ref.qd_ref.data,
                                    ref.qdd_ref.data)))
    pl.graph.stop()
    data = np.array(rows)
    q = data[:, 0:3].copy()
    q[200, 1] += 0.01               # a glitch the estimator's gate rejects
    q[300, 2] = np.nan              # a lost sample
    q[400, 0] = 5.0                 # outside the stroke: FK refused
    return {"q": q, "q_ref": data[:, 3:6], "qd_ref": data[:, 6:9], "qdd_ref": data[:, 9:12]}


def _model_block(model: RobotModel, compiled: bool) -> ModelState:
    blk = ModelState("model", model, compiled=compiled)
    blk.q_meas.data = np.zeros(3)
    blk.qd.data = np.zeros(3)
    blk.state_out.data = State()
    blk.fk_ok.data = np.zeros(1)
    return blk


def _estimator_block(compiled: bool) -> VelocityEstimation:
    blk = VelocityEstimation("estimator", compiled=compiled)
    blk.q_meas.data = np.zeros(3)
    blk.state = blk.make_state()
    return blk


def _replay_front(model_c: RobotModel, model_i: RobotModel, stream) -> list[tuple]:
    """Estimator and model block, compiled and interpreted, side by side; returns per cycle
    (compiled State copy, interpreted State copy, fk_ok) for the laws' replay."""
    est_c, est_i = _estimator_block(True), _estimator_block(False)
    mod_c, mod_i = _model_block(model_c, True), _model_block(model_i, False)
    states = []
    for k in range(CYCLES):
        q = stream["q"][k]
        for est in (est_c, est_i):
            est.q_meas.data[:] = q
            est.update(k * DT, DT)
        for name in ("q", "qd", "qdd", "status"):
            assert np.array_equal(getattr(est_c, name).data, getattr(est_i, name).data), \
                (k, name)
        for mod in (mod_c, mod_i):
            mod.q_meas.data[:] = q
            mod.qd.data[:] = est_c.qd.data
            mod.update(k * DT, DT)
        assert mod_c.fk_ok.data[0] == mod_i.fk_ok.data[0], k
        sc, si = mod_c.state_out.data, mod_i.state_out.data
        for name in ("Q", "Qd", "qd", "S", "Sd", "twist", "rot", "_q", "_phi"):
            a, b = getattr(sc, name), getattr(si, name)
            assert np.allclose(a, b, rtol=0.0, atol=RTOL * max(1.0, np.abs(b).max())), (k, name)
        assert sc.forward_det == pytest.approx(si.forward_det, rel=RTOL, abs=RTOL)
        ci, cc = si.cfg, sc.cfg
        assert cc.q == ci.q and cc.phi == ci.phi and cc.spheres == ci.spheres
        for f in ("z", "roll", "pitch", "x", "y", "yaw"):
            assert getattr(cc, f) == pytest.approx(getattr(ci, f), rel=RTOL, abs=RTOL), (k, f)
        copy_c, copy_i = State(), State()
        copy_c.buf[:] = sc.buf
        copy_c.buffer_filled()
        copy_i.buf[:] = si.buf
        copy_i.cfg = ci
        states.append((copy_c, copy_i, mod_c.fk_ok.data[0]))
    assert (model_c.kin._phi_guess == model_i.kin._phi_guess).all()
    return states


def test_estimator_and_model_block_match_the_interpreted_ones(stream) -> None:
    states = _replay_front(RobotModel.load(), RobotModel.load(), stream)
    fk = np.array([s[2] for s in states])
    # The NaN and the out-of-stroke reading were refused by both, nothing else.
    assert fk[300] == 0.0 and fk[400] == 0.0 and fk.sum() == CYCLES - 2


@pytest.mark.parametrize("law", sorted(CONTROLLERS))
def test_every_law_matches_its_interpreted_reference(law, stream) -> None:
    states = _replay_front(RobotModel.load(), RobotModel.load(), stream)
    model_c, model_i = RobotModel.load(), RobotModel.load()
    ctl_c = create(law, model_c, compiled=True)
    ctl_i = create(law, model_i, compiled=False)
    out_c, out_i = np.zeros(3), np.zeros(3)
    worst = 0.0
    for k, (st_c, st_i, fk_ok) in enumerate(states):
        ref = Reference(stream["q_ref"][k], stream["qd_ref"][k], stream["qdd_ref"][k])
        if k == 250:                           # a bumpless swap mid-stream, on both
            ctl_c.handover(np.array([50.0, -20.0, 10.0]), st_c, ref, DT)
            ctl_i.handover(np.array([50.0, -20.0, 10.0]), st_i, ref, DT)
        ctl_c.update(st_c, ref, DT, out_c)
        ctl_i.update(st_i, ref, DT, out_i)
        scale = max(1.0, float(np.abs(out_i).max()))
        worst = max(worst, float(np.abs(out_c - out_i).max()) / scale)
    assert worst <= RTOL, f"{law}: τ differs by {worst:.2e} of its scale"
    assert np.abs(out_i).max() > 1.0                     # the stream exercised the law
    if law == "adaptive":
        # The estimates moved and stayed together.
        assert np.abs(ctl_i.theta - ctl_i.nominal).max() > 0.0
        assert np.allclose(ctl_c.theta, ctl_i.theta, rtol=RTOL, atol=0.0)


@pytest.mark.parametrize("law", sorted(CONTROLLERS))
def test_a_laws_bound_cycle_is_its_update_bit_for_bit(law, stream) -> None:
    """``Controller.bind_cycle``: the one-call cycle a block runs gives ``update``'s τ bit for
    bit, through a bumpless handover (the fading offset goes through ``update``, then the
    bound cycle again), new gains and a reset (arrays rebuilt behind the bound call)."""
    states = _replay_front(RobotModel.load(), RobotModel.load(), stream)
    model_b, model_u = RobotModel.load(), RobotModel.load()
    bound, plain = create(law, model_b), create(law, model_u)
    st_b, st_u = State(), State()
    ref_b, ref_u = Reference(), Reference()
    out_b, out_u = np.zeros(3), np.zeros(3)
    bound.bind_cycle(st_b, ref_b, out_b)
    has_kernel = bound.cycle is not None
    ran_bound = 0
    gains = {"pid": {"ki_n_per_m_s": 900.0}, "adaptive": {"lambda_per_s": 30.0}}.get(
        law, {next(iter(bound.gain_ranges)): 1.1 * getattr(bound.gains,
                                                           next(iter(bound.gain_ranges)))})
    for k, (st_c, _st_i, _fk) in enumerate(states):
        for st in (st_b, st_u):
            st.buf[:] = st_c.buf
            st.buffer_filled()
        for ref in (ref_b, ref_u):
            ref.q[:], ref.qd[:], ref.qdd[:] = (stream["q_ref"][k], stream["qd_ref"][k],
                                               stream["qdd_ref"][k])
        if k == 150:
            for c, st, ref in ((bound, st_b, ref_b), (plain, st_u, ref_u)):
                c.handover(np.array([50.0, -20.0, 10.0]), st, ref, DT)
            assert bound.cycle is None or law == "pid"      # PID absorbs into its integral
        if k == 400:
            bound.set_gains(**gains)
            plain.set_gains(**gains)
        if k == 500:
            bound.reset()
            plain.reset()
        cycle = bound.cycle
        if cycle is not None:
            assert cycle(DT) == 0
            ran_bound += 1
        else:
            bound.update(st_b, ref_b, DT, out_b)
        plain.update(st_u, ref_u, DT, out_u)
        assert np.array_equal(out_b, out_u), (law, k)
    assert np.array_equal(bound.tau, out_u)
    # Every law with a whole kernel ran bound before the handover and after the reset (the
    # offset fades over seconds: through update meanwhile).
    assert (ran_bound >= 200) == has_kernel, (law, ran_bound)
    assert has_kernel


def test_compiled_dynamics_match_pinocchio(model) -> None:
    """M q̈ + C q̇_d + G through the RNEA products equals Pinocchio's matrices, and Pinocchio's
    Coriolis matrix is the Christoffel factorization the products assume (symmetric Γ)."""
    import pinocchio as pin

    dyn = model.dyn
    rng = np.random.default_rng(7)
    work = np.zeros(rb.work_size(12))
    pi = rb.unpack_tree(dyn.tree_i, dyn.tree_f)[5]
    for _ in range(20):
        cfg = model.kin.ik(rng.uniform(0.58, 0.68), rng.uniform(-0.15, 0.15),
                           rng.uniform(-0.15, 0.15))
        st = dyn.state(np.array(cfg.q), rng.normal(0.0, 0.1, 3), out=State(), cfg=cfg)
        qdd, qdr = rng.normal(0.0, 1.0, 3), rng.normal(0.0, 0.1, 3)
        m, c, g = dyn.mcg(st)
        out = np.zeros(3)
        rb.mixed_torque(dyn.tree_i, dyn.tree_f, pi, st.buf, qdd, qdr, True, work, out)
        want = m @ qdd + c @ qdr + g
        assert np.allclose(out, want, rtol=0.0, atol=RTOL * np.abs(want).max())
        v, w = rng.normal(size=12), rng.normal(size=12)
        cv = pin.computeCoriolisMatrix(dyn.model, dyn.data, st.Q, v).copy()
        cw = pin.computeCoriolisMatrix(dyn.model, dyn.data, st.Q, w).copy()
        assert np.allclose(cv @ w, cw @ v, rtol=0.0, atol=1e-12 * np.abs(cv @ w).max())


def test_payload_reaches_the_compiled_model(model) -> None:
    """set_payload changes what the kernels compute, the same as Pinocchio's."""
    from rt.model.dynamics import Payload

    m2 = RobotModel.load()
    dyn = m2.dyn
    cfg = m2.kin.ik(0.63, 0.05, -0.05)
    st = dyn.state(np.array(cfg.q), np.zeros(3), out=State(), cfg=cfg)
    ctl = create("pd_g", m2)
    ref = Reference(np.array(cfg.q), np.zeros(3), np.zeros(3))
    before = np.zeros(3)
    ctl.update(st, ref, DT, before)
    dyn.set_payload(Payload(100.0, (0.05, 0.0, 0.1)))
    after = np.zeros(3)
    ctl.update(st, ref, DT, after)
    want = dyn.gravity(st)
    assert np.allclose(after, want, rtol=0.0, atol=RTOL * np.abs(want).max())
    assert (after - before).sum() == pytest.approx(100.0 * 9.81, rel=0.05)


def _kernels():
    from rt.components.blocks import tap_row
    from rt.control import kernels as ck
    from rt.estimation import compiled as ec
    from rt.model import kernels as mk
    from rt.references import sequencer_kernel as sk

    return (ck.pid, ck.paden_panja, ck.adaptive, ck.pd_gravity, ck.computed_torque,
            ck.gravity, ck.pd_gravity_desired, ec.kalman_update, ec.block_update,
            mk.model_state, sk.cycle,
            sk.play_table, sk.emit, sk.finish, tap_row)


@pytest.mark.parametrize("controller", ["paden_panja", "adaptive", "pid"])
def test_no_kernel_compiles_inside_a_cycle(controller, model) -> None:
    """Kernels are compiled at construction for the argument types the loop passes (read-only
    port views): a first-cycle compile would stall the loop for seconds."""
    from rt.position_loop import build_protocol_loop, sim_devices
    from rt.twin.environment import FreeMotion
    from rt.twin.twin import SimClock, Twin

    pl = build_sim_position_loop(controller, duration_s=1.0, model=model)
    clock = SimClock()
    twin = Twin(None, FreeMotion(), clock=clock)
    twin.place((0.2, 0.2, 0.2))
    hybrid = build_protocol_loop(sim_devices(twin, clock), model=model, controller=controller)
    before = [len(k.signatures) for k in _kernels()]
    pl.loop.run(cycles=20)
    hybrid.loop.run(cycles=20)
    pl.graph.stop()
    hybrid.graph.stop()
    assert [len(k.signatures) for k in _kernels()] == before


def test_explicit_force_law_matches_its_interpreted_reference(stream) -> None:
    """The hybrid force law on the recorded states, with a force profile that loads, holds,
    learns the stiffness (RLS), saturates the feedforward and loses the sensor (NaN)."""
    from rt.control.force import ExplicitForce, ForceReference

    states = _replay_front(RobotModel.load(), RobotModel.load(), stream)
    law_c = ExplicitForce(RobotModel.load(), compiled=True)
    law_i = ExplicitForce(RobotModel.load(), compiled=False)
    out_c, out_i = np.zeros(3), np.zeros(3)
    worst = 0.0
    for k, (st_c, st_i, fk_ok) in enumerate(states):
        if not fk_ok:
            continue
        t = k * DT
        ref = ForceReference(f=300.0 + 200.0 * np.sin(6.0 * t), f_dot=1200.0 * np.cos(6.0 * t),
                             f_ddot=-7200.0 * np.sin(6.0 * t), roll=0.02, pitch=-0.01,
                             roll_rate=0.0, pitch_rate=0.0)
        if k == 100:
            ref.f_dot = 1.0e5                  # beyond the feedforward's speed bound
        force = math.nan if 350 <= k < 360 else 280.0 + 150.0 * np.sin(6.0 * t + 0.3)
        law_c.update(st_c, force, ref, DT, out_c)
        law_i.update(st_i, force, ref, DT, out_i)
        worst = max(worst, float(np.abs(out_c - out_i).max()) / max(1.0, np.abs(out_i).max()))
    assert worst <= RTOL
    assert law_c.integral == pytest.approx(law_i.integral, rel=RTOL, abs=RTOL)
    assert law_c.k_est == pytest.approx(law_i.k_est, rel=RTOL)
    assert law_i.k_est != law_i.gains.stiffness_guess_n_per_m     # the RLS ran


def test_benchmark_sampler_matches_its_interpreted_reference() -> None:
    """The compiled benchmark trajectory gives the interpreted one's samples bit for bit (and
    still takes lists)."""
    from rt.control.experiment import benchmark_reference, benchmark_reference_interpreted

    compiled, interpreted = benchmark_reference(0.21), benchmark_reference_interpreted(0.21)
    rc, ri = Reference(), Reference()
    for t in np.linspace(0.0, 60.0, 7919):
        compiled(float(t), rc)
        interpreted(float(t), ri)
        for name in ("q", "qd", "qdd"):
            assert np.array_equal(getattr(rc, name), getattr(ri, name)), (t, name)
    # Its table (a TrajectoryProgram's for the compiled sequencer): the same samples.
    table = compiled.tabulate(DT, 2001)
    for k in (0, 1, 777, 2000):
        interpreted(k * DT, ri)
        assert np.array_equal(table[k], np.concatenate((ri.q, ri.qd, ri.qdd))), k
    lists = Reference([0.0] * 3, [0.0] * 3, [0.0] * 3)  # type: ignore[arg-type]
    compiled(1.5, lists)
    interpreted(1.5, ri)
    assert lists.q == list(ri.q) and lists.qdd == list(ri.qdd)


# -- the sequencer (issue 16: the reference sampled compiled) ---------------------------------
class _PythonForceHold:
    """A program without a table (called every cycle): 250 N in z where it starts, reading the
    patient's torque each cycle as an interactive program would."""

    def __init__(self, q, duration_s: float) -> None:
        self.q = np.array(q, float)
        self.duration_s = duration_s
        self.n = round(duration_s / DT) + 1
        self.k = 0

    @staticmethod
    def new_output():
        from rt.references.program import ReferenceOutput

        return ReferenceOutput()

    def reset(self) -> None:
        self.k = 0

    def update(self, out, inp=None) -> int:
        from rt.references.program import Mode

        out.q_ref[:] = self.q
        out.qd_ref[:] = 0.0
        out.qdd_ref[:] = 0.0
        tau = 0.0 if inp is None else inp.tau_roll_nm
        out.buf[15], out.buf[16] = 250.0 + 0.5 * tau, 10.0 * math.sin(0.01 * self.k)
        out.mode = Mode.FORCE
        out.done = self.k >= self.n - 1
        self.k = min(self.k + 1, self.n - 1)
        return 1 if out.done else 0


class _PythonForcePreview(_PythonForceHold):
    """The same program known in advance (a ``ForcePreview``): its force can be read ahead."""

    def _force(self, k: int) -> tuple[float, float]:
        return 250.0 + 40.0 * math.sin(0.004 * k), 160.0 * math.cos(0.004 * k)

    def update(self, out, inp=None) -> int:
        from rt.references.program import Mode

        out.q_ref[:] = self.q
        out.qd_ref[:] = 0.0
        out.qdd_ref[:] = 0.0
        out.buf[15], out.buf[16] = self._force(self.k)
        out.mode = Mode.FORCE
        out.index = self.k
        out.done = self.k >= self.n - 1
        self.k = min(self.k + 1, self.n - 1)
        return 1 if out.done else 0

    def force_at(self, index: int, out) -> None:
        out[0], out[1] = self._force(min(max(index, 0), self.n - 1))


class _Twins:
    """A compiled and an interpreted sequencer on the same input buffers (q_meas, the
    supervisor's mode, the wrench, the force reader's tare answering the compiled one's
    request one cycle late, as in the loop); the measured position follows the compiled one's
    reference with a small deterministic error."""

    def __init__(self, q0) -> None:
        from rt.components.tare import Tare
        from rt.references.sequencer import ProgramReference

        stroke = RobotModel.load().description.limits.stroke
        self.refs = [ProgramReference("reference", stroke, DT, compiled=c) for c in (True, False)]
        self.q = np.array(q0, float)
        self.mode = np.zeros(1)
        self.wrench = np.array([0.3, -0.2, -3.9, 0.01, 0.02, 0.0])
        self.flags = np.zeros(2)                   # the force reader's [stale, saturated]
        self.tare = Tare()
        self.tare_port = np.zeros(10)
        self.tare_request = np.zeros(1)
        for r in self.refs:
            for port, buf in ((r.q_meas, self.q), (r.mode, self.mode), (r.wrench, self.wrench),
                              (r.wrench_flags, self.flags), (r.tare, self.tare_port)):
                view = buf.view()
                view.flags.writeable = False
                port._bind(view, "test")
            r.configure()
            r.start()
        self.interpreted_cycles = 0
        compiled = self.refs[0]
        run = compiled._update

        def counted(dt: float) -> int:
            self.interpreted_cycles += 1
            self.interpreted[self.kind(event=True)] += 1
            return run(dt)

        compiled._update = counted  # type: ignore[method-assign]
        self.k = 0
        self.yield_cycles = 0
        #: Cycles by kind as they begin (``kind``), and those the interpreted path ran.
        self.cycles: Counter[str] = Counter()
        self.interpreted: Counter[str] = Counter()

    def kind(self, event: bool = False) -> str:
        """What the compiled sequencer's next cycle is: a force program's tare wait, a force
        reference's ramp-down, a force stop's compliant hold, or "other"; with ``event``, a
        request, an abort or a mode change first (an event: Python's by design)."""
        from rt.references import sequencer_kernel as sk

        c = self.refs[0]
        if event and (c._pending is not None or c._abort
                      or self.mode[0] != c._seq[sk.S_MODE]):
            return "event"
        return c.steady_kind()

    def request(self, make_program, **kw) -> None:
        """Each sequencer gets its own program (the interpreted one calls it every cycle)."""
        for r in self.refs:
            r.request(make_program(), **kw)

    def abort(self) -> None:
        for r in self.refs:
            r.request_abort()

    def step(self) -> None:
        c, i = self.refs
        self.tare.cycle(self.wrench.copy(), True, self.tare_request[0] > 0.5, self.tare_port)
        w = self.wrench.copy()
        self.yield_cycles += int(c.state.yielding)
        self.cycles[self.kind()] += 1
        for r in self.refs:
            assert r.update(self.k * DT, DT) == 0
            self.wrench[:] = w
        assert np.array_equal(c._io, i._io, equal_nan=True), \
            (self.k, np.flatnonzero(~((c._io == i._io) | (np.isnan(c._io) & np.isnan(i._io)))))
        # The approach's whole state (its plan, its clock, where it holds) too.
        assert c.approach.plan.tobytes() == i.approach.plan.tobytes(), self.k
        for name in ("phase", "mode", "started", "k", "taring", "tare_measuring",
                     "tares_before", "yielding"):
            assert getattr(c.state, name) == getattr(i.state, name), (self.k, name)
        assert (c.epoch, c.refused, c.last_error, c.tare_refused) == \
            (i.epoch, i.refused, i.last_error, i.tare_refused), self.k
        assert (c.yielded_m, c.yield_exhausted) == (i.yielded_m, i.yield_exhausted), self.k
        self.tare_request[:] = c.tare_request.data
        self.q[:] = c.q_ref.data + 2e-6 * math.sin(0.37 * self.k)
        self.k += 1

    def run(self, cycles: int) -> None:
        for _ in range(cycles):
            self.step()

    def until(self, phase, limit: int = 60_000) -> None:
        from rt.references.sequencer import Phase

        for _ in range(limit):
            self.step()
            if Phase(int(self.refs[0].phase.data[0])) == phase:
                return
        raise AssertionError(f"never reached {phase!r}")


def test_the_compiled_sequencer_matches_the_interpreted_one_bit_for_bit(model) -> None:
    """Table programs (a force protocol with its tare, a position protocol, a trajectory, the
    identification excitation) and a Python program, through approach, play, return, a soft
    stop mid-play and its reset, a hard stop following the measured position, an abort in
    force, requests refused, a refused tare and a NaN wrench: every output of every cycle is
    the interpreted sequencer's bit for bit, and the interpreted path runs only on events."""
    from protocols.generators import make_generator
    from protocols.library import LIBRARY_DIR, parse_protocol_text
    from rt.control.experiment import benchmark_reference
    from rt.identification.program import ExcitationProgram
    from rt.references.program import TrajectoryProgram
    from rt.references.sequencer import Phase
    from rt.safety.events import SupervisorMode

    def protocol(name: str, **replace: tuple[str, str]):
        text = (LIBRARY_DIR / name).read_text()
        for old, new in replace.values():
            assert old in text
            text = text.replace(old, new)

        def make():
            gen = make_generator(parse_protocol_text(text), dt=DT, kinematics=model.kin)
            assert gen.validate().ok
            assert gen.table_view() is not None
            return gen
        return make

    sine = protocol("sine_fz.yaml", c=("cycles: 20", "cycles: 2"),
                    r=("ramp_in_s: 2.0", "ramp_in_s: 0.5"), o=("ramp_out_s: 2.0", "ramp_out_s: 0.5"))
    rom = protocol("ankle_rom.yaml", r=("repetitions: 3", "repetitions: 1"),
                   s=("sequence: [dorsi_plantar, inversion_eversion]", "sequence: [dorsi_plantar]"),
                   a=("dorsiflexion: 10.0", "dorsiflexion: 3.0"),
                   p=("plantarflexion: 10.0", "plantarflexion: 3.0"),
                   h=("hold_s: 1.0", "hold_s: 0.1"))
    q_mid = np.array(model.kin.ik(0.63, 0.0, 0.0).q)
    h = _Twins(q_mid + 0.002)
    h.run(5)                                       # at rest, nothing to play
    h.request(sine, rest_q=tuple(q_mid + 0.002))
    h.until(Phase.PLAY)                            # approach, tare
    h.wrench[2] = math.nan                         # a lost sensor sample while playing
    h.run(3)
    h.wrench[2] = -3.9
    h.run(800)
    h.request(rom)                                 # refused: a program is running
    h.run(2)
    h.mode[0] = SupervisorMode.SOFT_STOP           # mid-play: brake, ramp the force down
    h.run(2500)
    h.request(rom)                                 # refused: stopped
    h.run(3)
    h.mode[0] = SupervisorMode.RUN                 # the reset
    h.run(10)
    h.request(rom, rest_q=tuple(q_mid))            # plays to its end, returns to rest
    h.until(Phase.PLAY)
    h.until(Phase.REST)
    h.run(20)
    h.request(lambda: TrajectoryProgram(benchmark_reference(float(q_mid[0])), 1.0, DT))
    h.until(Phase.PLAY)
    h.run(300)
    h.mode[0] = SupervisorMode.HARD_STOP           # the reference follows the platform
    h.run(50)
    h.mode[0] = SupervisorMode.RUN
    h.run(10)
    table = np.zeros((400, 9))
    table[:, 0:3] = h.q + 1e-3 * np.sin(np.linspace(0.0, 3.0, 400))[:, None]
    table[:, 3:6] = 1e-3 * 3.0 / 0.399 * np.cos(np.linspace(0.0, 3.0, 400))[:, None]
    h.request(lambda: ExcitationProgram(table, DT))
    h.until(Phase.REST)
    h.run(5)
    # A Python program, aborted while in force: the ramp down, then the hold.
    start = h.q.copy()
    h.request(lambda: _PythonForceHold(start, 1.0))
    h.wrench[:] = [0.1, 0.0, -3.9, 0.2, 0.0, 0.0]
    h.until(Phase.PLAY)
    h.run(300)
    h.abort()
    h.until(Phase.REST)
    h.run(5)
    # A force protocol on a loaded platform: the tare is refused, nothing plays.
    h.wrench[2] = -80.0
    h.request(sine)
    h.until(Phase.APPROACH)
    h.until(Phase.REST)
    h.run(5)
    # A pull through a force-control soft stop's hold (issue 15): the hold's reference rises
    # while the foot is pulled (a step per cycle, all sliders alike), holds while it is not,
    # and once its distance is used up with the pull still there, holds as any stop (the
    # compiled cycle again).
    h.wrench[2] = -3.9
    h.request(sine, rest_q=tuple(q_mid))
    h.until(Phase.PLAY)
    h.run(300)
    h.mode[0] = SupervisorMode.SOFT_STOP
    h.run(3)
    c = h.refs[0]
    assert c.state.yielding and c.yielded_m == 0.0
    held = c.q_ref.data.copy()
    h.wrench[2] = 40.0                             # the platform pulls the foot with 40 N
    h.run(200)
    rise = c.q_ref.data - held
    assert np.allclose(rise, 200 * c.yield_speed_m_s * DT, rtol=0.0, atol=1e-12), rise
    h.wrench[2] = -1.0                             # unloaded: it holds there
    h.run(50)
    assert np.array_equal(c.q_ref.data - held, rise) and not c.qd_ref.data.any()
    h.wrench[2] = 40.0
    for flag in (0, 1):                            # a stale, a saturated sensor: no rise
        h.flags[flag] = 1.0
        h.run(30)
        h.flags[flag] = 0.0
        assert np.array_equal(c.q_ref.data - held, rise)
    before = h.interpreted_cycles
    h.wrench[2] = 40.0                             # pulled until the yield is used up
    h.run(900)
    assert c.yield_exhausted and not c.state.yielding
    assert c.yielded_m == pytest.approx(c.yield_max_m, abs=1e-12)
    h.run(100)                                     # the plain hold: compiled again
    assert h.interpreted_cycles - before < 900, h.interpreted_cycles - before
    h.wrench[2] = -3.9
    h.mode[0] = SupervisorMode.RUN
    h.run(10)
    assert not c.state.yielding
    c = h.refs[0]
    assert c.tare_refused == 1 and c.refused == 2 and c.epoch == 7
    # Steady cycles ran compiled: the interpreted path took the approaches, returns, ramps,
    # tares, the events and the force stops' compliant holds, not the playing or the holding.
    assert h.k > 10_000
    played = h.k - h.interpreted_cycles
    assert played > 0.4 * (h.k - h.yield_cycles), (played, h.k, h.yield_cycles)

    # The force law's preview (gait4): a force program known in advance is read ahead
    # (``force_preview``); the compiled cycle reads a table program ahead itself
    # (``sequencer_kernel.read_ahead``, issue 16) and hands a Python program's PLAY to the
    # interpreted read-ahead, and every output, ``force_preview`` included, is still the
    # interpreted sequencer's bit for bit, through the play, its last sample, a soft stop
    # mid-play and the return.
    from rt.references import sequencer_kernel as sk
    from rt.references.program import ForcePreview

    for r in h.refs:
        r.preview_steps = 5
    h.wrench[2] = -3.9
    preview = h.refs[0].force_preview.data
    force = h.refs[0].force.data
    ahead = 0

    def count_ahead(cycles: int) -> int:
        n = 0
        for _ in range(cycles):
            h.step()
            n += int(not np.array_equal(preview, force))
        return n

    h.request(sine, rest_q=tuple(q_mid))
    assert isinstance(h.refs[0]._pending.program, ForcePreview)
    h.until(Phase.PLAY)
    assert h.refs[0]._seq[sk.S_PREVIEW] == 1.0 and h.refs[0]._seq[sk.S_AHEAD] == 1.0
    before = h.interpreted_cycles
    ahead += count_ahead(500)
    assert h.interpreted_cycles == before                  # PLAY read ahead: the kernel's
    for _ in range(10_000):
        if Phase(int(h.refs[0].phase.data[0])) == Phase.REST:
            break
        ahead += int(not np.array_equal(preview, force))
        h.step()
    assert Phase(int(h.refs[0].phase.data[0])) == Phase.REST
    h.run(5)
    assert np.array_equal(preview, force)                  # no preview at rest
    # A Python program known in advance (its samples called each cycle), soft-stopped.
    start = h.q.copy()
    h.request(lambda: _PythonForcePreview(start, 1.0))
    h.until(Phase.PLAY)
    assert h.refs[0]._seq[sk.S_AHEAD] == 0.0
    before = h.interpreted_cycles
    ahead += count_ahead(400)
    assert h.interpreted_cycles - before == 400            # its read-ahead: interpreted
    h.mode[0] = SupervisorMode.SOFT_STOP
    h.run(1500)
    h.mode[0] = SupervisorMode.RUN
    h.run(10)
    assert ahead > 1500, ahead                             # the read-ahead really ran
    # Without a preview (0 steps) the same program plays compiled again, preview = force.
    for r in h.refs:
        r.preview_steps = 0
    h.request(sine)
    h.until(Phase.PLAY)
    before = h.interpreted_cycles
    assert count_ahead(300) == 0
    assert h.interpreted_cycles == before                  # steady PLAY: the kernel's


def test_the_tare_wait_the_force_ramp_and_the_compliant_hold_run_compiled(model) -> None:
    """hold9 (issue 16): a force program's tare wait, a force reference's ramp-down (an abort
    in force) and a force-control soft stop's compliant hold (pulled, unloaded, stale and
    saturated samples, pulled until exhausted) run in the compiled cycle, every output and the
    whole state bit for bit with the interpreted sequencer; the interpreted path runs only
    their events: the tare's grant, the ramp's end (and the brake's arrival before it), the
    hold's exhaustion."""
    from rt.references import sequencer_kernel as sk
    from rt.references.sequencer import Phase
    from rt.safety.events import SupervisorMode

    assert (sk.TARE_MEASURING, sk.TARE_DONE, sk.TARE_REFUSED) == (
        TareState.MEASURING, TareState.DONE, TareState.REFUSED)
    q_mid = np.array(model.kin.ik(0.63, 0.0, 0.0).q)
    h = _Twins(q_mid + 0.002)
    h.run(5)
    # A Python force program (no table): its approach, the tare wait, 300 cycles in force,
    # then an abort: RETURN brakes and ramps 250 N down (≈ 1.7 s at 0.3 s), then rests.
    h.request(lambda: _PythonForceHold(q_mid + 0.001, 1.0))
    h.until(Phase.PLAY)
    assert h.cycles["tare"] > 50 and h.interpreted["tare"] <= 1, (h.cycles, h.interpreted)
    h.run(300)
    h.abort()
    h.until(Phase.REST)
    h.run(5)
    assert h.cycles["ramp"] > 1000 and h.interpreted["ramp"] <= 3, (h.cycles, h.interpreted)
    assert not h.refs[0].force.data.any()
    # Again, soft-stopped in force: the compliant hold, pulled by 40 N.
    h.request(lambda: _PythonForceHold(q_mid + 0.001, 3.0))
    h.until(Phase.PLAY)
    h.run(200)
    h.mode[0] = SupervisorMode.SOFT_STOP
    h.run(3)
    c = h.refs[0]
    held = c.q_ref.data.copy()
    h.wrench[2] = 40.0
    h.run(200)
    rise = c.q_ref.data - held
    assert np.allclose(rise, 200 * c.yield_speed_m_s * DT, rtol=0.0, atol=1e-12), rise
    h.wrench[2] = -1.0                             # unloaded: it holds there
    h.run(50)
    h.wrench[2] = 40.0
    for flag in (0, 1):                            # a stale, a saturated sensor: no rise
        h.flags[flag] = 1.0
        h.run(30)
        h.flags[flag] = 0.0
    h.run(900)                                     # pulled until the yield is used up
    assert c.yield_exhausted and not c.state.yielding
    assert h.cycles["yield"] > 1000 and h.interpreted["yield"] <= 1, (h.cycles, h.interpreted)
    h.mode[0] = SupervisorMode.RUN
    h.wrench[2] = -3.9
    h.run(10)
    assert h.interpreted["tare"] + h.interpreted["ramp"] + h.interpreted["yield"] <= 6


def test_approaches_returns_and_brakes_run_compiled_bit_for_bit(model) -> None:
    """The approach, the return and a position-mode brake (issue 16, approach9): planned once
    with ruckig on their event's cycle (Python), then played by the compiled cycle
    (``approach_kernel.working_sample``), every output and the approach's whole plan the
    interpreted sequencer's bit for bit; only the plan and the arrival are Python's. A program
    whose first sample lies beyond the stroke (ruckig's community edition ignores position
    limits) and a return to a rest beyond it are refused by our check, compiled as
    interpreted; a second brake during a brake ends at rest."""
    from rt.identification.program import ExcitationProgram
    from rt.references.sequencer import Phase
    from rt.safety.events import SupervisorMode

    q_mid = np.array(model.kin.ik(0.63, 0.0, 0.0).q)
    lo, hi = RobotModel.load().description.limits.stroke
    h = _Twins(q_mid)
    c = h.refs[0]
    h.run(5)

    def table(start, n: int = 300) -> np.ndarray:
        t = np.zeros((n, 9))
        t[:, 0:3] = start + 2e-3 * np.sin(np.linspace(0.0, 3.0, n))[:, None]
        t[:, 3:6] = 2e-3 * 3.0 / ((n - 1) * DT) * np.cos(np.linspace(0.0, 3.0, n))[:, None]
        return t

    def python_in(phase: Phase, limit: int = 20_000) -> tuple[int, int]:
        """Cycles in ``phase`` from now until it ends, and how many were interpreted."""
        n = before = 0
        before = h.interpreted_cycles
        while Phase(int(c.phase.data[0])) == phase:
            h.step()
            n += 1
            assert n < limit
        return n, h.interpreted_cycles - before

    # An approach of 0.5 s and a return of 0.4 s to a rest 8 mm away.
    far = q_mid + np.array([0.01, -0.006, 0.004])
    rest = tuple(q_mid - 0.008)
    h.request(lambda: ExcitationProgram(table(far), DT), approach_min_s=0.5, rest_q=rest,
              return_min_s=0.4)
    h.step()                                        # the request: planned (Python)
    assert Phase(int(c.phase.data[0])) == Phase.APPROACH
    n, py = python_in(Phase.APPROACH)
    assert n >= 500 and py <= 1, (n, py)            # the arrival (the first sample) only
    h.until(Phase.RETURN)
    n, py = python_in(Phase.RETURN)
    assert n >= 400 and py <= 1, (n, py)            # the arrival at rest only
    assert np.array_equal(c.q_ref.data, rest)
    h.run(5)

    # A supervisor's soft stop mid-approach (position mode): the brake is compiled too.
    h.request(lambda: ExcitationProgram(table(far), DT), approach_min_s=0.5)
    h.run(200)
    h.mode[0] = SupervisorMode.SOFT_STOP
    h.step()                                        # the stop: planned (Python)
    before = h.interpreted_cycles
    h.run(400)
    assert h.interpreted_cycles - before <= 2       # the brake's arrival and its settle
    assert not c.qd_ref.data.any()
    h.mode[0] = SupervisorMode.RUN
    h.run(5)

    # An abort mid-approach (the return brakes), then a soft stop during that brake: the
    # second brake plans from where the first one got to and ends at rest.
    h.request(lambda: ExcitationProgram(table(far), DT), approach_min_s=0.5)
    h.run(200)
    h.abort()
    h.run(60)
    assert Phase(int(c.phase.data[0])) == Phase.RETURN and c.qd_ref.data.any()
    h.mode[0] = SupervisorMode.SOFT_STOP
    prev = c.qd_ref.data.copy()
    for _ in range(400):
        h.step()
        assert np.abs(c.qd_ref.data - prev).max() <= 0.5 * DT * (1 + 1e-9)
        prev = c.qd_ref.data.copy()
    assert not c.qd_ref.data.any() and Phase(int(c.phase.data[0])) == Phase.STOPPED
    h.mode[0] = SupervisorMode.RUN
    h.run(5)

    # Beyond the stroke: refused before anything moves.
    refused = c.refused
    outside = table(q_mid)
    outside[:, 0] += hi - outside[0, 0] + 1e-3      # the first sample 1 mm above the top
    h.request(lambda: ExcitationProgram(outside, DT))
    h.run(3)
    assert c.refused == refused + 1 and "ERROR_OUTSIDE_STROKE" in c.last_error
    assert Phase(int(c.phase.data[0])) == Phase.REST and not c.qd_ref.data.any()
    # A rest beyond the stroke: the return brakes where the program ended instead.
    h.request(lambda: ExcitationProgram(table(q_mid), DT), rest_q=(lo - 1e-3, *rest[1:]))
    h.until(Phase.RETURN)
    h.until(Phase.REST)
    assert (c.q_ref.data >= lo).all() and (c.q_ref.data <= hi).all()
    h.run(5)


def test_a_signal_taps_compiled_row_is_the_signals_in_order() -> None:
    """The tap's one-call row (``tap_row``) on a graph's read-only views holds t and every
    signal in order, wrapping around its ring; mixed array kinds keep the interpreted copy,
    with the same rows."""
    from rt.components.blocks import SignalTap

    rng = np.random.default_rng(3)
    rows = {}
    for read_only in (True, False):
        tap = SignalTap("tap", [("a", 3), ("b", 1), ("c", 6)], capacity=16)
        bufs = [np.zeros(3), np.zeros(1), np.zeros(6)]
        for port, buf in zip(tap.ports, bufs):
            view = buf.view()
            view.flags.writeable = not read_only if port.name == "b" else False
            port._bind(view, "test")
        tap.configure()
        tap.start()
        assert (tap._signals is not None) == read_only
        want = []
        for k in range(40):
            for buf in bufs:
                buf[:] = rng.normal(size=buf.shape)
            tap.update(k * DT, DT)
            want.append(np.concatenate([[k * DT], *bufs]))
        got, end = tap.drain(0)
        assert end == 40 and np.array_equal(got, np.array(want[-16:]))
        rows[read_only] = got
    assert rows[True].shape == rows[False].shape
