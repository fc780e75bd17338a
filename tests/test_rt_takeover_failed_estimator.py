"""Taking over a lost owner's robot after the estimator failed (gui3's report: an RT process
kept an owner whose heartbeats had stopped minutes ago, and nobody could take control).

The graph skips a failed component, so the estimator's q̇ stays what it was at the failure,
a speed if the robot moved: "at rest" judged by it would never hold, and without control
nobody could reset either. The RT process now judges rest by the encoders' positions the
recorder tap keeps every cycle (in fast mode, on the twin: the hard stop's brakes hold the
platform)."""
from __future__ import annotations

import numpy as np
import pytest

from rt.errors import InputError
from rt.service import REST_WINDOW_S, RtConfig, RtService, build_rt_loop


class Server:
    """The IPC server's heartbeat ages, set by the test."""

    def __init__(self) -> None:
        self.ages: dict[str, float] = {}

    def last_seen_age_s(self, client: str) -> float:
        return self.ages.get(client, float("inf"))


def moving_robot_whose_estimator_fails():
    pl, tap = build_rt_loop(RtConfig(loop_mode="fast"))
    svc = RtService(pl, RtConfig(loop_mode="fast"), tap)
    svc.server = Server()
    svc.server.ages["first"] = 0.0
    svc.control_acquire("first", "workstation 1")
    svc.run("first", "move", {"z": 0.60, "hold_s": 5.0})   # ≈ 4 cm down from rest
    pl.loop.run(cycles=400)
    qd = np.array(pl.graph.output("estimator.qd"))
    assert np.max(np.abs(qd)) > 0.01                    # moving when it fails
    # The RT process's failure: a loop stall longer than the estimator's dt_max (0.1 s) makes
    # its update refuse the step (ERROR_DT); here the bound shrinks below the period instead.
    pl.graph.component("estimator").state._c[0] = 1e-6
    pl.loop.run(cycles=3)
    assert "estimator" in pl.graph.failed
    assert "component_failed" in pl.supervisor.causes
    return pl, svc


def test_a_lost_owner_is_taken_over_once_the_encoders_show_the_robot_still():
    pl, svc = moving_robot_whose_estimator_fails()
    stale = np.array(pl.graph.output("estimator.qd"))
    svc.server.ages["first"] = 60.0                     # silent for a minute
    # Right after the failure the window is not yet behind it: nothing says "still".
    with pytest.raises(InputError, match="lost while the robot moves"):
        svc.control_acquire("second", "workstation 2")
    pl.loop.run(cycles=int(3 * REST_WINDOW_S * 1000) + 500)    # the brakes hold it
    assert np.array_equal(pl.graph.output("estimator.qd"), stale)    # still stale
    assert np.max(np.abs(stale)) > 0.01
    r = svc.control_acquire("second", "workstation 2")
    assert r["owner"] and r["took_over_from"] == "workstation 1"


def test_moving_encoders_keep_the_refusal_when_the_estimator_failed():
    pl, svc = moving_robot_whose_estimator_fails()
    svc.server.ages["first"] = 60.0
    pl.loop.run(cycles=int(3 * REST_WINDOW_S * 1000) + 500)
    # The encoders say the sliders move (a drifting axis): no take-over.
    rec = pl.recorder
    n = int(REST_WINDOW_S * 1000)
    rows = np.arange(rec.written - n, rec.written) % rec.capacity
    rec.ring[rows, 1] += np.linspace(0.0, 0.002, n)     # 2 mm in 0.1 s: 20 mm/s
    with pytest.raises(InputError, match="lost while the robot moves"):
        svc.control_acquire("second", "workstation 2")
    pl.graph.failed["encoders"] = "test: unreadable"
    with pytest.raises(InputError, match="lost while the robot moves"):
        svc.control_acquire("second", "workstation 2")
