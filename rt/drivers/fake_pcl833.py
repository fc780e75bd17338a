"""Register-level emulation of the PCL-833 encoder card, behind the ``PortIO`` interface.

Tests and the digital twin hand a ``FakePcl833Port`` to ``Pcl833Encoders`` instead of
``DevPortIO``, so the real driver (configuration writes, latch, byte reads, midpoint reset,
decoding) runs unchanged. The register map and the assumptions about latch and reset are
those documented in ``rt.drivers.pcl833``:

* reading a channel's high byte (+2/+6/+10) latches the live counter when that channel's
  latch source is "software read"; the low and middle bytes then return the latched value;
* the counter-reset register (+7) is a level: while a channel's bit is set the counter is
  held at its reset value (0, or 0x800000 with the mode register's "middle" bit) and drops
  pulses. A driver that forgets to release the reset therefore reads a frozen counter here.
  (If the real register is a strobe, a driver that releases it behaves the same on both.)
* a channel counts only when its input mode is not "disable". Counts are in counter units,
  after the card's x1/x2/x4 multiplication; the emulation does not model A/B edges.
* overflow (+3/+7/+11) and status (+14) registers read 0: not emulated, not used.

The simulation side, used by tests and the twin (axis i is card channel i+1, the thesis
wiring):

* ``set_position_m(axis, q)`` / ``set_positions_m(q)``: the encoder model. The slider is at
  ``q`` metres; the encoder has moved ``round(sign * q / m_per_count)`` counts from q = 0,
  and the change since the previous call is fed to the counter as pulses (dropped while the
  channel is disabled, held in reset or frozen). After the driver's midpoint reset at
  q = q0 the driver therefore reads ``q - q0``, as on the real rig.
* ``set_count(axis, count)``: a back door that presets the live counter (mod 2**24); with
  ``rt.drivers.pcl833.encode_position`` it places an absolute position directly.
* ``move_counts(axis, delta)``: ``delta`` pulses through the input stage.
* ``set_frozen(axis, True)``: fault injection, the counter stops (encoder freeze); a jump is
  ``move_counts`` with a large delta.

Not thread-safe: drive it from the loop's thread (the twin runs in lockstep).
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from rt.drivers import kernels
from rt.drivers.pcl833 import (
    COUNTER_MASK,
    DEFAULT_BASE,
    DEFAULT_M_PER_COUNT,
    LATCH_SOURCE_MASK,
    LATCH_SOURCE_SOFTWARE_READ,
    PORT_SPAN,
    REG_COUNTER_RESET,
    REG_STATUS,
    InputMode,
    reset_value,
)
from rt.drivers.port_io import PortIO
from rt.errors import ConfigurationError, HardwareError

#: Offsets that the card answers on when read / written (from the Advantech driver).
_READABLE = frozenset(range(12)) | {REG_STATUS}
_WRITABLE = frozenset(range(11))


def _per_axis(value: float | Sequence[float], name: str) -> list:
    if not isinstance(value, Iterable):                  # one value for every axis
        return [value] * 3
    values = list(value)
    if len(values) != 3:
        raise ConfigurationError(f"{name} needs 3 values (one per axis), got {len(values)}")
    return values


class FakePcl833Port(PortIO):
    """A PCL-833 at ``base`` (default 0x220), emulated byte by byte.

    ``m_per_count`` and ``sign`` (one value or one per axis) are the encoder model used by
    ``set_position_m``; give the driver the same values. ``strict`` makes an access to a port
    the card does not decode raise ``HardwareError`` (a driver bug) instead of reading 0xFF
    like an empty ISA bus.

    ``writes`` records every ``outb`` as ``(port, value)``; ``n_reads`` counts ``inb`` calls.
    At power-up every register is 0: inputs disabled, counters at 0.
    """

    def __init__(self, base: int = DEFAULT_BASE,
                 m_per_count: float | Sequence[float] = DEFAULT_M_PER_COUNT,
                 sign: int | Sequence[int] = +1, strict: bool = True) -> None:
        # The card's state in one int64 array, so a block of reads (``read_block``) and the
        # encoders' motion (``set_positions_m``) are one compiled call each
        # (``rt.drivers.kernels``); the views below are the same numbers by name.
        self._st = np.zeros(kernels.FAKE_SIZE, dtype=np.int64)
        st = self._st
        self.base = base
        self.m_per_count = [float(m) for m in _per_axis(m_per_count, "m_per_count")]
        self.sign = [int(s) for s in _per_axis(sign, "sign")]
        self.strict = strict
        self.writes: list[tuple[int, int]] = []
        self.n_reads = 0
        self._reg = st[kernels.FAKE_REG:kernels.FAKE_REG + PORT_SPAN]   # last byte written
        self._count = st[kernels.FAKE_COUNT:kernels.FAKE_COUNT + 3]      # live counters
        self._latched = st[kernels.FAKE_LATCHED:kernels.FAKE_LATCHED + 3]   # what bytes read
        self._encoder_index = st[kernels.FAKE_INDEX:kernels.FAKE_INDEX + 3]  # counts from q=0
        self._frozen = st[kernels.FAKE_FROZEN:kernels.FAKE_FROZEN + 3]
        self._sign_mpc = np.array([*self.sign, *self.m_per_count], dtype=np.float64)
        # Compile (or load from numba's cache) now, not in a cycle: on a scratch state.
        scratch, three = st.copy(), np.zeros(3, dtype=np.int64)
        kernels.fake_pcl833_read(scratch, np.array([base + 2], dtype=np.int64), three)
        kernels.fake_pcl833_move(scratch, np.zeros(3))
        kernels.fake_pcl833_positions(scratch, self._sign_mpc, np.zeros(3))
        kernels.fake_pcl833_set_counts(scratch, np.zeros(3, dtype=np.uint64), three)

    @property
    def base(self) -> int:
        """The card's base port (its DIP switches)."""
        return int(self._st[kernels.FAKE_BASE])

    @base.setter
    def base(self, value: int) -> None:
        self._st[kernels.FAKE_BASE] = value

    @property
    def strict(self) -> bool:
        """An access to a port the card does not decode raises ``HardwareError``."""
        return bool(self._st[kernels.FAKE_STRICT])

    @strict.setter
    def strict(self, value: bool) -> None:
        self._st[kernels.FAKE_STRICT] = 1 if value else 0

    # --- PortIO ----------------------------------------------------------------------------

    def inb(self, port: int) -> int:
        self._check_open()
        self.n_reads += 1
        offset = port - self.base
        if 0 <= offset < 12 and offset % 4 != 3:
            # Fast path for the count bytes (the twin reads nine of them every cycle).
            channel, byte = divmod(offset, 4)
            if byte == 2 and (self._reg[3 + channel] & LATCH_SOURCE_MASK) == LATCH_SOURCE_SOFTWARE_READ:
                self._latched[channel] = self._count[channel]
            return (int(self._latched[channel]) >> (8 * byte)) & 0xFF
        register = self._offset(port, _READABLE)
        if register is None:
            return 0xFF
        if register == REG_STATUS or register % 4 == 3:
            return 0
        channel, byte = divmod(register, 4)
        if byte == 2 and (self._reg[3 + channel] & LATCH_SOURCE_MASK) == LATCH_SOURCE_SOFTWARE_READ:
            self._latched[channel] = self._count[channel]
        return (int(self._latched[channel]) >> (8 * byte)) & 0xFF

    def read_block(self, ports: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``inb`` of each of ``ports`` (int64) in order into ``out`` (int64), as one
        compiled call (``rt.drivers.kernels.fake_pcl833_read``); the same bytes, latches,
        ``n_reads`` and refusal as ``inb`` one port at a time."""
        self._check_open()
        bad = kernels.fake_pcl833_read(self._st, ports, out)
        if bad >= 0:
            self.n_reads += bad + 1
            raise HardwareError(f"port 0x{int(ports[bad]):X} is not a PCL-833 register at "
                                f"base 0x{self.base:X}")
        self.n_reads += ports.shape[0]
        return out

    def compiled_block_state(self) -> np.ndarray | None:
        """The card's state for a compiled block read (:meth:`read_block`'s kernel); None
        once closed, or for a subclass with its own ``read_block``/``inb``."""
        if self._closed or type(self).read_block is not FakePcl833Port.read_block \
                or type(self).inb is not FakePcl833Port.inb:
            return None
        return self._st

    def outb(self, port: int, value: int) -> None:
        self._check_open()
        if not 0 <= value <= 0xFF:
            raise HardwareError(f"outb(0x{port:X}, {value}): value is not a byte")
        offset = self._offset(port, _WRITABLE)
        self.writes.append((port, value))
        if offset is None:
            return
        self._reg[offset] = value
        self._apply_reset_hold()

    def _offset(self, port: int, valid: frozenset[int]) -> int | None:
        offset = port - self.base
        if offset in valid:
            return offset
        if self.strict:
            raise HardwareError(
                f"port 0x{port:X} is not a PCL-833 register at base 0x{self.base:X}")
        return None

    def _close(self) -> None:
        pass

    # --- card behaviour --------------------------------------------------------------------

    def _held(self, axis: int) -> bool:
        return bool(self._reg[REG_COUNTER_RESET] & (1 << axis))

    def _counting(self, axis: int) -> bool:
        mode = int(self._reg[axis]) & 0x07
        return mode != InputMode.DISABLE and not self._held(axis) and not self._frozen[axis]

    def _apply_reset_hold(self) -> None:
        for axis in range(3):
            if self._held(axis):
                self._count[axis] = reset_value(int(self._reg[axis]))

    # --- simulation side -------------------------------------------------------------------

    def count(self, axis: int) -> int:
        """Live counter of ``axis`` (0-2, card channel axis+1), without latching."""
        return int(self._count[axis])

    def register(self, offset: int) -> int:
        """Last byte the driver wrote to write-register ``offset`` (0 if never written)."""
        return int(self._reg[offset])

    def set_count(self, axis: int, count: int) -> None:
        """Preset the live counter of ``axis`` to ``count`` (mod 2**24); a reset hold wins."""
        self._count[axis] = count & COUNTER_MASK
        self._apply_reset_hold()

    def set_counts(self, counts: np.ndarray, offsets: np.ndarray) -> None:
        """``set_count`` of every axis to ``counts + offsets`` (int arrays; e.g. the rig's
        counters read over shared memory and a reader's reset offsets), in one compiled call."""
        kernels.fake_pcl833_set_counts(self._st, counts, offsets)

    def move_counts(self, axis: int, delta: int) -> None:
        """Feed ``delta`` counts (signed) to ``axis``'s counter, wrapping modulo 2**24.

        Dropped while the channel is disabled, held in reset or frozen, as pulses would be.
        """
        if delta and self._counting(axis):
            self._count[axis] = (self._count[axis] + delta) & COUNTER_MASK

    def set_position_m(self, axis: int, position_m: float) -> None:
        """Move ``axis``'s encoder to slider position ``position_m`` (m, 0 at the stroke bottom).

        The encoder position is quantized to the nearest count; the change since the last
        call goes to the counter as pulses.
        """
        index = math.floor(self.sign[axis] * position_m / self.m_per_count[axis] + 0.5)
        delta = index - int(self._encoder_index[axis])
        self._encoder_index[axis] = index
        self.move_counts(axis, delta)

    def set_positions_m(self, positions_m: Sequence[float] | np.ndarray) -> None:
        """``set_position_m`` for the three axes (one compiled call: the twin calls it every
        period; ``rt.drivers.kernels.fake_pcl833_positions``)."""
        if not isinstance(positions_m, np.ndarray) or positions_m.dtype != np.float64:
            positions_m = np.asarray(positions_m, dtype=np.float64)
        bad = kernels.fake_pcl833_positions(self._st, self._sign_mpc, positions_m)
        if bad >= 0:        # what math.floor said of it, one axis at a time
            raise ValueError(f"cannot convert float {positions_m[bad]} to integer")

    def move_to_indices(self, indices: np.ndarray) -> None:
        """The encoders at ``indices`` (float64[3] holding integers, counts from q = 0, as the
        twin's fused period computes them): each change goes to the counter as pulses."""
        kernels.fake_pcl833_move(self._st, indices)

    def set_frozen(self, axis: int, frozen: bool = True) -> None:
        """Fault injection: a frozen channel ignores all motion until unfrozen."""
        self._frozen[axis] = 1 if frozen else 0
