"""The fault matrix as a test: every fault injected on the twin, every target of issue 5."""
from __future__ import annotations

import pytest

from rt.model import RobotModel
from rt.safety.fault_matrix import run_scenario, scenarios

MODEL = RobotModel.load()
SCENARIOS = {sc.name: sc for sc in scenarios(MODEL)}
EXPECTED = {
    "encoder_freeze": "hard_stop", "encoder_freeze_contact": "hard_stop",
    "encoder_jump": "hard_stop", "encoder_noise": "hard_stop",
    "dac_dead": "failover", "dac_stuck": "failover", "ati_dropout": "warn", "ati_stale": "warn",
    "ati_saturation": "soft_stop", "latency": "hard_stop", "hardware_estop": "hard_stop",
    "hand_stop": "soft_stop", "gui_estop": "hard_stop", "client_loss": "soft_stop",
    "rom_limit_at_speed": "soft_stop", "force_overload": "soft_stop",
    "latency_force": "hard_stop",
}


def test_matrix_covers_every_twin_fault_kind():
    from rt.twin.faults import KINDS

    covered = {"encoder_freeze", "encoder_jump", "encoder_noise", "dac_dead", "dac_stuck",
               "ati_dropout", "ati_stale", "ati_saturation", "latency", "hardware_estop",
               "hand_stop"}
    assert set(KINDS) <= covered <= set(SCENARIOS)
    assert set(EXPECTED) == set(SCENARIOS)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_fault_is_caught_within_its_targets(name):
    r = run_scenario(SCENARIOS[name], MODEL)
    assert r["detected"], r
    assert r["reaction"] == EXPECTED[name], r
    if name.startswith("encoder_freeze"):
        # The frozen encoder itself, free or with the foot on (and nothing tripped before it).
        assert r["cause"] == "encoder_frozen_0", r
    if name == "latency_force":
        # An unstable force loop (issue 15): soft-stopped at once (the stale stream), but a soft
        # stop ramps the force down through the same law, which goes on saturating the drives
        # both ways; the sustained-saturation check hard-stops it once a whole window (0.5 s)
        # into that soft stop more than half of it was saturated — within two windows of the
        # fault — and the outputs are zero within 20 ms of that hard stop. Twin figures (fast
        # mode, deterministic): soft stop 1 ms after the fault, hard stop 523 ms, zero output
        # 1 ms after it, at rest 546 ms after the fault.
        assert r["cause"].startswith("drive_saturated_"), r
        assert r["latency_ms"] is not None and r["latency_ms"] <= 20.0, r
        assert 0.0 < r["hard_stop_at_s"] - 3.0 <= 2 * 0.5 + 0.05, r
        assert r["zero_output_after_hard_ms"] is not None
        assert r["zero_output_after_hard_ms"] <= 20.0, r
    elif r["reaction"] == "hard_stop":
        # Hard stop: zero drive output within 20 ms of the fault (issue 5).
        assert r["time_to_zero_output_ms"] is not None and r["time_to_zero_output_ms"] <= 20.0
    if r["reaction"] == "soft_stop":
        assert r["time_to_rest_ms"] is not None and r["time_to_rest_ms"] <= 500.0
        assert r["final_state"] == "soft_stop"
    if r["reaction"] == "failover":
        assert r["final_state"] == "running_on_backup"
    # No patient ROM exceeded by more than 1°, no force limit by more than 5 %, stroke kept.
    assert r["excursion"]["rom_deg"] is not None and r["excursion"]["rom_deg"] <= 1.0
    assert r["excursion"]["force_pct"] <= 5.0
    assert r["excursion"]["stroke_mm"] == 0.0
