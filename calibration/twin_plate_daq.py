"""The twin plate behind a real DAQ path: the RT process's twin → a wire → a comedi double.

On the rig the plate's amplifier drives the DAQ card the client reads
(:mod:`calibration.plate_daq`). On the twin the load the plate feels is the RT process's twin's
true contact, which only the RT process has. So that the client runs the rig's code path down
to ``comedi_data_read`` (``--plate-daq twin``):

* the ``calibration_push`` program, given ``twin_contact_shm``, publishes the twin's contact
  (loop time, the environment's wrench on the platform at S in S's axes, slider positions)
  every cycle it plays into a small shared-memory block — the *wire* (:class:`ContactWire`,
  created and owned by the client; a seqlock as the rig segment's, :mod:`rt.twin.shm`);
* :class:`TwinPlateSignal` turns the wire's latest contact into the twin plate's channel volts
  (:class:`calibration.twin_plate.TwinPlate`: sensitivity, crosstalk, origin offset, bending,
  nonlinearity, hysteresis, noise, drift) at the plate's clock, for the plate's pose the
  operator's (simulated) move gave;
* :class:`TwinPlateCard` is a comedilib double of a 16-bit analog-input card
  (:class:`rt.drivers.fake_comedi_ai.FakeComediAnalogInput`: codes over ±10 / ±5 V) whose inputs
  are those volts, read by the real :class:`rt.drivers.comedi_plate.ComediForcePlate` driver:
  the card's 16-bit quantization is the twin plate's DAQ quantization.

The plate's clock: ``clock_offset_s + (1 + drift) (monotonic − epoch)``, the twin truth's
offset and drift on the host's monotonic clock, while the robot's rows are on the RT loop's
clock; the fit finds the relation by cross-correlation (the point of this path).
Twin figures only: the twin plate's signal reaches the card with the wire's latency (the
client thread's scheduling), the way a real DAQ samples a continuous signal asynchronously.
"""
from __future__ import annotations

import mmap
import os
import time
import uuid
from collections.abc import Callable
from multiprocessing import shared_memory

import numpy as np

from calibration.plate import PlateDescription
from calibration.twin_plate import TwinPlate
from rt.drivers.fake_comedi_ai import FakeComediAnalogInput
from rt.errors import ConfigurationError, HardwareError, InputError
from rt.twin.shm import FieldSpec, SeqlockBlock, check_shm_name

#: The wire's block: offsets include the 8-byte sequence word at +0.
WIRE_FIELDS: tuple[FieldSpec, ...] = (
    ("t", 8, np.float64, 1),             # RT loop time of the cycle (s)
    ("wrench", 16, np.float64, 6),       # environment on the platform at S, axes of S (N, N·m)
    ("q", 64, np.float64, 3),            # slider positions (m)
    ("count", 88, np.uint64, 1),         # cycles published (0: nothing yet)
    ("writer_pid", 96, np.int64, 1),
)
WIRE_SIZE = 128
#: The double's device file (never opened: the double answers comedi_open itself).
TWIN_DEVICE = "/dev/comedi-twin-plate"


class ContactWire:
    """The client's end: creates the block ``talus-plate-<pid>-<hex>``, reads it, unlinks it
    on :meth:`close` (safe twice)."""

    def __init__(self) -> None:
        self.name = f"talus-plate-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        self._shm: shared_memory.SharedMemory | None = shared_memory.SharedMemory(
            name=self.name, create=True, size=WIRE_SIZE)
        assert self._shm.buf is not None
        self._shm.buf[:WIRE_SIZE] = bytes(WIRE_SIZE)
        self.block: SeqlockBlock | None = SeqlockBlock(self._shm.buf, 0, WIRE_SIZE,
                                                       WIRE_FIELDS)

    def read(self) -> bool:
        """Refresh ``block.local`` from the RT process's last publication."""
        if self.block is None:
            raise HardwareError("the twin plate's wire is closed")
        return self.block.read()

    def close(self) -> None:
        if self.block is not None:
            self.block.release()
            self.block = None
        if self._shm is not None:
            self._shm.close()
            self._shm.unlink()
            self._shm = None


class WirePublisher:
    """The RT process's end: maps the client's block (without Python's resource tracker, which
    would unlink the client's segment when the RT process exits) and publishes one contact per
    call, allocation-free."""

    def __init__(self, name: str) -> None:
        check_shm_name(name)
        try:
            fd = os.open(f"/dev/shm/{name}", os.O_RDWR)
        except FileNotFoundError:
            raise InputError(f"twin_contact_shm {name!r}: no such shared memory (the "
                             "client creates it before the request)") from None
        try:
            if os.fstat(fd).st_size < WIRE_SIZE:
                raise InputError(f"twin_contact_shm {name!r} is too small to be a plate wire")
            self._mmap: mmap.mmap | None = mmap.mmap(fd, WIRE_SIZE)
        finally:
            os.close(fd)
        self._buf: memoryview | None = memoryview(self._mmap)
        self.block: SeqlockBlock | None = SeqlockBlock(self._buf, 0, WIRE_SIZE, WIRE_FIELDS)
        self.block.local.writer_pid[0] = os.getpid()
        # Counting on from the last trial's publications: the reader recomputes on a change.
        self._count = int(self.block.shared.count[0])

    def publish(self, t: float, wrench: np.ndarray, q: np.ndarray) -> None:
        block = self.block
        if block is None:
            return
        local = block.local
        local.t[0] = t
        local.wrench[:] = wrench
        local.q[:] = q
        self._count += 1
        local.count[0] = self._count
        block.publish()

    def close(self) -> None:
        if self.block is not None:
            self.block.release()
            self.block = None
        if self._buf is not None:
            self._buf.release()
            self._buf = None
        if self._mmap is not None:
            self._mmap.close()
            self._mmap = None


class TwinPlateSignal:
    """The twin plate's channel volts from the wire's latest contact (module docstring).

    ``volts(k)`` is plate channel ``k``'s value; a scan (channel 0) reads the wire once and
    computes every channel, so the channels of one scan see one load.
    """

    def __init__(self, plate: PlateDescription, twin_plate: TwinPlate, model: object,
                 wire: ContactWire, clock: Callable[[], float], tool_length_m: float) -> None:
        self.plate = plate
        self.twin_plate = twin_plate
        self.model = model
        self.wire = wire
        self.clock = clock
        self.tool_length_m = tool_length_m
        self.T_BF: np.ndarray | None = None
        self._s_offset = np.array(model.description.sensor.offset_m)  # type: ignore[attr-defined]
        self._volts = np.zeros(plate.n_channels)
        self._play = np.full(plate.n_channels, np.nan)
        self._last_count = -1
        self._force_F = np.zeros((1, 3))
        self._point_F = np.zeros((1, 3))

    def place(self, T_BF: np.ndarray) -> None:
        """Where the plate truly is (the operator's move, simulated), in the robot base."""
        self.T_BF = np.array(T_BF, dtype=float)

    def _load(self) -> None:
        w = self.wire.block
        if w is None or not self.wire.read() or self.T_BF is None:
            return
        count = int(w.local.count[0])
        if count == self._last_count:
            return
        self._last_count = count
        if count == 0:
            self._force_F[:] = 0.0
            return
        q = np.array(w.local.q, dtype=float)
        cfg = self.model.kin.fk(q, check=False)  # type: ignore[attr-defined]
        R = np.array(cfg.rotation).reshape(3, 3)
        tip_B = np.array([cfg.x, cfg.y, cfg.z]) + R @ self._s_offset + self.tool_length_m * R[:, 2]
        R_FB = self.T_BF[:3, :3].T
        # The load on the plate is minus the environment's wrench on the platform.
        self._force_F[0] = R_FB @ (-(R @ np.array(w.local.wrench[:3], dtype=float)))
        self._point_F[0] = R_FB @ (tip_B - self.T_BF[:3, 3])
        self._point_F[0, 2] = 0.0         # the tip presses on the surface

    def scan(self) -> None:
        self._load()
        t = np.array([self.clock()])
        self._volts[:] = self.twin_plate.channels(self._force_F, self._point_F, t,
                                                  quantized=False, play_state=self._play)[0]

    def volts(self, k: int) -> float:
        if k == 0:
            self.scan()
        return float(self._volts[k])


class TwinPlateCard(FakeComediAnalogInput):
    """A 16-bit AI card whose input ``k`` carries plate channel ``k`` (no read log: a campaign
    reads millions of samples)."""

    def __init__(self, signal: TwinPlateSignal) -> None:
        super().__init__()
        self.signal = signal

    def comedi_data_read(self, handle, subdevice, channel, rng, aref, data_ptr) -> int:
        import ctypes
        import math

        if self.fail_reads or subdevice != 0:
            self._errno = 5
            return -1
        lo, hi = self.RANGES[rng]
        v = self.signal.volts(channel) if channel < self.signal.plate.n_channels else 0.0
        code = max(0, min(self.MAXDATA, math.floor((v - lo) / (hi - lo) * self.MAXDATA + 0.5)))
        ctypes.cast(data_ptr, ctypes.POINTER(ctypes.c_uint))[0] = code
        return 1


def card_range_index(plate: PlateDescription) -> int:
    """The narrowest range of the 16-bit double covering every channel's ± range."""
    need = float(plate.channel_ranges().max())
    fits = [(hi - lo, k) for k, (lo, hi) in enumerate(FakeComediAnalogInput.RANGES)
            if -lo >= need and hi >= need]
    if not fits:
        raise ConfigurationError(f"the twin plate DAQ's ranges do not cover ±{need:g} "
                                 f"{plate.channels[0].unit}")
    return min(fits)[1]


class TwinPlateDaq:
    """The twin plate's DAQ as the client sees it: ``device`` (the real ``ComediForcePlate``
    driver over :class:`TwinPlateCard`), ``clock`` (the plate's clock), ``wire_name`` (sent to
    the RT process as ``twin_contact_shm``), :meth:`place` (the plate's true pose)."""

    def __init__(self, plate: PlateDescription, twin_plate: TwinPlate, model: object,
                 tool_length_m: float, monotonic: Callable[[], float] = time.monotonic
                 ) -> None:
        from rt.drivers.comedi_plate import ComediForcePlate

        epoch = monotonic()
        self.clock: Callable[[], float] = lambda: float(
            twin_plate.plate_time(monotonic() - epoch))
        self.wire = ContactWire()
        try:
            self.signal = TwinPlateSignal(plate, twin_plate, model, self.wire, self.clock,
                                          tool_length_m)
            self.card = TwinPlateCard(self.signal)
            self.device = ComediForcePlate(TWIN_DEVICE, 0, tuple(range(plate.n_channels)),
                                           card_range_index(plate), lib=self.card)
        except BaseException:
            self.wire.close()
            raise

    @property
    def wire_name(self) -> str:
        return self.wire.name

    def place(self, T_BF: np.ndarray) -> None:
        self.signal.place(T_BF)

    def close(self) -> None:
        try:
            self.device.close()
        finally:
            self.wire.close()
