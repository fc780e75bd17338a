"""The approach's compiled sampling (``rt.references.approach_kernel``) against ruckig itself.

Before issue 16's approach work, ``Approach.update`` called ruckig's online ``Ruckig.update``
every cycle. Now each move is planned once and its phases are evaluated by numba. The oracle
here is that online update, driven as the old cycle drove it (``pass_to_input`` after each
sample, the command's input at each command): every sample of random moves (states beyond
the limits: ruckig's brake pre-phases; target velocities and accelerations; minimum
durations; soft stops; retargets and stops mid-move) must be ruckig's bit for bit, and the
cycle's own rules on top (the target state written on arrival, rest after a stop, the stroke
clamp) as before.

One deliberate difference: every command plans afresh from the current state. The old cycle
left that to ruckig's ``update``, which re-plans only when its input changed; a second soft
stop during a stop has the same input (zero targets, the current state just passed back), so
ruckig went on with the first stop's trajectory and clock while ``Approach.duration`` took
the new plan's (shorter) one: the stop "arrived" early, and the velocity reference stepped to
zero by tens of mm/s (:func:`test_a_stop_during_a_stop_ends_at_rest_without_a_step`). The
oracle therefore plans each command on a fresh ``Ruckig`` (its first ``update`` calculates).
"""
from __future__ import annotations

import numpy as np
from ruckig import (
    ControlInterface,
    DurationDiscretization,
    InputParameter,
    OutputParameter,
    Result,
    Ruckig,
    Synchronization,
)

from rt.references import approach_kernel as ak
from rt.references.approach import (
    DEFAULT_MAX_ACCELERATION_M_S2,
    DEFAULT_MAX_JERK_M_S3,
    DEFAULT_MAX_VELOCITY_M_S,
    STROKE_M,
    Approach,
    ApproachStatus,
    Mode,
)

DT = 1e-3


class _Online:
    """ruckig's online update as the old ``Approach`` drove it (the oracle)."""

    def __init__(self, p, v, a) -> None:
        self.otg = Ruckig(3, DT)
        self.inp = inp = InputParameter(3)
        self.out = OutputParameter(3)
        inp.max_velocity = [DEFAULT_MAX_VELOCITY_M_S] * 3
        inp.max_acceleration = [DEFAULT_MAX_ACCELERATION_M_S2] * 3
        inp.max_jerk = [DEFAULT_MAX_JERK_M_S3] * 3
        self.set_state(p, v, a)

    def set_state(self, p, v, a) -> None:
        inp = self.inp
        inp.current_position, inp.current_velocity = list(p), list(v)
        inp.current_acceleration = list(a)

    def move(self, p, v, a, minimum_duration) -> None:
        self.otg = Ruckig(3, DT)                # plans afresh (module docstring)
        inp = self.inp
        inp.control_interface = ControlInterface.Position
        inp.synchronization = Synchronization.Time
        inp.duration_discretization = DurationDiscretization.Discrete
        inp.target_position, inp.target_velocity = list(p), list(v)
        inp.target_acceleration = list(a)
        inp.minimum_duration = minimum_duration

    def stop(self) -> None:
        self.otg = Ruckig(3, DT)
        inp = self.inp
        inp.control_interface = ControlInterface.Velocity
        inp.synchronization = Synchronization.No
        inp.duration_discretization = DurationDiscretization.Continuous
        inp.target_velocity = [0.0] * 3
        inp.target_acceleration = [0.0] * 3
        inp.minimum_duration = None

    def sample(self) -> tuple[np.ndarray, bool]:
        r = self.otg.update(self.inp, self.out)
        assert r in (Result.Working, Result.Finished)
        out = self.out
        out.pass_to_input(self.inp)
        return (np.array(out.new_position + out.new_velocity + out.new_acceleration),
                r == Result.Finished)


def _random_state(rng):
    p = rng.uniform(0.06, 0.34, 3)
    # half of the states beyond the velocity or acceleration limits (brake pre-phases)
    v = rng.uniform(-0.2, 0.2, 3) * (rng.random() < 0.5)
    a = rng.uniform(-0.7, 0.7, 3) * (rng.random() < 0.5)
    return p, v, a


def test_every_sample_is_ruckigs_online_update_bit_for_bit() -> None:
    rng = np.random.default_rng(16)
    out = np.zeros(9)
    samples = moves = stops = retargets = brakes = 0
    for _ in range(40):
        p, v, a = _random_state(rng)
        ap = Approach(stroke=(-1.0, 2.0))      # no stroke in the way: ruckig's samples only
        ap.reset(p, v, a)
        oracle = _Online(p, v, a)
        # up to three commands per case, each after a random part of the previous move
        for command in range(3):
            if rng.random() < 0.3:
                status = ap.soft_stop()
                oracle.stop()
                stops += 1
            else:
                target = (rng.uniform(0.06, 0.34, 3),
                          rng.uniform(-0.1, 0.1, 3) * (rng.random() < 0.5),
                          rng.uniform(-0.3, 0.3, 3) * (rng.random() < 0.3))
                minimum = float(rng.uniform(0.0, 2.0)) if rng.random() < 0.3 else None
                status = ap.set_target(*target, minimum_duration=minimum)
                oracle.move(*target, minimum)
                moves += 1
            assert status == ApproachStatus.WORKING
            retargets += command > 0
            plan = ap.plan
            brakes += any(plan[ak.P_PROFILES + d * ak.PROFILE_SIZE + ak.PR_BRAKE_DURATION] > 0
                          for d in range(3))
            stopping = ap.mode == Mode.STOPPING
            target_state = plan[ak.P_TARGET:ak.P_TARGET + 9].copy()
            cut = None if command == 2 or rng.random() < 0.4 else int(rng.integers(1, 300))
            k = 0
            while True:
                status = ap.update(out[0:3], out[3:6], out[6:9])
                expected, _ = oracle.sample()
                samples += 1
                k += 1
                if status == ApproachStatus.WORKING:
                    assert out.tobytes() == expected.tobytes(), (k, out - expected)
                else:
                    assert status == ApproachStatus.FINISHED
                    if stopping:            # at rest exactly where ruckig stopped
                        assert out[0:3].tobytes() == expected[0:3].tobytes()
                        assert not out[3:].any()
                    else:                   # exactly the target state
                        assert out.tobytes() == target_state.tobytes()
                    # the next command starts from the state emitted (as the old
                    # _enter_hold wrote it into ruckig's input)
                    oracle.set_state(out[0:3], out[3:6], out[6:9])
                    break
                if cut is not None and k == cut:
                    break                   # a new command mid-move
    assert samples > 20_000 and moves > 40 and stops > 10 and retargets > 30, \
        (samples, moves, stops, retargets)
    assert brakes > 5, brakes               # the brake pre-phases were exercised


def _play(ap: Approach, compiled: bool, n: int) -> tuple[np.ndarray, list[int], int]:
    """``n`` cycles as the compiled sequencer plays them (``working_sample``, else the
    interpreted ``update``) or interpreted throughout; rows of p, v, a, the plan after."""
    out = np.zeros(9)
    rows, statuses, by_kernel = [], [], 0
    for _ in range(n):
        if compiled and ak.working_sample(ap.plan, out[0:3], out[3:6], out[6:9]):
            by_kernel += 1
            statuses.append(int(ApproachStatus.WORKING))
        else:
            statuses.append(int(ap.update(out[0:3], out[3:6], out[6:9])))
        rows.append(np.concatenate([out, ap.plan]))
    return np.array(rows), statuses, by_kernel


def test_the_kernels_samples_are_updates_and_the_stroke_clamp_stays_pythons() -> None:
    """A soft stop that overshoots the stroke's top (slider 0 at 0.39 m rising at 0.1 m/s:
    ruckig's community edition ignores position limits): played by ``working_sample`` with
    ``update`` for what it declines, every output and the whole plan are ``update``'s alone bit
    for bit; no sample leaves the stroke; the samples past the top are clamped by ``update``
    (``ERROR_POSITION_LIMIT``), never written by the kernel."""
    lo, hi = STROKE_M
    aps = []
    for _ in range(2):
        ap = Approach()
        ap.reset([0.39, 0.2, 0.2], [0.1, -0.05, 0.0])
        assert ap.soft_stop() == ApproachStatus.ERROR_OVERSHOOT     # a stop is never refused
        aps.append(ap)
    fused, f_status, by_kernel = _play(aps[0], True, 400)
    plain, p_status, _ = _play(aps[1], False, 400)
    assert fused.tobytes() == plain.tobytes()
    assert f_status == p_status
    clamped = [k for k, s in enumerate(p_status) if s == ApproachStatus.ERROR_POSITION_LIMIT]
    assert clamped and by_kernel > 50, (len(clamped), by_kernel)
    assert fused[:, 0].max() == hi and fused[:, 0:3].min() >= lo
    assert p_status[-1] == ApproachStatus.FINISHED


def test_a_target_beyond_the_stroke_is_refused_and_nothing_plays() -> None:
    """The position limits are ours: a target outside the stroke, and one inside it that the
    move would overshoot on its way, are refused before anything is planned; the running
    move (played compiled) carries on unchanged."""
    lo, hi = STROKE_M
    ap = Approach()
    ap.reset([0.2, 0.2, 0.2])
    assert ap.set_target([0.3, 0.25, 0.15]) == ApproachStatus.WORKING
    out = np.zeros(9)
    for _ in range(200):
        assert ak.working_sample(ap.plan, out[0:3], out[3:6], out[6:9])
    plan = ap.plan.copy()
    assert ap.set_target([hi + 1e-3, 0.2, 0.2]) == ApproachStatus.ERROR_OUTSIDE_STROKE
    assert ap.set_target([0.2, lo - 1e-3, 0.2]) == ApproachStatus.ERROR_OUTSIDE_STROKE
    assert ap.plan.tobytes() == plan.tobytes()
    other = Approach()
    other.reset([0.39, 0.2, 0.2], [0.1, 0.0, 0.0])
    assert other.set_target([0.395, 0.2, 0.2]) == ApproachStatus.ERROR_OVERSHOOT
    assert other.mode == Mode.IDLE and not ak.working_sample(other.plan, out[0:3], out[3:6],
                                                             out[6:9])


def test_a_bad_plan_array_is_refused_by_name() -> None:
    import pytest

    from rt.errors import ConfigurationError

    with pytest.raises(ConfigurationError, match="plan must be float64"):
        Approach(plan=np.zeros(ak.PLAN_SIZE - 1))
    with pytest.raises(ConfigurationError, match="plan must be float64"):
        Approach(plan=np.zeros(ak.PLAN_SIZE, dtype=np.float32))


def test_a_stop_during_a_stop_ends_at_rest_without_a_step() -> None:
    """The sequencer brakes again during a brake (``_brake``: a supervisor soft stop during an
    abort's return): the second stop plans from the current state and ends at rest, each
    cycle's velocity step within the acceleration limit (0.5 m/s² × 1 ms; the old cycle
    stepped by 25.5 mm/s here, arriving after 100 of the 200 cycles left)."""
    ap = Approach()
    ap.reset([0.2, 0.2, 0.2], [0.1, -0.05, 0.0])
    ap.soft_stop()
    out = np.zeros(9)
    for _ in range(100):
        assert ap.update(out[0:3], out[3:6], out[6:9]) == ApproachStatus.WORKING
    ap.reset(out[0:3], out[3:6], out[6:9])
    assert ap.soft_stop() == ApproachStatus.WORKING
    assert abs(ap.duration - 0.2) < 1e-12            # from 0.075 m/s at -0.5 m/s²: v/a + a/j
    prev, steps, cycles = out[3:6].copy(), [], 0
    while ap.update(out[0:3], out[3:6], out[6:9]) == ApproachStatus.WORKING:
        steps.append(np.abs(out[3:6] - prev).max())
        prev = out[3:6].copy()
        cycles += 1
    steps.append(np.abs(out[3:6] - prev).max())
    assert cycles + 1 == 200 and not out[3:].any()
    assert max(steps) <= DEFAULT_MAX_ACCELERATION_M_S2 * DT * (1 + 1e-9), max(steps)


def test_a_sequencer_whose_approach_was_replaced_refuses_to_start() -> None:
    """Its compiled cycle plays the move kept in its own state array: an approach with a plan
    of its own would be planned by Python and never played (a frozen reference)."""
    import pytest

    from rt.errors import ConfigurationError
    from rt.references.sequencer import ProgramReference

    ref = ProgramReference("reference", STROKE_M, DT)
    ref.on_start()                                  # its own approach: fine
    ref.approach = Approach(dt=DT, stroke=STROKE_M)
    with pytest.raises(ConfigurationError, match="plan in the sequencer's state"):
        ref.on_start()
