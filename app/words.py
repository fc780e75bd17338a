"""What the robot's machine states and causes mean, in a clinician's words (GUI.md).

The RT process names causes for engineers (``rom_pitch``, ``heartbeat_lost``, ``stroke_2``);
the screen says "pitch at the end of the patient's range", with the value and the limit when
the event carries them. Every string here is translatable.
"""
from __future__ import annotations

import math
import re
from typing import Any

from app.i18n import tr

#: Colours of the robot states (GUI.md: grey idle, green running, amber soft stop, red hard).
STATE_COLOURS = {"idle": "#7a7a7a", "running": "#1e8a3c", "soft_stop": "#d08a00",
                 "hard_stop": "#c0262d", "disconnected": "#c0262d"}


def state_words(state: str) -> str:
    """The band's words for a display state (see :func:`display_state`)."""
    return {
        "idle": tr("Idle — robot at rest"),
        "running": tr("Running"),
        "soft_stop": tr("Stopped (soft stop) — reset to continue"),
        "hard_stop": tr("EMERGENCY STOP — drives off"),
        "disconnected": tr("Connection to the robot lost — motion disabled"),
    }.get(state, state)


def display_state(status: dict[str, Any] | None, connected: bool) -> str:
    """One of idle, running, soft_stop, hard_stop, disconnected from a ``status`` reply."""
    if not connected or status is None:
        return "disconnected"
    mode = status.get("state", "run")
    if mode == "hard_stop":
        return "hard_stop"
    if mode == "soft_stop":
        return "soft_stop"
    moving = status.get("session") is not None or status.get("phase_name") not in ("rest", None)
    return "running" if moving else "idle"


def _fixed(cause: str) -> str | None:
    return {
        "estop_gui": tr("E-STOP pressed on this screen"),
        "estop_keyboard": tr("E-STOP pressed on the keyboard"),
        "estop_cli": tr("E-STOP sent from a terminal"),
        "estop_hardware": tr("the emergency-stop button was pressed"),
        "hand_stop": tr("the patient pressed the hand switch"),
        "stop_client": tr("STOP pressed"),
        "drive_channel": tr("a motor drive failed"),
        "fk_failed": tr("the platform position is unknown"),
        "encoder_jump": tr("a position sensor gave an impossible reading"),
        "force_saturated": tr("force sensor overloaded"),
        "force_stale": tr("the force sensor stopped answering"),
        "force_implausible": tr("the force sensor reading is invalid"),
        "force_limit": tr("force above the patient's limit"),
        "deadline_overruns": tr("the control computer fell behind"),
        "heartbeat_lost": tr("lost contact with the controlling screen"),
        "rom_roll": tr("inversion/eversion at the end of the patient's range"),
        "rom_pitch": tr("dorsi/plantarflexion at the end of the patient's range"),
        "angular_speed_roll": tr("inversion/eversion faster than the patient's limit"),
        "angular_speed_pitch": tr("dorsi/plantarflexion faster than the patient's limit"),
        "pulling": tr("the platform pulled on the foot"),
        "pull_in_stop": tr("the foot is still pulled after the stop"),
        "contact_lost": tr("contact with the foot or plate was lost during force control"),
        "component_failed": tr("the control computer found a fault in its own software"),
    }.get(cause)


def cause_words(cause: str) -> str:
    """A cause name in a clinician's words (unknown names are shown as they are)."""
    fixed = _fixed(cause)
    if fixed is not None:
        return fixed
    m = re.fullmatch(r"(stroke|stroke_margin|speed|accel|tracking|actuator_force|"
                     r"encoder_frozen|drive_saturated)_(\d)", cause)
    if m:
        kind, leg = m.group(1), int(m.group(2)) + 1
        text = {
            "stroke": tr("actuator %1 at the end of its travel"),
            "stroke_margin": tr("actuator %1 near the end of its travel"),
            "speed": tr("actuator %1 moving too fast"),
            "accel": tr("actuator %1 accelerating too hard"),
            "tracking": tr("actuator %1 could not follow its path"),
            "actuator_force": tr("actuator %1 pushing too hard"),
            "encoder_frozen": tr("position sensor %1 stopped changing"),
            "drive_saturated": tr("actuator %1 held at its force limit (blocked or "
                                  "shaking)"),
        }[kind]
        return text.replace("%1", str(leg))
    m = re.fullmatch(r"dac_card_(\d)", cause)
    if m:   # a failover: the spare card took over (a warning, the session goes on)
        return tr("motor drive card %1 failed; the spare card took over").replace(
            "%1", str(int(m.group(1)) + 1))
    m = re.fullmatch(r"estop_(\w+)", cause)
    if m:   # an e-stop source this screen has no words for yet
        return tr("E-STOP (%1)").replace("%1", m.group(1))
    return cause


def alarm_instruction(alarm: dict[str, Any]) -> str:
    """What the staff must do about an alarm the RT status carries (``status["alarms"]``),
    one specific instruction: what is happening, the force, what to do."""
    if alarm.get("cause") == "pull_in_stop":
        fz = alarm.get("fz_n")
        force = f"{abs(fz):.0f}" if isinstance(fz, (int, float)) and math.isfinite(fz) else "?"
        return tr("ALARM: the robot has stopped but the strap is still pulling the patient's "
                  "foot down with %1 N, and the robot cannot lift it. Support the patient's "
                  "leg and release the strap now.").replace("%1", force)
    return tr("ALARM: %1").replace("%1", cause_words(str(alarm.get("cause", ""))))


def event_words(event: dict[str, Any]) -> str:
    """An event as one line: the cause in words, then its values in clinical units."""
    text = cause_words(str(event.get("cause", "")))
    values = event.get("values") or {}
    parts = []
    for key, value in values.items():
        if not isinstance(value, (int, float)) or isinstance(value, bool) \
                or not math.isfinite(value):
            continue
        if key.endswith("_deg"):
            parts.append(f"{value:.1f}°")
        elif key.endswith("_deg_s"):
            parts.append(f"{value:.1f} °/s")
        elif key in ("force_n", "fz_n", "limit_n") or key.endswith("_n"):
            parts.append(f"{value:.0f} N")
    return text if not parts else f"{text} ({', '.join(parts)})"


def local_time(iso: object) -> str:
    """An ISO-8601 instant of the clinical record (UTC) as the clinic reads it: local time,
    ``YYYY-MM-DD HH:MM``; what cannot be read is shown as it is (never hidden)."""
    import datetime as dt

    if not isinstance(iso, str) or not iso:
        return "—"
    try:
        when = dt.datetime.fromisoformat(iso)
    except ValueError:
        return iso
    if when.tzinfo is None:
        when = when.replace(tzinfo=dt.UTC)         # the record stores UTC
    return f"{when.astimezone():%Y-%m-%d %H:%M}"
