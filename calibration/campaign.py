"""A calibration campaign end to end: run the plan's trials into a folder, then process the
folder into a calibration record (``docs/calibration_record.md`` is the record's contract).
"""
from __future__ import annotations

import dataclasses
import importlib.metadata
import math
import shutil
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from calibration import dataset, fit, metrics
from calibration.plan import Plan, Trial, expand, force_profile, sites, tilt_profile, trial_pose
from calibration.plate import PlateDescription, cop_F, load_plate
from calibration.trial import (
    CAMPAIGN_FILE,
    CAMPAIGN_KIND,
    TRIALS_DIR,
    SampleSink,
    TrialData,
    TrialRunner,
    read_campaign,
    read_json_of_kind,
    sha256_file,
    write_json_atomic,
)
from calibration.twin_plate import PlateTruth, expected_matrix
from rt.ati.twin_sensor import DELTA_SI_660_60_RANGES
from rt.errors import ConfigurationError, InputError

DT = 1.0e-3
RECORD_KIND = "talus.calibration_record"
PLATE_COPY = "plate.yaml"
TRUTH_FILE = "twin_truth.json"


@dataclass(frozen=True)
class ReferenceSensor:
    """The reference load cell and its certificate (defaults: the twin's ATI Delta SI-660-60).

    ``accuracy_pct_fs``: the certificate's measurement uncertainty per axis, % of full scale,
    read as expanded (95 %, k = 2) values. The defaults are of the order ATI states for its
    Delta sensors, not a certificate: replace them with the real sensor's.
    """

    model: str = "ATI Delta SI-660-60 (digital twin)"
    serial: str = "TWIN-ATI"
    calibration_certificate: str = "twin (no certificate)"
    calibration_date: str = ""
    accuracy_pct_fs: tuple[float, ...] = (1.25, 1.25, 0.75, 1.0, 1.0, 1.5)
    full_scale: tuple[float, ...] = DELTA_SI_660_60_RANGES

    def record_entry(self) -> dict:
        d = dataclasses.asdict(self)
        d["accuracy_pct_fs"] = list(self.accuracy_pct_fs)
        d["full_scale"] = list(self.full_scale)
        return d


def software_version() -> str:
    try:
        return importlib.metadata.version("talus")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


# ------------------------------------------------------------------------------ running
def run_campaign(plan: Plan, plate_file: Path, runner: TrialRunner, out: Path,
                 truth: PlateTruth | None = None,
                 progress: Callable[[int, int, str], None] | None = None,
                 only: list[str] | None = None, trials: list[Trial] | None = None,
                 samples: SampleSink | None = None) -> dict:
    """Run every trial of ``plan`` (or the ids in ``only``, or the explicit ``trials``) into the
    new folder ``out``; ``samples`` receives each trial's samples while it runs (the runner's
    :attr:`~calibration.trial.TrialRunner.samples`)."""
    plate = load_plate(plate_file)
    if out.exists() and any(out.iterdir()):
        raise InputError(f"{out} exists and is not empty; choose a new campaign folder")
    trials = list(trials) if trials is not None else expand(plan, plate.size_m)
    if only:
        unknown = sorted(set(only) - {t.id for t in trials})
        if unknown:
            raise InputError(f"unknown trial id(s) {', '.join(unknown)}")
        trials = [t for t in trials if t.id in only]
    (out / TRIALS_DIR).mkdir(parents=True, exist_ok=True)
    if samples is not None:
        runner.samples = samples
    shutil.copyfile(plate_file, out / PLATE_COPY)
    entries = []
    t0 = time.perf_counter()
    for k, trial in enumerate(trials):
        if progress is not None:
            progress(k, len(trials), trial.id)
        profile = force_profile(plan, trial, DT)
        tilt = tilt_profile(plan, trial, DT)
        pose = trial_pose(plan, trial)
        data = (runner.run(trial.id, trial.site_xy_m, pose, profile, DT) if tilt is None
                else runner.run(trial.id, trial.site_xy_m, pose, profile, DT, tilt_rad=tilt))
        digest = data.save(out / TRIALS_DIR / f"{trial.id}.npz")
        entries.append({**trial.model_dump(mode="json"), "sha256": digest})
    index = {"schema_version": 1, "kind": CAMPAIGN_KIND, "plan": plan.model_dump(mode="json"),
             "plate_file": PLATE_COPY, "plate_sha256": sha256_file(out / PLATE_COPY),
             "runner": type(runner).__name__, "robot_time_s": runner.robot_time_s,
             "processing_time_s": time.perf_counter() - t0, "trials": entries}
    if truth is not None:
        write_json_atomic(out / TRUTH_FILE, truth_entry(plate, truth))
    write_json_atomic(out / CAMPAIGN_FILE, index)
    return index


def truth_entry(plate: PlateDescription, truth: PlateTruth) -> dict:
    s = dataclasses.asdict(truth.settings)
    return {"settings": s, "E": truth.E.tolist(), "origin_true_m": truth.origin_true_m.tolist(),
            "C_true": truth.C_true.tolist(), "C_expected": expected_matrix(plate, truth).tolist()}


# ------------------------------------------------------------------------------ processing
@dataclass
class Processed:
    plate: PlateDescription
    index: dict
    plan: Plan
    clock: object
    train: dataset.Samples
    held: dataset.Samples
    linear: fit.LinearFit
    nonlinear: fit.NonlinearCorrection
    stages_held: dict[str, np.ndarray]
    stages_all: dict[str, np.ndarray]
    all_samples: dataset.Samples
    processing_time_s: float


def process(folder: Path, degree: int = 3, estimate_angles: bool = True,
            allow_partial: bool = False, tool_squareness_rad: float = fit.TOOL_SQUARENESS_RAD
            ) -> Processed:
    """Align, fit and evaluate a campaign folder (no file written)."""
    t0 = time.perf_counter()
    index = read_campaign(folder)
    plate = load_plate(folder / index["plate_file"])
    plan = Plan.model_validate(index["plan"])
    planned = {t.id for t in expand(plan, plate.size_m)}
    missing = sorted(planned - {e["id"] for e in index["trials"]})
    if missing and not allow_partial:
        raise ConfigurationError(f"{folder}: the campaign is missing planned trial(s) "
                                 f"{', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''}; "
                                 "run them, or fit with --allow-partial")
    entries = index["trials"]
    trials = [TrialData.load(folder / TRIALS_DIR / f"{e['id']}.npz") for e in entries]
    clock = dataset.align_clocks(plate, trials)
    samples = dataset.build_samples(plate, trials, [e["site"] for e in entries], clock)
    held_trial = np.array([bool(entries[k]["held_out"]) for k in range(len(entries))])
    train = samples.select(~held_trial[samples.trial])
    held = samples.select(held_trial[samples.trial])
    if len(train) < 6 * plate.n_channels:
        raise InputError(f"{folder}: {len(train)} training samples are too few to fit "
                         f"{6 * plate.n_channels} matrix entries")
    if len(held) == 0:
        raise InputError(f"{folder}: no held-out trial: the fit cannot be validated")
    # Each site's angle prior: its registration's rotation uncertainty and the tool's
    # squareness, combined.
    angle_prior: dict[str, float] = {}
    for e, d in zip(entries, trials):
        angle_prior[e["site"]] = max(angle_prior.get(e["site"], 0.0),
                                     math.hypot(d.sigma_rotation_rad, tool_squareness_rad))
    lin = fit.fit_linear(plate, train, estimate_angles=estimate_angles,
                         angle_prior_rad=angle_prior)
    nl = fit.fit_nonlinear(plate, lin, train, degree)
    C0 = plate.nominal_C()

    def stages(s: dataset.Samples) -> dict[str, np.ndarray]:
        w_lin = s.v @ lin.C.T
        return {"before": s.v @ C0.T, "linear": w_lin, "nonlinear": nl.apply(w_lin)}

    return Processed(plate, index, plan, clock, train, held, lin, nl, stages(held),
                     stages(samples), samples, time.perf_counter() - t0)


def uncertainty(p: Processed, ref: ReferenceSensor, sig_t: float, sig_r: float) -> dict:
    """Expanded uncertainty (k = 2) of the calibrated plate's forces, moments and COP.

    Sources (standard uncertainties, combined in quadrature): the reference sensor's accuracy
    (its certificate's 95 % values halved), the registration (rotation → shear from the largest vertical
    load; translation → COP and moments), the fit's held-out residual (nonlinear stage, RMS).
    """
    fs_ref = np.array(ref.full_scale)
    u_ref = np.array(ref.accuracy_pct_fs) / 100.0 * fs_ref / 2.0
    fz_max = float(np.max(p.all_samples.w_ref[:, 2]))
    e = p.stages_held["nonlinear"] - p.held.w_ref
    u_fit = np.sqrt(np.mean(e ** 2, axis=0))
    cop, _ = cop_F(p.stages_held["nonlinear"], p.plate.origin_m)
    big = p.held.w_ref[:, 2] >= metrics.COP_MIN_LOAD_N
    d = np.linalg.norm(cop[big] - p.held.p_ref[big, :2], axis=1)
    u_cop_fit = float(np.sqrt(np.nanmean(d ** 2))) if big.any() else 0.0
    u_reg_force = np.array([fz_max * sig_r, fz_max * sig_r, 0.0])
    u_reg_moment = np.array([fz_max * sig_t, fz_max * sig_t, 0.0])
    u_force = np.sqrt(u_ref[:3] ** 2 + u_reg_force ** 2 + u_fit[:3] ** 2)
    u_moment = np.sqrt(u_ref[3:] ** 2 + u_reg_moment ** 2 + u_fit[3:] ** 2)
    # COP from the reference's moment accuracy at a mid-range load, registration, fit.
    f_typ = float(np.median(p.held.w_ref[big, 2])) if big.any() else fz_max
    u_cop_ref = float(np.hypot(u_ref[3], u_ref[4]) / max(f_typ, 1.0))
    u_cop = math.sqrt(u_cop_ref ** 2 + sig_t ** 2 + u_cop_fit ** 2)
    budget = []
    for i, axis in enumerate(("Fx", "Fy", "Fz")):
        budget.append({"source": f"reference sensor accuracy, {axis}", "value": float(u_ref[i]),
                       "unit": "N"})
    for i, axis in enumerate(("Mx", "My", "Mz")):
        budget.append({"source": f"reference sensor accuracy, {axis}",
                       "value": float(u_ref[3 + i]), "unit": "N·m"})
    budget += [
        {"source": "registration rotation (shear from max Fz)", "value": float(fz_max * sig_r),
         "unit": "N"},
        {"source": "registration translation (COP)", "value": sig_t * 1e3, "unit": "mm"},
        {"source": "fit residual, held-out, Fz (RMS)", "value": float(u_fit[2]), "unit": "N"},
        {"source": "fit residual, held-out, COP (RMS)", "value": u_cop_fit * 1e3, "unit": "mm"},
        {"source": "reference moment accuracy at the median load (COP)",
         "value": u_cop_ref * 1e3, "unit": "mm"},
    ]
    # The contract's force_n has six entries: the expanded uncertainty per wrench axis
    # (Fx, Fy, Fz in N, then Mx, My, Mz in N·m, repeated in moment_nm).
    return {"k": 2, "force_n": (2.0 * np.r_[u_force, u_moment]).tolist(),
            "moment_nm": (2.0 * u_moment).tolist(),
            "cop_mm": 2.0 * u_cop * 1e3, "budget": budget,
            "standard_uncertainties": "budget values are 1 σ; force_n, moment_nm, cop_mm are "
                                      "expanded (k = 2)"}


def build_record(folder: Path, p: Processed, thresholds: metrics.Thresholds,
                 ref: ReferenceSensor, operator: str,
                 now: Callable[[], datetime] = lambda: datetime.now(UTC)) -> dict:
    """The calibration record (``docs/calibration_record.md``)."""
    levels = list(p.plan.loads_n) + [t.load_n for t in p.plan.tilted]
    m = {stage: metrics.stage_metrics(p.plate, p.held, w, levels)
         for stage, w in p.stages_held.items()}
    # Repeatability is a property of the plate at one stage: from every trial (repeats are in
    # the training set), per stage.
    for stage, w in p.stages_all.items():
        m[stage]["repeatability_pct_fs"] = metrics.stage_metrics(
            p.plate, p.all_samples, w, levels)["repeatability_pct_fs"]
    verdicts = {stage: metrics.verdict(m[stage], thresholds, stage) for stage in m}
    trials = p.index["trials"]
    site_xy = {e["site"]: tuple(e["site_xy_m"]) for e in trials}
    cmap = metrics.cop_error_map(p.plate, p.all_samples,
                                 {"before": p.stages_all["before"],
                                  "after": p.stages_all["nonlinear"]}, site_xy)
    # Registration: the trials' registrations (one per site), summarized.
    regs: dict[str, tuple[np.ndarray, float, float]] = {}
    for e in trials:
        d = TrialData.load(folder / TRIALS_DIR / f"{e['id']}.npz")
        regs.setdefault(e["site"], (d.T_BF, d.sigma_translation_m, d.sigma_rotation_rad))
    sig_t = float(np.sqrt(np.mean([r[1] ** 2 for r in regs.values()])))
    sig_r = float(np.sqrt(np.mean([r[2] ** 2 for r in regs.values()])))
    centre = min(regs, key=lambda k: math.hypot(*site_xy[k]))
    created = now().astimezone(UTC)
    record = {
        "schema_version": 1,
        "kind": RECORD_KIND,
        "id": f"CAL-{created:%Y%m%d-%H%M%S}-{uuid.uuid4().hex[:6]}",
        "created_utc": created.strftime("%Y-%m-%dT%H:%M:%SZ"),
        "operator": operator,
        "software_version": software_version(),
        "plate": p.plate.record_entry(),
        "reference_sensor": ref.record_entry(),
        "registration": {
            "method": p.plan.registration, "T_robot_plate": regs[centre][0].tolist(),
            "sigma_translation_mm": sig_t * 1e3, "sigma_rotation_deg": math.degrees(sig_r),
            "per_site": {k: {"T_robot_plate": v[0].tolist(),
                             "sigma_translation_mm": v[1] * 1e3,
                             "sigma_rotation_deg": math.degrees(v[2])} for k, v in regs.items()},
            "reference_site": centre},
        "plan": {"grid_m": [list(site_xy[s.name]) for s in sites(p.plan, p.plate.size_m)],
                 "loads_n": list(p.plan.loads_n),
                 "trials": [{"id": e["id"], "site": e["site"], "profile": e["profile"],
                             "held_out": e["held_out"], "site_xy_m": e["site_xy_m"],
                             "roll_deg": e["roll_deg"], "pitch_deg": e["pitch_deg"]}
                            for e in trials],
                 "name": p.plan.name, "robot_time_s": p.index.get("robot_time_s")},
        "thresholds": thresholds.record_entry(),
        "metrics": m,
        "metrics_basis": "held-out sites and trials (never used by the fit); "
                         "repeatability from the repeated trials of the whole campaign",
        "verdict": verdicts["nonlinear"],
        "verdict_by_stage": verdicts,
        "cop_error_map": {"x_m": cmap.x_m, "y_m": cmap.y_m, "before_mm": cmap.grids["before"],
                          "after_mm": cmap.grids["after"],
                          "after_stage": "nonlinear", "basis": "mean per site, all trials"},
        "matrix": p.linear.record_entry(p.plate),
        "nonlinear_correction": p.nonlinear.record_entry(),
        "clock_alignment": p.clock.record_entry(),  # type: ignore[attr-defined]
        "uncertainty": uncertainty(p, ref, sig_t, sig_r),
        "exports": [],
        "campaign": {"folder": str(folder), "campaign_sha256": sha256_file(folder / CAMPAIGN_FILE),
                     "processing_time_s": p.processing_time_s,
                     "training_samples": len(p.train), "held_out_samples": len(p.held)},
    }
    return record


def record_json(record: dict) -> dict:
    """NaN/inf → null, numpy → lists/floats (the record is strict JSON)."""
    def clean(x: object) -> object:
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        if isinstance(x, np.ndarray):
            return clean(x.tolist())
        if isinstance(x, (np.floating, float)):
            return float(x) if math.isfinite(float(x)) else None
        if isinstance(x, (np.integer,)):
            return int(x)
        if isinstance(x, np.bool_):
            return bool(x)
        return x
    return clean(record)  # type: ignore[return-value]


def read_record(path: Path) -> dict:
    return read_json_of_kind(path, RECORD_KIND, "talus calibration record")
