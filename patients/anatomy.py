"""Clinical names of the limits and their signs on the robot.

The convention is the protocols' (``protocols.base.FOOT_MOUNTING``, ``anatomical_to_platform``):
this module uses their function, so the two cannot drift apart. The robot's limits are ``rt.safety.limits.PatientLimits``: roll and pitch of the platform frame
P (robot_nominal.yaml: z up, right-handed; roll about P's x, pitch about P's y). The foot is
strapped with the toes towards P's +x (the heel towards -x). Then:

* **pitch = dorsi/plantar flexion.** A positive pitch lowers +x, the toes: positive pitch is
  plantarflexion, negative pitch dorsiflexion. ``pitch_max_deg = plantarflexion``,
  ``pitch_min_deg = -dorsiflexion``.
* **roll = inversion/eversion, and the sign depends on the foot.** A positive roll raises +y,
  the foot's left edge. For a right foot that is the medial edge, so positive roll is
  inversion; for a left foot positive roll is eversion:
  right foot ``roll_max_deg = inversion, roll_min_deg = -eversion``;
  left foot ``roll_max_deg = eversion, roll_min_deg = -inversion``.

Clinical ROM values are degrees from neutral in the named direction (normally positive; a
negative value means the range does not reach neutral in that direction).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

from patients.errors import InputError
from patients.models import Side


@dataclass(frozen=True)
class ClinicalRom:
    """Range of motion in clinical terms (deg from neutral, each in its own direction)."""

    dorsiflexion_deg: float
    plantarflexion_deg: float
    inversion_deg: float
    eversion_deg: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def _foot(side: Side | str | None) -> Side:
    try:
        foot = Side(side) if side is not None else None
    except ValueError:
        foot = None
    if foot not in (Side.LEFT, Side.RIGHT):
        raise InputError(f"the foot on the platform must be 'left' or 'right' to map inversion/"
                         f"eversion to roll (got {side!r}); give --side, or set roll directly")
    return foot


def _inversion_sign(foot: Side) -> float:
    """+1 when positive roll is inversion for this foot (right), -1 when eversion (left)."""
    from protocols.base import anatomical_to_platform
    return anatomical_to_platform(0.0, 1.0, foot.value)[0]


def to_robot(rom: ClinicalRom, side: Side | str | None) -> dict[str, float]:
    """``PatientLimits`` roll/pitch fields (deg) for ``rom`` on the ``side`` foot."""
    if _inversion_sign(_foot(side)) > 0:
        roll_min, roll_max = -rom.eversion_deg, rom.inversion_deg
    else:
        roll_min, roll_max = -rom.inversion_deg, rom.eversion_deg
    return {"roll_min_deg": roll_min, "roll_max_deg": roll_max,
            "pitch_min_deg": -rom.dorsiflexion_deg, "pitch_max_deg": rom.plantarflexion_deg}


def to_clinical(limits: dict[str, float], side: Side | str | None) -> ClinicalRom | None:
    """The clinical view of robot limits (None when the foot is not known)."""
    try:
        foot = _foot(side)
    except InputError:
        return None
    if _inversion_sign(foot) > 0:
        inversion, eversion = limits["roll_max_deg"], -limits["roll_min_deg"]
    else:
        inversion, eversion = -limits["roll_min_deg"], limits["roll_max_deg"]
    return ClinicalRom(dorsiflexion_deg=-limits["pitch_min_deg"],
                       plantarflexion_deg=limits["pitch_max_deg"],
                       inversion_deg=inversion, eversion_deg=eversion)
