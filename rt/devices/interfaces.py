"""One small interface per device kind (CONVENTIONS items 1, 3 and 7).

Every device is a context manager whose ``close()`` is safe to call twice. Readings are
returned in SI units through typed views (``Wrench``); raw counts stay inside backends.
Frames: a force/torque sensor reports in its own sensor frame S (z along the tool axis).
"""
from __future__ import annotations

import abc
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rt.epoch import bump
from rt.errors import HardwareError

NAN = math.nan


@dataclass(slots=True)
class Wrench:
    """Force (N) and torque (N m) in the sensor frame, NaN until read.

    ``t`` is the host time of the reading (s, monotonic), ``sequence`` the device's sample
    counter, ``status`` its raw status word. ``stale`` is set when no fresh sample arrived within
    the client's timeout; ``saturated`` when the device flags an overload.
    """

    fx: float = NAN
    fy: float = NAN
    fz: float = NAN
    tx: float = NAN
    ty: float = NAN
    tz: float = NAN
    t: float = NAN
    sequence: int = -1
    status: int = 0
    stale: bool = True
    saturated: bool = False

    def as_tuple(self) -> tuple[float, float, float, float, float, float]:
        """(fx, fy, fz, tx, ty, tz) in N and N m."""
        return (self.fx, self.fy, self.fz, self.tx, self.ty, self.tz)

    def set(self, values: Sequence[float]) -> None:
        """Overwrite fx..tz in place (no allocation; used in the real-time path)."""
        self.fx, self.fy, self.fz, self.tx, self.ty, self.tz = (
            float(values[0]), float(values[1]), float(values[2]),
            float(values[3]), float(values[4]), float(values[5]),
        )

    def invalidate(self) -> None:
        """No sample yet: every value NaN, no sequence, stale."""
        self.fx = self.fy = self.fz = self.tx = self.ty = self.tz = NAN
        self.t, self.sequence, self.status = NAN, -1, 0
        self.stale, self.saturated = True, False

    def copy_from(self, other: Wrench) -> None:
        """Copy every field of ``other`` into this wrench, in place."""
        self.fx, self.fy, self.fz = other.fx, other.fy, other.fz
        self.tx, self.ty, self.tz = other.tx, other.ty, other.tz
        self.t, self.sequence, self.status = other.t, other.sequence, other.status
        self.stale, self.saturated = other.stale, other.saturated


class Device(abc.ABC):
    """Base of every device: context manager, idempotent ``close()``."""

    _closed: bool = False

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the device; safe to call more than once."""
        if not self._closed:
            self._closed = True
            bump()                    # the fused cycle's plan read this device (``rt.epoch``)
            self._close()

    @property
    def closed(self) -> bool:
        return self._closed

    def _check_open(self) -> None:
        if self._closed:
            raise HardwareError(f"{type(self).__name__} is closed; open a new one")

    @abc.abstractmethod
    def _close(self) -> None:
        """Backend-specific release."""


def replaced(device: object, *names: str) -> bool:
    """Whether one of the methods ``names`` was replaced on this instance (a wrapper, a test's
    injected fault): the ``compiled_*`` hooks then answer None, because a compiled caller
    reading the device's memory would no longer do what the method does; the block calls
    the method instead. (An instance's own attributes live in its ``__dict__``; methods do
    not, unless assigned there.)"""
    d = vars(device)
    return any(n in d for n in names)


class WatchReplaced:
    """Mixin: assigning or deleting one of the instance's ``REPLACEABLE`` names (a method
    replaced on the instance: a wrapper, a test's injected fault, :func:`replaced`) bumps the
    process's epoch (``rt.epoch``), so the fused cycle's fast path, which compiled what the
    method does, sees it at its next cycle without asking :func:`replaced` every cycle.

    Only for devices whose cycle writes no attribute (every other attribute assignment pays
    this Python ``__setattr__`` too, ≈ 0.2 µs)."""

    #: The method names whose replacement on an instance matters (the backend's reads/writes).
    REPLACEABLE: frozenset[str] = frozenset()

    def __setattr__(self, name: str, value: Any) -> None:
        object.__setattr__(self, name, value)
        if name in self.REPLACEABLE:
            bump()

    def __delattr__(self, name: str) -> None:
        object.__delattr__(self, name)
        if name in self.REPLACEABLE:
            bump()


class EncoderBank(Device):
    """Incremental encoders of the three sliders.

    ``read_positions_m(out)`` fills ``out`` (len 3) with slider positions in metres relative to
    the position at the last ``reset()``; ``read_counts()`` gives the raw counter values.
    """

    n_axes: int = 3

    @abc.abstractmethod
    def read_counts(self) -> tuple[int, ...]:
        """Raw counter values, one per axis."""

    @abc.abstractmethod
    def read_positions_m(self, out: np.ndarray) -> np.ndarray:
        """Decoded positions (m) written into ``out`` and returned."""

    @abc.abstractmethod
    def reset(self) -> None:
        """Set every counter to its reference value (the PCL-833 midpoint)."""

    def compiled_read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any] | None:
        """When this cycle's :meth:`read_positions_m` is memory a compiled caller can read
        itself (the twin's emulated PCL-833): the card's state, the driver's ports, its read
        state and decode constants (``rt.drivers.kernels.fake_pcl833_read`` then
        ``pcl833_decode``) and the port (its read count is the caller's to advance); else
        None (the default: call :meth:`read_positions_m`, e.g. the rig's ``/dev/port``)."""
        return None


class ActuatorOutputs(Device):
    """Analog command outputs (V) to the current-mode amplifiers, with drive enable.

    A card refuses ``write_volts`` with non-zero values while disabled. ``disable()`` writes
    zero volts first.
    """

    n_channels: int = 3

    @abc.abstractmethod
    def enable(self) -> None: ...

    @abc.abstractmethod
    def disable(self) -> None: ...

    @property
    @abc.abstractmethod
    def enabled(self) -> bool: ...

    @abc.abstractmethod
    def write_volts(self, volts: Sequence[float] | np.ndarray) -> None:
        """Command one voltage (V) per channel."""

    def compiled_write(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
        """The arguments of ``rt.drivers.kernels.pci1720_write_fake`` after the command when
        this card's write can run inside a caller's compiled call (the twin's PCI-1720 on the
        compiled comedilib double), else None (the default: call :meth:`write_volts`)."""
        return None

    def finish_compiled_write(self, volts: np.ndarray, rc: int, done: int) -> None:
        """What :meth:`write_volts` does after the compiled write answered (``rc``, ``done``):
        only cards whose :meth:`compiled_write` is not None are asked."""
        raise NotImplementedError(f"{type(self).__name__} has no compiled write")


class ForceTorqueSensor(Device):
    """A 6-axis force/torque sensor (the ATI reference)."""

    @abc.abstractmethod
    def start(self) -> None:
        """Start streaming."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop streaming."""

    @abc.abstractmethod
    def bias(self) -> None:
        """Zero the sensor at the current load (software bias)."""

    @abc.abstractmethod
    def read(self, out: Wrench) -> Wrench:
        """Latest wrench written into ``out`` (stale flag set if none arrived in time)."""

    def compiled_sample(self) -> tuple[np.ndarray, np.ndarray, float] | None:
        """When this cycle's :meth:`read_array` is a polled sample in memory (the twin's ATI,
        no fault): the sample (float64[8]: the wrench, its counter and status word, exact
        floats: the memory the device writes, read by the compiled caller, so no scalar of
        it passes through Python), this sensor's polled state and the sample's time, for
        ``rt.devices.sampled_ft._read_sample`` in a compiled caller; else None (the default:
        call :meth:`read_array`; a receiver thread or a driver keeps it so)."""
        return None

    def read_array(self, out: np.ndarray) -> np.ndarray:
        """:meth:`read` into a float64[``FT_READ_SIZE``] array (layout ``FT_*``: fx..tz, t,
        sequence, status, stale, saturated as 0/1), the loop's per-cycle form; as
        :meth:`read`, a reading without a fresh sample changes only the stale flag. This
        default goes through a ``Wrench``; a sensor that can fill the array directly (the
        polled ones, one compiled call) overrides it with the same values."""
        w = self._read_array_wrench
        if w is None:
            w = self._read_array_wrench = Wrench()
        self.read(w)
        out[0], out[1], out[2], out[3], out[4], out[5] = w.fx, w.fy, w.fz, w.tx, w.ty, w.tz
        out[FT_T], out[FT_SEQUENCE], out[FT_STATUS] = w.t, w.sequence, w.status
        out[FT_STALE] = 1.0 if w.stale else 0.0
        out[FT_SATURATED] = 1.0 if w.saturated else 0.0
        return out

    _read_array_wrench: Wrench | None = None


#: Layout of :meth:`ForceTorqueSensor.read_array`'s array: the wrench (6), then these.
FT_T, FT_SEQUENCE, FT_STATUS, FT_STALE, FT_SATURATED, FT_READ_SIZE = 6, 7, 8, 9, 10, 11


def new_ft_reading() -> np.ndarray:
    """A :meth:`ForceTorqueSensor.read_array` buffer as a new ``Wrench``: NaN, no sequence,
    stale."""
    out = np.full(FT_READ_SIZE, NAN)
    out[FT_SEQUENCE], out[FT_STATUS], out[FT_STALE], out[FT_SATURATED] = -1.0, 0.0, 1.0, 0.0
    return out


class ForcePlate(Device):
    """A force plate's raw channels (V or counts as the backend documents); calibration maps them."""

    n_channels: int = 8

    @abc.abstractmethod
    def read_channels(self, out: np.ndarray) -> np.ndarray:
        """Raw channel values written into ``out`` and returned."""


class Camera(Device):
    """A camera giving BGR frames (uint8, H x W x 3)."""

    @abc.abstractmethod
    def read(self) -> tuple[np.ndarray, float]:
        """The next frame and its host timestamp (s); raises ``HardwareError`` on failure."""


@dataclass(slots=True)
class DigitalInputState:
    """Safety-relevant digital inputs; True means the stop is pressed (fail-safe: open contact)."""

    hardware_estop: bool = False
    hand_stop: bool = False
    extra: dict[str, bool] = field(default_factory=dict)


class DigitalInputs(Device):
    """Digital inputs: hardware e-stop chain and the patient's hand-held stop."""

    @abc.abstractmethod
    def read(self, out: DigitalInputState) -> DigitalInputState: ...

    def compiled_levels(self) -> tuple[float, float] | None:
        """When this cycle's levels are memory (the twin's inputs): [hardware e-stop,
        hand-held stop] as 0/1 for a compiled caller to write; else None (the default: call
        :meth:`read_array`, e.g. the rig's comedi DIO)."""
        return None

    def read_array(self, out: np.ndarray) -> np.ndarray:
        """[hardware e-stop, hand-held stop] as 0/1 into ``out`` (float64[2]), the loop's
        per-cycle form of :meth:`read`; a backend holding the levels directly overrides it."""
        s = self._read_array_state
        if s is None:
            s = self._read_array_state = DigitalInputState()
        self.read(s)
        out[0] = 1.0 if s.hardware_estop else 0.0
        out[1] = 1.0 if s.hand_stop else 0.0
        return out

    _read_array_state: DigitalInputState | None = None
