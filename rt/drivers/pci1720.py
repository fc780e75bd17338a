"""Advantech PCI-1720 4-channel 12-bit DAC through comedilib (thesis 3.1.2 and 3.2.3).

The amplifiers run in current mode (1 A/V), so the volts written here are motor current
commands; 0 V is zero torque.

Sources, and what came from which:

* Thesis 3.1.2 / 3.2.3: ±10 V range, 12 bits (0.0048 V resolution), control saturated at
  ±6 V "to avoid too fast movements"; ``comedi_open("/dev/comedi0")``, ``comedi_get_maxdata``,
  ``comedi_get_range``, ``comedi_from_phys`` and ``comedi_data_write(..., AREF_GROUND, data)``.
  The thesis says nothing about a drive-enable signal.
* comedilib reference (``comedilib.h``, man pages ``comedi_data_write(3)``,
  ``comedi_get_range(3)``, ``comedi_from_phys(3)``): ``comedi_t *comedi_open(const char *)``
  (NULL on error), ``int comedi_close(comedi_t *)``, ``lsampl_t comedi_get_maxdata(comedi_t *,
  unsigned subdevice, unsigned chan)``, ``comedi_range *comedi_get_range(comedi_t *, unsigned
  subdevice, unsigned chan, unsigned range)`` (NULL on error; ``struct {double min; double
  max; unsigned unit;}``), ``int comedi_data_write(comedi_t *, unsigned subdevice, unsigned
  chan, unsigned range, unsigned aref, lsampl_t data)`` (1 on success, -1 on error),
  ``int comedi_get_n_channels(comedi_t *, unsigned subdevice)``, ``int comedi_dio_config(...,
  unsigned dir)``, ``int comedi_dio_write(..., unsigned bit)``, ``int comedi_errno(void)``,
  ``const char *comedi_strerror(int)``; ``AREF_GROUND = 0``, ``UNIT_volt = 0``,
  ``COMEDI_OUTPUT = 1`` (``comedi.h``).
* The cycle's write is one ``int comedi_do_insnlist(comedi_t *, comedi_insnlist *)``
  (``comedi_do_insnlist(3)``: "performs multiple Comedi instructions as part of one system
  call"; returns "the number of successfully completed instructions", -1 if there is an error
  before the first) with three ``INSN_WRITE`` instructions, one sample each, instead of three
  ``comedi_data_write`` calls (each its own ioctl). The structures, from the kernel's uapi
  header ``linux/comedi.h`` (checked by ``tests/test_pci1720_insnlist.py`` against the
  installed header with a C compiler): ``struct comedi_insn {unsigned int insn; unsigned int
  n; unsigned int *data; unsigned int subdev; unsigned int chanspec; unsigned int
  unused[3];}``, ``struct comedi_insnlist {unsigned int n_insns; struct comedi_insn
  *insns;}``, ``INSN_WRITE = 1 | INSN_MASK_WRITE (0x8000000)``, ``CR_PACK(chan, rng, aref) =
  ((aref & 0x3) << 24) | ((rng & 0xff) << 16) | chan``. The Linux ioctl behind it
  (``do_insnlist_ioctl`` in ``comedi_fops.c``) stops at the first failing instruction and
  then answers an error (-1 from comedilib) even when instructions before it were done; the
  man page's count covers a partial list too. Either way anything but 3 is a failed write
  (``Pci1720Outputs.write_volts``). ``comedi_from_phys`` computes
  ``s = (v - min) / (max - min) * maxdata``, clamps to [0, maxdata] and returns
  ``floor(s + 0.5)``; we do the same arithmetic in Python (``volts_to_code``) so it costs no
  library call and the test double needs no converter.
* Linux comedi driver ``adv_pci1720.c``: subdevice 0 is the analog output (4 channels,
  maxdata 0x0fff, ranges 0: 0-5 V, 1: 0-10 V, 2: ±5 V, 3: ±10 V); subdevice 1 is a
  4-bit digital *input* (the BoardID switch). The card has no digital output, so a
  drive-enable line, if the rig has one, lives on another comedi device. After power-up
  the outputs are at 0 V in the 0-5 V range; writing with range 3 switches to ±10 V, which
  is why ``Pci1720Outputs`` writes 0 V to every channel as soon as it opens.

Enable semantics (the thesis is silent, so this is our definition): ``enabled`` is a software
gate that refuses non-zero commands until the supervisor calls ``enable()``. If an
``EnableLine`` is configured, ``enable()`` also drives that digital output to its active
level and ``disable()`` drops it after writing 0 V to every channel; without one, disable
leaves the amplifiers powered with a 0 V (zero-current) command, and cutting power stays
the job of the hardware e-stop chain.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rt.devices.interfaces import ActuatorOutputs, WatchReplaced
from rt.drivers import kernels
from rt.errors import BackendUnavailableError, ConfigurationError, HardwareError, InputError

AREF_GROUND = 0
UNIT_VOLT = 0
COMEDI_INPUT = 0
COMEDI_OUTPUT = 1
#: adv_pci1720 range index of ±10 V (thesis 3.1.2).
RANGE_BIPOLAR_10V = 3
#: Thesis 3.1.2: commands are saturated at ±6 V.
DEFAULT_LIMIT_V = 6.0

# comedi.h: instruction codes and the packed channel specification.
INSN_MASK_WRITE = 0x8000000
INSN_WRITE = 1 | INSN_MASK_WRITE


def cr_pack(chan: int, rng: int, aref: int) -> int:
    """comedi.h ``CR_PACK``: channel, range index and analog reference in one chanspec."""
    return ((aref & 0x3) << 24) | ((rng & 0xFF) << 16) | chan


def cr_chan(chanspec: int) -> int:
    """comedi.h ``CR_CHAN``."""
    return chanspec & 0xFFFF


def cr_range(chanspec: int) -> int:
    """comedi.h ``CR_RANGE``."""
    return (chanspec >> 16) & 0xFF


def cr_aref(chanspec: int) -> int:
    """comedi.h ``CR_AREF``."""
    return (chanspec >> 24) & 0x03


_SHAPE = (3,)
_F64 = np.dtype(np.float64)
#: lsampl_t (``unsigned int``) as numpy sees it: the instruction samples' type.
_LSAMPL = np.dtype(np.uintc)

MISSING_LIBRARY_MESSAGE = "comedilib not found: install libcomedi0 or choose the 'sim' backend"


class ComediRange(ctypes.Structure):
    """``comedi_range`` from comedilib.h: physical limits of one range (V for UNIT_volt)."""

    _fields_ = [("min", ctypes.c_double), ("max", ctypes.c_double), ("unit", ctypes.c_uint)]


class ComediInsn(ctypes.Structure):
    """``struct comedi_insn`` (linux/comedi.h): one instruction; ``data`` points at ``n``
    samples (``unsigned int``), written for ``INSN_WRITE``."""

    _fields_ = [("insn", ctypes.c_uint), ("n", ctypes.c_uint),
                ("data", ctypes.POINTER(ctypes.c_uint)), ("subdev", ctypes.c_uint),
                ("chanspec", ctypes.c_uint), ("unused", ctypes.c_uint * 3)]


class ComediInsnList(ctypes.Structure):
    """``struct comedi_insnlist`` (linux/comedi.h): ``n_insns`` instructions at ``insns``."""

    _fields_ = [("n_insns", ctypes.c_uint), ("insns", ctypes.POINTER(ComediInsn))]


def comedilib_prototypes() -> dict[str, tuple[Any, tuple[Any, ...]]]:
    """comedilib's functions this package calls: name → (restype, argtypes) for ctypes."""
    u = ctypes.c_uint
    p = ctypes.c_void_p
    return {
        "comedi_open": (p, (ctypes.c_char_p,)),
        "comedi_close": (ctypes.c_int, (p,)),
        "comedi_get_n_channels": (ctypes.c_int, (p, u)),
        "comedi_get_maxdata": (u, (p, u, u)),
        "comedi_get_range": (ctypes.POINTER(ComediRange), (p, u, u, u)),
        "comedi_data_write": (ctypes.c_int, (p, u, u, u, u, u)),
        "comedi_do_insnlist": (ctypes.c_int, (p, ctypes.POINTER(ComediInsnList))),
        "comedi_data_read": (ctypes.c_int, (p, u, u, u, u, ctypes.POINTER(ctypes.c_uint))),
        "comedi_dio_config": (ctypes.c_int, (p, u, u, u)),
        "comedi_dio_write": (ctypes.c_int, (p, u, u, u)),
        "comedi_dio_read": (ctypes.c_int, (p, u, u, ctypes.POINTER(ctypes.c_uint))),
        "comedi_errno": (ctypes.c_int, ()),
        "comedi_strerror": (ctypes.c_char_p, (ctypes.c_int,)),
    }


def load_comedilib() -> Any:
    """Load comedilib with ctypes and declare the prototypes we call.

    Raises one ``BackendUnavailableError`` when the library is not installed.
    """
    name = ctypes.util.find_library("comedi")
    if name is None:
        raise BackendUnavailableError(MISSING_LIBRARY_MESSAGE)
    try:
        lib = ctypes.CDLL(name, use_errno=True)
    except OSError as exc:
        raise BackendUnavailableError(f"{MISSING_LIBRARY_MESSAGE} ({exc})") from None
    for fname, (restype, argtypes) in comedilib_prototypes().items():
        fn = getattr(lib, fname)
        fn.restype = restype
        fn.argtypes = argtypes
    return lib


def comedi_error_text(lib: Any) -> str:
    """comedilib's message for its last error (``comedi_strerror(comedi_errno())``)."""
    msg = lib.comedi_strerror(lib.comedi_errno())
    return msg.decode(errors="replace") if isinstance(msg, bytes) else str(msg)


def comedi_open_device(lib: Any, path: str, card: str) -> Any:
    """``comedi_open(path)``, or one clear error: ``BackendUnavailableError`` when the device
    file does not exist (driver for ``card`` not loaded), ``HardwareError`` otherwise."""
    handle = lib.comedi_open(path.encode())
    if not handle:
        reason = comedi_error_text(lib)
        if not os.path.exists(path):
            raise BackendUnavailableError(
                f"{path} does not exist: load the comedi driver for the {card} or choose the "
                f"'sim' backend ({reason})")
        raise HardwareError(f"comedi_open({path}) failed: {reason}")
    return handle


def volts_to_code(volts: float, v_min: float = -10.0, v_max: float = 10.0,
                  maxdata: int = 4095) -> int:
    """DAC code for ``volts`` (V): ``floor((V - v_min) / (v_max - v_min) * maxdata + 0.5)``.

    On the PCI-1720's ±10 V range that is ``round((V + 10) / 20 * 4095)`` with halves rounded
    up (as ``comedi_from_phys``), clamped to 0..4095. One LSB is 20/4095 V = 4.88 mV, and
    the output ``code_to_volts(volts_to_code(V))`` is within half an LSB (2.44 mV) of V
    inside the range. 0 V gives code 2048 = +2.44 mV: a symmetric range has no exact zero.
    """
    s = (volts - v_min) / (v_max - v_min) * maxdata
    if s <= 0.0:
        return 0
    if s >= maxdata:
        return maxdata
    return math.floor(s + 0.5)


def code_to_volts(code: int, v_min: float = -10.0, v_max: float = 10.0,
                  maxdata: int = 4095) -> float:
    """Ideal output voltage (V) of DAC ``code`` (``comedi_to_phys``)."""
    return v_min + code / maxdata * (v_max - v_min)


@dataclass(frozen=True)
class EnableLine:
    """A digital output that enables the drives (the rig's own wiring; not in the thesis).

    ``device`` is the comedi device holding it (``None``: the DAC's own device; the PCI-1720
    has no digital outputs, so on the thesis rig this is another card), ``subdevice`` and
    ``channel`` address the bit, ``active_high`` its polarity.
    """

    subdevice: int
    channel: int
    device: str | None = None
    active_high: bool = True


@dataclass(frozen=True)
class _Channel:
    number: int
    v_min: float
    v_max: float
    maxdata: int


class Pci1720Outputs(WatchReplaced, ActuatorOutputs):
    """Command voltages (V) to the three current-mode amplifiers through a PCI-1720.

    Inputs: ``write_volts(volts)`` with one voltage per axis. Outputs: ``last_codes`` (DAC
    codes written), ``last_volts`` (the quantized voltages they produce), ``clamped`` (which
    channels hit the command limit on the last write).

    Parameters (fixed after construction):

    * ``device``: comedi device file (thesis: /dev/comedi0).
    * ``subdevice``: analog-output subdevice (adv_pci1720: 0).
    * ``channels``: DAC channel of each axis (thesis: 0, 1, 2 on terminals A9, A15, B1).
    * ``range_index``: comedi range (adv_pci1720: 3 = ±10 V).
    * ``limit_v``: software command limit (V), symmetric (thesis: 6 V); must lie inside the
      range.
    * ``enable_line``: optional drive-enable output, see the module docstring.
    * ``lib``: comedilib, or a test double with the same functions; ``None`` loads the real
      library and fails with one clear ``BackendUnavailableError`` when it is missing.

    Starts disabled with 0 V on every channel. ``close()`` disables, then closes the device.
    """

    REPLACEABLE = frozenset({"write_volts"})

    def __init__(self, device: str = "/dev/comedi0", subdevice: int = 0,
                 channels: Sequence[int] = (0, 1, 2), range_index: int = RANGE_BIPOLAR_10V,
                 limit_v: float = DEFAULT_LIMIT_V, enable_line: EnableLine | dict | None = None,
                 lib: Any = None) -> None:
        self.device = device
        self.subdevice = int(subdevice)
        self.range_index = int(range_index)
        # Codes, voltages and clamp flags of the last write, the enable flag, the limit and
        # the channel ranges in one array: the compiled write (``rt.drivers.kernels.
        # pci1720_codes``) takes it as its one state argument; ``last_codes`` etc. read it.
        self._dac = np.zeros(kernels.DAC_STATE_SIZE)
        self._dac[kernels.DAC_VOLTS:kernels.DAC_VOLTS + 3] = math.nan
        self.limit_v = float(limit_v)
        if isinstance(enable_line, dict):          # from a YAML config
            enable_line = EnableLine(**enable_line)
        self.enable_line = enable_line
        numbers = tuple(int(c) for c in channels)
        if len(numbers) != self.n_channels or len(set(numbers)) != len(numbers):
            raise ConfigurationError(
                f"channels must name {self.n_channels} distinct DAC channels, got {numbers}")
        if not (math.isfinite(self.limit_v) and self.limit_v > 0):
            raise ConfigurationError(f"limit_v must be a positive voltage, got {limit_v}")

        self._lib = load_comedilib() if lib is None else lib
        self._enabled = False
        self._dev: Any = None
        self._enable_dev: Any = None

        self._dev = self._open(device)
        try:
            self._channels = tuple(self._probe_channel(n) for n in numbers)
            for i, ch in enumerate(self._channels):
                r = kernels.DAC_RANGES + 3 * i
                self._dac[r:r + 3] = (ch.v_min, ch.v_max, ch.maxdata)
            self._build_insnlist()
            # A comedilib double without comedi_do_insnlist gets the channel-by-channel write.
            self._do_insnlist = getattr(self._lib, "comedi_do_insnlist", None)
            # The comedilib double (the twin's cards) runs the list compiled: the codes and
            # the list in one call on its state array (``FakeComedi.preplanned``).
            preplanned = getattr(self._lib, "preplanned", None)
            self._fake_st: np.ndarray | None = None
            if preplanned is not None and self._do_insnlist is not None:
                self._fake_st = preplanned(self._insnlist_ptr)
            self._owner = ctypes.addressof(self._insnlist_ptr)
            # Compile (or load from numba's cache) now, not in a cycle: a read-only view, as
            # the loop's port is, on a scratch state and scratch samples.
            probe = np.zeros(3)
            probe.flags.writeable = False
            kernels.pci1720_codes(probe, self._dac.copy(), self._samples.copy())
            if self._fake_st is not None:
                kernels.pci1720_write_fake(probe, self._dac.copy(), self._samples.copy(),
                                           np.zeros_like(self._fake_st), 0)
            if enable_line is not None:
                self._setup_enable_line(enable_line)
            self._write_zero()
        except BaseException:
            self._release_handles()
            self._closed = True
            raise

    # --- setup -------------------------------------------------------------------------

    def _error_text(self) -> str:
        return comedi_error_text(self._lib)

    def _open(self, path: str) -> Any:
        return comedi_open_device(self._lib, path, "card (adv_pci1720)")

    def _probe_channel(self, number: int) -> _Channel:
        lib, dev, sub = self._lib, self._dev, self.subdevice
        n = lib.comedi_get_n_channels(dev, sub)
        if n < 0:
            raise ConfigurationError(
                f"{self.device} has no subdevice {sub}: {self._error_text()}")
        if not 0 <= number < n:
            raise ConfigurationError(
                f"{self.device} subdevice {sub} has channels 0-{n - 1}, not {number}")
        maxdata = int(lib.comedi_get_maxdata(dev, sub, number))
        rng = lib.comedi_get_range(dev, sub, number, self.range_index)
        if not rng or maxdata <= 0:
            raise ConfigurationError(
                f"{self.device} subdevice {sub} channel {number} has no range "
                f"{self.range_index}: {self._error_text()}")
        r = rng.contents
        if r.unit != UNIT_VOLT:
            raise ConfigurationError(
                f"range {self.range_index} of channel {number} is not a voltage range")
        if not r.min <= -self.limit_v < self.limit_v <= r.max:
            raise ConfigurationError(
                f"command limit ±{self.limit_v} V does not fit range "
                f"[{r.min}, {r.max}] V of channel {number}; pick a bipolar range")
        return _Channel(number, float(r.min), float(r.max), maxdata)

    def _build_insnlist(self) -> None:
        """The cycle's write as one instruction list, built once: an ``INSN_WRITE`` of one
        sample per channel (its chanspec ``CR_PACK(channel, range, AREF_GROUND)``), the
        samples in one ``unsigned int`` array that the compiled write fills
        (``self._samples`` is a numpy view of it) and ``comedi_do_insnlist`` reads."""
        n = len(self._channels)
        word = ctypes.sizeof(ctypes.c_uint)
        self._insn_data = (ctypes.c_uint * n)()
        self._insns = (ComediInsn * n)()
        for i, ch in enumerate(self._channels):
            insn = self._insns[i]
            insn.insn = INSN_WRITE
            insn.n = 1
            insn.data = ctypes.cast(ctypes.byref(self._insn_data, i * word),
                                    ctypes.POINTER(ctypes.c_uint))
            insn.subdev = self.subdevice
            insn.chanspec = cr_pack(ch.number, self.range_index, AREF_GROUND)
        self._insnlist = ComediInsnList(n, self._insns)
        self._insnlist_ptr = ctypes.pointer(self._insnlist)
        self._samples = np.frombuffer(memoryview(self._insn_data), dtype=_LSAMPL)

    def _setup_enable_line(self, line: EnableLine) -> None:
        if line.device is None or line.device == self.device:
            self._enable_dev = self._dev
        else:
            self._enable_dev = self._open(line.device)
        if self._lib.comedi_dio_config(self._enable_dev, line.subdevice, line.channel,
                                       COMEDI_OUTPUT) < 0:
            raise ConfigurationError(
                f"cannot make subdevice {line.subdevice} channel {line.channel} a digital "
                f"output: {self._error_text()}")
        self._drive_enable(False)

    # --- ActuatorOutputs ---------------------------------------------------------------

    @property
    def enabled(self) -> bool:
        return self._enabled

    @property
    def _enabled(self) -> bool:
        return self._dac[kernels.DAC_ENABLED] != 0.0

    @_enabled.setter
    def _enabled(self, value: bool) -> None:
        self._dac[kernels.DAC_ENABLED] = 1.0 if value else 0.0

    @property
    def limit_v(self) -> float:
        """The software command limit (V)."""
        return float(self._dac[kernels.DAC_LIMIT])

    @limit_v.setter
    def limit_v(self, value: float) -> None:
        self._dac[kernels.DAC_LIMIT] = value

    @property
    def last_codes(self) -> list[int]:
        """The DAC code of each channel's last write (0 before any)."""
        return [int(c) for c in self._dac[kernels.DAC_CODES:kernels.DAC_CODES + 3]]

    @property
    def last_volts(self) -> list[float]:
        """The voltage (V) each channel's last code produces (NaN before any write)."""
        return self._dac[kernels.DAC_VOLTS:kernels.DAC_VOLTS + 3].tolist()

    @property
    def clamped(self) -> list[bool]:
        """Which channels hit the command limit on the last write."""
        return [c != 0.0 for c in self._dac[kernels.DAC_CLAMPED:kernels.DAC_CLAMPED + 3]]

    @property
    def lsb_v(self) -> tuple[float, ...]:
        """Voltage step of one DAC code per channel (V); 20/4095 V on ±10 V."""
        return tuple((c.v_max - c.v_min) / c.maxdata for c in self._channels)

    def enable(self) -> None:
        """Allow non-zero commands and assert the drive-enable line (if configured)."""
        self._check_open()
        if self.enable_line is not None:
            self._drive_enable(True)
        self._enabled = True

    def disable(self) -> None:
        """Write 0 V to every channel, then drop the drive-enable line. Safe to repeat.

        Both steps are attempted even if the first fails; the first error is raised after.
        After ``close()`` (which already did this) it does nothing, so fault handling may
        call it unconditionally.
        """
        if self.closed:
            return
        self._enabled = False
        self._zero_and_drop()

    def _zero_and_drop(self) -> None:
        error: HardwareError | None = None
        try:
            self._write_zero()
        except HardwareError as exc:
            error = exc
        if self.enable_line is not None:
            try:
                self._drive_enable(False)
            except HardwareError as exc:
                error = error or exc
        if error is not None:
            raise error

    def write_volts(self, volts: Sequence[float] | np.ndarray) -> None:
        """Command ``volts`` (V), one per axis, clamped to ±``limit_v`` and quantized.

        Refused (``HardwareError``, nothing written) with a non-zero value while disabled;
        refused (``InputError``, nothing written) for a wrong length or a non-finite value.
        A float64 array (the loop's port) is validated and converted in one compiled call
        (``rt.drivers.kernels.pci1720_codes``) that puts the codes into the instruction list,
        then one ``comedi_do_insnlist`` writes the three channels (one ioctl on the rig); any
        other sequence takes :meth:`write_volts_interpreted`, the reference. Same results.

        A write that does not complete every instruction is a failed write (``HardwareError``
        naming the channel that failed), whatever comedilib answers: the count of those done
        (a partial list) or -1 (an error before the first; the Linux ioctl also answers -1
        after a partial list). The driver's state is then what the channel-by-channel write
        leaves (the channels before the failed one written); ``RedundantDrive`` fails over.
        """
        if type(volts) is not np.ndarray or volts.shape != _SHAPE or volts.dtype is not _F64 \
                or self._do_insnlist is None:
            self.write_volts_interpreted(volts)
            return
        if self._closed:
            self._check_open()
        st = self._fake_st
        if st is not None:                     # the double: codes and list in one call
            rc, done = kernels.pci1720_write_fake(volts, self._dac, self._samples, st,
                                                  self._owner)
            self.finish_compiled_write(volts, rc, done)
            return
        rc = kernels.pci1720_codes(volts, self._dac, self._samples)
        if rc < 0:
            self._refuse(rc, volts)
        done = self._do_insnlist(self._dev, self._insnlist_ptr)
        if done != 3:
            self._write_failed(done if 0 < done < 3 else 0)

    def compiled_write(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
        """What ``kernels.pci1720_write_fake`` takes after the command — (the driver's state,
        the list's samples, the double's state, the list pointer's address) — when this
        driver writes to the compiled comedilib double and is open, else None: a caller that
        runs the write inside its own compiled call (``RedundantDrive``) then calls
        :meth:`finish_compiled_write` with the answers, as :meth:`write_volts` does."""
        if self._fake_st is None or self._closed:
            return None
        return self._dac, self._samples, self._fake_st, self._owner

    def finish_compiled_write(self, volts: np.ndarray, rc: int, done: int) -> None:
        """The rest of :meth:`write_volts` after ``kernels.pci1720_write_fake`` answered
        (``rc``, ``done``): a refusal raises; a plan not the driver's list's (``FC_STALE``)
        has the double decode and write it; a log is kept; an incomplete list is a failed
        write (``HardwareError``, the state as the channel-by-channel write leaves it)."""
        if rc < 0:
            self._refuse(rc, volts)
        if done == kernels.FC_STALE:           # not its plan now: the double decodes again
            assert self._do_insnlist is not None      # a double with a plan has the call
            done = self._do_insnlist(self._dev, self._insnlist_ptr)
        elif self._lib.keep_log:
            self._lib.log_last(self._dev)
        if done != 3:
            self._write_failed(done if 0 < done < 3 else 0)

    def _refuse(self, rc: int, volts: np.ndarray) -> None:
        if rc == kernels.DAC_NOT_FINITE:
            raise InputError(f"write_volts got a non-finite command {list(volts)}; nothing "
                             f"was written")
        raise HardwareError(
            "Pci1720Outputs refused a non-zero command while disabled; only the "
            "supervisor enables the drives")

    def _write_failed(self, i: int) -> None:
        """Channel ``i``'s write failed: the state as the channel-by-channel write leaves it
        (the channels before ``i`` written, ``i``'s clamp flag set, the rest as before)."""
        dac, b = self._dac, kernels.DAC_BACKUP
        dac[kernels.DAC_CODES + i:3] = dac[b + kernels.DAC_CODES + i:b + 3]
        dac[kernels.DAC_VOLTS + i:6] = dac[b + kernels.DAC_VOLTS + i:b + 6]
        dac[kernels.DAC_CLAMPED + i + 1:9] = dac[b + kernels.DAC_CLAMPED + i + 1:b + 9]
        raise HardwareError(
            f"DAC write on {self.device} channel {self._channels[i].number} failed: "
            f"{self._error_text()}")

    def write_volts_interpreted(self, volts: Sequence[float] | np.ndarray) -> None:
        """:meth:`write_volts` one value at a time in Python (the reference; any sequence)."""
        self._check_open()
        if len(volts) != self.n_channels:
            raise InputError(f"write_volts needs {self.n_channels} values, got {len(volts)}")
        nonzero = False
        for v in volts:        # validate everything before writing anything
            if not math.isfinite(v):
                raise InputError(f"write_volts got a non-finite command {list(volts)}; nothing "
                                 f"was written")
            if v != 0.0:
                nonzero = True
        if nonzero and not self._enabled:
            raise HardwareError(
                "Pci1720Outputs refused a non-zero command while disabled; only the "
                "supervisor enables the drives")
        limit = self.limit_v
        for i in range(self.n_channels):
            v = float(volts[i])
            self._dac[kernels.DAC_CLAMPED + i] = 0.0 if -limit <= v <= limit else 1.0
            self._write_channel(i, min(limit, max(-limit, v)))

    # --- internals ---------------------------------------------------------------------

    def _write_channel(self, i: int, volts: float) -> None:
        ch = self._channels[i]
        code = volts_to_code(volts, ch.v_min, ch.v_max, ch.maxdata)
        rc = self._lib.comedi_data_write(self._dev, self.subdevice, ch.number,
                                         self.range_index, AREF_GROUND, code)
        if rc < 0:
            raise HardwareError(
                f"DAC write on {self.device} channel {ch.number} failed: "
                f"{self._error_text()}")
        self._dac[kernels.DAC_CODES + i] = code
        self._dac[kernels.DAC_VOLTS + i] = code_to_volts(code, ch.v_min, ch.v_max, ch.maxdata)

    def _write_zero(self) -> None:
        # Channel by channel, not one instruction list: a list stops at its first failing
        # instruction, and zeroing must still reach the channels after a dead one.
        error: HardwareError | None = None
        for i in range(self.n_channels):
            self._dac[kernels.DAC_CLAMPED + i] = 0.0
            try:
                self._write_channel(i, 0.0)
            except HardwareError as exc:     # still zero the other channels
                error = error or exc
        if error is not None:
            raise error

    def _drive_enable(self, on: bool) -> None:
        line = self.enable_line
        assert line is not None
        level = 1 if on == line.active_high else 0
        if self._lib.comedi_dio_write(self._enable_dev, line.subdevice, line.channel,
                                      level) < 0:
            raise HardwareError(
                f"cannot {'assert' if on else 'drop'} the drive-enable line: "
                f"{self._error_text()}")

    def _release_handles(self) -> None:
        if self._enable_dev is not None and self._enable_dev is not self._dev:
            self._lib.comedi_close(self._enable_dev)
        if self._dev is not None:
            self._lib.comedi_close(self._dev)
        self._enable_dev = None
        self._dev = None

    def _close(self) -> None:
        self._enabled = False
        try:
            self._zero_and_drop()
        finally:
            self._release_handles()
