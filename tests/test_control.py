"""Controllers on the twin: each converges and tracks; computed torque linearises exactly;
the adaptive law learns a payload; switches are bumpless; gains are validated."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.control.base import CONTROLLERS, Reference, create
from rt.control.experiment import benchmark_reference, run_tracking
from rt.errors import ConfigurationError
from rt.twin.environment import PayloadStep
from rt.twin.realism import RigImperfections

ALL = ["pid", "pd_g", "pd_g0", "paden_panja", "computed_torque_ptp", "computed_torque",
       "adaptive"]


def test_every_thesis_controller_is_registered(robot):
    create("pid", robot)                       # imports the laws
    assert set(ALL) <= set(CONTROLLERS)


def _step_reference(q_from: float, q_to: float, t_step: float = 0.2):
    def ref(t: float, out: Reference) -> None:
        out.q[:] = q_to if t >= t_step else q_from
        out.qd[:] = 0.0
        out.qdd[:] = 0.0
    return ref


@pytest.mark.parametrize("name", ALL)
def test_converges_on_a_step(name):
    # Ideal twin: the 60 µm PID bound is about the law; on the realistic twin backlash and
    # stiction leave a ~0.1 mm limit cycle (issue 15's note).
    log = run_tracking(name, 2.5, _step_reference(0.20, 0.205),
                       twin_kwargs={"imperfections": RigImperfections.none()})
    late = log.t > 2.0
    # 5 mm step. Only PID has integral action and holds within 3 encoder counts (60 µm); for the
    # others static friction (≤ 75 N, not in the model at rest) over a stiffness of 3.4e5 N/m
    # leaves up to 0.22 mm — the thesis's "dead zone" steady-state error.
    bound = 60e-6 if name == "pid" else 0.25e-3
    assert np.abs(log.error[late]).max() < bound
    assert np.abs(log.error[log.t < 0.19]).max() < 1e-4        # held before the step


@pytest.mark.parametrize("name, bound_mm", [
    # Mean absolute error over 2-6 s of the benchmark trajectory (no payload), on the realistic
    # twin (its perturbed truth against the nominal model the laws use, the screw, friction
    # varying with temperature and position, encoder quantization: mean abs of a uniform ±10 µm
    # error is 5 µm); PID/PD pay for the unmodelled inertia and friction. Measured since the
    # twin's slider friction acts through the coupled mass matrix (2026-11-26): Paden-Panja
    # 27.2 µm, computed torque 30.2, adaptive 20.3 (deterministic, simulated time).
    ("pid", 0.3), ("pd_g", 0.6), ("pd_g0", 0.6), ("paden_panja", 0.035),
    ("computed_torque", 0.035), ("adaptive", 0.03), ("computed_torque_ptp", 10.0),
])
def test_tracks_the_benchmark_trajectory(name, bound_mm):
    log = run_tracking(name, 6.0, benchmark_reference())
    window = log.t > 2.0
    assert np.abs(log.error[window]).mean() * 1e3 < bound_mm


def test_pid_clearly_worse_than_paden_panja():
    pid = run_tracking("pid", 8.0, benchmark_reference())
    paden = run_tracking("paden_panja", 8.0, benchmark_reference())
    w = pid.t > 2.0
    assert np.abs(pid.error[w]).max() > 3.0 * np.abs(paden.error[w]).max()
    assert np.abs(pid.error[w]).mean() > 5.0 * np.abs(paden.error[w]).mean()


def test_computed_torque_linearises_the_exact_model(robot):
    ctrl = create("computed_torque", robot)
    dyn = robot.dyn
    rng = np.random.default_rng(7)
    kp, kd = ctrl.gains.kp_per_s2, ctrl.gains.kd_per_s
    for _ in range(20):
        cfg = robot.kin.ik(rng.uniform(0.55, 0.75), rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2))
        q, qd = np.array(cfg.q), rng.normal(0.0, 0.1, 3)
        ref = Reference(q + rng.normal(0, 1e-3, 3), qd + rng.normal(0, 1e-2, 3),
                        rng.normal(0, 1.0, 3))
        st = dyn.state(q, qd)
        tau = np.zeros(3)
        ctrl.update(st, ref, 1e-3, tau)
        qdd = dyn.forward_dynamics(dyn.state(q, qd), tau)
        residual = (qdd - ref.qdd) + kd * (qd - ref.qd) + kp * (q - ref.q)
        # Exact cancellation up to float round-off of ~1e3 N forces over ~200 kg.
        assert np.abs(residual).max() < 1e-9


def test_adaptive_learns_the_payload(robot):
    env = PayloadStep(mass_kg=100.0, at_s=3.0)
    adaptive = run_tracking("adaptive", 8.0, benchmark_reference(), env)
    paden = run_tracking("paden_panja", 8.0, benchmark_reference(), env)
    ctrl = adaptive.controller
    k = ctrl.regressor.base.names.index("slider0.m")
    # The payload's 100 kg load the three legs about equally: slider0.m's base combination holds
    # platform.m / 3 (plus first-moment terms of the 0.1 m-high COM): ≈ +33 kg. The twin is the
    # realistic one, so the estimate must reach the *truth's* loaded value (its masses differ
    # from the nominal ones by up to 8 %) within 25 % of the payload's share: the estimate also
    # absorbs what the model lacks (per-axis friction, screw compliance), and 5 s of this
    # trajectory are not a persistent excitation — the law is a controller, not an identifier.
    from rt.model import RobotModel
    from rt.model.dynamics import Payload
    from rt.model.regressor import Regressor
    from rt.twin.realism import default_truth

    truth = RobotModel.from_description(default_truth())
    truth.dyn.set_payload(Payload(100.0, env.com_m))
    loaded = Regressor(truth.dyn).theta_base()[k]
    assert abs(ctrl.theta[k] - loaded) < 0.25 * 100.0 / 3.0
    assert ctrl.theta[k] - ctrl.nominal[k] > 0.6 * 100.0 / 3.0
    after = adaptive.t > 4.0
    assert np.abs(adaptive.error[after]).mean() < 0.2 * np.abs(paden.error[after]).mean()


def test_bumpless_switch(robot):
    """Switch PID → Paden-Panja mid-trajectory: the force is continuous at the switch."""
    from rt.control.experiment import run_tracking as _run  # noqa: F401  (same harness)
    from rt.estimation.velocity import KalmanVelocityEstimator
    from rt.model.dynamics import State
    from rt.twin.backends import TwinActuators, TwinEncoders
    from rt.twin.twin import SimClock, Twin

    def run(bumpless: bool) -> np.ndarray:
        clock = SimClock()
        twin = Twin(clock=clock)
        reference = benchmark_reference()
        ref = Reference()
        reference(0.0, ref)
        twin.place(ref.q, ref.qd)
        enc, card = TwinEncoders(twin), TwinActuators(twin, 0)
        card.enable()
        ctrl = create("pid", robot, {"ki_n_per_m_s": 4.0e6})
        est, st = KalmanVelocityEstimator(), State()
        q, tau = np.zeros(3), np.zeros(3)
        taus = []
        for k in range(3000):
            clock.t = k * 1e-3
            enc.read_positions_m(q)
            est.update(q, 1e-3)
            reference(clock.t, ref)
            robot.dyn.state(q, est.qd, out=st)
            if k == 2000:
                new = create("paden_panja", robot)
                if bumpless:
                    new.handover(tau, st, ref, 1e-3)
                ctrl = new
            ctrl.update(st, ref, 1e-3, tau)
            card.write_volts(np.clip(tau / 339.29, -6, 6))
            taus.append(tau.copy())
        return np.array(taus)

    smooth = run(True)
    steps = np.abs(np.diff(smooth, axis=0))
    normal = steps[1500:1999].max()
    # At the switch the force changes no more than the laws change it cycle to cycle anyway.
    assert steps[1999].max() <= 2.0 * normal + 1.0
    abrupt = np.abs(np.diff(run(False), axis=0))
    assert abrupt[1999].max() > 5.0 * (steps[1999].max() + 1.0)       # the test can fail


def test_gains_are_validated_and_changed_at_run_time(robot):
    with pytest.raises(ConfigurationError, match="kp_n_per_m"):
        create("pd_g", robot, {"kp_n_per_m": -1.0})
    with pytest.raises(ConfigurationError, match="kp: Extra inputs are not permitted"):
        create("pid", robot, {"kp": 1.0})
    with pytest.raises(ConfigurationError, match="unknown controller 'lqr'"):
        create("lqr", robot)
    ctrl = create("pd_g", robot)
    ctrl.set_gains(kp_n_per_m=1.0e5)
    assert ctrl.gains.kp_n_per_m == 1.0e5
    with pytest.raises(ConfigurationError):
        ctrl.set_gains(kd_n_s_per_m=math.nan)
    assert ctrl.gains.kd_n_s_per_m == 1.7e4                # unchanged by the refused call
