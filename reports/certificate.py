"""The force-plate calibration certificate (PDF) from a calibration record (JSON).

The record's contract (schema_version 1) is shared with ``calibration/`` (which writes it with
``talus calibrate fit``) and the clinical database: :class:`CalibrationRecord` validates the
keys the certificate needs and keeps any key the calibration engineer adds. Units SI (m, N,
N·m) unless the key says ``_mm``, ``_pct``, ``_deg``; matrices are lists of rows; COP-map
cells that could not be measured are ``null``.

Page 1 carries the verdict (PASS/FAIL, in words and colour), the plate's identity, the date,
the operator, the reference sensor and its traceability, and the metrics against the
acceptance thresholds. Then the COP error map before/after, the fitted matrix with its
standard errors and identifiable entries, the expanded uncertainty (k = 2) and its budget,
the registration and plan, and the exports with their sha256.
"""
from __future__ import annotations

import math
import os
from datetime import datetime
from typing import Annotated, Any, Literal

import numpy as np
from matplotlib.figure import Figure
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator
from reportlab.lib.units import mm
from reportlab.platypus import CondPageBreak, Flowable, KeepTogether, PageBreak, Spacer

from reports.document import (
    GREEN,
    RED,
    Clock,
    ReportContext,
    Styles,
    TableSpec,
    banner,
    figure_image,
    fmt,
    format_time,
    frame_width,
    key_values,
    p,
    table,
    utc_now,
    write_pdf,
)
from reports.inputs import ReportInputError, first_problem, read_json
from reports.settings import ReportSettings

TITLE = "Force-plate calibration certificate"
SCHEMA_VERSION = 1

Vec6 = Annotated[list[float], Field(min_length=6, max_length=6)]
Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Mat6 = Annotated[list[Vec6], Field(min_length=6, max_length=6)]


class _Open(BaseModel):
    """Record parts: unknown keys are kept (the calibration engineer may add keys)."""

    model_config = ConfigDict(extra="allow")


class Plate(_Open):
    name: str
    manufacturer: str
    model: str
    serial: str
    kind: Literal["six_channel", "kistler8", "linear_n"]
    size_m: Annotated[list[float], Field(min_length=2, max_length=2)]
    corners_m: Annotated[list[Vec3], Field(min_length=4, max_length=4)]
    origin_m: Vec3
    force_range_n: Vec3
    description_sha256: str


class ReferenceSensor(_Open):
    model: str
    serial: str
    calibration_certificate: str
    calibration_date: str
    accuracy_pct_fs: Vec6
    full_scale: Vec6


class Registration(_Open):
    method: Literal["nominal", "camera"]
    T_robot_plate: Annotated[list[Annotated[list[float], Field(min_length=4, max_length=4)]],
                             Field(min_length=4, max_length=4)]
    sigma_translation_mm: float
    sigma_rotation_deg: float


class Plan(_Open):
    grid_m: list[Annotated[list[float], Field(min_length=2, max_length=2)]]
    loads_n: list[float]
    trials: list[dict[str, Any]]


class Metrics(_Open):
    force_pct_fs: Vec6
    force_pct_applied: Vec6
    cop_rms_mm: float
    cop_max_mm: float
    crosstalk_pct: float
    linearity_pct_fs: float
    hysteresis_pct_fs: float
    repeatability_pct_fs: float


class Verdict(_Open):
    pass_: bool = Field(alias="pass")
    stage: Literal["nonlinear", "linear", "before"]
    failed: list[str]


class CopErrorMap(_Open):
    x_m: list[float]
    y_m: list[float]
    before_mm: list[list[float | None]]
    after_mm: list[list[float | None]]


class CalMatrix(_Open):
    cal_matrix: Mat6
    standard_error: Mat6
    identified: Annotated[list[Annotated[list[bool], Field(min_length=6, max_length=6)]],
                          Field(min_length=6, max_length=6)]
    channel_order: list[str]
    moment_unit: str


class BudgetItem(_Open):
    source: str
    value: float
    unit: str


class Uncertainty(_Open):
    k: float
    force_n: Vec6
    moment_nm: Vec3
    cop_mm: float
    budget: list[BudgetItem]


class Export(_Open):
    kind: Literal["c3d", "reference_csv"]
    path: str
    sha256: str


class CalibrationRecord(_Open):
    """A calibration record, schema_version 1 (``/work``'s contract; see the module doc)."""

    schema_version: int
    kind: Literal["talus.calibration_record"]
    id: str
    created_utc: str
    operator: str
    software_version: str
    plate: Plate
    reference_sensor: ReferenceSensor
    registration: Registration
    plan: Plan
    #: numbers, and lists naming what a threshold covers (calibration.metrics writes
    #: ``force_pct_fs_axes: [Fx, Fy, Fz]``)
    thresholds: dict[str, float | list[str]]
    metrics: dict[Literal["before", "linear", "nonlinear"], Metrics]
    verdict: Verdict
    cop_error_map: CopErrorMap
    matrix: CalMatrix
    nonlinear_correction: dict[str, Any] = Field(default_factory=dict)
    uncertainty: Uncertainty
    exports: list[Export]

    @field_validator("schema_version")
    @classmethod
    def _version(cls, v: int) -> int:
        if v != SCHEMA_VERSION:
            raise ValueError(f"this talus reads calibration records version {SCHEMA_VERSION}, "
                             f"not {v}")
        return v

    @field_validator("created_utc")
    @classmethod
    def _iso(cls, v: str) -> str:
        try:
            datetime.fromisoformat(v)
        except ValueError as exc:
            raise ValueError(f"not an ISO 8601 time: {v!r}") from exc
        return v


def load_calibration_record(path: str | os.PathLike[str]) -> CalibrationRecord:
    """Read and validate a calibration record; errors name the file and the key."""
    return calibration_record_from_dict(read_json(path), str(path))


def calibration_record_from_dict(data: Any, source: str = "<record>") -> CalibrationRecord:
    """Validate a record given as plain data (the database's seam)."""
    try:
        rec = CalibrationRecord.model_validate(data)
    except ValidationError as exc:
        raise ReportInputError(f"{source}: calibration record: {first_problem(exc)}") from exc
    m = rec.cop_error_map
    for name, grid in (("before_mm", m.before_mm), ("after_mm", m.after_mm)):
        if len(grid) != len(m.y_m) or any(len(row) != len(m.x_m) for row in grid):
            raise ReportInputError(f"{source}: calibration record: cop_error_map.{name}: "
                                   f"expected {len(m.y_m)} rows of {len(m.x_m)} values "
                                   "(rows along y_m, columns along x_m)")
    return rec


# ------------------------------------------------------------------------------ content

#: Metric key → (label, digits, unit, threshold key).
_METRIC_ROWS = (("cop_rms_mm", "COP error, RMS", 2, "mm", "cop_rms_mm"),
                ("cop_max_mm", "COP error, maximum", 2, "mm", "cop_max_mm"),
                ("force_pct_fs", "force error, worst channel", 3, "% FS", "force_pct_fs"),
                ("crosstalk_pct", "crosstalk", 3, "%", "crosstalk_pct"),
                ("linearity_pct_fs", "linearity", 3, "% FS", "linearity_pct_fs"),
                ("hysteresis_pct_fs", "hysteresis", 3, "% FS", "hysteresis_pct_fs"),
                ("repeatability_pct_fs", "repeatability", 3, "% FS", "repeatability_pct_fs"))
_STAGE_WORDS = {"before": "before (as found)", "linear": "after linear fit",
                "nonlinear": "after nonlinear correction"}


def _metric(m: Metrics, key: str) -> float:
    v = getattr(m, key)
    return max(abs(x) for x in v) if isinstance(v, list) else float(v)


def _first_page(rec: CalibrationRecord, st: Styles, width: float) -> list[Flowable]:
    v = rec.verdict
    stage = _STAGE_WORDS.get(v.stage, v.stage)
    if v.pass_:
        text, colour = f"PASS — {stage}", GREEN
    else:
        failed = ", ".join(v.failed) or "see the metrics"
        text, colour = f"FAIL — {stage}: {failed}", RED
    pl, ref = rec.plate, rec.reference_sensor
    story: list[Flowable] = [p(TITLE, st.title), banner(text, colour, st, width),
                             Spacer(1, 3 * mm)]
    story.append(key_values([
        ("Certificate", rec.id),
        ("Date", format_time(datetime.fromisoformat(rec.created_utc))),
        ("Operator", rec.operator),
        ("Force plate", f"{pl.manufacturer} {pl.model}, serial {pl.serial} ({pl.name})"),
        ("Plate type", {"six_channel": "six-channel (F = C·V)",
                        "kistler8": "Kistler-type, eight channels",
                        "linear_n": "generic linear N-channel"}[pl.kind]),
        ("Plate size", (f"{fmt(pl.size_m[0] * 1e3, 0)} × {fmt(pl.size_m[1] * 1e3, 0)} mm; "
                       f"range Fx, Fy, Fz {', '.join(fmt(x, 0) for x in pl.force_range_n)} N")),
        ("Reference sensor", f"{ref.model}, serial {ref.serial}"),
        ("Traceability", (f"certificate {ref.calibration_certificate} of "
                         f"{ref.calibration_date}; accuracy "
                         f"{', '.join(fmt(x, 2) for x in ref.accuracy_pct_fs)} % FS "
                         "(Fx Fy Fz Mx My Mz)")),
        ("Software", f"talus {rec.software_version}"),
    ], st, width, 0.24))
    story.append(p("Results against the acceptance thresholds", st.h1))
    stages = [s for s in ("before", "linear", "nonlinear") if s in rec.metrics]
    rows: list[list[Any]] = []
    failed_keys = set(v.failed)
    for key, label, digits, unit, tkey in _METRIC_ROWS:
        given = rec.thresholds.get(tkey)
        thr = float(given) if isinstance(given, (int, float)) else None
        row: list[Any] = [f"{label} ({unit})"]
        for s in stages:
            row.append(fmt(_metric(rec.metrics[s], key), digits))
        row.append(fmt(thr, digits, missing="—"))
        final = rec.metrics.get(v.stage)
        if thr is None or final is None:
            row.append("—")
        else:
            ok = _metric(final, key) <= thr and tkey not in failed_keys
            row.append("pass" if ok else "FAIL")
        rows.append(row)
    story.append(table(TableSpec(["metric"] + [_STAGE_WORDS[s] for s in stages]
                                 + ["threshold", "verdict"], rows,
                                 [0.28] + [0.16] * len(stages) + [0.12, 0.12]), st, width))
    story.append(p(f"The verdict applies to the {stage} stage. Force errors are the largest "
                   "over the six channels, in % of the plate's full scale.", st.small))
    story.append(p("Force error per channel (% FS)", st.h2))
    names = rec.matrix.channel_order if len(rec.matrix.channel_order) == 6 else \
        ["Fx", "Fy", "Fz", "Mx", "My", "Mz"]
    ch_rows = [[_STAGE_WORDS[s]] + [fmt(x, 3) for x in rec.metrics[s].force_pct_fs]
               for s in stages]
    story.append(table(TableSpec(["stage"] + names, ch_rows, [0.28] + [0.12] * 6), st,
                       width))
    return story


def _grid(rows: list[list[float | None]]) -> np.ndarray:
    return np.array([[math.nan if v is None else float(v) for v in r] for r in rows])


def _cop_figure(rec: CalibrationRecord) -> Figure:
    m = rec.cop_error_map
    before, after = _grid(m.before_mm), _grid(m.after_mm)
    x = np.asarray(m.x_m) * 1e3
    y = np.asarray(m.y_m) * 1e3
    fig = Figure(figsize=(7.2, 3.3))
    axes = fig.subplots(1, 2)
    vmax = float(np.nanmax(before)) if np.isfinite(before).any() else 1.0
    for ax, grid, title in ((axes[0], before, "before"), (axes[1], after, "after")):
        mesh = ax.pcolormesh(x, y, grid, shading="nearest", cmap="viridis", vmin=0,
                             vmax=vmax)
        for j, yy in enumerate(y):
            for i, xx in enumerate(x):
                val = grid[j, i]
                dark = not math.isnan(val) and val < 0.6 * vmax
                ax.text(xx, yy, "—" if math.isnan(val) else f"{val:.1f}", ha="center",
                        va="center", fontsize=6, color="white" if dark else "black")
        ax.set_title(f"COP error {title} (mm)", fontsize=8.5)
        ax.set_xlabel("x on the plate (mm)", fontsize=7.5)
        ax.set_aspect("equal")
        ax.tick_params(labelsize=7)
        fig.colorbar(mesh, ax=ax, shrink=0.8).ax.tick_params(labelsize=6.5)
    axes[0].set_ylabel("y on the plate (mm)", fontsize=7.5)
    fig.tight_layout()
    return fig


def _matrix_table(rec: CalibrationRecord, st: Styles, width: float) -> Flowable:
    mx = rec.matrix
    names = mx.channel_order if len(mx.channel_order) == 6 else [f"ch{i}" for i in range(6)]
    outs = ["Fx (N)", "Fy (N)", "Fz (N)", f"Mx ({mx.moment_unit})", f"My ({mx.moment_unit})",
            f"Mz ({mx.moment_unit})"]
    rows = []
    for i in range(6):
        row = [outs[i]]
        for j in range(6):
            val = f"{mx.cal_matrix[i][j]:.5g}"
            se = f"± {mx.standard_error[i][j]:.2g}"
            row.append(f"{val}\n{se}" if mx.identified[i][j] else f"({val})\nnot identified")
        rows.append(row)
    return table(TableSpec(["output \\ input"] + list(names), rows, [0.16] + [0.14] * 6),
                 st, width)


def _details(rec: CalibrationRecord, st: Styles, width: float) -> list[Flowable]:
    story: list[Flowable] = [p("Centre-of-pressure error over the plate", st.h1),
                             figure_image(_cop_figure(rec), width),
                             p("Each cell: COP error (mm) at that grid point, distance between "
                               "the plate's COP and the reference's; “—”: not measured.",
                               st.small)]
    story.append(CondPageBreak(90 * mm))
    story.append(p("Calibration matrix", st.h1))
    story.append(_matrix_table(rec, st, width))
    n_id = sum(sum(1 for x in r if x) for r in rec.matrix.identified)
    story.append(p(f"{n_id} of 36 entries are identifiable from this plan (value ± standard "
                   "error); entries in parentheses were not identified and keep their nominal "
                   "value. The matrix maps the channels (columns) to forces and moments "
                   "(rows), in C3D FORCE_PLATFORM:CAL_MATRIX form.", st.small))
    if rec.nonlinear_correction:
        nl = rec.nonlinear_correction
        story.append(p("Nonlinear correction: " + "; ".join(
            f"{k}: {v}" for k, v in nl.items() if not isinstance(v, (list, dict)))[:600],
            st.small))
    u = rec.uncertainty
    block: list[Flowable] = [p(f"Expanded uncertainty (k = {fmt(u.k, 0)})", st.h1)]
    names = rec.matrix.channel_order if len(rec.matrix.channel_order) == 6 else \
        [f"ch{i}" for i in range(6)]
    rows = [[f"force, channel {n}", fmt(x, 2, "N")] for n, x in zip(names, u.force_n)]
    rows += [[f"moment {n}", fmt(x, 3, "N·m")] for n, x in zip(("Mx", "My", "Mz"),
                                                                u.moment_nm)]
    rows.append(["centre of pressure", fmt(u.cop_mm, 2, "mm")])
    block.append(table(TableSpec(["quantity", f"U (k = {fmt(u.k, 0)})"], rows, [0.5, 0.5]),
                       st, width))
    block.append(p("Uncertainty budget", st.h2))
    block.append(table(TableSpec(["source", "value", "unit"],
                                 [[b.source, f"{b.value:.4g}", b.unit] for b in u.budget],
                                 [0.6, 0.2, 0.2]), st, width))
    story.append(KeepTogether(block))
    reg, plan = rec.registration, rec.plan
    story.append(p("Registration of the plate to the robot", st.h1))
    t = reg.T_robot_plate
    story.append(key_values([
        ("Method", "ArUco markers seen by the camera" if reg.method == "camera"
         else "nominal mounting"),
        ("Translation", (f"{fmt(t[0][3] * 1e3, 2)}, {fmt(t[1][3] * 1e3, 2)}, "
                        f"{fmt(t[2][3] * 1e3, 2)} mm (robot frame)")),
        ("1-σ", f"{fmt(reg.sigma_translation_mm, 2)} mm, {fmt(reg.sigma_rotation_deg, 3)}°"),
    ], st, width, 0.24))
    story.append(p("Plan", st.h1))
    story.append(key_values([
        ("Grid", f"{len(plan.grid_m)} points: " + ", ".join(
            f"({fmt(g[0] * 1e3, 0)}, {fmt(g[1] * 1e3, 0)})" for g in plan.grid_m[:25])
         + (" …" if len(plan.grid_m) > 25 else "") + " mm"),
        ("Loads", ", ".join(fmt(x, 0) for x in plan.loads_n) + " N"),
        ("Trials", f"{len(plan.trials)}: " + ", ".join(sorted(
            {str(tr.get('profile', '?')) for tr in plan.trials})) + " profiles"),
    ], st, width, 0.24))
    story.append(p("Exports (traceability)", st.h1))
    if rec.exports:
        story.append(table(TableSpec(["kind", "file", "sha256"],
                                     [[e.kind, os.path.basename(e.path), e.sha256]
                                      for e in rec.exports], [0.14, 0.26, 0.60]), st, width))
    else:
        story.append(p("No export recorded.", st.note))
    story.append(p(f"Plate description sha256 {rec.plate.description_sha256}.", st.small))
    return story


def render_certificate(rec: CalibrationRecord, out: str | os.PathLike[str],
                       settings: ReportSettings | None = None, clock: Clock = utc_now,
                       force: bool = False, software_version: str | None = None) -> int:
    """Write the calibration certificate PDF; returns its page count."""
    from rt.recording.writer import software_version as installed_version

    settings = settings or ReportSettings()
    st = Styles()
    ctx = ReportContext(TITLE, settings, clock(), software_version or installed_version(),
                        subject=f"{rec.id} · plate {rec.plate.serial}",
                        extra_footer=f"record {rec.id}")
    width = frame_width(ctx)
    story = _first_page(rec, st, width)
    story.append(PageBreak())
    story += _details(rec, st, width)
    return write_pdf(out, story, ctx, force)
