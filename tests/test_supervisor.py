"""Supervisor behaviour beyond the matrix: latching, resets that re-check the cause, limit
layers, and a clean recovery after a hard stop."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from rt.position_loop import build_sim_position_loop
from rt.safety.limits import PatientLimits, ProtocolLimits, RobotLimits, effective


def test_layers_take_the_most_restrictive():
    lim = effective((0.0, 0.4), RobotLimits(max_platform_force_n=1500.0),
                    PatientLimits(roll_min_deg=-15, roll_max_deg=12, max_force_n=900.0),
                    ProtocolLimits(roll_max_deg=20.0, roll_min_deg=-5.0, max_force_n=600.0))
    assert lim.roll_max == pytest.approx(math.radians(12.0))      # protocol cannot widen
    assert lim.roll_min == pytest.approx(math.radians(-5.0))      # but can narrow
    assert lim.max_force_n == 600.0
    lim = effective((0.0, 0.4), RobotLimits(max_platform_force_n=500.0), PatientLimits())
    assert lim.max_force_n == 500.0                                # robot caps the patient


def test_bad_limits_are_refused():
    with pytest.raises(ValidationError, match="roll_min_deg must be below roll_max_deg"):
        PatientLimits(roll_min_deg=10, roll_max_deg=5)
    with pytest.raises(ValidationError, match="max_force_n"):
        PatientLimits(max_force_n=-1)
    with pytest.raises(ValidationError, match="extra"):
        RobotLimits(max_speed=1.0)


def _mode(pl) -> float:
    return float(pl.graph.output("supervisor.mode")[0])


def test_reset_is_refused_while_the_cause_persists():
    pl = build_sim_position_loop("paden_panja", duration_s=30.0)
    pl.twin.faults.schedule("hand_stop", 2.0, 3.0)       # pressed for one second
    pl.loop.run(seconds=2.5)
    assert _mode(pl) == 2.0
    pl.supervisor.request_reset()
    pl.loop.run(seconds=0.01)
    assert _mode(pl) == 2.0
    refused = [e for e in pl.events.snapshot() if e.kind == "reset_refused"]
    assert refused and "hand_stop" in refused[0].values["causes"]
    pl.loop.run(seconds=0.6)                               # released at 3.0 s
    pl.supervisor.request_reset()
    pl.loop.run(seconds=0.01)
    assert _mode(pl) == 0.0
    assert any(e.kind == "reset" for e in pl.events.snapshot())
    ev = next(e for e in pl.events.snapshot() if e.cause == "hand_stop")
    assert ev.t == pytest.approx(2.001, abs=2e-3) and ev.reaction.name == "SOFT_STOP"


def test_hard_stop_then_reset_resumes_without_a_jump():
    pl = build_sim_position_loop("paden_panja", duration_s=30.0)
    pl.loop.run(seconds=2.0)
    pl.supervisor.request_estop("cli")
    pl.loop.run(seconds=0.3)
    assert _mode(pl) == 3.0
    assert not pl.twin.drives_enabled and np.all(pl.twin.amp_volts == 0.0)
    q_stopped = pl.twin.plant.q.copy()
    pl.supervisor.request_reset()
    pl.loop.run(seconds=0.5)
    assert _mode(pl) == 0.0 and pl.twin.drives_enabled
    # Back on, the robot holds where it stopped (the reference followed it during the stop).
    assert np.abs(pl.twin.plant.q - q_stopped).max() < 0.5e-3
    rows, _ = pl.recorder.drain(0)
    assert np.abs(rows[-1, 1:4] - rows[-1, 7:10]).max() < 1e-4


def test_normal_run_raises_no_event():
    pl = build_sim_position_loop("paden_panja", duration_s=5.0)
    pl.loop.run(seconds=7.0)
    assert pl.events.snapshot() == []


def _frozen_after(sup, tau_of_t, seconds: float, t0: float = 0.0, moving_s: float = 0.2):
    """Feed a count that moves (one count per cycle) for ``moving_s`` and then stands still,
    a still reference and the command ``tau_of_t(t)`` on every axis; time of the first
    frozen-encoder trip (None: none)."""
    dt = sup.period_s
    z3 = (0.0, 0.0, 0.0)
    q = 0.2
    for k in range(int(seconds / dt)):
        t = t0 + (k + 1) * dt
        if t - t0 < moving_s:
            q += sup.count_m
        tau = (tau_of_t(t),) * 3
        sup.check(t, dt, (q, q, q), 0, z3, z3, True, 0.0, 0.0, 0.0, 0.0, (q, q, q), z3, tau,
                  math.nan, False, False, False, False, False)
        if any(c.startswith("encoder_frozen") for c in sup.causes):
            return t
    return None


def test_frozen_encoder_check_is_load_aware():
    """A still axis carrying a heavy payload (a 100 kg platform load: ~330 N more per axis
    than unloaded, far beyond the unloaded holding force) is not a frozen encoder; a command
    that runs away from the force that carried the axis still is, payload or not."""
    from rt.model.description import load_description
    from rt.safety.supervisor import Supervisor, supervisor_physics

    phys = supervisor_physics(load_description())
    band = phys["holding_force_n"]
    lim = effective((0.0, 0.4), RobotLimits(), PatientLimits())
    loaded = 700.0                                        # N per axis under the payload
    sup = Supervisor(lim, 0.001, **phys)
    assert _frozen_after(sup, lambda t: loaded, 1.0) is None
    # Sticking at a reversal: the command swings through the friction band and back.
    sup = Supervisor(lim, 0.001, **phys)
    swing = 0.9 * band
    assert _frozen_after(sup, lambda t: loaded - swing * math.sin(math.pi * max(0.0, t - 0.2)
                                                                  / 0.1) ** 2, 1.0) is None
    # A truly frozen encoder: from 0.3 s the controller ramps the command up at 20 kN/s (the
    # reference runs away from the still count). The axis (≈ 207 kg) must have moved 4 counts
    # once ∫(excess) dt · T / (2 m) ≥ 80 µm: with the excess e = 20 kN/s·s' − band, about
    # 11 ms + band / 20 kN/s after the ramp starts, i.e. ≈ 22 ms.
    for base in (0.0, loaded):
        sup = Supervisor(lim, 0.001, **phys)
        t = _frozen_after(sup, lambda t, b=base: b + 2.0e4 * max(0.0, t - 0.3), 1.0)
        assert t is not None and 0.3 + band / 2.0e4 < t < 0.3 + 0.04, (base, t)
