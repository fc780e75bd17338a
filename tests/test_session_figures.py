"""One SessionFigures for the session summary (fed session-tap rows) and the session report (fed
recorded blocks): the same rows give the same figures whichever way they arrive and however they
are split into blocks; the vectorized in-contact state machine equals its per-sample
definition; what a recording lacks (drive commands, wrench, tare) is left out, not invented."""
from __future__ import annotations

import math

import numpy as np
import pytest

from protocols.session_figures import SampleBlock, SessionFigures
from rt.references.sequencer import Phase
from rt.safety.events import Reaction, SafetyEvent
from rt.sessions import COL_CTRL_MODE, COL_FREF, COL_FZ, COL_PHASE, COLUMNS, SESSION_SIGNALS


class _Kin:
    """Forward kinematics stand-in: roll and pitch proportional to the sliders' differences."""

    def fk_roll_pitch(self, qs):
        qs = np.asarray(qs, dtype=float).reshape(-1, 3)
        return qs[:, 0] - qs[:, 1], qs[:, 2] - qs[:, 0], np.ones(len(qs), dtype=bool)


def _rows(n: int, seed: int) -> np.ndarray:
    """Session-tap rows of a force session: approach, play in force control with stretches of
    position control, rest; a force around a 100 N preload that dips below it and has gaps."""
    rng = np.random.default_rng(seed)
    width = 1 + sum(w for _name, w in SESSION_SIGNALS)
    rows = np.zeros((n, width))
    rows[:, 0] = np.arange(n) * 1e-3
    phase = np.full(n, float(Phase.PLAY))
    phase[: n // 10] = Phase.APPROACH
    phase[-n // 10:] = Phase.REST
    rows[:, COL_PHASE] = phase
    mode = (np.sin(np.arange(n) / 137.0) > -0.6).astype(float)
    rows[:, COL_CTRL_MODE] = mode
    force = 100.0 + 60.0 * np.sin(np.arange(n) / 53.0) + rng.normal(0, 5, n)
    force[rng.random(n) < 0.01] = np.nan
    rows[:, COL_FZ] = -force
    rows[:, COL_FREF] = 110.0 + 50.0 * np.sin(np.arange(n) / 53.0)
    rows[:, COLUMNS["q"]] = 0.2 + 0.01 * rng.standard_normal((n, 3))
    rows[:, COLUMNS["qd"]] = 0.01 * rng.standard_normal((n, 3))
    rows[:, COLUMNS["tau"]] = 300.0 * rng.standard_normal((n, 3))
    rows[:, COLUMNS["volts"]] = np.clip(3.0 * rng.standard_normal((n, 3)), -10, 10)
    rows[:, COLUMNS["wrench"].start:COL_FZ] = rng.normal(0, 2, (n, 2))
    rows[:, COL_FZ + 1:COLUMNS["wrench"].stop] = rng.normal(0, 1, (n, 3))
    return rows


def _contact_reference(t, force, force_mode, preload):
    """The in-contact definition, one sample at a time (the summary's former loop)."""
    on, lo_f, lo_t = False, math.inf, math.nan
    for k in range(len(t)):
        f = force[k]
        on = bool(force_mode[k]) and (on or f >= preload)
        if on and f < lo_f:
            lo_f, lo_t = float(f), float(t[k])
    return lo_f, lo_t


def _figures(**kw) -> SessionFigures:
    return SessionFigures(_Kin(), "sine_fz", amplitude_n=50.0, preload_n=100.0, **kw)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_tap_rows_and_blocks_give_the_same_figures_however_split(seed):
    rows = _rows(6000, seed)
    events = [SafetyEvent(t=4.2, kind="fault", cause="force_max", reaction=Reaction.SOFT_STOP,
                          message="force above the limit"),
              SafetyEvent(t=4.3, kind="warn", cause="x", reaction=Reaction.SOFT_STOP,
                          message="a warning is not a stop")]
    whole = _figures()
    whole.add(SampleBlock.from_tap_rows(rows))
    split = _figures()
    cuts = np.sort(np.random.default_rng(seed).choice(np.arange(1, len(rows)), 9, replace=False))
    for part in np.split(rows, cuts):
        split.add(part)                                      # tap rows as the RT process feeds
    a = whole.result(events)
    b = split.result([e.as_dict() for e in events])          # as a recording holds them
    assert a.keys() == b.keys()
    for key in a:
        if isinstance(a[key], float):
            assert a[key] == pytest.approx(b[key], rel=1e-12), key
        else:
            assert a[key] == b[key], key
    assert [s["cause"] for s in a["stops"]] == ["force_max"] and not a["completed"]
    assert whole.saturation() == split.saturation() and whole.unloading() == split.unloading()
    # The in-contact minimum is the per-sample definition's.
    force = -rows[:, COL_FZ]
    tracked = (rows[:, COL_PHASE] == Phase.PLAY) & (rows[:, COL_CTRL_MODE] > 0.5)
    lo_f, lo_t = _contact_reference(rows[:, 0], force, tracked, 100.0)
    assert a["min_force_n"] == lo_f and whole._min_contact[1] == lo_t
    assert lo_f < 100.0 - 2.0 and whole.unloading()
    assert a["peak_actuator_force_n"] == pytest.approx(np.abs(rows[:, COLUMNS["tau"]]).max())
    # The longest stretch at the drive's limit: consecutive samples, whole or split.
    limit = whole.robot.max_command_v
    over = np.abs(rows[:, COLUMNS["volts"]]).max(axis=1) >= limit - 1e-9
    longest, current, start, longest_at = 0, 0, 0, 0
    for k, o in enumerate(over):
        current = current + 1 if o else 0
        start = k - current + 1
        if current > longest:
            longest, longest_at = current, start
    assert 0 < longest < over.sum()                 # stretches separated by samples below it
    for figures in (whole, split):
        assert figures._runs["drive command"][2] == longest
        assert figures._runs["drive command"][3] == rows[longest_at, 0]


def test_a_recording_without_drive_commands_leaves_their_figures_out():
    rows = _rows(3000, 7)
    rows[:, COLUMNS["volts"]] = 10.0                          # at the drive's limit throughout
    full = _figures()
    full.add(rows)
    assert any("drive command" in s for s in full.saturation())
    block = SampleBlock.from_tap_rows(rows)
    block.volts, block.wrench, block.tare = None, None, None   # what a recording may lack
    partial = _figures()
    partial.add(block)
    assert not any("drive command" in s for s in partial.saturation())
    assert "ati_tare" not in partial.result()
    assert partial.result()["rms_error_pct"] == full.result()["rms_error_pct"]
