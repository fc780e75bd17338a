"""The hybrid controller across force-mode entries (issue 15's leftovers): the contact's
stiffness is remembered from one push to the next, and a soft stop in force control hands over
to the position law's hold at once.

Two 400 N pushes on the twin's calibration plate (2e6 N/m through the tool tip), each its own
program on one loop, as the RT process plays a calibration's pushes. Without memory every
force-mode entry restarts the stiffness estimate k̂ at the gains' guess (1e5 N/m). With it
(``remember_contact``, off by default: see ``HybridController``) the approach still runs the
guess's gains and the remembered k̂ is applied on the contact's first loaded cycle (F past
``rt.control.kernels.CONTACT_LOADED_N``). The twin runs in fast mode (simulated time):
deterministic.
"""
from __future__ import annotations

import numpy as np
import pytest

from calibration.push import (
    ForceTableGenerator,
)
from calibration.twin_runner import plate_above_tool_tip
from rt.control import force as force_mod
from rt.control import kernels as ck
from rt.control.force import ExplicitForce
from rt.model import RobotModel
from rt.position_loop import build_protocol_loop, sim_devices
from rt.references.program import Mode
from rt.safety.events import Reaction
from rt.safety.limits import PatientLimits, RobotLimits
from rt.twin.twin import SimClock, Twin

DT = 1e-3
MODEL = RobotModel.load()
POSE = (0.633, 0.0, 0.0)


def _push_profile(peak_n: float = 400.0) -> np.ndarray:
    """0 → peak in 0.3 s, held 0.3 s, back to 0 in 0.3 s (N per 1 ms sample)."""
    up = np.linspace(0.0, peak_n, 300)
    return np.concatenate([up, np.full(300, peak_n), up[::-1]])


def _plate_loop():
    """A loop with the tool tip 0.5 mm above the twin's plate at ``POSE`` (as
    ``calibration.twin_runner.TwinTrialRunner`` places it), holding until a program comes."""
    q0 = np.array(MODEL.kin.ik(*POSE).q)
    env = plate_above_tool_tip(MODEL, POSE[0])
    clock = SimClock()
    twin = Twin(MODEL.description, env, seed=5, clock=clock)
    twin.place(q0)
    limits = PatientLimits(max_force_n=RobotLimits().max_platform_force_n)
    return build_protocol_loop(sim_devices(twin, clock), None, MODEL, 1.0 / DT, "fast",
                               patient_limits=limits)


def _push() -> ForceTableGenerator:
    gen = ForceTableGenerator("push", _push_profile(), POSE, DT, MODEL.kin)
    assert gen.validate().ok
    return gen


def _play(pl, seconds: float = 6.0) -> None:
    """Play one push to its end (back at rest), in 0.5 s slices."""
    epoch = pl.reference.epoch
    pl.reference.request(_push())
    t = 0.0
    while t < seconds:
        pl.loop.run(seconds=0.5)
        t += 0.5
        assert pl.supervisor.reaction < Reaction.SOFT_STOP, pl.events.snapshot()
        if pl.reference.epoch > epoch and not pl.reference.busy:
            return
    raise AssertionError("the push did not end")


@pytest.fixture
def entries(monkeypatch: pytest.MonkeyPatch) -> list[list[tuple[float, float]]]:
    """Per force-mode entry, (k̂ the law uses, measured F) at each of its cycles (N/m, N)."""
    seen: list[list[tuple[float, float]]] = []
    reset, update = ExplicitForce.reset, ExplicitForce.update

    def resetting(self, stiffness_n_per_m=None):
        reset(self, stiffness_n_per_m)
        seen.append([])

    def updating(self, st, force_n, ref, dt, out):
        seen[-1].append((self.k_est, force_n))
        return update(self, st, force_n, ref, dt, out)

    monkeypatch.setattr(force_mod.ExplicitForce, "reset", resetting)
    monkeypatch.setattr(force_mod.ExplicitForce, "update", updating)
    return seen


def _first_loaded(cycles: list[tuple[float, float]]) -> int:
    return next(i for i, (_, f) in enumerate(cycles) if f > ck.CONTACT_LOADED_N)


def test_the_second_push_is_scheduled_from_its_first_loaded_cycle(entries) -> None:
    """Push 1 starts from the guess and learns the plate (k̂ ≥ 1e6 N/m, near its clamp of 20×
    the guess); push 2 closes its gap on the guess's gains (k̂ = the guess on every cycle
    before the contact is loaded, so the approach is push 1's) and applies push 1's estimate
    on its first loaded cycle (F > ``CONTACT_LOADED_N``): the gain schedule s = k_s / k̂ < 1
    from there; after ``forget_contact`` (a new session) push 3 learns from the guess again."""
    pl = _plate_loop()
    try:
        ctl = pl.graph.component("controller")
        ctl.remember_contact = True
        law = ctl.force_law
        guess = law.gains.stiffness_guess_n_per_m
        k_s = law.gains.schedule_stiffness_n_per_m
        _play(pl)
        loaded = [c for c in entries if c and max(f for _, f in c) > 100.0]
        assert len(loaded) == 1 and loaded[0][0][0] == guess
        learnt = ctl._k_contact
        assert learnt >= 1e6
        n = len(entries)
        _play(pl)
        push2 = next(c for c in entries[n:] if c and max(f for _, f in c) > 100.0)
        i = _first_loaded(push2)
        assert i > 5                      # a gap closed first, on the guess's gains
        assert all(k == guess for k, _ in push2[:i])
        assert push2[i][0] == learnt
        assert ck.gain_schedule.py_func(k_s, push2[i][0]) < 0.25
        ctl.forget_contact()
        n = len(entries)
        _play(pl)
        push3 = next(c for c in entries[n:] if c and max(f for _, f in c) > 100.0)
        assert push3[_first_loaded(push3)][0] == guess
    finally:
        pl.graph.stop()


def test_a_soft_stop_in_force_control_holds_position_at_once() -> None:
    """A soft stop (the operator's hand switch) while pressing 400 N on the plate: the next
    cycle the sequencer is in position mode, its reference where the robot is and still, so
    the position law holds there; the force law is not run on through a ramp (before: the
    force ramped down over ``force_ramp_s``, ≈ 0.3-1 s, through the same force law). The
    platform then stays within 0.5 mm of where it was stopped."""
    pl = _plate_loop()
    try:
        pl.reference.request(_push())
        ref = pl.reference
        for _ in range(40):                      # approach, tare, into the hold at 400 N
            pl.loop.run(seconds=0.1)
            if ref.ctrl_mode.data[0] > 0.5 and ref.force.data[0] >= 399.0:
                break
        assert ref.ctrl_mode.data[0] > 0.5
        pl.loop.run(seconds=0.1)
        q_stop = pl.graph.output("encoders.q").copy()
        pl.twin.faults.schedule("hand_stop", float(pl.loop.t))
        modes = []
        for _ in range(5):
            pl.loop.run(seconds=0.001)
            modes.append(float(ref.ctrl_mode.data[0]))
        assert pl.supervisor.reaction == Reaction.SOFT_STOP
        # Within a few cycles of the stop (the supervisor's mode reaches the sequencer one
        # cycle late): position mode, the reference still.
        assert modes[-1] == float(Mode.POSITION)
        assert np.all(ref.qd_ref.data == 0.0) and ref.force.data[0] == 0.0
        pl.loop.run(seconds=1.0)
        assert np.max(np.abs(pl.graph.output("encoders.q") - q_stop)) < 0.5e-3
    finally:
        pl.graph.stop()
