"""Shared memory between the rig process (the twin as hardware) and the RT process.

The rig process (``rt.twin.rig``) creates one named POSIX shared-memory segment
(``multiprocessing.shared_memory``) and unlinks it when it exits; RT-side handles
(``rt.twin.shm_backends.ShmRig``) attach to it by name. All values are native little-endian
(x86-64), every field is 8 bytes and 8-byte aligned, blocks start on 64-byte cache lines.

Segment (``TOTAL_SIZE`` = 512 bytes)::

    offset  size  block
    0       128   header      written once by the rig before it reports ready (``rig_state``
                              is updated again at exit)
    128     256   sensors     rig -> RT, seqlock; one writer: the rig, once per rig period
    384     128   commands    RT -> rig, seqlock; one writer process: the RT process

Header (offsets from 0)::

    0    u8[8]  magic            b"TALUSRIG" (written last: a complete header)
    8    u64    version          LAYOUT_VERSION
    16   u64    size             TOTAL_SIZE
    24   i64    rig_pid
    32   f64    epoch_monotonic_s  time.monotonic() (s) at which rig time is 0
    40   f64    period_s         rig period (s)
    48   f64    watchdog_timeout_s (s)
    56   u64    rig_state        RIG_STARTING, RIG_RUNNING, RIG_STOPPED, RIG_FAILED
    64   f64    m_per_count      encoder resolution of the twin (m/count)
    72   f64    command_limit_v  amplifier input clamp (V)

Sensor block (offsets from 128; the sequence word at +0)::

    +0    u64     seq                    seqlock sequence (odd while the rig writes)
    +8    u64     heartbeat              +1 per rig period
    +16   f64     rig_time_s             twin time of this snapshot (s)
    +24   f64     rig_monotonic_s        time.monotonic() of this snapshot (s)
    +32   u64[3]  counts                 PCL-833 live counters, 24-bit, axes 0-2 (channels 1-3)
    +56   f64[6]  wrench                 ATI sample Fx Fy Fz (N) Tx Ty Tz (N m), sensor frame
    +104  u64     ft_status              ATI status word
    +112  i64     ft_sequence            ATI sample counter (repeats when the sensor is stale)
    +120  u64     ft_valid               0: no sample yet / dropout
    +128  u64     hardware_estop         1 = pressed
    +136  u64     hand_stop              1 = pressed
    +144  f64[3]  amp_volts              amplifier inputs actually applied (V), after gating
    +168  u64     drives_enabled         1 = amplifiers enabled (watchdog fed and a card enabled)
    +176  u64     watchdog_state         WD_WAITING, WD_FED, WD_TRIPPED
    +184  u64     watchdog_tripped       1 while tripped (latched)
    +192  f64     trip_rig_time_s        rig time of the last trip (NaN: never)
    +200  f64     trip_monotonic_s       time.monotonic() of the last trip (NaN: never)
    +208  u64     trips                  number of trips since start
    +216  u64     feed_seen              last feed counter the rig saw
    +224  u64     rearm_seen             last re-arm counter the rig saw
    +232  u64     command_read_failures  command reads given up (writer stuck mid-write)
    +240  f64     feed_seen_monotonic_s  time.monotonic() when the rig last saw the feed change

Command block (offsets from 384)::

    +0    u64     seq                    seqlock sequence (odd while the RT process writes)
    +8    u64[2]  card_enabled           per PCI-1720 card (0, 1)
    +24   i64[6]  dac_codes              [card * 3 + channel], 12-bit code; -1 never written
    +72   u64     write_count            +1 per card write (codes or enable)
    +80   f64     write_monotonic_s      time.monotonic() of the last card write (s)
    +88   u64     feed                   watchdog feed counter (+1 per RT cycle)
    +96   u64     rearm                  re-arm counter (+1 per explicit re-arm)
    +104  i64     writer_pid             pid of the last writer

Seqlock (why: one writer, readers never block it, ≈ 1 µs per copy): the writer stores
``seq + 1`` (odd), writes the fields, stores ``seq + 2`` (even). A reader loads ``seq``,
copies the whole block into a private mirror, loads ``seq`` again, and keeps the copy only
if both loads are equal and even. The sequence word is a native aligned ``uint64`` accessed
through a numpy view, so each load and store is one 8-byte machine access (a byte-wise
``struct.pack_into`` word can tear; PLATFORM.md). Ordering relies on x86-64's TSO (stores
become visible in program order, loads are not reordered with loads) and on every access
being a separate C call the compiler cannot reorder; a weakly ordered CPU (ARM) would need
fences. A writer killed mid-write leaves ``seq`` odd: readers give up after a bounded time
(never spin forever) and the next writer repairs the word before writing.
"""
from __future__ import annotations

import mmap
import os
import re
import threading
import time
from collections.abc import Iterable
from multiprocessing import shared_memory
from typing import TYPE_CHECKING

import numpy as np

from rt.errors import HardwareError, InputError

MAGIC = b"TALUSRIG"
LAYOUT_VERSION = 1

HEADER_OFFSET, HEADER_SIZE = 0, 128
SENSOR_OFFSET, SENSOR_SIZE = 128, 256
COMMAND_OFFSET, COMMAND_SIZE = 384, 128
TOTAL_SIZE = 512

RIG_STARTING, RIG_RUNNING, RIG_STOPPED, RIG_FAILED = 0, 1, 2, 3
RIG_STATE_NAMES = {RIG_STARTING: "starting", RIG_RUNNING: "running", RIG_STOPPED: "stopped",
                   RIG_FAILED: "failed"}

#: Watchdog states: waiting for the first feed (drives off), fed (drives follow commands),
#: tripped (drives off, latched until a re-arm while fed).
WD_WAITING, WD_FED, WD_TRIPPED = 0, 1, 2
WD_STATE_NAMES = {WD_WAITING: "waiting", WD_FED: "fed", WD_TRIPPED: "tripped"}

#: -1 in ``dac_codes``: the card never wrote that channel (the twin then applies 0 V).
NO_CODE = -1

#: Field tables: name -> (offset in its block, dtype, count). Offsets include the 8-byte
#: sequence word at +0 of each seqlock block.
FieldSpec = tuple[str, int, type, int]

HEADER_FIELDS: tuple[FieldSpec, ...] = (
    ("magic", 0, np.uint8, 8),
    ("version", 8, np.uint64, 1),
    ("size", 16, np.uint64, 1),
    ("rig_pid", 24, np.int64, 1),
    ("epoch_monotonic_s", 32, np.float64, 1),
    ("period_s", 40, np.float64, 1),
    ("watchdog_timeout_s", 48, np.float64, 1),
    ("rig_state", 56, np.uint64, 1),
    ("m_per_count", 64, np.float64, 1),
    ("command_limit_v", 72, np.float64, 1),
)

SENSOR_FIELDS: tuple[FieldSpec, ...] = (
    ("heartbeat", 8, np.uint64, 1),
    ("rig_time_s", 16, np.float64, 1),
    ("rig_monotonic_s", 24, np.float64, 1),
    ("counts", 32, np.uint64, 3),
    ("wrench", 56, np.float64, 6),
    ("ft_status", 104, np.uint64, 1),
    ("ft_sequence", 112, np.int64, 1),
    ("ft_valid", 120, np.uint64, 1),
    ("hardware_estop", 128, np.uint64, 1),
    ("hand_stop", 136, np.uint64, 1),
    ("amp_volts", 144, np.float64, 3),
    ("drives_enabled", 168, np.uint64, 1),
    ("watchdog_state", 176, np.uint64, 1),
    ("watchdog_tripped", 184, np.uint64, 1),
    ("trip_rig_time_s", 192, np.float64, 1),
    ("trip_monotonic_s", 200, np.float64, 1),
    ("trips", 208, np.uint64, 1),
    ("feed_seen", 216, np.uint64, 1),
    ("rearm_seen", 224, np.uint64, 1),
    ("command_read_failures", 232, np.uint64, 1),
    ("feed_seen_monotonic_s", 240, np.float64, 1),
)

COMMAND_FIELDS: tuple[FieldSpec, ...] = (
    ("card_enabled", 8, np.uint64, 2),
    ("dac_codes", 24, np.int64, 6),
    ("write_count", 72, np.uint64, 1),
    ("write_monotonic_s", 80, np.float64, 1),
    ("feed", 88, np.uint64, 1),
    ("rearm", 96, np.uint64, 1),
    ("writer_pid", 104, np.int64, 1),
)

_SEQ_BYTES = 8
_NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")

_writer_locks: dict[str, threading.Lock] = {}
_writer_locks_guard = threading.Lock()


def check_shm_name(name: object) -> str:
    """Return ``name`` if it is a valid segment name, else raise ``InputError``.

    1-100 characters of letters, digits, ``_ . -``, starting with a letter or digit (a POSIX
    shared-memory name without its leading slash; it appears as ``/dev/shm/<name>``).
    """
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        raise InputError(
            f"shared-memory name {name!r} is malformed: use 1-100 letters, digits, '_', '.' "
            f"or '-', starting with a letter or digit (e.g. 'talus-rig')")
    return name


class FieldViews:
    """Typed numpy views, one attribute per field of ``specs``, over a block's bytes.

    ``data`` holds the block *without* its sequence word (offsets in ``specs`` count it), so
    the same class serves the shared block and its private mirror. Scalars are length-1 arrays:
    ``views.heartbeat[0]``.
    """

    def __init__(self, data: np.ndarray, specs: Iterable[FieldSpec], skip: int = _SEQ_BYTES):
        self._names: list[str] = []
        for name, offset, dtype, count in specs:
            start = offset - skip
            itemsize = np.dtype(dtype).itemsize
            view: np.ndarray = data[start:start + itemsize * count].view(dtype)
            setattr(self, name, view)
            self._names.append(name)

    if TYPE_CHECKING:
        # The fields are set by name at run time; to the type checker each one is an array.
        def __getattr__(self, name: str) -> np.ndarray: ...

    def release(self) -> None:
        """Drop every view (they pin the shared buffer, which cannot close while pinned)."""
        for name in self._names:
            setattr(self, name, None)


class SeqlockBlock:
    """One seqlock-protected block of the segment plus a private mirror of its payload.

    ``shared`` and ``local`` are ``FieldViews`` over the shared payload and the mirror. A
    writer that owns the whole block fills ``local`` then calls :meth:`publish`; a writer that
    owns only some fields (the RT process's per-card writes) brackets direct writes to
    ``shared`` with :meth:`begin_write` / :meth:`end_write`. Readers call :meth:`read`, then
    use ``local``. Nothing here allocates numpy arrays after construction.
    """

    def __init__(self, buf: memoryview, offset: int, size: int, specs: Iterable[FieldSpec]):
        specs = tuple(specs)
        self._seq = np.frombuffer(buf, np.uint64, 1, offset)
        self._shared_bytes = np.frombuffer(buf, np.uint8, size - _SEQ_BYTES, offset + _SEQ_BYTES)
        self._local_bytes = np.zeros(size - _SEQ_BYTES, np.uint8)
        self._scratch = np.zeros(size - _SEQ_BYTES, np.uint8)
        self.shared = FieldViews(self._shared_bytes, specs)
        self.local = FieldViews(self._local_bytes, specs)
        #: Reads given up because the sequence stayed odd or kept changing.
        self.failed_reads = 0

    @property
    def sequence(self) -> int:
        """Current value of the shared sequence word."""
        return int(self._seq[0])

    # --- reader ----------------------------------------------------------------------------
    def read(self, timeout_s: float = 0.001, fast_tries: int = 64) -> bool:
        """Copy a consistent snapshot of the shared block into ``local``.

        Retries while the writer is mid-write; gives up after ``fast_tries`` attempts plus
        ``timeout_s`` (s) of yielding retries and returns False, leaving ``local`` as it was
        (a writer preempted or killed mid-write must not hang the reader).
        """
        seq, src, scratch = self._seq, self._shared_bytes, self._scratch
        deadline = 0.0
        tries = 0
        while True:
            s1 = int(seq[0])
            if not s1 & 1:
                # Copy to scratch first: a torn copy must not overwrite the last good snapshot.
                np.copyto(scratch, src)
                if int(seq[0]) == s1:
                    np.copyto(self._local_bytes, scratch)
                    return True
            tries += 1
            if tries >= fast_tries:
                now = time.monotonic()
                if deadline == 0.0:
                    deadline = now + timeout_s
                elif now > deadline:
                    self.failed_reads += 1
                    return False
                os.sched_yield()

    # --- writers ---------------------------------------------------------------------------
    def begin_write(self) -> int:
        """Mark the block as being written (sequence odd); returns the token for end_write.

        An odd sequence found here means a writer died mid-write (one writer at a time is the
        contract): the word is repaired by moving on from it.
        """
        s = int(self._seq[0])
        if s & 1:
            s += 1
        self._seq[0] = s + 1
        return s + 2

    def end_write(self, token: int) -> None:
        """Mark the block as consistent again (sequence even)."""
        self._seq[0] = token

    def publish(self) -> None:
        """Copy the whole ``local`` mirror to the shared block under the seqlock."""
        token = self.begin_write()
        np.copyto(self._shared_bytes, self._local_bytes)
        self.end_write(token)

    def release(self) -> None:
        self.shared.release()
        self.local.release()
        self._seq = None  # type: ignore[assignment]
        self._shared_bytes = None  # type: ignore[assignment]


class RigSegment:
    """The mapped segment: header views and the two seqlock blocks.

    Use :func:`create_segment` (rig side) or :func:`attach_segment` (RT side).
    """

    def __init__(self, shm: shared_memory.SharedMemory | _AttachedShm, name: str, owner: bool):
        self.name = name
        self.owner = owner
        self._shm: shared_memory.SharedMemory | _AttachedShm | None = shm
        buf = shm.buf
        if buf is None:
            raise HardwareError(f"shared-memory segment {name!r} is not mapped")
        self._header_bytes = np.frombuffer(buf, np.uint8, HEADER_SIZE, HEADER_OFFSET)
        self.header = FieldViews(self._header_bytes, HEADER_FIELDS, skip=0)
        self.sensors = SeqlockBlock(buf, SENSOR_OFFSET, SENSOR_SIZE, SENSOR_FIELDS)
        self.commands = SeqlockBlock(buf, COMMAND_OFFSET, COMMAND_SIZE, COMMAND_FIELDS)

    @property
    def closed(self) -> bool:
        return self._shm is None

    def writer_lock(self) -> threading.Lock:
        """The lock serializing this process's command writers (one writer per seqlock)."""
        with _writer_locks_guard:
            return _writer_locks.setdefault(self.name, threading.Lock())

    def close(self) -> None:
        """Unmap (and, for the creator, unlink) the segment. Safe to call twice."""
        shm, self._shm = self._shm, None
        if shm is None:
            return
        self.header.release()
        self.sensors.release()
        self.commands.release()
        self._header_bytes = None  # type: ignore[assignment]
        try:
            shm.close()
        except BufferError:
            # Someone still holds a view of the buffer; the mapping goes when it is collected.
            pass
        if self.owner and isinstance(shm, shared_memory.SharedMemory):  # the creator's handle
            try:
                shm.unlink()
            except FileNotFoundError:
                pass


def create_segment(name: str) -> RigSegment:
    """Create the named segment (rig side), zeroed, with the sequence words even.

    Raises ``InputError`` for a malformed name and ``HardwareError`` if the name exists.
    """
    check_shm_name(name)
    try:
        shm = shared_memory.SharedMemory(name=name, create=True, size=TOTAL_SIZE)
    except FileExistsError:
        raise HardwareError(
            f"shared memory {name!r} already exists (/dev/shm/{name}): another rig is running "
            f"or one crashed; stop it or remove the file") from None
    seg = RigSegment(shm, name, owner=True)
    seg._header_bytes[:] = 0
    empty_codes = seg.commands.shared.dac_codes
    empty_codes[:] = NO_CODE
    return seg


class _AttachedShm:
    """A mapping of an existing segment, without ``SharedMemory``'s resource tracking.

    Python 3.11's ``SharedMemory(create=False)`` registers the segment with the process's
    resource tracker, which then unlinks the *rig's* segment when the attaching process exits
    (and confuses the rig's own tracker when both share one). Only the rig owns the segment,
    so attachers map ``/dev/shm/<name>`` (what ``shm_open`` does on Linux) directly.
    """

    def __init__(self, name: str):
        fd = os.open(f"/dev/shm/{name}", os.O_RDWR)
        try:
            self.size = os.fstat(fd).st_size
            if self.size == 0:
                raise HardwareError(f"shared memory {name!r} is empty: not a talus rig segment")
            self._mmap: mmap.mmap | None = mmap.mmap(fd, self.size)
        finally:
            os.close(fd)
        self.buf: memoryview | None = memoryview(self._mmap)

    def close(self) -> None:
        if self.buf is not None:
            self.buf.release()
            self.buf = None
        if self._mmap is not None:
            self._mmap.close()
            self._mmap = None


def attach_segment(name: str) -> RigSegment:
    """Attach to the rig's segment by name (RT side); checks magic, version and size.

    Raises ``InputError`` for a malformed name, ``HardwareError`` when no rig runs under that
    name or the segment is not a talus rig's.
    """
    check_shm_name(name)
    try:
        shm = _AttachedShm(name)
    except FileNotFoundError:
        raise HardwareError(
            f"no rig shared memory named {name!r} (/dev/shm/{name} does not exist): start the "
            f"rig first (talus twin rig --shm {name})") from None
    except PermissionError as exc:
        raise HardwareError(f"cannot open the rig shared memory {name!r}: {exc}") from None
    if shm.size < TOTAL_SIZE:
        shm.close()
        raise HardwareError(f"shared memory {name!r} is {shm.size} bytes, too small for a "
                            f"talus rig segment ({TOTAL_SIZE} bytes); wrong name?")
    seg = RigSegment(shm, name, owner=False)
    header = seg.header
    magic = bytes(header.magic)
    version = int(header.version[0])
    if magic != MAGIC or version != LAYOUT_VERSION:
        seg.close()
        if magic != MAGIC:
            raise HardwareError(f"shared memory {name!r} is not a talus rig segment (or the rig "
                                f"is still starting): magic {magic!r}")
        raise HardwareError(f"rig segment {name!r} has layout version {version}, this code "
                            f"reads version {LAYOUT_VERSION}: update both sides")
    return seg
