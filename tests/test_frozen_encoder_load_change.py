"""No false "encoder frozen" after an unmeasured load change (issue 15), and a frozen encoder
still caught right after one. Twin, fast (simulated-time) mode, deterministic.

* The thesis bench's physical payload step at 100 Hz (``talus bench tracking --profile
  thesis``): 100 kg land on the platform at 13 s; the rising axis 0 is stopped by them at once
  and stays still ~0.1 s while the law's command climbs to the new load. Before the fix the
  force balance, against the carried load learnt unloaded, stopped Paden-Panja 0.11 s after the
  step with ``encoder_frozen_0``.
* 500 kg put on the platform under a 200 N force hold on the strapped foot: the sliders sink at
  the drives' limit (never quasi-static: the carried load is never learnt) and their counts
  pause for a few ms at a time; before the fix ``encoder_frozen_0``/``_1`` at +56 ms.
* The worst case for the carried-load estimate: axis 0's encoder frozen 20 ms after the payload
  lands (its carried load is the unloaded one; its count has just stopped under the new load).
"""
from __future__ import annotations

import pytest

import rt.benchmarks.tracking as T
from rt.model import RobotModel
from rt.model.dynamics import Payload
from rt.position_loop import build_protocol_loop, build_sim_position_loop, sim_devices
from rt.safety.fault_matrix import FORCE_HOLD_Z_M, ForceHold
from rt.twin.environment import PayloadStep, patient_foot
from rt.twin.twin import SimClock, Twin


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


def _faults(pl) -> list:
    return [e for e in pl.events.snapshot() if e.kind == "fault"]


def test_thesis_payload_step_at_100_hz_runs_paden_panja_to_the_end(model) -> None:
    t, err, _ = T.run_one("payload-step", "paden_panja", rate_hz=100.0)
    m = T.metrics(t, err)
    assert len(t) == round(T.DURATION_S * 100.0)
    # Period 2 is the unloaded model's statics: the payload's 327 N per axis over the rule's
    # Kp 41.3 kN/m ≈ 7.9 mm (tests/test_bench_tracking.py's parameter step: 0.85-1.02 of it).
    p2 = m["period2"]["mean_abs_m"]
    assert 6.0e-3 < p2 < 9.0e-3, m
    assert m["period1"]["mean_abs_m"] < 0.5e-3, m


def _bench_loop(model, rate_hz: float):
    twin = Twin(None, environment=PayloadStep(mass_kg=T.PAYLOAD_KG, at_s=1e9,
                                              com_m=T.PAYLOAD_COM_M), seed=0)
    twin.place((T.Q0_M,) * 3)
    pl = build_sim_position_loop("paden_panja", T.rate_gains("paden_panja", rate_hz, model),
                                 T.benchmark_reference(T.Q0_M), T.DURATION_S, rate_hz=rate_hz,
                                 model=model, twin=twin, robot_limits=T.BENCH_LIMITS)
    while pl.reference.phase.data[0] != 1.0:          # the approach to the trajectory
        pl.loop.run(cycles=1)
    return twin, pl


@pytest.mark.parametrize(("rate_hz", "bound_ms"), [(100.0, 300.0), (1000.0, 60.0)])
def test_an_encoder_frozen_right_after_the_payload_step_is_caught(model, rate_hz,
                                                                   bound_ms) -> None:
    """Axis 0 frozen 20 ms after the 100 kg land at the bench's 13 s (its carried load still
    the unloaded one, its count just stopped by the payload): caught by the force balance
    (the bench's limits leave the reference-speed criterion a 1 s window) within
    ``bound_ms`` — measured 190 ms at 100 Hz, 31 ms at 1 kHz (twin figures, the closing
    note's ``latency.py``; the command must leave the band of where it stood at the freeze)."""
    twin, pl = _bench_loop(model, rate_hz)
    pl.loop.run(cycles=round(T.STEP_S * rate_hz))     # the trajectory up to the step
    twin.plant.set_payload(Payload(T.PAYLOAD_KG, T.PAYLOAD_COM_M))
    t_fault = twin.plant.t + 0.02
    twin.faults.schedule("encoder_freeze", t_fault, axis=0)
    pl.loop.run(cycles=round(0.5 * rate_hz))
    faults = _faults(pl)
    assert faults, "the frozen encoder was not caught"
    first = faults[0]
    assert first.cause == "encoder_frozen_0", faults
    assert 0.0 < first.t - t_fault <= bound_ms * 1e-3, (first.t - t_fault, first.values)


def test_500_kg_under_a_force_hold_is_not_read_as_a_frozen_encoder(model) -> None:
    """Under the unmeasured 500 kg the sliders sink ~1.1 mm at the drives' limit (35 ms
    saturated), then the drives carry it (≈ 1.7-1.9 kN of their 2.04 kN per axis), the force
    hold wins the foot's force back (its integral carries the payload; the axes rise back to
    where they stood: tests/test_force_hold_payload.py) and the axes stand still under a load
    ≈ 1.3 kN beyond the carried one, never learnt (never quasi-static while moving). Nothing
    else trips either: the saturation is far from half of the 0.5 s window."""
    clock = SimClock()
    twin = Twin(None, patient_foot(model.kin, FORCE_HOLD_Z_M, 0.0, 0.0), seed=0, clock=clock)
    twin.place(model.kin.ik(FORCE_HOLD_Z_M, 0.0, 0.0).q)
    pl = build_protocol_loop(sim_devices(twin, clock),
                             ForceHold(model.kin, FORCE_HOLD_Z_M, 200.0, 60.0, 1e-3), model)
    pl.loop.run(seconds=3.0)
    assert _faults(pl) == []
    twin.plant.set_payload(Payload(500.0, (0.0, 0.0, 0.10)))
    pl.loop.run(seconds=1.5)
    causes = [e.cause for e in _faults(pl)]
    assert causes == [], causes
    assert max(pl.supervisor.saturated_peak_s) < 0.1
    # The carried load is stale by most of the payload's share (the axes rose back under the
    # load too quickly to learn it: 0.4-0.5 kN carried against ≈ 1.75 kN commanded), and the
    # axes are still once the hold has won the force back: the force balance holds only
    # because a constant load holds their still stretch (the carry's own band is 225 N).
    tau = pl.graph.output("controller.tau")
    stale = [float(tau[i]) - c for i, c in enumerate(pl.supervisor.carry_force_n)]
    assert min(stale) > 4.0 * pl.supervisor.holding_force_n, stale
