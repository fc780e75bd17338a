"""The patient's ankle on the platform: where its joint centre is, how the platform must move to
turn the foot about it, how far the centre still moves, and the sensor's wrench moved to it.

Frames (``rt/data/robot_nominal.yaml``): P is the platform frame (origin at the centre of the
three spherical joints, z up), S the ATI sensor frame (axes parallel to P, origin at
``sensor.offset_m`` in P). The foot rests on the sensor's top face, the sole plane at
``sole_above_sensor_m`` above S's origin, toes towards +x (``FOOT_MOUNTING`` in
``protocols.base``). The ankle joint centre — the midpoint of the malleoli, taken as the
talocrural joint's centre — is at ``a_P = s + (offset_x_m, offset_y_m, sole_above_sensor_m +
height_above_sole_m)`` in P.

What the mechanism allows (why the residual displacement is not zero). A 3-PRS platform has
three degrees of freedom: heave z, roll γ and pitch β; its yaw α and horizontal position (x, y)
are parasitic, fixed by (γ, β) alone (``rt.model.kinematics``). The foot is strapped to the
platform, so the ankle angle *is* the platform's rotation from the neutral pose: the rotation is
prescribed and only z is free. The ankle centre A = (x, y, z) + R a_P therefore moves
horizontally by ``(x, y) + (R a_P - a_P)_xy`` whatever z is — about h·sin θ for a tilt θ at
height h above P's origin, plus the parasitic (x, y) — and z only cancels the vertical part:
z = A0_z - (R a_P)_z. The horizontal residual is what pre-flight compares with the comfort
limit (:data:`DEFAULT_COMFORT_LIMIT_M`). Rotation about the platform's centre keeps z
constant and moves A vertically as well.

Ankle angles here are the foot's rotation from the neutral pose with the shank assumed still:
plantarflexion = pitch - pitch₀, inversion = ±(roll - roll₀) (+ for a right foot), the
parasitic yaw reported as the foot's internal/external rotation (abduction/adduction).

Ankle torques (:func:`ankle_torques`) are the moments the foot applies to the platform about
the ankle centre (the sensor reads the foot's push on the platform), signed as the rotation the
effort would give the foot: a plantarflexion effort presses the toes' end down (+), an inversion
effort presses the lateral border down (+): the torques of the plantarflexors and invertors.
The foot's own weight is not removed: the sensor is tared with the foot resting, before the
exercise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from rt.errors import InputError, KinematicsError, validation_summary
from rt.model.kinematics import Kinematics

#: Plausible ankle-centre heights above the sole (m). The lateral malleolus of adults stands
#: about 0.039 × body height above the floor (Winter, Biomechanics and Motor Control of Human
#: Movement, 4th ed. 2009, fig. 4.1: 55-80 mm for 1.4-2.0 m), children's lower: below 25 mm or
#: above 150 mm is a typing error (cm for m) or a marker on the wrong landmark.
HEIGHT_RANGE_M = (0.025, 0.150)
#: Largest horizontal displacement (m) of the ankle centre pre-flight accepts by default.
#: No standard states a tolerable ankle-centre misalignment. The default is the upper end of
#: the soft-tissue motion of the shank relative to its bones, which marker studies put at up
#: to 1-3 cm (Leardini, Chiari, Della Croce, Cappozzo, "Human movement analysis using
#: stereophotogrammetry. Part 3: soft tissue artifact assessment and compensation", Gait &
#: Posture 21:212-225, 2005): within it the displacement is taken up by the soft tissue under
#: the straps; beyond it the shank is dragged and the knee or hip must move, the constraint
#: forces misalignment creates (Schiele & van der Helm, "Kinematic design to improve ergonomics
#: in human machine interaction", IEEE TNSRE 14:456-469, 2006). With the ankle 150 mm above
#: the platform's joint plane, 30 mm allows about ±11° of tilt. A clinician's choice per
#: exercise (``ankle_displacement_limit_mm``), not a safety limit of the robot.
DEFAULT_COMFORT_LIMIT_M = 0.030
#: Foot placement offsets beyond this fraction of the platform radius leave the heel or the
#: toes off the sensor plate.
_FOOTPRINT_FRACTION = 1.0


class AnkleSetup(BaseModel):
    """Where the patient's ankle joint centre is on the platform (per patient and session).

    Lengths in m, in the platform frame P: ``offset_x_m`` along the foot (toes +x),
    ``offset_y_m`` across it, both the ankle centre's horizontal position from P's z axis;
    ``height_above_sole_m`` the centre's height above the sole; ``side`` the foot on the
    platform; ``sole_above_sensor_m`` the thickness of the foot plate between the sensor's
    origin and the sole; ``source`` how it was obtained (entered by hand, or measured by the
    camera from malleolus markers).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    side: Literal["left", "right"]
    height_above_sole_m: Annotated[float, Field(allow_inf_nan=False)]
    offset_x_m: Annotated[float, Field(allow_inf_nan=False)] = 0.0
    offset_y_m: Annotated[float, Field(allow_inf_nan=False)] = 0.0
    sole_above_sensor_m: Annotated[float, Field(ge=0.0, le=0.10, allow_inf_nan=False)] = 0.0
    source: Literal["entered", "camera"] = "entered"

    @field_validator("height_above_sole_m")
    @classmethod
    def _plausible_height(cls, v: float) -> float:
        lo, hi = HEIGHT_RANGE_M
        if v <= 0.0:
            raise ValueError(f"{v:g} m puts the ankle centre at or below the sole: give the "
                             "malleoli's height above the sole (positive, m)")
        if not lo <= v <= hi:
            raise ValueError(f"{v:g} m is not a plausible ankle-centre height above the sole "
                             f"({lo * 1e3:.0f}-{hi * 1e3:.0f} mm): check the unit (m) and the "
                             "landmark (the malleoli)")
        return v


def parse_ankle_setup(data: Any, platform_radius_m: float, side: str | None = None
                      ) -> AnkleSetup:
    """Validate an ankle setup (a mapping or an :class:`AnkleSetup`) against the platform.

    Raises ``InputError`` naming the field and the reason: missing fields, a height at or below
    the sole or implausible, a centre outside the platform's footprint (radius
    ``platform_radius_m``), a side that disagrees with ``side`` (the session's foot).
    """
    if data is None:
        raise InputError("ankle setup: missing: the exercise turns the foot about the ankle "
                         "centre; enter its height above the sole and its offsets, or measure "
                         "them with the camera")
    try:
        setup = data if isinstance(data, AnkleSetup) else AnkleSetup.model_validate(data)
    except ValidationError as exc:
        raise InputError(f"ankle setup: {validation_summary(exc)}") from None
    reach = _FOOTPRINT_FRACTION * platform_radius_m
    off = math.hypot(setup.offset_x_m, setup.offset_y_m)
    if off > reach:
        raise InputError(f"ankle setup: offset_x_m, offset_y_m: the ankle centre is "
                         f"{off * 1e3:.0f} mm from the platform's centre, outside the platform "
                         f"(radius {reach * 1e3:.0f} mm): check the foot placement and the unit "
                         "(m)")
    if side is not None and side != setup.side:
        raise InputError(f"ankle setup: side: the setup is for the {setup.side} foot but the "
                         f"session is for the {side} foot")
    return setup


#: Plausible distance between the malleoli's markers (m): the bimalleolar width of adults is
#: about 60-80 mm (children's less); outside this the markers are not on the two malleoli.
MALLEOLI_WIDTH_RANGE_M = (0.040, 0.110)


def setup_from_malleoli(lateral_P: tuple[float, float, float] | list[float],
                        medial_P: tuple[float, float, float] | list[float], side: str,
                        sensor_offset_m: tuple[float, float, float] | list[float],
                        sole_above_sensor_m: float = 0.0) -> AnkleSetup:
    """The ankle setup from the two malleoli's marker centres in the platform frame P (m), as
    the camera measures them (``source="camera"``): the centre is their midpoint (the
    talocrural axis passes close to both malleoli's tips), its height taken above the sole at
    ``sensor_offset_m[2] + sole_above_sensor_m`` in P.

    Raises ``InputError`` when the markers are implausibly far apart or close together, or when
    the medial marker is on the lateral side for that foot (medial is +y for a right foot:
    ``FOOT_MOUNTING``), or the resulting height is implausible (:class:`AnkleSetup`).
    """
    lat = [float(v) for v in lateral_P]
    med = [float(v) for v in medial_P]
    width = math.dist(lat, med)
    lo, hi = MALLEOLI_WIDTH_RANGE_M
    if not lo <= width <= hi:
        raise InputError(f"ankle setup from the camera: the malleoli markers are "
                         f"{width * 1e3:.0f} mm apart, outside {lo * 1e3:.0f}-{hi * 1e3:.0f} mm: "
                         "check that one marker is on each malleolus")
    medial_sign = 1.0 if side == "right" else -1.0
    if (med[1] - lat[1]) * medial_sign <= 0.0:
        raise InputError(f"ankle setup from the camera: the medial marker is on the lateral "
                         f"side of a {side} foot (toes towards +x): markers swapped, or the "
                         "other foot")
    centre = [(a + b) / 2.0 for a, b in zip(lat, med, strict=True)]
    sole_z = float(sensor_offset_m[2]) + sole_above_sensor_m
    data = {"side": side, "height_above_sole_m": centre[2] - sole_z,
            "offset_x_m": centre[0] - float(sensor_offset_m[0]),
            "offset_y_m": centre[1] - float(sensor_offset_m[1]),
            "sole_above_sensor_m": sole_above_sensor_m, "source": "camera"}
    try:
        return AnkleSetup.model_validate(data)
    except ValidationError as exc:
        raise InputError(f"ankle setup from the camera: {validation_summary(exc)}") from None


def platform_angles(plantar_rad: float, inversion_rad: float, side: str) -> tuple[float, float]:
    """(roll, pitch) offsets (rad) of the foot for a plantarflexion and an inversion angle (rad;
    negative values are dorsiflexion and eversion) on the ``side`` foot."""
    sign = 1.0 if side == "right" else -1.0
    return sign * inversion_rad, plantar_rad


def ankle_angles(d_roll_rad: float, d_pitch_rad: float, side: str) -> tuple[float, float]:
    """(plantarflexion, inversion) (rad) of a platform rotation (roll, pitch) from neutral."""
    sign = 1.0 if side == "right" else -1.0
    return d_pitch_rad, sign * d_roll_rad


@dataclass(frozen=True, slots=True)
class AnklePose:
    """A platform pose for an ankle angle and where the ankle centre then is.

    ``z_m, roll_rad, pitch_rad`` are the platform command; ``yaw_rad`` its parasitic yaw (the
    foot's abduction); ``displacement_m`` the ankle centre's displacement from where it was at
    the neutral pose (base frame, m).
    """

    z_m: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    displacement_m: tuple[float, float, float]

    @property
    def horizontal_m(self) -> float:
        """Horizontal displacement of the ankle centre (m)."""
        return math.hypot(self.displacement_m[0], self.displacement_m[1])

    @property
    def residual_m(self) -> float:
        """Whole displacement of the ankle centre (m)."""
        dx, dy, dz = self.displacement_m
        return math.sqrt(dx * dx + dy * dy + dz * dz)


class AnkleKinematics:
    """Platform poses that turn the foot about its ankle centre (module docstring).

    ``neutral`` is the platform pose (z m, roll rad, pitch rad) where the foot is in its neutral
    position; the ankle centre's position there is the one to keep.
    """

    def __init__(self, kinematics: Kinematics, setup: AnkleSetup,
                 sensor_offset_m: tuple[float, float, float] | list[float],
                 neutral: tuple[float, float, float]) -> None:
        self.kinematics = kinematics
        self.setup = setup
        s = sensor_offset_m
        self.centre_P = (s[0] + setup.offset_x_m, s[1] + setup.offset_y_m,
                         s[2] + setup.sole_above_sensor_m + setup.height_above_sole_m)
        self.neutral = (float(neutral[0]), float(neutral[1]), float(neutral[2]))
        self.start = self.centre(*self.neutral)

    def centre(self, z: float, roll: float, pitch: float) -> tuple[float, float, float]:
        """The ankle centre in the base frame (m) at platform pose (z, roll, pitch)."""
        c = self.kinematics.ik(z, roll, pitch, check=False)
        r, (ax, ay, az) = c.rotation, self.centre_P
        return (c.x + r[0] * ax + r[1] * ay + r[2] * az,
                c.y + r[3] * ax + r[4] * ay + r[5] * az,
                z + r[6] * ax + r[7] * ay + r[8] * az)

    def z_for(self, roll: float, pitch: float) -> float:
        """The heave (m) that keeps the ankle centre at its starting height at platform angles
        (roll, pitch) (rad): z = A0_z - (R a_P)_z, R's last row (-sβ, cβ sγ, cβ cγ) being
        free of the parasitic yaw (no IK needed: cheap enough for every cycle)."""
        ax, ay, az = self.centre_P
        cb = math.cos(pitch)
        return self.start[2] - (-math.sin(pitch) * ax + cb * math.sin(roll) * ay
                                + cb * math.cos(roll) * az)

    def pose_for_platform_angles(self, roll: float, pitch: float, compensate: bool = True
                                 ) -> AnklePose:
        """The pose for absolute platform angles (rad): z chosen so the ankle centre keeps its
        height (``compensate``), or the neutral z (rotation about the platform's centre)."""
        c = self.kinematics.ik(self.neutral[0], roll, pitch, check=False)
        r, (ax, ay, az) = c.rotation, self.centre_P
        rx = r[0] * ax + r[1] * ay + r[2] * az
        ry = r[3] * ax + r[4] * ay + r[5] * az
        rz = r[6] * ax + r[7] * ay + r[8] * az
        a0 = self.start
        z = a0[2] - rz if compensate else self.neutral[0]
        return AnklePose(z, roll, pitch, c.yaw, (c.x + rx - a0[0], c.y + ry - a0[1],
                                                 z + rz - a0[2]))

    def pose(self, plantar_rad: float, inversion_rad: float, compensate: bool = True
             ) -> AnklePose:
        """The pose that sets the ankle to (plantarflexion, inversion) (rad) from neutral."""
        dr, dp = platform_angles(plantar_rad, inversion_rad, self.setup.side)
        return self.pose_for_platform_angles(self.neutral[1] + dr, self.neutral[2] + dp,
                                             compensate)

    def angles(self, roll: float, pitch: float) -> tuple[float, float]:
        """(plantarflexion, inversion) (rad) of the foot at platform angles (roll, pitch)."""
        return ankle_angles(roll - self.neutral[1], pitch - self.neutral[2], self.setup.side)


    def limit_along(self, plantar_rad: float, inversion_rad: float, limit_m: float,
                    compensate: bool = True) -> float:
        """The largest fraction s in [0, 1] of the ankle angle (plantar, inversion) whose
        horizontal displacement stays within ``limit_m`` (bisection to 1e-4; the displacement
        grows monotonically along a ray from neutral over the ankle's range)."""
        if self.pose(plantar_rad, inversion_rad, compensate).horizontal_m <= limit_m:
            return 1.0
        lo, hi = 0.0, 1.0
        while hi - lo > 1e-4:
            mid = 0.5 * (lo + hi)
            if self.pose(mid * plantar_rad, mid * inversion_rad, compensate).horizontal_m \
                    <= limit_m:
                lo = mid
            else:
                hi = mid
        return lo


def describe_angles(plantar_rad: float, inversion_rad: float) -> str:
    """Clinical words for an ankle angle: ``plantarflexion 12.0 deg, eversion 3.0 deg``."""
    parts = []
    for value, pos, neg in ((plantar_rad, "plantarflexion", "dorsiflexion"),
                            (inversion_rad, "inversion", "eversion")):
        deg = math.degrees(value)
        if abs(deg) >= 0.05:
            parts.append(f"{pos if deg > 0 else neg} {abs(deg):.1f} deg")
    return ", ".join(parts) or "neutral"


def transfer_wrench(wrench_s: tuple[float, ...] | list[float], r_SA_S: tuple[float, float, float]
                    ) -> tuple[float, float, float, float, float, float]:
    """A wrench (fx, fy, fz N, mx, my, mz N m) at the sensor origin, moved to the point A at
    ``r_SA_S`` from it (m, sensor frame): same force, m_A = m_S + (S - A) × f = m_S - r_SA × f.
    """
    fx, fy, fz, mx, my, mz = (float(w) for w in wrench_s[:6])
    rx, ry, rz = r_SA_S
    return (fx, fy, fz,
            mx - (ry * fz - rz * fy),
            my - (rz * fx - rx * fz),
            mz - (rx * fy - ry * fx))


def sensor_to_ankle_S(setup: AnkleSetup) -> tuple[float, float, float]:
    """The ankle centre from the sensor origin (m, sensor frame = P axes)."""
    return (setup.offset_x_m, setup.offset_y_m,
            setup.sole_above_sensor_m + setup.height_above_sole_m)


def ankle_torques(wrench_s: tuple[float, ...] | list[float], setup: AnkleSetup
                  ) -> tuple[float, float, float]:
    """The patient's ankle torques (N m) from the sensor's wrench (sensor frame): plantarflexion
    (+) / dorsiflexion (-), inversion (+) / eversion (-), abduction about the vertical axis.

    The wrench is the foot's push on the platform, moved to the ankle centre; plantarflexion is
    its moment about +y (toes down), inversion its moment about ±x (+ for a right foot).
    """
    _, _, _, mx, my, mz = transfer_wrench(wrench_s, sensor_to_ankle_S(setup))
    sign = 1.0 if setup.side == "right" else -1.0
    return my, sign * mx, mz


class AnkleMonitor:
    """The ankle's state in clinical terms from the loop's samples, for the ``/ankle/state``
    recording channel (non-real-time: the recorder's pump thread).

    Holds its own :class:`Kinematics` (forward kinematics keeps a warm start: sharing the
    loop's would race with it). ``period_s`` spaces the messages (default 10 ms: 100 Hz, well
    above an ankle exercise's bandwidth, a tenth of the 1 kHz channels' cost).
    """

    def __init__(self, kinematics: Kinematics, setup: AnkleSetup,
                 neutral: tuple[float, float, float], period_s: float = 0.01) -> None:
        own = Kinematics(kinematics.description)
        self.ankle = AnkleKinematics(own, setup, list(own.description.sensor.offset_m), neutral)
        self.period_s = period_s
        self._next_t = -math.inf
        #: The last message (:meth:`message`), for live views (the RT process's telemetry):
        #: replaced whole, so a reader on another thread sees one message or the next.
        self.last: dict[str, Any] | None = None

    def due(self, t: float) -> bool:
        """True when a message is due at loop time ``t`` (s)."""
        return t + 1e-9 >= self._next_t

    def message(self, t: float, q: Any, wrench_s: Any) -> dict[str, Any] | None:
        """The ``/ankle/state`` message at loop time ``t`` (s) (:meth:`state`), and the next
        one is due a period later; None when there is none."""
        msg = self.state(t, q, wrench_s)
        if msg is not None:
            self._next_t = t + self.period_s
            self.last = msg
        return msg

    def state(self, t: float, q: Any, wrench_s: Any) -> dict[str, Any] | None:
        """The ankle's state at loop time ``t`` (s) from slider positions ``q`` (m)
        and the sensor's wrench (N, N m; sensor frame); None when FK fails or the wrench has
        no finite sample yet (as ``/robot/wrench``: not a measurement, not written)."""
        ak = self.ankle
        if not all(math.isfinite(float(x)) for x in wrench_s[:6]):
            return None
        try:
            c = ak.kinematics.fk(q, check=False)
        except KinematicsError:
            return None
        plantar, inversion = ak.angles(c.roll, c.pitch)
        a = ak.centre(c.z, c.roll, c.pitch)
        d = [(a[i] - ak.start[i]) * 1e3 for i in range(3)]
        tp, ti, ta = ankle_torques(wrench_s, ak.setup)
        return {"t": t, "plantarflexion_deg": math.degrees(plantar),
                "inversion_deg": math.degrees(inversion),
                "abduction_deg": math.degrees(c.yaw),
                "plantarflexion_torque_nm": tp, "inversion_torque_nm": ti,
                "abduction_torque_nm": ta, "centre_displacement_mm": d,
                "platform_roll_deg": math.degrees(c.roll),
                "platform_pitch_deg": math.degrees(c.pitch)}
