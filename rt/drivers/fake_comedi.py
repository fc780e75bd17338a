"""A comedilib double for the PCI-1720: the same function names, arguments and return
conventions as the C library, so the real driver code path (volts -> 12-bit codes) runs in tests
and in the digital twin without a card. ``FakeComediSystem`` puts several such cards behind
their device files, as one comedilib sees a machine's cards."""
from __future__ import annotations

import ctypes
from collections.abc import Callable, Mapping
from typing import Any

from rt.drivers.pci1720 import (
    INSN_WRITE,
    ComediInsn,
    ComediRange,
    cr_aref,
    cr_chan,
    cr_range,
    volts_to_code,
)

#: errno values the double reports (Linux): an I/O error, an invalid argument.
EIO = 5
EINVAL = 22


def _unchanged(watched: list) -> bool:
    """Every watched memory still holds its bytes (``.raw`` of a cached ``c_char`` array
    reads the memory now; ``ctypes.string_at`` costs ~2 µs a call here, this ~0.05)."""
    for view, raw in watched:
        if view.raw != raw:
            return False
    return True


class FakeComedi:
    """comedilib's functions with the same names, arguments and return conventions, for a
    PCI-1720 (adv_pci1720: subdevice 0 = AO, 4 channels, maxdata 4095, ranges 0-5, 0-10,
    ±5, ±10 V) plus digital-I/O subdevices (``dio_subdevices``, default 2; 8 lines each,
    configured as input or output with ``comedi_dio_config``, like an 8255 port) on the same
    "device". A digital I/O card alone is ``FakeComedi(dio_subdevices=(0, 1))``; an
    analog-input card (PCI-1711-like: 16 inputs, 12 bit, ranges ±10, ±5, ±2.5, ±1.25,
    ±0.625 V) is ``FakeComedi(ai_source=volts_of_channel)``, its inputs on subdevice 0.

    Records ``writes`` as (handle, subdevice, channel, range, aref, code) and ``dio`` as
    (handle, subdevice, channel, bit). ``fail_open`` / ``fail_writes`` inject errors;
    ``fail_channels`` makes the analog outputs of those channels fail (a dead DAC channel:
    its writes answer EIO, the others still work). ``comedi_do_insnlist`` runs ``INSN_WRITE``
    instructions on the analog outputs in order, each sample as ``comedi_data_write`` would
    write it, and stops at the first that fails: it answers the number done, -1 when the
    first one failed (``comedi_do_insnlist(3)``); other instructions are refused (EINVAL).
    ``level(subdevice, channel)`` is a line's level (what an output drives, what the outside
    world puts on an input: ``set_input``); ``fail_dio_reads`` makes ``comedi_dio_read`` fail.
    """

    DIO_CHANNELS = 8

    RANGES = ((0.0, 5.0), (0.0, 10.0), (-5.0, 5.0), (-10.0, 10.0))
    AI_RANGES = ((-10.0, 10.0), (-5.0, 5.0), (-2.5, 2.5), (-1.25, 1.25), (-0.625, 0.625))
    AO_CHANNELS = 4
    AI_SUBDEVICE = 0
    AI_CHANNELS = 16

    def __init__(self, keep_log: bool = True, dio_subdevices: tuple[int, ...] = (2,),
                 ai_source: Callable[[int], float] | None = None) -> None:
        # The twin keeps no log (it runs for hours); tests keep every write.
        self.keep_log = keep_log
        self.last_code: dict[int, int] = {}
        self.writes: list[tuple] = []
        self.dio: list[tuple] = []
        self.dio_config: list[tuple] = []
        self.opened: list[object] = []
        self.closed: list[object] = []
        self.fail_open = False
        self.fail_writes = False
        self.fail_channels: set[int] = set()
        self._insn_plan: tuple | None = None
        self.fail_dio_reads = False
        self.dio_subdevices = tuple(dio_subdevices)
        self.ai_source = ai_source
        self.fail_ai_reads = False
        self._ai_ranges = [ComediRange(lo, hi, 0) for lo, hi in self.AI_RANGES]
        self._levels = {sub: [0] * self.DIO_CHANNELS for sub in self.dio_subdevices}
        self._errno = 0
        # comedi_get_range returns a pointer valid until close; keep the structures alive.
        self._ranges = [ComediRange(lo, hi, 0) for lo, hi in self.RANGES]

    def comedi_open(self, path: bytes):
        assert isinstance(path, bytes)
        if self.fail_open:
            self._errno = 2
            return None                                # NULL
        handle = object()
        self.opened.append((path, handle))
        return handle

    def comedi_close(self, handle) -> int:
        self.closed.append(handle)
        return 0

    def _is_ao(self, subdevice: int) -> bool:
        return subdevice == 0 and not self._is_ai(0) and 0 not in self.dio_subdevices

    def _is_ai(self, subdevice: int) -> bool:
        return self.ai_source is not None and subdevice == self.AI_SUBDEVICE

    def comedi_get_n_channels(self, handle, subdevice: int) -> int:
        if self._is_ai(subdevice):
            return self.AI_CHANNELS
        if subdevice in self.dio_subdevices:
            return self.DIO_CHANNELS
        return self.AO_CHANNELS if subdevice == 0 else -1

    def comedi_get_maxdata(self, handle, subdevice: int, channel: int) -> int:
        return 4095 if subdevice == 0 and subdevice not in self.dio_subdevices else 1

    def comedi_get_range(self, handle, subdevice: int, channel: int, rng: int):
        if self._is_ai(subdevice):
            if not 0 <= rng < len(self._ai_ranges):
                return ctypes.POINTER(ComediRange)()
            return ctypes.pointer(self._ai_ranges[rng])
        if subdevice != 0 or subdevice in self.dio_subdevices or not 0 <= rng < len(self._ranges):
            return ctypes.POINTER(ComediRange)()       # NULL
        return ctypes.pointer(self._ranges[rng])

    def comedi_data_write(self, handle, subdevice, channel, rng, aref, data) -> int:
        if self.fail_writes or channel in self.fail_channels:
            self._errno = EIO
            return -1
        if not 0 <= data <= 4095:
            self._errno = EINVAL
            return -1
        if subdevice == 0:
            self.last_code[channel] = data
        if self.keep_log:
            self.writes.append((handle, subdevice, channel, rng, aref, data))
        return 1

    def comedi_do_insnlist(self, handle, insnlist) -> int:
        """``insnlist``: a ``POINTER(ComediInsnList)``, as ctypes passes ``comedi_insnlist *``.

        The instructions are what the list's memory holds at this call, as the kernel copies
        them in: the decoded list is reused only while the bytes of the pointer, the list and
        its instructions are unchanged (the twin writes the same list every cycle, and
        decoding ctypes structures costs microseconds); the samples are read every call."""
        plan = self._insn_plan
        if plan is None or plan[0] is not insnlist or not _unchanged(plan[1]):
            plan = self._insn_plan = self._decode_insnlist(insnlist)
        _, _, reads, samples, stop, n_insns = plan
        codes = reads[0][:] if len(reads) == 1 else [c for r in reads for c in r[:]]
        # Each sample as comedi_data_write writes it (same checks, same record), inline: a
        # method call per sample would double the double's cost in the twin's cycle.
        last, log, dead = self.last_code, self.writes if self.keep_log else None, \
            self.fail_channels
        for (insn, subdevice, channel, rng, aref), code in zip(samples, codes):
            if self.fail_writes or channel in dead:
                self._errno = EIO
                return insn if insn else -1
            if not 0 <= code <= 4095:
                self._errno = EINVAL
                return insn if insn else -1
            last[channel] = code                     # analog outputs: subdevice 0
            if log is not None:
                log.append((handle, subdevice, channel, rng, aref, code))
        if stop < n_insns:                           # an instruction this card refuses
            self._errno = EINVAL
            return stop if stop else -1
        return n_insns

    def _decode_insnlist(self, insnlist) -> tuple:
        """(the pointer; [(a live view, its bytes now)] of the pointer, the list and its
        instructions; the samples' memory as live ctypes arrays (one when they are
        contiguous, as the driver's are); per sample (instruction, subdevice, channel, range,
        aref); the first instruction this double refuses (or the count); the count). Refused
        (EINVAL): anything but an ``INSN_WRITE`` to an analog output channel and range the card
        has (the kernel refuses a chanspec outside the subdevice; this double writes analog
        outputs only); the samples of the instructions after it are never read."""
        lst = insnlist.contents
        n = lst.n_insns
        watched = [(ctypes.addressof(insnlist), ctypes.sizeof(insnlist)),
                   (ctypes.addressof(lst), ctypes.sizeof(lst))]
        samples: list[tuple[int, int, int, int, int]] = []
        spans: list[tuple[int, int]] = []            # (address, count) of each data array
        stop = n
        if n:
            watched.append((ctypes.addressof(lst.insns.contents),
                            n * ctypes.sizeof(ComediInsn)))
        for i in range(n):
            insn = lst.insns[i]
            spec = insn.chanspec
            channel, rng = cr_chan(spec), cr_range(spec)
            if not (insn.insn == INSN_WRITE and self._is_ao(insn.subdev)
                    and 0 <= channel < self.AO_CHANNELS and 0 <= rng < len(self.RANGES)):
                stop = i
                break
            if insn.n:
                address = ctypes.cast(insn.data, ctypes.c_void_p).value or 0
                word = ctypes.sizeof(ctypes.c_uint)
                if spans and spans[-1][0] + spans[-1][1] * word == address:
                    spans[-1] = (spans[-1][0], spans[-1][1] + insn.n)
                else:
                    spans.append((address, insn.n))
                samples += [(i, insn.subdev, channel, rng, cr_aref(spec))] * insn.n
        reads = [(ctypes.c_uint * count).from_address(address) for address, count in spans]
        views = [(ctypes.c_char * size).from_address(a) for a, size in watched]
        return insnlist, [(view, view.raw) for view in views], reads or [[]], samples, stop, n

    def _dio_ok(self, subdevice: int, channel: int) -> bool:
        if subdevice not in self.dio_subdevices or not 0 <= channel < self.DIO_CHANNELS:
            self._errno = 22
            return False
        return True

    def comedi_data_read(self, handle, subdevice, channel, rng, aref, data) -> int:
        """``data`` is a ``POINTER(c_uint)``: the code of ``ai_source(channel)`` volts."""
        if not self._is_ai(subdevice) or self.fail_ai_reads or not 0 <= rng < len(self.AI_RANGES):
            self._errno = 5 if self.fail_ai_reads else 22
            return -1
        assert self.ai_source is not None
        lo, hi = self.AI_RANGES[rng]
        data[0] = volts_to_code(self.ai_source(channel), lo, hi, 4095)
        return 1

    def comedi_dio_config(self, handle, subdevice, channel, direction) -> int:
        if not self._dio_ok(subdevice, channel):
            return -1
        self.dio_config.append((handle, subdevice, channel, direction))
        return 1

    def comedi_dio_write(self, handle, subdevice, channel, bit) -> int:
        if not self._dio_ok(subdevice, channel):
            return -1
        self.dio.append((handle, subdevice, channel, bit))
        self._levels[subdevice][channel] = 1 if bit else 0
        return 1

    def comedi_dio_read(self, handle, subdevice, channel, bit) -> int:
        """``bit`` is a ``POINTER(c_uint)``, as ctypes passes ``unsigned int *``."""
        if self.fail_dio_reads:
            self._errno = 5
            return -1
        if not self._dio_ok(subdevice, channel):
            return -1
        bit[0] = self._levels[subdevice][channel]
        return 1

    def set_input(self, subdevice: int, channel: int, level: int) -> None:
        """The outside world drives digital line ``channel`` of ``subdevice`` (0/1)."""
        self._levels[subdevice][channel] = 1 if level else 0

    def level(self, subdevice: int, channel: int) -> int:
        """The level of digital line ``channel`` of ``subdevice`` (0/1)."""
        return self._levels[subdevice][channel]

    def comedi_errno(self) -> int:
        return self._errno

    def comedi_strerror(self, errnum: int) -> bytes:
        return f"fake comedi error {errnum}".encode()

    def codes(self, n: int = 3) -> list[int | None]:
        """The last code written to each of channels 0..n-1 (None: never written)."""
        return [self.last_code.get(c) for c in range(n)]


class FakeComediSystem:
    """comedilib over several fake cards, each behind its device file (``{path: FakeComedi}``).

    ``comedi_open(path)`` opens that card (NULL and errno 2 for an unknown path); every other
    call goes to the card that owns its handle. The real drivers take it as their ``lib``.
    """

    def __init__(self, devices: Mapping[str, FakeComedi]) -> None:
        self.devices = dict(devices)
        self._owner: dict[Any, FakeComedi] = {}
        self._errno = 0
        self._last: FakeComedi | None = None

    def comedi_open(self, path: bytes):
        card = self.devices.get(path.decode())
        if card is None:
            self._errno, self._last = 2, None
            return None
        handle = card.comedi_open(path)
        if handle is not None:
            self._owner[handle] = card
        self._last = card
        return handle

    def __getattr__(self, name: str):
        if not name.startswith("comedi_"):
            raise AttributeError(name)

        def call(handle, *args):
            card = self._owner[handle]
            self._last = card
            return getattr(card, name)(handle, *args)
        return call

    def comedi_errno(self) -> int:
        return self._last.comedi_errno() if self._last is not None else self._errno

    def comedi_strerror(self, errnum: int) -> bytes:
        return f"fake comedi error {errnum}".encode()
