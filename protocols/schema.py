"""Protocol file schema: one pydantic model per kind, discriminated by ``kind`` (CONVENTIONS 9).

Every file carries ``schema_version: 1``, ``kind``, ``name``, an optional ``description`` and an
optional ``limits`` block (the fields of :class:`rt.safety.limits.ProtocolLimits`: roll/pitch
min/max in degrees, ``max_force_n``, ``max_angular_speed_deg_s``; a protocol can only narrow the
patient's limits). Units are in the field names; angles are degrees in the files (what clinicians
write) and are converted to radians once, by the generators.

Kinds:

* ``sine_fz`` — sinusoidal force in Z (N, positive pushing up into what the platform touches),
  cosine ramps in and out, the pose held.
* ``gait_replay`` — a ground-reaction-force record (C3D force plate or CSV) replayed in Z at
  real speed, scaled to a percentage of the patient's body weight, repeated with rests.
* ``ankle_rom`` — passive range of motion: dorsi/plantar flexion (pitch), inversion/eversion
  (roll), or an elliptical circuit through the four ends; smooth profiles, holds at the ends.
* ``isometric_hold`` — the platform held at set angles while the patient pushes; optional
  force target shown to the patient, or per hold an ankle-torque target the RT process
  regulates (``torque``, ``torque_control``).
* ``active_assist`` — an admittance (virtual mass, damping, stiffness per axis) driven by the
  patient's torque, pulled towards a guide motion by ``assistance_gain``.
* ``position_playback`` — slider positions from a CSV file (thesis 3.7.4).

Anatomical directions map to the platform through :data:`FOOT_MOUNTING` (generators): the foot
lies along +x (toes towards +x), so plantarflexion is positive pitch; inversion is positive roll
for a right foot and negative roll for a left foot.

Refusals are :class:`~rt.errors.ProtocolValidationError` naming the file, the line when known,
the field path and the reason (:func:`validate_protocol_data`).
"""
from __future__ import annotations

import math
import types
import typing
from collections.abc import Callable, Sequence
from pathlib import PurePath
from typing import Annotated, Any, Literal, Union

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    TypeAdapter,
    ValidationError,
    field_validator,
    model_validator,
)

from rt.errors import ProtocolValidationError
from rt.safety.limits import ProtocolLimits

#: The schema version this code reads and writes.
SCHEMA_VERSION = 1
#: Migrations from older versions: ``MIGRATIONS[v]`` turns a version-v mapping into version v+1.
#: Empty while version 1 is the only one; a new version adds its predecessor's migration here.
MIGRATIONS: dict[int, Callable[[dict[str, Any]], dict[str, Any]]] = {}

# Field types (finite floats only: YAML's .nan/.inf are refused everywhere).
Angle = Annotated[float, Field(ge=-30.0, le=30.0, allow_inf_nan=False)]
RomDeg = Annotated[float, Field(ge=0.0, le=30.0, allow_inf_nan=False)]
Speed = Annotated[float, Field(gt=0.0, le=60.0, allow_inf_nan=False)]
AccelDeg = Annotated[float, Field(gt=0.0, le=1000.0, allow_inf_nan=False)]
JerkDeg = Annotated[float, Field(gt=0.0, le=20000.0, allow_inf_nan=False)]


class FieldProblem(ValueError):
    """Raised by cross-field validators to blame one field (``path`` is relative to the model)."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(message)
        self.path = path


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Pose(_Model):
    """Platform pose held (force modes) or neutral (exercises): heave and tilt."""

    z_m: Annotated[float, Field(gt=0.0, le=2.0, allow_inf_nan=False)]
    roll_deg: Angle = 0.0
    pitch_deg: Angle = 0.0


class Directions(_Model):
    """Range per anatomical direction (deg from the neutral pose, ≥ 0)."""

    dorsiflexion: RomDeg | None = None
    plantarflexion: RomDeg | None = None
    inversion: RomDeg | None = None
    eversion: RomDeg | None = None


AXIS_DIRECTIONS = {"dorsi_plantar": ("dorsiflexion", "plantarflexion"),
                   "inversion_eversion": ("inversion", "eversion"),
                   "circuit": ("dorsiflexion", "plantarflexion", "inversion", "eversion")}


def _require_directions(block: Directions, block_name: str, items: Sequence[str]) -> None:
    for item in items:
        for d in AXIS_DIRECTIONS[item]:
            value = getattr(block, d)
            if value is None or value <= 0.0:
                raise FieldProblem(f"{block_name}.{d}", f"must be set and > 0 deg: the movement "
                                   f"{item!r} uses it (got {value!r})")


class _Base(_Model):
    schema_version: Literal[1]
    name: Annotated[str, Field(min_length=1, max_length=120)]
    description: str = ""
    limits: ProtocolLimits | None = None
    _source: PurePath | None = PrivateAttr(default=None)

    @property
    def loaded_from(self) -> PurePath | None:
        """The file this protocol was loaded from (None when built in memory)."""
        return self._source

    @model_validator(mode="after")
    def _limits_ordered(self) -> _Base:
        lim = self.limits
        if lim is not None:
            for axis in ("roll", "pitch"):
                lo, hi = getattr(lim, f"{axis}_min_deg"), getattr(lim, f"{axis}_max_deg")
                if lo is not None and hi is not None and not lo < hi:
                    raise FieldProblem(f"limits.{axis}_min_deg", f"must be below {axis}_max_deg "
                                       f"(got {lo} and {hi})")
        return self


class _AnkleCentred(_Model):
    """Shared fields of the ankle exercises: about which centre the foot turns.

    ``centre``: ``ankle`` turns the foot about the patient's ankle centre (the heave follows
    the angles; the patient's ankle setup is required), ``platform`` about the platform's centre
    (heave held); ``auto`` (the default) = about the ankle when the patient's ankle setup is
    known, else the platform. With a setup, pre-flight refuses an exercise that would move the ankle centre
    horizontally by more than ``ankle_displacement_limit_mm`` (default
    ``rt.model.ankle.DEFAULT_COMFORT_LIMIT_M``, cited there).
    """

    centre: Literal["auto", "ankle", "platform"] = "auto"
    ankle_displacement_limit_mm: Annotated[float, Field(gt=0.0, le=100.0,
                                                        allow_inf_nan=False)] | None = None


class _Smooth(_Model):
    """Shared motion-profile fields of the exercises that move between angles."""

    profile: Literal["jerk_limited", "cosine"] = "jerk_limited"
    max_acceleration_deg_s2: AccelDeg = 40.0
    max_jerk_deg_s3: JerkDeg = 400.0


# ------------------------------------------------------------------------------ kinds
class SineFz(_Base):
    """Sinusoidal force in Z: ``mean_n + amplitude_n sin(2π f t)`` for ``cycles`` full cycles.

    The whole signal is multiplied by raised-cosine ramps (``ramp_in_s`` before, ``ramp_out_s``
    after the full-amplitude cycles), so the force starts and ends at 0 N with zero slope.
    """

    kind: Literal["sine_fz"]
    pose: Pose
    mean_n: Annotated[float, Field(gt=0.0, le=5000.0, allow_inf_nan=False)]
    amplitude_n: Annotated[float, Field(ge=0.0, le=5000.0, allow_inf_nan=False)]
    frequency_hz: Annotated[float, Field(gt=0.0, le=20.0, allow_inf_nan=False)]
    cycles: Annotated[int, Field(ge=1, le=100_000)]
    ramp_in_s: Annotated[float, Field(ge=0.1, le=60.0, allow_inf_nan=False)] = 2.0
    ramp_out_s: Annotated[float, Field(ge=0.1, le=60.0, allow_inf_nan=False)] = 2.0

    @model_validator(mode="after")
    def _pushes(self) -> SineFz:
        if self.amplitude_n > self.mean_n:
            raise FieldProblem("amplitude_n", f"{self.amplitude_n} N exceeds mean_n "
                               f"{self.mean_n} N: the reference would go below 0 N, pulling "
                               "on a contact that can only push")
        return self


class StanceAuto(_Model):
    """The ``occurrence``-th run of samples with Fz above ``threshold_n`` (0 = the first)."""

    select: Literal["auto"]
    threshold_n: Annotated[float, Field(gt=0.0, le=2000.0, allow_inf_nan=False)] = 20.0
    occurrence: Annotated[int, Field(ge=0, le=100)] = 0


class StanceExplicit(_Model):
    """The samples between ``start_s`` and ``end_s`` (s from the record's first sample)."""

    select: Literal["explicit"]
    start_s: Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
    end_s: Annotated[float, Field(gt=0.0, allow_inf_nan=False)]

    @model_validator(mode="after")
    def _ordered(self) -> StanceExplicit:
        if not self.end_s > self.start_s:
            raise FieldProblem("end_s", f"must be after start_s (got {self.start_s} s .. "
                               f"{self.end_s} s)")
        return self


class GaitReplay(_Base):
    """Vertical ground-reaction force of one stance, replayed in Z (``protocols.gait``).

    The force is ``percent_body_weight/100 × patient_weight / source body mass`` times the
    record (the record is the subject's force; the patient's weight comes at run time). The
    source body mass is the C3D file's PROCESSING:Bodymass when it has one, else
    ``source_body_weight_kg`` (required then; both given and different is refused). The stance
    is played ``time_scale`` times slower than recorded (1.0 = real speed), ``repetitions``
    times with ``rest_between_s`` between stances; an automatically selected stance starts
    ``ramp_s`` (played time) plus ``gait.LEAD_MARGIN_S`` before contact and ends as long after
    toe off, so its ``ramp_s`` tapers act on the unloaded plate, never on the heel strike.
    ``include_shear`` carries the record's fx, fy in the output (not actuated).
    """

    kind: Literal["gait_replay"]
    pose: Pose
    source: Annotated[str, Field(min_length=1)]
    plate_index: Annotated[int, Field(ge=0, le=31)] | None = None
    stance: Annotated[StanceAuto | StanceExplicit, Field(discriminator="select")] = \
        StanceAuto(select="auto")
    source_body_weight_kg: Annotated[float, Field(gt=0.0, le=300.0, allow_inf_nan=False)] | \
        None = None
    percent_body_weight: Annotated[float, Field(gt=0.0, le=150.0, allow_inf_nan=False)]
    time_scale: Annotated[float, Field(ge=0.5, le=5.0, allow_inf_nan=False)] = 1.0
    repetitions: Annotated[int, Field(ge=1, le=1000)] = 1
    rest_between_s: Annotated[float, Field(ge=0.0, le=600.0, allow_inf_nan=False)] = 1.0
    ramp_s: Annotated[float, Field(gt=0.0, le=0.5, allow_inf_nan=False)] = 0.02
    include_shear: bool = False
    interpolation: Literal["cubic", "linear"] = "cubic"

    @field_validator("source")
    @classmethod
    def _known_format(cls, v: str) -> str:
        if PurePath(v).suffix.lower() not in (".c3d", ".csv"):
            raise ValueError(f"must name a .c3d or .csv file (got {v!r})")
        return v

    @property
    def is_c3d(self) -> bool:
        return PurePath(self.source).suffix.lower() == ".c3d"

    @model_validator(mode="after")
    def _plate_fits_source(self) -> GaitReplay:
        if self.is_c3d and self.plate_index is None:
            raise FieldProblem("plate_index", "is required for a C3D source (0-based index of "
                               "the force platform, in FORCE_PLATFORM order)")
        if not self.is_c3d and self.plate_index is not None:
            raise FieldProblem("plate_index", "applies to C3D sources only; a CSV holds one "
                               "force record")
        return self


class AnkleRom(_Base, _Smooth, _AnkleCentred):
    """Passive range of motion (module docstring for the direction conventions).

    Each item of ``sequence`` is repeated ``repetitions`` times: neutral → first end (hold
    ``hold_s``) → opposite end (hold) → neutral; a ``circuit`` goes from neutral to the plantar
    end, runs an ellipse through the four ends ``repetitions`` times, and returns. The speed
    along the path never exceeds ``speed_deg_s``.
    """

    kind: Literal["ankle_rom"]
    pose: Pose
    sequence: Annotated[list[Literal["dorsi_plantar", "inversion_eversion", "circuit"]],
                        Field(min_length=1, max_length=20)]
    amplitude_deg: Directions
    speed_deg_s: Speed
    repetitions: Annotated[int, Field(ge=1, le=100)] = 1
    hold_s: Annotated[float, Field(ge=0.0, le=60.0, allow_inf_nan=False)] = 1.0

    @model_validator(mode="after")
    def _amplitudes_set(self) -> AnkleRom:
        _require_directions(self.amplitude_deg, "amplitude_deg", self.sequence)
        return self


#: Largest ankle-torque target (N·m) a hold may set. Adults' maximal voluntary isometric
#: torques are about 100-150 N·m in plantarflexion, 30-45 N·m in dorsiflexion and 20-40 N·m in
#: inversion/eversion (e.g. Winter 2009; Anderson, Madigan, Nussbaum, "Maximum voluntary joint
#: torque as a function of joint angle and angular velocity", Clin. Biomech. 22:1022-1031,
#: 2007 (ankle)); rehabilitation holds stay well below. Beyond 100 N·m is a typing error.
MAX_TORQUE_TARGET_NM = 100.0
AnkleDirection = Literal["plantarflexion", "dorsiflexion", "inversion", "eversion"]


class TorqueTarget(_Model):
    """An ankle-torque target: the patient's torque about the ankle centre
    (``rt.model.ankle.ankle_torques``) in one clinical direction, N·m (> 0)."""

    direction: AnkleDirection
    target_nm: Annotated[float, Field(gt=0.0, le=MAX_TORQUE_TARGET_NM, allow_inf_nan=False)]


class Hold(_Model):
    """One isometric hold: the platform angles, the hold and the rest after it; optionally an
    ankle-torque target the RT process regulates during the hold (``torque``)."""

    roll_deg: Angle
    pitch_deg: Angle
    hold_s: Annotated[float, Field(gt=0.0, le=120.0, allow_inf_nan=False)]
    rest_s: Annotated[float, Field(ge=0.0, le=600.0, allow_inf_nan=False)] = 0.0
    torque: TorqueTarget | None = None


class TorqueControl(_Model):
    """How the RT process regulates a hold's ankle torque (``protocols.torque_hold``).

    The platform turns the foot about the hold's axis through an admittance driven by the
    torque error, I θ̈ + B θ̇ = τ_measured - τ_target (θ the angle from the hold's angle, τ
    about the ankle centre), so it pushes with the target torque and a patient holding still
    against it contracts isometrically at the target; a patient who yields is turned at most
    ``max_excursion_deg`` from the hold's angle, never faster than ``max_speed_deg_s``. The
    target ramps in and out over ``ramp_s`` (raised cosine); the foot then returns to the
    hold's angle within ``return_s`` (braked to rest, then a raised cosine).
    """

    max_excursion_deg: Annotated[float, Field(gt=0.0, le=20.0, allow_inf_nan=False)] = 10.0
    virtual_inertia_kg_m2: Annotated[float, Field(gt=0.0, le=50.0, allow_inf_nan=False)] = 0.2
    damping_n_m_s_rad: Annotated[float, Field(gt=0.0, le=2000.0, allow_inf_nan=False)] = 20.0
    ramp_s: Annotated[float, Field(ge=0.2, le=10.0, allow_inf_nan=False)] = 1.0
    return_s: Annotated[float, Field(ge=0.2, le=20.0, allow_inf_nan=False)] = 2.0
    max_speed_deg_s: Speed = 10.0
    max_acceleration_deg_s2: AccelDeg = 60.0

    @property
    def brake_s(self) -> float:
        """Longest time (s) the return spends braking the admittance's rate to rest."""
        return self.max_speed_deg_s / self.max_acceleration_deg_s2

    @model_validator(mode="after")
    def _return_within_limits(self) -> TorqueControl:
        # The return brakes to rest (at most brake_s), then a raised cosine from the largest
        # excursion over the rest of return_s, T: peak rate π e/(2T), acceleration π² e/(2T²).
        e, t = self.max_excursion_deg, self.return_s - self.brake_s
        rate = math.pi * e / (2.0 * t) if t > 0.0 else math.inf
        acc = math.pi ** 2 * e / (2.0 * t * t) if t > 0.0 else math.inf
        if rate > self.max_speed_deg_s or acc > self.max_acceleration_deg_s2:
            raise FieldProblem("return_s", f"{self.return_s:g} s is too short: returning from "
                               f"max_excursion_deg {e:g} would reach {rate:.1f} deg/s and "
                               f"{acc:.1f} deg/s² (limits {self.max_speed_deg_s:g} deg/s, "
                               f"{self.max_acceleration_deg_s2:g} deg/s²)")
        return self


class IsometricHold(_Base, _Smooth, _AnkleCentred):
    """Isometric holds at set platform angles (degrees in the platform frame, not anatomical).

    The platform moves from the neutral pose to each hold's angles at ``transition_speed_deg_s``,
    holds them ``hold_s`` (the patient pushes; ``target_force_n`` is shown as the goal), stays
    there ``rest_s`` with no target, and finally returns to neutral. Position mode throughout.

    A hold with ``torque`` (an ankle-torque target, N·m about DF/PF or INV/EV; needs the
    patient's ankle setup) is regulated instead (:class:`TorqueControl`): at the hold's angles
    the target ramps in over ``torque_control.ramp_s``, is held ``hold_s``, ramps out, the foot
    returns to the hold's angles over ``torque_control.return_s``, then ``rest_s``.
    """

    kind: Literal["isometric_hold"]
    pose: Pose
    holds: Annotated[list[Hold], Field(min_length=1, max_length=100)]
    target_force_n: Annotated[float, Field(gt=0.0, le=2000.0, allow_inf_nan=False)] | None = None
    transition_speed_deg_s: Speed = 10.0
    torque_control: TorqueControl = TorqueControl()

    @property
    def has_torque_targets(self) -> bool:
        """True when a hold sets an ankle-torque target (the RT process regulates it)."""
        return any(h.torque is not None for h in self.holds)


class AxisAdmittance(_Model):
    """Virtual dynamics of one axis: I θ̈ + B (θ̇ - g θ̇_guide) + g K (θ - θ_guide) = τ_patient
    (g = assistance_gain; θ from the neutral pose)."""

    virtual_mass_kg_m2: Annotated[float, Field(gt=0.0, le=50.0, allow_inf_nan=False)]
    damping_n_m_s_rad: Annotated[float, Field(ge=0.0, le=5000.0, allow_inf_nan=False)]
    stiffness_n_m_rad: Annotated[float, Field(ge=0.0, le=20000.0, allow_inf_nan=False)]


class Admittance(_Model):
    """Per-axis admittance; the axes the exercise uses must be given."""

    pitch: AxisAdmittance | None = None
    roll: AxisAdmittance | None = None


class ActiveAssist(_Base, _AnkleCentred):
    """Active-assisted exercise: the platform follows the patient's torque through an admittance.

    A guide motion oscillates between the ROM ends of each axis with period ``guide_period_s``
    (roll a quarter period behind pitch when both are used), faded in and out over ``ramp_s``.
    ``assistance_gain`` (0..1) scales the spring-damper pulling towards the guide's angle and
    rate: 1 = fully guided, 0 = the patient moves the platform alone against the virtual mass
    and damping. The reference
    never leaves ``rom_deg``, never moves faster than ``max_speed_deg_s`` and never accelerates
    beyond ``max_acceleration_deg_s2`` (which is also how it brakes before a ROM end).
    """

    kind: Literal["active_assist"]
    pose: Pose
    axes: Annotated[list[Literal["dorsi_plantar", "inversion_eversion"]],
                    Field(min_length=1, max_length=2)]
    rom_deg: Directions
    admittance: Admittance
    assistance_gain: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]
    guide_period_s: Annotated[float, Field(ge=1.0, le=120.0, allow_inf_nan=False)] = 8.0
    duration_s: Annotated[float, Field(gt=0.0, le=3600.0, allow_inf_nan=False)]
    ramp_s: Annotated[float, Field(ge=0.0, le=60.0, allow_inf_nan=False)] = 2.0
    max_speed_deg_s: Speed = 20.0
    max_acceleration_deg_s2: AccelDeg = 100.0

    @model_validator(mode="after")
    def _consistent(self) -> ActiveAssist:
        if len(set(self.axes)) != len(self.axes):
            raise FieldProblem("axes", f"lists an axis twice ({self.axes})")
        _require_directions(self.rom_deg, "rom_deg", self.axes)
        for item in self.axes:
            axis = "pitch" if item == "dorsi_plantar" else "roll"
            if getattr(self.admittance, axis) is None:
                raise FieldProblem(f"admittance.{axis}", f"is required: the exercise moves "
                                   f"{item!r}")
        if 2.0 * self.ramp_s > self.duration_s:
            raise FieldProblem("ramp_s", f"ramps in and out ({2.0 * self.ramp_s:g} s) are longer "
                               f"than the protocol (duration_s {self.duration_s:g} s)")
        for item in self.axes:
            a, b = AXIS_DIRECTIONS[item]
            span = getattr(self.rom_deg, a) + getattr(self.rom_deg, b)
            guide_speed = math.pi * span / self.guide_period_s
            if guide_speed > self.max_speed_deg_s:
                raise FieldProblem("guide_period_s", f"{self.guide_period_s:g} s is too short: "
                                   f"the guide would cross the {item} range ({span:g} deg) at "
                                   f"{guide_speed:.1f} deg/s, above max_speed_deg_s "
                                   f"{self.max_speed_deg_s:g}")
        return self


class PositionPlayback(_Base):
    """Slider positions from a CSV (``rt.references.playback`` format: ``t,q0,q1,q2`` in s, m,
    or ``q0,q1,q2`` with ``sample_rate_hz``), resampled to the loop rate."""

    kind: Literal["position_playback"]
    file: Annotated[str, Field(min_length=1)]
    sample_rate_hz: Annotated[float, Field(gt=0.0, le=100_000.0, allow_inf_nan=False)] | None = \
        None
    interpolation: Literal["cubic", "linear"] = "cubic"
    uniform: bool = True

    @field_validator("file")
    @classmethod
    def _csv(cls, v: str) -> str:
        if PurePath(v).suffix.lower() != ".csv":
            raise ValueError(f"must name a .csv file (got {v!r})")
        return v


Protocol = Annotated[SineFz | GaitReplay | AnkleRom | IsometricHold | ActiveAssist | PositionPlayback, Field(discriminator="kind")]
ProtocolModel = SineFz | GaitReplay | AnkleRom | IsometricHold | ActiveAssist | PositionPlayback
KINDS: dict[str, type[_Base]] = {
    "sine_fz": SineFz, "gait_replay": GaitReplay, "ankle_rom": AnkleRom,
    "isometric_hold": IsometricHold, "active_assist": ActiveAssist,
    "position_playback": PositionPlayback,
}
#: Validates any kind; ``PROTOCOL_ADAPTER.json_schema()`` describes the files (e.g. for an editor).
PROTOCOL_ADAPTER: TypeAdapter[Any] = TypeAdapter(Protocol)


# ------------------------------------------------------------------------------ validation
Locator = Callable[[Sequence[str | int]], int | None]


def _where(source: str, locate: Locator | None, path: Sequence[str | int]) -> str:
    line = locate(path) if locate is not None else None
    return f"{source}, line {line}" if line is not None else source


def _dotted(path: Sequence[str | int]) -> str:
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


def _fields_of(cls: Any, path: Sequence[str | int]) -> list[str] | None:
    """The field names allowed at ``path`` below model ``cls`` (best effort, for messages)."""
    tp: Any = cls
    for p in path:
        tp = _unwrap(tp)
        if isinstance(p, int):
            args = typing.get_args(tp)
            if not args:
                return None
            tp = args[0]
            continue
        if not (isinstance(tp, type) and issubclass(tp, BaseModel)) or p not in tp.model_fields:
            return None
        tp = tp.model_fields[p].annotation
    tp = _unwrap(tp)
    if isinstance(tp, type) and issubclass(tp, BaseModel):
        return list(tp.model_fields)
    return None


def _unwrap(tp: Any) -> Any:
    """Strip Annotated and Optional (X | None) from a type."""
    while True:
        origin = typing.get_origin(tp)
        if origin is Annotated:
            tp = typing.get_args(tp)[0]
        elif origin in (Union, types.UnionType):
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            if len(args) != 1:
                return tp
            tp = args[0]
        else:
            return tp


def _reason(err: Any, cls: type[_Base], loc: Sequence[str | int]) -> str:
    kind = err["type"]
    if kind == "extra_forbidden":
        allowed = _fields_of(cls, loc[:-1])
        hint = f" (allowed here: {', '.join(allowed)})" if allowed else ""
        return f"unknown key{hint}"
    if kind == "missing":
        return "required field is missing"
    msg = str(err["msg"])
    msg = msg.removeprefix("Value error, ")
    if kind not in ("value_error",) and "input" in err and not isinstance(err["input"],
                                                                          (dict, list)):
        msg += f" (got {err['input']!r})"
    return msg


def _migrate(data: dict[str, Any], source: str, locate: Locator | None) -> dict[str, Any]:
    if "schema_version" not in data:
        raise ProtocolValidationError(f"{source}: schema_version: required field is missing "
                                      f"(this talus reads schema_version {SCHEMA_VERSION})")
    version = data["schema_version"]
    where = _where(source, locate, ["schema_version"])
    if isinstance(version, bool) or not isinstance(version, int):
        raise ProtocolValidationError(f"{where}: schema_version: must be an integer "
                                      f"(got {version!r})")
    if version > SCHEMA_VERSION:
        raise ProtocolValidationError(f"{where}: schema_version: unsupported version {version}: "
                                      f"this talus reads up to {SCHEMA_VERSION}; update talus")
    while version < SCHEMA_VERSION:
        if version not in MIGRATIONS:
            raise ProtocolValidationError(f"{where}: schema_version: unsupported version "
                                          f"{version}: no migration to {SCHEMA_VERSION}")
        data = MIGRATIONS[version](dict(data))
        version += 1
        data["schema_version"] = version
    return data


def validate_protocol_data(data: object, source: str = "<memory>",
                           locate: Locator | None = None) -> ProtocolModel:
    """Check a parsed mapping and build its protocol model.

    Args:
        data: the mapping read from a protocol file.
        source: the file name used in messages.
        locate: maps a field path to its 1-based line in the file (None: no line numbers).

    Raises:
        ProtocolValidationError: ``"<file>, line <n>: <field.path>: <reason>"``, one line per
            problem found.
    """
    if not isinstance(data, dict):
        raise ProtocolValidationError(f"{source}: the file must hold a mapping of fields "
                                      f"(got {type(data).__name__})")
    bad_keys = [k for k in data if not isinstance(k, str)]
    if bad_keys:
        raise ProtocolValidationError(f"{source}: keys must be text (got {bad_keys[0]!r})")
    data = _migrate(data, source, locate)
    kind = data.get("kind")
    if kind is None:
        raise ProtocolValidationError(f"{source}: kind: required field is missing (one of "
                                      f"{', '.join(KINDS)})")
    if not isinstance(kind, str) or kind not in KINDS:
        raise ProtocolValidationError(f"{_where(source, locate, ['kind'])}: kind: unknown kind "
                                      f"{kind!r} (known: {', '.join(KINDS)})")
    cls = KINDS[kind]
    try:
        model = cls.model_validate(data)
    except ValidationError as exc:
        problems = []
        for err in exc.errors():
            loc: list[str | int] = list(err["loc"])
            # Drop the tag pydantic inserts for a discriminated member (e.g. stance.auto).
            loc = [p for i, p in enumerate(loc)
                   if not (i > 0 and loc[i - 1] == "stance" and p in ("auto", "explicit"))]
            ctx_err = err.get("ctx", {}).get("error")
            if isinstance(ctx_err, FieldProblem):
                loc = [*loc, *ctx_err.path.split(".")]
                reason = str(ctx_err)
            else:
                reason = _reason(err, cls, loc)
            problems.append(f"{_where(source, locate, loc)}: {_dotted(loc)}: {reason}")
        raise ProtocolValidationError("\n".join(problems)) from None
    return typing.cast(ProtocolModel, model)
