"""The RT runner's live samples on the trial file's clock (``calibration.rt_runner``): on the twin
plate the file starts at the first played cycle, and the live samples are placed on it by the
program's progress, not by the arrival of the first telemetry of the play (the publisher's thread
can be late at load: 0.14 s seen in CI, a 288 N disagreement on a 2 kN/s ramp). No RT process:
a scripted subscription hands the messages the RT process would publish."""
from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
import pytest

from calibration.rt_runner import _LiveTelemetry

DT = 1e-3
STEPS = 1000          # the program's samples after the first (``reference.progress`` = k / STEPS)
T_OFFSET = 10.0       # where the runner's file for this trial starts (s)


class _Subscription:
    """What ``RtClient.subscribe`` returns: messages already received, none waited for."""

    def __init__(self) -> None:
        self.queue: deque[dict[str, Any]] = deque()

    def recv(self, timeout_s: float) -> dict[str, Any] | None:
        return self.queue.popleft() if self.queue else None

    def close(self) -> None:
        pass


class _Client:
    def __init__(self, sub: _Subscription) -> None:
        self.sub = sub

    def subscribe(self, topics: list[str]) -> _Subscription:
        assert topics == ["telemetry"]
        return self.sub


class _Runner:
    """The part of ``RtTrialRunner`` the live samples use."""

    def __init__(self, sub: _Subscription) -> None:
        self._t_offset = T_OFFSET
        self.client = _Client(sub)
        self.blocks: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]] = []

    def publish(self, trial_id: str, t: np.ndarray, ref: np.ndarray, fz: np.ndarray) -> None:
        self.blocks.append((trial_id, t, ref, fz))


def _message(t_loop: float, k: int, phase: str = "play") -> dict[str, Any]:
    return {"t": t_loop, "progress": k / STEPS, "phase": phase, "force_n": 5.0 * k,
            "force_ref_n": 2.0 * k}


@pytest.mark.parametrize("late_cycles", [0, 1, 149])
def test_live_samples_start_at_the_first_played_cycle_however_late_the_telemetry(late_cycles):
    """The play begins at loop time 5.000 s (sample 0 played, k = 1). The first telemetry of the
    play arrives ``late_cycles`` later; every sample lands where the file has that cycle:
    T_OFFSET + (its loop time − 5.000 s), to the float's rounding."""
    t_play = 5.0
    ks = [1 + late_cycles + 17 * i for i in range(5)]
    sub = _Subscription()
    runner = _Runner(sub)
    live = _LiveTelemetry(runner, "T1", loop_clock=False, dt=DT, steps=STEPS)
    sub.queue.append(_message(4.99, 0, phase="approach"))     # published before: dropped
    live.started()
    sub.queue.append(_message(4.995, 0, phase="approach"))    # not the play: not in the file
    sub.queue.extend(_message(t_play + (k - 1) * DT, k) for k in ks)
    live.pump(0.0)
    ((trial, t, ref, fz),) = runner.blocks
    assert trial == "T1"
    np.testing.assert_allclose(t, [T_OFFSET + (k - 1) * DT for k in ks], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(ref, [2.0 * k for k in ks])
    np.testing.assert_array_equal(fz, [-5.0 * k for k in ks])


def test_with_the_plates_daq_the_samples_keep_the_loops_clock():
    """With the plate's DAQ the file keeps the loop's clock: the samples' times are the loop's,
    whatever the progress."""
    sub = _Subscription()
    runner = _Runner(sub)
    live = _LiveTelemetry(runner, "T2", loop_clock=True, dt=DT, steps=STEPS)
    live.started()
    sub.queue.extend([_message(7.25, 300, phase="approach"), _message(7.3, 350)])
    live.pump(0.0)
    ((_, t, _, _),) = runner.blocks
    np.testing.assert_array_equal(t, [7.25, 7.3])
