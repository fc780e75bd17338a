"""Supervisor trips the fault matrix does not fire, each injected on the twin with the full
position loop and judged on the outcome: the cause and reaction logged, the drives off within
20 ms for hard stops, the robot at rest inside its limits for soft stops."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.control.base import Reference
from rt.model import RobotModel
from rt.position_loop import build_sim_position_loop
from rt.safety.events import Reaction
from rt.safety.limits import PatientLimits, RobotLimits
from rt.twin.environment import ForcePlateContact

MODEL = RobotModel.load()
KIN = MODEL.kin
Z0 = 0.633


def heave(speed_m_s: float, top_q: float, start_s: float = 0.5, ramp_s: float = 0.2):
    """All sliders from 0.2 m at ``speed_m_s`` (reached over ``ramp_s``) to ``top_q``; a
    negative speed moves them down, to ``top_q`` from above."""
    def ref(t: float, out: Reference) -> None:
        s = t - start_s
        if s <= 0.0:
            q, v = 0.2, 0.0
        elif s < ramp_s:
            q, v = 0.2 + 0.5 * speed_m_s / ramp_s * s * s, speed_m_s * s / ramp_s
        else:
            q, v = 0.2 + speed_m_s * (s - 0.5 * ramp_s), speed_m_s
        if (speed_m_s > 0.0 and q >= top_q) or (speed_m_s < 0.0 and q <= top_q):
            q, v = top_q, 0.0
        out.q[:] = q
        out.qd[:] = v
        out.qdd[:] = 0.0
    return ref


def tilt(axis: str, speed_deg_s: float, target_deg: float, ramp_s: float = 0.25):
    """Roll or pitch from 0 towards ``target_deg`` at ``speed_deg_s`` from t = 0.5 s."""
    w = math.radians(speed_deg_s)

    def angle_at(t: float) -> tuple[float, float]:
        s = t - 0.5
        if s <= 0.0:
            return 0.0, 0.0
        a, r = (0.5 * w / ramp_s * s * s, w * s / ramp_s) if s < ramp_s else \
            (0.5 * w * ramp_s + w * (s - ramp_s), w)
        return (a, r) if a < math.radians(target_deg) else (math.radians(target_deg), 0.0)

    def ref(t: float, out: Reference) -> None:
        a, r = angle_at(t)
        roll, pitch = (a, 0.0) if axis == "roll" else (0.0, a)
        droll, dpitch = (r, 0.0) if axis == "roll" else (0.0, r)
        cfg = KIN.ik(Z0, roll, pitch, check=False)
        ahead = KIN.ik(Z0, roll + droll * 1e-4, pitch + dpitch * 1e-4, check=False)
        for i in range(3):
            out.q[i] = cfg.q[i]
            out.qd[i] = (ahead.q[i] - cfg.q[i]) / 1e-4
            out.qdd[i] = 0.0
    return ref


def step(at_s: float, axis: int, size_m: float):
    """Hold 0.2 m, then the reference of one slider jumps by ``size_m``: a broken reference."""
    def ref(t: float, out: Reference) -> None:
        out.q[:] = 0.2
        if t >= at_s:
            out.q[axis] += size_m
        out.qd[:] = 0.0
        out.qdd[:] = 0.0
    return ref


def run(seconds: float, **kw):
    pl = build_sim_position_loop("paden_panja", duration_s=60.0, model=MODEL, **kw)
    return pl


def first_stop(pl):
    stops = [e for e in pl.events.snapshot() if e.reaction in (Reaction.SOFT_STOP,
                                                               Reaction.HARD_STOP)]
    assert stops, [(e.cause, e.reaction) for e in pl.events.snapshot()]
    return stops[0]


def mode(pl) -> float:
    return float(pl.graph.output("supervisor.mode")[0])


def assert_hard_stop_within_20_ms(pl, t_event: float) -> None:
    """Drives off and amplifiers at 0 V at the end, and the stop came ≤ 20 ms after the
    event (the supervisor's own timestamp)."""
    assert mode(pl) == 3.0 and not pl.twin.drives_enabled
    assert np.all(pl.twin.amp_volts == 0.0)
    rows, _ = pl.recorder.drain(0)
    after = rows[rows[:, 0] >= t_event]
    zero = after[np.all(after[:, 13:16] == 0.0, axis=1)]
    assert len(zero) and zero[0, 0] - t_event <= 0.020


def assert_soft_stop_at_rest(pl) -> None:
    assert mode(pl) == 2.0 and pl.twin.drives_enabled
    assert np.abs(pl.twin.plant.qd).max() < 1e-3


def test_stroke_margin_soft_stops_before_the_end():
    """At 20 mm/s the soft stop (0.5 m/s², 5 m/s³) brakes within ≈ 1.4 mm, inside the 5 mm
    margin. (At 50 mm/s it needs ≈ 5 mm and reaches the end: the margin is not speed-aware.)"""
    pl = run(0, trajectory=heave(-0.02, 0.001))
    pl.loop.run(seconds=12.0)
    ev = first_stop(pl)
    assert ev.cause.startswith("stroke_margin_") and ev.reaction == Reaction.SOFT_STOP
    assert ev.values["q"] < RobotLimits().stroke_margin_m
    assert_soft_stop_at_rest(pl)
    assert pl.twin.plant.q.min() > MODEL.description.limits.stroke_m[0]


def test_beyond_the_stroke_hard_stops():
    pl = run(0, trajectory=heave(-0.05, -0.01), robot_limits=RobotLimits(stroke_margin_m=0.0))
    pl.loop.run(seconds=6.0)
    ev = pl.events.first("stroke_")
    assert ev is not None and ev.reaction == Reaction.HARD_STOP
    assert ev.values["q"] < MODEL.description.limits.stroke_m[0]
    # Beyond the stroke FK refuses the pose too, in the same cycle.
    assert first_stop(pl).t == ev.t
    assert_hard_stop_within_20_ms(pl, ev.t)


def test_fk_failure_hard_stops():
    """One encoder reads 0.2 m more than the truth: no platform pose fits the three readings."""
    pl = run(0)
    pl.twin.faults.schedule("encoder_jump", 2.0, axis=0, counts=10_000)
    pl.loop.run(seconds=2.5)
    fk = pl.events.first("fk_failed")
    assert fk is not None and fk.reaction == Reaction.HARD_STOP
    assert fk.t == pytest.approx(2.0, abs=3e-3)
    assert_hard_stop_within_20_ms(pl, fk.t)


def test_tracking_error_beyond_three_times_the_limit_hard_stops():
    size = 4.0 * RobotLimits().max_tracking_error_m
    pl = run(0, trajectory=step(1.0, 1, size))
    pl.loop.run(seconds=1.5)
    ev = first_stop(pl)
    assert ev.cause == "tracking_1" and ev.reaction == Reaction.HARD_STOP
    assert ev.values["error"] > 3.0 * RobotLimits().max_tracking_error_m
    assert_hard_stop_within_20_ms(pl, ev.t)


def test_patient_rom_soft_stops_inside_the_range():
    patient = PatientLimits(pitch_min_deg=-4.0, pitch_max_deg=4.0)
    pl = run(0, trajectory=tilt("pitch", 5.0, 10.0), patient_limits=patient)
    pl.loop.run(seconds=4.0)
    ev = first_stop(pl)
    assert ev.cause == "rom_pitch" and ev.reaction == Reaction.SOFT_STOP
    assert_soft_stop_at_rest(pl)
    pitch = math.degrees(KIN.fk(pl.twin.plant.q, check=False).pitch)
    assert 3.0 < pitch <= 4.0 + patient.rom_tolerance_deg


def test_slider_speed_soft_stops():
    pl = run(0, trajectory=heave(0.25, 0.35))
    pl.loop.run(seconds=2.0)
    ev = first_stop(pl)
    assert ev.cause.startswith("speed_") and ev.reaction == Reaction.SOFT_STOP
    assert abs(ev.values["qd"]) > RobotLimits().max_slider_speed_m_s
    assert_soft_stop_at_rest(pl)


def test_angular_speed_soft_stops():
    patient = PatientLimits(max_angular_speed_deg_s=10.0)
    pl = run(0, trajectory=tilt("roll", 20.0, 15.0), patient_limits=patient)
    pl.loop.run(seconds=3.0)
    ev = first_stop(pl)
    assert ev.cause == "angular_speed_roll" and ev.reaction == Reaction.SOFT_STOP
    assert abs(ev.values["rate_deg_s"]) > 10.0
    assert_soft_stop_at_rest(pl)


def test_force_beyond_the_limit_on_a_stiff_plate_hard_stops():
    """Rising into a rigid plate at 20 mm/s, the force passes the 90 % cushion and the limit
    within a few ms: only dropping the drive force is fast enough."""
    patient = PatientLimits(max_force_n=400.0)
    pl = run(0, trajectory=heave(0.02, 0.3), patient_limits=patient,
             environment=ForcePlateContact(plate_height_m=0.74))
    pl.loop.run(seconds=5.0)
    hard = [e for e in pl.events.snapshot() if e.cause == "force_limit"
            and e.reaction == Reaction.HARD_STOP]
    assert hard and hard[0].values["force_n"] > 400.0
    assert_hard_stop_within_20_ms(pl, hard[0].t)


def test_both_dac_cards_failing_on_a_channel_hard_stops():
    pl = run(0)
    pl.twin.faults.schedule("dac_dead", 2.0, card=0, channel=1)
    pl.twin.faults.schedule("dac_dead", 2.0, card=1, channel=1)
    pl.loop.run(seconds=3.0)
    kinds = [(e.kind, e.cause) for e in pl.events.snapshot()]
    assert ("failover", "dac_card_0") in kinds
    ev = pl.events.first("drive_channel")
    assert ev is not None and ev.reaction == Reaction.HARD_STOP
    assert_hard_stop_within_20_ms(pl, ev.t)


def test_a_failed_block_hard_stops_and_restarts_on_reset_once_its_device_works():
    """An encoder card whose read fails puts the loop's encoder block in error: its port keeps
    a stale position, so the supervisor hard-stops naming the block (drives off ≤ 20 ms). A
    reset restarts the block: refused while the card still fails, accepted once it reads."""
    from rt.errors import HardwareError

    hold = step(at_s=1e9, axis=0, size_m=0.0)
    pl = run(0.0, trajectory=hold)
    pl.loop.run(seconds=0.3)
    bank = pl.graph.component("encoders").encoders
    works = bank.read_positions_m

    def broken(out):
        raise HardwareError("PCL-833 read timed out")

    bank.read_positions_m = broken
    pl.loop.run(seconds=0.1)
    ev = first_stop(pl)
    assert ev.cause == "component_failed" and ev.reaction == Reaction.HARD_STOP
    assert "encoders" in ev.message and "PCL-833 read timed out" in ev.message
    assert_hard_stop_within_20_ms(pl, ev.t)

    def reset_outcome(also=("estimator",)):
        refused = pl.graph.restart_failed(also)       # what the RT process does on a reset
        ticket = pl.supervisor.request_reset(None)
        pl.loop.run(seconds=0.01)
        assert ticket.done
        return refused, ticket

    refused, ticket = reset_outcome()                 # the card still fails: in error again
    assert refused == {} and [r["cause"] for r in ticket.refused] == ["component_failed"]
    assert "encoders" in pl.graph.failed
    bank.read_positions_m = works
    pl.twin.place(pl.twin.plant.q + 0.002)           # it moved meanwhile (brakes slipping)
    refused, ticket = reset_outcome()
    assert refused == {} and ticket.refused == [] and pl.graph.failed == {}
    assert [c["cause"] for c in ticket.cleared] == ["component_failed"]
    pl.loop.run(seconds=0.05)
    assert pl.graph.component("encoders").lifecycle.value == "active"
    # The realistic twin's encoders sit on the motor side of a compliant screw: tens of µm.
    np.testing.assert_allclose(pl.graph.output("encoders.q"), pl.twin.plant.q, atol=5e-5)


@pytest.mark.parametrize("restart_estimator", [True, False])
def test_encoders_failing_from_the_first_cycle_recover_only_with_the_estimator(
        restart_estimator):
    """The RT process's start on a loaded machine: the encoder block fails before its first
    reading, its port still 0 m (every slider in its stroke-end margin). Restarting the
    encoders alone leaves the estimator judging the first true reading against 0 m — an
    encoder jump that never clears; restarting the estimator with them clears everything."""
    from rt.errors import HardwareError

    hold = step(at_s=1e9, axis=0, size_m=0.0)
    pl = run(0.0, trajectory=hold)
    bank = pl.graph.component("encoders").encoders
    works = bank.read_positions_m

    def broken(out):
        raise HardwareError("rig not published for 80 ms")

    bank.read_positions_m = broken
    pl.loop.run(seconds=0.05)
    causes = {e["cause"] for e in pl.supervisor.latched()}
    assert {"component_failed", "stroke_margin_0"} <= causes, causes
    bank.read_positions_m = works
    pl.graph.restart_failed(("estimator",) if restart_estimator else ())
    ticket = pl.supervisor.request_reset(None)
    pl.loop.run(seconds=0.05)
    assert ticket.done
    if restart_estimator:
        assert ticket.refused == [] and pl.supervisor.latched() == []
    else:
        still = {e["cause"] for e in pl.supervisor.latched()}
        assert "encoder_jump" in still, still
