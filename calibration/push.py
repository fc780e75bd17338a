"""The calibration's push: a force-mode program playing a precomputed force with the pose held.

Light on imports on purpose: the RT process imports it when it composes its programs
(``calibration.rt_program``), so a ``calibration_push`` request does not wait for the twin
runner's registration and camera code to load on the IPC thread.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from protocols.base import ForceGenerator, GeneratorInput
from protocols.output import ValidationReport
from protocols.schema import Pose
from rt.errors import KinematicsError
from rt.references.program import FORCE_BLOCK, POSE, ProgramTable, Q, ReferenceOutput

if TYPE_CHECKING:
    from rt.twin.environment import ForcePlateContact

#: Tool (load applicator) length above the ATI's origin along its z axis (m).
TOOL_LENGTH_M = 0.02
#: The tool tip on the plate (the twin's contact): lateral stiffness of tip and plate (N/m) and
#: the static friction coefficient (a hard-rubber tip on an aluminium top plate).
TIP_TANGENTIAL_STIFFNESS_N_PER_M = 5.0e5
TIP_FRICTION_COEFFICIENT = 0.6


def tool_plate(height_m: float) -> ForcePlateContact:
    """The twin's calibration plate with its surface at ``height_m`` (base frame) under the
    push tool: the tool's length, its tip's tangential stiffness and friction. (The twin is
    imported here, not with this module: the RT process loads this module on the rig too.)"""
    from rt.twin.environment import ForcePlateContact

    return ForcePlateContact(plate_height_m=height_m, tool_length_m=TOOL_LENGTH_M,
                             tangential_stiffness_n_per_m=TIP_TANGENTIAL_STIFFNESS_N_PER_M,
                             friction_coefficient=TIP_FRICTION_COEFFICIENT)


@dataclass(frozen=True)
class _Push:
    """The protocol-like description a force generator reads (pose held, no own limits)."""

    name: str
    pose: Pose
    kind: str = "calibration_push"
    limits: None = None


class ForceTableGenerator(ForceGenerator):
    """A force-mode generator playing a precomputed force (N) with the pose held, or, with
    ``tilt_rad`` ((n, 2) roll, pitch offsets in rad per sample), tilting under load about the
    held pose (the angles stay position-controlled in force mode)."""

    def __init__(self, name: str, force_n: np.ndarray, pose: tuple[float, float, float],
                 dt: float, kinematics, tilt_rad: np.ndarray | None = None) -> None:
        z, roll, pitch = pose
        push = _Push(name, Pose(z_m=z, roll_deg=math.degrees(roll), pitch_deg=math.degrees(pitch)))
        super().__init__(push, dt, kinematics, name)  # type: ignore[arg-type]
        self._force = np.asarray(force_n, dtype=float)
        self._set_length(len(self._force))
        self._tilt = None if tilt_rad is None else np.asarray(tilt_rad, dtype=float)
        if self._tilt is not None and self._tilt.shape != (len(self._force), 2):
            raise ValueError(f"tilt_rad must be ({len(self._force)}, 2), got "
                             f"{self._tilt.shape}")
        self._q = np.zeros((0, 3))
        self._pose = np.zeros((0, 3))

    def _build(self, report: ValidationReport) -> np.ndarray | None:
        if not self._hold_pose(report):
            return None
        table = np.zeros((self.n_samples, 4))
        table[:, 0] = self._force
        table[:, 1] = np.gradient(self._force, self.dt)
        if self._tilt is not None and not self._build_tilt(report):
            return None
        return table

    def _build_tilt(self, report: ValidationReport) -> bool:
        assert self._tilt is not None
        z, roll0, pitch0 = (float(x) for x in self._const[9:12])
        pose = np.column_stack([np.full(len(self._tilt), z), roll0 + self._tilt[:, 0],
                                pitch0 + self._tilt[:, 1]])
        q = np.empty((len(pose), 3))
        # IK where the tilt changes, reused while it is constant (most of the trial).
        last: tuple[float, float] | None = None
        for k, (_, r, p) in enumerate(pose):
            if last is None or (r, p) != last:
                try:
                    cfg = self.kinematics.ik(z, float(r), float(p), check=True)
                except KinematicsError as exc:
                    report.violations.append(f"tilt at sample {k}: {exc}")
                    return False
                last = (r, p)
            q[k] = cfg.q
        self._q, self._pose = q, pose
        report.roll_range_rad = (float(pose[:, 1].min()), float(pose[:, 1].max()))
        report.pitch_range_rad = (float(pose[:, 2].min()), float(pose[:, 2].max()))
        return True

    def table_view(self) -> ProgramTable | None:
        """The validated trial as the loop's compiled sequencer plays it: each sample's whole
        row as :meth:`update` writes it (the force columns; with a tilt, that sample's slider
        and pose references too), so a push's PLAY, read-ahead included, runs compiled."""
        if not self._ready or type(self).update is not ForceTableGenerator.update:
            return None
        rows = np.tile(self._const, (self.n_samples, 1))
        rows[:, FORCE_BLOCK] = self._table
        if self._tilt is not None:
            rows[:, Q] = self._q
            rows[:, POSE] = self._pose
        return ProgramTable(np.ascontiguousarray(rows, dtype=np.float64), 0,
                            self._const.copy(), self.mode)

    def update(self, out: ReferenceOutput, inp: GeneratorInput | None = None) -> int:
        k = self.index
        status = super().update(out, inp)
        if self._tilt is not None and status >= 0:
            out.q_ref[:] = self._q[k]
            out.pose_ref[:] = self._pose[k]
        return status
