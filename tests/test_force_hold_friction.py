"""A force hold on the calibration plate is no longer friction-limited (issue 15).

The mechanism (twin figures, 600 N on the 2e6 N/m plate): the gain schedule scales the force
loop's (1 + Kp) and integral rate by k_s/k̂ ≈ 1/8 against the plate, so the command changes by
the sliders' static friction band (≈ 3 × 75 N in z) only after ≈ 44 N of error or the
integral's windup; the slider sticks at a few N of error for 0.3-1 s while ∫e winds ≈ 100 N,
breaks away, slides past the reference and sticks on the other side (hold spread 1.1-1.5 N, a
20 N step 0.5 s). ``rt.control.kernels.error_friction`` adds the model's believed Coulomb
friction in the direction the force error asks where the schedule has weakened the loop (in
full at s ≤ 1/2), past a deadband of 3σ of the ATI's z noise.

The twin here runs the perturbed truth (``rt.twin.realism.default_truth``: Coulomb
64/63/73 N and static 80/79/91 N per axis against the believed 60/75): the law does not assume
the rig's friction. Fast mode, simulated time: deterministic.
"""
from __future__ import annotations

import numpy as np
import pytest

from calibration.push import (
    ForceTableGenerator,
)
from calibration.twin_runner import plate_above_tool_tip
from rt.components.protocol_blocks import HybridController
from rt.control import kernels as ck
from rt.control.force import ExplicitForce, ForceReference
from rt.model import RobotModel
from rt.position_loop import build_protocol_loop, sim_devices
from rt.safety.events import Reaction
from rt.safety.limits import PatientLimits, RobotLimits
from rt.twin.realism import default_truth
from rt.twin.twin import SimClock, Twin

DT = 1e-3
MODEL = RobotModel.load()
POSE = (0.633, 0.0, 0.0)
HOLD_N, STEP_N = 600.0, 20.0


def _run_hold(gains: dict | None) -> tuple[np.ndarray, np.ndarray]:
    """0 → 600 N in 0.5 s, held 1.5 s, +20 N for 0.5 s, back to 600 N for 0.3 s, unloaded in
    0.5 s, on the plate 0.5 mm above the tool tip. Returns the measured F and the reference
    the law tracked (N) for every force-mode cycle."""
    q0 = np.array(MODEL.kin.ik(*POSE).q)
    env = plate_above_tool_tip(MODEL, POSE[0])
    clock = SimClock()
    twin = Twin(default_truth(), env, seed=5, clock=clock)
    twin.place(q0)
    pl = build_protocol_loop(sim_devices(twin, clock), None, MODEL, 1.0 / DT, "fast",
                             patient_limits=PatientLimits(
                                 max_force_n=RobotLimits().max_platform_force_n),
                             force_gains=gains)
    profile = np.concatenate([np.linspace(0.0, HOLD_N, 500), np.full(1500, HOLD_N),
                              np.full(500, HOLD_N + STEP_N), np.full(300, HOLD_N),
                              np.linspace(HOLD_N, 0.0, 500)])
    gen = ForceTableGenerator("hold", profile, POSE, DT, MODEL.kin)
    assert gen.validate().ok
    ctl = pl.graph.component("controller")
    assert isinstance(ctl, HybridController)
    ref = pl.reference
    measured, tracked = [], []
    try:
        ref.request(gen)
        epoch = ref.epoch
        for _ in range(9000):
            pl.loop.run(seconds=DT)
            assert pl.supervisor.reaction < Reaction.SOFT_STOP, pl.events.snapshot()
            if ref.ctrl_mode.data[0] > 0.5:
                measured.append(-float(pl.graph.output("force.wrench")[2]))
                tracked.append(ctl.law_force_ref_n)
            if ref.epoch > epoch and not ref.busy:
                break
    finally:
        pl.graph.stop()
    return np.array(measured), np.array(tracked)


def _figures(f: np.ndarray, fd: np.ndarray) -> tuple[float, float]:
    """(std of F over the last 1 s of the 600 N hold (N), the +20 N step's settling time
    (s): after it F stays within ±2 N of 620 N for the rest of the step's 0.5 s)."""
    k0 = int(np.argmax(fd >= HOLD_N + STEP_N - 1.0))   # (the entry offset leaves < 1 mN)
    hold = f[k0 - 1000:k0]
    dev = np.abs(f[k0:k0 + 500] - (HOLD_N + STEP_N))
    outside = np.flatnonzero(dev > 2.0)
    settle = (outside[-1] + 1) * DT if len(outside) else 0.0
    return float(hold.std()), settle


@pytest.fixture(scope="module")
def uncompensated() -> tuple[float, float]:
    return _figures(*_run_hold({"friction_compensation": 0.0}))


@pytest.fixture(scope="module")
def compensated() -> tuple[float, float]:
    return _figures(*_run_hold(None))


def test_without_compensation_the_hold_sticks_and_slips(uncompensated) -> None:
    """The reproduction (the law before): spread ≥ 0.8 N (measured 1.08), the step ≥ 0.3 s
    (measured: not within ±2 N after 0.5 s)."""
    spread, settle = uncompensated
    assert spread > 0.8
    assert settle > 0.3


def test_the_hold_on_the_plate_is_held_within_the_sensors_noise(compensated) -> None:
    """Spread ≤ 0.5 N (measured 0.30 N; the ATI's own z noise is 0.25 N) and the 20 N step
    within ±2 N in ≤ 0.1 s (measured 0.089 s; 7 ms when the twin's friction is the believed
    one)."""
    spread, settle = compensated
    assert spread <= 0.5
    assert settle <= 0.1


@pytest.mark.parametrize("compiled", [True, False])
def test_the_compensation_is_the_believed_coulomb_level_in_the_errors_direction(
        compiled: bool) -> None:
    """One cycle at the plate's k̂ (2e6, s = 1/8) with the integral held (a transient), the
    feedforward still: the command differs from the uncompensated law's by the model's
    Coulomb level per slider (in full: s ≤ 1/2), up for a force short of the reference and down for
    one beyond; half of it half-way through the ramp (1.5 deadbands); none within the deadband
    and none at the foot's k̂ (≤ k_s: s = 1)."""
    q = MODEL.kin.ik(*POSE).q
    st = MODEL.dyn.state(np.asarray(q), np.zeros(3))
    fc = np.asarray(MODEL.description.friction.coulomb_axes)
    up = np.sign(st.inverse_jacobian()[:, 0])

    def tau(k: float, e: float, comp: float) -> np.ndarray:
        law = ExplicitForce(MODEL, {"estimate_stiffness": False,
                                    "friction_compensation": comp}, compiled=compiled)
        law.k_est = k
        out = np.zeros(3)
        law.update(st, HOLD_N - e, ForceReference(f=HOLD_N, transient=True), DT, out)
        return out

    db = ExplicitForce(MODEL).gains.friction_deadband_n
    for e, share in ((10.0, 1.0), (-10.0, 1.0), (1.5 * db, 0.5), (-1.5 * db, 0.5),
                     (0.9 * db, 0.0), (-0.9 * db, 0.0)):
        np.testing.assert_allclose(tau(2.0e6, e, 1.0) - tau(2.0e6, e, 0.0),
                                   np.sign(e) * share * fc * up, atol=1e-9)
    # The foot: not scheduled, not compensated (bit for bit the law before).
    np.testing.assert_array_equal(tau(2.0e5, 10.0, 1.0), tau(2.0e5, 10.0, 0.0))
    # k̂ = 1.5 k_s (s = 2/3): two thirds of it; it grows from nothing at k_s (no jump).
    np.testing.assert_allclose(tau(3.75e5, 10.0, 1.0) - tau(3.75e5, 10.0, 0.0),
                               (1.0 - 2.0 / 3.0) / 0.5 * fc * up, atol=1e-9)


def test_a_commanded_motion_owns_its_friction() -> None:
    """Where the law commands a slider to move (the feedforward's ż_ff or the pose's roll or
    pitch rate through J_ik), its friction is that motion's: the error's compensation adds only
    what 1 − |tanh(q̇_r / v_s)| leaves: nothing at |q̇_r| ≫ v_s, all of it at rest (compiled
    and interpreted agree)."""
    jik = np.ones((3, 3))
    fc = np.array([60.0, 60.0, 60.0])
    for z_dot, roll_rate, left in ((0.0, 0.0, 1.0), (0.05, 0.0, 0.0), (0.0, 0.05, 0.0)):
        outs = []
        for fn in (ck.error_friction, ck.error_friction.py_func):
            out = np.zeros(3)
            fn(fc, 1e-3, jik, z_dot, roll_rate, 0.0, 10.0, 0.125, 1.0, 0.75, out)
            outs.append(out)
        np.testing.assert_array_equal(outs[0], outs[1])
        np.testing.assert_allclose(outs[0], 60.0 * left * np.ones(3), atol=1e-9)
