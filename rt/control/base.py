"""The controller interface: what every position controller takes and gives each cycle.

Inputs per cycle (SI): the robot's kinematic ``State`` for the measured q and estimated q̇
(computed once per cycle by the model component), and the reference (q_d, q̇_d, q̈_d).
Output: actuator forces τ (N) along the ball screws, written into a preallocated array.
Errors follow the thesis: e = q − q_d, ė = q̇ − q̇_d.

Controllers keep parameters (gains, validated, changeable at run time through ``set_gains``)
apart from their state (integrals, estimates), which ``reset`` restores. Every law declares the
range of each of its gains with units (``gain_ranges``, a class-level table of ``GainRange``);
a gain outside its range is refused naming the range, at construction and at run time, so a
typo on a clinic's workstation (an extra zero on Kp) never reaches a patient's ankle.

Bumpless transfer: when a controller takes over from another, ``handover`` records the
difference between the force the old law gave and the new law's first output and fades it out
with time constant ``bumpless_time_s`` — the actuator force is continuous at the switch and
afterwards converges to what the new law demands. Laws with an integrator absorb the difference
into it instead (classic bumpless PID).
"""
from __future__ import annotations

import abc
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

from rt.epoch import bump
from rt.errors import ConfigurationError
from rt.model import RobotModel
from rt.model import rigid_body as rb
from rt.model.dynamics import State
from rt.model.kernels import TREE_DOF

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


@dataclass(frozen=True)
class GainRange:
    """The values a gain may take, ``lo`` to ``hi`` inclusive, in ``unit`` (SI)."""

    lo: float
    hi: float
    unit: str

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.lo <= self.hi):
            raise ConfigurationError(f"gain range [{self.lo}, {self.hi}] is not an interval")

    def __str__(self) -> str:
        return f"[{self.lo:g}, {self.hi:g}] {self.unit}".rstrip()

    def as_dict(self) -> dict[str, Any]:
        return {"min": self.lo, "max": self.hi, "unit": self.unit}


def check_gain_ranges(owner: str, ranges: Mapping[str, GainRange], gains: BaseModel) -> None:
    """Raise ``ConfigurationError`` naming the gain, its value and its range when any numeric
    gain in ``gains`` (tuples: every element) lies outside ``ranges``."""
    for name, rng in ranges.items():
        value = getattr(gains, name)
        for v in value if isinstance(value, tuple) else (value,):
            if not rng.lo <= v <= rng.hi:
                raise ConfigurationError(
                    f"{owner} gain {name} = {v:g} {rng.unit} is outside its range {rng}".rstrip())


def check_range_table(owner: str, ranges: Mapping[str, GainRange],
                      gains_type: type[BaseModel]) -> None:
    """The table must give a range to every numeric gain of ``gains_type`` and nothing else
    (booleans are switches, not gains)."""
    numeric = {n for n, f in gains_type.model_fields.items() if f.annotation is not bool}
    if set(ranges) != numeric:
        raise ConfigurationError(
            f"{owner}: gain ranges {sorted(ranges)} do not match its gains {sorted(numeric)}")


class Controller(abc.ABC):
    """One position-control law. Subclasses set ``name``, ``gains_type`` and ``_law``.

    A block that hosts the law calls :meth:`bind_cycle` once with its buffers; ``cycle`` is
    then the compiled law bound to them (``cycle(dt) -> status``: one kernel call, what
    ``update`` computes, without the interpreter's layers) whenever that is all ``update``
    would do, and None otherwise (interpreted, a law without a whole kernel, a bumpless
    offset still fading): the block then calls ``update``.
    """

    name: ClassVar[str]
    gains_type: ClassVar[type[Gains]]
    #: gain name -> allowed range (with units); checked on every change of gains.
    gain_ranges: ClassVar[Mapping[str, GainRange]]
    bumpless_time_s: float = 0.2

    def __init__(self, model: RobotModel, gains: Gains | dict | None = None,
                 compiled: bool = True):
        self.model = model
        self.dyn = model.dyn
        self.gains = self._validate(gains or {})
        self._offset = np.zeros(3)
        self._offset_weight = 0.0
        self.tau = np.zeros(3)
        #: The compiled kernel (``rt.control.kernels``) runs the law; ``False`` runs the
        #: interpreted ``_law``, the reference the compiled one is tested against.
        self.compiled = compiled
        self._gain_array = np.zeros(4)
        self._work = np.zeros(8 + rb.work_size(TREE_DOF))
        self._binding: tuple[State, Reference, np.ndarray] | None = None
        self.cycle: Callable[[float], int] | None = None
        self._pack_gains()
        self.reset()
        if compiled:
            from rt.control.kernels import warm_up
            warm_up(self.dyn)

    # ------------------------------------------------------------------ parameters
    def _validate(self, gains: Gains | dict) -> Gains:
        if isinstance(gains, self.gains_type):
            return gains
        if isinstance(gains, Gains):
            gains = gains.model_dump()
        try:
            validated = self.gains_type.model_validate(gains)
        except ValidationError as exc:
            msgs = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
            raise ConfigurationError(f"{self.name} gains invalid: {msgs}") from None
        check_gain_ranges(self.name, self.gain_ranges, validated)
        return validated

    @classmethod
    def describe_gains(cls) -> dict[str, dict[str, Any]]:
        """Each gain's default and range: ``{name: {"default", "min", "max", "unit"}}``."""
        defaults = cls.gains_type()
        return {name: {"default": getattr(defaults, name), **rng.as_dict()}
                for name, rng in cls.gain_ranges.items()}

    def check_gains(self, **changes: Any) -> Gains:
        """The gains ``changes`` would give, validated (ranges included); changes nothing.
        Raises ``ConfigurationError`` naming the gain and its range."""
        return self._validate({**self.gains.model_dump(), **changes})

    def set_gains(self, **changes: Any) -> None:
        """Change gains at run time; invalid values raise and change nothing."""
        self.gains = self.check_gains(**changes)
        self._pack_gains()
        self._gains_changed()

    def _gains_changed(self) -> None:
        """Hook for laws that precompute from their gains."""

    def _pack_gains(self) -> None:
        """Hook: copy the gains into ``_gain_array`` in the layout the law's kernel reads."""

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to the initial state (integrals and estimates cleared)."""
        self._offset[:] = 0.0
        self._offset_weight = 0.0
        self._rebind()

    def bind_cycle(self, st: State, ref: Reference, out: np.ndarray) -> None:
        """The buffers a block runs this law on every cycle (its state and reference inputs,
        its τ output, N): ``cycle`` is the law bound to them when it can be (class
        docstring). ``tau`` becomes ``out`` (the last output either way)."""
        self._binding = (st, ref, out)
        self.tau = out
        self._rebind()

    def _rebind(self) -> None:
        b = self._binding
        self.cycle = (None if b is None or not self.compiled or self._offset_weight > 0.0
                      else self._bound_kernel(*b))
        bump()                        # the fused cycle binds the law's buffers again

    def _bound_kernel(self, st: State, ref: Reference, out: np.ndarray
                      ) -> Callable[[float], int] | None:
        """Hook: the compiled law as ``cycle(dt) -> status`` on these buffers, exactly what
        ``update`` computes when no offset fades; arrays a reset or new gains replace are
        read through ``self`` at call time. None: the law has no whole kernel."""
        return None

    def handover(self, previous_tau: np.ndarray, st: State, ref: Reference, dt: float) -> None:
        """Take over from a controller whose last output was ``previous_tau`` (N)."""
        probe = np.zeros(3)
        self._run_law(st, ref, dt, probe, True)
        self._absorb(np.asarray(previous_tau, dtype=float) - probe)

    def _absorb(self, difference: np.ndarray) -> None:
        self._offset[:] = difference
        self._offset_weight = 1.0
        self._rebind()

    # ------------------------------------------------------------------ cycle
    def update(self, st: State, ref: Reference, dt: float, out: np.ndarray) -> int:
        """Write τ (N) into ``out``; returns a status (0 = ok)."""
        status = self._run_law(st, ref, dt, out, False)
        if self._offset_weight > 0.0:
            out += self._offset_weight * self._offset
            self._offset_weight *= math.exp(-dt / self.bumpless_time_s)
            if self._offset_weight < 1e-6:
                self._offset_weight = 0.0
                self._rebind()
        if out is not self.tau:
            self.tau[:] = out
        return status

    def _run_law(self, st: State, ref: Reference, dt: float, out: np.ndarray,
                 dry_run: bool) -> int:
        if self.compiled:
            return self._law_compiled(st, ref, dt, out, dry_run)
        return self._law(st, ref, dt, out, dry_run)

    @abc.abstractmethod
    def _law(self, st: State, ref: Reference, dt: float, out: np.ndarray, dry_run: bool) -> int:
        """The control law, interpreted (the reference implementation); with ``dry_run`` it
        must not change the controller's state."""

    def _law_compiled(self, st: State, ref: Reference, dt: float, out: np.ndarray,
                      dry_run: bool) -> int:
        """The same law through its compiled kernel; laws without one run ``_law``."""
        return self._law(st, ref, dt, out, dry_run)


CONTROLLERS: dict[str, type[Controller]] = {}


def register(cls: type[Controller]) -> type[Controller]:
    """Add a law to the registry; its range table must cover exactly its gains, and its
    default gains must lie inside it."""
    check_range_table(cls.name, cls.gain_ranges, cls.gains_type)
    check_gain_ranges(cls.name, cls.gain_ranges, cls.gains_type())
    CONTROLLERS[cls.name] = cls
    return cls


def create(name: str, model: RobotModel, gains: dict | None = None,
           compiled: bool = True) -> Controller:
    """A controller by name, with gains from config (defaults when omitted); ``compiled=False``
    runs the interpreted reference implementation of the law."""
    import rt.control.adaptive
    import rt.control.laws  # noqa: F401  (registers the laws)
    from rt.cli_args import canonical_name

    try:
        cls = CONTROLLERS[canonical_name(name)]
    except KeyError:
        raise ConfigurationError(f"unknown controller {name!r}; known: "
                                 f"{', '.join(sorted(CONTROLLERS))}") from None
    return cls(model, gains, compiled=compiled)
