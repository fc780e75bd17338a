"""The robot description file: YAML with ``schema_version``, SI units, loaded into typed objects.

A bad file is refused with a ``ConfigurationError`` that names the field and the reason. The
frames and the meaning of every field are documented at the top of
``rt/data/robot_nominal.yaml``.
"""
from __future__ import annotations

import math
from importlib import resources
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from rt.errors import ConfigurationError, validation_summary
from rt.safe_yaml import parse_yaml, read_text_file

SCHEMA_VERSION = 1

PositiveFloat = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
NonNegativeFloat = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
Vector3 = Annotated[list[FiniteFloat], Field(min_length=3, max_length=3)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Geometry(_Strict):
    base_radius_m: PositiveFloat
    platform_radius_m: PositiveFloat
    rod_length_m: PositiveFloat
    leg_angles_deg: Annotated[list[FiniteFloat], Field(min_length=3, max_length=3)]

    @field_validator("leg_angles_deg")
    @classmethod
    def _equally_spaced(cls, angles: list[float]) -> list[float]:
        # The closed-form parasitic yaw (thesis eq. 9) and the (x, y) solution assume legs 120°
        # apart, counter-clockwise; any starting angle is fine.
        for k in (1, 2):
            gap = (angles[k] - angles[0] - 120.0 * k) % 360.0
            if min(gap, 360.0 - gap) > 1e-9:
                raise ValueError("legs must be 120 degrees apart, counter-clockwise "
                                 f"(got {angles})")
        return angles

    @model_validator(mode="after")
    def _reachable(self) -> Geometry:
        if self.rod_length_m <= abs(self.base_radius_m - self.platform_radius_m):
            raise ValueError("rod_length_m must exceed |base_radius_m - platform_radius_m|")
        return self


class Limits(_Strict):
    stroke_m: Annotated[list[FiniteFloat], Field(min_length=2, max_length=2)]
    rod_angle_max_deg: Annotated[float, Field(gt=0.0, lt=90.0)]
    spherical_cone_half_angle_deg: Annotated[float, Field(gt=0.0, lt=90.0)]
    roll_max_deg: Annotated[float, Field(gt=0.0, lt=60.0)]
    pitch_max_deg: Annotated[float, Field(gt=0.0, lt=60.0)]

    @property
    def stroke(self) -> tuple[float, float]:
        """``stroke_m`` as (lower, upper) slider position (m)."""
        return self.stroke_m[0], self.stroke_m[1]

    @field_validator("stroke_m")
    @classmethod
    def _ordered(cls, stroke: list[float]) -> list[float]:
        if not stroke[0] < stroke[1]:
            raise ValueError(f"stroke_m must be [low, high] with low < high (got {stroke})")
        return stroke


class Body(_Strict):
    mass_kg: PositiveFloat
    com_m: Vector3
    inertia_kg_m2: Annotated[list[Vector3], Field(min_length=3, max_length=3)]

    @field_validator("inertia_kg_m2")
    @classmethod
    def _physical(cls, rows: list[list[float]]) -> list[list[float]]:
        inertia = np.array(rows, dtype=float)
        if not np.allclose(inertia, inertia.T, rtol=0.0, atol=1e-12):
            raise ValueError("inertia tensor must be symmetric")
        eig = np.linalg.eigvalsh(inertia)
        if eig[0] < 0.0:
            raise ValueError(f"inertia tensor must be positive semi-definite (eigenvalues {eig})")
        # Triangle inequality of principal moments: a real body satisfies I1 + I2 >= I3.
        if eig[0] + eig[1] < eig[2] * (1.0 - 1e-9):
            raise ValueError(f"principal moments {eig} violate I1 + I2 >= I3 (not a real body)")
        return rows


class Bodies(_Strict):
    slider: Body
    rod: Body
    platform: Body
    sensor: Body


class SensorMount(_Strict):
    offset_m: Vector3


PositiveVector3 = Annotated[list[PositiveFloat], Field(min_length=3, max_length=3)]
#: Bounds of the amplifier's fields: a current loop is closed below its PWM frequency (tens of
#: kHz), and a delay beyond a millisecond is not an amplifier's (it would be the loop's own).
CURRENT_LOOP_MAX_HZ = 50_000.0
AMPLIFIER_DELAY_MAX_S = 1.0e-3
#: Bound of an amplifier's input offset (V): 10 % of a servo amplifier's ±10 V input range
#: (340 N at the slider on the nominal drive). Real ones are millivolts after the balance trim
#: (the twin's ±15 mV); one beyond this is a faulty amplifier or a wrong identification, not an
#: imperfection to compensate, and is refused.
AMPLIFIER_OFFSET_MAX_V = 1.0
OffsetVolts = Annotated[float, Field(ge=-AMPLIFIER_OFFSET_MAX_V, le=AMPLIFIER_OFFSET_MAX_V,
                                     allow_inf_nan=False)]
NonNegativeVector3 = Annotated[list[NonNegativeFloat], Field(min_length=3, max_length=3)]


class Drive(_Strict):
    rotor_inertia_kg_m2: PositiveFloat
    #: Optional per-axis rotor inertias (kg m²), e.g. from identification; overrides the above.
    rotor_inertia_per_axis_kg_m2: PositiveVector3 | None = None
    screw_lead_m: PositiveFloat
    screw_efficiency: Annotated[float, Field(gt=0.0, le=1.0)]
    torque_constant_n_m_per_a: PositiveFloat
    amplifier_gain_a_per_v: PositiveFloat
    command_limit_v: PositiveFloat
    current_limit_a: PositiveFloat
    #: The current-mode amplifiers' response to a command step (the amplifier's datasheet; the
    #: thesis does not name its amplifiers): the current loop's −3 dB bandwidth (Hz; analog
    #: servo amplifiers in current mode close it at 1-3 kHz, the default takes the slow end)
    #: after a transport delay (s; DAC settling plus one PWM period of a 10-20 kHz amplifier
    #: ≈ 100 µs). Optional in a file (the defaults below). The twin runs its truth's values;
    #: identification aligns the commanded forces by the believed ones (``rt.identification``).
    current_loop_bandwidth_hz: Annotated[float, Field(gt=0.0, le=CURRENT_LOOP_MAX_HZ,
                                                      allow_inf_nan=False)] = 1000.0
    amplifier_delay_s: Annotated[float, Field(ge=0.0, le=AMPLIFIER_DELAY_MAX_S,
                                              allow_inf_nan=False)] = 1.0e-4
    #: Each axis' amplifier input offset (V): what the amplifier adds to every command while
    #: the drives are enabled (the DAC's zero-scale error plus the amplifier's residual input
    #: offset), so the force delivered is (command + offset) × force per volt. Measured by
    #: identification (``talus identify``, ``rt.identification.estimate``: a constant force
    #: per axis), for the lab to report; every loop built from the description compensates
    #: it where force becomes volts (the supervisor writes τ·k − offset while the drives are
    #: enabled: ``rt.safety.supervisor_kernel.outputs``). Optional (zero: unknown or trimmed
    #: out, nothing compensated); bounded by ``AMPLIFIER_OFFSET_MAX_V``.
    amplifier_offset_v: Annotated[list[OffsetVolts],
                                  Field(min_length=3, max_length=3)] = [0.0, 0.0, 0.0]

    @property
    def amplifier_offsets_n(self) -> tuple[float, float, float]:
        """The amplifiers' input offsets as forces at the sliders (N), per axis."""
        k = self.force_per_volt_n
        v = self.amplifier_offset_v
        return (v[0] * k, v[1] * k, v[2] * k)

    @property
    def reflected_inertia_kg(self) -> float:
        """Rotor inertia seen at the slider: J (2π / lead)² (kg)."""
        return self.rotor_inertia_kg_m2 * (2.0 * math.pi / self.screw_lead_m) ** 2

    @property
    def reflected_inertia_axes_kg(self) -> tuple[float, float, float]:
        """Per-axis reflected rotor inertia (kg): the per-axis values when given, else the
        common one on every axis."""
        rotor = self.rotor_inertia_per_axis_kg_m2 or [self.rotor_inertia_kg_m2] * 3
        k = (2.0 * math.pi / self.screw_lead_m) ** 2
        return (rotor[0] * k, rotor[1] * k, rotor[2] * k)

    @property
    def force_per_amp_n(self) -> float:
        """Screw force per motor current: Kt η 2π / lead (N/A)."""
        return (self.torque_constant_n_m_per_a * self.screw_efficiency * 2.0 * math.pi
                / self.screw_lead_m)

    @property
    def current_loop_time_constant_s(self) -> float:
        """The current loop's first-order time constant 1 / (2π bandwidth) (s)."""
        return 1.0 / (2.0 * math.pi * self.current_loop_bandwidth_hz)

    @property
    def force_per_volt_n(self) -> float:
        """Screw force per amplifier command volt (N/V), current-mode amplifier."""
        return self.force_per_amp_n * self.amplifier_gain_a_per_v


class Friction(_Strict):
    viscous_n_s_per_m: NonNegativeFloat
    coulomb_n: NonNegativeFloat
    coulomb_smoothing_m_s: PositiveFloat
    static_n: NonNegativeFloat
    stribeck_velocity_m_s: PositiveFloat
    stiction_smoothing_m_s: PositiveFloat
    #: Optional per-axis values (identified, or the twin's truth); override the common ones.
    viscous_per_axis_n_s_per_m: NonNegativeVector3 | None = None
    coulomb_per_axis_n: NonNegativeVector3 | None = None
    static_per_axis_n: NonNegativeVector3 | None = None

    @property
    def viscous_axes(self) -> tuple[float, float, float]:
        """Viscous coefficient per axis (N s/m)."""
        v = self.viscous_per_axis_n_s_per_m or [self.viscous_n_s_per_m] * 3
        return (v[0], v[1], v[2])

    @property
    def coulomb_axes(self) -> tuple[float, float, float]:
        """Coulomb level per axis (N)."""
        v = self.coulomb_per_axis_n or [self.coulomb_n] * 3
        return (v[0], v[1], v[2])

    @property
    def static_axes(self) -> tuple[float, float, float]:
        """Static break-away level per axis (N)."""
        v = self.static_per_axis_n or [self.static_n] * 3
        return (v[0], v[1], v[2])


class Encoder(_Strict):
    m_per_count: PositiveFloat
    counter_bits: Annotated[int, Field(ge=8, le=32)]
    midpoint: Annotated[int, Field(ge=0)]

    @model_validator(mode="after")
    def _midpoint_fits(self) -> Encoder:
        if self.midpoint >= 2 ** self.counter_bits:
            raise ValueError(f"midpoint {self.midpoint} does not fit {self.counter_bits} bits")
        return self


class Dac(_Strict):
    bits: Annotated[int, Field(ge=8, le=24)]
    range_v: Annotated[list[FiniteFloat], Field(min_length=2, max_length=2)]


class RobotDescription(_Strict):
    """Everything the model, the twin and the drivers need to know about one robot."""

    schema_version: int
    name: str
    gravity_m_s2: PositiveFloat
    geometry: Geometry
    limits: Limits
    bodies: Bodies
    sensor: SensorMount
    drive: Drive
    friction: Friction
    encoder: Encoder
    dac: Dac

    @field_validator("schema_version")
    @classmethod
    def _known_version(cls, version: int) -> int:
        if version != SCHEMA_VERSION:
            raise ValueError(f"unsupported schema_version {version}; this talus reads "
                             f"{SCHEMA_VERSION}")
        return version

    @model_validator(mode="after")
    def _stroke_within_rod(self) -> RobotDescription:
        stroke = self.limits.stroke_m
        if stroke[0] < 0.0:
            raise ValueError("limits.stroke_m must start at or above 0 (bottom of the guide)")
        return self


def _format_validation_error(exc: ValidationError, source: str) -> str:
    return f"robot description {source} is invalid: {validation_summary(exc)}"


def description_from_dict(data: Any, source: str = "<dict>") -> RobotDescription:
    """Validate a parsed description; raises ``ConfigurationError`` naming the bad field."""
    if not isinstance(data, dict):
        raise ConfigurationError(f"robot description {source} must be a YAML mapping, "
                                 f"got {type(data).__name__}")
    try:
        return RobotDescription.model_validate(data)
    except ValidationError as exc:
        raise ConfigurationError(_format_validation_error(exc, source)) from None


def load_description(path: str | Path | None = None) -> RobotDescription:
    """Load a description file; ``None`` loads the packaged nominal twin description."""
    if path is None:
        text = resources.files("rt.data").joinpath("robot_nominal.yaml").read_text()
        source = "robot_nominal.yaml (packaged)"
    else:
        text = read_text_file(path, "robot description")
        source = str(path)
    data, _ = parse_yaml(text, f"robot description {source}")
    return description_from_dict(data, source)
