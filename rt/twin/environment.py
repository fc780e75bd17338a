"""What the twin's platform touches: free motion, a force plate through the ATI sensor, a
compliant foot/ankle; payloads (with scheduled steps) are parameter changes of the platform.

Each environment packs into the float64[ENV_SIZE] array read by ``rt.twin.physics``.
"""
from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from rt.twin import physics

Finite = Annotated[float, Field(allow_inf_nan=False)]
NonNeg = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class _Env(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class FreeMotion(_Env):
    """Nothing touches the platform."""

    kind: Literal["free"] = "free"

    def pack(self) -> np.ndarray:
        return np.zeros(physics.ENV_SIZE)


class ForcePlateContact(_Env):
    """A force plate rigidly mounted above the platform, pressed through the ATI sensor.

    The tool tip (``tool_length_m`` above the sensor origin along its z axis) meets the plate's
    horizontal lower face at ``plate_height_m`` (base frame). Normal spring-damper, one-sided
    (the contact can open); tangential viscous drag models the tip's grip. With
    ``tangential_stiffness_n_per_m`` > 0 the tip also sticks by static friction (Coulomb,
    ``friction_coefficient``): a tilted push then loads the plate in shear, as a calibration
    needs to identify the Fx/Fy columns; 0 (the default) keeps the drag alone.
    """

    kind: Literal["plate"] = "plate"
    plate_height_m: Finite = 0.75
    stiffness_n_per_m: Annotated[float, Field(gt=0.0)] = 2.0e6
    damping_n_s_per_m: NonNeg = 2.0e3
    tangential_damping_n_s_per_m: NonNeg = 5.0e3
    tool_length_m: NonNeg = 0.02
    tangential_stiffness_n_per_m: NonNeg = 0.0
    friction_coefficient: NonNeg = 0.5

    def pack(self) -> np.ndarray:
        env = np.zeros(physics.ENV_SIZE)
        env[:8] = (physics.ENV_PLATE, self.plate_height_m, self.stiffness_n_per_m,
                   self.damping_n_s_per_m, self.tangential_damping_n_s_per_m, self.tool_length_m,
                   self.tangential_stiffness_n_per_m, self.friction_coefficient)
        return env


class CompliantAnkle(_Env):
    """A patient's strapped foot turning about its ankle joint centre, plus limb weight.

    The foot is rigid with the platform; its ankle joint centre is ``centre_from_sensor_m``
    from the sensor origin (P axes; default 70 mm above the sole, the adult malleolus height,
    ``rt.model.ankle.HEIGHT_RANGE_M``). The shank holds the centre near its rest position
    ``neutral_centre_m`` (base frame) through translational springs and dampers — vertical:
    the heel pad and the leg; horizontal: the soft tissue under the straps and the knee — so a
    platform that does not turn the foot about the ankle pushes and pulls on it, and the
    sensor reads it as on a real foot. The joint resists rotation from the neutral angles with
    a stiffness rising towards the end of range, τ = K θ (1 + (θ/θ_end)²) (the secant stiffness
    doubles at θ_end), and viscous damping.

    Parameters, per axis (roll = inversion/eversion, pitch = dorsi/plantar flexion, yaw =
    abduction/adduction):

    * stiffness near neutral: the relaxed quasi-static ankle stiffness of unimpaired adults is
      a few tens of N m/rad, dorsi/plantar flexion stiffer than inversion/eversion (Roy, Krebs,
      Williams, Bever, Forrester, Macko, Hogan, "Robot-aided neurorehabilitation: a novel robot
      for ankle rehabilitation", IEEE Trans. Robotics 25:569-582, 2009; Rastgaar, Ho, Lee,
      Krebs, Hogan, "Multi-directional dynamic mechanical impedance of the human ankle", IEEE
      ICORR 2009): 45, 30 and 20 N m/rad here;
    * the rise towards the end of range: Weiss, Kearney, Hunter, "Position dependence of ankle
      joint dynamics - I. Passive mechanics", J. Biomech. 19:727-735, 1986 (stiffness least
      near neutral, growing steeply towards the ends): θ_end 20° (DF/PF), 15° (INV/EV);
    * damping of order 1 N m s/rad (Kearney & Hunter, Crit. Rev. Biomed. Eng. 18:55-87, 1990).

    The translational stiffnesses are design values of this twin, not measurements: 1e5 N/m
    vertically (heel pad and leg, as before) and 3e3 N/m horizontally (3 N per mm of
    misalignment: the seated patient's shank, pivoting at the knee, gives way before the ATI
    sensor's lateral range is reached; 1e4 N/m saturated it at 50 mm). ``neutral_z_m`` is the
    height of the sensor origin where the foot is unloaded; when ``neutral_centre_m`` is not
    given the centre's rest position is computed from it assuming no parasitic translation at
    the neutral pose (exact for a level neutral pose); :meth:`at_pose` computes both from the
    robot's kinematics.
    """

    kind: Literal["ankle"] = "ankle"
    neutral_z_m: Finite = 0.713
    neutral_roll_rad: Finite = 0.0
    neutral_pitch_rad: Finite = 0.0
    neutral_yaw_rad: Finite = 0.0
    centre_from_sensor_m: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.07)
    neutral_centre_m: tuple[Finite, Finite, Finite] | None = None
    vertical_stiffness_n_per_m: NonNeg = 1.0e5
    vertical_damping_n_s_per_m: NonNeg = 1.0e3
    horizontal_stiffness_n_per_m: NonNeg = 3.0e3
    horizontal_damping_n_s_per_m: NonNeg = 1.0e2
    stiffness_n_m_per_rad: tuple[NonNeg, NonNeg, NonNeg] = (30.0, 45.0, 20.0)
    damping_n_m_s_per_rad: tuple[NonNeg, NonNeg, NonNeg] = (0.6, 1.0, 0.3)
    end_of_range_rad: tuple[NonNeg, NonNeg] = (0.2618, 0.3491)
    limb_weight_n: NonNeg = 60.0

    @classmethod
    def at_pose(cls, kinematics, z_m: float, roll_rad: float, pitch_rad: float,
                **fields) -> CompliantAnkle:
        """The foot unloaded with the platform at (z, roll, pitch): the centre's rest position
        from the robot's kinematics (parasitic x, y and yaw included)."""
        c = kinematics.ik(z_m, roll_rad, pitch_rad, check=False)
        s = kinematics.description.sensor.offset_m
        a = fields.get("centre_from_sensor_m", cls.model_fields["centre_from_sensor_m"].default)
        r = c.rotation
        p = (s[0] + a[0], s[1] + a[1], s[2] + a[2])
        centre = tuple(v + r[3 * i] * p[0] + r[3 * i + 1] * p[1] + r[3 * i + 2] * p[2]
                       for i, v in enumerate((c.x, c.y, c.z)))
        sensor_z = c.z + r[6] * s[0] + r[7] * s[1] + r[8] * s[2]
        return cls(neutral_z_m=sensor_z, neutral_roll_rad=roll_rad, neutral_pitch_rad=pitch_rad,
                   neutral_yaw_rad=c.yaw, neutral_centre_m=centre, **fields)

    def rest_centre(self) -> tuple[float, float, float]:
        """The ankle centre's rest position (base frame, m)."""
        if self.neutral_centre_m is not None:
            return self.neutral_centre_m
        cg, sg = math.cos(self.neutral_roll_rad), math.sin(self.neutral_roll_rad)
        cb, sb = math.cos(self.neutral_pitch_rad), math.sin(self.neutral_pitch_rad)
        a = self.centre_from_sensor_m
        # R = Ry(β) Rx(γ) (the yaw at a neutral pose is second order).
        return (cb * a[0] + sb * sg * a[1] + sb * cg * a[2],
                cg * a[1] - sg * a[2],
                self.neutral_z_m - sb * a[0] + cb * sg * a[1] + cb * cg * a[2])

    def pack(self) -> np.ndarray:
        env = np.zeros(physics.ENV_SIZE)
        env[:23] = (physics.ENV_ANKLE, *self.rest_centre(), *self.centre_from_sensor_m,
                    self.horizontal_stiffness_n_per_m, self.vertical_stiffness_n_per_m,
                    self.horizontal_damping_n_s_per_m, self.vertical_damping_n_s_per_m,
                    *self.stiffness_n_m_per_rad, *self.damping_n_m_s_per_rad,
                    self.neutral_roll_rad, self.neutral_pitch_rad, self.neutral_yaw_rad,
                    *self.end_of_range_rad, self.limb_weight_n)
        return env


def patient_foot(kinematics, z_m: float, roll_rad: float, pitch_rad: float,
                 ankle=None) -> CompliantAnkle:
    """The patient's foot strapped on the platform at a session's start pose, unloaded: its
    ankle centre where the patient's ankle setup (``rt.model.ankle.AnkleSetup``) puts it, or
    the twin's default height above the sole when there is none."""
    fields: dict = {"limb_weight_n": 0.0}
    if ankle is not None:
        fields["centre_from_sensor_m"] = (ankle.offset_x_m, ankle.offset_y_m,
                                          ankle.sole_above_sensor_m + ankle.height_above_sole_m)
    return CompliantAnkle.at_pose(kinematics, z_m, roll_rad, pitch_rad, **fields)


class PayloadStep(_Env):
    """Free motion with a payload of ``mass_kg`` put on the platform at ``at_s`` (s).

    The thesis's experiment (fig. 50): 100 kg at 13 s. COM in P (m).
    """

    kind: Literal["payload"] = "payload"
    #: Up to 500 kg: three 2 kN drives hold about 600 kg of platform and payload statically.
    mass_kg: Annotated[float, Field(ge=0.0, le=500.0, allow_inf_nan=False)] = 100.0
    at_s: NonNeg = 13.0
    com_m: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.10)

    def pack(self) -> np.ndarray:
        return np.zeros(physics.ENV_SIZE)


Environment = Annotated[FreeMotion | ForcePlateContact | CompliantAnkle | PayloadStep,
                        Field(discriminator="kind")]


def parse_environment(text: str) -> FreeMotion | ForcePlateContact | CompliantAnkle | PayloadStep:
    """Parse the CLI form ``free``, ``payload:100[@13]``, ``plate[:height_m]``, ``ankle``."""
    from pydantic import ValidationError

    from rt.errors import InputError, validation_summary

    name, _, arg = text.partition(":")
    try:
        if name == "free" and not arg:
            return FreeMotion()
        if name == "payload":
            mass, _, at = arg.partition("@")
            return PayloadStep(mass_kg=float(mass) if mass else 100.0,
                               at_s=float(at) if at else 0.0)
        if name == "plate":
            return (ForcePlateContact(plate_height_m=float(arg)) if arg
                    else ForcePlateContact())
        if name == "ankle" and not arg:
            return CompliantAnkle()
    except ValidationError as exc:
        raise InputError(f"environment {text!r}: {validation_summary(exc)}") from None
    except ValueError:
        raise InputError(f"environment {text!r}: {arg!r} is not a number") from None
    raise InputError(f"unknown environment {text!r}; use free, payload:KG[@S], plate[:HEIGHT_M] "
                     "or ankle")


