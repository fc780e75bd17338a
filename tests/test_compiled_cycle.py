"""The compiled cycle against the interpreted blocks it replaced (issue 16).

A cycle stream is recorded from the position loop on the twin (measured positions and the
reference each cycle), with an encoder glitch, a NaN and an out-of-stroke reading spliced in,
and replayed through both implementations of the estimator, the model block and every position
law. The estimator must be bit-identical; the model state and the forces within 1e-12 relative
to their scale (the compiled RNEA sums in another order than Pinocchio: ~1e-16 observed).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import rt.control.adaptive
import rt.control.laws  # noqa: F401  (registers the laws for the parametrization)
from rt.components.blocks import ModelState, VelocityEstimation
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
    for port in (blk.q, blk.qd, blk.qdd):
        port.data = np.zeros(3)
    blk.status.data = np.zeros(1)
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
    from rt.control import kernels as ck
    from rt.estimation import compiled as ec
    from rt.model import kernels as mk

    return (ck.pid, ck.paden_panja, ck.adaptive, ck.pd_gravity, ck.computed_torque,
            ck.gravity, ec.kalman_update, mk.model_state)


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
    lists = Reference([0.0] * 3, [0.0] * 3, [0.0] * 3)  # type: ignore[arg-type]
    compiled(1.5, lists)
    interpreted(1.5, ri)
    assert lists.q == list(ri.q) and lists.qdd == list(ri.qdd)
