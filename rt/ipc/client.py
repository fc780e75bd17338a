"""Client side of the RT process boundary: commands, heartbeat, telemetry subscription.

Qt-free: the GUI runs these from worker threads. :class:`RtClient` is thread-safe (one request
at a time on its socket); its heartbeat thread has a socket of its own so a slow command never
delays a heartbeat from this side.
"""
from __future__ import annotations

import itertools
import math
import os
import threading
import time
import uuid
from typing import Any, Iterable

import zmq

from rt.errors import HardwareError, InputError, ProtocolError, TalusError
from rt.ipc.messages import (
    DEFAULT_ENDPOINT, TOPICS, decode_publication, decode_reply, encode_request,
)
from rt.ipc.security import ClientCurveConfig, ClientSecurity, check_client_endpoint

_CANCEL_SLICE_S = 0.05  # how often a cancellable wait checks its stop flag, s


class RtUnavailableError(HardwareError):
    """The RT server did not answer in time (not running, wrong endpoint, or stuck)."""


def default_client_id(prefix: str = "py") -> str:
    """A client id unique to this process and object: ``<prefix>-<pid>-<8 hex>``."""
    return f"{prefix}-{os.getpid()}-{uuid.uuid4().hex[:8]}"


class _ReqChannel:
    """One REQ socket with the lazy-pirate recovery: a REQ socket that missed its reply is
    stuck in its send/recv state machine, so after a timeout it is discarded and the next
    request opens a fresh one. Not thread-safe: one owner thread."""

    def __init__(self, ctx: zmq.Context[Any], endpoint: str,
                 security: ClientSecurity | None = None) -> None:
        self._ctx = ctx
        self.endpoint = endpoint
        self._security = security
        self._sock: zmq.Socket[bytes] | None = None

    def _open(self) -> zmq.Socket[bytes]:
        sock: zmq.Socket[bytes] = self._ctx.socket(zmq.REQ)
        sock.setsockopt(zmq.LINGER, 0)  # a request nobody answered must not hold up close()
        if self._security is not None:
            self._security.apply(sock)
        try:
            sock.connect(self.endpoint)
        except zmq.ZMQError as exc:
            sock.close()
            raise InputError(f"bad RT server endpoint {self.endpoint!r}: {exc}") from None
        self._sock = sock
        return sock

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close(linger=0)
            self._sock = None

    def request(self, body: bytes, timeout_s: float,
                cancel: threading.Event | None = None) -> bytes:
        """Send ``body`` and wait up to ``timeout_s`` s for the reply frame.

        Raises:
            RtUnavailableError: no reply in time (or ``cancel`` was set); the socket is reset.
        """
        sock = self._sock or self._open()
        deadline = time.monotonic() + timeout_s
        try:
            sock.send(body, zmq.NOBLOCK)
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0 or (cancel is not None and cancel.is_set()):
                    break
                wait = min(remaining, _CANCEL_SLICE_S) if cancel is not None else remaining
                if sock.poll(max(1, math.ceil(wait * 1000)), zmq.POLLIN):
                    return sock.recv()
        except zmq.Again:
            pass  # cannot even queue the request: treat like no reply
        self.close()
        raise RtUnavailableError(
            f"no reply from the RT server at {self.endpoint} within {timeout_s:g} s; "
            f"is `talus rt serve` running there?")


class RtClient:
    """Send commands to the RT server and, optionally, heartbeat from a background thread.

    Args:
        endpoint: the server's request address.
        client_id: this client's name in the server's heartbeat table (default: unique).
        timeout_s: longest wait for a reply, s.
        context: a zmq context to share (default: a private one, terminated by ``close()``).
        curve: this client's key pair and the server's public key (:mod:`rt.ipc.security`);
            required when ``endpoint`` is not loopback.

    Raises:
        ConfigurationError: a non-loopback endpoint without ``curve``, or unreadable keys.
    """

    def __init__(self, endpoint: str = DEFAULT_ENDPOINT, client_id: str | None = None,
                 timeout_s: float = 1.0, *,
                 context: zmq.Context[Any] | None = None,
                 curve: ClientCurveConfig | None = None) -> None:
        if not timeout_s > 0:
            raise InputError(f"timeout_s must be > 0, got {timeout_s}")
        self.curve = curve
        self._security = None if curve is None else ClientSecurity(curve)
        check_client_endpoint(endpoint, self._security)
        self.endpoint = endpoint
        self.client_id = client_id or default_client_id()
        self.timeout_s = float(timeout_s)
        self._own_context = context is None
        self._ctx = zmq.Context() if context is None else context
        self._lock = threading.Lock()
        self._channel = _ReqChannel(self._ctx, endpoint, self._security)
        self._ids = itertools.count(1)  # next() on a C iterator is atomic under the GIL
        self._hb_thread: threading.Thread | None = None
        self._hb_stop = threading.Event()
        #: heartbeats that got no (or an error) reply since start_heartbeat
        self.heartbeat_failures = 0
        #: message of the last failed heartbeat, None after a successful one
        self.last_heartbeat_error: str | None = None
        self._closed = False

    # ------------------------------------------------------------------ requests

    def _call(self, channel: _ReqChannel, cmd: str, args: dict[str, Any],
              cancel: threading.Event | None = None,
              timeout_s: float | None = None) -> dict[str, Any]:
        request_id = next(self._ids)
        body = encode_request(request_id, self.client_id, cmd, args)  # refuses bad args here
        reply = decode_reply(channel.request(body, timeout_s or self.timeout_s, cancel))
        if reply.id != request_id:
            # Cannot happen with a fresh REQ socket per timeout; a server bug if it does.
            raise ProtocolError(f"RT server answered request {reply.id!r} to {request_id!r}")
        if not reply.ok:
            raise InputError(reply.error or "request refused")
        assert reply.result is not None
        return reply.result

    def request(self, cmd: str, /, *, timeout_s: float | None = None,
                **args: Any) -> dict[str, Any]:
        """Send ``cmd`` with ``args`` and return the reply's ``result`` (waiting up to
        ``timeout_s``, default the client's).

        Raises:
            InputError: the request is invalid (checked before sending) or the server refused
                it; the message is the server's.
            RtUnavailableError: no reply within ``timeout_s`` (the client stays usable).
            ProtocolError: the reply was not a valid v1 reply.
        """
        if self._closed:
            raise InputError("RtClient is closed")
        with self._lock:
            return self._call(self._channel, cmd, args, timeout_s=timeout_s)

    def status(self) -> dict[str, Any]:
        """The RT process's status (the handler's dict)."""
        return self.request("status")

    def heartbeat(self) -> dict[str, Any]:
        """One heartbeat (any request also counts as one)."""
        return self.request("heartbeat")

    def stop(self) -> dict[str, Any]:
        """Soft stop: decelerate to hold, ramp force down."""
        return self.request("stop")

    def estop(self, source: str) -> dict[str, Any]:
        """Hard stop from ``source`` ("gui", "cli" or "keyboard")."""
        return self.request("estop", source=source)

    def reset(self, acknowledge: list[int] | None = None) -> dict[str, Any]:
        """Reset the latched faults with these event ids (default: those ``status`` shows now).
        Only the owner may; the reply comes after the cycle that took the reset."""
        if acknowledge is None:
            acknowledge = [e["id"] for e in self.status()["latched"]]
        return self.request("reset", acknowledge=list(acknowledge))

    def control_acquire(self, name: str) -> dict[str, Any]:
        """Become the client that controls the robot (``name`` is shown to the others)."""
        return self.request("control_acquire", name=name)

    def control_release(self) -> dict[str, Any]:
        """Give control back (refused while a motion or a session runs)."""
        return self.request("control_release")

    def session_start(self, protocol: dict[str, Any], patient: dict[str, Any],
                      record: dict[str, Any] | None = None,
                      timeout_s: float = 120.0) -> dict[str, Any]:
        """Start a session: the RT process validates and pre-flights the protocol (seconds),
        then answers with the session id and the predicted peaks, or refuses with the reason.
        Only the owner may; keep heartbeating while it runs."""
        return self.request("session_start", timeout_s=timeout_s, protocol=protocol,
                            patient=patient, record=record or {})

    def session_preflight(self, protocol: dict[str, Any], patient: dict[str, Any],
                          timeout_s: float = 120.0) -> dict[str, Any]:
        """The pre-flight alone: ``{"ok", "predicted", "duration_s", ...}``, or the refusal's
        reason as :class:`InputError`. Nothing moves; anyone may ask."""
        return self.request("session_preflight", timeout_s=timeout_s, protocol=protocol,
                            patient=patient)

    def session_status(self) -> dict[str, Any]:
        """The running session's phase, progress, forces and stops, or the last summary."""
        return self.request("session_status")

    def session_abort(self) -> dict[str, Any]:
        """Soft-stop the session, then return to rest (anyone may)."""
        return self.request("session_abort")

    def set_gains(self, controller: str, gains: dict[str, float]) -> dict[str, Any]:
        """Set gains of ``controller`` (names and units are the controller's)."""
        return self.request("set_gains", controller=controller, gains=gains)

    def run(self, program: str, params: dict[str, Any] | None = None) -> dict[str, Any]:
        """Start motion program ``program`` with ``params``."""
        return self.request("run", program=program, params={} if params is None else params)

    def subscribe_info(self) -> dict[str, Any]:
        """``{"pub_endpoint": ..., "topics": [...]}`` of the server."""
        return self.request("subscribe_info")

    def subscribe(self, topics: Iterable[str] = TOPICS) -> Subscriber:
        """A :class:`Subscriber` to the server's PUB endpoint (asked with ``subscribe_info``).
        It has its own context, so it may outlive this client and live in another thread."""
        return Subscriber(self.subscribe_info()["pub_endpoint"], topics, curve=self.curve)

    # ------------------------------------------------------------------ heartbeat

    @property
    def heartbeat_running(self) -> bool:
        """True while the heartbeat thread runs."""
        return self._hb_thread is not None and self._hb_thread.is_alive()

    def start_heartbeat(self, period_s: float = 0.05) -> None:
        """Send a heartbeat every ``period_s`` s from a background thread (no-op if running).
        Failures are counted (:attr:`heartbeat_failures`) and the thread keeps trying."""
        if not period_s > 0:
            raise InputError(f"heartbeat period_s must be > 0, got {period_s}")
        if self._closed:
            raise InputError("RtClient is closed")
        if self.heartbeat_running:
            return
        self._hb_stop.clear()
        self._hb_thread = threading.Thread(target=self._heartbeat_loop, args=(period_s,),
                                           name="rt-ipc-heartbeat", daemon=True)
        self._hb_thread.start()

    def stop_heartbeat(self) -> None:
        """Stop the heartbeat thread (returns within about 50 ms)."""
        thread = self._hb_thread
        if thread is None:
            return
        self._hb_stop.set()
        thread.join()
        self._hb_thread = None

    def _heartbeat_loop(self, period_s: float) -> None:
        channel = _ReqChannel(self._ctx, self.endpoint, self._security)  # one thread's socket
        try:
            next_t = time.monotonic()
            while not self._hb_stop.is_set():
                try:
                    self._call(channel, "heartbeat", {}, cancel=self._hb_stop)
                    self.last_heartbeat_error = None
                except TalusError as exc:
                    if self._hb_stop.is_set():
                        break
                    self.heartbeat_failures += 1
                    self.last_heartbeat_error = str(exc)
                # Fixed rate, but no burst to catch up after a long stall.
                next_t = max(next_t + period_s, time.monotonic())
                self._hb_stop.wait(next_t - time.monotonic())
        finally:
            channel.close()

    # ------------------------------------------------------------------ lifecycle

    def close(self) -> None:
        """Stop the heartbeat, close the socket (and the private context); safe twice."""
        if self._closed:
            return
        self._closed = True
        self.stop_heartbeat()
        with self._lock:
            self._channel.close()
        if self._own_context:
            self._ctx.term()

    def __enter__(self) -> RtClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Subscriber:
    """Receive telemetry and events from the RT server's PUB endpoint.

    PUB/SUB drops rather than blocks: a subscriber that reads too slowly loses messages
    (beyond ``rcvhwm`` queued ones), and messages published before the subscription reached
    the server are never seen (ZeroMQ's "slow joiner").

    Args:
        pub_endpoint: the server's PUB address (``subscribe_info()["pub_endpoint"]``).
        topics: any of "telemetry", "event".
        context: a zmq context to share (default: a private one, terminated by ``close()``).
        rcvhwm: messages queued for this subscriber before newer ones are dropped.
        curve: as for :class:`RtClient`; required when ``pub_endpoint`` is not loopback.
    """

    def __init__(self, pub_endpoint: str, topics: Iterable[str] = TOPICS, *,
                 context: zmq.Context[Any] | None = None, rcvhwm: int = 10_000,
                 curve: ClientCurveConfig | None = None) -> None:
        self.topics = tuple(topics)
        unknown = [t for t in self.topics if t not in TOPICS]
        if unknown or not self.topics:
            raise InputError(f"unknown or no topics {unknown or list(self.topics)}; "
                             f"topics: {', '.join(TOPICS)}")
        security = None if curve is None else ClientSecurity(curve)
        check_client_endpoint(pub_endpoint, security)
        self.pub_endpoint = pub_endpoint
        self._own_context = context is None
        self._ctx = zmq.Context() if context is None else context
        self._sock = self._ctx.socket(zmq.SUB)
        self._sock.setsockopt(zmq.LINGER, 0)
        self._sock.setsockopt(zmq.RCVHWM, rcvhwm)
        if security is not None:
            security.apply(self._sock)
        try:
            self._sock.connect(pub_endpoint)
        except zmq.ZMQError as exc:
            self._sock.close()
            if self._own_context:
                self._ctx.term()
            raise InputError(f"bad RT publish endpoint {pub_endpoint!r}: {exc}") from None
        for topic in self.topics:
            self._sock.setsockopt(zmq.SUBSCRIBE, topic.encode())
        self._closed = False

    def recv(self, timeout_s: float = 0.0) -> dict[str, Any] | None:
        """The next message (``{"v": 1, "topic": ..., "t": ..., ...}``), or None if none
        arrived within ``timeout_s`` s.

        Raises:
            ProtocolError: the publisher sent something that is not a v1 publication.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            wait_ms = max(0, math.ceil((deadline - time.monotonic()) * 1000))
            if not self._sock.poll(wait_ms, zmq.POLLIN):
                return None
            frames = self._sock.recv_multipart(zmq.NOBLOCK)
            # SUBSCRIBE matches prefixes; keep only the exact topics asked for.
            if frames and frames[0].decode("utf-8", "replace") in self.topics:
                return decode_publication(frames)

    def close(self) -> None:
        """Close the socket (and the private context); safe to call twice."""
        if self._closed:
            return
        self._closed = True
        self._sock.close(linger=0)
        if self._own_context:
            self._ctx.term()

    def __enter__(self) -> Subscriber:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
