"""``talus identify run``: identify the robot's dynamics on the twin and write a description."""
from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from rt.twin.realism import add_twin_arguments


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser(
        "run", help="optimised excitation through the position loop, least squares on the base "
                    "and the description's parameters, validation on a second trajectory; "
                    "writes a description file for --robot")
    p.add_argument("--out", required=True, help="description file to write (YAML)")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.add_argument("--seconds", type=float, default=40.0, help="excitation length (s)")
    p.add_argument("--robot", help="the description believed before identification "
                                   "(default: nominal)")
    add_twin_arguments(p)
    p.add_argument("--compare-tracking", action="store_true",
                   help="also run Paden-Panja and computed torque with the nominal vs the "
                        "identified model (13 s each)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_run)


def _write_description(desc, out: Path, force: bool) -> None:
    from rt.errors import InputError

    if out.exists() and not force:
        raise InputError(f"{out} exists; use --force to overwrite it")
    text = ("# Robot description identified by `talus identify run` on the twin (SI units).\n"
            + yaml.safe_dump(desc.model_dump(), sort_keys=False))
    fd, tmp = tempfile.mkstemp(dir=out.parent or Path("."), prefix=f".{out.name}.")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(tmp, out)


def _run(args) -> int:
    from rt.benchmarks.tracking import run_one
    from rt.errors import InputError
    from rt.identification.estimate import (
        description_from_physical,
        estimate_base,
        estimate_physical,
        force_prediction_error,
    )
    from rt.identification.excitation import optimize_excitation
    from rt.identification.workflow import record, record_benchmark, truth_base
    from rt.model import RobotModel
    from rt.model.description import load_description
    from rt.model.regressor import Regressor
    from rt.twin.realism import default_truth, twin_setup

    if args.seconds < 20.0:
        raise InputError(f"--seconds must be ≥ 20 (two excitation periods), got {args.seconds}")
    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError(f"{out} exists; use --force to overwrite it")
    nominal = load_description(args.robot) if args.robot else load_description()
    truth_arg, imp = twin_setup(args, nominal)
    truth = truth_arg or default_truth()
    model = RobotModel.from_description(nominal)
    excitation = optimize_excitation(model)
    data = record(excitation, args.seconds, model, truth, imp)
    reg = Regressor(RobotModel.from_description(nominal).dyn)
    base = estimate_base(reg, data)
    true_base = truth_base(truth, base.names)
    ident = description_from_physical(estimate_physical(reg, data, nominal), nominal,
                                      f"{nominal.name}-identified")
    _write_description(ident, out, args.force)
    validation = record_benchmark(args.seconds, model, truth, imp)
    result: dict[str, Any] = {
        "out": str(out), "excitation_peaks": excitation.peaks(),
        "base": [{"name": n, "estimate": float(e), "sigma": float(s), "truth": float(t),
                  "rel_error": float(abs(e - t) / max(abs(t), 1e-12)),
                  "rel_sigma": float(s / max(abs(e), 1e-12))}
                 for n, e, s, t in zip(base.names, base.theta, base.sigma, true_base)],
        "residual_rms_n": base.residual_rms_n,
        "validation": {"nominal": force_prediction_error(nominal, validation),
                       "identified": force_prediction_error(ident, validation)},
    }
    if args.compare_tracking:
        tracking = {}
        for ctrl in ("paden_panja", "computed_torque"):
            for label, robot in (("nominal", nominal), ("identified", ident)):
                _t, e, _ = run_one("pid-vs-paden", ctrl, 13.0, 1000.0, truth, robot,
                                  args.ideal_twin)
                tracking[f"{ctrl}/{label}"] = {"mean_abs_m": float(np.abs(e).mean()),
                                               "rms_m": float(np.sqrt(np.mean(e ** 2)))}
        result["tracking"] = tracking
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"identified description written to {out}")
    print(f"{'base parameter':34s} {'estimate':>11s} {'σ':>10s} {'truth':>11s} {'rel err':>8s}")
    for b in result["base"]:
        print(f"{b['name']:34s} {b['estimate']:11.4g} {b['sigma']:10.3g} {b['truth']:11.4g} "
              f"{100 * b['rel_error']:7.2f}%")
    for label, v in result["validation"].items():
        print(f"validation (benchmark trajectory), {label:10s} model: force RMS error "
              f"{v['rms_n']:.1f} N = {v['rms_pct_of_peak']:.2f} % of the {v['peak_n']:.0f} N peak")
    for k, v in result.get("tracking", {}).items():
        print(f"tracking {k:28s} mean|e| {v['mean_abs_m'] * 1e3:.4f} mm  RMS "
              f"{v['rms_m'] * 1e3:.4f} mm")
    return 0
