"""Each supervisor trip the fault matrix does not fire, driven through ``Supervisor.check`` with
the values that must trip it (and the values just inside that must not), plus the pulling
check and the matrix's excursion when forward kinematics fails."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.model import RobotModel
from rt.safety.events import Reaction
from rt.safety.fault_matrix import Scenario, _excursions
from rt.safety.limits import PatientLimits, RobotLimits, effective
from rt.safety.supervisor import Supervisor

LIM = effective((0.0, 0.4), RobotLimits(), PatientLimits())
DT = 1e-3


def _check(sup: Supervisor, t: float = 1.0, **over) -> Reaction:
    """One cycle at a healthy mid-stroke state, with ``over`` replacing some inputs."""
    args = {"q": [0.2, 0.2, 0.2], "est_status": 0, "qd": [0.0] * 3, "qdd": [0.0] * 3, "fk_ok": True,
                "roll": 0.0, "pitch": 0.0, "roll_rate": 0.0, "pitch_rate": 0.0, "q_ref": [0.2, 0.2, 0.2],
                "qd_ref": [0.0] * 3, "tau": [0.0] * 3, "force_n": 0.0, "wrench_stale": False,
                "wrench_saturated": False, "hw_estop": False, "hand_stop": False, "drive_failed": False}
    args.update(over)
    return sup.check(t, DT, **args)


CASES = [
    ("stroke_margin_0", {"q": [0.003, 0.2, 0.2], "q_ref": [0.003, 0.2, 0.2]}, Reaction.SOFT_STOP),
    ("stroke_1", {"q": [0.2, 0.401, 0.2], "q_ref": [0.2, 0.401, 0.2]}, Reaction.HARD_STOP),
    ("fk_failed", {"fk_ok": False}, Reaction.HARD_STOP),
    ("tracking_2", {"q": [0.2, 0.2, 0.2 + 3.1 * LIM.max_tracking_error_m]}, Reaction.HARD_STOP),
    ("tracking_0", {"q": [0.2 + 1.5 * LIM.max_tracking_error_m, 0.2, 0.2]}, Reaction.SOFT_STOP),
    ("rom_roll", {"roll": LIM.roll_max + LIM.rom_tolerance + 0.01}, Reaction.HARD_STOP),
    ("rom_pitch", {"pitch": LIM.pitch_min + 0.001, "pitch_rate": -0.2}, Reaction.SOFT_STOP),
    ("speed_2", {"qd": [0.0, 0.0, 0.25]}, Reaction.SOFT_STOP),
    ("angular_speed_pitch", {"pitch_rate": math.radians(70.0)}, Reaction.SOFT_STOP),
    ("force_limit", {"force_n": LIM.max_force_n * 1.01}, Reaction.HARD_STOP),
    ("force_limit", {"force_n": LIM.max_force_n * 0.95}, Reaction.SOFT_STOP),
    ("drive_channel", {"drive_failed": True}, Reaction.HARD_STOP),
]


@pytest.mark.parametrize("cause,inputs,reaction", CASES,
                         ids=[f"{c[0]}-{c[2].name.lower()}" for c in CASES])
def test_each_trip_fires_with_its_reaction(cause, inputs, reaction):
    sup = Supervisor(LIM, DT)
    assert _check(sup) == Reaction.NONE
    assert _check(sup, **inputs) == reaction
    ev = sup.log.first(cause)
    assert ev is not None and ev.reaction == reaction and ev.t == 1.0


def test_implausible_force_stops_only_under_force_control():
    sup = Supervisor(LIM, DT)
    assert _check(sup, force_n=math.nan) == Reaction.NONE
    sup.force_control = True
    assert _check(sup, force_n=math.nan) == Reaction.SOFT_STOP
    assert sup.log.first("force_implausible") is not None


def test_pulling_on_the_foot_soft_stops_after_max_pull_s():
    """Fz below 0 N in force control: a noise crossing shorter than max_pull_s is tolerated,
    a pull held for it is a soft stop; in position control it is not judged."""
    sup = Supervisor(LIM, DT)
    sup.force_control = True
    n = round(LIM.max_pull_s / DT)
    for k in range(n - 1):
        assert _check(sup, t=k * DT, fz_n=-5.0, force_n=5.0) == Reaction.NONE
    assert _check(sup, t=n * DT, fz_n=2.0, force_n=2.0) == Reaction.NONE   # crossed back
    for k in range(n):
        r = _check(sup, t=(n + 1 + k) * DT, fz_n=-5.0, force_n=5.0)
    assert r == Reaction.SOFT_STOP
    ev = sup.log.first("pulling")
    assert ev is not None and ev.values["fz_n"] == -5.0
    free = Supervisor(LIM, DT)
    for k in range(3 * n):
        assert _check(free, t=k * DT, fz_n=-5.0, force_n=5.0) == Reaction.NONE


def test_excursion_is_unknown_not_zero_when_fk_fails():
    model = RobotModel.load()
    rows = np.zeros((50, 12))
    rows[:, 0] = np.arange(50) * DT
    rows[:, 1:4] = [0.0, 0.4, 0.0]                 # far outside the workspace: FK fails
    rows[:, 10] = 0.0
    ex = _excursions(rows, Scenario("x", lambda pl, t: None), model, 0.0)
    assert ex["rom_deg"] is None and ex["fk_failed_samples"] == 10


@pytest.mark.parametrize("sup_class", ["compiled", "interpreted"])
def test_no_frozen_encoder_is_judged_while_a_hard_stop_holds_the_drives_off(sup_class):
    """In a hard stop the drives are off and the brakes hold: a still count with a moving
    reference (or the law's unapplied force) is expected, not a frozen encoder — judged anyway,
    it latched a cause no reset could clear (the calibration's RT tests under load). The same
    inputs without the hard stop do trip it."""
    from rt.safety.supervisor import InterpretedSupervisor

    cls = Supervisor if sup_class == "compiled" else InterpretedSupervisor
    moving = {"qd_ref": [0.02, 0.02, 0.02], "tau": [600.0, 600.0, 600.0]}
    held = cls(LIM, DT)
    held.request_estop("client")
    for k in range(300):
        _check(held, t=1.0 + k * DT, **moving)
    assert held.reaction == Reaction.HARD_STOP
    assert not any(c.startswith("encoder_frozen") for c in held.causes), held.causes
    free = cls(LIM, DT)
    for k in range(300):
        _check(free, t=1.0 + k * DT, **moving)
    assert any(c.startswith("encoder_frozen") for c in free.causes), free.causes
