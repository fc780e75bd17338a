"""Advantech PCL-833 3-axis quadrature encoder card (ISA, thesis 3.1.3 and 3.2.2).

Pure helpers (``decode_counts``, ``encode_position``, ``CountUnwrapper``) turn 24-bit counter
values into slider positions and back; the digital twin uses the same helpers so the real
decoding path runs against simulated sliders. ``Pcl833Encoders`` is the ``EncoderBank``
backend that talks to the card through a ``PortIO``.

Sources, and what came from which:

* Thesis 3.2.2 (the rig's own driver): base address 0x220 set on the card's DIP switches;
  per channel ``SetInputMode(x1)``, ``DefineResetValue(middle)``, ``SetCascadeMode(c24bits)``;
  a read gives three bytes ``InReg[2]*65536 + InReg[1]*256 + InReg[0]``; the midpoint
  8388608 is subtracted and the result multiplied by 0.02/1000 = 2e-5 m per count. The
  midpoint reset is there so the counter can neither underflow nor overflow when the robot
  first moves down.
* Advantech's DOS driver for the card, as ported to the SHARK RTOS (files ``833drive.h`` and
  ``pcl833.c``, Cerri & Fracassi 2001, found by code search): the register map below, the
  option codes, the initialisation sequence of ``vInitialize833`` and the read order of
  ``vCh_Read`` (high byte first, then low, then middle). The thesis's function names
  (``vInitialize833``, ``vCh_Read`` ...) are the same, so its library was this driver.
* Not confirmed (the card's manual was not available): which read strobes the software
  latch and whether the counter-reset register is a strobe or a level. We read in the
  vendor's order (high byte first, which we take as the latch strobe) and reset with a
  write of the channel bits followed by a write of zero, which is right for either kind of
  reset register. ``FakePcl833Port`` emulates exactly these assumptions.

Register map (offsets from the base address; channels 1-3)::

    write  +0/+1/+2  channel mode: bits 0-2 input mode, bit 3 reset value (0 start, 1 middle)
    write  +3/+4/+5  channel latch: bits 0-2 latch source, bit 3 reset counter on latch
    write  +6        latch-when-overflow enables (bit k-1 cleared = enabled for channel k)
    write  +7        counter reset (bit k-1 = reset channel k to its reset value)
    write  +8        bits 0-1 system clock (8/4/2 MHz), bits 2-3 cascade (24/48/72 bit)
    write  +9        bits 0-2 16C54 timer time base, bit 3 interrupt source (DI1 / timer)
    write  +10       16C54 timer divider (0-255)
    read   +0/+1/+2  channel 1 counter bytes LSB/middle/MSB, +3 channel 1 overflow
    read   +4/+5/+6  channel 2 counter bytes,              +7 channel 2 overflow
    read   +8/+9/+10 channel 3 counter bytes,              +11 channel 3 overflow
    read   +14       status
"""
from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Sequence

import numpy as np

from rt.devices.interfaces import EncoderBank, WatchReplaced
from rt.drivers import kernels
from rt.drivers.port_io import DevPortIO, PortIO
from rt.errors import ConfigurationError

# --- counter format -----------------------------------------------------------------------

COUNTER_BITS = 24
COUNTER_MODULUS = 1 << COUNTER_BITS          # 16777216 counter states
COUNTER_MASK = COUNTER_MODULUS - 1
HALF_RANGE = COUNTER_MODULUS >> 1            # 8388608
#: Reset value "middle" of thesis 3.2.2: positions are measured from here.
MIDPOINT = HALF_RANGE
#: Thesis 3.2.2: 0.02 mm of slider travel per count.
DEFAULT_M_PER_COUNT = 2e-5

# --- card ---------------------------------------------------------------------------------

DEFAULT_BASE = 0x220
N_CHANNELS = 3
#: The card decodes 16 consecutive ports (the highest one used is +14).
PORT_SPAN = 16
#: ISA cards decode 10 address bits.
ISA_MAX_PORT = 0x3FF

#: Write registers (offsets from base), from the Advantech driver.
REG_OVERFLOW_LATCH = 6
REG_COUNTER_RESET = 7
REG_CLOCK_CASCADE = 8
REG_TIMER_BASE = 9
REG_TIMER_DIVIDER = 10
#: Read register (offset from base).
REG_STATUS = 14


def mode_register(channel: int) -> int:
    """Offset of channel ``channel``'s (1-3) mode register (write)."""
    return channel - 1


def latch_register(channel: int) -> int:
    """Offset of channel ``channel``'s (1-3) latch-configuration register (write)."""
    return 3 + channel - 1


def count_register(channel: int, byte: int) -> int:
    """Offset of byte ``byte`` (0 LSB, 1 middle, 2 MSB) of channel ``channel``'s counter (read)."""
    return 4 * (channel - 1) + byte


def overflow_register(channel: int) -> int:
    """Offset of channel ``channel``'s overflow register (read)."""
    return 4 * (channel - 1) + 3


class InputMode(enum.IntEnum):
    """Channel input modes (mode register bits 0-2). The thesis uses ``X1``."""

    DISABLE = 0
    X1 = 1
    X2 = 2
    X4 = 3
    TWO_PULSE = 4
    ONE_PULSE = 5


#: Mode register bit 3: reset to 0x800000 ("middle") instead of 0 ("start").
RESET_VALUE_MIDDLE = 0x08
#: Latch register bits 0-2: latch source; 0 = latch on a software read.
LATCH_SOURCE_SOFTWARE_READ = 0
LATCH_SOURCE_MASK = 0x07
#: Latch register bit 3: reset the counter whenever it is latched (not used).
RESET_ON_LATCH = 0x08
#: Clock/cascade register values used by ``vInitialize833``: 8 MHz clock, no cascade (24 bit).
CLOCK_8MHZ = 0x00
CASCADE_24BIT = 0x00
#: Timer register values used by ``vInitialize833``: 0.1 ms time base, timer interrupt.
TIMER_BASE_0_1MS = 0x00
TIMER_INTERRUPT = 0x08


def reset_value(mode_byte: int) -> int:
    """Counter value a reset loads, given the byte last written to the mode register."""
    return MIDPOINT if mode_byte & RESET_VALUE_MIDDLE else 0


# --- pure conversions (shared with the digital twin) ---------------------------------------

def signed_offset(count: int, reference: int = MIDPOINT) -> int:
    """``count - reference`` taken modulo 2**24 into [-2**23, 2**23) counts."""
    return ((count - reference + HALF_RANGE) & COUNTER_MASK) - HALF_RANGE


def decode_counts(count: int, midpoint: int = MIDPOINT, m_per_count: float = DEFAULT_M_PER_COUNT,
                  sign: int = +1) -> float:
    """Slider position (m) from a raw 24-bit counter value (thesis 3.2.2).

    ``position = sign * (count - midpoint) * m_per_count``, with the difference taken modulo
    2**24 into [-2**23, 2**23) counts, so a counter reset to 0 ("start") that has
    underflowed to 0xFFFFFF still decodes to -1 count. With the thesis's midpoint reset this
    is exactly ``(count - 8388608) * 2e-5``. Unambiguous for displacements below 2**23
    counts from the reset point (±167.77 m at 2e-5 m/count, far beyond the 0.40 m stroke);
    use ``CountUnwrapper`` if a counter can travel further than that.
    """
    return sign * signed_offset(count, midpoint) * m_per_count


def encode_position(position_m: float, midpoint: int = MIDPOINT,
                    m_per_count: float = DEFAULT_M_PER_COUNT, sign: int = +1) -> int:
    """Raw 24-bit counter value (0 .. 2**24-1) that reads as ``position_m`` (m).

    The inverse of ``decode_counts``: the displacement is quantized to the nearest count
    (half-counts round up), added to ``midpoint`` and wrapped modulo 2**24 like the card's
    counter. ``decode_counts(encode_position(x))`` is within half a count of ``x`` whenever
    ``|x| / m_per_count < 2**23``; beyond that the value wraps as the hardware would.
    """
    counts = math.floor(sign * position_m / m_per_count + 0.5)
    return (midpoint + counts) & COUNTER_MASK


class CountUnwrapper:
    """Extends a wrapping 24-bit counter into an unbounded displacement (counts).

    Each ``update(count)`` adds the change since the previous count, taken modulo 2**24 into
    [-2**23, 2**23). That is right as long as the counter moves less than 2**23 counts
    between two updates (at 1 kHz: 8.4e9 counts/s, i.e. never for this rig).
    ``displacement`` is measured from ``reference`` (the reset value).

    ``store`` (int64[2]: last count, displacement) holds the state when given: the driver
    keeps its three unwrappers in one array that its compiled decode (``rt.drivers.kernels.
    pcl833_decode``) updates, so both paths share one state.
    """

    __slots__ = ("_s", "reference")

    def __init__(self, reference: int = MIDPOINT, count: int | None = None,
                 store: np.ndarray | None = None) -> None:
        self.reference = reference
        self._s = np.zeros(2, dtype=np.int64) if store is None else store
        self._s[0] = reference
        self._s[1] = 0
        self.reset(reference if count is None else count)

    def reset(self, count: int | None = None) -> None:
        """Restart from ``count`` (default: the reference value, as after a card reset)."""
        count = self.reference if count is None else count
        last = count & COUNTER_MASK
        self._s[0] = last
        self._s[1] = signed_offset(last, self.reference)

    def update(self, count: int) -> int:
        """Feed a new raw counter value; returns the displacement from the reference (counts)."""
        count &= COUNTER_MASK
        s = self._s
        displacement = int(s[1]) + ((count - int(s[0]) + HALF_RANGE) & COUNTER_MASK) - HALF_RANGE
        s[0] = count
        s[1] = displacement
        return displacement

    @property
    def displacement(self) -> int:
        """Displacement from the reference after the last update (counts)."""
        return int(self._s[1])


# --- the driver ----------------------------------------------------------------------------

def _per_axis(value: float | Sequence[float], name: str, n: int) -> tuple:
    if not isinstance(value, Iterable):                  # one value for every axis
        return (value,) * n
    values = tuple(value)
    if len(values) != n:
        raise ConfigurationError(f"{name} needs {n} values (one per axis), got {len(values)}")
    return values


class Pcl833Encoders(WatchReplaced, EncoderBank):
    """The three slider encoders read through a PCL-833 card.

    Outputs: ``read_positions_m(out)`` -> slider positions q (m, len 3): ``origin_m`` plus the
    displacement since the last ``reset()`` (or open, with ``reset_on_open``);
    ``read_counts()`` -> raw 24-bit counter values.

    Parameters (fixed after construction):

    * ``port_io``: port access; ``None`` opens ``DevPortIO(port_path)`` (root needed). A
      port passed in is *not* closed by ``close()`` (the twin shares it); one opened here is.
    * ``base``: I/O base address set on the card's switches (thesis: 0x220).
    * ``m_per_count``: metres of slider travel per count, one value or one per axis
      (thesis: 2e-5 m).
    * ``sign``: +1 or -1 per axis, so that q grows upward along each guide.
    * ``channels``: card channel (1-3) of each axis; thesis wiring: axis i on channel i+1.
    * ``input_mode``: quadrature multiplication (thesis: x1). ``m_per_count`` must match it.
    * ``reset_on_open``: configure and reset the counters to the midpoint at open, as the
      thesis does at start-up. ``False`` configures without resetting, so a process can
      reopen the card and keep the positions counted so far.
    * ``origin_m``: slider positions (m) that the counters' reset value stands for, i.e. where
      the sliders are when the counters are reset (the rig's homing position); default 0.
    """

    REPLACEABLE = frozenset({"read_positions_m"})

    def __init__(self, port_io: PortIO | None = None, base: int = DEFAULT_BASE,
                 m_per_count: float | Sequence[float] = DEFAULT_M_PER_COUNT,
                 sign: int | Sequence[int] = +1,
                 channels: Sequence[int] = (1, 2, 3),
                 input_mode: InputMode | int = InputMode.X1,
                 reset_on_open: bool = True,
                 port_path: str = "/dev/port",
                 origin_m: float | Sequence[float] = 0.0) -> None:
        if not 0 <= base <= ISA_MAX_PORT - PORT_SPAN + 1:
            raise ConfigurationError(
                f"PCL-833 base 0x{base:X} is outside the ISA I/O range 0x000-0x3F0")
        self.base = base
        self.m_per_count = tuple(float(m) for m in _per_axis(m_per_count, "m_per_count", 3))
        if not all(m > 0 and math.isfinite(m) for m in self.m_per_count):
            raise ConfigurationError(f"m_per_count must be positive, got {self.m_per_count}")
        self.origin_m = tuple(float(x) for x in _per_axis(origin_m, "origin_m", 3))
        if not all(math.isfinite(x) for x in self.origin_m):
            raise ConfigurationError(f"origin_m must be finite, got {self.origin_m}")
        self.sign = tuple(int(s) for s in _per_axis(sign, "sign", 3))
        if not all(s in (1, -1) for s in self.sign):
            raise ConfigurationError(f"sign must be +1 or -1 per axis, got {self.sign}")
        self.channels = tuple(int(c) for c in channels)
        if len(self.channels) != 3 or sorted(self.channels) != [1, 2, 3]:
            raise ConfigurationError(
                f"channels must assign the card channels 1, 2, 3 to the three axes, "
                f"got {tuple(channels)}")
        try:
            self.input_mode = InputMode(input_mode)
        except ValueError:
            raise ConfigurationError(f"unknown PCL-833 input mode {input_mode!r}") from None
        if self.input_mode is InputMode.DISABLE:
            raise ConfigurationError("input mode DISABLE would stop the counters")

        self._owns_port = port_io is None
        self._port = DevPortIO(port_path) if port_io is None else port_io
        # Per cycle: one block read of the nine count bytes (high, low, middle per axis, the
        # vendor's order) and one compiled decode (``rt.drivers.kernels``).
        self._read_ports = np.array(
            [base + count_register(c, b) for c in self.channels for b in (2, 0, 1)],
            dtype=np.int64)
        self._io = np.zeros(kernels.PCL_IO_SIZE, dtype=np.int64)
        self._raw = self._io[kernels.PCL_RAW:kernels.PCL_RAW + 9]
        self._unwrap_state = self._io[kernels.PCL_UNWRAP:kernels.PCL_UNWRAP + 6]
        self._unwrap = tuple(CountUnwrapper(MIDPOINT, store=self._unwrap_state[2 * i:2 * i + 2])
                             for i in range(3))
        self._dec = np.array([*self.sign, *self.origin_m, *self.m_per_count], dtype=np.float64)
        # Compile (or load from numba's cache) now, not in the first cycle (scratch arrays).
        kernels.pcl833_decode(self._io.copy(), self._dec, np.zeros(3))
        try:
            self.configure()
            if reset_on_open:
                self.reset()
            else:
                # Positions continue from the counters' current values.
                for unwrapper, count in zip(self._unwrap, self.read_counts()):
                    unwrapper.reset(count)
        except BaseException:
            self.close()
            raise

    def configure(self) -> None:
        """Write the thesis's configuration (``vInitialize833`` then x1, middle, 24 bit).

        Unlike ``vInitialize833`` this does not disable the inputs first, so no pulses are
        lost when the card is reconfigured while the robot moves, and it does not reset.
        """
        self._check_open()
        out = self._port.outb
        b = self.base
        for channel in (1, 2, 3):
            out(b + mode_register(channel), int(self.input_mode) | RESET_VALUE_MIDDLE)
            out(b + latch_register(channel), LATCH_SOURCE_SOFTWARE_READ)  # no reset on latch
        out(b + REG_OVERFLOW_LATCH, 0x00)            # as vInitialize833 leaves it
        out(b + REG_CLOCK_CASCADE, CLOCK_8MHZ | CASCADE_24BIT)
        out(b + REG_TIMER_BASE, TIMER_BASE_0_1MS | TIMER_INTERRUPT)
        out(b + REG_TIMER_DIVIDER, 0)

    def reset(self) -> None:
        """Reset every counter to the midpoint 8388608 (thesis 3.2.2): positions restart at 0."""
        self._check_open()
        # Bits then zero: a strobe-type register resets on the first write, a level-type one
        # holds the counters at the reset value until the second write releases them.
        self._port.outb(self.base + REG_COUNTER_RESET, 0x07)
        self._port.outb(self.base + REG_COUNTER_RESET, 0x00)
        for unwrapper in self._unwrap:
            unwrapper.reset()

    def read_channel(self, channel: int) -> int:
        """Latch and read card channel ``channel`` (1-3): the raw 24-bit count.

        Bytes are read high, low, middle as the vendor driver does; the high-byte read is the
        software latch, so the three bytes belong to one instant.
        """
        base = self.base + count_register(channel, 0)
        inb = self._port.inb
        msb = inb(base + 2)
        lsb = inb(base)
        mid = inb(base + 1)
        return (msb << 16) | (mid << 8) | lsb

    def read_counts(self) -> tuple[int, ...]:
        self._check_open()
        return tuple(self.read_channel(c) for c in self.channels)

    def read_positions_m(self, out: np.ndarray) -> np.ndarray:
        """The three slider positions (m) into ``out`` (float64[3]): one block read of the
        port and one compiled decode, bit for bit :meth:`read_positions_m_interpreted`."""
        self._check_open()
        self._port.read_block(self._read_ports, self._raw)
        kernels.pcl833_decode(self._io, self._dec, out)
        return out

    def compiled_read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                     PortIO] | None:
        """:meth:`read_positions_m`'s arrays when its port is memory (the emulated card:
        ``PortIO.compiled_block_state``): (card state, ports, read state, decode constants,
        port); None on ``/dev/port`` or once closed."""
        if self._closed:
            return None
        st = self._port.compiled_block_state()
        if st is None:
            return None
        return st, self._read_ports, self._io, self._dec, self._port

    def read_positions_m_interpreted(self, out: np.ndarray) -> np.ndarray:
        """:meth:`read_positions_m` one byte and one axis at a time (the reference)."""
        self._check_open()
        for i in range(3):
            displacement = self._unwrap[i].update(self.read_channel(self.channels[i]))
            out[i] = self.origin_m[i] + self.sign[i] * displacement * self.m_per_count[i]
        return out

    def _close(self) -> None:
        # The counters keep counting on the card; only our handle goes.
        if self._owns_port:
            self._port.close()
