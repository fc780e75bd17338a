"""A UDP server speaking ATI's RDT protocol, fed by the twin (or any ``WrenchSource``).

It behaves like the Net F/T's RDT server as far as a client can see (manual facts in
``rt.ati.rdt``): it answers the address that sent the start command, a new command overrides
the previous one, ``sample_count`` ends the stream after that many records, bias zeroes the
readings at the current load, and malformed requests get no reply (they are counted here).

One thread per server: it waits in ``select`` for requests, the next send time or the close
signal, so it never spins. Sends are paced on a monotonic clock at ``rate_hz``; if the thread
falls far behind (a long GC pause) it resynchronises instead of sending a burst.
"""
from __future__ import annotations

import select
import socket
import threading
import time
from dataclasses import dataclass
from typing import Self

from rt.ati.rdt import (
    CMD_SET_SOFTWARE_BIAS,
    CMD_START_BUFFERED,
    CMD_START_REALTIME,
    CMD_STOP,
    RDT_PORT,
    RECORD_SIZE,
    CountsPerUnit,
    decode_request,
    pack_record_into,
)
from rt.ati.twin_sensor import SourceReader, WrenchSource
from rt.errors import InputError, ProtocolError


@dataclass(slots=True)
class RdtServerCounters:
    """What the server did; read them from any thread (values are plain ints)."""

    requests: int = 0
    malformed_requests: int = 0
    records_sent: int = 0
    datagrams_sent: int = 0
    dropouts: int = 0  # ticks on which the source had no new sample
    send_errors: int = 0
    source_errors: int = 0


class RdtServer:
    """RDT server on ``host:port`` streaming samples from ``source``.

    ``source()`` is called once per record from the server thread and returns ``None`` (no new
    sample: nothing is sent, as during a sensor dropout), ``(wrench6, status)`` or
    ``(wrench6, status, ft_sequence)``; wrench in N and N m, see ``rt.ati.twin_sensor``.

    Parameters: ``rate_hz`` record rate (Hz); ``buffer_records`` records per datagram in
    buffered mode (the device's "RDT buffer size"); ``counts`` the counts-per-unit used to
    encode values; ``port=0`` picks an ephemeral port (read it back from ``port``).
    """

    def __init__(self, source: WrenchSource, *, host: str = "127.0.0.1", port: int = RDT_PORT,
                 rate_hz: float = 1000.0, buffer_records: int = 10,
                 counts: CountsPerUnit | None = None) -> None:
        if not rate_hz > 0.0:
            raise InputError(f"RDT server rate must be > 0 Hz, got {rate_hz}")
        if not 1 <= buffer_records <= 40:
            # 40 records = 1440 bytes: one datagram still fits an Ethernet MTU.
            raise InputError(f"buffer_records must be within 1..40, got {buffer_records}")
        self.rate_hz = float(rate_hz)
        self.buffer_records = int(buffer_records)
        self.counts = counts if counts is not None else CountsPerUnit()
        self.counters = RdtServerCounters()
        self.last_error: str = ""
        self._reader = SourceReader(source)
        self._period = 1.0 / self.rate_hz

        # Streaming state, touched only by the server thread.
        self._dest: tuple[str, int] | None = None
        self._buffered = False
        self._remaining: int | None = None
        self._rdt_sequence = 0
        self._n_pending = 0
        self._next_t = 0.0
        self._out = bytearray(RECORD_SIZE * self.buffer_records)
        self._out_view = memoryview(self._out)
        self._in = bytearray(512)

        self._skip_lock = threading.Lock()
        self._skip = 0
        self._closed = False

        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
            self._sock.setblocking(False)
            self._wake_r, self._wake_w = socket.socketpair()
        except OSError:
            self._sock.close()
            raise
        self.host, self.port = self._sock.getsockname()[:2]
        self._thread = threading.Thread(target=self._run, name=f"rdt-server:{self.port}",
                                        daemon=True)
        self._thread.start()

    # ---------------------------------------------------------------- public API
    @property
    def address(self) -> tuple[str, int]:
        """(host, port) the server is bound to."""
        return (self.host, self.port)

    @property
    def streaming(self) -> bool:
        """True while a start command is being served."""
        return self._dest is not None

    def skip_sequence(self, n: int) -> None:
        """Fault injection: advance ``rdt_sequence`` by ``n`` extra before the next record.

        To a client this looks exactly like ``n`` records lost on the network.
        """
        if n < 0:
            raise InputError(f"skip count must be >= 0, got {n}")
        with self._skip_lock:
            self._skip += n

    def close(self) -> None:
        """Stop the thread and release the socket; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass
        self._thread.join(timeout=5.0)
        for s in (self._sock, self._wake_r, self._wake_w):
            s.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---------------------------------------------------------------- thread
    def _run(self) -> None:
        sock, wake = self._sock, self._wake_r
        while True:
            if self._dest is None:
                timeout: float | None = None  # idle: sleep until a request or close
            else:
                timeout = max(0.0, self._next_t - time.monotonic())
            readable, _, _ = select.select([sock, wake], [], [], timeout)
            if wake in readable:
                return
            if sock in readable:
                self._drain_requests()
            if self._dest is not None:
                now = time.monotonic()
                if now >= self._next_t:
                    self._tick()
                    self._next_t += self._period
                    if now - self._next_t > 10.0 * self._period:
                        self._next_t = now + self._period

    def _drain_requests(self) -> None:
        sock, buf = self._sock, self._in
        while True:
            try:
                n, addr = sock.recvfrom_into(buf)
            except BlockingIOError:
                return
            except ConnectionRefusedError:
                # ICMP "port unreachable" from an earlier send to a client that went away.
                self.counters.send_errors += 1
                continue
            except OSError as exc:
                self.last_error = f"receive failed: {exc}"
                return
            self.counters.requests += 1
            try:
                request = decode_request(memoryview(buf)[:n])
            except ProtocolError as exc:
                self.counters.malformed_requests += 1  # the device ignores it, so do we
                self.last_error = str(exc)
                continue
            self._handle(request.command, request.sample_count, addr)

    def _handle(self, command: int, sample_count: int, addr: tuple[str, int]) -> None:
        if command == CMD_STOP:
            self._dest = None
            self._n_pending = 0
        elif command in (CMD_START_REALTIME, CMD_START_BUFFERED):
            self._dest = addr
            self._buffered = command == CMD_START_BUFFERED
            self._remaining = sample_count if sample_count > 0 else None
            self._rdt_sequence = 0
            self._n_pending = 0
            self._next_t = time.monotonic()
        elif command == CMD_SET_SOFTWARE_BIAS:
            try:
                # Averages BIAS_SAMPLES fresh samples, waiting one record period for each
                # the source has not produced yet (≈ 16 ms at 1 kHz; requests wait meanwhile).
                self._reader.set_bias(wait=lambda: time.sleep(self._period))
            # A faulty source must not kill the server thread.
            except Exception as exc:  # noqa: BLE001
                self.counters.source_errors += 1
                self.last_error = f"source failed during bias: {exc!r}"

    def _tick(self) -> None:
        reader = self._reader
        try:
            fresh = reader.poll()
        except Exception as exc:  # noqa: BLE001 - a faulty source must not kill the server thread
            self.counters.source_errors += 1
            self.last_error = f"source failed: {exc!r}"
            return
        if not fresh:
            self.counters.dropouts += 1
            return
        with self._skip_lock:
            skip, self._skip = self._skip, 0
        self._rdt_sequence = (self._rdt_sequence + 1 + skip) & 0xFFFF_FFFF
        try:
            counts = self.counts.to_counts(reader.value)
        except InputError as exc:
            self.counters.source_errors += 1
            self.last_error = f"source gave an unencodable wrench: {exc}"
            return
        pack_record_into(self._out, self._n_pending * RECORD_SIZE, self._rdt_sequence,
                         reader.ft_sequence, reader.status, counts)
        self._n_pending += 1
        if self._remaining is not None:
            self._remaining -= 1
        last = self._remaining == 0
        if not self._buffered or last or self._n_pending == self.buffer_records:
            self._send(self._n_pending)
            self._n_pending = 0
        if last:
            self._dest = None

    def _send(self, n_records: int) -> None:
        dest = self._dest
        if dest is None:
            return
        try:
            self._sock.sendto(self._out_view[:n_records * RECORD_SIZE], dest)
        except OSError as exc:
            self.counters.send_errors += 1
            self.last_error = f"send to {dest} failed: {exc}"
            return
        self.counters.datagrams_sent += 1
        self.counters.records_sent += n_records
