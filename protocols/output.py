"""The per-cycle output struct, the statuses and the pre-flight report of protocol generators.

A generator writes one :class:`ReferenceOutput` per cycle (CONVENTIONS 6: allocated once by the
caller, filled in place, a status returned instead of an exception). Every reference lives in one
float64 buffer so a cycle is one or two block copies; the named fields are views into it:

========================  =========  ==============================================================
field                     unit       meaning
========================  =========  ==============================================================
``q_ref``                 m          slider positions (3,), from ``kinematics.ik`` of ``pose_ref``
``qd_ref``                m/s        slider velocities (3,)
``qdd_ref``               m/s²       slider accelerations (3,)
``pose_ref``              m, rad     platform pose (z, roll, pitch)
``pose_dot_ref``          m/s, rad/s its time derivative
``fz_ref``                N          force in Z on the platform, positive pushing up into what it
                                     touches (force modes); in position modes the isometric target
                                     shown to the patient, NaN when there is none
``fz_ref_dot``            N/s        its time derivative (NaN with it)
``shear_ref``             N          (fx, fy) of a gait record when ``include_shear``; carried for
                                     recording and comparison only — a 3-PRS cannot apply shear
========================  =========  ==============================================================

``mode`` says which references the loop must track: :attr:`Mode.POSITION` (the q references;
the force fields are informative) or :attr:`Mode.FORCE` (``fz_ref`` in Z, the angles of
``pose_ref`` held, ``q_ref`` is the pose where the contact starts). ``done`` is True from the
cycle that emits the last sample on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from rt.errors import ProtocolValidationError
from rt.safety.limits import PatientLimits, RobotLimits

# Column layout of ReferenceOutput.buf (and of the generators' precomputed tables).
Q, QD, QDD = slice(0, 3), slice(3, 6), slice(6, 9)
POSE, POSE_DOT = slice(9, 12), slice(12, 15)
FZ, FZ_DOT = 15, 16
SHEAR = slice(17, 19)
N_FIELDS = 19
#: Block written per cycle by position generators: motion + force target (columns 0..16).
POSITION_BLOCK = slice(0, 17)
#: Block written per cycle by force generators: fz, fz_dot, fx, fy (columns 15..18).
FORCE_BLOCK = slice(15, 19)


class Mode(IntEnum):
    """Which references the loop tracks."""

    POSITION = 0
    FORCE = 1


class GeneratorStatus(IntEnum):
    """Per-cycle result of ``Generator.update``; negative values are errors (outputs unchanged)."""

    RUNNING = 0  # a sample inside the protocol was written
    FINISHED = 1  # the last sample was written (and is written again on later calls)
    ERROR_NOT_VALIDATED = -1  # validate() was not called, or reported violations
    ERROR_INPUT = -2  # active assist: a non-finite measured torque; the state was not advanced
    ERROR_KINEMATICS = -3  # active assist: the pose could not be converted to slider positions


class ReferenceOutput:
    """Preallocated per-cycle references (module docstring for the fields and units)."""

    __slots__ = ("buf", "q_ref", "qd_ref", "qdd_ref", "pose_ref", "pose_dot_ref", "shear_ref",
                 "blocks", "mode", "done", "index")

    def __init__(self) -> None:
        self.buf = np.zeros(N_FIELDS)
        self.buf[FZ] = self.buf[FZ_DOT] = math.nan
        self.q_ref = self.buf[Q]
        self.qd_ref = self.buf[QD]
        self.qdd_ref = self.buf[QDD]
        self.pose_ref = self.buf[POSE]
        self.pose_dot_ref = self.buf[POSE_DOT]
        self.shear_ref = self.buf[SHEAR]
        # Prebuilt views so a cycle copies a table row without creating a slice view.
        self.blocks = (self.buf[POSITION_BLOCK], self.buf[FORCE_BLOCK])
        self.mode: Mode = Mode.POSITION
        self.done = False
        self.index = 0  # the sample written by the last update

    @property
    def fz_ref(self) -> float:
        """Force reference in Z (N), positive pushing up; NaN when there is none."""
        return float(self.buf[FZ])

    @property
    def fz_ref_dot(self) -> float:
        """Its time derivative (N/s)."""
        return float(self.buf[FZ_DOT])


class GeneratorInput:
    """Measurements an interactive generator (active assist) reads each cycle.

    The loop writes plain floats before ``update``: the patient's torque on the platform about
    its roll (x) and pitch (y) axes (N·m, platform frame, from the force/torque sensor with the
    platform's own weight removed).
    """

    __slots__ = ("tau_roll_nm", "tau_pitch_nm")

    def __init__(self) -> None:
        self.tau_roll_nm = 0.0
        self.tau_pitch_nm = 0.0


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
    violations: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.violations

    def summary(self) -> str:
        """A few human lines (angles in degrees for the clinician)."""
        deg = math.degrees
        lines = [f"{self.name} ({self.kind}, {self.mode.name.lower()} mode): "
                 f"{self.duration_s:.2f} s, {self.n_samples} samples at {1.0 / self.dt:.0f} Hz"]
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
