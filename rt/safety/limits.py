"""Limits in three layers (DESIGN 6): robot (the machine), patient (set by the clinician,
stored with the patient), protocol (the exercise). The effective limit of each quantity is the
most restrictive of the layers that set it.

Angles in the files are degrees (what clinicians write); everything is converted to SI once.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, model_validator

Pos = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


class _Limits(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class RobotLimits(_Limits):
    """What the machine tolerates (nominal twin values)."""

    stroke_margin_m: Annotated[float, Field(ge=0.0, le=0.05)] = 0.005
    max_slider_speed_m_s: Pos = 0.20
    max_slider_accel_m_s2: Pos = 5.0
    max_command_v: Pos = 6.0
    max_actuator_force_n: Pos = 2000.0
    max_tracking_error_m: Pos = 0.003
    max_platform_force_n: Pos = 1800.0
    deadline_overruns: Annotated[int, Field(ge=1, le=1000)] = 5
    heartbeat_timeout_s: Pos = 0.25
    frozen_encoder_s: Pos = 0.05
    frozen_min_ref_speed_m_s: Pos = 0.004
    #: In force control the platform only pushes on the foot: measured Fz below 0 N for this
    #: long (s) means it is pulling → soft stop. Longer than the sensor's noise crossings.
    max_pull_s: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] = 0.02
    #: Pre-flight: the drives may saturate (command at max_command_v, or the actuator force
    #: asked beyond max_actuator_force_n) for at most this long at a time (s).
    max_saturation_s: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] = 0.02
    #: Sustained drive saturation (issue 15): a drive's command at its limit (the force of
    #: ``max_command_v``) for more than ``max_saturated_fraction`` of the last
    #: ``saturation_window_s`` → soft stop (``drive_saturated_<axis>``; hard stop when it goes
    #: on a whole window into a soft stop): an unstable force loop, a stuck contact or an
    #: obstruction the drives push against in vain. Legitimate saturation is brief (a heel
    #: strike 3-4 ms, a pull's yank ~20 ms; pre-flight allows ``max_saturation_s`` at a time).
    #: Twin figures (branch satwatch5's note): the most any 0.5 s window held in the library's
    #: pre-flights, the fault matrix, the calibration steps push and the payload step is 0, in
    #: the never-pull yank 32 ms (6.4 %); the shear push's limit cycle 82-87 %.
    saturation_window_s: Annotated[float, Field(ge=0.05, le=5.0, allow_inf_nan=False)] = 0.5
    max_saturated_fraction: Annotated[float, Field(gt=0.0, lt=1.0, allow_inf_nan=False)] = 0.5
    #: The compliant hold after a force-control soft stop (issue 15): while the foot is
    #: pulled the hold's reference rises at this speed (m/s), by at most this far (m; 0: the
    #: hold does not yield), then holds (``ProgramReference._yield_step`` says why: a hard
    #: stop's brakes would hold a deeper pull). Ranges as ``rt.references.sequencer``'s.
    pull_yield_speed_m_s: Annotated[float, Field(ge=0.001, le=0.05, allow_inf_nan=False)] = 0.02
    pull_yield_max_m: Annotated[float, Field(ge=0.0, le=0.05, allow_inf_nan=False)] = 0.02

    @model_validator(mode="after")
    def _saturation_beyond_preflight(self) -> RobotLimits:
        # The window must tolerate what pre-flight lets a protocol do (one stretch at the
        # drives' limit of max_saturation_s), else an accepted protocol would be stopped.
        allowed = self.max_saturated_fraction * self.saturation_window_s
        if not allowed > self.max_saturation_s:
            raise ValueError(
                f"max_saturated_fraction × saturation_window_s ({self.max_saturated_fraction:g}"
                f" × {self.saturation_window_s:g} s = {allowed:g} s) must exceed "
                f"max_saturation_s ({self.max_saturation_s:g} s), the saturation pre-flight "
                "accepts at a time")
        return self


class PatientLimits(_Limits):
    """Set by the clinician per patient and session (Biodex-style ROM with end cushion)."""

    roll_min_deg: Finite = -20.0
    roll_max_deg: Finite = 20.0
    pitch_min_deg: Finite = -20.0
    pitch_max_deg: Finite = 20.0
    max_force_n: Pos = 800.0
    max_angular_speed_deg_s: Pos = 60.0
    #: Stops still under way when this close to a ROM end are escalated (deg).
    rom_tolerance_deg: Annotated[float, Field(gt=0.0, le=5.0)] = 0.5

    @model_validator(mode="after")
    def _ordered(self) -> PatientLimits:
        if not self.roll_min_deg < self.roll_max_deg:
            raise ValueError("roll_min_deg must be below roll_max_deg")
        if not self.pitch_min_deg < self.pitch_max_deg:
            raise ValueError("pitch_min_deg must be below pitch_max_deg")
        return self


class ProtocolLimits(_Limits):
    """A protocol may only narrow the patient's limits; unset fields leave them as they are."""

    roll_min_deg: Finite | None = None
    roll_max_deg: Finite | None = None
    pitch_min_deg: Finite | None = None
    pitch_max_deg: Finite | None = None
    max_force_n: Pos | None = None
    max_angular_speed_deg_s: Pos | None = None


@dataclass(frozen=True)
class EffectiveLimits:
    """The most restrictive combination, in SI units, as plain floats for the cycle."""

    stroke_lo_m: float
    stroke_hi_m: float
    stroke_margin_m: float
    max_slider_speed_m_s: float
    max_slider_accel_m_s2: float
    max_command_v: float
    max_actuator_force_n: float
    max_tracking_error_m: float
    max_force_n: float
    roll_min: float
    roll_max: float
    pitch_min: float
    pitch_max: float
    max_angular_speed: float
    rom_tolerance: float
    deadline_overruns: int
    heartbeat_timeout_s: float
    frozen_encoder_s: float
    frozen_min_ref_speed_m_s: float
    max_pull_s: float
    saturation_window_s: float
    max_saturated_fraction: float


def effective(stroke_m: tuple[float, float], robot: RobotLimits, patient: PatientLimits,
              protocol: ProtocolLimits | None = None) -> EffectiveLimits:
    """Combine the layers (most restrictive wins)."""
    protocol = protocol or ProtocolLimits()

    def narrow_min(a: float, b: float | None) -> float:
        return a if b is None else max(a, b)

    def narrow_max(a: float, b: float | None) -> float:
        return a if b is None else min(a, b)

    rad = math.radians
    return EffectiveLimits(
        stroke_lo_m=stroke_m[0], stroke_hi_m=stroke_m[1],
        stroke_margin_m=robot.stroke_margin_m,
        max_slider_speed_m_s=robot.max_slider_speed_m_s,
        max_slider_accel_m_s2=robot.max_slider_accel_m_s2,
        max_command_v=robot.max_command_v,
        max_actuator_force_n=robot.max_actuator_force_n,
        max_tracking_error_m=robot.max_tracking_error_m,
        max_force_n=narrow_max(min(patient.max_force_n, robot.max_platform_force_n),
                               protocol.max_force_n),
        roll_min=rad(narrow_min(patient.roll_min_deg, protocol.roll_min_deg)),
        roll_max=rad(narrow_max(patient.roll_max_deg, protocol.roll_max_deg)),
        pitch_min=rad(narrow_min(patient.pitch_min_deg, protocol.pitch_min_deg)),
        pitch_max=rad(narrow_max(patient.pitch_max_deg, protocol.pitch_max_deg)),
        max_angular_speed=rad(narrow_max(patient.max_angular_speed_deg_s,
                                         protocol.max_angular_speed_deg_s)),
        rom_tolerance=rad(patient.rom_tolerance_deg),
        deadline_overruns=robot.deadline_overruns,
        heartbeat_timeout_s=robot.heartbeat_timeout_s,
        frozen_encoder_s=robot.frozen_encoder_s,
        frozen_min_ref_speed_m_s=robot.frozen_min_ref_speed_m_s,
        max_pull_s=robot.max_pull_s,
        saturation_window_s=robot.saturation_window_s,
        max_saturated_fraction=robot.max_saturated_fraction,
    )
