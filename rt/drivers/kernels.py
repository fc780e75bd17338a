"""The drivers' per-cycle arithmetic compiled (issue 16): one call per device block and cycle.

The loop reads the encoder card and writes the DAC card every cycle. In Python that was nine
``inb`` calls and their byte decoding, and a validation loop and three code conversions per
write: tens of interpreted operations per cycle for what is integer and float arithmetic on a
handful of numbers. These kernels do the same operations, in the same order, on preallocated
arrays, so their results are bit for bit the interpreted ones (``tests/test_device_compiled.py``
replays recorded cycles through both):

* :func:`fake_pcl833_read`: the emulated PCL-833 answering a block of byte reads
  (``FakePcl833Port.read_block``), latch included;
* :func:`fake_pcl833_move`, :func:`fake_pcl833_positions`: the emulated card's counters fed
  with the encoders' new indices (the twin's encoder model, ``set_positions_m``);
* :func:`pcl833_decode`: the driver's decoding of the latched bytes (24-bit count, unwrap,
  slider position: ``Pcl833Encoders.read_positions_m``);
* :func:`pci1720_codes`: the PCI-1720 driver's validation, clamp and 12-bit codes
  (``Pci1720Outputs.write_volts``), written straight into the samples of the driver's
  instruction list; the one ``comedi_do_insnlist`` call itself stays behind the driver's
  ``lib`` (ctypes on the rig, the fake in the twin);
* :func:`dac_code`, :func:`dac_code_volts`: the volts → code quantizer and its inverse, shared
  by the driver and the pre-flight's DAC stage (``rt.preflight.stages``);
* :func:`fake_insnlist`: the comedilib double's ``comedi_do_insnlist`` (the twin's DAC cards)
  on its decoded plan, its codes in an array the twin reads; :func:`pci1720_write_fake`: the
  driver's codes and that list in one call (the twin's whole DAC write).

The real port I/O and comedilib calls are not here: they stay behind ``PortIO`` and the
driver's ``lib``, as on the rig.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rt.pointers import i64_at, u32_at

# --- the emulated PCL-833's state (int64 array; rt.drivers.fake_pcl833) ---------------------
FAKE_REG = 0            # 16: last byte written to each write register
FAKE_COUNT = 16         # 3: live counters
FAKE_LATCHED = 19       # 3: latched counters (what the count bytes read)
FAKE_INDEX = 22         # 3: encoder position in counts from q = 0
FAKE_FROZEN = 25        # 3: fault injection, 1 = frozen
FAKE_BASE = 28          # the card's base port (read by the block read: one argument less)
FAKE_STRICT = 29        # 1: an undecoded port is an error (else it reads 0xFF)
FAKE_SIZE = 30

_COUNTER_MASK = (1 << 24) - 1
_HALF_RANGE = 1 << 23
_REG_COUNTER_RESET = 7
_REG_STATUS = 14
_LATCH_SOURCE_MASK = 0x07
_LATCH_SOURCE_SOFTWARE_READ = 0

# --- PCI-1720 write outcome (``pci1720_codes``' answer) --------------------------------------
DAC_WRITTEN = 0             # the codes are in the instruction buffer, ready to write
DAC_NOT_FINITE = -1         # a command is NaN or infinite: nothing written
DAC_DISABLED = -2           # a non-zero command while disabled: nothing written


@njit(cache=True)
def fake_pcl833_read(st, ports, out):
    """``inb`` of each of ``ports`` in order into ``out`` (``FakePcl833Port.inb``): a high
    byte read latches its channel (software-read latch source), count bytes read the latch,
    overflow and status read 0. Returns -1, or the index of the first port the card does not
    decode when the card is strict (the reads before it happened); an undecoded port reads
    0xFF otherwise. The base port and strictness are read from ``st``."""
    base = st[FAKE_BASE]
    strict = st[FAKE_STRICT] != 0
    for k in range(ports.shape[0]):
        offset = ports[k] - base
        if 0 <= offset < 12 and offset % 4 != 3:
            channel = offset // 4
            byte = offset % 4
            if byte == 2 and (st[FAKE_REG + 3 + channel] & _LATCH_SOURCE_MASK) \
                    == _LATCH_SOURCE_SOFTWARE_READ:
                st[FAKE_LATCHED + channel] = st[FAKE_COUNT + channel]
            out[k] = (st[FAKE_LATCHED + channel] >> (8 * byte)) & 0xFF
        elif 0 <= offset < 12 or offset == _REG_STATUS:
            out[k] = 0
        elif strict:
            return k
        else:
            out[k] = 0xFF
    return -1


@njit(cache=True)
def _counting(st, axis):
    mode = st[FAKE_REG + axis] & 0x07
    held = (st[FAKE_REG + _REG_COUNTER_RESET] >> axis) & 1
    return mode != 0 and held == 0 and st[FAKE_FROZEN + axis] == 0


@njit(cache=True)
def fake_pcl833_move(st, new_index):
    """The encoders now at ``new_index`` (counts from q = 0, floats holding integers): each
    axis' change since the last call goes to its counter as pulses (dropped while the channel
    is disabled, held in reset or frozen), wrapping modulo 2**24."""
    for axis in range(3):
        new = int(new_index[axis])
        delta = new - st[FAKE_INDEX + axis]
        if delta != 0:
            st[FAKE_INDEX + axis] = new
            if _counting(st, axis):
                st[FAKE_COUNT + axis] = (st[FAKE_COUNT + axis] + delta) & _COUNTER_MASK


@njit(cache=True)
def fake_pcl833_positions(st, sign_mpc, positions_m):
    """``FakePcl833Port.set_positions_m``: the encoder index ``floor(sign·q/mpc + 0.5)`` per
    axis (``sign_mpc``: the three signs, then the three m per count), fed as pulses. Returns
    -1, or the first axis whose position is not finite (nothing after it is moved)."""
    for axis in range(3):
        if not math.isfinite(positions_m[axis]):
            return axis
        new = math.floor(sign_mpc[axis] * positions_m[axis] / sign_mpc[3 + axis] + 0.5)
        delta = new - st[FAKE_INDEX + axis]
        if delta != 0:
            st[FAKE_INDEX + axis] = new
            if _counting(st, axis):
                st[FAKE_COUNT + axis] = (st[FAKE_COUNT + axis] + delta) & _COUNTER_MASK
    return -1


@njit(cache=True)
def fake_pcl833_set_counts(st, counts, offsets):
    """``FakePcl833Port.set_count`` for the three axes: each live counter preset to
    ``counts + offsets`` modulo 2**24, then the reset hold (a held channel keeps its reset
    value: 0x800000 with the mode register's "middle" bit, else 0)."""
    for axis in range(3):
        st[FAKE_COUNT + axis] = (int(counts[axis]) + offsets[axis]) & _COUNTER_MASK
    for axis in range(3):
        if (st[FAKE_REG + _REG_COUNTER_RESET] >> axis) & 1:
            st[FAKE_COUNT + axis] = _HALF_RANGE if st[FAKE_REG + axis] & 0x08 else 0


# --- the PCL-833 driver's read buffer (int64 array; rt.drivers.pcl833) ------------------------
PCL_RAW = 0             # 9: each axis' bytes in read order (high, low, middle)
PCL_UNWRAP = 9          # 6: each axis' last count and displacement (``CountUnwrapper``)
PCL_IO_SIZE = 15


@njit(cache=True)
def pcl833_decode(io, dec, out):
    """Slider positions (m) into ``out`` from one read of the three channels: ``io`` holds the
    bytes read and each axis' (last count, displacement), updated in place
    (``CountUnwrapper.update``; layout ``PCL_*``), ``dec`` the signs, the origins (m) and the
    m per count. ``origin + sign·displacement·mpc``, as the driver computes it."""
    for i in range(3):
        r = PCL_RAW + 3 * i
        count = ((io[r] << 16) | (io[r + 2] << 8) | io[r + 1]) & _COUNTER_MASK
        u = PCL_UNWRAP + 2 * i
        step = ((count - io[u] + _HALF_RANGE) & _COUNTER_MASK) - _HALF_RANGE
        displacement = io[u + 1] + step
        io[u] = count
        io[u + 1] = displacement
        out[i] = dec[3 + i] + (dec[i] * displacement) * dec[6 + i]


# --- the PCI-1720 driver's output state (float64 array; rt.drivers.pci1720) ------------------
DAC_CODES = 0           # 3: codes of the last write (floats holding integers)
DAC_VOLTS = 3           # 3: the voltages they produce (V)
DAC_CLAMPED = 6         # 3: 1 where the last write hit the command limit
DAC_BACKUP = 9          # 9: the three above before the last write (restored on a failed write)
DAC_ENABLED = 18        # 1 when the driver is enabled (non-zero commands allowed)
DAC_LIMIT = 19          # the command limit (V)
DAC_RANGES = 20         # 9: (v_min, v_max, maxdata) per channel
DAC_STATE_SIZE = 29


@njit(cache=True)
def dac_code(volts, limit, v_min, v_max, maxdata):
    """The DAC code (a float holding an integer) for a command of ``volts`` (V): clamped to
    ±``limit``, scaled onto the channel's range [``v_min``, ``v_max``] V and rounded as
    ``comedi_from_phys`` does, ``floor((V − v_min)/(v_max − v_min)·maxdata + 0.5)``, clamped
    to 0..``maxdata``. The one quantizer of the drive path: the driver's compiled write
    (:func:`pci1720_codes`) and the pre-flight's DAC stage (``rt.preflight.stages.dac_stage``)
    both call it; ``rt.drivers.pci1720.volts_to_code`` is its interpreted reference (without
    the limit, which the driver applies before calling it)."""
    v = min(limit, max(-limit, volts))
    s = (v - v_min) / (v_max - v_min) * maxdata
    if s <= 0.0:
        return 0.0
    if s >= maxdata:
        return maxdata
    return float(math.floor(s + 0.5))


@njit(cache=True)
def dac_code_volts(code, v_min, v_max, maxdata):
    """The voltage (V) DAC ``code`` produces (``comedi_to_phys``; ``code_to_volts``)."""
    return v_min + code / maxdata * (v_max - v_min)


@njit(cache=True)
def pci1720_codes(volts, dac, data):
    """``Pci1720Outputs.write_volts``' arithmetic for the three axes: every command finite
    (else :data:`DAC_NOT_FINITE`), no non-zero command while disabled (else
    :data:`DAC_DISABLED`); nothing is changed then. Otherwise, per channel: the clamp flag,
    the code (:func:`dac_code`) and the voltage it produces into ``dac`` (layout ``DAC_*``; the
    previous values go to its backup; the enable flag, the limit and the channels' ranges are
    read from it: one array argument, as numba's dispatch costs per argument), and the code
    into ``data`` (uint32[3]: the samples of the driver's three ``INSN_WRITE`` instructions,
    which ``comedi_do_insnlist`` then writes in one call). Returns :data:`DAC_WRITTEN`, or a
    refusal (< 0)."""
    enabled = dac[DAC_ENABLED] != 0.0
    limit = dac[DAC_LIMIT]
    nonzero = False
    for i in range(3):
        v = volts[i]
        if not math.isfinite(v):
            return DAC_NOT_FINITE
        if v != 0.0:
            nonzero = True
    if nonzero and not enabled:
        return DAC_DISABLED
    for k in range(9):
        dac[DAC_BACKUP + k] = dac[k]
    for i in range(3):
        v = volts[i]
        dac[DAC_CLAMPED + i] = 0.0 if -limit <= v <= limit else 1.0
        v_min = dac[DAC_RANGES + 3 * i]
        v_max = dac[DAC_RANGES + 3 * i + 1]
        maxdata = dac[DAC_RANGES + 3 * i + 2]
        code = dac_code(v, limit, v_min, v_max, maxdata)
        dac[DAC_CODES + i] = code
        dac[DAC_VOLTS + i] = dac_code_volts(code, v_min, v_max, maxdata)
        data[i] = int(code)
    return DAC_WRITTEN


# --- the comedilib double's analog outputs and instruction lists (int64 array; fake_comedi) ---
# ``FakeComedi`` keeps its DAC codes here, not in a dict, so the twin's amplifier input (and the
# rig process) read them as an array, and ``comedi_do_insnlist`` runs compiled: the list is
# decoded once in Python into a plan (per sample: instruction, channel, the sample's address),
# and every call checks, here, that the memory the plan was decoded from still holds the same
# words (as the kernel copies the list in at each call) before writing the samples it reads now.
FC_CODES = 0            # 4: each analog output's last code (FC_NO_CODE: never written)
FC_FAIL_ALL = 4         # 1: every write fails (``fail_writes``)
FC_FAIL_MASK = 5        # bit c set: channel c's writes fail (``fail_channels``)
FC_ERRNO = 6            # the double's errno (``comedi_errno``)
FC_N_INSNS = 7          # the planned list's instruction count
FC_STOP = 8             # its first refused instruction (FC_N_INSNS when none)
FC_N_SAMPLES = 9        # samples in the plan (those of the instructions before FC_STOP)
FC_N_WATCHED = 10       # watched words
FC_DONE = 11            # samples the last call wrote (for the Python side's log)
FC_KEEP_LOG = 12        # 1: the double records every write (Python must log this call's)
FC_PLAN = 16            # FC_MAX_SAMPLES × (instruction, channel, sample address)
FC_MAX_SAMPLES = 32
FC_WATCH = FC_PLAN + 3 * FC_MAX_SAMPLES   # FC_MAX_WATCHED × (address, the word it held)
FC_MAX_WATCHED = 128
FC_SIZE = FC_WATCH + 2 * FC_MAX_WATCHED
FC_NO_CODE = -1
FC_MAXDATA = 4095
#: ``fake_insnlist``'s answer when the list's memory changed since the plan: decode again.
FC_STALE = -1000
_EIO = 5
_EINVAL = 22


@njit(cache=True)
def fake_insnlist(st):
    """``FakeComedi.comedi_do_insnlist`` on its plan in ``st`` (layout ``FC_*``): returns
    :data:`FC_STALE` (nothing done) when a watched word of the list's memory changed since the
    plan was decoded. Otherwise each planned sample, in order, as ``comedi_data_write`` writes
    it: a failing channel (``FC_FAIL_ALL``, ``FC_FAIL_MASK``) answers EIO, a code beyond
    ``FC_MAXDATA`` EINVAL, and the list stops there (answer: the instructions done before it, -1
    when none); else the code is the channel's. Then a refused instruction (``FC_STOP``) answers
    EINVAL the same way; a list done whole answers its count. ``FC_DONE``: samples written."""
    for k in range(st[FC_N_WATCHED]):
        w = FC_WATCH + 2 * k
        if i64_at(st[w])[0] != st[w + 1]:
            return FC_STALE
    st[FC_DONE] = 0
    fail_all = st[FC_FAIL_ALL] != 0
    dead = st[FC_FAIL_MASK]
    for s in range(st[FC_N_SAMPLES]):
        p = FC_PLAN + 3 * s
        insn = st[p]
        channel = st[p + 1]
        if fail_all or (dead >> channel) & 1:
            st[FC_ERRNO] = _EIO
            return insn if insn else -1
        code = np.int64(u32_at(st[p + 2])[0])
        if code > FC_MAXDATA:
            st[FC_ERRNO] = _EINVAL
            return insn if insn else -1
        st[FC_CODES + channel] = code
        st[FC_DONE] = s + 1
    stop = st[FC_STOP]
    if stop < st[FC_N_INSNS]:
        st[FC_ERRNO] = _EINVAL
        return stop if stop else -1
    return st[FC_N_INSNS]


@njit(cache=True)
def pci1720_write_fake(volts, dac, data, st, owner):
    """``Pci1720Outputs.write_volts`` on the comedilib double in one call: :func:`pci1720_codes`
    then :func:`fake_insnlist` (the driver's ``comedi_do_insnlist``) on the double's state
    ``st``, if its plan is of the driver's list (its first watched word is at ``owner``, the
    address of the driver's list pointer). Returns (the codes' answer, the list's answer):
    the list is not run after a refusal, and answers :data:`FC_STALE` (nothing done) when the
    plan is not the driver's or its list's memory changed: the driver then calls the double's
    ``comedi_do_insnlist``, which decodes it again."""
    rc = pci1720_codes(volts, dac, data)
    if rc < 0:
        return rc, 0
    if st[FC_N_WATCHED] == 0 or st[FC_WATCH] != owner:
        return rc, FC_STALE
    return rc, fake_insnlist(st)
