"""Moving the plate to a trial's site: the interface, and the real plate's moves.

:class:`SiteMoves` is what a runner asks before a site's first trial: "the plate is now at this
site; where exactly?" — the true pose (known on the twin only; the registered one on the rig)
and the registration the fit uses. Implementations: the twin's simulated operator
(``calibration.twin_runner._SiteMoves``) and :class:`CameraSiteMoves` (a real plate: the
operator moves it, a real camera confirms, :mod:`calibration.operator`).
"""
from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from calibration import registration as reg
from calibration.operator import MoveTolerance, Operator, confirm_move
from rt.devices.interfaces import Camera
from rt.errors import HardwareError

#: Frames averaged per registration.
CAMERA_FRAMES = 4


class SiteMoves(Protocol):
    def place(self, tip_B: np.ndarray, site: tuple[float, float], name: str = ""
              ) -> tuple[np.ndarray, reg.Registration]:
        """(T_BF true — or as registered where the truth is unknown —, registration) of the
        plate once it is at ``site`` (m, in F) under the tool tip ``tip_B`` (base B)."""


class CameraSiteMoves:
    """A real plate: the operator moves it (``operator``), ``camera`` frames register it
    (``rig``: the boards and intrinsics, the same estimator as the twin's), checked within
    ``tolerance`` of the planned pose. ``registration="nominal"``: no camera, the operator's
    word and the nominal pose (no check possible)."""

    def __init__(self, operator: Operator, camera: Camera | None, registration: str = "camera",
                 level_sigma_rad: float | None = math.radians(0.1),
                 tolerance: MoveTolerance | None = None, rig: reg.MarkerRig | None = None,
                 frames: int = CAMERA_FRAMES) -> None:
        if registration == "camera" and camera is None:
            raise HardwareError("camera registration needs a camera (--camera)")
        self.operator = operator
        self.camera = camera
        self.method = registration
        self.level_sigma_rad = level_sigma_rad
        self.tolerance = tolerance or MoveTolerance()
        self.rig = rig or reg.MarkerRig()
        self.frames = frames
        self.T_BF_centre: np.ndarray | None = None
        self.current: tuple[tuple[float, float], reg.Registration] | None = None

    def place(self, tip_B: np.ndarray, site: tuple[float, float], name: str = ""
              ) -> tuple[np.ndarray, reg.Registration]:
        if self.current is not None and self.current[0] == site:
            return self.current[1].T_BF, self.current[1]
        if self.T_BF_centre is None:
            self.T_BF_centre = reg.nominal_T_BF(tip_B, (0.0, 0.0))
        T_B_R = self.rig.T_B_R(self.T_BF_centre)
        planned = reg.nominal_T_BF(tip_B, site)
        camera = self.camera

        def register() -> reg.Registration:
            if self.method != "camera" or camera is None:
                return reg.nominal(tip_B, site)
            regs = [reg.camera_registration(camera.read()[0], self.rig, T_B_R)
                    for _ in range(self.frames)]
            return reg.with_level_prior(reg.average_registrations(regs), self.level_sigma_rad)

        registered = confirm_move(self.operator, name or str(site), site, planned,
                                  lambda: None, register,
                                  self.tolerance if self.method == "camera" else None)
        self.current = (site, registered)
        return registered.T_BF, registered

    def close(self) -> None:
        if self.camera is not None:
            self.camera.close()
