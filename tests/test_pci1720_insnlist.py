"""The PCI-1720's cycle write as one ``comedi_do_insnlist`` (issue 16): the ctypes structures
against the kernel's uapi header, the instruction list through a real C function, the
comedilib double's semantics (the count done; -1 when the first instruction fails), and a
partial write treated as a failed write by the driver and by the redundant drive."""
from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from rt.components.safety_blocks import RedundantDrive
from rt.drivers.fake_comedi import EINVAL, EIO, FakeComedi
from rt.drivers.pci1720 import (
    AREF_GROUND,
    INSN_WRITE,
    RANGE_BIPOLAR_10V,
    ComediInsn,
    ComediInsnList,
    Pci1720Outputs,
    comedilib_prototypes,
    cr_pack,
    volts_to_code,
)
from rt.errors import HardwareError
from rt.safety.events import EventLog

HEADER = Path("/usr/include/linux/comedi.h")
ZERO_CODE = 2048
needs_cc = pytest.mark.skipif(shutil.which("cc") is None or not HEADER.exists(),
                              reason="needs a C compiler and linux/comedi.h")


def _build(tmp_path: Path, source: str, name: str, shared: bool) -> Path:
    c = tmp_path / f"{name}.c"
    c.write_text(source)
    out = tmp_path / (f"lib{name}.so" if shared else name)
    flags = ["-shared", "-fPIC"] if shared else []
    subprocess.run(["cc", "-O1", *flags, "-o", str(out), str(c)], check=True,
                   capture_output=True, timeout=60)
    return out


@needs_cc
def test_the_structures_and_constants_are_the_kernel_headers(tmp_path):
    """sizeof/offsetof of ``struct comedi_insn`` and ``struct comedi_insnlist``, INSN_WRITE and
    CR_PACK as the C compiler sees ``linux/comedi.h`` on this machine."""
    exe = _build(tmp_path, r"""
#include <stdio.h>
#include <stddef.h>
#include <linux/comedi.h>
int main(void) {
    printf("%zu %zu %zu %zu %zu %zu %zu %zu %zu %zu %u %u\n",
           sizeof(struct comedi_insn), offsetof(struct comedi_insn, insn),
           offsetof(struct comedi_insn, n), offsetof(struct comedi_insn, data),
           offsetof(struct comedi_insn, subdev), offsetof(struct comedi_insn, chanspec),
           offsetof(struct comedi_insn, unused), sizeof(struct comedi_insnlist),
           offsetof(struct comedi_insnlist, n_insns), offsetof(struct comedi_insnlist, insns),
           (unsigned)INSN_WRITE, (unsigned)CR_PACK(2, 3, AREF_GROUND));
    return 0;
}
""", "layout", shared=False)
    got = [int(x) for x in subprocess.run([str(exe)], check=True, capture_output=True,
                                          text=True, timeout=30).stdout.split()]
    ours = [ctypes.sizeof(ComediInsn), *(getattr(ComediInsn, f).offset
                                         for f in ("insn", "n", "data", "subdev", "chanspec",
                                                   "unused")),
            ctypes.sizeof(ComediInsnList), ComediInsnList.n_insns.offset,
            ComediInsnList.insns.offset, INSN_WRITE, cr_pack(2, 3, AREF_GROUND)]
    assert ours == got


_STUB = r"""
#include <linux/comedi.h>
/* comedi_do_insnlist's signature with the header's structures: records what it was given. */
unsigned int seen[16][5];
unsigned int seen_n;
int answer = -2;            /* -2: the count of instructions; else this value */
int comedi_do_insnlist(void *dev, struct comedi_insnlist *list) {
    seen_n = list->n_insns;
    for (unsigned int i = 0; i < list->n_insns && i < 16; i++) {
        struct comedi_insn *in = &list->insns[i];
        seen[i][0] = in->insn; seen[i][1] = in->n; seen[i][2] = in->subdev;
        seen[i][3] = in->chanspec; seen[i][4] = in->n ? in->data[0] : 0xFFFFFFFFu;
    }
    return answer == -2 ? (int)list->n_insns : answer;
}
"""


class _CLib(FakeComedi):
    """The double for everything else; ``comedi_do_insnlist`` is the C stub, declared with
    the driver's own ctypes prototype (so ctypes checks and converts the argument)."""

    def __init__(self, so: Path) -> None:
        super().__init__()
        self.c = ctypes.CDLL(str(so))
        fn = self.c.comedi_do_insnlist
        fn.restype, fn.argtypes = comedilib_prototypes()["comedi_do_insnlist"]
        self._fn = fn

    def comedi_do_insnlist(self, handle, insnlist) -> int:
        return self._fn(None, insnlist)

    def seen(self) -> list[list[int]]:
        n = ctypes.c_uint.in_dll(self.c, "seen_n").value
        table = ((ctypes.c_uint * 5) * 16).in_dll(self.c, "seen")
        return [list(table[i]) for i in range(n)]


@needs_cc
def test_the_instruction_list_reaches_c_as_the_header_declares_it(tmp_path):
    lib = _CLib(_build(tmp_path, _STUB, "stub", shared=True))
    dac = Pci1720Outputs(lib=lib, channels=(2, 0, 3))
    dac.enable()
    volts = np.array([1.0, -2.5, 5.9])
    dac.write_volts(volts)
    assert lib.seen() == [[INSN_WRITE, 1, 0, cr_pack(ch, RANGE_BIPOLAR_10V, AREF_GROUND),
                           volts_to_code(v)] for ch, v in zip((2, 0, 3), volts)]
    assert dac.last_codes == [volts_to_code(v) for v in volts]
    # What C answers decides: fewer than three done is a failed write naming the channel.
    ctypes.c_int.in_dll(lib.c, "answer").value = 1
    with pytest.raises(HardwareError, match="channel 0 failed"):
        dac.write_volts(np.array([0.5, 0.5, 0.5]))
    assert dac.last_codes == [volts_to_code(0.5), volts_to_code(-2.5), volts_to_code(5.9)]
    ctypes.c_int.in_dll(lib.c, "answer").value = -1
    with pytest.raises(HardwareError, match="channel 2 failed"):
        dac.write_volts(np.array([0.7, 0.7, 0.7]))
    assert dac.last_codes == [volts_to_code(0.5), volts_to_code(-2.5), volts_to_code(5.9)]


def _write_list(lib: FakeComedi, handle, specs: list[tuple[int, int, int, list[int]]]) -> int:
    """``comedi_do_insnlist`` of instructions (insn, subdev, chanspec, samples)."""
    insns = (ComediInsn * len(specs))()
    keep = []
    for i, (insn, sub, spec, samples) in enumerate(specs):
        data = (ctypes.c_uint * max(1, len(samples)))(*samples)
        keep.append(data)
        insns[i].insn, insns[i].n, insns[i].subdev, insns[i].chanspec = \
            insn, len(samples), sub, spec
        insns[i].data = ctypes.cast(data, ctypes.POINTER(ctypes.c_uint))
    return lib.comedi_do_insnlist(handle, ctypes.pointer(ComediInsnList(len(specs), insns)))


def test_the_double_answers_the_count_done_and_stops_at_the_first_failure():
    lib = FakeComedi()
    h = lib.comedi_open(b"/dev/comedi0")
    spec = [cr_pack(c, 3, 0) for c in range(4)]
    assert _write_list(lib, h, [(INSN_WRITE, 0, spec[c], [100 + c]) for c in range(3)]) == 3
    assert lib.codes(4) == [100, 101, 102, None]
    assert [w[1:] for w in lib.writes] == [(0, c, 3, 0, 100 + c) for c in range(3)]
    # Several samples in one instruction: each written in turn (the last one stays).
    assert _write_list(lib, h, [(INSN_WRITE, 0, spec[3], [7, 8, 9])]) == 1
    assert lib.codes(4)[3] == 9
    # A dead channel part-way: the instructions before it are done and counted, none after.
    lib.fail_channels = {1}
    n = len(lib.writes)
    assert _write_list(lib, h, [(INSN_WRITE, 0, spec[c], [200 + c]) for c in range(3)]) == 1
    assert lib.codes(3) == [200, 101, 102] and len(lib.writes) == n + 1
    assert lib.comedi_errno() == EIO
    # The first instruction failing: -1, nothing written.
    assert _write_list(lib, h, [(INSN_WRITE, 0, spec[1], [5]),
                                (INSN_WRITE, 0, spec[0], [6])]) == -1
    assert lib.codes(3) == [200, 101, 102]
    lib.fail_channels = set()
    # Refused with EINVAL: a code beyond 12 bits, a channel or range the card does not have,
    # another subdevice, an instruction other than a write.
    for bad in ((INSN_WRITE, 0, spec[0], [4096]), (INSN_WRITE, 0, cr_pack(4, 3, 0), [1]),
                (INSN_WRITE, 0, cr_pack(0, 4, 0), [1]), (INSN_WRITE, 2, spec[0], [1]),
                (0x4000000, 0, spec[0], [1])):                 # INSN_READ
        assert _write_list(lib, h, [(INSN_WRITE, 0, spec[2], [300]), bad]) == 1
        assert lib.comedi_errno() == EINVAL
    assert lib.codes(3) == [200, 101, 300]
    assert _write_list(lib, h, []) == 0


@pytest.mark.parametrize("dead", [0, 1, 2])
def test_a_partial_write_is_a_failed_write_leaving_what_the_channel_by_channel_write_leaves(
        dead):
    libs = (FakeComedi(), FakeComedi())
    cards = [Pci1720Outputs(lib=lib) for lib in libs]
    for card in cards:
        card.enable()
        card.write_volts(np.array([1.0, 2.0, 3.0]))
    for lib in libs:
        lib.fail_channels = {dead}
    volts = np.array([-1.0, 7.0, -2.0])                # channel 1 beyond the 6 V limit
    errors = []
    for write in (cards[0].write_volts, cards[1].write_volts_interpreted):
        with pytest.raises(HardwareError) as info:
            write(volts)
        errors.append(str(info.value))
    assert errors[0] == errors[1] == f"DAC write on /dev/comedi0 channel {dead} failed: " \
                                     f"fake comedi error {EIO}"
    assert cards[0].last_codes == cards[1].last_codes
    assert cards[0].last_volts == cards[1].last_volts
    assert cards[0].clamped == cards[1].clamped
    assert [w[1:] for w in libs[0].writes] == [w[1:] for w in libs[1].writes]
    new = [volts_to_code(-1.0), volts_to_code(6.0), volts_to_code(-2.0)]
    old = [volts_to_code(1.0), volts_to_code(2.0), volts_to_code(3.0)]
    assert cards[0].last_codes == new[:dead] + old[dead:]
    assert libs[0].codes() == new[:dead] + old[dead:]


class _LinuxAnswer(FakeComedi):
    """The Linux ioctl's answer to a list that fails part-way: -1, though the instructions
    before the failing one were done."""

    def comedi_do_insnlist(self, handle, insnlist) -> int:
        done = super().comedi_do_insnlist(handle, insnlist)
        return -1 if done != insnlist.contents.n_insns else done


def test_minus_one_after_a_partial_list_is_a_failed_write_too():
    lib = _LinuxAnswer()
    card = Pci1720Outputs(lib=lib)
    card.enable()
    lib.fail_channels = {2}
    with pytest.raises(HardwareError, match="failed"):
        card.write_volts(np.array([1.0, 1.0, 1.0]))
    # The driver claims nothing written (the card is failed over and zeroed anyway).
    assert card.last_codes == [ZERO_CODE] * 3


def test_a_double_without_insnlist_writes_channel_by_channel():
    class _Old(FakeComedi):
        comedi_do_insnlist = None

    lib = _Old()
    card = Pci1720Outputs(lib=lib)
    assert card._do_insnlist is None
    card.enable()
    card.write_volts(np.array([1.0, -1.0, 0.5]))
    assert lib.codes() == [volts_to_code(1.0), volts_to_code(-1.0), volts_to_code(0.5)]


def test_the_redundant_drive_fails_over_on_a_partial_write():
    """Card 0's channel 2 dies: the list writes channels 0 and 1 and stops. The drive takes
    that as a failed write: card 1 takes over in the same cycle with the command, card 0 is
    zeroed (its live channels back at 0 V) and disabled, one failover event."""
    libs = (FakeComedi(), FakeComedi())
    cards = [Pci1720Outputs(device=f"/dev/comedi{i}", lib=lib) for i, lib in enumerate(libs)]
    log = EventLog()
    blk = RedundantDrive("drive", cards, log)
    command = np.array([1.0, -0.5, 2.0])
    command.flags.writeable = False
    blk.volts.data = command
    blk.enable.data = np.ones(1)
    blk.on_start()
    blk.update(0.0, 1e-3)
    assert libs[0].codes() == [volts_to_code(v) for v in command]
    libs[0].fail_channels = {2}
    second = np.array([1.5, -1.0, 2.5])
    second.flags.writeable = False
    blk.volts.data = second
    blk.update(1e-3, 1e-3)
    assert blk.active_card.data[0] == 1.0 and blk.failed.data[0] == 0.0
    assert libs[1].codes() == [volts_to_code(v) for v in second]
    assert cards[1].enabled and not cards[0].enabled
    assert libs[0].codes() == [ZERO_CODE, ZERO_CODE, volts_to_code(2.0)]   # dead: kept
    events = log.snapshot()
    assert [e.cause for e in events] == ["dac_card_0"]
    assert "write failed: DAC write on /dev/comedi0 channel 2 failed" in events[0].message
    assert blk._last.tolist() == second.tolist()


def test_insnlist_prototype_is_declared_for_the_real_library():
    restype, argtypes = comedilib_prototypes()["comedi_do_insnlist"]
    assert restype is ctypes.c_int
    assert argtypes == (ctypes.c_void_p, ctypes.POINTER(ComediInsnList))


def _random_specs(rng: np.random.Generator) -> list[tuple[int, int, int, list[int]]]:
    """A random instruction list: mostly analog-output writes, sometimes a refused one (a
    read, another subdevice, a channel or range the card lacks), 0-3 samples each, now and
    then a code beyond 12 bits."""
    specs = []
    for _ in range(int(rng.integers(0, 6))):
        kind = rng.random()
        insn, sub = INSN_WRITE, 0
        chan, rng_i = int(rng.integers(0, 4)), int(rng.integers(0, 4))
        if kind < 0.05:
            insn = 0x4000000                           # INSN_READ
        elif kind < 0.10:
            sub = 2
        elif kind < 0.15:
            chan = 4
        elif kind < 0.20:
            rng_i = 4
        samples = [int(c) for c in rng.integers(0, 4096, int(rng.integers(0, 4)))]
        if samples and rng.random() < 0.05:
            samples[-1] = 4096 + int(rng.integers(0, 100))
        specs.append((insn, sub, cr_pack(chan, rng_i, int(rng.integers(0, 4))), samples))
    return specs


def test_the_compiled_double_answers_as_the_interpreted_one_on_random_lists():
    """``comedi_do_insnlist`` (compiled: ``kernels.fake_insnlist`` on the double's plan) and
    ``comedi_do_insnlist_interpreted`` (the reference) on 400 random lists, with random dead
    channels and whole-card failures switched between them: the same answers, errno, codes and
    log, every call."""
    rng = np.random.default_rng(16)
    libs = (FakeComedi(), FakeComedi())
    handles = [lib.comedi_open(b"/dev/comedi0") for lib in libs]
    calls = (FakeComedi.comedi_do_insnlist, FakeComedi.comedi_do_insnlist_interpreted)
    partial = refused = 0
    for k in range(400):
        dead = {int(c) for c in rng.integers(0, 5, int(rng.integers(0, 3)))} \
            if rng.random() < 0.3 else set()
        fail_all = rng.random() < 0.03
        specs = _random_specs(rng)
        answers = []
        for lib, h, call in zip(libs, handles, calls):
            lib.fail_channels = set(dead)
            lib.fail_writes = fail_all
            answers.append((call_list(lib, h, specs, call), lib.comedi_errno()))
        assert answers[0] == answers[1], f"list {k}: {specs}"
        assert libs[0].ao.tolist() == libs[1].ao.tolist(), f"list {k}"
        assert [w[1:] for w in libs[0].writes] == [w[1:] for w in libs[1].writes], f"list {k}"
        partial += 0 < answers[0][0] < len(specs) or answers[0][0] == -1
        refused += answers[0][1] == EINVAL
    assert partial > 20 and refused > 20                # both kinds of stop were exercised


def call_list(lib: FakeComedi, handle, specs, call) -> int:
    """``call`` (either implementation) on the instruction list ``specs``, built as
    :func:`_write_list` builds it."""
    insns = (ComediInsn * max(1, len(specs)))()
    keep = []
    for i, (insn, sub, spec, samples) in enumerate(specs):
        data = (ctypes.c_uint * max(1, len(samples)))(*samples)
        keep.append(data)
        insns[i].insn, insns[i].n, insns[i].subdev, insns[i].chanspec = \
            insn, len(samples), sub, spec
        insns[i].data = ctypes.cast(data, ctypes.POINTER(ctypes.c_uint))
    return call(lib, handle, ctypes.pointer(ComediInsnList(len(specs), insns)))


def test_the_double_sees_a_list_changed_in_place_and_new_dead_channels():
    """The driver's own list, reused every cycle: a dead channel added in place (the set's
    ``add``) fails the next write; an instruction edited in place (another channel) is
    decoded again (the plan's words changed), as the kernel copies the list at each call."""
    lib = FakeComedi(keep_log=False)
    card = Pci1720Outputs(lib=lib)
    card.enable()
    card.write_volts(np.array([1.0, 2.0, 3.0]))
    assert lib.codes() == [volts_to_code(v) for v in (1.0, 2.0, 3.0)]
    lib.fail_channels.add(2)
    with pytest.raises(HardwareError, match="channel 2 failed"):
        card.write_volts(np.array([0.5, 0.5, 0.5]))
    assert lib.codes() == [volts_to_code(0.5), volts_to_code(0.5), volts_to_code(3.0)]
    lib.fail_channels.discard(2)
    card.write_volts(np.array([0.25, 0.25, 0.25]))
    assert lib.codes() == [volts_to_code(0.25)] * 3
    card._insns[2].chanspec = cr_pack(3, RANGE_BIPOLAR_10V, AREF_GROUND)
    card.write_volts(np.array([-1.0, -1.0, -1.0]))
    assert lib.codes(4) == [volts_to_code(-1.0)] * 2 + [volts_to_code(0.25),
                                                        volts_to_code(-1.0)]
    # Another driver on the same double takes the plan; the first one's write still lands.
    other = Pci1720Outputs(lib=lib)
    other.enable()
    other.write_volts(np.array([0.0, 0.0, 0.0]))
    card.write_volts(np.array([2.0, 2.0, 2.0]))
    assert lib.codes(4) == [volts_to_code(2.0)] * 2 + [volts_to_code(0.0), volts_to_code(2.0)]


def test_last_code_is_a_view_of_the_code_array():
    lib = FakeComedi()
    assert dict(lib.last_code) == {} and lib.codes() == [None, None, None]
    lib.last_code[1] = 4000
    assert lib.ao.tolist() == [-1, 4000, -1, -1] and lib.last_code.get(1) == 4000
    assert lib.last_code.pop(1) == 4000 and lib.last_code.pop(1, None) is None
    with pytest.raises(KeyError):
        lib.last_code[4] = 1
    with pytest.raises(ValueError):
        lib.last_code[0] = 4096
    assert lib.ao.tolist() == [-1] * 4
