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


# ---------------------------------------------------------------- the drives' saturation (1)
#: The force a drive applies at the DAC's command limit (6 V at the nominal robot's N/V).
DRIVE_MAX_N = RobotLimits().max_command_v * MODEL.description.drive.force_per_volt_n


def _stall_saturated(sup: Supervisor, windup_n_s: float, seconds: float,
                     freeze_after_s: float | None = None) -> float | None:
    """The slider moves (a count per cycle) carrying 300 N until 0.3 s, then stalls against a
    stiff contact while the force law's command winds up at ``windup_n_s`` far beyond the
    drive's limit (a pre-flight with the drives limited, a heel strike): the drive applies
    ``DRIVE_MAX_N`` at most and the contact holds what the drive pushes beyond the static
    300 N, measured 2 ms late. ``freeze_after_s``: from then on the slider really moves under
    the applied excess but its count stands (a frozen encoder: the contact gave way). Returns
    the frozen-encoder trip's time (None: none)."""
    carry, q, measured = 300.0, 0.2, 0.0
    history = [0.0, 0.0]
    for k in range(int(seconds / DT)):
        t = (k + 1) * DT
        if t < 0.3:
            q += sup.count_m
            tau = carry
        else:
            tau = carry + windup_n_s * (t - 0.3)
        applied = min(tau, DRIVE_MAX_N)
        held = applied - carry
        if freeze_after_s is not None and t >= freeze_after_s:
            held = 0.0                       # the contact gave way: nothing measured holds it
        history.append(held)
        measured = history.pop(0)
        # (The force the ATI reads stays under the force limit: not this test's business.)
        sup.check(t, DT, (q,) * 3, 0, Z3, Z3, True, 0.0, 0.0, 0.0, 0.0, (q,) * 3, Z3,
                  (tau,) * 3, min(measured, 1000.0), False, False, False, False, False,
                  contact_share=(measured,) * 3)
        if _frozen(sup):
            return t
    return None


@pytest.mark.parametrize("cls", SUPERVISORS)
def test_a_saturated_drive_is_balanced_with_the_force_it_applies(cls) -> None:
    """A command winding up to 20 kN against a contact while the drive gives 2 kN: the contact
    holds what the drive applies, so the balance is judged with the command saturated at the
    DAC's limit (``applied_force_max_n``) — no trip. Judged with the command itself (no
    saturation known), the same stall trips. A frozen encoder under the saturated drive (the
    contact gives way, the count stands) is still caught within 40 ms."""
    sup = cls(LIMITS, DT, **PHYS)
    sup.applied_force_max_n = DRIVE_MAX_N
    assert _stall_saturated(sup, 2.0e4, 1.3) is None
    blind = cls(LIMITS, DT, **PHYS)
    assert blind.applied_force_max_n == math.inf              # direct checks: unsaturated
    assert _stall_saturated(blind, 2.0e4, 1.3) is not None
    sup = cls(LIMITS, DT, **PHYS)
    sup.applied_force_max_n = DRIVE_MAX_N
    t = _stall_saturated(sup, 2.0e4, 1.3, freeze_after_s=1.0)
    assert t is not None and 1.0 < t < 1.04, t


def test_the_supervisor_block_saturates_the_balance_at_the_dac_limit() -> None:
    """The block sets the applied-force limit from the limits' command voltage and the drives'
    N/V, compiled and interpreted alike (the same bits)."""
    from rt.components.safety_blocks import SupervisorBlock
    from rt.model.dynamics import State

    limits = effective((0.0, 0.4), RobotLimits(max_command_v=0.5), PatientLimits())
    fpv = MODEL.description.drive.force_per_volt_n
    got = []
    for cls in SUPERVISORS:
        sup = cls(limits, DT, **PHYS)
        blk = SupervisorBlock("supervisor", sup, fpv)
        for port, n in (("q", 3), ("est_status", 1), ("qd", 3), ("qdd", 3), ("fk_ok", 1),
                        ("q_ref", 3), ("qd_ref", 3), ("tau", 3), ("wrench", 6),
                        ("wrench_flags", 2), ("stops", 2), ("drive_failed", 1)):
            getattr(blk, port).data = np.zeros(n)
        blk.state_in.data = State()
        blk.volts.data, blk.enable.data, blk.mode.data = np.zeros(3), np.ones(1), np.zeros(1)
        blk.update(DT, DT)
        got.append(sup.applied_force_max_n)
    assert got[0] == got[1] == pytest.approx(0.5 * fpv, rel=1e-12)


# ---------------------------------------------------------------- inertia vs carried load (2)
class _Axis:
    """One slider as the supervisor sees it: true motion under the applied force (mass
    ``PHYS['axis_mass_kg']``, a static 60 N load), its quantized count, and the velocity
    estimator's acceleration: the true one through a first-order lag of 8 ms (the Kalman
    estimate reaches a drive-limited step in ~15-20 ms on the twin)."""

    def __init__(self, v0: float) -> None:
        self.m = PHYS["axis_mass_kg"]
        self.x, self.v, self.qdd_est = 0.2, v0, 0.0
        self.static_n = 60.0

    def step(self, applied: float) -> tuple[float, float]:
        a = (applied - self.static_n) / self.m
        v = self.v + a * DT
        if self.v != 0.0 and v * self.v <= 0.0:      # comes to rest (held by friction)
            v, a = 0.0, -self.v / DT
        self.v = v
        self.x += v * DT
        self.qdd_est += (a - self.qdd_est) * DT / (0.008 + DT)
        count = PHYS["count_m"]
        return math.floor(self.x / count) * count, self.qdd_est


def _brake_to_rest(sup: Supervisor, v0: float = 0.2, qdd_known: bool = True,
                   freeze_ramp_n_s: float = 0.0) -> float | None:
    """A slider moving at ``v0`` under its static load for 0.3 s (quasi-static), braked at
    the drive's limit to rest (a soft stop after a pull), then held for 0.5 s. With
    ``freeze_ramp_n_s`` its count freezes 0.1 s after it stops and the command runs away from
    there. ``qdd_known=False`` hides the acceleration estimate from the supervisor (the
    carried load then learns the braking's inertia). Returns the frozen-encoder trip's time."""
    sup.applied_force_max_n = DRIVE_MAX_N
    ax = _Axis(v0)
    stopped_at = None
    q_frozen = None
    for k in range(1000):
        t = (k + 1) * DT
        if t < 0.3:
            tau = ax.static_n
        elif ax.v > 0.0:
            tau = ax.static_n - 3.0 * DRIVE_MAX_N          # the law asks more than it gets
        else:
            stopped_at = stopped_at or t
            tau = ax.static_n
            if freeze_ramp_n_s and t >= stopped_at + 0.1:
                tau += freeze_ramp_n_s * (t - stopped_at - 0.1)
        q, qdd = ax.step(max(-DRIVE_MAX_N, min(DRIVE_MAX_N, tau)))
        if freeze_ramp_n_s and stopped_at is not None and t >= stopped_at + 0.1:
            q_frozen = q if q_frozen is None else q_frozen
            q = q_frozen
        sup.check(t, DT, (q,) * 3, 0, Z3, (qdd if qdd_known else 0.0,) * 3, True, 0.0, 0.0,
                  0.0, 0.0, (q,) * 3, Z3, (tau,) * 3, 0.0, False, False, False, False, False,
                  contact_share=Z3)
        if _frozen(sup):
            return t - (stopped_at or 0.0)
    return None


@pytest.mark.parametrize("cls", SUPERVISORS)
def test_a_braking_at_the_drive_limit_is_not_learnt_as_carried_load(cls) -> None:
    """Braked at the drive's limit (≈ 10 m/s²) to rest from 0.2 m/s (20 ms, the pull's soft
    stop on the twin) and from 0.5 m/s (50 ms): the carried load stays the static one (learnt
    only while quasi-static, the inertia's m·q̈ taken out), so the still slider balances.
    Without the acceleration estimate the braking is learnt as load, bounded only by the
    carry's slew (the friction band per CARRY_TAU_S): the longer braking then trips."""
    for v0 in (0.2, 0.5):
        sup = cls(LIMITS, DT, **PHYS)
        assert _brake_to_rest(sup, v0) is None, v0
        assert abs(sup.carry_force_n[0] - 60.0) < 0.1 * PHYS["holding_force_n"], v0
    blind = cls(LIMITS, DT, **PHYS)
    assert _brake_to_rest(blind, 0.5, qdd_known=False) is not None
    # A frozen encoder after the stop is still caught: the command runs away at 20 kN/s.
    sup = cls(LIMITS, DT, **PHYS)
    t = _brake_to_rest(sup, freeze_ramp_n_s=2.0e4)
    assert t is not None and 0.1 < t < 0.14, t
