"""The session report (PDF): what was done, how it went, every stop, traceable to the file.

Page 1 is for the clinician at a glance: the outcome in words and colour, who/what/when, and
the results against the patient's limits (ROM reached per direction, force tracking, peak
force, stops). Then the plots (reference vs measured force and its error, platform angles in
clinical terms against the ROM limits, slider positions), then the details: parameters,
limits in force, time per phase, stops, pre-flight predictions against what happened, and the
recording's file name and sha256.
"""
from __future__ import annotations

import math
import os
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from reportlab.lib.units import mm
from reportlab.platypus import CondPageBreak, Flowable, KeepTogether, PageBreak, Spacer

from reports.clinical import (
    DIRECTIONS,
    KIND_WORDS,
    LEVEL_DEG,
    limits_by_direction,
    narrowed_limits,
    reached_by_direction,
    reaction_words,
    stop_trigger,
)
from reports.decimate import Envelope
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
    format_time,
    frame_width,
    key_values,
    p,
    table,
    utc_now,
    write_pdf,
)
from reports.session_data import SessionReportInput
from reports.settings import ReportSettings

TITLE = "Session report"


def _side(inp: SessionReportInput) -> tuple[str, bool]:
    """The foot (``right``/``left``) and whether the recording said so."""
    ankle = inp.metadata.get("ankle")
    side = inp.metadata.get("side") or (inp.identity or {}).get("side") or \
        (ankle.get("side") if isinstance(ankle, dict) else None)
    if side in ("right", "left"):
        return str(side), True
    return "right", False


def _figures(inp: SessionReportInput) -> dict[str, Any]:
    """The recording's figures, else the stored summary's (no recording)."""
    if inp.figures is not None:
        return inp.figures
    return dict(inp.summary or {})


def _alarm_row(alarm: dict[str, Any]) -> list[str]:
    """One staff alarm of the figures (``alarms``: a pull the robot could not end after a
    stop) as a report row: time, what happened, the pull, how it ended."""
    fz = alarm.get("fz_n")
    ended = alarm.get("ended_t")
    end = ("still pulled at the end of the session" if ended is None
           else f"ended at {fmt(ended, 3, 's')}"
           + (" (stop reset)" if alarm.get("how") == "stop_reset" else ""))
    what = ("the foot was still pulled after the stop; the robot could not lift it "
            "(staff: support the leg, release the strap)")
    return [fmt(alarm.get("t"), 3, "s"), what,
            fmt(abs(fz) if isinstance(fz, (int, float)) else None, 0, "N"), end]


def _outcome(inp: SessionReportInput, f: dict[str, Any]) -> tuple[str, Any]:
    stops = f.get("stops") or []
    if stops:
        first = stops[0]
        _who, words = stop_trigger(str(first.get("cause", "")))
        colour = RED if first.get("reaction") == "hard_stop" else AMBER
        return (f"STOPPED at {fmt(first.get('t'), 1, 's')}: {words}", colour)
    if inp.recording is not None and not inp.recording.complete:
        return "RECORDING INCOMPLETE — see the notes below", AMBER
    if f.get("completed"):
        return "COMPLETED — no stops", GREEN
    return "NOT COMPLETED — the protocol did not reach its end", AMBER


def _protocol_limits(inp: SessionReportInput) -> dict[str, Any] | None:
    params = inp.metadata.get("parameters")
    lim = params.get("limits") if isinstance(params, dict) else None
    return lim if isinstance(lim, dict) else None


def _first_page(inp: SessionReportInput, st: Styles, width: float) -> list[Flowable]:
    f = _figures(inp)
    md = inp.metadata
    side, side_known = _side(inp)
    text, colour = _outcome(inp, f)
    story: list[Flowable] = [p(TITLE, st.title), banner(text, colour, st, width),
                             Spacer(1, 3 * mm)]
    raw_params = md.get("parameters")
    params: dict[str, Any] = raw_params if isinstance(raw_params, dict) else {}
    kind = str(params.get("kind", f.get("kind", "unknown")))
    ident = inp.identity or {}
    patient = str(md.get("patient_id", "not recorded"))
    if ident.get("name"):
        patient = f"{ident['name']} ({patient})"
    phase_time = f.get("phase_time_s") or {}
    rows = [
        ("Patient", patient),
        ("Foot", side if side_known else f"{side} (assumed: not recorded)"),
        ("Date and time", _start_time(md)),
        ("Clinician", str(md.get("clinician", "not recorded"))),
        ("Protocol", f"{md.get('protocol_name', 'unknown')} — {KIND_WORDS.get(kind, kind)}"),
        ("Exercise time", fmt(phase_time.get("play"), 1, "s") if phase_time else "—"),
    ]
    if inp.session_id:
        rows.insert(0, ("Session", inp.session_id))
    story.append(key_values(rows, st, width))
    story.append(p("Results", st.h1))
    limits = narrowed_limits(inp.limits, _protocol_limits(inp))
    lim_dir = limits_by_direction(limits, side)
    reached = reached_by_direction(f.get("rom_deg"), side)
    ankle_rom = (f.get("ankle") or {}).get("rom_deg")
    if ankle_rom:
        # Angles of the foot about the patient's ankle centre (/ankle/state): the recording's
        # own clinical terms, foot side included.
        reached = {d: ankle_rom.get(d) for d in DIRECTIONS}
    res_rows: list[list[Any]] = []
    for d in DIRECTIONS:
        r, lim = reached[d], lim_dir[d]
        res_rows.append([f"{d.capitalize()} reached", fmt(r, 1, "°"),
                         fmt(lim, 1, "°", "not recorded"), _rom_comment(r, lim)])
    if f.get("rms_error_pct") is not None:
        basis = "amplitude" if f.get("rms_error_basis") == "amplitude" else "peak force"
        res_rows.append(["Force tracking error (RMS)",
                         f"{fmt(f['rms_error_pct'], 2, '%')} of the {basis}"
                         + (f" ({fmt(f.get('rms_error_n'), 1, 'N')})"
                            if f.get("rms_error_n") is not None else ""), "—",
                         "how closely the robot followed the prescribed force"])
    lim_force = (limits or {}).get("max_force_n")
    res_rows.append(["Peak force on the foot", fmt(f.get("peak_force_n"), 1, "N"),
                     fmt(lim_force, 0, "N", "not recorded"),
                     _force_comment(f.get("peak_force_n"), lim_force)])
    ankle = f.get("ankle")
    if ankle:
        # The torques the patient produced about the ankle centre (/ankle/state).
        for d, value in (ankle.get("peak_torque_nm") or {}).items():
            res_rows.append([f"Peak {d} torque", fmt(value, 1, "N·m"), "—",
                             f"the patient's {d} effort about the ankle"])
        disp = ankle.get("centre_displacement_mm") or {}
        res_rows.append(["Ankle centre moved", fmt(disp.get("horizontal"), 1, "mm"), "—",
                         "horizontal; the platform cannot follow the ankle in x, y"])
    res_rows += _torque_hold_rows(inp)
    n_stops = len(f.get("stops") or [])
    res_rows.append(["Stops", str(n_stops), "—",
                     "none" if not n_stops else "see “Stops” below"])
    story.append(table(TableSpec(["", "measured", "patient limit", "meaning"], res_rows,
                                 [0.3, 0.22, 0.16, 0.32]), st, width))
    if not side_known:
        story.append(p("Inversion/eversion are named as for a right foot (positive roll = "
                       "inversion), the session's default; the recording does not say which "
                       "foot.", st.small))
    if inp.notes:
        story.append(p("What is missing or doubtful", st.h2))
        story += [p("• " + n, st.note) for n in inp.notes]
    return story


def _torque_hold_rows(inp: SessionReportInput) -> list[list[Any]]:
    """One row per isometric hold with an ankle-torque target (the session summary's
    ``ankle.torque_holds``): the torque reported about the ankle centre against the target,
    and pre-flight's twin figure of the reported torque against the twin ankle's true one."""
    summary = inp.summary or {}
    holds = (summary.get("ankle") or {}).get("torque_holds") or []
    pre = summary.get("preflight") or inp.metadata.get("preflight") or {}
    twin = {h.get("hold"): h for h in (pre.get("ankle_torque_holds") or [])
            if isinstance(h, dict)}
    rows: list[list[Any]] = []
    for h in holds:
        if not isinstance(h, dict):
            continue
        meaning = (f"target {fmt(h.get('target_nm'), 1, 'N·m')}; RMS "
                   f"{fmt(h.get('rms_error_to_target_nm'), 2, 'N·m')} from it")
        t = twin.get(h.get("hold")) or {}
        if t.get("rms_reported_vs_true_nm") is not None:
            meaning += (f"; pre-flight (twin): reported vs the twin ankle's true torque "
                        f"{fmt(t['rms_reported_vs_true_nm'], 2, 'N·m')} RMS")
        rows.append([f"Hold {int(h.get('hold', 0)) + 1}: {h.get('direction')} torque",
                     fmt(h.get("reported_mean_nm"), 1, "N·m"), "—", meaning])
    return rows


def _rom_comment(reached: float | None, limit: float | None) -> str:
    if reached is None:
        return "no data"
    if limit is None:
        return ""
    if reached > limit + 0.05:
        return "beyond the limit"
    if limit > 0 and reached >= 0.9 * limit:
        return "near the limit"
    return "within the limit"


def _force_comment(peak: float | None, limit: float | None) -> str:
    if peak is None:
        return "no force measured"
    if limit is None:
        return ""
    return "beyond the limit" if peak > limit else f"{peak / limit * 100:.0f} % of the limit"


def _start_time(md: dict[str, Any]) -> str:
    from datetime import datetime
    raw = md.get("start_wall_time")
    if not raw:
        return "not recorded"
    try:
        return format_time(datetime.fromisoformat(str(raw)))
    except ValueError:
        return str(raw)


# ------------------------------------------------------------------------------ plots

def _env_plot(ax: Any, env: Envelope, scale: float, colour: str, label: str,
              dashed: bool = False) -> None:
    if not len(env):
        return
    ax.plot(env.t, env.mean * scale, color=colour, lw=0.9, ls="--" if dashed else "-",
            label=label)
    if not dashed and np.any(env.hi - env.lo > 0):
        ax.fill_between(env.t, env.lo * scale, env.hi * scale, color=colour, alpha=0.25, lw=0)


def _stop_marks(ax: Any, f: dict[str, Any]) -> None:
    for s in f.get("stops") or []:
        ax.axvline(float(s["t"]), color="#b3261e", lw=1.0, ls=":")


def _force_figure(inp: SessionReportInput, f: dict[str, Any]) -> Figure | None:
    s = inp.series
    if not len(s.get("force_n", Envelope(*[np.empty(0)] * 4))):
        return None
    tracked = len(s.get("force_ref_n", Envelope(*[np.empty(0)] * 4))) > 0
    if not tracked:
        # A position protocol: the force the foot felt, no prescription to compare with.
        fig = Figure(figsize=(7.2, 2.4))
        ax = fig.subplots()
        _env_plot(ax, s["force_n"], 1.0, "#1a73e8", "measured")
        ax.set_ylabel("force on the foot (N)")
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
        _stop_marks(ax, f)
        fig.suptitle("Force on the foot (measured; this protocol prescribes positions)",
                     fontsize=9)
        fig.tight_layout()
        return fig
    fig = Figure(figsize=(7.2, 3.8))
    ax, ax_e = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2.2, 1]})
    _env_plot(ax, s["force_n"], 1.0, "#1a73e8", "measured")
    _env_plot(ax, s["force_ref_n"], 1.0, "#202124", "reference", dashed=True)
    lim = (narrowed_limits(inp.limits, _protocol_limits(inp)) or {}).get("max_force_n")
    if lim is not None:
        ax.axhline(lim, color="#b3261e", lw=1.0, label="force limit in force")
    ax.set_ylabel("force on the foot (N)")
    ax.legend(loc="upper right", fontsize=7, ncol=3)
    ax.grid(alpha=0.3)
    _env_plot(ax_e, s["force_error_n"], 1.0, "#e37400", "reference − measured")
    ax_e.axhline(0.0, color="#5f6368", lw=0.6)
    ax_e.set_ylabel("error (N)")
    ax_e.set_xlabel("time (s)")
    ax_e.grid(alpha=0.3)
    _stop_marks(ax, f)
    _stop_marks(ax_e, f)
    fig.suptitle("Force: prescribed (dashed) and measured", fontsize=9)
    fig.tight_layout()
    return fig


def _angle_figure(inp: SessionReportInput, f: dict[str, Any]) -> Figure | None:
    s = inp.series
    if not len(s.get("pitch", Envelope(*[np.empty(0)] * 4))) or not _platform_moved(f):
        return None
    side, _ = _side(inp)
    limits = narrowed_limits(inp.limits, _protocol_limits(inp))
    lim = limits_by_direction(limits, side)
    fig = Figure(figsize=(7.2, 3.6))
    ax_p, ax_r = fig.subplots(2, 1, sharex=True)
    deg = 180.0 / math.pi
    inv = 1.0 if side == "right" else -1.0
    for ax, key, scale, pos, neg, label in (
            (ax_p, "pitch", deg, "plantarflexion", "dorsiflexion", "plantar + / dorsi − (°)"),
            (ax_r, "roll", deg * inv, "inversion", "eversion", "inv. + / ev. − (°)")):
        _env_plot(ax, s[key], scale, "#1a73e8", "reached")
        hi, lo = lim[pos], lim[neg]
        if hi is not None and lo is not None:
            ax.axhspan(-lo, hi, color="#1b7f3b", alpha=0.08, label="range in force")
            ax.axhline(hi, color="#1b7f3b", lw=0.8)
            ax.axhline(-lo, color="#1b7f3b", lw=0.8)
            ax.set_ylim(min(ax.get_ylim()[0], -lo - 2.0), max(ax.get_ylim()[1], hi + 2.0))
        else:
            ax.set_ylim(min(ax.get_ylim()[0], -2.0), max(ax.get_ylim()[1], 2.0))
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=7)
        _stop_marks(ax, f)
    ax_r.set_xlabel("time (s)")
    fig.suptitle("Ankle angles reached, against the range of motion in force", fontsize=9)
    fig.tight_layout()
    return fig


def _platform_moved(f: dict[str, Any]) -> bool:
    rom = f.get("rom_deg") or {}
    return any(r and (r[1] - r[0]) > LEVEL_DEG for r in rom.values())


def _slider_figure(inp: SessionReportInput, f: dict[str, Any]) -> Figure | None:
    s = inp.series
    if not len(s.get("q0", Envelope(*[np.empty(0)] * 4))):
        return None
    fig = Figure(figsize=(7.2, 2.4))
    ax = fig.subplots()
    for i, c in enumerate(("#1a73e8", "#e37400", "#1b7f3b")):
        _env_plot(ax, s[f"q_ref{i}"], 1e3, c, f"slider {i + 1} reference", dashed=True)
        _env_plot(ax, s[f"q{i}"], 1e3, c, f"slider {i + 1}")
    ax.set_ylabel("position (mm)")
    ax.set_xlabel("time (s)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=6.5, ncol=3)
    _stop_marks(ax, f)
    fig.suptitle("Slider positions: reference (dashed) and measured", fontsize=9)
    fig.tight_layout()
    return fig


# ------------------------------------------------------------------------------ details

def _details(inp: SessionReportInput, st: Styles, width: float) -> list[Flowable]:
    f = _figures(inp)
    md = inp.metadata
    story: list[Flowable] = [p("Protocol and parameters", st.h1)]
    raw_params = md.get("parameters")
    params: dict[str, Any] = raw_params if isinstance(raw_params, dict) else {}
    rows: list[list[Any]]
    if params:
        rows = [[k, _value(v)] for k, v in params.items() if k not in ("limits",)]
        story.append(table(TableSpec(["parameter", "value"], rows, [0.35, 0.65]), st, width))
    else:
        story.append(p("The recording does not hold the protocol's parameters.", st.note))
    story.append(p(f"Protocol version {md.get('protocol_version', '—')}; robot description "
                   f"{md.get('robot_description', '—')}; recorded by talus "
                   f"{md.get('software_version', '—')}.", st.small))

    story.append(p("Limits in force", st.h1))
    patient, proto = inp.limits, _protocol_limits(inp)
    effective = narrowed_limits(patient, proto)
    keys = ("roll_min_deg", "roll_max_deg", "pitch_min_deg", "pitch_max_deg", "max_force_n",
            "max_angular_speed_deg_s")
    rows = []
    for k in keys:
        rows.append([k, _value((patient or {}).get(k)), _value((proto or {}).get(k)),
                     _value((effective or {}).get(k))])
    story.append(table(TableSpec(["limit", "patient", "protocol", "in force"], rows,
                                 [0.34, 0.22, 0.22, 0.22]), st, width))
    if patient is None:
        story.append(p("The patient's limits are not in the recording: only the protocol's "
                       "are shown.", st.note))

    story.append(p("Time in each phase", st.h1))
    phases = f.get("phase_time_s") or {}
    if phases:
        rows = [[_PHASE_WORDS.get(k, k), fmt(v, 2, "s")] for k, v in phases.items() if v > 0]
        story.append(table(TableSpec(["phase", "time"], rows, [0.5, 0.5]), st, width))
    else:
        story.append(p("Not available without the recording.", st.note))

    story.append(p("Stops", st.h1))
    stops = f.get("stops") or []
    if stops:
        rows = []
        s: dict[str, Any]
        for s in stops:
            who, words = stop_trigger(str(s.get("cause", "")))
            rows.append([fmt(s.get("t"), 3, "s"), words, who,
                         reaction_words(str(s.get("reaction", ""))),
                         f"{s.get('cause', '')}: {s.get('message', '')}"])
        story.append(table(TableSpec(["time", "what happened", "triggered by", "reaction",
                                      "supervisor's record"], rows,
                                     [0.1, 0.27, 0.14, 0.19, 0.30]), st, width))
    else:
        story.append(p("No stop: the session ran without a soft or hard stop.", st.body))
    alarms = f.get("alarms") or []
    if alarms:
        # What the robot could not end and the staff had to (a pull after a stop).
        rows = [_alarm_row(a) for a in alarms]
        story.append(p("Alarms to the staff", st.h1))
        story.append(table(TableSpec(["time", "what happened", "pull", "end"], rows,
                                     [0.12, 0.53, 0.1, 0.25]), st, width))
    fail = f.get("failovers") or []
    if fail:
        story.append(p("Drive failovers (the robot kept running on the backup card): "
                       + "; ".join(f"{fmt(x['t'], 3, 's')} {x['message']}" for x in fail),
                       st.body))
    warn = [e for e in inp.events if e.get("reaction") == "warn"]
    if warn:
        story.append(p(f"{len(warn)} warning(s) without a stop, first: "
                       f"{fmt(warn[0].get('t'), 3, 's')} {warn[0].get('message', '')}.",
                       st.small))

    story.append(CondPageBreak(60 * mm))
    story.append(p("Pre-flight prediction and what happened", st.h1))
    pre = (inp.summary or {}).get("preflight") if inp.summary else None
    story.append(_preflight_table(pre, f, st, width))
    if pre is None:
        story.append(p("No pre-flight prediction is recorded with this session.", st.note))

    rt_stats = (inp.summary or {}).get("rt")
    if isinstance(rt_stats, dict) and rt_stats:
        story.append(p("Real-time controller", st.h2))
        story.append(table(TableSpec(["figure", "value"],
                                     [[k, _value(v)] for k, v in rt_stats.items()],
                                     [0.5, 0.5]), st, width))

    rec = inp.recording
    block: list[Flowable] = [p("Recording (traceability)", st.h1)]
    if rec is None:
        block.append(p("No recording: the figures above are the session summary's as stored "
                       "with the session.", st.note))
    else:
        pairs = [("File", rec.file_name), ("sha256", rec.sha256),
                ("Size", f"{rec.bytes} bytes"),
                ("Complete", "yes" if rec.complete else f"no — {rec.tail}"),
                ("Messages", ", ".join(f"{k} {v}" for k, v in sorted(rec.messages.items())))]
        block.append(key_values(pairs, st, width, 0.18))
        block.append(p("Every figure in this report is computed from this file's samples "
                       f"({f.get('samples', '—')} loop cycles); plots are decimated "
                       "(min–max envelopes).", st.small))
    story.append(KeepTogether(block))
    if inp.summary is not None and inp.figures is not None:
        story.append(_cross_check(inp.summary, inp.figures, st, width))
    return story


_PHASE_WORDS = {"approach": "approach to the start pose", "play": "exercise",
                "return": "return to rest", "stopped": "stopped (braking, held)",
                "rest": "at rest", "unknown": "phase not recorded"}
_PREFLIGHT_ROWS = (("peak_platform_force_n", "peak_force_n", "peak force on the foot", 1, "N"),
                   ("rms_error_pct", "rms_error_pct", "force tracking error (RMS)", 2, "%"),
                   ("peak_actuator_force_n", "peak_actuator_force_n", "peak actuator force",
                    0, "N"),
                   ("peak_slider_speed_m_s", "peak_slider_speed_m_s", "peak slider speed",
                    4, "m/s"),
                   ("duration_s", None, "exercise duration", 1, "s"))


def _preflight_table(pre: dict[str, Any] | None, f: dict[str, Any], st: Styles,
                     width: float) -> Flowable:
    rows = []
    for pk, fk, label, digits, unit in _PREFLIGHT_ROWS:
        actual = f.get(fk) if fk else (f.get("phase_time_s") or {}).get("play")
        rows.append([label, fmt((pre or {}).get(pk), digits, unit), fmt(actual, digits, unit)])
    pre_rom = (pre or {}).get("platform_angles_deg") or {}
    for axis in ("roll", "pitch"):
        a, b = pre_rom.get(axis), (f.get("rom_deg") or {}).get(axis)
        rows.append([f"{axis} range", _range(a), _range(b)])
    return table(TableSpec(["", "pre-flight (twin)", "this session"], rows,
                           [0.4, 0.3, 0.3]), st, width)


def _range(r: Any) -> str:
    if not r:
        return "—"
    return f"{fmt(r[0], 1)} … {fmt(r[1], 1)} °"


def _cross_check(summary: dict[str, Any], figures: dict[str, Any], st: Styles,
                 width: float) -> Flowable:
    rows = []
    for key, label, digits in (("rms_error_pct", "force RMS error (%)", 3),
                               ("peak_force_n", "peak force (N)", 2)):
        rows.append([label, fmt(summary.get(key), digits), fmt(figures.get(key), digits)])
    rows.append(["stops", str(len(summary.get("stops") or [])),
                 str(len(figures.get("stops") or []))])
    return KeepTogether([p("Controller's summary and this recording", st.h2),
                         table(TableSpec(["figure", "controller", "recording"], rows,
                                         [0.4, 0.3, 0.3]), st, width)])


def _value(v: Any) -> str:
    if v is None:
        return "—"
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_value(x) for x in v) if len(v) <= 8 else f"{len(v)} values"
    if isinstance(v, dict):
        return "; ".join(f"{k}: {_value(x)}" for k, x in v.items())
    return str(v)


# ------------------------------------------------------------------------------ entry

def render_session_report(inp: SessionReportInput, out: str | os.PathLike[str],
                          settings: ReportSettings | None = None, clock: Clock = utc_now,
                          force: bool = False, software_version: str | None = None) -> int:
    """Write the session report PDF; returns its page count."""
    from rt.recording.writer import software_version as installed_version

    settings = settings or ReportSettings()
    st = Styles()
    ctx = ReportContext(TITLE, settings, clock(), software_version or installed_version(),
                        subject=f"Patient {inp.metadata.get('patient_id', 'unknown')}",
                        extra_footer=(f"recording sha256 {inp.recording.sha256[:12]}…"
                                      if inp.recording else "no recording"))
    width = frame_width(ctx)
    story = _first_page(inp, st, width)
    f = _figures(inp)
    figs = [fig for fig in (_force_figure(inp, f), _angle_figure(inp, f),
                            _slider_figure(inp, f)) if fig is not None]
    if figs:
        story.append(PageBreak())
        story.append(p("Plots", st.h1))
        if not _platform_moved(f) and inp.figures is not None:
            story.append(p(f"The platform stayed level (angles within ±{LEVEL_DEG}°): no angle "
                           "plot.", st.small))
        for fig in figs:
            story.append(figure_image(fig, width))
            story.append(Spacer(1, 2 * mm))
    elif inp.recording is None:
        story.append(p("Plots need the session's recording, which is missing.", st.note))
    story.append(PageBreak())
    story += _details(inp, st, width)
    return write_pdf(out, story, ctx, force)
