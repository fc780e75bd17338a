"""The thesis's tracking experiments (4.1.3-4.1.4, figs. 48-50) through the product's own
position loop (``rt.position_loop``: encoders → estimator → model → controller → supervisor →
redundant drive), on the twin.

Experiments (each slider follows the fixed benchmark trajectory, ``benchmark_reference``: the
thesis does not give its trajectory):

* ``pid-vs-paden`` (fig. 48): PID and Paden-Panja on the same trajectory;
* ``parameter-step`` (fig. 50 as the thesis ran it, 4.1.4): at 13 s the *controller's* dynamic
  parameters are changed as if 100 kg were on the platform; nothing touches the robot. Paden-
  Panja keeps the wrong model; the adaptive law restarts from the changed parameters and
  re-identifies the real ones;
* ``payload-step``: a real 100 kg payload put on the platform at 13 s, the controllers keep the
  unloaded model (the product's own experiment).

Metrics: mean absolute and RMS joint error (measured q − q_d, as the thesis plots it) over all
joints and cycles of period 1 (0-13 s) and period 2 (13-26 s), and the peak over 26 s. Profiles:
``product`` (1 kHz) and ``thesis`` (100 Hz as on the thesis's Xenomai rig; ``rate_hz`` gives the
same experiments at 1 kHz). The twin is the realistic one (truth apart from the model, the rig's
imperfections) unless ``ideal``.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from rt.control.experiment import RefFn, benchmark_reference
from rt.control.laws import PdGains
from rt.errors import TalusError
from rt.model import RobotModel
from rt.model.description import RobotDescription
from rt.model.dynamics import Payload
from rt.position_loop import build_sim_position_loop
from rt.safety.limits import RobotLimits
from rt.twin.environment import FreeMotion, PayloadStep
from rt.twin.realism import RigImperfections
from rt.twin.twin import Twin

Q0_M = 0.20
DURATION_S = 26.0
STEP_S = 13.0
PAYLOAD_KG = 100.0
PAYLOAD_COM_M = (0.0, 0.0, 0.10)
#: The supervisor runs as in the product, but with the tracking-error limit widened from 3 mm
#: to 15 mm: the experiment measures how badly PID tracks (the thesis saw 7 mm), which the
#: product's 3 mm limit would stop. The frozen-encoder window is widened from 50 ms to 1 s:
#: under PID at 100 Hz the realistic twin's axes stick (static friction) for tens of ms near
#: velocity reversals while the reference still moves slowly, which the 50 ms check takes for a
#: frozen encoder (a false positive the supervisor's issue must address; see the closing note).
#: Every other limit is the product's. The widened window does not cover the check's force
#: balance, which runs as in the product: at 100 Hz the payload stops the rising axis 0 for
#: ~0.1 s while the law's command climbs to the new load; the balance judges that stall
#: against the loads the still axis held, not only the carried (unloaded) one, so the run
#: goes on (issue 15; before, ``encoder_frozen_0`` stopped Paden-Panja 0.11 s after the step).
BENCH_LIMITS = RobotLimits(max_tracking_error_m=0.015, frozen_encoder_s=1.0)
PROFILES = {"product": 1000.0, "thesis": 100.0}

#: Thesis figures (Xenomai, 100 Hz, real rig), mm.
THESIS = {
    "pid-vs-paden": {"pid": {"peak_abs_mm": 7.0}, "paden_panja": {"peak_abs_mm": 1.0}},
    "parameter-step": {
        "adaptive": {"period1_mean_abs_mm": 0.681, "period2_mean_abs_mm": 0.687,
                     "period1_rms_mm": 0.871, "period2_rms_mm": 0.868},
        "paden_panja": {"period1_mean_abs_mm": 0.615, "period2_mean_abs_mm": 2.809,
                        "period1_rms_mm": 0.813, "period2_rms_mm": 2.923}},
}
THESIS["payload-step"] = THESIS["parameter-step"]

EXPERIMENTS = {
    "pid-vs-paden": ("pid", "paden_panja"),
    "parameter-step": ("paden_panja", "adaptive"),
    "payload-step": ("paden_panja", "adaptive", "pid"),
}


class StoppedBySupervisor(TalusError):
    """The product's supervisor stopped the experiment (the reason is in the message)."""


def gains_for_rate(controller: str, rate_hz: float, axis_mass_kg: float) -> dict | None:
    """Gains for slow loops. The product's gains are tuned for 1 kHz; at 100 Hz their
    derivative action (k_d·T/M ≈ 0.8) plus the estimator's lag is unstable. Below 500 Hz this
    designs a critically damped axis with k_d·T/M = 0.28 (a margin of ~7 to the sampled
    derivative's limit of 2), M the axis's mass (reflected rotor + links, kg): a rule, not a
    fit to any result. ``None``: the controller's defaults."""
    if rate_hz >= 500.0:
        return None
    kd = 0.28 * axis_mass_kg * rate_hz
    kp = kd * kd / (4.0 * axis_mass_kg)
    wn = (kp / axis_mass_kg) ** 0.5
    if controller in ("pid",):
        return {"kp_n_per_m": kp, "kd_n_s_per_m": kd, "ki_n_per_m_s": 0.1 * kp * wn}
    if controller in ("pd_g", "pd_g0", "paden_panja"):
        return {"kp_n_per_m": kp, "kd_n_s_per_m": kd}
    if controller == "adaptive":
        return {"kd_n_s_per_m": kd, "lambda_per_s": kp / kd}
    if controller in ("computed_torque", "computed_torque_ptp"):
        return {"kp_per_s2": wn * wn, "kd_per_s": 2.0 * wn}
    return None


def rate_gains(controller: str, rate_hz: float, model: RobotModel) -> dict | None:
    """``gains_for_rate`` with the axis mass of ``model`` at the benchmark's home."""
    st = model.dyn.state((Q0_M, Q0_M, Q0_M))
    return gains_for_rate(controller, rate_hz, float(model.dyn.mass_matrix(st)[0, 0]))


def metrics(t: np.ndarray, error: np.ndarray) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, window in (("period1", t < STEP_S), ("period2", t >= STEP_S)):
        e = error[window]
        out[name] = {"mean_abs_m": float(np.abs(e).mean()),
                     "rms_m": float(np.sqrt(np.mean(e ** 2)))}
    out["peak_abs_m"] = float(np.abs(error).max())
    return out


def _change_controller_parameters(model: RobotModel, controller) -> None:
    """Thesis 4.1.4: the controller's parameters now describe a 100 kg payload."""
    model.dyn.set_payload(Payload(PAYLOAD_KG, PAYLOAD_COM_M))
    if hasattr(controller, "regressor"):                 # adaptive: its estimate jumps too
        controller.theta[:] = np.clip(controller.regressor.theta_base(), controller.theta_lo,
                                      controller.theta_hi)


def run_one(experiment: str, controller: str, seconds: float = DURATION_S,
            rate_hz: float = 1000.0, truth: RobotDescription | None = None,
            robot: RobotDescription | None = None, ideal: bool = False, seed: int = 0,
            gains: dict | None = None, imperfections: RigImperfections | None = None,
            trajectory: RefFn | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """One controller through one experiment: (trajectory time s, error (n, 3) m, approach s).

    ``robot`` is the description the controllers believe (default the nominal one); ``truth``
    the twin's (default: the realistic twin's truth; with ``ideal`` the model itself);
    ``imperfections`` the realistic twin's unmodelled effects (default: ``RigImperfections()``);
    ``trajectory`` the sliders' reference (default: ``benchmark_reference``; it must start near
    the benchmark's home, ``Q0_M``, where the twin is placed).
    """
    model = RobotModel.from_description(robot) if robot is not None else RobotModel.load()
    if gains is None:
        gains = rate_gains(controller, rate_hz, model)
    env: FreeMotion | PayloadStep = FreeMotion()
    if experiment == "payload-step":
        env = PayloadStep(mass_kg=PAYLOAD_KG, at_s=1e9, com_m=PAYLOAD_COM_M)  # timed below
    twin = (Twin.ideal(truth or model.description, environment=env, seed=seed) if ideal
            else Twin(truth, environment=env, seed=seed, imperfections=imperfections))
    twin.place((Q0_M, Q0_M, Q0_M))
    reference = trajectory if trajectory is not None else benchmark_reference(Q0_M)
    pl = build_sim_position_loop(controller, gains, reference, seconds,
                                 rate_hz=rate_hz, model=model, twin=twin,
                                 robot_limits=BENCH_LIMITS)
    dt = 1.0 / rate_hz
    approach_cycles = 0
    while pl.reference.phase.data[0] != 1.0:            # ruckig approach to the first point
        pl.loop.run(cycles=1)
        approach_cycles += 1
        if approach_cycles * dt > 30.0 or pl.reference.phase.data[0] == 3.0:
            raise StoppedBySupervisor(f"{controller} at {rate_hz:g} Hz did not reach the "
                                      f"trajectory: {_events(pl)}")
    _, start = pl.recorder.drain(0)
    n = round(seconds * rate_hz)
    n_step = min(n, round(STEP_S * rate_hz))
    # The trajectory sample k is produced at cycle k after the approach: the step happens
    # between cycles n_step - 1 and n_step, i.e. at trajectory time 13 s.
    pl.loop.run(cycles=n_step)
    if n_step < n:
        if experiment == "parameter-step":
            _change_controller_parameters(model, pl.controller)
        elif experiment == "payload-step":
            twin.plant.set_payload(Payload(PAYLOAD_KG, PAYLOAD_COM_M))
        pl.loop.run(cycles=n - n_step)
    if pl.reference.phase.data[0] == 3.0:
        raise StoppedBySupervisor(f"{controller} at {rate_hz:g} Hz stopped by the supervisor: "
                                  f"{_events(pl)}")
    rows, _ = pl.recorder.drain(start)
    rows = rows[:n]
    q = rows[:, 1:4]
    q_ref = rows[:, 7:10]
    t = np.arange(len(rows)) * dt
    return t, q - q_ref, approach_cycles * dt


def _events(pl) -> str:
    return "; ".join(f"{e.cause}: {e.message}" for e in pl.events.snapshot()[:3]) or "no event"


def run_experiment(name: str, seconds: float = DURATION_S, rate_hz: float = 1000.0,
                   profile: str = "product", truth: RobotDescription | None = None,
                   robot: RobotDescription | None = None, ideal: bool = False) -> dict:
    """Run one experiment; returns the JSON shape (plus ``rate_hz`` and ``profile``), with the
    gains each controller ran with (``None``: the controller's defaults) and, for the
    parameter step, Paden-Panja's period 2 predicted by statics (``p2_statics``)."""
    results = {}
    model = RobotModel.from_description(robot) if robot is not None else RobotModel.load()
    gains = {ctrl: rate_gains(ctrl, rate_hz, model) for ctrl in EXPERIMENTS[name]}
    approach = 0.0
    for ctrl in EXPERIMENTS[name]:
        try:
            t, err, approach = run_one(name, ctrl, seconds, rate_hz, truth, robot, ideal)
        except StoppedBySupervisor as exc:
            results[ctrl] = {"stopped_by_supervisor": str(exc)}
            continue
        results[ctrl] = metrics(t, err)
    out = {"experiment": name, "profile": profile, "twin": "ideal" if ideal else "realistic",
           "rate_hz": rate_hz, "duration_s": seconds, "approach_s": approach,
           "controllers": results, "thesis": THESIS[name], "gains": gains}
    if name == "parameter-step" and seconds > STEP_S:
        out["p2_statics"] = _p2_statics(gains["paden_panja"], seconds - STEP_S, robot)
    return out


def _p2_statics(gains: dict | None, seconds: float, robot: RobotDescription | None) -> dict:
    """Paden-Panja's period 2 of the parameter step from statics: the model's error Δτ over Kp
    (``rt.benchmarks.thesis_gains``), and the Kp the thesis's figure would need."""
    from rt.benchmarks.thesis_gains import model_error  # imports this module: not at the top

    kp = gains["kp_n_per_m"] if gains else PdGains().kp_n_per_m
    d = float(np.abs(model_error(PAYLOAD_COM_M, seconds=seconds, robot=robot)).mean())
    thesis = THESIS["parameter-step"]["paden_panja"]["period2_mean_abs_mm"] * 1e-3
    return {"kp_n_per_m": kp, "model_error_mean_abs_n": d, "mean_abs_m": d / kp,
            "kp_for_thesis_n_per_m": d / thesis}


def table(results: list[dict]) -> str:
    """The fig. 48/50 table: twin beside thesis (mm)."""
    lines = [(f"{'experiment':15s} {'rate':>6s} {'controller':12s} {'metric':10s} "
             f"{'twin mm':>9s} {'thesis mm':>10s} {'ratio':>6s}")]
    for r in results:
        for ctrl, m in r["controllers"].items():
            if "stopped_by_supervisor" in m:
                lines.append(f"{r['experiment']:15s} {r['rate_hz']:6.0f} {ctrl:12s} stopped: "
                             f"{m['stopped_by_supervisor'].split(': ', 1)[-1][:70]}")
                continue
            th = r["thesis"].get(ctrl, {})
            rows = [("peak", m["peak_abs_m"], th.get("peak_abs_mm"))]
            for p in ("period1", "period2"):
                rows.append((f"{p[:1]}{p[-1]} mean", m[p]["mean_abs_m"],
                             th.get(f"{p}_mean_abs_mm")))
                rows.append((f"{p[:1]}{p[-1]} RMS", m[p]["rms_m"], th.get(f"{p}_rms_mm")))
            if r["experiment"] == "pid-vs-paden":
                rows = rows[:1]
            for label, twin_m, thesis_mm in rows:
                ratio = "" if not thesis_mm else f"{twin_m * 1e3 / thesis_mm:6.2f}"
                lines.append(f"{r['experiment']:15s} {r['rate_hz']:6.0f} {ctrl:12s} {label:10s} "
                             f"{twin_m * 1e3:9.3f} "
                             f"{'' if thesis_mm is None else f'{thesis_mm:10.3f}':>10s} "
                             f"{ratio:>6s}")
        st = r.get("p2_statics")
        if st:
            lines.append(f"{r['experiment']:15s} {r['rate_hz']:6.0f} {'paden_panja':12s} p2 statics: "
                         f"|Δτ| {st['model_error_mean_abs_n']:.0f} N / Kp {st['kp_n_per_m'] / 1e3:.1f}"
                         f" kN/m = {st['mean_abs_m'] * 1e3:.3f} mm; the thesis's 2.809 mm needs Kp "
                         f"{st['kp_for_thesis_n_per_m'] / 1e3:.0f} kN/m "
                         f"({st['kp_for_thesis_n_per_m'] / st['kp_n_per_m']:.2f}×; bench/thesis_gap.py)")
    return "\n".join(lines)

