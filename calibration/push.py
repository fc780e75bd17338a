"""The calibration's push: a force-mode program playing a precomputed force with the pose held.

Light on imports on purpose: the RT process imports it when it composes its programs
(``calibration.rt_program``), so a ``calibration_push`` request does not wait for the twin
runner's registration and camera code to load on the IPC thread.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocols.base import ForceGenerator
from protocols.output import ValidationReport
from protocols.schema import Pose

#: Tool (load applicator) length above the ATI's origin along its z axis (m).
TOOL_LENGTH_M = 0.02


@dataclass(frozen=True)
class _Push:
    """The protocol-like description a force generator reads (pose held, no own limits)."""

    name: str
    pose: Pose
    kind: str = "calibration_push"
    limits: None = None


class ForceTableGenerator(ForceGenerator):
    """A force-mode generator playing a precomputed force (N) with the pose held."""

    def __init__(self, name: str, force_n: np.ndarray, pose: tuple[float, float, float],
                 dt: float, kinematics) -> None:
        z, roll, pitch = pose
        push = _Push(name, Pose(z_m=z, roll_deg=math.degrees(roll), pitch_deg=math.degrees(pitch)))
        super().__init__(push, dt, kinematics, name)  # type: ignore[arg-type]
        self._force = np.asarray(force_n, dtype=float)
        self._set_length(len(self._force))

    def _build(self, report: ValidationReport) -> np.ndarray | None:
        if not self._hold_pose(report):
            return None
        table = np.zeros((self.n_samples, 4))
        table[:, 0] = self._force
        table[:, 1] = np.gradient(self._force, self.dt)
        return table
