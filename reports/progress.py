"""The progress report (PDF): a patient's sessions over time against the prescription.

Input is plain data (:class:`ProgressInput`), so the clinical database only has to fill it:
the patient's code, the prescribed ROM per direction, the foot, an optional plan (sessions per
week over a period) and the sessions, each with its summary dict (``rom_deg``,
``rms_error_pct``, ``peak_force_n``, ``stops`` as the session summary holds them) and the
limits snapshot in force that day. ``talus report progress --input progress.json`` reads the
same thing from JSON.

Figures: ROM reached per session and direction with the prescribed range and a least-squares
trend line (°/week); force-tracking error and peak force per session with trends; session
count, adherence = sessions attended / sessions planned in the period; the sessions table.
"""
from __future__ import annotations

import math
import os
from datetime import date, timedelta
from typing import Annotated, Any, Literal

import numpy as np
from matplotlib.figure import Figure
from pydantic import ConfigDict, Field, TypeAdapter, ValidationError, field_validator
from pydantic.dataclasses import dataclass
from reportlab.lib.units import mm
from reportlab.platypus import Flowable, PageBreak, Spacer

from protocols.session_figures import FORCE_KINDS
from reports.clinical import DIRECTIONS, LEVEL_DEG, reached_by_direction
from reports.document import (
    AMBER,
    GREEN,
    RED,
    Clock,
    ReportContext,
    Styles,
    TableSpec,
    banner,
    figure_image,
    fmt,
    frame_width,
    key_values,
    p,
    table,
    utc_now,
    write_pdf,
)
from reports.inputs import ReportInputError, first_problem, read_json
from reports.settings import ReportSettings

TITLE = "Progress report"
#: Outcomes a session can have; the first three mean the patient came.
Outcome = Literal["completed", "stopped", "aborted", "missed", "cancelled"]
ATTENDED = ("completed", "stopped", "aborted")

_CONFIG = ConfigDict(extra="forbid")


@dataclass(config=_CONFIG)
class ProgressSession:
    """One session: id, date, protocol name (and kind), outcome, summary, limits snapshot."""

    id: str
    date: date
    protocol: str
    outcome: Outcome
    kind: str | None = None
    summary: dict[str, Any] | None = None
    limits: dict[str, Any] | None = None


@dataclass(config=_CONFIG)
class ProgressPlan:
    """The prescription's schedule: sessions per week from ``start`` to ``end`` (inclusive)."""

    sessions_per_week: Annotated[float, Field(gt=0, le=21)]
    start: date
    end: date | None = None


@dataclass(config=_CONFIG)
class ProgressInput:
    """A patient's progress as plain data (module docstring)."""

    patient_code: Annotated[str, Field(min_length=1)]
    #: direction (dorsiflexion, plantarflexion, inversion, eversion) → degrees.
    prescribed_rom_deg: dict[str, Annotated[float, Field(ge=0, le=60)]]
    sessions: list[ProgressSession]
    side: Literal["right", "left"] = "right"
    plan: ProgressPlan | None = None
    schema_version: int = 1

    @field_validator("prescribed_rom_deg")
    @classmethod
    def _directions(cls, v: dict[str, float]) -> dict[str, float]:
        unknown = sorted(set(v) - set(DIRECTIONS))
        if unknown:
            raise ValueError(f"unknown direction(s) {unknown}; use {list(DIRECTIONS)}")
        return v


_ADAPTER = TypeAdapter(ProgressInput)


def load_progress_input(path: str | os.PathLike[str]) -> ProgressInput:
    """Read and validate a progress input JSON; errors name the file and the field."""
    return progress_input_from_dict(read_json(path), str(path))


def progress_input_from_dict(data: Any, source: str = "<progress input>") -> ProgressInput:
    """Validate plain data into a :class:`ProgressInput` (the database's seam)."""
    try:
        return _ADAPTER.validate_python(data)
    except ValidationError as exc:
        raise ReportInputError(f"{source}: {first_problem(exc)}") from exc


# ------------------------------------------------------------------------------ figures

def _parse_day(s: str | None, what: str) -> date | None:
    if s is None:
        return None
    try:
        return date.fromisoformat(s)
    except ValueError as exc:
        raise ReportInputError(f"{what} {s!r}: not a date (YYYY-MM-DD)") from exc


def trend_per_week(days: list[date], values: list[float | None]) -> float | None:
    """Least-squares slope of ``values`` over time, per week; None with < 2 points or one day."""
    pts = [(d, v) for d, v in zip(days, values) if v is not None and math.isfinite(v)]
    if len(pts) < 2:
        return None
    x = np.array([(d - pts[0][0]).days for d, _ in pts], dtype=float)
    y = np.array([v for _, v in pts], dtype=float)
    if np.ptp(x) == 0:
        return None
    slope = np.polyfit(x, y, 1)[0]
    return float(slope * 7.0)


def adherence(inp: ProgressInput, first: date, last: date) -> dict[str, Any]:
    """Sessions planned and attended in ``[first, last]`` and their ratio (None without plan)."""
    attended = sum(1 for s in inp.sessions if s.outcome in ATTENDED and first <= s.date <= last)
    out: dict[str, Any] = {"attended": attended, "planned": None, "pct": None}
    plan = inp.plan
    if plan is None:
        return out
    start = max(first, plan.start)
    end = min(last, plan.end) if plan.end else last
    if end < start:
        out["planned"] = 0
        return out
    days = (end - start).days + 1
    planned = round(plan.sessions_per_week * days / 7.0)
    out["planned"] = planned
    out["pct"] = attended / planned * 100.0 if planned else None
    return out


def _moves_the_ankle(s: ProgressSession) -> bool:
    """Whether a session's ROM counts: position kinds move the ankle, force kinds hold the
    platform level (their ROM reads 0 and would drag the trend down)."""
    if s.kind is not None:
        return s.kind not in FORCE_KINDS
    rom = (s.summary or {}).get("rom_deg") or {}
    return any(r and (r[1] - r[0]) > LEVEL_DEG for r in rom.values())


def _rows(inp: ProgressInput, sessions: list[ProgressSession]) -> list[dict[str, Any]]:
    out = []
    for s in sessions:
        summ = s.summary or {}
        came = s.outcome in ATTENDED
        reached = reached_by_direction(summ.get("rom_deg"), inp.side) \
            if came and _moves_the_ankle(s) else {d: None for d in DIRECTIONS}
        force = came and (s.kind in FORCE_KINDS if s.kind is not None
                          else summ.get("rms_error_pct") is not None)
        out.append({"session": s, "reached": reached,
                    "rms": summ.get("rms_error_pct") if force else None,
                    "peak": summ.get("peak_force_n") if force else None,
                    "stops": len(summ.get("stops") or [])})
    return out


# ------------------------------------------------------------------------------ render

def render_progress_report(inp: ProgressInput, out: str | os.PathLike[str],
                           settings: ReportSettings | None = None, clock: Clock = utc_now,
                           date_from: str | date | None = None,
                           date_to: str | date | None = None, force: bool = False,
                           software_version: str | None = None) -> int:
    """Write the progress report PDF for the sessions in ``[date_from, date_to]``; pages."""
    from rt.recording.writer import software_version as installed_version

    d0 = date_from if isinstance(date_from, date) else _parse_day(date_from, "--from")
    d1 = date_to if isinstance(date_to, date) else _parse_day(date_to, "--to")
    if d0 and d1 and d1 < d0:
        raise ReportInputError(f"--to {d1} is before --from {d0}")
    sessions = sorted((s for s in inp.sessions if (d0 is None or s.date >= d0)
                       and (d1 is None or s.date <= d1)), key=lambda s: (s.date, s.id))
    settings = settings or ReportSettings()
    st = Styles()
    ctx = ReportContext(TITLE, settings, clock(), software_version or installed_version(),
                        subject=f"Patient {inp.patient_code}")
    width = frame_width(ctx)
    today = ctx.generated_at.date()
    plan = inp.plan
    first = d0 or (min(sessions[0].date, plan.start) if sessions and plan else
                   sessions[0].date if sessions else None)
    last = d1 or (max(sessions[-1].date, min(plan.end or today, today)) if sessions and plan
                  else sessions[-1].date if sessions else None)
    period = f"{first} to {last}" if first and last else "no sessions"
    story: list[Flowable] = [p(TITLE, st.title)]
    rows = _rows(inp, sessions)
    attended = [r for r in rows if r["session"].outcome in ATTENDED]
    if not sessions:
        story.append(banner("NO SESSIONS in this period", AMBER, st, width))
        story.append(Spacer(1, 3 * mm))
        story.append(key_values([("Patient", inp.patient_code), ("Foot", inp.side),
                                 ("Period", period if (d0 or d1) else "all dates")], st, width))
        story.append(p("There is nothing to show: the patient has no session"
                       + (" in the period asked." if (d0 or d1) else " yet."), st.note))
        return write_pdf(out, story, ctx, force)

    assert first is not None and last is not None
    adh = adherence(inp, first, last)
    if adh["pct"] is None:
        colour, text = GREEN if attended else AMBER, f"{adh['attended']} sessions attended"
    else:
        colour = GREEN if adh["pct"] >= 80 else AMBER if adh["pct"] >= 50 else RED
        text = (f"{adh['attended']} of {adh['planned']} planned sessions attended "
                f"({adh['pct']:.0f} %)")
    story.append(banner(text, colour, st, width))
    story.append(Spacer(1, 3 * mm))
    story.append(key_values([
        ("Patient", inp.patient_code), ("Foot", inp.side), ("Period", period),
        ("Sessions", f"{len(sessions)} in the period: "
                     + ", ".join(f"{n} {o}" for o, n in _count_outcomes(sessions))),
        ("Plan", f"{plan.sessions_per_week:g} per week from {plan.start}"
                 + (f" to {plan.end}" if plan.end else "") if plan else "no plan recorded: "
                 "adherence cannot be computed"),
    ], st, width))
    story.append(p("Range of motion", st.h1))
    rom_sessions = [r for r in attended if _moves_the_ankle(r["session"])]
    days = [r["session"].date for r in rom_sessions]
    rom_rows = []
    for d in DIRECTIONS:
        vals = [r["reached"][d] for r in rom_sessions]
        known = [v for v in vals if v is not None]
        trend = trend_per_week(days, vals)
        rom_rows.append([d.capitalize(), fmt(inp.prescribed_rom_deg.get(d), 1, "°"),
                         fmt(known[0] if known else None, 1, "°"),
                         fmt(known[-1] if known else None, 1, "°"),
                         fmt(max(known) if known else None, 1, "°"),
                         fmt(trend, 2, "°/week", "—")])
    story.append(table(TableSpec(["direction", "prescribed", "first", "latest", "best",
                                  "trend"], rom_rows, [0.22, 0.15, 0.14, 0.14, 0.14, 0.21]),
                       st, width))
    story.append(p("First/latest/best: ROM reached in the first, the latest and the best "
                   "attended session of the period. Trend: least-squares slope over the "
                   "period.", st.small))
    if rom_sessions:
        story.append(figure_image(_rom_figure(inp, rom_sessions), width))
    else:
        story.append(p("No range-of-motion session in the period.", st.body))
    story.append(PageBreak())
    story.append(p("Force", st.h1))
    force_fig = _force_figure(attended)
    if force_fig is not None:
        story.append(figure_image(force_fig, width))
        forced = [r for r in attended if r["rms"] is not None]
        f_days = [r["session"].date for r in forced]
        rms = [r["rms"] for r in forced]
        peak = [r["peak"] for r in forced]
        story.append(p(f"Trend of the force-tracking error: "
                       f"{fmt(trend_per_week(f_days, rms), 3, '%/week')}; of the peak force: "
                       f"{fmt(trend_per_week(f_days, peak), 1, 'N/week')}.", st.body))
    else:
        story.append(p("No force protocol in the period.", st.body))
    story.append(p("Sessions", st.h1))
    t_rows = []
    for r in rows:
        s: ProgressSession = r["session"]
        rd = r["reached"]
        t_rows.append([str(s.date), s.id, s.protocol, s.outcome]
                      + [fmt(rd[d], 1) for d in DIRECTIONS]
                      + [fmt(r["rms"], 2), fmt(r["peak"], 0), str(r["stops"])])
    story.append(table(TableSpec(["date", "id", "protocol", "outcome", "dorsi °", "plantar °",
                                  "inv °", "ev °", "RMS err %", "peak N", "stops"], t_rows,
                                 [0.115, 0.06, 0.245, 0.1, 0.065, 0.07, 0.06, 0.06, 0.08,
                                  0.07, 0.055]), st, width))
    missing = [r["session"].id for r in attended if not r["session"].summary]
    if missing:
        story.append(p(f"Sessions without a summary (figures missing): {', '.join(missing)}.",
                       st.note))
    return write_pdf(out, story, ctx, force)


def _count_outcomes(sessions: list[ProgressSession]) -> list[tuple[str, int]]:
    counts: dict[str, int] = {}
    for s in sessions:
        counts[s.outcome] = counts.get(s.outcome, 0) + 1
    return sorted(counts.items())


def _trend_line(ax: Any, days: list[date], values: list[float | None], colour: str) -> None:
    pts = [(d, v) for d, v in zip(days, values) if v is not None]
    if len(pts) < 2 or len({d for d, _ in pts}) < 2:
        return
    x = np.array([(d - pts[0][0]).days for d, _ in pts], dtype=float)
    y = np.array([v for _, v in pts], dtype=float)
    a, b = np.polyfit(x, y, 1)
    xs = np.array([x.min(), x.max()])
    ax.plot([pts[0][0] + timedelta(days=float(v)) for v in xs], a * xs + b, color=colour,
            lw=1.0, ls="--", label="trend")


def _rom_figure(inp: ProgressInput, attended: list[dict[str, Any]]) -> Figure:
    fig = Figure(figsize=(7.2, 4.6))
    axes = fig.subplots(2, 2, sharex=True).ravel()
    days = [r["session"].date for r in attended]
    for ax, d in zip(axes, DIRECTIONS):
        vals = [r["reached"][d] for r in attended]
        ax.plot([dd for dd, v in zip(days, vals) if v is not None],
                [v for v in vals if v is not None], "o-", color="#1a73e8", ms=3.5, lw=0.8,
                label="reached")
        presc = inp.prescribed_rom_deg.get(d)
        if presc is not None:
            ax.axhline(presc, color="#1b7f3b", lw=1.0, label="prescribed")
        _trend_line(ax, days, vals, "#e37400")
        ax.set_title(d, fontsize=8.5)
        ax.set_ylabel("°", fontsize=8)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    axes[0].legend(fontsize=6.5, loc="lower right")
    fig.autofmt_xdate()
    fig.suptitle("Range of motion reached per session", fontsize=9)
    fig.tight_layout()
    return fig


def _force_figure(attended: list[dict[str, Any]]) -> Figure | None:
    forced = [r for r in attended if r["rms"] is not None]
    if not forced:
        return None
    fig = Figure(figsize=(7.2, 3.6))
    ax_e, ax_p = fig.subplots(1, 2, sharex=True)
    days = [r["session"].date for r in forced]
    for ax, key, label, colour in ((ax_e, "rms", "force-tracking error, RMS (%)", "#e37400"),
                                   (ax_p, "peak", "peak force (N)", "#1a73e8")):
        vals = [r[key] for r in forced]
        ax.plot([d for d, v in zip(days, vals) if v is not None],
                [v for v in vals if v is not None], "o-", color=colour, ms=3.5, lw=0.8)
        _trend_line(ax, days, vals, "#5f6368")
        ax.set_title(label, fontsize=8.5)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    fig.autofmt_xdate()
    fig.tight_layout()
    return fig
