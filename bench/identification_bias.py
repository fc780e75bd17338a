"""Which of the realistic twin's unmodelled forces biases which identified parameter.

Records the optimised excitation through the product's position loop on the realistic twin
(as ``talus identify run`` does) together with the twin's internal states at every cycle:
slider positions and speeds (behind the screw), motor positions and speeds (what the encoders
count), motor currents. Each force the identification model leaves out is then computed from
those states and projected onto the estimator's filtered regressor: its least-squares image
is the bias it puts on each base parameter (the biases add up, the fit being linear). Twin
figures.

Components:
* amplifier: the commands as the fit aligns them (held half period, then the description's
  amplifier delay and current loop: ``estimate.amplifier_to_positions``) minus the force the
  twin's amplifiers delivered (the held commands plus their input offsets through the truth's
  current loop, band-limited; see ``main``); ``--half-period-only`` aligns by the held half
  period alone (the estimator before the description had the amplifier); of which the input
  offsets (a constant force per axis: read as gravity, i.e. as masses);
* screw, total: the delivered force minus the truth's rigid-body inverse dynamics at the motor
  states (everything the screw, its friction split and backlash, the ripple, the warming
  grease, the ATI tool and cable add);
* slider inertia: the slider side's rigid-body forces at the slider vs the motor states
  (compliance and backlash seen as a position/acceleration difference);
* friction split: the slider side's friction at the slider's vs the motor's speed;
* cross-coupled Coulomb: what a per-axis implicit Coulomb step (each axis's impulse over its
  own M_ii) would add — M diag(1/M_ii) F_c − F_c — the twin's step before it used the coupled
  mass matrix (``rt.twin.physics.coulomb_step``);
* ripple: the screw's Coulomb ripple with position (both sides), modelled by the estimator's
  nuisance columns by default (so its image here is ≈ 0 unless ``--no-ripple``);
* grease warming: the friction the warming grease took off (the twin's temperature scales
  below 1, both sides of the screw);
* ATI cable: its pull on the platform (weight share and loop stiffness) as actuator forces.

Also the identified errors with each alignment of the commands, from the same recording: the
held half period alone, + the description's amplifier, + the twin's encoder latency (the
encoders read the motor ``encoder_latency_s`` late, which the description cannot say either).

    .venv/bin/python bench/identification_bias.py [--seconds 40] [--no-ripple]
        [--half-period-only]
"""
from __future__ import annotations

import argparse

import numpy as np

import rt.identification.estimate as E
from rt.identification.excitation import optimize_excitation
from rt.identification.workflow import RATE_HZ, truth_base
from rt.model import RobotModel
from rt.model.description import description_from_dict, load_description
from rt.model.regressor import Regressor
from rt.position_loop import build_sim_position_loop
from rt.twin.realism import RigImperfections, default_truth
from rt.twin.twin import Twin

KEY = [f"{p}{i}" for p in ("Jr", "fv", "fc") for i in range(3)]


def record_with_states(excitation, seconds: float, model: RobotModel, truth):
    """(q encoders, τ commanded, states (n, 8, 3): slider q, q̇, motor x, v, current A, cable
    forces N, viscous and Coulomb temperature scales)."""
    twin = Twin(truth, seed=0)
    twin.place((excitation.q0,) * 3)
    pl = build_sim_position_loop("paden_panja", None, excitation, seconds, rate_hz=RATE_HZ,
                                 model=model, twin=twin)
    while pl.reference.phase.data[0] != 1.0:
        pl.loop.run(cycles=1)
    _, start = pl.recorder.drain(0)
    n = round(seconds * RATE_HZ)
    p = twin.plant
    st = np.empty((n, 8, 3))
    for j in range(n):
        pl.loop.run(cycles=1)
        st[j] = (p.q, p.qd, p.xm, p.vm, p.current, p.cable_tau, p.friction[11:14],
                 p.friction[14:17])
    if pl.reference.phase.data[0] == 3.0:
        raise SystemExit("the supervisor stopped the excitation")
    rows, _ = pl.recorder.drain(start)
    rows = rows[:n]
    return (rows[:, 1:4].copy(), rows[:, 13:16] * model.description.drive.force_per_volt_n, st,
            float(p.bodies[32]))


def _inverse_dynamics(model: RobotModel, q, qd, qdd) -> np.ndarray:
    out = np.empty_like(q)
    s = None
    for j in range(len(q)):
        s = model.dyn.state(q[j], qd[j], out=s)
        out[j] = model.dyn.inverse_dynamics(s, qdd[j])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--no-ripple", action="store_true",
                    help="fit without the screw-ripple nuisance columns")
    ap.add_argument("--half-period-only", action="store_true",
                    help="align the commands by the held half period only, not by the "
                         "description's amplifier")
    args = ap.parse_args()
    ripple = not args.no_ripple
    nominal = load_description()
    model = RobotModel.from_description(nominal)
    truth = default_truth()
    q, tau, st, _fpa = record_with_states(optimize_excitation(model), args.seconds, model, truth)
    qs, qds, xm, vm, _cur, cable, sv, sc = (st[:, k] for k in range(8))
    reg = Regressor(model.dyn)
    tb = truth_base(truth, reg.base.names)
    imp = RigImperfections()
    drive = nominal.drive
    latency = drive.model_copy(update={"amplifier_delay_s": drive.amplifier_delay_s
                                       + imp.encoder_latency_s})
    alignments = {"held half period": None, "+ amplifier (description)": drive,
                  "+ encoder latency (twin's)": latency}
    chosen = "held half period" if args.half_period_only else "+ amplifier (description)"
    data = E.prepare(q, tau, RATE_HZ, amplifier=alignments[chosen])
    # Without the offsets' columns: the base parameters as such (Jr not folded with the
    # leg masses), the set this bench's rows have been compared on.
    est = E.estimate_base(reg, data, ripple=ripple, offsets=False)
    w_std, nuisance, _y = E._system(reg, data, ripple)
    keep = E._sliding(data)
    w = np.hstack((w_std[:, reg.base.base_index], nuisance))
    nb = len(reg.base.base_index)

    def image(component: np.ndarray) -> np.ndarray:
        y = E._parallel(data, component).reshape(-1)[keep]
        theta, *_ = np.linalg.lstsq(w, y, rcond=None)
        return theta[:nb]

    idx = [reg.base.names.index(k) for k in KEY]
    print(f"realistic twin, {args.seconds:g} s optimised excitation (twin figures); "
          f"ripple columns {'on' if ripple else 'off'}; commands aligned by: {chosen}; "
          f"residual {est.residual_rms_n:.2f} N")
    print(f"{'':34s}" + "".join(f"{k:>8s}" for k in KEY))
    for label, amp in alignments.items():
        e = est if label == chosen else E.estimate_base(
            reg, E.prepare(q, tau, RATE_HZ, amplifier=amp), ripple=ripple)
        print(f"{'error %, ' + label:34s}"
              + "".join(f"{100 * (e.theta[k] - tb[k]) / tb[k]:+8.2f}" for k in idx))
        print(f"{'error / σ, ' + label:34s}"
              + "".join(f"{(e.theta[k] - tb[k]) / e.sigma[k]:+8.1f}" for k in idx)
              + f"   (residual {e.residual_rms_n:.2f} N)")
    dt = 1.0 / RATE_HZ
    am = np.gradient(vm, dt, axis=0)
    aqs = np.gradient(qds, dt, axis=0)
    # What the amplifiers delivered, band-limited: the held commands plus the input offsets
    # through the truth's current loop and delay, which the twin realises exactly (the mean
    # current over each substep; ``tests/test_amplifier_description.py``). The current the
    # twin ends each period with is not that: after a held period it has all but reached that
    # period's command, i.e. it lags the commands by about a whole period, where the force's
    # band-limited equivalent lags them by T/2 + the amplifier's lag; comparing the aligned
    # commands with it (as this bench did) put a fictitious 0.2-0.4 ms shift, read as
    # −0.2…−0.9 % of fv, on the amplifier's row, and its opposite on the screw's.
    offsets_n = RigImperfections().amplifier_offsets_v() * truth.drive.force_per_volt_n
    f_app = E.amplifier_to_positions(tau + offsets_n, RATE_HZ,
                                     truth.drive.current_loop_bandwidth_hz,
                                     truth.drive.amplifier_delay_s)
    slider_side = truth.model_dump()
    slider_side["drive"]["rotor_inertia_per_axis_kg_m2"] = [1e-12] * 3
    for k in ("viscous_per_axis_n_s_per_m", "coulomb_per_axis_n", "static_per_axis_n"):
        slider_side["friction"][k] = [0.0] * 3
    ms = RobotModel.from_description(description_from_dict(slider_side, "slider side"))
    split = imp.motor_side_friction
    fv = np.array(truth.friction.viscous_axes)
    fc = np.array(truth.friction.coulomb_axes)
    vsm = truth.friction.stiction_smoothing_m_s
    cross = np.empty_like(q)
    s = None
    for j in range(len(q)):
        s = ms.dyn.state(qs[j], qds[j], out=s)
        m = ms.dyn.mass_matrix(s)
        f = (1.0 - split) * fc * np.sign(qds[j])
        cross[j] = m @ (f / np.diag(m)) - f
    phase = 2.0 * np.pi * np.arange(3) / 3.0
    per = imp.friction_ripple_period_m
    rip = 0.5 * imp.friction_ripple * fc * (np.sin(2 * np.pi * qs / per + phase) * np.sign(qds)
                                            + np.sin(2 * np.pi * xm / per + phase)
                                            * np.sign(vm))
    components = {
        # The commands at the positions' instants (held half a period), as the fit sees them.
        "amplifier (aligned τ − delivered)": data.tau - f_app,
        "of which: its input offsets": np.tile(-offsets_n, (len(tau), 1)),
        "screw, total (delivered − τ(xm))": f_app - _inverse_dynamics(
            RobotModel.from_description(truth), xm, vm, am),
        "slider inertia at slider vs motor": (_inverse_dynamics(ms, qs, qds, aqs)
                                              - _inverse_dynamics(ms, xm, vm, am)),
        "friction split (slider vs motor v)": (1.0 - split) * (
            fv * (qds - vm) + fc * (np.tanh(qds / vsm) - np.tanh(vm / vsm))),
        "cross-coupled Coulomb (M_ii step)": cross,
        "screw ripple with position": rip,
        # Friction the warming grease took off (the scales multiply both sides' friction).
        "grease warming": (sv - 1.0) * fv * (split * vm + (1.0 - split) * qds)
        + (sc - 1.0) * fc * (split * np.tanh(vm / vsm) + (1.0 - split) * np.tanh(qds / vsm)),
        # The cable pulls the platform: a force the drives carry, as minus an actuator force.
        "ATI cable (weight share, loop)": -cable,
    }
    print("bias each component puts on the estimate, % of the truth:")
    for label, comp in components.items():
        th = image(comp)
        print(f"  {label:32s}" + "".join(f"{100 * th[k] / tb[k]:+8.2f}" for k in idx)
              + f"   (RMS {np.sqrt(np.mean(comp ** 2)):.1f} N)")
    print("backlash: share of cycles with the motor inside the gap, per axis: "
          + ", ".join(f"{v:.3f}" for v in np.mean(np.abs(xm - qs) < 0.99 * 0.5
                                                 * imp.backlash_m, axis=0)))


if __name__ == "__main__":
    main()
