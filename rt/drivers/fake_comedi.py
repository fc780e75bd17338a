"""A comedilib double for the PCI-1720: the same function names, arguments and return
conventions as the C library, so the real driver code path (volts -> 12-bit codes) runs in tests
and in the digital twin without a card. ``FakeComediSystem`` puts several such cards behind
their device files, as one comedilib sees a machine's cards."""
from __future__ import annotations

import ctypes
import operator
from collections.abc import Callable, Iterator, Mapping, MutableMapping
from typing import Any

import numpy as np

from rt.drivers import kernels
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


class _CodeView(MutableMapping[int, int]):
    """``FakeComedi.last_code``: the analog outputs' codes as a mapping (channel → code; a
    channel never written is absent), a view of the double's code array (``FC_CODES``):
    writing or deleting through it changes the array that the twin and the compiled
    ``comedi_do_insnlist`` use."""

    def __init__(self, codes: np.ndarray) -> None:
        self._codes = codes

    def __getitem__(self, channel: int) -> int:
        try:
            c = operator.index(channel)
        except TypeError:
            raise KeyError(channel) from None
        if not 0 <= c < len(self._codes):
            raise KeyError(channel)
        code = int(self._codes[c])
        if code == kernels.FC_NO_CODE:
            raise KeyError(channel)
        return code

    def __setitem__(self, channel: int, code: int) -> None:
        if not 0 <= channel < len(self._codes):
            raise KeyError(f"the PCI-1720 has analog outputs 0-{len(self._codes) - 1}, "
                           f"not {channel}")
        if not 0 <= code <= kernels.FC_MAXDATA:
            raise ValueError(f"a 12-bit DAC code is 0-{kernels.FC_MAXDATA}, not {code}")
        self._codes[channel] = code

    def __delitem__(self, channel: int) -> None:
        self[channel]                                # KeyError when absent
        self._codes[channel] = kernels.FC_NO_CODE

    def __iter__(self) -> Iterator[int]:
        return iter([c for c in range(len(self._codes))
                     if self._codes[c] != kernels.FC_NO_CODE])

    def __len__(self) -> int:
        return int(np.count_nonzero(self._codes != kernels.FC_NO_CODE))


class _ChannelSet(set):
    """``FakeComedi.fail_channels``: a set of dead DAC channels that keeps the compiled
    state's mask (``FC_FAIL_MASK``) in step on every change, so the per-cycle write reads the
    mask without a Python step (tests add and remove channels mid-run)."""

    def __init__(self, st: np.ndarray, channels: Any = ()) -> None:
        super().__init__(channels)
        self._st = st
        self._sync()

    def _sync(self) -> None:
        self._st[kernels.FC_FAIL_MASK] = sum(
            1 << c for c in self if type(c) is int and 0 <= c < FakeComedi.AO_CHANNELS)


def _syncing(name: str) -> Callable:
    method = getattr(set, name)

    def call(self: _ChannelSet, *args: Any) -> Any:
        out = method(self, *args)
        self._sync()
        return self if name.startswith("__i") else out
    call.__name__ = name
    return call


for _name in ("add", "discard", "remove", "pop", "clear", "update", "difference_update",
              "intersection_update", "symmetric_difference_update",
              "__ior__", "__iand__", "__isub__", "__ixor__"):
    setattr(_ChannelSet, _name, _syncing(_name))


class _Plan:
    """A decoded instruction list: the pointer it came from, the memory it was decoded from
    (address, size), per sample (instruction, subdevice, channel, range, aref, address), the
    first instruction the double refuses (or the count), the count."""

    __slots__ = ("compiled", "insnlist", "n", "samples", "stop", "watched", "words")

    def __init__(self, insnlist: Any, watched: list[tuple[int, int]],
                 samples: list[tuple[int, int, int, int, int, int]], stop: int, n: int) -> None:
        self.insnlist = insnlist
        self.watched = watched
        self.samples = samples
        self.stop = stop
        self.n = n
        self.compiled = False
        # The words the watched memory held at decoding (the interpreted path compares them).
        self.words = [bytes((ctypes.c_char * size).from_address(a)) for a, size in watched]


class FakeComedi:
    """comedilib's functions with the same names, arguments and return conventions, for a
    PCI-1720 (adv_pci1720: subdevice 0 = AO, 4 channels, maxdata 4095, ranges 0-5, 0-10,
    ±5, ±10 V) plus digital-I/O subdevices (``dio_subdevices``, default 2; 8 lines each,
    configured as input or output with ``comedi_dio_config``, like an 8255 port) on the same
    "device". A digital I/O card alone is ``FakeComedi(dio_subdevices=(0, 1))``; an
    analog-input card (PCI-1711-like: 16 inputs, 12 bit, ranges ±10, ±5, ±2.5, ±1.25,
    ±0.625 V) is ``FakeComedi(ai_source=volts_of_channel)``, its inputs on subdevice 0.

    The analog outputs' last codes are the int64 array ``ao`` (``codes3``: channels 0-2, what
    the twin's amplifiers read; ``last_code`` is a mapping view of it); the list runs compiled
    (``rt.drivers.kernels.fake_insnlist``) with the interpreted reference
    :meth:`comedi_do_insnlist_interpreted` beside it.

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
        # The analog outputs' codes, the fault switches, errno and the decoded instruction
        # list in one int64 array (layout ``kernels.FC_*``): the compiled
        # ``comedi_do_insnlist`` takes it as its one argument, the twin reads ``ao``.
        self._st = np.zeros(kernels.FC_SIZE, dtype=np.int64)
        #: Each analog output's last code (int64[4], ``FC_NO_CODE`` = never written).
        self.ao = self._st[kernels.FC_CODES:kernels.FC_CODES + self.AO_CHANNELS]
        self.ao[:] = kernels.FC_NO_CODE
        # The twin keeps no log (it runs for hours); tests keep every write.
        self.keep_log = keep_log
        #: Channels 0-2's codes (the twin's amplifiers), a view of ``ao``.
        self.codes3 = self.ao[:3]
        self._last_code = _CodeView(self.ao)
        self.writes: list[tuple] = []
        self.dio: list[tuple] = []
        self.dio_config: list[tuple] = []
        self.opened: list[object] = []
        self.closed: list[object] = []
        self.fail_open = False
        self._fail_channels = _ChannelSet(self._st)
        self._insn_plan: _Plan | None = None
        self.fail_dio_reads = False
        self.dio_subdevices = tuple(dio_subdevices)
        self.ai_source = ai_source
        self.fail_ai_reads = False
        self._ai_ranges = [ComediRange(lo, hi, 0) for lo, hi in self.AI_RANGES]
        self._levels = {sub: [0] * self.DIO_CHANNELS for sub in self.dio_subdevices}
        # comedi_get_range returns a pointer valid until close; keep the structures alive.
        self._ranges = [ComediRange(lo, hi, 0) for lo, hi in self.RANGES]

    @property
    def last_code(self) -> MutableMapping[int, int]:
        """The last code written to each analog output (channel → code), a view of ``ao``."""
        return self._last_code

    @property
    def fail_channels(self) -> set[int]:
        """DAC channels whose writes fail (EIO); a set, changed in place or assigned."""
        return self._fail_channels

    @fail_channels.setter
    def fail_channels(self, channels: Any) -> None:
        self._fail_channels = _ChannelSet(self._st, channels)

    @property
    def keep_log(self) -> bool:
        """Every write is recorded in ``writes`` (tests; the twin keeps none)."""
        return self._st[kernels.FC_KEEP_LOG] != 0

    @keep_log.setter
    def keep_log(self, value: bool) -> None:
        self._st[kernels.FC_KEEP_LOG] = 1 if value else 0

    @property
    def fail_writes(self) -> bool:
        """Every analog-output write fails (EIO)."""
        return self._st[kernels.FC_FAIL_ALL] != 0

    @fail_writes.setter
    def fail_writes(self, value: bool) -> None:
        self._st[kernels.FC_FAIL_ALL] = 1 if value else 0

    @property
    def _errno(self) -> int:
        return int(self._st[kernels.FC_ERRNO])

    @_errno.setter
    def _errno(self, value: int) -> None:
        self._st[kernels.FC_ERRNO] = value

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
        if not 0 <= data <= 4095 or (self._is_ao(subdevice)
                                     and not 0 <= channel < self.AO_CHANNELS):
            self._errno = EINVAL
            return -1
        if subdevice == 0:
            self.ao[channel] = data
        if self.keep_log:
            self.writes.append((handle, subdevice, channel, rng, aref, data))
        return 1

    def comedi_do_insnlist(self, handle, insnlist) -> int:
        """``insnlist``: a ``POINTER(ComediInsnList)``, as ctypes passes ``comedi_insnlist *``.

        The instructions are what the list's memory holds at this call, as the kernel copies
        them in: the list is decoded into a plan once and the plan reused while the words of
        the pointer, the list and its instructions are unchanged (the twin writes the same list
        every cycle; decoding ctypes structures costs microseconds); the samples are read at
        every call. One compiled call (``kernels.fake_insnlist``) checks those words and
        writes the samples; a list too long for its table takes the interpreted reference
        (:meth:`comedi_do_insnlist_interpreted`), with the same answers."""
        plan = self._insn_plan
        if plan is None or plan.insnlist is not insnlist:
            plan = self._plan(insnlist)
        if not plan.compiled:
            return self.comedi_do_insnlist_interpreted(handle, insnlist)
        st = self._st
        rc = kernels.fake_insnlist(st)
        if rc == kernels.FC_STALE:                   # the list's memory changed: decode again
            plan = self._plan(insnlist)
            if not plan.compiled:
                return self.comedi_do_insnlist_interpreted(handle, insnlist)
            rc = kernels.fake_insnlist(st)
        if self.keep_log:
            self._log(handle, plan, int(st[kernels.FC_DONE]))
        return int(rc)

    def preplanned(self, insnlist) -> np.ndarray | None:
        """The state array ``kernels.fake_insnlist`` runs ``insnlist`` on, its plan decoded
        now (None when the list is too long for the compiled table): the driver's one
        compiled write (``kernels.pci1720_write_fake``) takes it, checks that the plan is its
        list's (the first watched word is the address of its pointer), and calls
        :meth:`comedi_do_insnlist` itself whenever the kernel answers ``FC_STALE``; with
        ``keep_log`` it then calls :meth:`log_last`. None too for a subclass with its own
        ``comedi_do_insnlist`` (a test's C stub): the driver must call that."""
        if type(self).comedi_do_insnlist is not FakeComedi.comedi_do_insnlist:
            return None
        plan = self._insn_plan
        if plan is None or plan.insnlist is not insnlist:
            plan = self._plan(insnlist)
        return self._st if plan.compiled else None

    def log_last(self, handle) -> None:
        """Record the samples the last compiled call wrote (``keep_log``)."""
        if self._insn_plan is not None:
            self._log(handle, self._insn_plan, int(self._st[kernels.FC_DONE]))

    def _log(self, handle, plan: _Plan, done: int) -> None:
        for insn, subdevice, channel, rng, aref, address in plan.samples[:done]:
            code = ctypes.c_uint.from_address(address).value
            self.writes.append((handle, subdevice, channel, rng, aref, code))

    def _plan(self, insnlist) -> _Plan:
        """Decode ``insnlist`` (:meth:`_decode_insnlist`) and, when it fits, put the plan into
        the compiled state: per sample (instruction, channel, address), the counts, and each
        watched 8-byte word with its value now."""
        plan = self._insn_plan = self._decode_insnlist(insnlist)
        st = self._st
        st[kernels.FC_N_WATCHED] = 0                 # a failed fit leaves no stale plan behind
        words = [(a + k, int.from_bytes(raw[k:k + 8], "little", signed=True))
                 for (a, size), raw in zip(plan.watched, plan.words) for k in range(0, size, 8)]
        if (len(plan.samples) > kernels.FC_MAX_SAMPLES or len(words) > kernels.FC_MAX_WATCHED
                or any(size % 8 for _, size in plan.watched)):
            return plan
        for s, (insn, _, channel, _, _, address) in enumerate(plan.samples):
            p = kernels.FC_PLAN + 3 * s
            st[p:p + 3] = (insn, channel, address)
        for k, (address, word) in enumerate(words):
            w = kernels.FC_WATCH + 2 * k
            st[w:w + 2] = (address, word)
        st[kernels.FC_N_INSNS] = plan.n
        st[kernels.FC_STOP] = plan.stop
        st[kernels.FC_N_SAMPLES] = len(plan.samples)
        st[kernels.FC_N_WATCHED] = len(words)
        plan.compiled = True
        return plan

    def comedi_do_insnlist_interpreted(self, handle, insnlist) -> int:
        """:meth:`comedi_do_insnlist` in Python (the reference of the compiled call): each
        sample as ``comedi_data_write`` writes it (same checks, same record), stopping at the
        first that fails; then a refused instruction answers EINVAL."""
        plan = self._insn_plan
        if plan is None or plan.insnlist is not insnlist or any(
                bytes((ctypes.c_char * size).from_address(a)) != raw
                for (a, size), raw in zip(plan.watched, plan.words)):
            plan = self._plan(insnlist)
        dead = self.fail_channels
        for insn, subdevice, channel, rng, aref, address in plan.samples:
            code = ctypes.c_uint.from_address(address).value
            if self.fail_writes or channel in dead:
                self._errno = EIO
                return insn if insn else -1
            if not 0 <= code <= 4095:
                self._errno = EINVAL
                return insn if insn else -1
            self.ao[channel] = code                  # analog outputs: subdevice 0
            if self.keep_log:
                self.writes.append((handle, subdevice, channel, rng, aref, code))
        if plan.stop < plan.n:                       # an instruction this card refuses
            self._errno = EINVAL
            return plan.stop if plan.stop else -1
        return plan.n

    def _decode_insnlist(self, insnlist) -> _Plan:
        """The plan of ``insnlist`` (:class:`_Plan`). Refused (EINVAL): anything but an
        ``INSN_WRITE`` to an analog output channel and range the card has (the kernel refuses
        a chanspec outside the subdevice; this double writes analog outputs only); the
        samples of the instructions after it are never read."""
        lst = insnlist.contents
        n = lst.n_insns
        watched = [(ctypes.addressof(insnlist), ctypes.sizeof(insnlist)),
                   (ctypes.addressof(lst), ctypes.sizeof(lst))]
        samples: list[tuple[int, int, int, int, int, int]] = []
        stop = n
        if n:
            watched.append((ctypes.addressof(lst.insns.contents),
                            n * ctypes.sizeof(ComediInsn)))
        word = ctypes.sizeof(ctypes.c_uint)
        for i in range(n):
            insn = lst.insns[i]
            spec = insn.chanspec
            channel, rng = cr_chan(spec), cr_range(spec)
            if not (insn.insn == INSN_WRITE and self._is_ao(insn.subdev)
                    and 0 <= channel < self.AO_CHANNELS and 0 <= rng < len(self.RANGES)):
                stop = i
                break
            address = ctypes.cast(insn.data, ctypes.c_void_p).value or 0
            samples += [(i, insn.subdev, channel, rng, cr_aref(spec), address + j * word)
                        for j in range(insn.n)]
        return _Plan(insnlist, watched, samples, stop, n)

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
        return [self._last_code.get(c) for c in range(n)]


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
