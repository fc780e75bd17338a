"""The calibration wizard's steps (Qt-free; each runs on a worker): plan → run on the twin → fit
→ verify → certificate, over the ``calibration`` package as ``talus calibrate`` drives it.

Everything goes into a new work folder (``campaign/``, ``calibration_record.json``,
``verification/``); the certificate goes where the engineer chooses, never over a file. Each
step refuses to run before the one it needs.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rt.errors import InputError

#: (trial index, trial count, trial id) while trials run
Progress = Callable[[int, int, str], None]
#: The backends the wizard offers: the robot twin (realistic, minutes) or the plate driven
#: directly with the planned forces (no robot dynamics; seconds — a dry run of the workflow).
BACKENDS = ("twin", "direct")


@dataclass
class CalibrationFlow:
    """One calibration in ``folder`` (created empty) for the plate described in ``plate_file``."""

    folder: Path
    plate_file: Path
    backend: str = "twin"
    seed: int = 1
    operator: str = "talus GUI"
    plan: Any = None
    trials: list[Any] = field(default_factory=list)
    record: dict[str, Any] | None = None
    verification: dict[str, Any] | None = None

    @property
    def campaign(self) -> Path:
        return self.folder / "campaign"

    @property
    def record_path(self) -> Path:
        return self.folder / "calibration_record.json"

    def make_plan(self, plan_text: str | None = None) -> dict[str, Any]:
        """Step 1: the loading plan (the default one, or YAML text) expanded on the plate.
        Returns the plate outline and the sites, in the plate's frame (m)."""
        import yaml

        from calibration.plan import Plan, default_plan, expand, sites
        from calibration.plate import load_plate

        if self.backend not in BACKENDS:
            raise InputError(f"unknown backend {self.backend!r}: one of {', '.join(BACKENDS)}")
        plate = load_plate(self.plate_file)
        if plan_text:
            try:
                data = yaml.safe_load(plan_text)
            except yaml.YAMLError as exc:
                raise InputError(f"plan: not valid YAML: {exc}") from None
            try:
                plan = Plan.model_validate(data)
            except ValueError as exc:
                raise InputError(f"plan: {exc}") from None
        else:
            plan = default_plan()
        try:
            self.trials = expand(plan, plate.size_m)
            site_list = sites(plan, plate.size_m)
        except ValueError as exc:
            raise InputError(f"plan: {exc}") from None
        self.plan = plan
        return {"plate": plate.name, "size_m": list(plate.size_m),
                "sites": [(s.name, s.x_m, s.y_m, s.held_out) for s in site_list],
                "trials": len(self.trials), "held_out": sum(t.held_out for t in self.trials),
                "loads_n": list(plan.loads_n)}

    def run(self, progress: Progress | None = None) -> dict[str, Any]:
        """Step 2: run every trial on the backend into ``folder/campaign``."""
        from calibration.campaign import run_campaign
        from calibration.plate import load_plate
        from calibration.twin_runner import make_runner

        if self.plan is None:
            raise InputError("make the plan first")
        self.folder.mkdir(parents=True, exist_ok=True)
        plate = load_plate(self.plate_file)
        runner, truth = make_runner(self.backend, plate, self.seed, self.plan.registration,
                                    self.plan.level_sigma_rad())
        index = run_campaign(self.plan, self.plate_file, runner, self.campaign, truth, progress)
        return {"trials": len(index["trials"]), "robot_time_s": index["robot_time_s"]}

    def fit(self) -> dict[str, Any]:
        """Step 3: fit the campaign; the record (with its PASS/FAIL verdict and COP error
        map before/after) is written to ``calibration_record.json``."""
        from calibration.cli import fit_campaign
        from calibration.metrics import Thresholds

        if not (self.campaign / "campaign.json").exists():
            raise InputError("run the campaign first")
        record, _processed = fit_campaign(self.campaign, self.record_path, Thresholds(),
                                          self.operator)
        self.record = record
        return record

    def verify(self, load_n: float = 800.0,
               progress: Progress | None = None) -> dict[str, Any]:
        """Step 4: a short independent check of the fitted calibration (new trials at check
        sites, no fitting)."""
        from calibration.metrics import Thresholds
        from calibration.verify import verify

        if self.record is None:
            raise InputError("fit the calibration first")
        self.verification = verify(self.record_path, self.folder / "verification",
                                   self.backend, self.seed + 100, load_n, Thresholds(),
                                   progress, plate_file=self.plate_file)
        return self.verification

    def certificate(self, out: Path, settings: Any = None, record: Any = None,
                    actor: Any = None) -> dict[str, Any]:
        """Step 5: the certificate PDF at ``out`` (refused if it exists); with a clinical
        record and an actor allowed to, the calibration is stored there too."""
        from reports.certificate import calibration_record_from_dict, render_certificate

        if self.record is None:
            raise InputError("fit the calibration first")
        pages = render_certificate(calibration_record_from_dict(self.record, "the fit"), out,
                                   settings)
        stored = None
        if record is not None and actor is not None:
            stored = record.add_calibration(actor, self.record, str(out))
        return {"out": str(out), "pages": pages, "stored": stored}


def cop_error_points(record: dict[str, Any], stage: str) -> list[tuple[float, float, float]]:
    """(x m, y m, COP error mm) of the record's error map at ``stage`` ("before"/"after"),
    cells without data left out."""
    cmap = record["cop_error_map"]
    grid = cmap[f"{stage}_mm"]
    out = []
    for j, y in enumerate(cmap["y_m"]):
        for i, x in enumerate(cmap["x_m"]):
            v = grid[j][i]
            if v is not None and math.isfinite(float(v)):
                out.append((float(x), float(y), float(v)))
    return out
