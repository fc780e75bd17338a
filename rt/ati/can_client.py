"""ATI Net F/T over CAN with python-can: the ``ati_can`` backend and the twin's responder.

Frame layouts and what was verified in the manual: ``rt.ati.can_protocol``. The Net F/T's CAN
protocol is request/response, so "streaming" here means a client thread that sends a
short-data request (0x02) at ``poll_rate_hz`` and assembles the two reply frames (base+5,
base+6) into one sample.

Both classes own one thread that blocks in ``bus.recv(timeout)``; the timeout bounds how long
``close()`` waits, it is not a poll loop.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any, Self

import can

from rt.ati.can_protocol import (
    DEFAULT_CAN_COUNTS_PER_FORCE,
    DEFAULT_CAN_COUNTS_PER_TORQUE,
    OFFSET_SHORT_XY,
    OFFSET_SHORT_Z,
    OP_BIAS,
    OP_REQUEST_SHORT,
    STATUS16_SATURATION_MASK,
    check_base_id,
    decode_request,
    decode_short_xy,
    decode_short_z,
    encode_request,
    encode_short_response,
    status16_from_status32,
    status32_from_status16,
    to_counts16,
)
from rt.ati.rdt import CountsPerUnit
from rt.ati.twin_sensor import SourceReader, WrenchSource
from rt.devices.interfaces import ForceTorqueSensor, Wrench
from rt.errors import HardwareError, InputError, ProtocolError

NAN = math.nan
#: Longest a thread blocks in recv before re-checking for close (s).
_RECV_SLICE_S = 0.05


def _open_bus(bus: can.BusABC | None, interface: str, channel: str,
              bus_kwargs: dict[str, Any]) -> tuple[can.BusABC, bool]:
    if bus is not None:
        return bus, False
    try:
        return can.Bus(interface=interface, channel=channel, **bus_kwargs), True
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise HardwareError(
            f"cannot open CAN bus {interface}:{channel}: {exc}; check the interface name and "
            "that the channel is up (e.g. 'ip link set can0 up type can bitrate 500000')"
        ) from exc


@dataclass(slots=True)
class AtiCanCounters:
    """Client statistics: ``requests`` sent, complete samples ``received``, frames rejected as
    ``malformed`` (wrong length, or a base+6 frame without its base+5), requests left without
    a complete reply (``timeouts``) and fresh -> stale transitions seen by ``read()``."""

    requests: int = 0
    received: int = 0
    malformed: int = 0
    timeouts: int = 0
    stale_events: int = 0


class AtiCanForceTorqueSensor(ForceTorqueSensor):
    """ATI Net F/T read over CAN (short data format).

    Parameters: ``interface``/``channel`` (python-can, e.g. "socketcan"/"can0"; tests use
    "virtual"), or an already open ``bus`` (then not shut down by ``close``); ``base_id``: the
    sensor's CAN base address; ``counts_per_force`` (counts/N) and ``counts_per_torque``
    (counts/(N m)) of the short format; ``poll_rate_hz``: request rate while started (Hz);
    ``timeout_s``: a reading is stale when no complete sample arrived, or the sample number did
    not advance, within this time (s). Extra keyword arguments go to ``can.Bus``.
    """

    def __init__(self, channel: str = "can0", interface: str = "socketcan", *,
                 base_id: int = 0x000,
                 counts_per_force: float = DEFAULT_CAN_COUNTS_PER_FORCE,
                 counts_per_torque: float = DEFAULT_CAN_COUNTS_PER_TORQUE,
                 poll_rate_hz: float = 500.0, timeout_s: float = 0.05,
                 bus: can.BusABC | None = None, **bus_kwargs: Any) -> None:
        if not poll_rate_hz > 0.0:
            raise InputError(f"poll_rate_hz must be > 0, got {poll_rate_hz}")
        if not timeout_s > 0.0:
            raise InputError(f"timeout_s must be > 0 s, got {timeout_s}")
        self.base_id = check_base_id(base_id)
        self.counts = CountsPerUnit(counts_per_force, counts_per_torque)
        self.poll_period_s = 1.0 / poll_rate_hz
        self.timeout_s = float(timeout_s)
        self.counters = AtiCanCounters()
        self.last_error = ""
        self._id_xy = base_id + OFFSET_SHORT_XY
        self._id_z = base_id + OFFSET_SHORT_Z
        self._request_short = can.Message(arbitration_id=base_id, is_extended_id=False,
                                          data=encode_request(OP_REQUEST_SHORT))
        self._lock = threading.Lock()
        self._latest = [NAN] * 6
        self._sample = -1
        self._status = 0
        self._t_rx = -math.inf
        self._t_sample_change = -math.inf
        self._was_stale = True
        self._xy: tuple[int, int, int, int] | None = None
        self._awaiting = False
        self._polling = threading.Event()
        self._closing = threading.Event()
        self._bus, self._owns_bus = _open_bus(bus, interface, channel, bus_kwargs)
        self._thread = threading.Thread(target=self._run, name=f"ati-can:{channel}", daemon=True)
        self._thread.start()

    # ---------------------------------------------------------------- ForceTorqueSensor
    def start(self) -> None:
        """Start polling the sensor with short-data requests (opcode 0x02)."""
        self._check_open()
        self._polling.set()

    def stop(self) -> None:
        """Stop polling."""
        self._check_open()
        self._polling.clear()

    def bias(self) -> None:
        """Bias (opcode 0x04): the sensor zeroes its readings at the current load."""
        self._check_open()
        self._send(can.Message(arbitration_id=self.base_id, is_extended_id=False,
                               data=encode_request(OP_BIAS)))

    def read(self, out: Wrench) -> Wrench:
        """Latest complete sample into ``out`` (N, N m; t = host monotonic time, s)."""
        now = time.monotonic()
        with self._lock:
            if self._sample < 0:
                out.invalidate()
                return out
            out.set(self._latest)
            out.t, out.sequence = self._t_rx, self._sample
            out.status = status32_from_status16(self._status)
            out.saturated = bool(self._status & STATUS16_SATURATION_MASK)
            stale = (now - self._t_rx > self.timeout_s
                     or now - self._t_sample_change > self.timeout_s)
            if stale and not self._was_stale:
                self.counters.stale_events += 1
            self._was_stale = stale
            out.stale = stale
        return out

    # ---------------------------------------------------------------- internals
    def _send(self, msg: can.Message) -> None:
        try:
            self._bus.send(msg, timeout=self.timeout_s)
        except can.CanError as exc:
            raise HardwareError(f"cannot send to ATI sensor on CAN: {exc}") from exc

    def _close(self) -> None:
        self._closing.set()
        self._polling.set()  # wake the thread if it waits for start()
        self._thread.join(timeout=5.0)
        if self._owns_bus:
            self._bus.shutdown()

    def _run(self) -> None:
        next_poll = time.monotonic()
        while not self._closing.is_set():
            if not self._polling.is_set():
                self._polling.wait()
                next_poll = time.monotonic()
                self._awaiting = False  # a reply missed while stopped is not a timeout
                continue
            now = time.monotonic()
            if now >= next_poll:
                if self._awaiting:
                    self.counters.timeouts += 1
                # _xy is kept: a reply in flight still pairs correctly, because the device
                # always sends base+5 before base+6 and a newer base+5 replaces an older one.
                try:
                    self._bus.send(self._request_short, timeout=self.timeout_s)
                    self.counters.requests += 1
                    self._awaiting = True
                except (can.CanError, OSError) as exc:
                    self.last_error = f"request failed: {exc}"
                next_poll += self.poll_period_s
                if now - next_poll > 10.0 * self.poll_period_s:
                    next_poll = now + self.poll_period_s
            try:
                msg = self._bus.recv(timeout=min(_RECV_SLICE_S,
                                                 max(0.0, next_poll - time.monotonic())))
            except (can.CanError, OSError) as exc:
                self.last_error = f"receive failed: {exc}"
                self._closing.wait(_RECV_SLICE_S)  # a bus that is down fails at once: no spin
                continue
            if msg is not None:
                self._on_frame(msg, time.monotonic())
        self._polling.clear()

    def _on_frame(self, msg: can.Message, t_rx: float) -> None:
        arb = msg.arbitration_id
        if msg.is_extended_id or (arb != self._id_xy and arb != self._id_z):
            return  # other traffic on the bus, not ours
        try:
            if msg.is_remote_frame or msg.is_error_frame:
                raise ProtocolError(f"unexpected remote/error frame on id 0x{arb:x}")
            if arb == self._id_xy:
                self._xy = decode_short_xy(msg.data)
                return
            fz, tz, status16, sample = decode_short_z(msg.data)
            xy = self._xy
            if xy is None:
                raise ProtocolError(f"Fz/Tz frame 0x{arb:x} without its Fx/Fy frame")
        except ProtocolError as exc:
            self.counters.malformed += 1
            self.last_error = str(exc)
            self._xy = None
            return
        self._xy = None
        self._awaiting = False
        fx, tx, fy, ty = xy
        cpf, cpt = self.counts.force, self.counts.torque
        with self._lock:
            latest = self._latest
            latest[0], latest[1], latest[2] = fx / cpf, fy / cpf, fz / cpf
            latest[3], latest[4], latest[5] = tx / cpt, ty / cpt, tz / cpt
            if sample != self._sample:
                self._t_sample_change = t_rx
            self._sample, self._status, self._t_rx = sample, status16, t_rx
            self.counters.received += 1


@dataclass(slots=True)
class AtiCanResponderCounters:
    """Responder statistics: ``requests`` for our base id, ``malformed`` ones (wrong length or
    opcode; the device ignores them), ``responses`` sent, ``dropouts`` (no sample to send)."""

    requests: int = 0
    malformed: int = 0
    responses: int = 0
    dropouts: int = 0
    source_errors: int = 0


class AtiCanResponder:
    """The twin side: answers Net F/T CAN requests on a bus with samples from ``source``.

    ``source`` follows the ``WrenchSource`` contract of ``rt.ati.twin_sensor`` (``None`` =
    dropout: no reply). Bias (0x04) zeroes at the current reading, like the device. Defaults to
    python-can's ``virtual`` interface; pass ``bus`` to share an open bus (not shut down here).
    """

    def __init__(self, source: WrenchSource, *, channel: str = "talus-ati",
                 interface: str = "virtual", base_id: int = 0x000,
                 counts_per_force: float = DEFAULT_CAN_COUNTS_PER_FORCE,
                 counts_per_torque: float = DEFAULT_CAN_COUNTS_PER_TORQUE,
                 bus: can.BusABC | None = None, **bus_kwargs: Any) -> None:
        self.base_id = check_base_id(base_id)
        self.counts = CountsPerUnit(counts_per_force, counts_per_torque)
        self.counters = AtiCanResponderCounters()
        self.last_error = ""
        self._reader = SourceReader(source)
        self._closing = threading.Event()
        self._closed = False
        self._bus, self._owns_bus = _open_bus(bus, interface, channel, bus_kwargs)
        self._thread = threading.Thread(target=self._run, name=f"ati-can-responder:{channel}",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the thread and release the bus (if owned); safe to call twice."""
        if self._closed:
            return
        self._closed = True
        self._closing.set()
        self._thread.join(timeout=5.0)
        if self._owns_bus:
            self._bus.shutdown()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        while not self._closing.is_set():
            try:
                msg = self._bus.recv(timeout=_RECV_SLICE_S)
            except (can.CanError, OSError) as exc:
                self.last_error = f"receive failed: {exc}"
                self._closing.wait(_RECV_SLICE_S)  # a bus that is down fails at once: no spin
                continue
            if msg is None or msg.arbitration_id != self.base_id or msg.is_extended_id:
                continue
            self.counters.requests += 1
            try:
                if msg.is_remote_frame or msg.is_error_frame:
                    raise ProtocolError("ATI CAN request is a remote/error frame")
                opcode = decode_request(self.base_id, msg.arbitration_id, msg.data)
            except ProtocolError as exc:
                self.counters.malformed += 1
                self.last_error = str(exc)
                continue
            try:
                if opcode == OP_BIAS:
                    self._reader.set_bias()
                elif opcode == OP_REQUEST_SHORT:
                    self._reply()
            # A faulty source must not kill the responder thread.
            except Exception as exc:  # noqa: BLE001
                self.counters.source_errors += 1
                self.last_error = f"source failed: {exc!r}"

    def _reply(self) -> None:
        reader = self._reader
        if not reader.poll():
            self.counters.dropouts += 1
            return
        xy, z = encode_short_response(to_counts16(reader.value, self.counts),
                                      status16_from_status32(reader.status),
                                      reader.ft_sequence)
        self._bus.send(can.Message(arbitration_id=self.base_id + OFFSET_SHORT_XY,
                                   is_extended_id=False, data=xy))
        self._bus.send(can.Message(arbitration_id=self.base_id + OFFSET_SHORT_Z,
                                   is_extended_id=False, data=z))
        self.counters.responses += 1
