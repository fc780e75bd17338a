"""``talus calibrate plan|run|fit|verify|export|demo`` — the calibration engineer's workflow.

* ``plan --out PLAN.yaml`` writes the default plan (or checks ``--plan FILE``) and prints its
  trials.
* ``run --plan PLAN.yaml --out DIR`` runs the campaign into a new folder. Backends: ``twin``
  (the robot twin pressing the twin plate under force control, the default) and ``direct``
  (the twin plate fed the commanded load, no robot: seconds instead of minutes). The real rig
  (and the twin through the RT process: ``rt``, at ``--endpoint``) plays each trial as the RT
  process's ``calibration_push`` program (``calibration.rt_program``).
* ``fit --campaign DIR`` aligns, fits and judges; writes the calibration record
  (``DIR/calibration_record.json`` unless ``--record``) and prints the figures.
* ``verify --record CAL.json --out DIR`` runs a short CalTester-like check (≥ 200 N at the
  centre and four points near the corners) and applies the record's calibration, without
  fitting; ``--backend rt`` plays it through the RT process, as ``run`` does.
* ``run|verify --backend rt --plate-daq FILE`` (a real plate): this client reads the plate's DAQ
  on the plate's clock while the RT process pushes (:mod:`calibration.plate_daq`); between
  sites it waits for the operator to move the plate and the camera (``--camera``) confirms the
  move (:mod:`calibration.operator`; ``--yes`` for scripts: no waiting, a move outside the
  tolerance is refused). ``--plate-daq twin``: the same path with the twin plate behind the
  comedi driver (:mod:`calibration.twin_plate_daq`), moves simulated.
* ``export --campaign DIR --c3d OUT.c3d --reference-csv REF.csv`` writes the C3D (TYPE 4 or, for
  a Kistler plate, TYPE 3 with calibrated channels;
  fitted CAL_MATRIX, validation trials' raw channels) and the ATI reference in its frame.
* ``demo --out DIR`` runs plan, run, fit and export on the twin.

Every command prints one JSON object; a refused input prints ``{"error": ...}`` and exits 2.
Existing outputs are refused unless ``--force`` (campaign folders must be new).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rt.errors import InputError, TalusError

DEFAULT_SEED = 12


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("plan", help="write or check a loading plan and list its trials")
    p.add_argument("--plan", help="plan file to check (default: the default plan)")
    p.add_argument("--plate", help="plate description YAML (default: the twin plate)")
    p.add_argument("--out", help="write the plan here (YAML)")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p.set_defaults(func=_guard(_plan))

    p = commands.add_parser("run", help="run a campaign into a new folder")
    p.add_argument("--plan", help="plan file (default: the default plan)")
    p.add_argument("--plate", help="plate description YAML (default: the twin plate)")
    p.add_argument("--out", required=True, help="new campaign folder")
    p.add_argument("--backend", choices=("twin", "direct", "rt"), default="twin")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED,
                   help="twin plate's truth and noise seed")
    p.add_argument("--trials", help="comma-separated trial ids (default: all)")
    p.add_argument("--endpoint", help="backend rt: the RT process's endpoint (default: "
                   "its default); it must be configured for the plan's loads "
                   "(patient_limits.max_force_n)")
    _plate_daq_args(p)
    p.set_defaults(func=_guard(_run))

    p = commands.add_parser("fit", help="fit a campaign and write its calibration record")
    p.add_argument("--campaign", required=True)
    p.add_argument("--record", help="record path (default: CAMPAIGN/calibration_record.json)")
    p.add_argument("--operator", default="talus")
    p.add_argument("--degree", type=int, default=3, choices=(1, 2, 3, 4),
                   help="degree of the position-dependent correction")
    p.add_argument("--no-angles", action="store_true",
                   help="do not estimate load-misalignment angles")
    p.add_argument("--allow-partial", action="store_true",
                   help="fit although planned trials are missing")
    _threshold_args(p)
    p.add_argument("--force", action="store_true")
    p.set_defaults(func=_guard(_fit))

    p = commands.add_parser("verify", help="short check of a calibration, without fitting")
    p.add_argument("--record", required=True)
    p.add_argument("--out", required=True, help="new folder for the check's trials")
    p.add_argument("--backend", choices=("twin", "direct", "rt"), default="twin")
    p.add_argument("--plate", help="plate description YAML (default: the twin plate); the "
                   "record's plate")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED)
    p.add_argument("--load", type=float, default=800.0, help="static load (N, ≥ 200)")
    p.add_argument("--endpoint", help="backend rt: the RT process's endpoint")
    _plate_daq_args(p)
    _threshold_args(p)
    p.set_defaults(func=_guard(_verify))

    p = commands.add_parser("export", help="C3D TYPE-4 file and reference CSV of a campaign")
    p.add_argument("--campaign", required=True)
    p.add_argument("--c3d", required=True)
    p.add_argument("--reference-csv", required=True)
    p.add_argument("--record", help="add the exports to this record (written by fit)")
    p.add_argument("--force", action="store_true")
    p.set_defaults(func=_guard(_export))

    p = commands.add_parser("demo", help="default campaign on the twin: plan, run, fit, export")
    p.add_argument("--out", required=True)
    p.add_argument("--backend", choices=("twin", "direct"), default="twin")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED)
    p.set_defaults(func=_guard(_demo))


def _plate_daq_args(p: argparse.ArgumentParser) -> None:
    from calibration.operator import TOLERANCE_M, TOLERANCE_RAD

    p.add_argument("--plate-daq", help="backend rt: the plate's DAQ, read by this client on "
                   "the plate's clock while the RT process pushes: a DAQ file "
                   "(calibration/plate_daq.py) for a real plate, or 'twin' (the twin plate "
                   "behind the same comedi driver). Default: the RT process's twin records "
                   "the plate")
    p.add_argument("--camera", help="real plate: the camera confirming each move, "
                   "BACKEND[:SOURCE] (default opencv:0)")
    p.add_argument("--yes", action="store_true",
                   help="real plate, for scripts: do not wait for the operator between sites; "
                        "a move the camera does not confirm is refused")
    p.add_argument("--move-tolerance-mm", type=float, default=TOLERANCE_M * 1e3,
                   help="how far the registered plate may be from a site's planned pose (mm)")
    p.add_argument("--move-tolerance-deg", type=float,
                   default=math.degrees(TOLERANCE_RAD), help="... and turned (deg)")


def _runner_kw(args: argparse.Namespace) -> dict[str, Any]:
    """make_runner's keywords for the plate's DAQ, the operator and the camera."""
    from calibration.operator import MoveTolerance, terminal_or_refuse

    daq = getattr(args, "plate_daq", None)
    real = daq is not None and daq != "twin"
    tolerance = MoveTolerance(getattr(args, "move_tolerance_mm", 10.0) * 1e-3,
                              math.radians(getattr(args, "move_tolerance_deg", 2.0)))
    return {"endpoint": getattr(args, "endpoint", None), "plate_daq": daq,
            "camera": getattr(args, "camera", None), "tolerance": tolerance,
            "operator": terminal_or_refuse(getattr(args, "yes", False)) if real else None}


def _threshold_args(p: argparse.ArgumentParser) -> None:
    from calibration.metrics import Thresholds

    d = Thresholds()
    p.add_argument("--cop-rms-mm", type=float, default=d.cop_rms_mm)
    p.add_argument("--cop-max-mm", type=float, default=d.cop_max_mm)
    p.add_argument("--force-pct-fs", type=float, default=d.force_pct_fs)
    p.add_argument("--crosstalk-pct", type=float, default=d.crosstalk_pct)


def _thresholds(args: argparse.Namespace):
    from calibration.metrics import Thresholds

    values = (args.cop_rms_mm, args.cop_max_mm, args.force_pct_fs, args.crosstalk_pct)
    if not all(np.isfinite(v) and v > 0 for v in values):
        raise InputError("thresholds must be positive numbers")
    return Thresholds(*values)


def _guard(func: Callable[[argparse.Namespace], dict]) -> Callable[[argparse.Namespace], int]:
    def run(args: argparse.Namespace) -> int:
        try:
            out = func(args)
        except TalusError as exc:
            print(json.dumps({"error": str(exc)}))
            return 2
        print(json.dumps(out, indent=1))
        return 0
    return run


def _plate_file(args: argparse.Namespace) -> Path:
    from calibration.plate import TWIN_PLATE_FILE

    return Path(args.plate) if getattr(args, "plate", None) else TWIN_PLATE_FILE


def _load_plan(args: argparse.Namespace):
    from calibration.plan import default_plan, load_plan

    return load_plan(args.plan) if args.plan else default_plan()


def _plan(args: argparse.Namespace) -> dict:
    import yaml

    from calibration.plan import expand, force_profile
    from calibration.plate import load_plate
    from calibration.trial import write_json_atomic

    plan = _load_plan(args)
    plate = load_plate(_plate_file(args))
    try:
        trials = expand(plan, plate.size_m)
    except ValueError as exc:
        raise InputError(f"plan: {exc}") from None
    if args.out:
        out = Path(args.out)
        if out.suffix == ".json":
            write_json_atomic(out, plan.model_dump(mode="json"), force=args.force)
        else:
            if out.exists() and not args.force:
                raise InputError(f"{out} exists; choose another name or pass --force")
            text = "# talus calibration plan (calibration/plan.py documents every field)\n" + \
                yaml.safe_dump(plan.model_dump(mode="json"), sort_keys=False)
            tmp = out.with_name(out.name + ".tmp")
            tmp.write_text(text, encoding="utf-8")
            tmp.replace(out)
    duration = sum(len(force_profile(plan, t, 1e-3)) * 1e-3 for t in trials)
    return {"plan": plan.name, "plate": plate.name, "trials": len(trials),
            "held_out_trials": sum(t.held_out for t in trials),
            "sites": len({t.site for t in trials}), "loads_n": list(plan.loads_n),
            "profile_time_s": round(duration, 1), "written": args.out,
            "trial_ids": [t.id for t in trials]}


def _progress(k: int, n: int, trial_id: str) -> None:
    sys.stderr.write(f"\r[{k + 1}/{n}] {trial_id:<20}")
    sys.stderr.flush()
    if k + 1 == n:
        sys.stderr.write("\n")


def _run(args: argparse.Namespace) -> dict:
    from calibration.campaign import run_campaign
    from calibration.plate import load_plate
    from calibration.twin_runner import make_runner

    plan = _load_plan(args)
    plate_file = _plate_file(args)
    plate = load_plate(plate_file)
    runner, truth = make_runner(args.backend, plate, args.seed, plan.registration,
                                plan.level_sigma_rad(), plan=plan, **_runner_kw(args))
    only = [t.strip() for t in args.trials.split(",")] if args.trials else None
    t0 = time.perf_counter()
    try:
        index = run_campaign(plan, plate_file, runner, Path(args.out), truth, _progress, only)
    finally:
        runner.close()       # the RT runner's heartbeat and control of the robot
    return {"campaign": args.out, "trials": len(index["trials"]),
            "robot_time_s": round(index["robot_time_s"], 1),
            "wall_time_s": round(time.perf_counter() - t0, 1), "backend": args.backend}


def fit_campaign(folder: Path, record_path: Path, thresholds, operator: str,
                 degree: int = 3, angles: bool = True, allow_partial: bool = False,
                 force: bool = False) -> tuple[dict, Any]:
    from calibration.campaign import ReferenceSensor, build_record, process, record_json
    from calibration.trial import write_json_atomic

    if record_path.exists() and not force:
        raise InputError(f"{record_path} exists; choose another name or pass --force")
    p = process(folder, degree, angles, allow_partial)
    record = record_json(build_record(folder, p, thresholds, ReferenceSensor(), operator))
    write_json_atomic(record_path, record, force=force)
    return record, p


def _summary(record: dict) -> dict:
    m = record["metrics"]
    return {"record": record["id"], "verdict": record["verdict"],
            "cop_rms_mm": {k: m[k]["cop_rms_mm"] for k in m},
            "cop_max_mm": {k: m[k]["cop_max_mm"] for k in m},
            "force_pct_fs": {k: max(x for x in m[k]["force_pct_fs"][:3] if x is not None)
                             for k in m},
            "uncertainty_k2": {"force_n": record["uncertainty"]["force_n"][:3],
                               "cop_mm": record["uncertainty"]["cop_mm"]},
            "not_identified": [f"{r}<-{c}" for i, r in enumerate(record["matrix"]["row_order"])
                               for j, c in enumerate(record["matrix"]["channel_order"])
                               if not record["matrix"]["identified"][i][j]]}


def _fit(args: argparse.Namespace) -> dict:
    folder = Path(args.campaign)
    path = Path(args.record) if args.record else folder / "calibration_record.json"
    record, p = fit_campaign(folder, path, _thresholds(args), args.operator, args.degree,
                             not args.no_angles, args.allow_partial, args.force)
    return {"written": str(path), **_summary(record),
            "processing_time_s": round(p.processing_time_s, 2)}


def _export(args: argparse.Namespace) -> dict:
    from calibration.c3d_export import export
    from calibration.campaign import process, read_record
    from calibration.trial import write_json_atomic

    folder = Path(args.campaign)
    record = read_record(Path(args.record)) if args.record else None
    p = process(folder, allow_partial=True)
    if record is not None and not np.allclose(np.array(record["matrix"]["cal_matrix"]),
                                              p.linear.C, rtol=1e-9, atol=1e-12):
        raise InputError(f"{args.record} was not fitted from {folder} (its matrix differs)")
    exports = export(folder, p, Path(args.c3d), Path(args.reference_csv), args.force)
    if record is not None:
        record["exports"] = [e for e in record.get("exports", [])
                             if e["path"] not in {x["path"] for x in exports}] + exports
        write_json_atomic(Path(args.record), record, force=True)
    return {"exports": exports, "record_updated": args.record}


def _verify(args: argparse.Namespace) -> dict:
    from calibration.verify import verify

    return verify(Path(args.record), Path(args.out), args.backend, args.seed, args.load,
                  _thresholds(args), _progress, _plate_file(args), runner_kw=_runner_kw(args))


def _demo(args: argparse.Namespace) -> dict:
    from calibration.campaign import run_campaign
    from calibration.metrics import Thresholds
    from calibration.plan import default_plan
    from calibration.plate import TWIN_PLATE_FILE, load_plate
    from calibration.twin_runner import make_runner

    out = Path(args.out)
    if out.exists() and any(out.iterdir()):
        raise InputError(f"{out} exists and is not empty; choose a new folder")
    plan = default_plan()
    plate = load_plate(TWIN_PLATE_FILE)
    runner, truth = make_runner(args.backend, plate, args.seed, plan.registration,
                                    plan.level_sigma_rad())
    t0 = time.perf_counter()
    campaign = out / "campaign"
    index = run_campaign(plan, TWIN_PLATE_FILE, runner, campaign, truth, _progress)
    wall = time.perf_counter() - t0
    record_path = out / "calibration_record.json"
    record, p = fit_campaign(campaign, record_path, Thresholds(), "talus demo")
    from calibration.c3d_export import export
    from calibration.trial import write_json_atomic

    record["exports"] = export(campaign, p, out / "plate_calibrated.c3d",
                               out / "reference.csv")
    write_json_atomic(record_path, record, force=True)
    return {"folder": str(out), "record": str(record_path), **_summary(record),
            "robot_time_s": round(index["robot_time_s"], 1), "run_wall_time_s": round(wall, 1),
            "processing_time_s": round(p.processing_time_s, 2),
            "exports": [e["path"] for e in record["exports"]],
            "next": f"talus calibrate export --campaign {campaign} --c3d OUT.c3d "
                    "--reference-csv REF.csv"}
