"""Real-time hygiene for the loop's thread (DESIGN 5, PLATFORM "Timing on these VMs").

Each measure is *tried*: what it achieved is reported, and nothing fails hard when the process
lacks the privilege (an unprivileged developer laptop still runs the loop, just with more
jitter). Everything applied is undone on exit, so a test process is left as it was.

* ``SCHED_FIFO`` for the calling thread (``os.sched_setscheduler(0, ...)`` acts on the calling
  thread on Linux). The loop never spins a whole period: a busy FIFO thread is throttled
  ≈ 50 ms per second by ``sched_rt_runtime_us``.
* ``mlockall(MCL_CURRENT | MCL_FUTURE)`` through libc: no page fault in the cycle. Process-wide
  and reference-counted, so nested/concurrent loops do not unlock each other's memory.
* CPU affinity of the calling thread, if asked for.
* Timer slack of 1 ns (``prctl(PR_SET_TIMERSLACK)``): a non-FIFO thread's ``sleep`` otherwise
  overshoots by the default 50 µs slack.
* GIL switch interval: another busy Python thread keeps the GIL for up to
  ``sys.getswitchinterval()`` (5 ms by default) after the loop thread asks for it; a shorter
  interval bounds that wait. Process-wide.
* gc frozen and disabled while the loop runs (:func:`gc_paused`, reference-counted).
* CPU wake-up latency bound through the kernel's PM QoS (``/dev/cpu_dma_latency``, as
  ``cyclictest`` does): an idle CPU otherwise enters an idle state (on these VMs ``haltpoll``
  with ``guest_halt_poll_ns=0``: a HLT, i.e. the vCPU is handed back to the host) and the
  loop's wake-up waits for the host to schedule the vCPU again. Process-wide, held while the
  file stays open, reference-counted.
"""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import gc
import os
import platform
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

# Linux values on x86, x86-64, ARM and RISC-V (alpha, powerpc and sparc differ).
MCL_CURRENT = 1
MCL_FUTURE = 2
PR_SET_TIMERSLACK = 29
PR_GET_TIMERSLACK = 30
_MCL_ARCH_OK = not platform.machine().lower().startswith(("alpha", "ppc", "powerpc", "sparc"))

_lock = threading.Lock()
_gc_users = 0
_gc_was_enabled = True
_mlock_users = 0
_qos_users = 0
_qos_fd: int | None = None
#: The kernel's PM QoS request file (Documentation/power/pm_qos_interface.rst): write a 32-bit
#: latency bound in µs; the request holds while the file descriptor stays open.
CPU_DMA_LATENCY = "/dev/cpu_dma_latency"


def _libc() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name, use_errno=True) if name else ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None


@dataclass
class HygieneReport:
    """What :func:`realtime_thread` achieved. ``*_detail`` say why when something was not done."""

    fifo: bool = False
    fifo_priority: int | None = None
    fifo_detail: str = "not requested"
    mlockall: bool = False
    mlock_detail: str = "not requested"
    affinity: tuple[int, ...] | None = None
    affinity_detail: str = "not requested"
    timer_slack_ns: int | None = None
    timer_slack_detail: str = "not requested"
    switch_interval_s: float | None = None
    switch_interval_detail: str = "not requested"
    cpu_latency_us: int | None = None
    cpu_latency_detail: str = "not requested"
    notes: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """One line per measure."""
        fifo = f"yes, priority {self.fifo_priority}" if self.fifo else "no"
        si = (f"{self.switch_interval_s * 1e6:.0f} µs" if self.switch_interval_s is not None
              else "unchanged")
        return "\n".join([
            f"SCHED_FIFO: {fifo} ({self.fifo_detail})",
            f"mlockall:   {'yes' if self.mlockall else 'no'} ({self.mlock_detail})",
            (f"affinity:   {list(self.affinity) if self.affinity else 'unchanged'} "
            f"({self.affinity_detail})"),
            (f"timerslack: {self.timer_slack_ns if self.timer_slack_ns is not None else '-'} ns "
            f"({self.timer_slack_detail})"),
            f"GIL switch: {si} ({self.switch_interval_detail})",
            (f"CPU wake:   {self.cpu_latency_us if self.cpu_latency_us is not None else '-'} µs "
             f"({self.cpu_latency_detail})"),
        ] + self.notes)


# ---------------------------------------------------------------------- individual measures
def try_sched_fifo(priority: int) -> tuple[bool, str, tuple[int, int] | None]:
    """Put the calling thread in SCHED_FIFO at ``priority`` (1-99).

    Returns (achieved, detail, previous (policy, priority) to restore, or None)."""
    if not hasattr(os, "sched_setscheduler"):
        return False, "os.sched_setscheduler unavailable on this platform", None
    try:
        lo, hi = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
        prio = max(lo, min(hi, int(priority)))
        prev = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
    except PermissionError:
        return False, "not permitted (needs root or CAP_SYS_NICE / an rtprio limit)", None
    except OSError as exc:
        return False, f"refused: {exc}", None
    return True, "ok", prev


def restore_scheduler(prev: tuple[int, int]) -> None:
    """Undo :func:`try_sched_fifo` for the calling thread."""
    with contextlib.suppress(OSError):
        os.sched_setscheduler(0, prev[0], os.sched_param(prev[1]))


def try_mlockall() -> tuple[bool, str]:
    """Lock current and future pages of the process in RAM (reference-counted)."""
    global _mlock_users
    with _lock:
        if _mlock_users > 0:
            _mlock_users += 1
            return True, "already locked by another loop"
        if not sys.platform.startswith("linux") or not _MCL_ARCH_OK:
            return False, f"unsupported on {sys.platform}/{platform.machine()}"
        libc = _libc()
        if libc is None:
            return False, "libc not found"
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
            err = ctypes.get_errno()
            return False, f"mlockall failed: {os.strerror(err)} (errno {err}; RLIMIT_MEMLOCK?)"
        _mlock_users = 1
        return True, "ok"


def release_mlockall() -> None:
    """Undo one successful :func:`try_mlockall`; unlocks when the last user leaves."""
    global _mlock_users
    with _lock:
        if _mlock_users == 0:
            return
        _mlock_users -= 1
        if _mlock_users == 0:
            libc = _libc()
            if libc is not None:
                libc.munlockall()


def try_affinity(cpus: Iterable[int]) -> tuple[bool, str, set[int] | None]:
    """Pin the calling thread to ``cpus``; returns (achieved, detail, previous set)."""
    if not hasattr(os, "sched_setaffinity"):
        return False, "os.sched_setaffinity unavailable on this platform", None
    wanted = {int(c) for c in cpus}
    try:
        prev = os.sched_getaffinity(0)
        os.sched_setaffinity(0, wanted)
    except PermissionError:
        return False, "not permitted", None
    except OSError as exc:
        return False, f"refused for {sorted(wanted)}: {exc}", None
    return True, "ok", prev


def try_timer_slack(ns: int) -> tuple[bool, str, int | None]:
    """Set the calling thread's timer slack (ns); returns (achieved, detail, previous)."""
    if not sys.platform.startswith("linux"):
        return False, f"unsupported on {sys.platform}", None
    libc = _libc()
    if libc is None:
        return False, "libc not found", None
    prctl = libc.prctl
    prctl.restype = ctypes.c_int
    prev = prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0)
    if prev < 0 or prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(ns), 0, 0, 0) != 0:
        return False, f"prctl failed: {os.strerror(ctypes.get_errno())}", None
    return True, "ok", prev


def try_cpu_latency_bound(us: int, path: str = CPU_DMA_LATENCY) -> tuple[bool, str]:
    """Ask the kernel to keep every CPU's wake-up latency ≤ ``us`` µs (0: no idle state deeper
    than polling) while the request is held; reference-counted across loops of the process.

    Costs power (an idle CPU polls instead of halting): a rig's RT PC pays it gladly."""
    global _qos_users, _qos_fd
    if not (0 <= int(us) <= 1_000_000):
        return False, f"a wake-up latency bound in [0, 1e6] µs, got {us!r}"
    with _lock:
        if _qos_users > 0:
            _qos_users += 1
            return True, "already held by another loop"
        try:
            fd = os.open(path, os.O_WRONLY)
        except FileNotFoundError:
            return False, f"{path} not present (kernel without PM QoS)"
        except PermissionError:
            return False, f"{path} not writable (needs root)"
        except OSError as exc:
            return False, f"{path}: {exc}"
        try:
            os.write(fd, int(us).to_bytes(4, sys.byteorder, signed=True))
        except OSError as exc:
            os.close(fd)
            return False, f"{path} refused the request: {exc}"
        _qos_fd, _qos_users = fd, 1
        return True, "ok (process-wide)"


def release_cpu_latency_bound() -> None:
    """Undo one successful :func:`try_cpu_latency_bound`; the request ends with the last user."""
    global _qos_users, _qos_fd
    with _lock:
        if _qos_users == 0:
            return
        _qos_users -= 1
        if _qos_users == 0 and _qos_fd is not None:
            with contextlib.suppress(OSError):
                os.close(_qos_fd)
            _qos_fd = None


@contextlib.contextmanager
def gc_paused(collect: bool = True) -> Iterator[None]:
    """Collect once (if ``collect``), freeze what survives, and disable gc until the last user
    leaves.

    Disabled, the collector cannot stall a cycle for milliseconds; frozen, the existing heap
    stays out of any collection that someone triggers anyway (``gc.collect()`` in another
    thread). The loop allocates nothing that needs collecting. The initial collection costs
    tens of ms in a large process: worth it before a real-time run, skipped for fast runs.
    """
    global _gc_users, _gc_was_enabled
    with _lock:
        if _gc_users == 0:
            _gc_was_enabled = gc.isenabled()
            if collect:
                gc.collect()
            gc.freeze()
            gc.disable()
        _gc_users += 1
    try:
        yield
    finally:
        with _lock:
            _gc_users -= 1
            if _gc_users == 0:
                gc.unfreeze()
                if _gc_was_enabled:
                    gc.enable()


@contextlib.contextmanager
def realtime_thread(priority: int | None = 80, cpus: Iterable[int] | None = None,
                    lock_memory: bool = True, timer_slack_ns: int | None = 1,
                    switch_interval_s: float | None = 0.0002,
                    cpu_latency_us: int | None = None) -> Iterator[HygieneReport]:
    """Apply the hygiene measures to the calling thread for the duration of the ``with``.

    ``None``/``False`` skips a measure. Yields a :class:`HygieneReport`; restores the previous
    scheduler, affinity, timer slack, switch interval and memory locking on exit.
    """
    report = HygieneReport()
    undo: list = []
    try:
        if priority is not None:
            ok, detail, prev = try_sched_fifo(priority)
            report.fifo, report.fifo_detail = ok, detail
            if ok:
                report.fifo_priority = os.sched_getparam(0).sched_priority
                undo.append(lambda p=prev: restore_scheduler(p))
        if lock_memory:
            ok, report.mlock_detail = try_mlockall()
            report.mlockall = ok
            if ok:
                undo.append(release_mlockall)
        if cpus is not None:
            ok, detail, prev_cpus = try_affinity(cpus)
            report.affinity_detail = detail
            if ok:
                report.affinity = tuple(sorted(os.sched_getaffinity(0)))
                undo.append(lambda p=prev_cpus: os.sched_setaffinity(0, p))
        if timer_slack_ns is not None:
            ok, detail, prev_slack = try_timer_slack(timer_slack_ns)
            report.timer_slack_detail = detail
            if ok:
                report.timer_slack_ns = timer_slack_ns
                undo.append(lambda p=prev_slack: try_timer_slack(p))
        if switch_interval_s is not None:
            prev_si = sys.getswitchinterval()
            try:
                sys.setswitchinterval(switch_interval_s)
                report.switch_interval_s = sys.getswitchinterval()
                report.switch_interval_detail = "ok (process-wide)"
                undo.append(lambda p=prev_si: sys.setswitchinterval(p))
            except ValueError as exc:
                report.switch_interval_detail = f"refused: {exc}"
        if cpu_latency_us is not None:
            ok, report.cpu_latency_detail = try_cpu_latency_bound(cpu_latency_us)
            if ok:
                report.cpu_latency_us = int(cpu_latency_us)
                undo.append(release_cpu_latency_bound)
        yield report
    finally:
        for fn in reversed(undo):
            with contextlib.suppress(Exception):
                fn()


# ---------------------------------------------------------------------- the GIL
class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


def _gil_holding_nanosleep() -> Callable[[int], None] | None:
    """libc's ``nanosleep`` called through ``ctypes.PyDLL``, which does *not* release the GIL
    around the call (``ctypes.CDLL`` and ``time.sleep`` do)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.PyDLL(ctypes.util.find_library("c") or None)
        fn = libc.nanosleep
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.POINTER(_Timespec), ctypes.c_void_p]
    fn.restype = ctypes.c_int
    ts = _Timespec()
    ref = ctypes.byref(ts)

    def sleep_ns(ns: int) -> None:
        if ns <= 0:
            return
        ts.tv_sec, ts.tv_nsec = divmod(int(ns), 1_000_000_000)
        fn(ref, None)            # EINTR: returns early; the caller spins the rest
    return sleep_ns


def _busy_wait_ns(ns: int) -> None:
    end = time.perf_counter_ns() + ns
    while time.perf_counter_ns() < end:
        pass


#: Sleep ``ns`` nanoseconds *keeping* the GIL (no other Python thread runs meanwhile); a busy
#: wait where libc's nanosleep is not reachable. The loop's guard before its deadline.
sleep_holding_gil: Callable[[int], None] = _gil_holding_nanosleep() or _busy_wait_ns


# ---------------------------------------------------------------------- threads sharing the GIL
@contextlib.contextmanager
def gil_peer(priority: int | None, nice: int = -10) -> Iterator[str]:
    """Raise the calling thread, which shares the GIL with a SCHED_FIFO loop thread of the same
    process, above ordinary processes for the duration of the ``with``: ``SCHED_FIFO`` at
    ``priority`` (below the loop's), inherited by the threads it starts; when FIFO is not
    permitted, a ``nice`` value instead;
    ``priority=None`` does nothing. Yields what was done; restores the thread on exit.

    Why: the GIL is a lock the loop shares with these threads, and CPython's GIL has no
    priority inheritance. A thread that holds the GIL while the scheduler runs an ordinary
    process (a pre-flight worker, a GUI, a compiler) in its place keeps the loop waiting for
    milliseconds: the loop is late although it is SCHED_FIFO. Running every GIL holder above
    ordinary processes (a priority ceiling) bounds the loop's wait to the GIL's switch interval.
    Threads created inside inherit the policy (pthreads' default): entered in the RT process's
    main thread before it starts any, it covers IPC, telemetry, sessions and the recorder.
    """
    if priority is None:
        yield "unchanged"
        return
    undo: Callable[[], None] | None = None
    detail = "not permitted"
    if hasattr(os, "sched_setscheduler"):
        try:
            prev = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
            prio = max(os.sched_get_priority_min(os.SCHED_FIFO), int(priority))
            # No SCHED_RESET_ON_FORK: it applies to threads too (clone), and the threads are
            # what must inherit. A process started from here inherits FIFO until it resets
            # itself (the pre-flight worker's initializer: ordinary_process_priority).
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
            detail = f"SCHED_FIFO {prio}"
            undo = lambda: restore_scheduler(prev)
        except OSError:
            undo = None
    if undo is None:
        try:
            tid = threading.get_native_id()      # setpriority acts on one thread on Linux
            prev_nice = os.getpriority(os.PRIO_PROCESS, tid)
            os.setpriority(os.PRIO_PROCESS, tid, nice)
            detail = f"nice {nice}"
            undo = lambda: os.setpriority(os.PRIO_PROCESS, tid, prev_nice)
        except (OSError, AttributeError):
            undo = None
    try:
        yield detail
    finally:
        if undo is not None:
            with contextlib.suppress(OSError):
                undo()


def ordinary_process_priority(nice: int) -> str:
    """For a process started by the RT process to do background work (the pre-flight worker):
    an ordinary scheduling policy (whatever it inherited) at ``nice``, so that it never takes a
    core from the RT process's threads. Returns what was done."""
    done = []
    if hasattr(os, "sched_setscheduler"):
        try:
            if os.sched_getscheduler(0) != os.SCHED_OTHER:
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
                done.append("SCHED_OTHER")
        except OSError:
            pass
    try:
        now = os.getpriority(os.PRIO_PROCESS, 0)
        os.setpriority(os.PRIO_PROCESS, 0, max(now, nice))
        done.append(f"nice {max(now, nice)}")
    except OSError:
        pass
    return ", ".join(done) or "unchanged"
