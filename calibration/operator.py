"""The operator's move of the plate between grid points, confirmed by the camera.

Between two sites of a campaign the plate (or the robot) is moved by hand. With a real plate
the CLI tells the operator where to put it and waits (:class:`TerminalOperator`: Enter when
done, ``q`` to stop); then the camera registers the plate (ArUco boards, ``solvePnP``,
:mod:`calibration.registration`) and the pose must be within :class:`MoveTolerance` of the
planned one (the site under the tool tip) before the site's trials run. Outside it, the
operator is shown the measured offset and asked again (up to ``attempts`` times); a script
(``--yes``: :class:`ScriptOperator`, nothing waits) is refused with the measured offset
instead, and so is a run with no terminal to ask on and no ``--yes``.

The tolerance guards against gross mistakes (the wrong site, a plate not moved or knocked):
the fit always uses the registered pose, never the planned one. On the twin the operator's
move is simulated (a placement error drawn per move) and checked by the same code; a
simulated operator re-places the plate when asked again.
"""
from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TextIO

import numpy as np

from calibration.registration import Registration
from rt.errors import InputError

#: Default tolerance of a move (plate plane translation, rotation about any axis).
TOLERANCE_M = 10.0e-3
TOLERANCE_RAD = math.radians(2.0)
ATTEMPTS = 3


@dataclass(frozen=True)
class MoveTolerance:
    translation_m: float = TOLERANCE_M
    rotation_rad: float = TOLERANCE_RAD

    def __post_init__(self) -> None:
        for name, v in (("translation_m", self.translation_m),
                        ("rotation_rad", self.rotation_rad)):
            if not (math.isfinite(v) and v > 0.0):
                raise InputError(f"move tolerance {name} must be positive, got {v}")

    def describe(self) -> str:
        return f"{self.translation_m * 1e3:.1f} mm, {math.degrees(self.rotation_rad):.2f}°"


@dataclass(frozen=True)
class PoseOffset:
    """The registered plate pose against the planned one, in the planned plate's axes."""

    dx_m: float
    dy_m: float
    dz_m: float
    rotation_rad: float     # angle of the relative rotation
    yaw_rad: float          # its part about the plate's normal

    @property
    def translation_m(self) -> float:
        return math.hypot(self.dx_m, self.dy_m)

    def within(self, tol: MoveTolerance) -> bool:
        return self.translation_m <= tol.translation_m and self.rotation_rad <= tol.rotation_rad

    def describe(self) -> str:
        return (f"{self.translation_m * 1e3:.1f} mm (x {self.dx_m * 1e3:+.1f}, y "
                f"{self.dy_m * 1e3:+.1f} mm) and {math.degrees(self.rotation_rad):.2f}° "
                f"(yaw {math.degrees(self.yaw_rad):+.2f}°)")


def pose_offset(T_planned: np.ndarray, T_measured: np.ndarray) -> PoseOffset:
    """Offset of ``T_measured`` from ``T_planned`` (both plate F in the base B)."""
    R_p = T_planned[:3, :3]
    d = R_p.T @ (T_measured[:3, 3] - T_planned[:3, 3])
    R = R_p.T @ T_measured[:3, :3]
    angle = math.acos(max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0)))
    return PoseOffset(float(d[0]), float(d[1]), float(d[2]), angle,
                      math.atan2(float(R[1, 0]), float(R[0, 0])))


class Operator(Protocol):
    """Who moves the plate. ``interactive``: can be asked again after a failed check."""

    interactive: bool

    def ask(self, instruction: str) -> None:
        """Tell the operator what to do and wait until it is done; InputError to stop."""


class TerminalOperator:
    """Asks on a terminal: the instruction on ``out``, Enter on ``inp`` when done, ``q`` stops."""

    interactive = True

    def __init__(self, inp: TextIO | None = None, out: TextIO | None = None) -> None:
        self.inp = inp if inp is not None else sys.stdin
        self.out = out if out is not None else sys.stderr

    def ask(self, instruction: str) -> None:
        self.out.write(f"\n{instruction}\n  Enter when done, q to stop: ")
        self.out.flush()
        line = self.inp.readline()
        if not line or line.strip().lower() in ("q", "quit", "stop"):
            raise InputError("the operator stopped the campaign (the trials run so far are "
                             "in the campaign folder's trials/)")


class ScriptOperator:
    """``--yes``: nothing waits (the plate is assumed placed by the script's own means); the
    instruction goes to ``out`` for the log; a failed camera check is refused."""

    interactive = False

    def __init__(self, out: TextIO | None = None) -> None:
        self.out = out

    def ask(self, instruction: str) -> None:
        if self.out is not None:
            self.out.write(f"\n{instruction} (--yes: not waiting)\n")


class SimulatedOperator:
    """The twin's operator: the move itself is simulated by the caller's ``move``; asked again
    after a failed check, it places the plate again."""

    def __init__(self, interactive: bool = True) -> None:
        self.interactive = interactive
        self.instructions: list[str] = []

    def ask(self, instruction: str) -> None:
        self.instructions.append(instruction)


def terminal_or_refuse(yes: bool, inp: TextIO | None = None) -> Operator:
    """The CLI's operator: ``--yes`` → :class:`ScriptOperator`; a terminal → ask on it; else
    refuse (a script must say it does not wait)."""
    stream = inp if inp is not None else sys.stdin
    if yes:
        return ScriptOperator(sys.stderr)
    if not stream.isatty():
        raise InputError("a campaign on a real plate waits for the operator to move the plate "
                         "between sites, and there is no terminal to ask on: run it in a "
                         "terminal, or pass --yes for a script (each move is then only "
                         "checked by the camera, and refused outside the tolerance)")
    return TerminalOperator(stream)


def confirm_move(operator: Operator, site: str, site_xy_m: tuple[float, float],
                 T_planned: np.ndarray, move: Callable[[], None],
                 register: Callable[[], Registration], tolerance: MoveTolerance | None,
                 attempts: int = ATTEMPTS) -> Registration:
    """Ask for the move to ``site``, register, check against ``T_planned`` (module docstring).

    ``move`` runs after each instruction (the twin's simulated move; nothing on the rig);
    ``tolerance`` None skips the check (no camera: the nominal registration)."""
    instruction = (f"Move the plate so that site {site} (x {site_xy_m[0] * 1e3:+.0f} mm, y "
                   f"{site_xy_m[1] * 1e3:+.0f} mm of the plate) is under the tool tip.")
    for attempt in range(attempts):
        operator.ask(instruction)
        move()
        reg = register()
        if tolerance is None:
            return reg
        off = pose_offset(T_planned, reg.T_BF)
        if off.within(tolerance):
            return reg
        refusal = (f"site {site}: the camera sees the plate {off.describe()} from its planned "
                   f"pose (tolerance {tolerance.describe()})")
        if not operator.interactive:
            raise InputError(f"{refusal}; place it and run the remaining trials "
                             "(--trials) into a new folder")
        if attempt + 1 == attempts:
            raise InputError(f"{refusal} after {attempts} attempts; the campaign stops")
        instruction = f"{refusal}. Adjust it so that site {site} is under the tool tip."
    raise AssertionError("unreachable")
