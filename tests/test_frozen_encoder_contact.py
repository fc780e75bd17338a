"""The frozen-encoder check in contact (issue 15): a still axis is judged by its force balance
with the measured contact's share of its command, and the sensor's lag allowed for.

A slider pressing something stalls legitimately while its command (and its reference) say it
should move; a frozen encoder must still be caught there. Compiled and interpreted alike.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.model import RobotModel
from rt.safety.limits import PatientLimits, RobotLimits, effective
from rt.safety.supervisor import (
    CONTACT_RELEASE_S,
    FORCE_LAG_S,
    InterpretedSupervisor,
    Supervisor,
    supervisor_physics,
)

DT = 1e-3
Z3 = (0.0, 0.0, 0.0)
MODEL = RobotModel.load()
PHYS = supervisor_physics(MODEL.description)
LIMITS = effective((0.0, 0.4), RobotLimits(), PatientLimits(max_force_n=1500.0))
SUPERVISORS = [Supervisor, InterpretedSupervisor]


def _frozen(sup: Supervisor) -> bool:
    return any(c.startswith("encoder_frozen") for c in sup.causes)


def test_the_contact_share_is_the_statics_of_the_measured_wrench() -> None:
    """``contact_share`` (compiled, and as Python) = −J_Sᵀ w_S of the robot model, tilted."""
    from rt.safety import supervisor_kernel as sk

    sup = Supervisor(LIMITS, DT, **PHYS)
    q = MODEL.kin.ik(0.64, math.radians(6.0), math.radians(-4.0)).q
    st = MODEL.dyn.state(q)
    wrench = np.array([35.0, -20.0, -600.0, 4.0, -7.5, 1.2])
    expected = MODEL.dyn.actuator_forces_for_wrench(st, wrench)
    np.testing.assert_allclose(sup.contact_share(st.buf, wrench), expected, rtol=1e-12,
                               atol=1e-9)
    py = [0.0, 0.0, 0.0]
    sk.contact_share.py_func(st.buf, wrench, sup._par, py)
    assert py == sup.contact_share(st.buf, wrench).tolist()          # same bits
    # Pressing up (the environment pushes the platform down): every axis lifts more.
    assert np.all(expected > 150.0)
    # No sensor (NaN) takes nothing.
    assert np.all(sup.contact_share(st.buf, np.full(6, math.nan)) == 0.0)


def _press(sup: Supervisor, rate_n_s: float, peak_n: float, lag_s: float, seconds: float,
           freeze_ramp_n_s: float = 0.0, share_known: bool = True,
           qd_ref: float = 0.0) -> float | None:
    """The slider moves (a count per cycle) carrying 300 N until 0.3 s, then meets a stiff
    contact: its count stands while the contact's true share of its command rises at
    ``rate_n_s`` to ``peak_n`` and the command follows it (the force law pushing); the sensor
    shows the share through a first-order filter of time constant ``lag_s / 2`` after a
    ``lag_s / 2`` delay. ``freeze_ramp_n_s``: from 0.5 s the command also runs away (a frozen
    encoder under a controller chasing its reference). Returns the frozen-encoder trip's time
    (None: none)."""
    carry, q, measured = 300.0, 0.2, 0.0
    delay = max(1, round(0.5 * lag_s / DT))
    history = [0.0] * delay
    alpha = DT / (0.5 * lag_s + DT)
    for k in range(int(seconds / DT)):
        t = (k + 1) * DT
        if t < 0.3:
            q += sup.count_m
            true_share = 0.0
        else:
            true_share = min(peak_n, rate_n_s * (t - 0.3))
        history.append(true_share)
        measured += alpha * (history.pop(0) - measured)
        tau = carry + true_share + freeze_ramp_n_s * max(0.0, t - 0.5)
        share = (measured,) * 3 if share_known else None
        sup.check(t, DT, (q,) * 3, 0, Z3, Z3, True, 0.0, 0.0, 0.0, 0.0, (q,) * 3,
                  (qd_ref,) * 3, (tau,) * 3, 1.5 * measured, False, False, False, False,
                  False, contact_share=share)
        if _frozen(sup):
            return t
    return None


@pytest.mark.parametrize("cls", SUPERVISORS)
def test_a_slider_stalling_against_a_contact_at_onset_is_not_a_frozen_encoder(cls) -> None:
    """Impact onset: the share rises at 30 kN/s per axis (a stiff plate met at speed) to 600 N,
    seen 2 ms late: no trip. Without the contact's share (what the check did before: the
    command alone against the carried force) the same onset trips."""
    sup = cls(LIMITS, DT, **PHYS)
    assert _press(sup, 3.0e4, 600.0, 0.002, 1.0) is None
    blind = cls(LIMITS, DT, **PHYS)
    assert _press(blind, 3.0e4, 600.0, 0.002, 1.0, share_known=False) is not None
    # The lag allowance is what lets a faster onset through: at 100 kN/s a 2 ms lag hides
    # 200 N of share, within FORCE_LAG_S's allowance (300 N at that rate).
    assert 0.002 < FORCE_LAG_S
    sup = cls(LIMITS, DT, **PHYS)
    assert _press(sup, 1.0e5, 600.0, 0.002, 1.0) is None


@pytest.mark.parametrize("cls", SUPERVISORS)
def test_a_frozen_encoder_in_contact_is_caught(cls) -> None:
    """Pressing 600 N per axis, the count frozen while the command runs away at 20 kN/s from
    0.5 s: caught within 40 ms (the carried load, followed in contact with CARRY_TAU_S, lags
    the ramp by 400 N: the excess over the 225 N band then moves the axis 4 counts)."""
    sup = cls(LIMITS, DT, **PHYS)
    t = _press(sup, 3.0e4, 600.0, 0.002, 1.0, freeze_ramp_n_s=2.0e4)
    assert t is not None and 0.5 < t < 0.54, t


@pytest.mark.parametrize("cls", SUPERVISORS)
def test_the_reference_speed_criterion_waits_for_the_contact_to_be_released(cls) -> None:
    """A still slider under a moving reference (5 mm/s) while 600 N is measured: no trip for a
    second. Once nothing is measured, it counts again after the release time and trips
    ``frozen_encoder_s`` later."""
    sup = cls(LIMITS, DT, **PHYS)
    q = 0.2
    for k in range(1000):
        t = (k + 1) * DT
        sup.check(t, DT, (q,) * 3, 0, Z3, Z3, True, 0.0, 0.0, 0.0, 0.0, (q,) * 3,
                  (0.005,) * 3, (300.0,) * 3, 600.0, False, False, False, False, False,
                  contact_share=(0.0,) * 3)
    assert not _frozen(sup)
    tripped = None
    for k in range(200):
        t = 1.0 + (k + 1) * DT
        sup.check(t, DT, (q,) * 3, 0, Z3, Z3, True, 0.0, 0.0, 0.0, 0.0, (q,) * 3,
                  (0.005,) * 3, (300.0,) * 3, 0.0, False, False, False, False, False)
        if _frozen(sup):
            tripped = t - 1.0
            break
    wait = CONTACT_RELEASE_S + LIMITS.frozen_encoder_s
    assert tripped is not None and wait - 2 * DT <= tripped <= wait + 2 * DT, tripped
