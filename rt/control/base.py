"""The controller interface: what every position controller takes and gives each cycle.

Inputs per cycle (SI): the robot's kinematic ``State`` for the measured q and estimated q̇
(computed once per cycle by the model component), and the reference (q_d, q̇_d, q̈_d).
Output: actuator forces τ (N) along the ball screws, written into a preallocated array.
Errors follow the thesis: e = q − q_d, ė = q̇ − q̇_d.

Controllers keep parameters (gains, validated, changeable at run time through ``set_gains``)
apart from their state (integrals, estimates), which ``reset`` restores.

Bumpless transfer: when a controller takes over from another, ``handover`` records the
difference between the force the old law gave and the new law's first output and fades it out
with time constant ``bumpless_time_s`` — the actuator force is continuous at the switch and
afterwards converges to what the new law demands. Laws with an integrator absorb the difference
into it instead (classic bumpless PID).
"""
from __future__ import annotations

import abc
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

from rt.errors import ConfigurationError
from rt.model import RobotModel
from rt.model.dynamics import State

STATUS_OK = 0


@dataclass
class Reference:
    """Desired slider positions (m), velocities (m/s) and accelerations (m/s²)."""

    q: np.ndarray = field(default_factory=lambda: np.zeros(3))
    qd: np.ndarray = field(default_factory=lambda: np.zeros(3))
    qdd: np.ndarray = field(default_factory=lambda: np.zeros(3))


class Gains(BaseModel):
    """Base of every controller's gains: strict, validated, documented per field."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class Controller(abc.ABC):
    """One position-control law. Subclasses set ``name``, ``gains_type`` and ``_law``."""

    name: ClassVar[str]
    gains_type: ClassVar[type[Gains]]
    bumpless_time_s: float = 0.2

    def __init__(self, model: RobotModel, gains: Gains | dict | None = None):
        self.model = model
        self.dyn = model.dyn
        self.gains = self._validate(gains or {})
        self._offset = np.zeros(3)
        self._offset_weight = 0.0
        self.tau = np.zeros(3)
        self.reset()

    # ------------------------------------------------------------------ parameters
    def _validate(self, gains: Gains | dict) -> Gains:
        if isinstance(gains, self.gains_type):
            return gains
        if isinstance(gains, Gains):
            gains = gains.model_dump()
        try:
            return self.gains_type.model_validate(gains)
        except ValidationError as exc:
            msgs = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
            raise ConfigurationError(f"{self.name} gains invalid: {msgs}") from None

    def set_gains(self, **changes: Any) -> None:
        """Change gains at run time; invalid values raise and change nothing."""
        merged = {**self.gains.model_dump(), **changes}
        self.gains = self._validate(merged)
        self._gains_changed()

    def _gains_changed(self) -> None:
        """Hook for laws that precompute from their gains."""

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to the initial state (integrals and estimates cleared)."""
        self._offset[:] = 0.0
        self._offset_weight = 0.0

    def handover(self, previous_tau: np.ndarray, st: State, ref: Reference, dt: float) -> None:
        """Take over from a controller whose last output was ``previous_tau`` (N)."""
        probe = np.zeros(3)
        self._law(st, ref, dt, probe, dry_run=True)
        self._absorb(np.asarray(previous_tau, dtype=float) - probe)

    def _absorb(self, difference: np.ndarray) -> None:
        self._offset[:] = difference
        self._offset_weight = 1.0

    # ------------------------------------------------------------------ cycle
    def update(self, st: State, ref: Reference, dt: float, out: np.ndarray) -> int:
        """Write τ (N) into ``out``; returns a status (0 = ok)."""
        status = self._law(st, ref, dt, out, dry_run=False)
        if self._offset_weight > 0.0:
            out += self._offset_weight * self._offset
            self._offset_weight *= math.exp(-dt / self.bumpless_time_s)
            if self._offset_weight < 1e-6:
                self._offset_weight = 0.0
        self.tau[:] = out
        return status

    @abc.abstractmethod
    def _law(self, st: State, ref: Reference, dt: float, out: np.ndarray, dry_run: bool) -> int:
        """The control law; with ``dry_run`` it must not change the controller's state."""


CONTROLLERS: dict[str, type[Controller]] = {}


def register(cls: type[Controller]) -> type[Controller]:
    CONTROLLERS[cls.name] = cls
    return cls


def create(name: str, model: RobotModel, gains: dict | None = None) -> Controller:
    """A controller by name, with gains from config (defaults when omitted)."""
    import rt.control.laws  # noqa: F401  (registers the laws)
    import rt.control.adaptive  # noqa: F401

    from rt.cli_args import canonical_name

    try:
        cls = CONTROLLERS[canonical_name(name)]
    except KeyError:
        raise ConfigurationError(f"unknown controller {name!r}; known: "
                                 f"{', '.join(sorted(CONTROLLERS))}") from None
    return cls(model, gains)
