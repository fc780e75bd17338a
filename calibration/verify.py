"""``talus calibrate verify``: a short accuracy check of a calibration, without fitting
(C-Motion CalTester's practice: static loads ≥ 200 N at ≥ 3, ideally ≥ 8 points; ASTM F3109's
figures at grid points).

The check loads the centre, four points near the corners and the four edge midpoints with one
static load each, applies the record's calibration (its matrix and its position-dependent
correction) to the plate's channels and compares with the reference, stage by stage. The plate
description must be the one the record was fitted for (same sha256).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from calibration import dataset, metrics
from calibration.campaign import read_record, run_campaign
from calibration.fit import NonlinearCorrection
from calibration.plan import ProfileKind, Trial, default_plan
from calibration.plate import TWIN_PLATE_FILE, load_plate
from calibration.trial import TRIALS_DIR, TrialData, read_campaign, write_json_atomic
from calibration.twin_runner import make_runner
from rt.errors import ConfigurationError, InputError

MIN_LOAD_N = 200.0
EDGE_INSET_M = 0.05


def check_sites(size_m: tuple[float, float]) -> list[tuple[str, float, float]]:
    hx, hy = size_m[0] / 2 - EDGE_INSET_M, size_m[1] / 2 - EDGE_INSET_M
    return [("V-centre", 0.0, 0.0), ("V-c0", hx, hy), ("V-c1", -hx, hy), ("V-c2", -hx, -hy),
            ("V-c3", hx, -hy), ("V-e0", hx, 0.0), ("V-e1", 0.0, hy), ("V-e2", -hx, 0.0),
            ("V-e3", 0.0, -hy)]


def verify(record_path: Path, out: Path, backend: str, seed: int, load_n: float,
           thresholds: metrics.Thresholds,
           progress: Callable[[int, int, str], None] | None = None,
           plate_file: Path = TWIN_PLATE_FILE, runner_kw: dict[str, Any] | None = None) -> dict:
    """Run the check into the new folder ``out`` and judge it (module docstring).
    ``runner_kw``: :func:`calibration.twin_runner.make_runner`'s keywords for the rt backend
    (endpoint, plate DAQ, operator, camera, move tolerance)."""
    if not math.isfinite(load_n) or load_n < MIN_LOAD_N:
        raise InputError(f"--load must be at least {MIN_LOAD_N:.0f} N (COP is not judged "
                         f"below it), got {load_n}")
    record = read_record(record_path)
    plate = load_plate(plate_file)
    if plate.sha256 != record["plate"]["description_sha256"]:
        raise ConfigurationError(f"{plate_file} is not the plate description {record_path} "
                                 "was fitted for (sha256 differs)")
    C = np.array(record["matrix"]["cal_matrix"])
    correction = NonlinearCorrection.from_record(record["nonlinear_correction"],
                                                 tuple(plate.origin_m))  # type: ignore[arg-type]
    plan = default_plan(registration=record["registration"]["method"])
    trials = [Trial(id=f"{name}-hold", site=name, site_xy_m=(x, y), profile=ProfileKind.TILTED,
                    held_out=True, load_n=load_n) for name, x, y in check_sites(plate.size_m)]
    runner, _ = make_runner(backend, plate, seed, plan.registration, plan.level_sigma_rad(),
                            plan=plan, trials=trials, **(runner_kw or {}))
    try:
        run_campaign(plan, plate_file, runner, out, None, progress, trials=trials)
    finally:
        runner.close()          # the RT runner's heartbeat, control and DAQ
    index = read_campaign(out)
    data = [TrialData.load(out / TRIALS_DIR / f"{e['id']}.npz") for e in index["trials"]]
    clock = dataset.align_clocks(plate, data)
    s = dataset.build_samples(plate, data, [e["site"] for e in index["trials"]], clock)
    w_lin = s.v @ C.T
    stages = {"before": s.v @ plate.nominal_C().T, "linear": w_lin,
              "nonlinear": correction.apply(w_lin)}
    m = {k: metrics.stage_metrics(plate, s, w, [load_n]) for k, w in stages.items()}
    result = {"kind": "talus.calibration_verification", "record": record["id"],
              "load_n": load_n, "sites": [t.site_xy_m for t in trials],
              "robot_time_s": index["robot_time_s"], "metrics": m,
              "verdict": metrics.verdict(m["nonlinear"], thresholds, "nonlinear"),
              "verdict_linear": metrics.verdict(m["linear"], thresholds, "linear"),
              "thresholds": thresholds.record_entry()}
    write_json_atomic(out / "verification.json", _clean(result))
    return _clean(result)


def _clean(x: object) -> dict:
    from calibration.campaign import record_json

    return record_json(x)  # type: ignore[arg-type]
