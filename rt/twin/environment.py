"""What the twin's platform touches: free motion, a force plate through the ATI sensor, a
compliant foot/ankle; payloads (with scheduled steps) are parameter changes of the platform.

Each environment packs into the float64[16] array read by ``rt.twin.physics``.
"""
from __future__ import annotations

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
        return np.zeros(16)


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
        env = np.zeros(16)
        env[:8] = (physics.ENV_PLATE, self.plate_height_m, self.stiffness_n_per_m,
                   self.damping_n_s_per_m, self.tangential_damping_n_s_per_m, self.tool_length_m,
                   self.tangential_stiffness_n_per_m, self.friction_coefficient)
        return env


class CompliantAnkle(_Env):
    """A patient's strapped foot: springs and dampers about a neutral pose, plus limb weight.

    ``neutral_z_m`` is the height (base frame) of the sensor origin at which the foot is
    unloaded; the default puts it at the platform's home (z 0.633 m + 80 mm sensor offset).
    Defaults are of the order reported for the passive human ankle (rotational stiffness
    tens of N m/rad, heel-pad/leg vertical stiffness ~1e5 N/m).
    """

    kind: Literal["ankle"] = "ankle"
    neutral_z_m: Finite = 0.713
    neutral_roll_rad: Finite = 0.0
    neutral_pitch_rad: Finite = 0.0
    vertical_stiffness_n_per_m: NonNeg = 1.0e5
    vertical_damping_n_s_per_m: NonNeg = 1.0e3
    stiffness_n_m_per_rad: tuple[NonNeg, NonNeg, NonNeg] = (40.0, 60.0, 20.0)
    damping_n_m_s_per_rad: tuple[NonNeg, NonNeg, NonNeg] = (1.0, 1.5, 0.5)
    limb_weight_n: NonNeg = 60.0

    def pack(self) -> np.ndarray:
        env = np.zeros(16)
        env[:13] = (physics.ENV_ANKLE, self.neutral_z_m, self.neutral_roll_rad,
                    self.neutral_pitch_rad, self.vertical_stiffness_n_per_m,
                    self.vertical_damping_n_s_per_m, *self.stiffness_n_m_per_rad,
                    *self.damping_n_m_s_per_rad, self.limb_weight_n)
        return env


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
        return np.zeros(16)


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


