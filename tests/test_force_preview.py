"""The force law's preview of a reference known in advance and its anti-windup at the drives'
limit (issue 15: the gait replay's heel strikes).

* the sequencer reads a precomputed force program ``preview_steps`` samples ahead onto
  ``force_preview`` (F̈_d by a centred difference about that sample), leaves ``force`` (the
  reference the session's error is measured against) as it was, and mirrors ``force`` when
  there is nothing to preview;
* the law holds its integral while a drive would be at its force limit in the direction the
  integral pushes (compiled and interpreted alike);
* on the twin, a force ramp through the foot's known stiffness: the measured force's lag behind
  the reference is reduced by the preview, by the preview's length.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_references import DT, Harness

from protocols.generators import make_generator
from protocols.library import parse_protocol_text
from rt.control.force import ExplicitForce, ForceReference
from rt.errors import ConfigurationError
from rt.model import RobotModel
from rt.references.program import FZ, FZ_DOT, ForcePreview, Mode, ReferenceOutput
from rt.references.sequencer import PREVIEW_F_DDOT_HALF_WIDTH, Phase

MODEL = RobotModel.load()

SINE = ("schema_version: 1\nkind: sine_fz\nname: preview\npose: {{z_m: 0.63}}\n"
        "mean_n: {mean}\namplitude_n: {amp}\nfrequency_hz: {f}\ncycles: {cycles}\n"
        "ramp_in_s: {ramp}\nramp_out_s: {ramp}\n")


def _sine(mean=300.0, amp=100.0, f=2.0, cycles=2, ramp=0.5):
    proto = parse_protocol_text(SINE.format(mean=mean, amp=amp, f=f, cycles=cycles, ramp=ramp),
                                "preview.yaml")
    gen = make_generator(proto, dt=DT, kinematics=MODEL.kin)
    assert gen.validate().ok
    return gen


def test_a_force_generator_reads_its_table_ahead_clamped_to_its_ends():
    gen = _sine()
    assert isinstance(gen, ForcePreview)
    s = gen.samples()
    out = np.zeros(2)
    for k in (0, 1, 700, gen.n_samples - 1):
        gen.force_at(k, out)
        assert out[0] == s["fz"][k] and out[1] == s["fz_dot"][k]
    gen.force_at(gen.n_samples + 50, out)
    assert out[0] == s["fz"][-1] and out[1] == s["fz_dot"][-1]
    gen.force_at(-3, out)
    assert out[0] == s["fz"][0] and out[1] == s["fz_dot"][0]


def test_the_sequencer_previews_a_known_force_program_and_keeps_its_reference():
    """``force`` is the program's sample (what the error is measured against); ``force_preview``
    is the sample ``preview_steps`` later, F̈ its centred difference; after the program, and
    for a program that cannot be read ahead, the two are equal."""
    gen = _sine()
    s = gen.samples()
    h = Harness(gen.samples()["q"][0])
    steps = 4
    h.ref.preview_steps = steps
    h.ref.request(gen)
    played = 0
    while played < 900:
        ph = h.step()
        if ph != Phase.PLAY:
            continue
        assert h.ref.ctrl_mode.data[0] == Mode.FORCE
        # The sample just played: the sequencer's count (the compiled sequencer plays a table
        # program from its table, without calling it: the program's own index stays put).
        k = h.ref.state.k - 1
        assert h.ref.force.data[0] == s["fz"][k] and h.ref.force.data[1] == s["fz_dot"][k]
        j = min(k + steps, gen.n_samples - 1)
        pv = h.ref.force_preview.data
        assert pv[0] == s["fz"][j] and pv[1] == s["fz_dot"][j]
        hw = PREVIEW_F_DDOT_HALF_WIDTH
        lo, hi = max(j - hw, 0), min(j + hw, gen.n_samples - 1)
        assert pv[2] == pytest.approx((s["fz_dot"][hi] - s["fz_dot"][lo]) / (2 * hw * DT),
                                      rel=1e-12, abs=1e-9)
        played += 1
    # F̈ of the sine: −A ω² sin at full amplitude, within the centred difference's O(ω² h²).
    omega = 2.0 * math.pi * 2.0
    assert abs(pv[2]) <= 100.0 * omega ** 2 * 1.001
    while h.step() == Phase.PLAY:
        pass
    assert h.ref.force.data[0] == 0.0
    while h.step() != Phase.REST:
        np.testing.assert_array_equal(h.ref.force_preview.data, h.ref.force.data)
    # Without a preview the law tracks the reference itself.
    gen2 = _sine()
    h2 = Harness(gen2.samples()["q"][0])
    h2.ref.request(gen2)
    for _ in range(3000):
        h2.step()
        np.testing.assert_array_equal(h2.ref.force_preview.data, h2.ref.force.data)


def test_the_preview_is_a_gain_with_a_range():
    assert ExplicitForce(MODEL, {"preview_s": 0.004}).gains.preview_s == 0.004
    with pytest.raises(ConfigurationError, match=r"preview_s"):
        ExplicitForce(MODEL, {"preview_s": 0.2})
    with pytest.raises(ConfigurationError, match=r"preview_s"):
        ExplicitForce(MODEL, {"preview_s": -0.001})


def _pressed_state():
    q = MODEL.kin.ik(0.633, 0.0, 0.0).q
    return MODEL.dyn.state(np.asarray(q), np.zeros(3))


@pytest.mark.parametrize("compiled", [True, False])
def test_the_integral_is_held_while_a_drive_is_at_its_limit(compiled):
    """A heel strike: 2.5 kN asked, 50 N measured. The command is beyond the drives' ≈ 2 kN,
    so the integral does not move (without the limit it winds by e·dt each cycle); once the
    error reverses, it integrates again."""
    st = _pressed_state()
    law = ExplicitForce(MODEL, compiled=compiled)
    limit = law.drive_force_limit_n
    d = MODEL.description.drive
    assert limit == pytest.approx(d.force_per_volt_n * d.command_limit_v, rel=1e-12)
    tau = np.zeros(3)
    for _ in range(5):
        law.update(st, 50.0, ForceReference(f=2500.0), 1e-3, tau)
    assert np.abs(tau).max() > limit and law.integral == 0.0
    law.update(st, 300.0, ForceReference(f=250.0), 1e-3, tau)
    assert np.abs(tau).max() < limit
    assert law.integral == pytest.approx(-50.0 * 1e-3, rel=1e-12)
    free = ExplicitForce(MODEL, compiled=compiled)
    free.drive_force_limit_n = 0.0              # no limit known: the integral winds
    free._pack_gains()
    for _ in range(5):
        free.update(st, 2400.0, ForceReference(f=2500.0), 1e-3, tau)
    assert np.abs(tau).max() > limit
    assert free.integral == pytest.approx(5 * 100.0 * 1e-3, rel=1e-12)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_transient_beyond_the_robot_holds_the_integral(compiled):
    """While the reference is a transient the robot cannot follow (the hybrid controller's
    lead), the error drives the proportional action but not the integral: a 40 N error for
    50 ms would otherwise leave 2 N s (2 kN at Ki 1000) to overshoot with afterwards."""
    st = _pressed_state()
    law = ExplicitForce(MODEL, compiled=compiled)
    tau_held, tau_free = np.zeros(3), np.zeros(3)
    for _ in range(50):
        law.update(st, 260.0, ForceReference(f=300.0, transient=True), 1e-3, tau_held)
    assert law.integral == 0.0
    law.update(st, 260.0, ForceReference(f=300.0), 1e-3, tau_free)
    assert law.integral == pytest.approx(40.0 * 1e-3, rel=1e-12)
    # The integral's one step is all that differs: Ki·e·dt on the task force.
    np.testing.assert_allclose(tau_free - tau_held, st.S[8, :] * 1000.0 * 0.04, rtol=1e-9)


def test_compiled_and_interpreted_laws_agree_through_saturation():
    st = _pressed_state()
    laws = [ExplicitForce(MODEL, compiled=c) for c in (True, False)]
    outs = [np.zeros(3), np.zeros(3)]
    for k in range(400):
        t = k * 1e-3
        f_ref = 10.0 + 2400.0 * math.exp(-((t - 0.1) / 0.01) ** 2)
        measured = 10.0 + 300.0 * (1.0 - math.cos(8.0 * t))
        ref = ForceReference(f=f_ref, f_dot=0.0, f_ddot=0.0, transient=150 <= k < 200)
        for law, out in zip(laws, outs, strict=True):
            law.update(st, measured, ref, 1e-3, out)
        np.testing.assert_allclose(outs[0], outs[1], rtol=1e-12, atol=1e-9)
        assert laws[0].integral == pytest.approx(laws[1].integral, rel=1e-12, abs=1e-15)
    assert laws[0].integral != 0.0


class _Step:
    """A force program known in advance (``ForcePreview``): 20 N held, a ramp at ``rate_n_s``
    to 300 N (a heel strike's rise: at 20 kN/s it asks the platform 0.2 m/s through the 1e5 N/m
    heel pad, four times what the law's motion feedforward may), held, then down at 1 kN/s."""

    def __init__(self, rate_n_s: float) -> None:
        t = np.arange(0.0, 1.2, DT)
        f = np.clip(20.0 + rate_n_s * (t - 0.3), 20.0, 300.0)
        f = np.minimum(f, np.clip(300.0 - 1000.0 * (t - 0.9), 20.0, 300.0))
        self.fz, self.fz_dot = f, np.gradient(f, DT)
        self.q = MODEL.kin.ik(0.63, 0.0, 0.0).q
        self.duration_s = (len(t) - 1) * DT
        self.index = 0

    @staticmethod
    def new_output() -> ReferenceOutput:
        return ReferenceOutput()

    def reset(self) -> None:
        self.index = 0

    def force_at(self, index: int, out: np.ndarray) -> None:
        k = min(max(index, 0), len(self.fz) - 1)
        out[0], out[1] = self.fz[k], self.fz_dot[k]

    def update(self, out: ReferenceOutput, inp=None) -> int:
        k = min(self.index, len(self.fz) - 1)
        out.q_ref[:] = self.q
        out.qd_ref[:] = 0.0
        out.qdd_ref[:] = 0.0
        out.pose_ref[:] = (0.63, 0.0, 0.0)
        out.buf[FZ], out.buf[FZ_DOT] = self.fz[k], self.fz_dot[k]
        out.mode = Mode.FORCE
        out.index = k
        out.done = k >= len(self.fz) - 1
        self.index = k + 1
        return 1 if out.done else 0


def _step_on_the_twin(preview_s: float, rate_n_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The step through the patient's foot on the realistic twin: the reference and the
    measured force (N) of every play cycle."""
    from rt.components.blocks import SignalTap
    from rt.position_loop import build_protocol_loop, sim_devices
    from rt.twin.environment import patient_foot
    from rt.twin.twin import SimClock, Twin

    program = _Step(rate_n_s)
    clock = SimClock()
    twin = Twin(None, patient_foot(MODEL.kin, 0.63, 0.0, 0.0), clock=clock)
    twin.place(program.q)
    tap = SignalTap("tap", [("force", 3), ("wrench", 6), ("phase", 1)], capacity=6000)
    pl = build_protocol_loop(sim_devices(twin, clock), program, MODEL,
                             force_gains={"preview_s": preview_s}, extra_blocks=[tap],
                             extra_connections=[("reference.force", "tap.force"),
                                                ("force.wrench", "tap.wrench"),
                                                ("reference.phase", "tap.phase")])
    for _ in range(50):
        pl.loop.run(seconds=0.1)
        rows = tap.ring[:tap.written]
        if (rows[:, -1] == Phase.PLAY).any() and rows[-1, -1] != Phase.PLAY:
            break
    pl.graph.stop()
    assert pl.events.first("pulling") is None
    rows = tap.ring[:tap.written]
    play = rows[:, -1] == Phase.PLAY
    return rows[play, 1], -rows[play, 6]


def _crossing(f: np.ndarray, level: float) -> float:
    """When ``f`` first rises through ``level`` (s from the play's start, interpolated)."""
    k = int(np.argmax(f >= level))
    return (k - 1 + (level - f[k - 1]) / (f[k] - f[k - 1])) * DT


def test_the_preview_starts_a_step_beyond_the_robot_earlier_by_its_length():
    """A 20 kN/s step through the 1e5 N/m heel pad asks 0.2 m/s of the platform: the force
    lags the reference by tens of ms. With 5 ms of preview the law starts the push 5 ms
    earlier: the measured force crosses each level 5 ± 1 ms earlier, and the step's RMS error
    falls. A slow step (1 kN/s, within what the law follows) is tracked as before: no preview
    is taken."""
    ref, f0 = _step_on_the_twin(0.0, 20000.0)
    _, f5 = _step_on_the_twin(0.005, 20000.0)
    for level in (100.0, 160.0, 220.0):
        lag0 = _crossing(f0, level) - _crossing(ref, level)
        lag5 = _crossing(f5, level) - _crossing(ref, level)
        assert lag0 > 0.005, lag0
        assert lag0 - lag5 == pytest.approx(0.005, abs=0.001), (level, lag0, lag5)
    window = slice(250, 450)                    # the step and its settling
    rms0 = np.sqrt(np.mean((ref - f0)[window] ** 2))
    rms5 = np.sqrt(np.mean((ref - f5)[window] ** 2))
    assert rms5 < 0.7 * rms0, (rms0, rms5)          # 36.7 → 18.3 N measured
    _, slow0 = _step_on_the_twin(0.0, 1000.0)
    _, slow5 = _step_on_the_twin(0.005, 1000.0)
    np.testing.assert_allclose(slow5, slow0, atol=1e-9)
