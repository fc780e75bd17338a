"""The pre-flight report of protocol generators, and the program interface they implement.

The per-cycle output struct, the modes and the statuses are the loop's program interface,
defined in :mod:`rt.references.program` (``rt`` does not import ``protocols``); they are
re-exported here under the names the generators use.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from rt.errors import ProtocolValidationError
from rt.references.program import (
    FORCE_BLOCK,
    FZ,
    FZ_DOT,
    N_FIELDS,
    POSE,
    POSE_DOT,
    POSITION_BLOCK,
    QD,
    QDD,
    SHEAR,
    Mode,
    ProgramInput,
    ProgramStatus,
    Q,
    ReferenceOutput,
)
from rt.safety.limits import PatientLimits, RobotLimits

#: The generators' names for the program interface's input and status.
GeneratorInput = ProgramInput
GeneratorStatus = ProgramStatus

__all__ = [
    "FORCE_BLOCK",
    "FZ",
    "FZ_DOT",
    "N_FIELDS",
    "POSE",
    "POSE_DOT",
    "POSITION_BLOCK",
    "QD",
    "QDD",
    "SHEAR",
    "GeneratorInput",
    "GeneratorStatus",
    "Mode",
    "Q",
    "ReferenceOutput",
    "ValidationReport",
]


@dataclass
class ValidationReport:
    """What ``Generator.validate()`` predicts from the reference itself (SI units).

    ``violations`` lists every breach of the protocol's own limits, of the kinematic workspace
    and of the generator's own constraints; ``ok`` is True when there is none. Peaks of a
    quantity a protocol does not produce are NaN (e.g. force in a ROM exercise without target).
    """

    name: str
    kind: str
    source: str
    mode: Mode
    dt: float
    duration_s: float = 0.0
    n_samples: int = 0
    peak_fz_n: float = math.nan
    min_fz_n: float = math.nan
    peak_fz_rate_n_s: float = math.nan
    roll_range_rad: tuple[float, float] = (math.nan, math.nan)
    pitch_range_rad: tuple[float, float] = (math.nan, math.nan)
    peak_roll_rate_rad_s: float = math.nan
    peak_pitch_rate_rad_s: float = math.nan
    q_range_m: tuple[float, float] = (math.nan, math.nan)
    peak_slider_speed_m_s: float = math.nan
    peak_slider_accel_m_s2: float = math.nan
    #: The patient's ankle centre's horizontal displacement over the exercise (m; NaN without
    #: an ankle setup) and the comfort limit it was checked against.
    ankle_peak_displacement_m: float = math.nan
    ankle_rms_displacement_m: float = math.nan
    ankle_displacement_limit_m: float = math.nan
    violations: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.violations

    def summary(self) -> str:
        """A few human lines (angles in degrees for the clinician)."""
        deg = math.degrees
        lines = [(f"{self.name} ({self.kind}, {self.mode.name.lower()} mode): "
                 f"{self.duration_s:.2f} s, {self.n_samples} samples at {1.0 / self.dt:.0f} Hz")]
        if not math.isnan(self.peak_fz_n):
            lines.append(f"  force {self.min_fz_n:.1f} .. {self.peak_fz_n:.1f} N, "
                         f"rate ≤ {self.peak_fz_rate_n_s:.1f} N/s")
        (r0, r1), (p0, p1) = self.roll_range_rad, self.pitch_range_rad
        lines.append(f"  roll {deg(r0):.2f} .. {deg(r1):.2f}"
                     f" deg (≤ {deg(self.peak_roll_rate_rad_s):.2f} deg/s), pitch "
                     f"{deg(p0):.2f} .. {deg(p1):.2f} deg"
                     f" (≤ {deg(self.peak_pitch_rate_rad_s):.2f} deg/s)")
        lines.append(f"  sliders {self.q_range_m[0]:.4f} .. {self.q_range_m[1]:.4f} m, "
                     f"≤ {self.peak_slider_speed_m_s:.4f} m/s, "
                     f"≤ {self.peak_slider_accel_m_s2:.3f} m/s²")
        lines += [f"  note: {n}" for n in self.notes]
        lines += [f"  VIOLATION: {v}" for v in self.violations]
        return "\n".join(lines)

    def raise_if_failed(self) -> None:
        """Raise ProtocolValidationError naming the file and every violation."""
        if self.violations:
            raise ProtocolValidationError(f"{self.source}: protocol {self.name!r} refused: "
                                          + "; ".join(self.violations))

    def check_against(self, patient: PatientLimits | None = None,
                      robot: RobotLimits | None = None) -> list[str]:
        """Violations of a patient's and the robot's limits (pre-flight's first step).

        Args:
            patient: the patient's ROM, force and angular-speed limits.
            robot: the robot's slider speed/acceleration and platform force limits.
        """
        out: list[str] = []
        deg = math.degrees
        if patient is not None:
            p = patient
            for axis, (lo, hi), rate, (plo, phi) in (
                    ("roll", self.roll_range_rad, self.peak_roll_rate_rad_s,
                     (p.roll_min_deg, p.roll_max_deg)),
                    ("pitch", self.pitch_range_rad, self.peak_pitch_rate_rad_s,
                     (p.pitch_min_deg, p.pitch_max_deg))):
                if deg(lo) < plo - 1e-9 or deg(hi) > phi + 1e-9:
                    out.append(f"{axis} {deg(lo):.2f} .. {deg(hi):.2f} deg leaves the patient's "
                               f"ROM [{plo}, {phi}] deg")
                if deg(rate) > p.max_angular_speed_deg_s + 1e-9:
                    out.append(f"{axis} rate {deg(rate):.2f} deg/s exceeds the patient's "
                               f"{p.max_angular_speed_deg_s} deg/s")
            if self.peak_fz_n > p.max_force_n:
                out.append(f"force {self.peak_fz_n:.1f} N exceeds the patient's "
                           f"{p.max_force_n} N")
        if robot is not None:
            r = robot
            if self.peak_slider_speed_m_s > r.max_slider_speed_m_s:
                out.append(f"slider speed {self.peak_slider_speed_m_s:.4f} m/s exceeds the robot's "
                           f"{r.max_slider_speed_m_s} m/s")
            if self.peak_slider_accel_m_s2 > r.max_slider_accel_m_s2:
                out.append(f"slider acceleration {self.peak_slider_accel_m_s2:.3f} m/s² "
                           f"exceeds the robot's {r.max_slider_accel_m_s2} m/s²")
            if self.peak_fz_n > r.max_platform_force_n:
                out.append(f"force {self.peak_fz_n:.1f} N exceeds the robot's "
                           f"{r.max_platform_force_n} N")
        return out
