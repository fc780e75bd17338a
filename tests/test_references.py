"""Reference generation: ruckig moves and soft stop, file playback, sequence, benchmark.

Limit checks on produced samples use difference quotients: (p_{k+1} - p_k)/dt is the mean of the
velocity over the cycle, so it can never exceed the velocity bound; the same holds one derivative
up for acceleration (from velocities) and jerk (from accelerations, piecewise linear in ruckig's
profiles). Only floating-point round-off is added, hence relative slack 1e-9 (1e-6 for the jerk,
whose quotient divides a difference of O(1e-3) m/s² values by 1e-3 s).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from ruckig import ControlInterface, InputParameter, OutputParameter, Result, Ruckig, Trajectory

from rt.components.tare import Tare
from rt.errors import ProtocolValidationError
from rt.references.approach import DEFAULT_MAX_ACCELERATION_M_S2 as AMAX
from rt.references.approach import DEFAULT_MAX_JERK_M_S3 as JMAX
from rt.references.approach import DEFAULT_MAX_VELOCITY_M_S as VMAX
from rt.references.approach import (
    STROKE_M,
    Approach,
    ApproachStatus,
    Mode,
    trajectory_position_extrema,
)
from rt.references.benchmark_trajectory import BenchmarkTrajectory
from rt.references.playback import ReferenceStatus, SourceProgram, TrajectoryPlayback, load_csv
from rt.references.program import Mode as ProgramMode
from rt.references.program import ReferenceOutput
from rt.references.sequencer import Phase, ProgramReference
from rt.safety.events import SupervisorMode

DT = 1e-3
LO, HI = STROKE_M


def run(gen, n_max: int = 100_000, stop_on=(ApproachStatus.FINISHED,)):
    """Step a generator; returns (positions, velocities, accelerations, statuses) arrays."""
    p, v, a = np.zeros(3), np.zeros(3), np.zeros(3)
    rows, statuses = [], []
    for _ in range(n_max):
        status = gen.update(p, v, a)
        rows.append(np.concatenate([p, v, a]))
        statuses.append(status)
        if status in stop_on:
            break
    arr = np.array(rows)
    return arr[:, :3], arr[:, 3:6], arr[:, 6:], statuses


def assert_within_limits(p0, v0, a0, p, v, a, vmax=VMAX, amax=AMAX, jmax=JMAX):
    """Samples (initial state prepended) respect v/a/j limits, from difference quotients."""
    P, V, A = (np.vstack([np.asarray(x0, float)[None, :], x])
               for x0, x in ((p0, p), (v0, v), (a0, a)))
    assert np.max(np.abs(V)) <= vmax * (1 + 1e-9)
    assert np.max(np.abs(A)) <= amax * (1 + 1e-9)
    assert np.max(np.abs(np.diff(P, axis=0))) / DT <= vmax * (1 + 1e-9)
    assert np.max(np.abs(np.diff(V, axis=0))) / DT <= amax * (1 + 1e-9)
    assert np.max(np.abs(np.diff(A, axis=0))) / DT <= jmax * (1 + 1e-6)


def test_stroke_matches_description() -> None:
    from rt.model.description import load_description
    assert tuple(load_description().limits.stroke_m) == STROKE_M


# -- approach -------------------------------------------------------------------------------------
def test_reaches_target_state_exactly() -> None:
    ap = Approach()
    start = [0.05, 0.1, 0.2]
    assert ap.reset(start) == ApproachStatus.IDLE
    target = ([0.3, 0.15, 0.25], [0.05, -0.02, 0.0], [0.1, 0.0, -0.1])
    assert ap.set_target(*target) == ApproachStatus.WORKING
    p, v, a, statuses = run(ap)
    assert statuses[-1] == ApproachStatus.FINISHED
    assert set(statuses[:-1]) == {ApproachStatus.WORKING}
    # FINISHED comes on the cycle whose sample is the target; the duration is a whole cycle count
    assert len(statuses) * DT == pytest.approx(ap.duration, abs=1e-9)
    for got, want in zip((p[-1], v[-1], a[-1]), target):
        np.testing.assert_allclose(got, want, atol=1e-12)
    assert_within_limits(start, [0] * 3, [0] * 3, p, v, a)
    # afterwards: holds the position at rest
    pp, vv, aa = np.zeros(3), np.ones(3), np.ones(3)
    assert ap.update(pp, vv, aa) == ApproachStatus.FINISHED
    np.testing.assert_array_equal(pp, target[0])
    np.testing.assert_array_equal(vv, 0.0)


@given(start=st.lists(st.floats(0.0, 0.4), min_size=3, max_size=3),
       v0=st.lists(st.floats(-0.1, 0.1), min_size=3, max_size=3),
       goal=st.lists(st.floats(0.0, 0.4), min_size=3, max_size=3))
def test_limits_respected_from_any_state(start, v0, goal) -> None:
    ap = Approach()
    assert ap.reset(start, v0) == ApproachStatus.IDLE
    status = ap.set_target(goal)
    if status == ApproachStatus.ERROR_OVERSHOOT:  # fast towards a nearby stroke end: refused
        assert any(lo < LO - 1e-9 or hi > HI + 1e-9 for lo, hi in ap.position_extrema)
        return
    assert status == ApproachStatus.WORKING
    p, v, a, statuses = run(ap)
    assert statuses[-1] == ApproachStatus.FINISHED
    np.testing.assert_allclose(p[-1], goal, atol=1e-12)
    assert np.all((p >= LO) & (p <= HI))
    assert_within_limits(start, v0, [0] * 3, p, v, a)


def test_minimum_duration_like_the_thesis() -> None:
    ap = Approach()
    ap.reset([0.0, 0.0, 0.0])
    assert ap.set_target([0.2, 0.25, 0.15], minimum_duration=8.0) == ApproachStatus.WORKING
    p, v, a, statuses = run(ap)
    assert len(statuses) == 8000  # 8 s at 1 kHz, ending on the target
    np.testing.assert_allclose(p[-1], [0.2, 0.25, 0.15], atol=1e-12)
    assert_within_limits([0] * 3, [0] * 3, [0] * 3, p, v, a)


def test_retargeting_is_continuous() -> None:
    ap = Approach()
    ap.reset([0.1, 0.1, 0.1])
    ap.set_target([0.3, 0.3, 0.3])
    p1, v1, a1, _ = run(ap, n_max=700)  # mid-move, near full speed
    assert np.all(np.abs(v1[-1]) > 0.05)
    assert ap.set_target([0.15, 0.35, 0.2], [0.0, 0.05, 0.0]) == ApproachStatus.WORKING
    p2, v2, a2, statuses = run(ap)
    assert statuses[-1] == ApproachStatus.FINISHED
    p, v, a = np.vstack([p1, p2]), np.vstack([v1, v2]), np.vstack([a1, a2])
    # no jump at the seam beyond one cycle of limited motion
    assert_within_limits([0.1] * 3, [0] * 3, [0] * 3, p, v, a)
    np.testing.assert_allclose(p[-1], [0.15, 0.35, 0.2], atol=1e-12)


def test_retarget_on_the_finished_cycle_continues_from_the_target_velocity() -> None:
    ap = Approach()
    ap.reset([0.1, 0.1, 0.1])
    ap.set_target([0.2, 0.2, 0.2], [0.05, 0.05, 0.05])
    p1, v1, a1, _ = run(ap)
    np.testing.assert_allclose(v1[-1], 0.05)
    assert ap.set_target([0.25, 0.25, 0.25]) == ApproachStatus.WORKING
    p2, v2, a2, _ = run(ap)
    assert_within_limits([0.1] * 3, [0] * 3, [0] * 3, np.vstack([p1, p2]), np.vstack([v1, v2]),
                         np.vstack([a1, a2]))


def test_refused_retarget_leaves_running_move() -> None:
    ap = Approach()
    ap.reset([0.1, 0.1, 0.1])
    ap.set_target([0.3, 0.3, 0.3])
    run(ap, n_max=300)
    assert ap.set_target([0.41, 0.3, 0.3]) == ApproachStatus.ERROR_OUTSIDE_STROKE
    assert ap.mode == Mode.MOVING
    p, *_ = run(ap)
    np.testing.assert_allclose(p[-1], 0.3, atol=1e-12)


@pytest.mark.parametrize("target, velocity, expected", [
    ([0.41, 0.2, 0.2], None, ApproachStatus.ERROR_OUTSIDE_STROKE),
    ([0.2, -0.001, 0.2], None, ApproachStatus.ERROR_OUTSIDE_STROKE),
    ([0.2, math.nan, 0.2], None, ApproachStatus.ERROR_INVALID_INPUT),
    ([0.2, 0.2], None, ApproachStatus.ERROR_INVALID_INPUT),
    ([0.2, 0.2, 0.2], [0.2, 0.0, 0.0], ApproachStatus.ERROR_LIMITS),
])
def test_bad_targets_refused(target, velocity, expected) -> None:
    ap = Approach()
    assert ap.set_target([0.2] * 3) == ApproachStatus.ERROR_NOT_READY
    ap.reset([0.2] * 3)
    assert ap.set_target(target, velocity) == expected
    assert ap.mode == Mode.IDLE
    assert ap.reset([0.5, 0.2, 0.2]) == ApproachStatus.ERROR_OUTSIDE_STROKE


def test_plain_ruckig_overshoots_but_approach_refuses() -> None:
    # Slider 0 at 0.39 m moving up at 0.1 m/s, target 0.395 m: braking within 0.5 m/s², 5 m/s³
    # takes 15 mm, so any trajectory passes 0.40 m.
    otg, inp, out = Ruckig(1, DT), InputParameter(1), OutputParameter(1)
    inp.current_position, inp.current_velocity = [0.39], [0.1]
    inp.target_position = [0.395]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [VMAX], [AMAX], [JMAX]
    inp.min_position, inp.max_position = [LO], [HI]  # silently ignored by the community edition
    peak, result = 0.0, Result.Working
    while result == Result.Working:
        result = otg.update(inp, out)
        peak = max(peak, out.new_position[0])
        out.pass_to_input(inp)
    assert result == Result.Finished
    assert peak > HI + 0.004  # ≈ 0.4042 m

    ap = Approach()
    ap.reset([0.39, 0.2, 0.2], [0.1, 0.0, 0.0])
    assert ap.set_target([0.395, 0.2, 0.2]) == ApproachStatus.ERROR_OVERSHOOT
    assert ap.position_extrema[0][1] > HI + 0.004  # its own (discretised) plan: ≈ 0.4042 m
    assert ap.mode == Mode.IDLE  # nothing started


def test_extrema_computed_where_ruckig_misses_them() -> None:
    # ruckig 0.19.4's position_extrema reports min +3.2 mm here; the move reaches -1.5 mm.
    otg, inp, traj = Ruckig(1, DT), InputParameter(1), Trajectory(1)
    inp.current_position, inp.current_velocity = [0.01171875], [-0.09375]
    inp.target_position = [0.25]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [VMAX], [AMAX], [JMAX]
    otg.calculate(inp, traj)
    sampled = min(traj.at_time(t)[0][0] for t in np.linspace(0.0, traj.duration, 5001))
    assert traj.position_extrema[0].min > 0.003  # ruckig's answer: wrong
    assert sampled < -0.0015
    assert trajectory_position_extrema(traj)[0][0] == pytest.approx(sampled, abs=1e-9)
    ap = Approach()
    ap.reset([0.01171875, 0.2, 0.2], [-0.09375, 0.0, 0.0])
    assert ap.set_target([0.25, 0.2, 0.2]) == ApproachStatus.ERROR_OVERSHOOT


@given(p0=st.lists(st.floats(0.0, 0.4), min_size=3, max_size=3),
       v0=st.lists(st.floats(-0.2, 0.2), min_size=3, max_size=3),
       a0=st.lists(st.floats(-0.7, 0.7), min_size=3, max_size=3),
       goal=st.lists(st.floats(0.0, 0.4), min_size=3, max_size=3),
       stop=st.booleans())
def test_extrema_match_dense_sampling(p0, v0, a0, goal, stop) -> None:
    # includes states beyond the limits (ruckig's brake pre-profiles) and soft stops
    otg, inp, traj = Ruckig(3, DT), InputParameter(3), Trajectory(3)
    inp.current_position, inp.current_velocity, inp.current_acceleration = p0, v0, a0
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [VMAX] * 3, [AMAX] * 3, [JMAX] * 3
    if stop:
        inp.control_interface = ControlInterface.Velocity
        inp.target_velocity = [0.0] * 3
    else:
        inp.target_position = goal
    otg.calculate(inp, traj)
    ext = trajectory_position_extrema(traj)
    samples = np.array([traj.at_time(t)[0] for t in np.linspace(0.0, traj.duration, 2001)])
    for i in range(3):
        assert ext[i][0] <= samples[:, i].min() + 1e-12
        assert ext[i][1] >= samples[:, i].max() - 1e-12
        # and tight: a 2001-point grid is within v·Δt²-ish of the true extremum
        assert samples[:, i].min() - ext[i][0] < 1e-5 and ext[i][1] - samples[:, i].max() < 1e-5


def test_overshooting_soft_stop_is_clamped_and_flagged() -> None:
    ap = Approach()
    ap.reset([0.39, 0.2, 0.2], [0.1, 0.0, 0.0])
    assert ap.soft_stop() == ApproachStatus.ERROR_OVERSHOOT  # a stop is never refused
    p, _v, _a, statuses = run(ap)
    assert np.max(p) <= HI
    assert ApproachStatus.ERROR_POSITION_LIMIT in statuses
    assert statuses[-1] == ApproachStatus.FINISHED
    assert p[-1, 0] == HI


def _stop_time_bound(v0: float, amax: float = AMAX, jmax: float = JMAX) -> float:
    """Time-optimal jerk-limited stop from speed v0 (a0 = 0): v/a + a/j if a_max is reached."""
    v0 = abs(v0)
    return v0 / amax + amax / jmax if v0 >= amax ** 2 / jmax else 2.0 * math.sqrt(v0 / jmax)


def test_soft_stop_bounded() -> None:
    v0 = [0.1, -0.05, 0.02]
    # from 0.1 m/s: 0.1/0.5 + 0.5/5 = 0.3 s over 0.1·0.3/2 = 15 mm
    assert _stop_time_bound(0.1) == pytest.approx(0.3)
    ap = Approach()
    ap.reset([0.2] * 3, v0)
    assert ap.soft_stop() == ApproachStatus.WORKING
    assert ap.duration <= 0.3 + DT
    p, v, a, statuses = run(ap)
    assert statuses[-1] == ApproachStatus.FINISHED
    assert len(statuses) * DT <= 0.3 + DT
    np.testing.assert_array_equal(v[-1], 0.0)
    np.testing.assert_array_equal(a[-1], 0.0)
    for i in range(3):
        at_rest = np.flatnonzero(np.abs(v[:, i]) < 1e-12)
        t_rest = (at_rest[0] + 1) * DT
        assert t_rest <= _stop_time_bound(v0[i]) + DT  # each axis brakes time-optimally
        assert np.all(np.abs(v[at_rest[0]:, i]) < 1e-12)
        assert np.all(v[:, i] * v0[i] >= -1e-15)  # never backs up
        dist = abs(p[-1, i] - 0.2)
        assert dist <= abs(v0[i]) * _stop_time_bound(v0[i]) / 2 + 1e-9
    assert_within_limits([0.2] * 3, v0, [0] * 3, p, v, a)


def test_soft_stop_mid_move_is_continuous() -> None:
    ap = Approach()
    ap.reset([0.1, 0.2, 0.3])
    ap.set_target([0.3, 0.05, 0.1])
    p1, v1, a1, _ = run(ap, n_max=400)  # accelerating hard: a ≠ 0 at the stop
    assert ap.soft_stop() == ApproachStatus.WORKING
    p2, v2, a2, statuses = run(ap)
    assert statuses[-1] == ApproachStatus.FINISHED
    assert len(statuses) * DT < 0.5
    np.testing.assert_array_equal(v2[-1], 0.0)
    assert_within_limits([0.1, 0.2, 0.3], [0] * 3, [0] * 3, np.vstack([p1, p2]),
                         np.vstack([v1, v2]), np.vstack([a1, a2]))


# Per-cycle costs (approach ≈ 3 µs, benchmark ≈ 2-3 µs, playback ≈ 2 µs per update) are
# figures printed by bench/costs.py, not asserted: a loaded machine would fail any bound.


# -- benchmark trajectory -------------------------------------------------------------------------
def test_benchmark_derivatives_match_finite_differences() -> None:
    b = BenchmarkTrajectory()
    h = 1e-4
    t = np.linspace(0.0, 26.0, 5001)
    q_p, v_p, _ = b.evaluate(t + h)
    q_m, v_m, _ = b.evaluate(t - h)
    q, v, a = b.evaluate(t)
    # central differences err by h²/6·max|q'''| ≈ 1.6e-9 (+ round-off ~1e-12 m / h)
    np.testing.assert_allclose((q_p - q_m) / (2 * h), v, atol=1e-7)
    np.testing.assert_allclose((v_p - v_m) / (2 * h), a, atol=1e-6)
    np.testing.assert_allclose(q[0], 0.2 + 0.045 * np.sin(np.array([0, 2, 4]) * np.pi / 3))


def test_benchmark_cycle_api_and_peaks() -> None:
    b = BenchmarkTrajectory()
    assert b.update(np.zeros(3), np.zeros(3), np.zeros(3)) == ReferenceStatus.ERROR_NOT_VALIDATED
    b.validate()
    assert b.n_samples == 26001
    p, v, a, statuses = run(b, stop_on=(ReferenceStatus.FINISHED,))
    assert len(statuses) == 26001 and statuses[-1] == ReferenceStatus.FINISHED
    qa, va, aa = b.evaluate(np.arange(26001) * DT)
    np.testing.assert_allclose(p, qa, atol=1e-12)
    np.testing.assert_allclose(v, va, atol=1e-12)
    np.testing.assert_allclose(a, aa, atol=1e-12)
    assert np.max(np.abs(v)) == pytest.approx(0.03 * 2 * np.pi * 0.25 + 0.015 * 2 * np.pi * 0.6,
                                              rel=1e-6)  # 0.104 m/s at t = 0 on slider 0
    assert np.max(np.abs(a)) < 0.2875
    with pytest.raises(ProtocolValidationError, match="stroke"):
        BenchmarkTrajectory(q0=0.37).validate()


# -- playback files -------------------------------------------------------------------------------
def write_csv(path: Path, t: np.ndarray | None, q: np.ndarray, header: str | None = "auto") -> Path:
    lines = []
    if header == "auto":
        header = "t,q0,q1,q2" if t is not None else "q0,q1,q2"
    if header is not None:
        lines.append(header)
    for k in range(q.shape[0]):
        vals = ([repr(float(t[k]))] if t is not None else []) + [repr(float(x)) for x in q[k]]
        lines.append(",".join(vals))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture()
def bench() -> BenchmarkTrajectory:
    return BenchmarkTrajectory()


def test_playback_at_loop_rate_reproduces_samples(tmp_path: Path, bench) -> None:
    t = np.arange(0.0, 2.0 + 1e-9, DT)
    q = bench.evaluate(t)[0]
    play = TrajectoryPlayback.from_csv(write_csv(tmp_path / "traj.csv", t, q))
    assert play.n_samples == t.size
    p, v, _a, statuses = run(play, stop_on=(ReferenceStatus.FINISHED,))
    np.testing.assert_allclose(p, q, atol=1e-15)  # an interpolating spline hits its samples
    assert statuses.count(ReferenceStatus.FINISHED) == 1
    assert statuses[-1] == ReferenceStatus.FINISHED
    _, va, _aa = bench.evaluate(t)
    np.testing.assert_allclose(v, va, atol=1e-6)  # analytic derivative of the spline


def test_resampling_100hz_file_to_1khz(tmp_path: Path, bench) -> None:
    h = 0.01  # the thesis's 100 Hz reference files
    t = np.arange(0.0, 26.0 + 1e-9, h)
    play = TrajectoryPlayback.from_csv(write_csv(tmp_path / "b.csv", t, bench.evaluate(t)[0]))
    tk = np.arange(play.n_samples) * DT
    assert play.n_samples == 26001
    qa, va, aa = bench.evaluate(tk)
    p, v, a, _ = run(play, stop_on=(ReferenceStatus.FINISHED,))
    # cubic spline errors: (5/384) h⁴ max|q''''| ≈ 4e-10 m, ~h³ for velocity, ~h² for
    # acceleration (largest at the not-a-knot ends); measured 9e-10 m, 6e-7 m/s, 2.2e-4 m/s²
    assert np.max(np.abs(p - qa)) < 2e-9
    assert np.max(np.abs(v - va)) < 2e-6
    assert np.max(np.abs(a - aa)) < 5e-4

    lin = TrajectoryPlayback(t, bench.evaluate(t)[0], interpolation="linear")
    lin.validate()
    p, v, a, _ = run(lin, stop_on=(ReferenceStatus.FINISHED,))
    qpp = np.max(np.abs(aa))
    # linear interpolation: |error| ≤ h²/8·max|q''| in position, h/2·max|q''| in velocity
    assert np.max(np.abs(p - qa)) <= h * h / 8 * qpp * (1 + 1e-6)
    assert np.max(np.abs(v - va)) <= h / 2 * qpp * (1 + 1e-6)
    np.testing.assert_array_equal(a, 0.0)


def test_nonuniform_file_resampled_when_allowed(tmp_path: Path, bench) -> None:
    rng = np.random.default_rng(1)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.004, 0.012, 500))])
    path = write_csv(tmp_path / "nu.csv", t, bench.evaluate(t)[0])
    with pytest.raises(ProtocolValidationError, match="not uniformly sampled"):
        TrajectoryPlayback.from_csv(path)
    play = TrajectoryPlayback.from_csv(path, uniform=False)
    p, *_ = run(play, stop_on=(ReferenceStatus.FINISHED,))
    np.testing.assert_allclose(p, bench.evaluate(np.arange(play.n_samples) * DT)[0], atol=1e-8)


def test_positions_only_with_declared_rate(tmp_path: Path, bench) -> None:
    t = np.arange(0.0, 1.0 + 1e-9, 0.01)
    q = bench.evaluate(t)[0]
    with_time = load_csv(write_csv(tmp_path / "a.csv", t, q))
    with_header = load_csv(write_csv(tmp_path / "b.csv", None, q), sample_rate_hz=100.0)
    headerless = load_csv(write_csv(tmp_path / "c.csv", None, q, header=None), sample_rate_hz=100.0)
    for other in (with_header, headerless):
        np.testing.assert_allclose(other[0], with_time[0], atol=1e-12)
        np.testing.assert_array_equal(other[1], with_time[1])
    np.testing.assert_array_equal(headerless[2], np.arange(1, t.size + 1))


_GOOD = ["t,q0,q1,q2", "0.0,0.2,0.2,0.2", "0.01,0.2,0.2,0.2", "0.02,0.2,0.2,0.2",
         "0.03,0.2,0.2,0.2", "0.04,0.2,0.2,0.2"]


def _edit(line: int, text: str | None) -> list[str]:
    rows = list(_GOOD)
    if text is None:
        del rows[line - 1]
    else:
        rows[line - 1] = text
    return rows


@pytest.mark.parametrize("rows, kwargs, line, reason", [
    ([], {}, None, "no header and no samples"),
    (["t,q0,q1,q2"], {}, None, "header but no samples"),
    (_edit(1, "time,a,b,c"), {}, 1, "header must be 't,q0,q1,q2' or 'q0,q1,q2'"),
    (_edit(4, "0.02,0.2,0.2"), {}, 4, "expected 4 columns"),
    (_edit(4, "0.02,0.2,0.2,0.2,0.2"), {}, 4, "expected 4 columns"),
    (_edit(3, "0.01,0.2,abc,0.2"), {}, 3, "column 'q1': 'abc' is not a number"),
    (_edit(3, "0.01,0.2,0.2,nan"), {}, 3, "column 'q2': nan is not a finite number"),
    (_edit(3, "0.01,inf,0.2,0.2"), {}, 3, "column 'q0': inf is not a finite number"),
    (_edit(4, "0.005,0.2,0.2,0.2"), {}, 4, "is not after the previous sample's"),
    (_edit(4, "0.01,0.2,0.2,0.2"), {}, 4, "is not after the previous sample's"),
    (_edit(4, None), {}, 4, "not uniformly sampled"),  # line 4 is now t = 0.03 (0.02 dropped)
    (_edit(3, "0.01,0.45,0.2,0.2"), {}, 3, r"column 'q0': position 0.45 m is outside the stroke"),
    (_edit(3, "0.01,0.2,-0.01,0.2"), {}, 3, "column 'q1': position -0.01 m is outside the stroke"),
    (_edit(4, "0.02,0.2,0.2,0.2025"), {}, 4, ("column 'q2': velocity 0.25 m/s from line 3 to 4 "
                                             "exceeds the limit 0.15 m/s")),
    (_edit(4, "0.02,0.2,0.2001,0.2"), {}, 3, ("column 'q1': acceleration 1 m/s² (second difference "
                                             "over lines 2 to 4) exceeds the limit 0.5 m/s²")),
    (["q0,q1,q2", "0.2,0.2,0.2", "0.2,0.2,0.2"], {}, 1, "declare its sample_rate_hz"),
    (_GOOD, {"sample_rate_hz": 100.0}, 1, "do not also declare sample_rate_hz"),
    (["0.0,0.2,0.2,0.2", "0.01,0.2,0.2,0.2"], {"sample_rate_hz": 100.0}, 1,
     "without a header must have 3 position columns"),
    (_GOOD[:2], {}, None, "at least 2 samples"),
    (["# exported by the lab's tool", *_edit(3, "0.01,0.2,x,0.2")], {}, 4, "'x' is not a number"),
])
def test_malformed_files_refused(tmp_path: Path, rows, kwargs, line, reason) -> None:
    path = tmp_path / "protocol.csv"
    path.write_text("\n".join(rows) + ("\n" if rows else ""))
    where = f"{path}, line {line}: " if line is not None else f"{path}: "
    with pytest.raises(ProtocolValidationError) as info:
        TrajectoryPlayback.from_csv(path, **kwargs)
    message = str(info.value)
    assert message.startswith(where), message
    assert reason in message, message


def test_missing_file_refused(tmp_path: Path) -> None:
    with pytest.raises(ProtocolValidationError, match=r"nope\.csv: cannot read the file"):
        TrajectoryPlayback.from_csv(tmp_path / "nope.csv")


def test_interpolation_overshoot_refused(tmp_path: Path) -> None:
    # Samples of a parabola peaking at 0.40005 m between two samples: every sample is inside the
    # stroke and the limits (0.4 m/s² curvature), but the cubic through them (exact on a
    # parabola) passes 0.40 m. What would be played is checked, not only the samples.
    t = np.arange(0.0, 0.2 + 1e-9, 0.05)
    q = np.full((t.size, 3), 0.2)
    q[:, 0] = 0.40005 - 0.2 * (t - 0.125) ** 2
    assert q[:, 0].max() < HI
    path = write_csv(tmp_path / "edge.csv", t, q)
    with pytest.raises(ProtocolValidationError,
                       match=r"edge\.csv, line 5: column 'q0': the cubic interpolation between "
                             r"lines 4 and 5 gives position 0\.4000\d+ m at t = 0\.1\d+ s, "
                             r"which is outside the stroke"):
        TrajectoryPlayback.from_csv(path)
    TrajectoryPlayback.from_csv(path, interpolation="linear")  # no overshoot: accepted


# -- the sequencer (approach → play → return → rest) ----------------------------------------------
class Harness:
    """The sequencer alone, its inputs bound to arrays: the measured position follows the
    reference exactly (a perfect inner loop), the supervisor's mode is set by the test."""

    def __init__(self, q0, dt: float = DT) -> None:
        self.ref = ProgramReference("reference", STROKE_M, dt)
        self.q = np.array(q0, float)
        self.mode = np.zeros(1)
        self.wrench = np.zeros(6)
        self.ref.q_meas._bind(self.q, "test.q")
        self.ref.mode._bind(self.mode, "test.mode")
        self.ref.wrench._bind(self.wrench, "test.wrench")
        # The force reader's tare, answering the sequencer's request one cycle late.
        self.tare = Tare()
        self.tare_port = np.zeros(10)
        self.tare_request = np.zeros(1)
        self.ref.tare._bind(self.tare_port, "test.tare")
        self.ref.configure()
        self.ref.start()
        self.t = 0.0

    def step(self) -> Phase:
        self.tare.cycle(self.wrench.copy(), True, self.tare_request[0] > 0.5, self.tare_port)
        assert self.ref.update(self.t, DT) == 0
        self.tare_request[:] = self.ref.tare_request.data
        self.t += DT
        self.q[:] = self.ref.q_ref.data
        return Phase(int(self.ref.phase.data[0]))

    def run(self, n_max: int = 100_000, until=(Phase.REST,), skip_first: bool = True):
        """Step until a phase in ``until`` (after the first cycle); (p, v, a, phases)."""
        rows, phases = [], []
        for k in range(n_max):
            ph = self.step()
            r = self.ref
            rows.append(np.concatenate([r.q_ref.data, r.qd_ref.data, r.qdd_ref.data]))
            phases.append(ph)
            if ph in until and (k > 0 or not skip_first):
                break
        arr = np.array(rows)
        return arr[:, :3], arr[:, 3:6], arr[:, 6:], phases


def _seams(statuses):
    """Phases in order with their cycle counts."""
    out = []
    for s in statuses:
        if out and out[-1][0] == s:
            out[-1][1] += 1
        else:
            out.append([s, 1])
    return out


def test_sequencer_phases_in_order_and_seamless(tmp_path: Path, bench) -> None:
    t = np.arange(0.0, 4.0 + 1e-9, 0.01)
    play = TrajectoryPlayback.from_csv(write_csv(tmp_path / "p.csv", t, bench.evaluate(t)[0]))
    play.validate()
    start = [0.0, 0.0, 0.0]  # the thesis starts from the bottom of the stroke
    h = Harness(start)
    h.ref.request(SourceProgram(play), rest_q=tuple(start))
    p, v, a, phases = h.run()
    seams = _seams(phases)
    assert [s for s, _ in seams] == [Phase.APPROACH, Phase.PLAY, Phase.RETURN, Phase.REST]
    n_app, n_play = seams[0][1], seams[1][1]
    assert n_play == play.n_samples - 1  # sample 0 was the approach's last sample
    first = (np.zeros(3), np.zeros(3), np.zeros(3))
    play.state_at(0, *first)  # the approach ends exactly on the first sample's state
    np.testing.assert_allclose(p[n_app - 1], first[0], atol=1e-12)
    np.testing.assert_allclose(v[n_app - 1], first[1], atol=1e-12)
    np.testing.assert_allclose(a[n_app - 1], first[2], atol=1e-12)
    np.testing.assert_allclose(p[n_app], play._pos[1], atol=1e-15)
    np.testing.assert_allclose(p[-1], start, atol=1e-12)  # back to rest where it started
    np.testing.assert_array_equal(v[-1], 0.0)
    assert_within_limits(start, [0] * 3, [0] * 3, p, v, a)  # no jump at any seam
    assert h.step() == Phase.REST and h.ref.epoch == 1 and not h.ref.busy


def test_sequencer_benchmark_with_thesis_8s_approach(bench) -> None:
    bench.validate()
    h = Harness([0.2, 0.2, 0.2])
    h.ref.request(SourceProgram(bench), approach_min_s=8.0, rest_q=(0.2, 0.2, 0.2),
                  return_min_s=8.0)
    p, v, a, phases = h.run()
    seams = _seams(phases)
    # The request is taken on the first cycle, whose sample is the approach's first.
    assert [(s, n) for s, n in seams] == [(Phase.APPROACH, 8000), (Phase.PLAY, 26000),
                                          (Phase.RETURN, 7999), (Phase.REST, 1)]
    qa, _va, _aa = bench.evaluate(np.arange(1, 26001) * DT)
    np.testing.assert_allclose(p[8000:34000], qa, atol=1e-12)
    assert_within_limits([0.2] * 3, [0] * 3, [0] * 3, p, v, a)


def test_sequencer_soft_stop_while_playing_latches_until_reset(bench) -> None:
    bench.validate()
    h = Harness([0.2, 0.2, 0.2])
    h.ref.request(SourceProgram(bench))
    p1, v1, a1, ph1 = h.run(n_max=5000, until=())
    assert ph1[-1] == Phase.PLAY
    h.mode[0] = SupervisorMode.SOFT_STOP
    p2, v2, a2, ph2 = h.run(n_max=2000, until=())
    assert set(ph2) == {Phase.STOPPED}
    stopped_at = np.argmax(np.all(np.abs(v2) == 0.0, axis=1))
    assert 0 < stopped_at * DT <= 0.5
    np.testing.assert_array_equal(v2[-1], 0.0)
    assert_within_limits([0.2] * 3, [0] * 3, [0] * 3, np.vstack([p1, p2]), np.vstack([v1, v2]),
                         np.vstack([a1, a2]))
    h.ref.request(SourceProgram(bench))  # refused while stopped
    assert h.step() == Phase.STOPPED and h.ref.refused == 1
    assert "reset the faults" in h.ref.last_error
    h.mode[0] = SupervisorMode.RUN  # the supervisor was reset: hold where the robot is
    held = h.q.copy()
    assert h.step() == Phase.REST
    np.testing.assert_allclose(h.ref.q_ref.data, held, atol=1e-12)


def test_sequencer_abort_returns_to_rest_without_fault(bench) -> None:
    bench.validate()
    h = Harness([0.2, 0.2, 0.2])
    h.ref.request(SourceProgram(bench))
    h.run(n_max=3000, until=())
    h.ref.request_abort()
    _p, v, _a, phases = h.run(n_max=5000)
    assert phases[0] == Phase.RETURN and phases[-1] == Phase.REST
    assert len(phases) * DT <= 0.5
    np.testing.assert_array_equal(v[-1], 0.0)


def test_sequencer_hard_stop_follows_the_measured_position(bench) -> None:
    bench.validate()
    h = Harness([0.2, 0.2, 0.2])
    h.ref.request(SourceProgram(bench))
    h.run(n_max=3000, until=())
    h.mode[0] = SupervisorMode.HARD_STOP
    h.q[:] = [0.21, 0.19, 0.2]                         # the platform sank while unpowered
    assert h.step() == Phase.STOPPED
    np.testing.assert_allclose(h.ref.q_ref.data, [0.21, 0.19, 0.2])
    np.testing.assert_array_equal(h.ref.qd_ref.data, 0.0)


def test_sequencer_refusals(bench) -> None:
    bench.validate()
    h = Harness([0.2, 0.45, 0.2])            # outside the stroke: no approach can start here
    h.ref.request(SourceProgram(bench))
    assert h.step() == Phase.REST
    assert h.ref.refused == 1 and "refused" in h.ref.last_error and h.ref.epoch == 0
    h = Harness([0.2, 0.2, 0.2])
    h.ref.request(SourceProgram(bench))
    h.step()
    h.ref.request(SourceProgram(bench))      # one program at a time
    assert h.step() == Phase.APPROACH
    assert h.ref.refused == 1 and h.ref.last_error == "a program is running"
    assert not SourceProgram(BenchmarkTrajectory()).update(ReferenceOutput()) >= 0  # unvalidated


class _ForceHold:
    """A force program: 300 N in z at the pose where it starts, for ``duration_s``."""

    def __init__(self, q, duration_s: float = 2.0) -> None:
        self.q = np.array(q, float)
        self.duration_s = duration_s
        self.n = round(duration_s / DT) + 1
        self.k = 0

    @staticmethod
    def new_output() -> ReferenceOutput:
        return ReferenceOutput()

    def reset(self) -> None:
        self.k = 0

    def update(self, out: ReferenceOutput, inp=None) -> int:
        out.q_ref[:] = self.q
        out.qd_ref[:] = 0.0
        out.qdd_ref[:] = 0.0
        out.buf[15], out.buf[16] = 300.0, 0.0
        out.mode = ProgramMode.FORCE
        out.done = self.k >= self.n - 1
        self.k = min(self.k + 1, self.n - 1)
        return 1 if out.done else 0


def test_sequencer_abort_in_force_ramps_the_force_down_then_holds_where_the_robot_is() -> None:
    h = Harness([0.2, 0.2, 0.2])
    h.ref.request(_ForceHold([0.2, 0.2, 0.2]))
    for _ in range(500):
        h.step()
    assert h.ref.ctrl_mode.data[0] == ProgramMode.FORCE and h.ref.force.data[0] == 300.0
    h.q[:] = [0.195, 0.195, 0.195]          # pressed 5 mm into the foot
    h.ref.request_abort()
    forces = []
    for _ in range(3000):
        ph = Phase(int(h.ref.phase.data[0]))
        h.ref.update(h.t, DT)
        h.t += DT
        forces.append(h.ref.force.data[0])
        if Phase(int(h.ref.phase.data[0])) == Phase.REST:
            break
    f = np.array(forces)
    assert np.all(np.diff(f) <= 0.0) and f[0] > 250.0      # monotonic ramp, no step to zero
    # Exponential ramp, time constant 0.3 s, then zero below 1 N: ln(301) * 0.3 s ≈ 1.7 s.
    assert 1.5 <= len(f) * DT <= 1.9 and f[-1] == 0.0
    assert ph in (Phase.RETURN, Phase.REST)
    assert h.ref.ctrl_mode.data[0] == ProgramMode.POSITION
    np.testing.assert_allclose(h.ref.q_ref.data, [0.195] * 3)   # holds where it is, no jump


def test_a_watched_programs_outcome_from_its_phase_blocks():
    import numpy as np

    from rt.references.sequencer import Phase, program_outcome

    rest = np.full(5, float(Phase.REST))
    # At rest before anything moved: still waiting (the program has not been taken yet).
    assert program_outcome(rest, False) == (False, None)
    moving = np.array([Phase.REST, Phase.APPROACH, Phase.PLAY], dtype=float)
    assert program_outcome(moving, False) == (True, None)
    # Back at rest after moving, in this block or an earlier one: completed.
    assert program_outcome(np.array([Phase.RETURN, Phase.REST], dtype=float), False) == \
        (True, "completed")
    assert program_outcome(rest, True) == (True, "completed")
    # Stopped, moving or not before: stopped.
    assert program_outcome(np.array([Phase.PLAY, Phase.STOPPED], dtype=float), False) == \
        (True, "stopped")
    assert program_outcome(np.full(3, float(Phase.STOPPED)), False) == (False, "stopped")
