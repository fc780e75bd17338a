"""The 3-PRS robot model: description file, kinematics, Pinocchio dynamics, regressor."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rt.model.description import RobotDescription, load_description
from rt.model.dynamics import Dynamics, Payload, State
from rt.model.kinematics import Configuration, Kinematics


@dataclass
class RobotModel:
    """A description with its kinematics and dynamics, sharing one FK warm start."""

    description: RobotDescription
    kin: Kinematics
    dyn: Dynamics

    @classmethod
    def load(cls, path: str | Path | None = None) -> RobotModel:
        return cls.from_description(load_description(path))

    @classmethod
    def from_description(cls, desc: RobotDescription) -> RobotModel:
        kin = Kinematics(desc)
        return cls(desc, kin, Dynamics(desc, kin))


__all__ = ["Configuration", "Dynamics", "Kinematics", "Payload", "RobotDescription",
           "RobotModel", "State", "load_description"]
