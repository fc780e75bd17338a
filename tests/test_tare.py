"""The ATI's tare before force work: the zero it takes, its refusals, and a force session that
tares on the unloaded platform (or refuses to start its play on a loaded one)."""
from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest

from rt.components.tare import TARE_MAX_LOAD_N, TARE_SAMPLES, Tare, TareRefusal, TareState

#: The Delta's noise (N, N m per axis: twin sensor defaults) on the tool's weight at level.
SIGMA = np.array([0.125, 0.125, 0.25, 0.0075, 0.0075, 0.0075])
TOOL = np.array([0.0, 0.0, -0.4 * 9.81, 0.0, 0.0, 0.0])


def _feed(tare: Tare, reading, n: int, port: np.ndarray, seed: int = 0, requested=True,
          valid: bool = True) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        w = np.asarray(reading, float) + SIGMA * rng.standard_normal(6)
        tare.cycle(w, valid, requested, port)
        out.append(w)
    return out


def test_tare_zeroes_the_tool_weight_within_the_noise_of_its_mean():
    tare, port = Tare(), np.zeros(10)
    _feed(tare, TOOL, 5, port, requested=False)
    assert tare.state == TareState.NONE and port[0] == TareState.NONE
    _feed(tare, TOOL, TARE_SAMPLES, port)              # rising edge: the tare measures
    assert tare.state == TareState.DONE and port[0] == TareState.DONE and port[1] == 1
    # The zero is the mean of 100 readings: within 4 σ/√100 of the tool's weight.
    assert np.all(np.abs(tare.offset - TOOL) <= 4.0 * SIGMA / math.sqrt(TARE_SAMPLES))
    np.testing.assert_array_equal(port[4:], tare.offset)
    assert port[3] == pytest.approx(0.4 * 9.81, abs=0.1)
    # Later readings are zero-mean: a 300 N push reads 300 N, not 296 N.
    later = np.array(_feed(tare, TOOL + [0, 0, -300.0, 0, 0, 0], 200, port, seed=1))
    assert later[:, 2].mean() == pytest.approx(-300.0, abs=0.1)


@pytest.mark.parametrize("reading, code, words", [
    (TOOL + [0, 0, -80.0, 0, 0, 0], TareRefusal.LOADED, "platform loaded"),
    (TOOL + [TARE_MAX_LOAD_N, 0, 0, 0, 0, 0], TareRefusal.LOADED, "platform loaded"),
])
def test_a_loaded_platform_is_not_tared_and_the_zero_is_kept(reading, code, words):
    tare, port = Tare(), np.zeros(10)
    _feed(tare, TOOL, TARE_SAMPLES + 1, port)
    first = tare.offset.copy()
    _feed(tare, TOOL, 3, port, requested=False)
    _feed(tare, reading, TARE_SAMPLES + 1, port)
    assert tare.state == TareState.REFUSED and port[0] == TareState.REFUSED
    assert port[2] == code and words in tare.reason
    np.testing.assert_array_equal(tare.offset, first)   # nothing changed
    assert tare.count == 1 and port[1] == 1


def test_an_unsteady_or_silent_sensor_is_not_tared():
    tare, port = Tare(), np.zeros(10)
    rng = np.random.default_rng(3)
    for k in range(TARE_SAMPLES):                          # someone taps the platform: ±8 N
        tare.cycle(TOOL + [0, 0, 8.0 * math.sin(k / 5.0), 0, 0, 0]
                   + SIGMA * rng.standard_normal(6), True, True, port)
    assert tare.state == TareState.REFUSED and tare.refusal == TareRefusal.UNSTEADY
    assert "not steady" in tare.reason
    tare, port = Tare(), np.zeros(10)
    _feed(tare, TOOL, tare.max_cycles, port, valid=False)
    assert tare.state == TareState.REFUSED and tare.refusal == TareRefusal.NO_READING
    assert not tare.offset.any()


def test_bad_tare_sizes_are_refused():
    with pytest.raises(ValueError, match="samples"):
        Tare(samples=1)
    with pytest.raises(ValueError, match="max_cycles"):
        Tare(samples=100, max_cycles=50)


SINE = """schema_version: 1
kind: sine_fz
name: tare sine
description: tare test
pose: {z_m: 0.63, roll_deg: 0.0, pitch_deg: 0.0}
mean_n: 300.0
amplitude_n: 100.0
frequency_hz: 2.0
cycles: 2
ramp_in_s: 0.5
ramp_out_s: 0.5
"""


def _sine_loop(limb_weight_n: float):
    from protocols.session import SessionSetup, _build, _run, figures_of
    from rt.model import RobotModel
    from rt.twin.environment import CompliantAnkle

    model = RobotModel.load()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sine.yaml"
        path.write_text(SINE)
        protocol, _gen, report, pl, tap = _build(SessionSetup(path), model, "fast")
    env = pl.twin.environment
    if limb_weight_n:
        pl.twin.set_environment(CompliantAnkle(
            neutral_z_m=env.neutral_z_m, neutral_roll_rad=env.neutral_roll_rad,
            neutral_pitch_rad=env.neutral_pitch_rad, limb_weight_n=limb_weight_n))
    _run(pl, tap, report.duration_s, None)
    rows = tap.ring[:tap.written].copy()
    return pl, rows, figures_of(pl, tap, protocol, model).result(pl.events.snapshot())


def test_a_force_session_tares_the_unloaded_platform_before_it_plays():
    from rt.references.sequencer import Phase
    from rt.sessions import COL_FZ, COL_PHASE

    pl, rows, summary = _sine_loop(0.0)
    assert summary["completed"]
    tare = summary["ati_tare"]
    # The twin's ATI carries its tool side (0.4 kg: −3.9 N) and a drifting offset (≤ 4 N):
    # the zero takes what the unloaded sensor read.
    assert tare["state"] == "done" and abs(tare["offset_n"][2]) > 1.0
    assert tare["mean_force_n"] <= TARE_MAX_LOAD_N
    assert pl.reference.tare_refused == 0
    # The tare sits in the approach (which lasts at least the tare's 100 samples), before
    # play: the first play sample reads the unloaded foot as ≈ 0 N (noise σ 0.25 N, drift over
    # a second ≪ 1 N), not the tool's weight.
    assert summary["phase_s"]["approach"] >= TARE_SAMPLES / 1000.0
    first_play = rows[np.flatnonzero(rows[:, COL_PHASE] == Phase.PLAY)[0]]
    assert abs(first_play[COL_FZ]) < 1.0


def test_a_force_session_on_a_loaded_platform_is_refused_before_it_plays():
    pl, _, summary = _sine_loop(80.0)              # the foot rests on the platform: 80 N
    assert not summary["completed"] and "play" not in summary["phase_s"]
    assert summary["ati_tare"]["state"] == "refused"
    assert "platform loaded" in summary["ati_tare"]["reason"]
    assert pl.reference.tare_refused == 1 and "ATI tare refused" in pl.reference.last_error
    assert summary["stops"] == []                 # refused, not a fault
