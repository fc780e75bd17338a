"""x86 I/O-port access for ISA cards (the PCL-833 encoder card).

``PortIO`` is the byte-wide port interface (``inb``/``outb``) the PCL-833 driver is written
against, so the same driver runs on the real bus (``DevPortIO``) and on the register-level
emulation (``rt.drivers.fake_pcl833.FakePcl833Port``) that tests and the digital twin use.

Sources:

* Linux ``mem(4)``: ``/dev/port`` is like ``/dev/mem`` but for I/O ports; reading or writing
  one byte at file offset ``port`` performs ``inb``/``outb`` on that port in the kernel. It
  needs root (``CAP_SYS_RAWIO``); the kernel may be built without it (``CONFIG_DEVPORT``).
* Linux ``ioperm(2)``: ``int ioperm(unsigned long from, unsigned long num, int turn_on)``
  grants the *calling thread* direct ``in``/``out`` instructions on ports
  ``from .. from+num-1``; needs ``CAP_SYS_RAWIO``; x86 only (ENOSYS elsewhere). Python cannot
  issue ``in``/``out`` itself, so we only use it as an early, precise permission probe.
* The thesis (3.2.2) called ``iopl(3)`` and then used ``inb``/``outb`` directly from C under
  Xenomai; ``/dev/port`` is the equivalent reachable from Python, at about 1-2 µs per byte
  (one system call each).
"""
from __future__ import annotations

import abc
import ctypes
import ctypes.util
import errno
import os

import numpy as np

from rt.devices.interfaces import Device
from rt.errors import BackendUnavailableError, ConfigurationError, HardwareError

#: Highest x86 I/O port address.
MAX_PORT = 0xFFFF


def _check_port(port: int) -> None:
    if not 0 <= port <= MAX_PORT:
        raise HardwareError(f"I/O port 0x{port:X} is outside 0x0000-0xFFFF")


class PortIO(Device):
    """Byte-wide access to x86 I/O ports; a context manager whose ``close()`` is idempotent.

    Ports are absolute addresses (for example ``0x220 + 3``); values are bytes 0-255.
    """

    @abc.abstractmethod
    def inb(self, port: int) -> int:
        """Read one byte from ``port``."""

    @abc.abstractmethod
    def outb(self, port: int, value: int) -> None:
        """Write the byte ``value`` (0-255) to ``port``."""

    def read_block(self, ports: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``inb`` of each of ``ports`` (int64), in this order, into ``out`` (int64): a
        driver's whole per-cycle read in one call. The order is kept because a read may have
        side effects (the PCL-833 latches a counter on its high byte). This default reads one
        port at a time; a backend that can do better (the card's emulation: one compiled
        call) overrides it with the same results."""
        inb = self.inb
        for k in range(ports.shape[0]):
            out[k] = inb(int(ports[k]))
        return out


    def compiled_block_state(self) -> np.ndarray | None:
        """The int64 state ``rt.drivers.kernels.fake_pcl833_read`` reads a block from, when
        this port is memory (the card's emulation), else None (a system call per byte)."""
        return None


class DevPortIO(PortIO):
    """Port access through ``/dev/port`` (Linux, root or ``CAP_SYS_RAWIO``).

    ``path`` exists so tests can point it at a file that does not exist; on a real machine
    leave it at ``/dev/port``. Opening fails with one ``BackendUnavailableError`` that says
    what to do (run as root, or pick the ``sim`` backend).
    """

    def __init__(self, path: str = "/dev/port") -> None:
        self.path = path
        self._fd = -1
        try:
            self._fd = os.open(path, os.O_RDWR | os.O_CLOEXEC)
        except FileNotFoundError:
            raise BackendUnavailableError(
                f"{path} does not exist: this kernel has no /dev/port (CONFIG_DEVPORT) or this "
                f"is not an x86 machine; ISA cards cannot be reached here. Choose the 'sim' "
                f"backend") from None
        except PermissionError:
            raise BackendUnavailableError(
                f"permission denied opening {path}: I/O-port access needs root "
                f"(CAP_SYS_RAWIO); run the real-time process as root or choose the 'sim' "
                f"backend") from None
        except OSError as exc:
            raise BackendUnavailableError(f"cannot open {path}: {exc.strerror}") from exc

    def inb(self, port: int) -> int:
        self._check_open()
        _check_port(port)
        try:
            data = os.pread(self._fd, 1, port)
        except OSError as exc:
            raise HardwareError(f"inb(0x{port:X}) through {self.path} failed: {exc}") from exc
        if len(data) != 1:
            raise HardwareError(f"inb(0x{port:X}) through {self.path} returned no byte")
        return data[0]

    def outb(self, port: int, value: int) -> None:
        self._check_open()
        _check_port(port)
        if not 0 <= value <= 0xFF:
            raise HardwareError(f"outb(0x{port:X}, {value}): value is not a byte")
        try:
            written = os.pwrite(self._fd, bytes((value,)), port)
        except OSError as exc:
            raise HardwareError(f"outb(0x{port:X}) through {self.path} failed: {exc}") from exc
        if written != 1:
            raise HardwareError(f"outb(0x{port:X}) through {self.path} wrote nothing")

    def _close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


def check_ioperm(base: int, length: int) -> None:
    """Probe that this process may touch ports ``base .. base+length-1``; release them again.

    Raises ``BackendUnavailableError`` with the reason (no libc ``ioperm``, not x86, missing
    ``CAP_SYS_RAWIO``). Useful before a long configuration sequence so that a permission
    problem shows up as one clear message instead of a failure halfway through.
    """
    if base < 0 or length <= 0 or base + length - 1 > MAX_PORT:
        raise ConfigurationError(f"port range 0x{base:X}+{length} is not a valid I/O range")
    libc_name = ctypes.util.find_library("c")
    if libc_name is None:
        raise BackendUnavailableError("C library not found; cannot probe ioperm()")
    libc = ctypes.CDLL(libc_name, use_errno=True)
    ioperm = getattr(libc, "ioperm", None)
    if ioperm is None:
        raise BackendUnavailableError("this C library has no ioperm(): not an x86 Linux machine")
    ioperm.argtypes = (ctypes.c_ulong, ctypes.c_ulong, ctypes.c_int)
    ioperm.restype = ctypes.c_int
    if ioperm(base, length, 1) != 0:
        err = ctypes.get_errno()
        hint = {
            errno.EPERM: "needs root (CAP_SYS_RAWIO)",
            errno.ENOSYS: "not supported on this architecture",
            errno.EINVAL: "invalid port range",
        }.get(err, os.strerror(err))
        raise BackendUnavailableError(
            f"ioperm(0x{base:X}, {length}) refused: {hint}; choose the 'sim' backend if this "
            f"machine has no ISA card")
    # Release at once: /dev/port does the I/O in the kernel, this thread needs no grant.
    ioperm(base, length, 0)
