"""``talus identify``: identify the robot's dynamics and write a description file.

* ``run --backend twin`` (default): the optimised excitation through the position loop on an
  in-process twin, least squares, validation on the benchmark trajectory.
* ``run --backend rt``: the same two trajectories played by the RT process at ``--endpoint``
  as ``identify_excitation`` programs (under its supervisor, recorded there as MCAP files in
  ``--record-dir``), then the fit of ``fit`` on those recordings.
* ``fit --recording R [--validation V]``: least squares on a recording the RT process made;
  writes the description, reports σ per base parameter and the validation's force error (and,
  on the twin, each parameter's error against the twin's truth recorded in the file).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from rt.twin.realism import add_twin_arguments

#: Off by default. Every loop compensates the written offsets (the supervisor's outputs write
#: τ·k − offset: ``rt.safety.supervisor_kernel.outputs``), and so compensated the offsets fit
#: tracks as well as the default fit, not better (twin, one 40 s recording, 13 s pid-vs-paden
#: at 1 kHz, mean |e|: Paden-Panja 7.43 vs 7.41 µm, computed torque 10.92 vs 10.75, adaptive
#: 6.51 vs 6.46; validation force error 1.56 vs 1.55 % of peak): both put the same constant
#: force on each axis, the default fit through its leg masses' weight (which absorbs the
#: offset), the offsets fit through the compensation, since the data cannot tell a leg mass's
#: weight from an offset (estimate.py's docstring, 5.). With --offsets the description keeps
#: the believed leg masses and carries the offsets (a lab that weighed its parts, or wants
#: its amplifiers' offsets reported and compensated).
OFFSETS_HELP = ("also estimate each amplifier's input offset (a constant force per axis, "
                "reported given the believed leg masses and written as drive.amplifier_offset_v"
                ", which every loop then compensates at its outputs); off by default: "
                "compensated, that description tracks as well as the default fit, whose leg "
                "masses absorb the offsets' constant force, not better")


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "run", help="optimised excitation through the position loop (in-process twin, or the "
                    "RT process with --backend rt), least squares on the base and the "
                    "description's parameters, validation on a second trajectory; writes a "
                    "description file for --robot")
    p.add_argument("--out", required=True, help="description file to write (YAML)")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.add_argument("--seconds", type=float, default=40.0, help="excitation length (s)")
    p.add_argument("--robot", help="the description believed before identification "
                                   "(default: nominal; with --backend rt: the RT process's)")
    p.add_argument("--backend", choices=("twin", "rt"), default="twin",
                   help="twin: an in-process twin; rt: the RT process at --endpoint plays and "
                        "records the trajectories")
    p.add_argument("--endpoint", help="the RT process (--backend rt; default: the local one)")
    p.add_argument("--record-dir", default=".",
                   help="where the RT process writes the recordings (--backend rt)")
    add_twin_arguments(p)
    p.add_argument("--compare-tracking", action="store_true",
                   help="also run Paden-Panja and computed torque with the nominal vs the "
                        "identified model (13 s each)")
    p.add_argument("--offsets", action="store_true", help=OFFSETS_HELP)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_run)

    f = commands.add_parser(
        "fit", help="least squares on an identify_excitation recording; writes a description")
    f.add_argument("--recording", required=True, help="the excitation's recording (MCAP)")
    f.add_argument("--validation", help="a second recording to validate the forces on")
    f.add_argument("--robot", help="the description believed before identification "
                                   "(default: the one recorded in the file)")
    f.add_argument("--out", required=True, help="description file to write (YAML)")
    f.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    f.add_argument("--offsets", action="store_true", help=OFFSETS_HELP)
    f.add_argument("--json", action="store_true")
    f.set_defaults(func=_fit)


def _write_description(desc, out: Path, force: bool, inputs: tuple[str, ...] = ()) -> None:
    from rt.output_files import atomic_output

    text = ("# Robot description identified by `talus identify` (SI units).\n"
            + yaml.safe_dump(desc.model_dump(), sort_keys=False))
    with atomic_output(out, "w", force=force, inputs=inputs, what="description") as fh:
        fh.write(text)


def identify(data, validation, nominal, truth=None, truth_offsets_n=None,
             offsets: bool = False) -> tuple[Any, dict[str, Any]]:
    """Base and physical estimates on ``data``, validation on ``validation``: the identified
    description and the figures (truth only on the twin; ``truth_offsets_n``, the twin's
    amplifier offsets in N, when known: else the rows holding an offset have no truth)."""
    from rt.identification.estimate import (
        description_from_physical,
        estimate_base,
        estimate_physical,
        force_prediction_error,
    )
    from rt.model import RobotModel
    from rt.model.regressor import Regressor

    reg = Regressor(RobotModel.from_description(nominal).dyn)
    base = estimate_base(reg, data, offsets=offsets)
    ident = description_from_physical(estimate_physical(reg, data, nominal, offsets=offsets),
                                      nominal, f"{nominal.name}-identified")
    rows = []
    true_base = None
    if truth is not None:
        true_base = base.truth(Regressor(RobotModel.from_description(truth).dyn).theta_base(),
                               truth_offsets_n)
    for k, (n, e, s) in enumerate(zip(base.names, base.theta, base.sigma)):
        row = {"name": n, "estimate": float(e), "sigma": float(s),
               "rel_sigma": float(s / max(abs(e), 1e-12))}
        if true_base is not None and (truth_offsets_n is not None or "offset" not in n):
            t = float(true_base[k])
            row.update({"truth": t, "rel_error": float(abs(e - t) / max(abs(t), 1e-12)),
                        "error_sigmas": float(abs(e - t) / max(s, 1e-300))})
        rows.append(row)
    result: dict[str, Any] = {"base": rows, "residual_rms_n": base.residual_rms_n}
    if base.ripple_n is not None:
        # The screw's friction ripple per axis (N), estimated as nuisance parameters.
        result["friction_ripple_n"] = [float(v) for v in base.ripple_n]
    if base.offset_n is not None and base.offset_sigma_n is not None:
        # The amplifiers' input offsets (N at the slider, V at the amplifier), given the leg
        # masses the lab believes (the nominal description): estimate.py's docstring, 5.
        per_volt = nominal.drive.force_per_volt_n
        amp: dict[str, Any] = {
            "estimate_n": [float(v) for v in base.offset_n],
            "sigma_n": [float(v) for v in base.offset_sigma_n],
            "estimate_v": [float(v / per_volt) for v in base.offset_n],
            "written_v": list(ident.drive.amplifier_offset_v)}
        if truth_offsets_n is not None:
            amp["truth_n"] = [float(v) for v in truth_offsets_n]
        result["amplifier_offsets"] = amp
    if validation is not None:
        result["validation"] = {"nominal": force_prediction_error(nominal, validation),
                                "identified": force_prediction_error(ident, validation)}
    return ident, result


def _run(args) -> int:
    from rt.errors import InputError
    from rt.identification.excitation import optimize_excitation
    from rt.model import RobotModel
    from rt.model.description import load_description
    from rt.output_files import check_output

    if args.seconds < 20.0:
        raise InputError(f"--seconds must be ≥ 20 (two excitation periods), got {args.seconds}")
    out = check_output(args.out, force=args.force, what="description")
    if args.backend == "rt":
        if args.truth or args.ideal_twin or args.compare_tracking:
            raise InputError("--truth, --ideal-twin and --compare-tracking belong to the "
                             "in-process twin (--backend twin); the RT process has its own")
        return _run_rt(args, out)
    nominal = load_description(args.robot) if args.robot else load_description()
    from rt.identification.workflow import record, record_benchmark
    from rt.twin.realism import default_truth, twin_setup

    truth_arg, imp = twin_setup(args, nominal)
    truth = truth_arg or default_truth()
    model = RobotModel.from_description(nominal)
    excitation = optimize_excitation(model)
    data = record(excitation, args.seconds, model, truth, imp)
    validation = record_benchmark(args.seconds, model, truth, imp)
    from rt.twin.realism import RigImperfections

    # The twin's amplifier offsets (its imperfections', volts × the truth's drive), the
    # figure the identified ones are compared with.
    truth_offsets = ((imp or RigImperfections()).amplifier_offsets_v()
                     * truth.drive.force_per_volt_n)
    ident, result = identify(data, validation, nominal, truth, truth_offsets, args.offsets)
    _write_description(ident, out, args.force)
    result = {"out": str(out), "backend": "twin", "excitation_peaks": excitation.peaks(),
              **result}
    if args.compare_tracking:
        from rt.benchmarks.tracking import run_one

        tracking = {}
        for ctrl in ("paden_panja", "computed_torque"):
            for label, robot in (("nominal", nominal), ("identified", ident)):
                _t, e, _ = run_one("pid-vs-paden", ctrl, 13.0, 1000.0, truth, robot,
                                   args.ideal_twin)
                tracking[f"{ctrl}/{label}"] = {"mean_abs_m": float(np.abs(e).mean()),
                                               "rms_m": float(np.sqrt(np.mean(e ** 2)))}
        result["tracking"] = tracking
    return _print(result, args.json)


def _run_rt(args, out: Path) -> int:
    from rt.errors import InputError
    from rt.identification.excitation import benchmark_excitation, optimize_excitation
    from rt.identification.rt_runner import record_on_rt
    from rt.ipc.messages import DEFAULT_ENDPOINT
    from rt.model import RobotModel
    from rt.model.description import load_description

    record_dir = Path(args.record_dir)
    if not record_dir.is_dir():
        raise InputError(f"--record-dir {record_dir} is not a directory")
    nominal = load_description(args.robot) if args.robot else None
    model = RobotModel.from_description(nominal) if nominal else RobotModel.load()
    excitation = optimize_excitation(model)
    recs = record_on_rt(args.endpoint or DEFAULT_ENDPOINT,
                        [("excitation", excitation, args.seconds),
                         ("validation", benchmark_excitation(excitation.q0), args.seconds)],
                        record_dir)
    result = _fit_recordings(recs[0], recs[1], nominal, out, args.force, args.offsets)
    result = {"backend": "rt", "excitation_peaks": excitation.peaks(), **result}
    return _print(result, args.json)


def _fit_recordings(recording: Path, validation: Path | None, nominal, out: Path,
                    force: bool, offsets: bool = False) -> dict[str, Any]:
    from rt.identification.recording import load_excitation_recording

    rec = load_excitation_recording(recording)
    nominal = nominal or rec.robot()
    val = load_excitation_recording(validation) if validation else None
    ident, result = identify(rec.data(nominal),
                             None if val is None else val.data(nominal), nominal, rec.truth(),
                             offsets=offsets)
    _write_description(ident, out, force,
                       (str(recording),) + ((str(validation),) if validation else ()))
    return {"out": str(out), "recordings": {"excitation": str(recording),
                                            "validation": None if val is None
                                            else str(validation)},
            "max_loop_gap_s": rec.max_gap_s, "twin_truth": rec.truth() is not None, **result}


def _fit(args) -> int:
    from rt.model.description import load_description
    from rt.output_files import check_output

    out = check_output(args.out, [args.recording] + ([args.validation] if args.validation
                                                     else []),
                       force=args.force, what="description")
    nominal = load_description(args.robot) if args.robot else None
    result = _fit_recordings(Path(args.recording),
                             Path(args.validation) if args.validation else None,
                             nominal, out, args.force, args.offsets)
    return _print(result, args.json)


def _print(result: dict[str, Any], as_json: bool) -> int:
    if as_json:
        print(json.dumps(result))
        return 0
    print(f"identified description written to {result['out']}")
    truth = any("truth" in b for b in result["base"])
    print(f"{'base parameter':34s} {'estimate':>11s} {'σ':>10s}"
          + (f" {'truth':>11s} {'rel err':>8s} {'err/σ':>6s}" if truth else ""))
    for b in result["base"]:
        line = f"{b['name']:34s} {b['estimate']:11.4g} {b['sigma']:10.3g}"
        if "truth" in b:
            line += (f" {b['truth']:11.4g} {100 * b['rel_error']:7.2f}% "
                     f"{b['error_sigmas']:6.1f}")
        print(line)
    if "amplifier_offsets" in result:
        o = result["amplifier_offsets"]
        print("amplifier input offsets (given the believed leg masses), per axis: "
              + ", ".join(f"{v:+.2f} ± {s:.2f} N" for v, s in zip(o["estimate_n"],
                                                                  o["sigma_n"]))
              + (" (truth " + ", ".join(f"{v:+.2f}" for v in o["truth_n"]) + " N)"
                 if "truth_n" in o else ""))
    if "friction_ripple_n" in result:
        print("screw friction ripple (once per revolution), amplitude per axis: "
              + ", ".join(f"{v:.2f} N" for v in result["friction_ripple_n"]))
    for label, v in result.get("validation", {}).items():
        print(f"validation (benchmark trajectory), {label:10s} model: force RMS error "
              f"{v['rms_n']:.1f} N = {v['rms_pct_of_peak']:.2f} % of the {v['peak_n']:.0f} N peak")
    for k, v in result.get("tracking", {}).items():
        print(f"tracking {k:28s} mean|e| {v['mean_abs_m'] * 1e3:.4f} mm  RMS "
              f"{v['rms_m'] * 1e3:.4f} mm")
    return 0
