"""ATI Net F/T client over UDP (RDT): the force_torque backend ``ati_rdt``.

Protocol facts are in ``rt.ati.rdt``. The client connects its UDP socket to the sensor, so the
kernel drops datagrams from any other address; a background thread receives records, keeps
the latest one (converted to N and N m) and counts what went wrong. ``read()`` never blocks and
never raises on bad data: bad datagrams are counted, missing ones show up as ``stale``.
"""
from __future__ import annotations

import math
import select
import socket
import threading
import time
from dataclasses import dataclass

from rt.ati.rdt import (
    CMD_SET_SOFTWARE_BIAS,
    CMD_START_BUFFERED,
    CMD_START_REALTIME,
    CMD_STOP,
    RDT_PORT,
    RECORD_SIZE,
    RECORD_STRUCT,
    STATUS_SATURATION_MASK,
    CountsPerUnit,
    check_datagram,
    encode_request,
    sequence_gap,
)
from rt.devices.interfaces import ForceTorqueSensor, Wrench
from rt.errors import HardwareError, InputError, ProtocolError

NAN = math.nan


@dataclass(slots=True)
class RdtClientCounters:
    """Receive statistics (plain ints, written by the receive thread only).

    ``received``: records accepted; ``datagrams``: datagrams accepted; ``sequence_gaps``:
    records lost, counted from forward jumps of ``rdt_sequence``; ``malformed``: datagrams
    rejected (wrong length); ``stale_events``: fresh -> stale transitions seen by ``read()``;
    ``unreachable``: ICMP "port unreachable" reports (nothing listens at the sensor address).
    """

    received: int = 0
    datagrams: int = 0
    sequence_gaps: int = 0
    malformed: int = 0
    stale_events: int = 0
    unreachable: int = 0


class RdtForceTorqueSensor(ForceTorqueSensor):
    """ATI Net F/T (or the twin's ``RdtServer``) read over UDP RDT.

    Parameters: ``host``/``port`` of the sensor (Net F/T factory IP 192.168.1.1, port 49152);
    ``counts_per_force`` (counts/N) and ``counts_per_torque`` (counts/(N m)) from the sensor's
    configuration page; ``timeout_s``: a reading is ``stale`` when no record arrived, or the
    sensor's ft_sequence did not advance, within this time (s) - keep it above the datagram
    period in buffered mode; ``buffered``: start with command 0x0003 (several records per
    datagram) instead of 0x0002; ``local_host``/``local_port``: where to bind (0 = any port).
    """

    def __init__(self, host: str = "192.168.1.1", port: int = RDT_PORT, *,
                 counts_per_force: float = 1_000_000.0,
                 counts_per_torque: float = 1_000_000.0, timeout_s: float = 0.05,
                 buffered: bool = False, local_host: str = "", local_port: int = 0) -> None:
        if not timeout_s > 0.0:
            raise InputError(f"timeout_s must be > 0 s, got {timeout_s}")
        self.host, self.port = host, int(port)
        self.counts = CountsPerUnit(counts_per_force, counts_per_torque)
        self.timeout_s = float(timeout_s)
        self.buffered = bool(buffered)
        self.counters = RdtClientCounters()
        self.last_error = ""

        self._cond = threading.Condition()
        # Latest sample, guarded by _cond's lock; preallocated so receiving allocates nothing.
        self._latest = [NAN] * 6
        self._rdt_sequence = -1
        self._ft_sequence = -1
        self._status = 0
        self._t_rx = -math.inf
        self._t_ft_change = -math.inf
        self._last_seq_for_gaps: int | None = None
        self._was_stale = True
        self._collector: list[Wrench] | None = None
        self._collect_n = 0
        self._started = False

        self._buf = bytearray(65536)
        self._view = memoryview(self._buf)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((local_host, local_port))
            self._sock.connect((host, self.port))
            self._sock.setblocking(False)
            self._wake_r, self._wake_w = socket.socketpair()
        except OSError as exc:
            self._sock.close()
            raise HardwareError(
                f"cannot open UDP socket to ATI sensor {host}:{port}: {exc}") from exc
        self._thread = threading.Thread(target=self._run, name=f"rdt-client:{host}:{port}",
                                        daemon=True)
        self._thread.start()

    # ---------------------------------------------------------------- ForceTorqueSensor
    def start(self, sample_count: int = 0) -> None:
        """Ask the sensor to stream (0x0002, or 0x0003 when buffered); 0 records = endless."""
        self._check_open()
        with self._cond:
            self._last_seq_for_gaps = None  # the device restarts rdt_sequence on a new start
        self._request(CMD_START_BUFFERED if self.buffered else CMD_START_REALTIME, sample_count)
        self._started = True

    def stop(self) -> None:
        """Ask the sensor to stop streaming (0x0000)."""
        self._check_open()
        self._request(CMD_STOP)
        self._started = False

    def bias(self) -> None:
        """Software bias (0x0042): the sensor zeroes its readings at the current load."""
        self._check_open()
        self._request(CMD_SET_SOFTWARE_BIAS)

    def read(self, out: Wrench) -> Wrench:
        """Latest record into ``out`` (N, N m; t = host monotonic receipt time, s)."""
        now = time.monotonic()
        with self._cond:
            if self._rdt_sequence < 0:
                out.invalidate()
                return out
            out.set(self._latest)
            out.t = self._t_rx
            out.sequence = self._rdt_sequence
            out.status = self._status
            out.saturated = bool(self._status & STATUS_SATURATION_MASK)
            stale = (now - self._t_rx > self.timeout_s
                     or now - self._t_ft_change > self.timeout_s)
            if stale and not self._was_stale:
                self.counters.stale_events += 1
            self._was_stale = stale
            out.stale = stale
        return out

    # ---------------------------------------------------------------- helpers
    @property
    def local_address(self) -> tuple[str, int]:
        """(host, port) this client receives on."""
        return self._sock.getsockname()[:2]

    def read_samples(self, n: int, timeout_s: float = 1.0, *, start: bool = False
                     ) -> list[Wrench]:
        """Block until the next ``n`` records arrived; one ``Wrench`` per record, in order.

        ``timeout_s`` is the longest wait for each next record (s). With ``start=True`` the
        collection is armed first and then the sensor is asked for exactly ``n`` records, so
        none is missed. Returns fewer than ``n`` when the stream stops early; raises
        ``HardwareError`` when none arrives at all. For the CLI and tests; the control loop
        uses ``read``.
        """
        if n < 1:
            raise InputError(f"sample count must be >= 1, got {n}")
        self._check_open()
        collected: list[Wrench] = []
        with self._cond:
            self._collector, self._collect_n = collected, n
        try:
            if start:
                self.start(sample_count=n)
            with self._cond:
                deadline = time.monotonic() + timeout_s
                while len(collected) < n:
                    remaining = deadline - time.monotonic()
                    if remaining <= 0.0:
                        break
                    before = len(collected)
                    self._cond.wait(remaining)
                    if len(collected) > before:
                        deadline = time.monotonic() + timeout_s
        finally:
            with self._cond:
                self._collector = None
        if not collected:
            detail = f" ({self.last_error})" if self.last_error else ""
            raise HardwareError(
                f"no RDT data from {self.host}:{self.port} within {timeout_s} s{detail}; "
                "is the sensor (or 'talus twin serve-ati') running at that address?")
        return collected[:n]

    def _request(self, command: int, sample_count: int = 0) -> None:
        try:
            self._sock.send(encode_request(command, sample_count))
        except OSError as exc:
            raise HardwareError(
                f"cannot send RDT command 0x{command:04x} to {self.host}:{self.port}: {exc}"
            ) from exc

    def _close(self) -> None:
        if self._started:
            try:  # leave the sensor quiet rather than streaming to a closed port
                self._sock.send(encode_request(CMD_STOP))
            except OSError:
                pass
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass
        self._thread.join(timeout=5.0)
        for s in (self._sock, self._wake_r, self._wake_w):
            s.close()

    # ---------------------------------------------------------------- receive thread
    def _run(self) -> None:
        sock, wake = self._sock, self._wake_r
        while True:
            readable, _, _ = select.select([sock, wake], [], [])
            if wake in readable:
                return
            while True:
                try:
                    n = sock.recv_into(self._buf)
                except BlockingIOError:
                    break
                except ConnectionRefusedError:
                    self.counters.unreachable += 1
                    self.last_error = f"nothing listens at {self.host}:{self.port}"
                    continue
                except OSError as exc:
                    self.last_error = f"receive failed: {exc}"
                    break
                self._on_datagram(self._view[:n], time.monotonic())

    def _on_datagram(self, data: memoryview, t_rx: float) -> None:
        try:
            k = check_datagram(data)
        except ProtocolError as exc:
            self.counters.malformed += 1
            self.last_error = str(exc)
            return
        c = self.counters
        with self._cond:
            for i in range(k):
                (rdt, ft, status, n0, n1, n2, n3, n4, n5) = RECORD_STRUCT.unpack_from(
                    data, i * RECORD_SIZE)
                last = self._last_seq_for_gaps
                if last is not None:
                    gap = sequence_gap(last, rdt)
                    if gap > 0:
                        c.sequence_gaps += gap
                self._last_seq_for_gaps = rdt
                if ft != self._ft_sequence:
                    self._ft_sequence = ft
                    self._t_ft_change = t_rx
                c.received += 1
                if self._collector is not None and len(self._collector) < self._collect_n:
                    cpf, cpt = self.counts.force, self.counts.torque
                    self._collector.append(Wrench(
                        n0 / cpf, n1 / cpf, n2 / cpf, n3 / cpt, n4 / cpt, n5 / cpt,
                        t=t_rx, sequence=rdt, status=status, stale=False,
                        saturated=bool(status & STATUS_SATURATION_MASK)))
            self.counts.to_si((n0, n1, n2, n3, n4, n5), self._latest)
            self._rdt_sequence = rdt
            self._status = status
            self._t_rx = t_rx
            c.datagrams += 1
            if self._collector is not None:
                self._cond.notify_all()
