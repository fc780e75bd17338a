"""A force plate's DAQ acquired by the calibration client while the RT process pushes.

On the rig the plate's amplifier drives an analog-input card that the RT process does not own:
the client (``talus calibrate run|verify --backend rt --plate-daq FILE``) reads it through a
:class:`rt.devices.interfaces.ForcePlate` (``rt.drivers.comedi_plate.ComediForcePlate``: one
``comedi_data_read`` per channel, codes → volts) from a thread of its own
(:class:`PlateAcquisition`), at the plate's sample rate, and stamps every scan with the host's
monotonic clock. That clock is the *plate's* clock as far as the fit is concerned: its relation
to the RT loop's clock (offset and drift) is found afterwards from the data by cross-correlation
(:mod:`calibration.alignment`), never assumed, exactly as for a DAQ with its own oscillator.

Software timing: scan k is due at ``k / fs`` after the start; a late scan is taken at once and
stamped when it was read (the stamps, not the nominal instants, are written), a scan more than
:data:`LATE_PERIODS` periods late re-phases the schedule (no burst of catch-up reads) and is
counted in ``late_scans``. The fit interpolates the plate's samples at the robot's instants, so
an irregular scan only costs resolution in time, never a wrong time stamp.

The DAQ file (YAML, ``schema_version: 1``; :class:`DaqConfig`) names the backend and its
wiring; ``backend: twin`` is the digital twin's plate behind the same driver
(:mod:`calibration.twin_plate_daq`)::

    schema_version: 1
    backend: comedi            # rt.devices.registry "force_plate" backends, or twin
    device: /dev/comedi1
    subdevice: 0
    channels: [0, 1, 2, 3, 4, 5]   # one AI input per plate channel, in the plate file's order
    range_index: 0                 # a range covering the channels' ± range (V)
    aref: differential             # or ground
"""
from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from calibration import yaml_files
from rt.devices.interfaces import ForcePlate
from rt.errors import ConfigurationError, HardwareError, InputError

#: A scan later than this many periods re-phases the schedule (and counts as late).
LATE_PERIODS = 2.0
#: How long ``stop`` waits for the acquisition thread to finish its scan (s).
JOIN_TIMEOUT_S = 2.0


class DaqConfig(BaseModel):
    """A plate DAQ's wiring (module docstring)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    schema_version: Literal[1]
    backend: str = Field(min_length=1)
    device: str = "/dev/comedi1"
    subdevice: Annotated[int, Field(ge=0)] = 0
    channels: list[Annotated[int, Field(ge=0)]] | None = None
    range_index: Annotated[int, Field(ge=0)] = 0
    aref: Literal["differential", "ground"] = "differential"


def load_daq_config(path: str | Path) -> DaqConfig:
    return yaml_files.load(DaqConfig, Path(path))


def open_plate_device(cfg: DaqConfig, n_channels: int) -> ForcePlate:
    """The real plate DAQ of ``cfg`` (not ``twin``: :mod:`calibration.twin_plate_daq`)."""
    from rt.devices import registry
    from rt.drivers.comedi_plate import AREF_DIFF, AREF_GROUND

    channels = cfg.channels if cfg.channels is not None else list(range(n_channels))
    if len(channels) != n_channels:
        raise ConfigurationError(f"plate DAQ: {len(channels)} AI channels wired for a plate of "
                                 f"{n_channels} channels (channels: one per plate channel)")
    device: ForcePlate = registry.create(
        "force_plate", cfg.backend, device=cfg.device, subdevice=cfg.subdevice,
        channels=channels, range_index=cfg.range_index,
        aref=AREF_DIFF if cfg.aref == "differential" else AREF_GROUND)
    return device


class PlateAcquisition:
    """Scans ``device`` at ``sample_rate_hz`` on a thread, stamped by ``clock`` (s).

    ``start(duration_s)`` preallocates room for ``duration_s`` of scans and starts the thread;
    ``stop()`` ends it and returns ``(t, channels)`` of the scans taken, or raises
    ``HardwareError`` when the device failed, the amplifier clipped (``saturated``) or the
    buffer filled. One acquisition at a time; the device stays open (the caller owns it).
    """

    def __init__(self, device: ForcePlate, n_channels: int, sample_rate_hz: float,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if not (math.isfinite(sample_rate_hz) and 0.0 < sample_rate_hz <= 20_000.0):
            raise ConfigurationError(f"plate sample rate {sample_rate_hz} Hz: software-timed "
                                     "acquisition runs at 0-20 kHz")
        self.device = device
        self.n_channels = int(n_channels)
        self.period_s = 1.0 / sample_rate_hz
        self.clock = clock
        self.sleep = sleep
        self.late_scans = 0
        self.saturated_scans = 0
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._t = np.zeros(0)
        self._v = np.zeros((0, self.n_channels))
        self._n = 0
        self._error: BaseException | None = None

    @property
    def running(self) -> bool:
        return self._thread is not None

    def start(self, duration_s: float) -> None:
        if self._thread is not None:
            raise InputError("plate acquisition already running")
        if not (math.isfinite(duration_s) and duration_s > 0.0):
            raise InputError(f"plate acquisition: duration {duration_s} s must be positive")
        capacity = math.ceil(duration_s / self.period_s) + 16
        self._t = np.zeros(capacity)
        self._v = np.zeros((capacity, self.n_channels))
        self._n = 0
        self._error = None
        self.late_scans = self.saturated_scans = 0
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="plate-daq", daemon=True)
        self._thread.start()

    def stop(self) -> tuple[np.ndarray, np.ndarray]:
        thread = self._thread
        if thread is None:
            raise InputError("plate acquisition is not running")
        self._stop.set()
        thread.join(JOIN_TIMEOUT_S)
        self._thread = None
        if thread.is_alive():
            raise HardwareError("the plate DAQ did not finish its scan within "
                                f"{JOIN_TIMEOUT_S:.0f} s (a hung read?)")
        if self._error is not None:
            raise HardwareError(f"plate DAQ: {self._error}") from self._error
        if self.saturated_scans:
            raise HardwareError(f"plate DAQ: {self.saturated_scans} scans at the end of the "
                                "input range (the plate's amplifier or the DAQ range clipped); "
                                "lower the load or widen the range")
        if self._n >= len(self._t):
            raise HardwareError(f"plate DAQ: the recording filled its {len(self._t)} scans "
                                "before the trial ended")
        return self._t[:self._n].copy(), self._v[:self._n].copy()

    def _run(self) -> None:
        device, clock, sleep, period = self.device, self.clock, self.sleep, self.period_s
        t_buf, v_buf = self._t, self._v
        capacity = len(t_buf)
        try:
            next_due = clock()
            while not self._stop.is_set() and self._n < capacity:
                now = clock()
                if next_due - now > 0.0:
                    sleep(next_due - now)
                elif now - next_due > LATE_PERIODS * period:
                    self.late_scans += 1
                    next_due = now
                t0 = clock()
                device.read_channels(v_buf[self._n])
                # Stamped mid-scan: the channels are read one after the other.
                t_buf[self._n] = 0.5 * (t0 + clock())
                if getattr(device, "saturated", False):
                    self.saturated_scans += 1
                self._n += 1
                next_due += period
        except Exception as exc:  # noqa: BLE001 - reported by stop(), in the caller's thread
            self._error = exc
