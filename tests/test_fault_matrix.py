"""The fault matrix as a test: every fault injected on the twin, every target of issue 5."""
from __future__ import annotations

import pytest

from rt.model import RobotModel
from rt.safety.fault_matrix import run_scenario, scenarios
from rt.safety.limits import RobotLimits

MODEL = RobotModel.load()
SCENARIOS = {sc.name: sc for sc in scenarios(MODEL)}
EXPECTED = {
    "encoder_freeze": "hard_stop", "encoder_freeze_contact": "hard_stop",
    "encoder_jump": "hard_stop", "encoder_noise": "hard_stop",
    "dac_dead": "failover", "dac_stuck": "failover", "ati_dropout": "warn", "ati_stale": "warn",
    "ati_saturation": "soft_stop", "latency": "hard_stop", "hardware_estop": "hard_stop",
    "hand_stop": "soft_stop", "gui_estop": "hard_stop", "client_loss": "soft_stop",
    "rom_limit_at_speed": "soft_stop", "force_overload": "soft_stop",
    "latency_force": "soft_stop", "payload_pull": "soft_stop",
    "pull_beyond_drives": "hard_stop", "contact_removed": "soft_stop",
}


def test_matrix_covers_every_twin_fault_kind():
    from rt.twin.faults import KINDS

    covered = {"encoder_freeze", "encoder_jump", "encoder_noise", "dac_dead", "dac_stuck",
               "ati_dropout", "ati_stale", "ati_saturation", "latency", "hardware_estop",
               "hand_stop", "contact_removed"}
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
        # An unstable force loop (issue 15): soft-stopped at once (the stale stream), and the
        # soft stop in force control hands over to the position law's hold at once, which
        # needs neither the lagging sensor nor the contact: at rest within a few ms (twin
        # figures, fast mode: soft stop 1 ms after the fault, at rest 6 ms after it). Before,
        # the soft stop ramped the force down through the same unstable law and only the
        # sustained-saturation check's hard stop (523 ms) ended it, at rest after 546 ms.
        assert r["cause"] == "force_stale", r
        assert r["latency_ms"] is not None and r["latency_ms"] <= 20.0, r
        assert r["time_to_rest_ms"] is not None and r["time_to_rest_ms"] <= 50.0, r
    if name == "payload_pull":
        # A pull through the soft stop's hold (issue 15): 565 kg land under the force hold,
        # the foot is pulled and the supervisor soft-stops on ``pulling``; the stop's hold
        # then yields upward while the foot is pulled, so the pull ends within the yield's
        # stated bound (its distance over its speed: 20 mm at 20 mm/s, 1 s; twin figures,
        # fast mode: ended 0.26 s after the stop, peak −286 N) and the platform comes to
        # rest. Before, the hold kept pulling with ≈ −507 N for as long as it ran.
        limits = RobotLimits()
        bound_ms = 1e3 * limits.pull_yield_max_m / limits.pull_yield_speed_m_s
        assert r["cause"] == "pulling", r
        assert r["pull_end_ms"] is not None and r["pull_end_ms"] <= bound_ms, r
        assert -450.0 < r["pull_peak_n"] < -100.0, r
    if name == "payload_pull":
        assert r["alarm_ms"] is None, r          # the hold ended the pull: no alarm
    if name == "pull_beyond_drives":
        # 700 kg (issue 15): ``pulling`` soft stop, ``force_limit`` hard stop, the brakes
        # hold the foot pulled by ≈ 1.7 kN (twin: soft 54 ms, hard 139 ms after the landing,
        # −1748 N peak). The robot cannot end it: the ``pull_in_stop`` alarm, PULL_IN_STOP_S
        # after the first stop (+ the cycle that latches it), so within that bound after the
        # hard stop; no escalation. The issue-5 targets are the load's to miss (F% is the
        # brakes' hold, the outputs drop at the hard stop, not at the landing): not applied.
        from rt.safety.supervisor_kernel import PULL_IN_STOP_S
        bound_ms = PULL_IN_STOP_S * 1e3
        assert r["cause"] == "force_limit" and r["pull_end_ms"] is None, r
        assert bound_ms <= r["alarm_ms"] <= bound_ms + 2.0, r
        assert 0.0 < r["alarm_after_hard_ms"] <= bound_ms, r
        assert r["pull_peak_n"] < -1500.0 and r["final_state"] == "hard_stop", r
        assert r["zero_output_after_hard_ms"] is not None and \
            r["zero_output_after_hard_ms"] <= 20.0, r
        return
    if name == "contact_removed":
        # The foot goes away under the 200 N hold (issue 15): ``contact_lost`` soft stop
        # before the slider-speed check's (twin: stop 17 ms after the removal, the sliders
        # 2.3 mm above where they stood, the foot's 2 mm heel pad released included).
        assert r["cause"] == "contact_lost" and r["stop_ms"] <= 20.0, r
        assert 1.0 < r["rise_mm"] < 3.0, r
    if r["reaction"] == "hard_stop":
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
