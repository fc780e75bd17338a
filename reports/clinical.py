"""Clinical words for the robot's quantities: ankle directions, protocol kinds, stop causes.

The platform's angles map to the ankle as the protocols define it (``protocols.schema``): the
foot lies along +x, toes towards +x, so **plantarflexion is positive pitch** and dorsiflexion
negative pitch; **inversion is positive roll for a right foot** and negative roll for a left
foot (eversion the opposite).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

#: Below this range (°) on both axes the platform is said to have stayed level.
LEVEL_DEG = 0.5
#: Directions in the order clinicians read them (GUI.md: the patient's card).
DIRECTIONS = ("dorsiflexion", "plantarflexion", "inversion", "eversion")

KIND_WORDS = {
    "sine_fz": "sinusoidal force in Z",
    "gait_replay": "gait ground-reaction force replay",
    "ankle_rom": "passive ankle range of motion",
    "isometric_hold": "isometric holds at set angles",
    "active_assist": "active-assist exercise",
    "position_playback": "position trajectory playback",
}


def _axis_and_sign(direction: str, side: str) -> tuple[str, float]:
    """Which platform axis a direction moves, and the sign of the angle in that direction."""
    if direction == "plantarflexion":
        return "pitch", 1.0
    if direction == "dorsiflexion":
        return "pitch", -1.0
    inv = 1.0 if side == "right" else -1.0
    if direction == "inversion":
        return "roll", inv
    if direction == "eversion":
        return "roll", -inv
    raise ValueError(f"unknown direction {direction!r}")


def reached_by_direction(rom_deg: Mapping[str, Any] | None, side: str
                         ) -> dict[str, float | None]:
    """ROM reached per direction (degrees, ≥ 0) from ``{"roll": [min, max], "pitch": [...]}``.

    A direction the platform never moved into reads 0; an axis without data reads None.
    """
    out: dict[str, float | None] = {}
    for d in DIRECTIONS:
        axis, sign = _axis_and_sign(d, side)
        rng = (rom_deg or {}).get(axis)
        if not rng or any(v is None or (isinstance(v, float) and math.isnan(v)) for v in rng):
            out[d] = None
            continue
        lo, hi = float(rng[0]), float(rng[1])
        out[d] = max(0.0, hi if sign > 0 else -lo)
    return out


def limits_by_direction(limits: Mapping[str, Any] | None, side: str
                        ) -> dict[str, float | None]:
    """The ROM limit per direction (degrees, ≥ 0) from a PatientLimits-like dict."""
    out: dict[str, float | None] = {}
    for d in DIRECTIONS:
        axis, sign = _axis_and_sign(d, side)
        key = f"{axis}_{'max' if sign > 0 else 'min'}_deg"
        v = (limits or {}).get(key)
        out[d] = None if v is None else abs(float(v)) if (float(v) * sign) >= 0 else 0.0
    return out


def narrowed_limits(patient: Mapping[str, Any] | None, protocol: Mapping[str, Any] | None
                    ) -> dict[str, float] | None:
    """The limits in force: the patient's, narrowed by the protocol's (most restrictive).

    Without the patient's limits, the protocol's alone (what is known to have applied);
    None when neither is known.
    """
    if patient is None and not protocol:
        return None
    out = {k: float(v) for k, v in (patient or {}).items() if isinstance(v, (int, float))}
    for k, v in (protocol or {}).items():
        if v is None or not isinstance(v, (int, float)):
            continue
        if k.endswith("_min_deg"):
            out[k] = max(out.get(k, -math.inf), float(v))
        elif k in out:
            out[k] = min(out[k], float(v))
        else:
            out[k] = float(v)
    return out


#: Stop cause (prefix) → who or what triggered it, and the words a clinician reads.
_TRIGGERS: tuple[tuple[str, str, str], ...] = (
    ("estop_gui", "clinician", "E-STOP pressed on the screen"),
    ("estop_keyboard", "clinician", "E-STOP key pressed"),
    ("estop_hardware", "operator", "the hardware emergency-stop button was pressed"),
    ("estop", "operator", "emergency stop requested"),
    ("hand_stop", "patient", "the patient pressed the hand-held stop"),
    ("stop_client", "clinician", "stop requested from the software"),
    ("heartbeat_lost", "system", "lost contact with the controlling computer"),
    ("rom_", "safety supervisor", "the ankle reached the patient's range-of-motion limit"),
    ("angular_speed_", "safety supervisor", "the platform turned faster than the patient's limit"),
    ("force_limit", "safety supervisor", "force above the patient's limit"),
    ("force_saturated", "safety supervisor", "the force sensor was overloaded"),
    ("force_stale", "safety supervisor", "the force sensor stopped answering"),
    ("force_implausible", "safety supervisor", "the force sensor gave an implausible reading"),
    ("tracking_", "safety supervisor", "the robot could not follow its planned motion"),
    ("speed_", "safety supervisor", "a slider moved faster than the robot allows"),
    ("stroke", "safety supervisor", "a slider reached the end of its travel"),
    ("encoder", "safety supervisor", "a position sensor (encoder) failed"),
    ("fk_failed", "safety supervisor", "the platform's position could not be computed"),
    ("drive_channel", "safety supervisor", "a motor drive channel failed"),
    ("deadline_overruns", "safety supervisor", "the controller ran late repeatedly"),
    ("drive_saturated", "safety supervisor",
     "a motor was held at its force limit (blocked, or the control shaking)"),
    ("pulling", "safety supervisor", "the platform pulled on the foot"),
    ("contact_lost", "safety supervisor",
     "contact with the foot or plate was lost during force control"),
)


def stop_trigger(cause: str) -> tuple[str, str]:
    """``(who/what triggered it, what happened in a clinician's words)`` for a stop cause."""
    for prefix, who, words in _TRIGGERS:
        if cause.startswith(prefix):
            return who, words
    return "safety supervisor", cause.replace("_", " ")


def reaction_words(reaction: str) -> str:
    return {"soft_stop": "soft stop (braked to a hold)",
            "hard_stop": "hard stop (drives switched off)",
            "failover": "switched to the backup drive card",
            "warn": "warning"}.get(reaction, reaction.replace("_", " "))
