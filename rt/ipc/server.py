"""The RT process's command and telemetry server (ZeroMQ ROUTER + PUB, one thread).

Requests are validated by :mod:`rt.ipc.messages` and dispatched to a plain handler object
(``handler.<cmd>(client=<the caller's id>, **args)``) on the server thread. Every request gets
exactly one reply; a bad request never reaches the handler and never stops the server. A handler
that cannot answer at once returns a :class:`Deferred`: the server keeps serving (other clients'
e-stops are never queued behind it) and replies when the deferred is ready.

The RT loop talks to the server only through :meth:`RtServer.publish` (a bounded hand-over
queue, never the network) and :meth:`RtServer.heartbeat_age_s` (one float read).
"""
from __future__ import annotations

import logging
import math
import socket
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol, Self

import zmq

from rt.errors import ConfigurationError, InputError, TalusError
from rt.ipc.messages import (
    COMMANDS,
    DEFAULT_ENDPOINT,
    DEFAULT_PUB_ENDPOINT,
    MAX_MESSAGE_BYTES,
    TOPICS,
    Request,
    RequestRejected,
    check_publication,
    decode_request,
    encode_publication,
    error_reply,
    ok_reply,
)
from rt.ipc.security import ServerCurveConfig, ServerSecurity, check_server_endpoint

log = logging.getLogger(__name__)

#: Handler methods the server dispatches to: every command but ``subscribe_info``, which the
#: server answers itself.
HANDLER_METHODS: tuple[str, ...] = tuple(c for c in COMMANDS if c != "subscribe_info")
# libzmq disconnects a peer whose frame exceeds this, reading only the frame's header (set
# before bind: ZMQ_MAXMSGSIZE applies to connections made after it is set); between
# MAX_MESSAGE_BYTES and this the peer gets an error reply instead. It guards the process's
# memory against a runaway or hostile peer.
_HARD_FRAME_LIMIT = 16 * 1024 * 1024
_MAX_REQUESTS_PER_TURN = 64  # so a flood of requests cannot starve publishing
_MAX_CLIENTS_TRACKED = 1000


#: How often a pending :class:`Deferred` is polled unless it says otherwise (s).
DEFERRED_POLL_S = 0.005


class Deferred:
    """A reply the handler cannot give at once: a reset answered after the cycle that took it,
    a session start answered after its pre-flight. The server calls ``poll()`` on its own
    thread once when the request arrives, then every ``poll_interval_s``, and at once after
    :meth:`notify`; ``poll`` returns the result dict when ready, None while not, or raises
    :class:`TalusError` (the error reply). Past ``timeout_s`` the reply is an error naming
    ``what``.

    Why not poll every millisecond: the server thread shares the GIL with the RT loop, and a
    wake-up per ms during a pre-flight of seconds is a thousand chances per second to hold the
    GIL when the loop wants it. A handler whose outcome comes from another thread (a session's
    pre-flight) calls :meth:`notify` when it is there, and polls rarely as a backstop."""

    def __init__(self, poll: Callable[[], dict[str, Any] | None], timeout_s: float,
                 what: str, poll_interval_s: float = DEFERRED_POLL_S) -> None:
        if not poll_interval_s > 0:
            raise ConfigurationError(f"poll_interval_s must be > 0, got {poll_interval_s!r}")
        self.poll = poll
        self.deadline = time.monotonic() + timeout_s
        self.what = what
        self.poll_interval_s = float(poll_interval_s)
        self.next_poll = -math.inf                  # polled at once when the server gets it
        self._wake: Callable[[], None] | None = None
        self._notified = False

    def notify(self) -> None:
        """The outcome may be ready: the server polls at once (any thread; never blocks)."""
        self._notified = True
        wake = self._wake
        if wake is not None:
            wake()


class Handler(Protocol):
    """What the server calls, one method per command (:data:`HANDLER_METHODS`), each with the
    caller's id as keyword ``client`` and the command's arguments. Each returns a JSON-able
    dict (or None for ``{}``), or a :class:`Deferred`, or raises :class:`rt.errors.TalusError`,
    whose message becomes the error reply. Called on the server thread: hand work to the RT
    loop or a worker, never block."""

    def status(self, client: str) -> dict[str, Any]: ...


class RtServer:
    """Serve commands on ``endpoint`` (ROUTER, for REQ clients) and publish on ``pub_endpoint``.

    Binds and starts its thread on construction; ``close()`` (or leaving the ``with`` block)
    stops it. A port of ``*`` (``tcp://127.0.0.1:*``) picks a free one; :attr:`endpoint` and
    :attr:`pub_endpoint` hold the bound addresses.

    Args:
        handler: the object commands are dispatched to (see :class:`Handler`).
        endpoint: request/reply address.
        pub_endpoint: telemetry/event address.
        heartbeat_timeout_s: age after which :meth:`heartbeat_lost` reports the client lost, s.
        publish_queue_len: hand-over queue length; when full the oldest message is dropped.
        context: a zmq context to share (default: a private one, terminated by ``close()``).
        poll_interval_s: longest wait of the server thread between checks of its stop flag, s
            (``close()`` wakes it at once; the wait only bounds a lost wake-up: the thread
            shares the GIL with the RT loop, and each idle wake-up is a chance to hold it
            when the loop wants it).
        curve: CurveZMQ keys (see :mod:`rt.ipc.security`); required for an endpoint that is
            not loopback.

    Raises:
        ConfigurationError: the handler lacks a command method, an endpoint cannot be bound,
            or is not loopback and no CurveZMQ keys are configured.
    """

    def __init__(self, handler: Handler, endpoint: str = DEFAULT_ENDPOINT,
                 pub_endpoint: str = DEFAULT_PUB_ENDPOINT, heartbeat_timeout_s: float = 0.25,
                 *, publish_queue_len: int = 1024,
                 context: zmq.Context[Any] | None = None,
                 poll_interval_s: float = 0.5,
                 curve: ServerCurveConfig | None = None) -> None:
        missing = [m for m in HANDLER_METHODS if not callable(getattr(handler, m, None))]
        if missing:
            raise ConfigurationError(
                f"RT server handler {type(handler).__name__} lacks {', '.join(missing)}")
        if not heartbeat_timeout_s > 0 or publish_queue_len < 1 or not poll_interval_s > 0:
            raise ConfigurationError("heartbeat_timeout_s and poll_interval_s must be > 0 and "
                                     "publish_queue_len >= 1")
        self._handler = handler
        self.heartbeat_timeout_s = float(heartbeat_timeout_s)
        self._poll_ms = max(1, int(poll_interval_s * 1000))
        self._own_context = context is None
        self._ctx = zmq.Context() if context is None else context
        self._router: zmq.Socket[bytes] | None = None
        self._pub: zmq.Socket[bytes] | None = None
        self._security: ServerSecurity | None = None
        self._wake_r, self._wake_w = socket.socketpair()
        try:
            if curve is not None:
                self._security = ServerSecurity(self._ctx, curve)
            for address in (endpoint, pub_endpoint):
                check_server_endpoint(address, self._security)
            self._router = self._bind(zmq.ROUTER, endpoint)
            self._pub = self._bind(zmq.PUB, pub_endpoint)
        except BaseException:
            self._release()
            raise
        self.endpoint: str = self._router.getsockopt_string(zmq.LAST_ENDPOINT)
        self.pub_endpoint: str = self._pub.getsockopt_string(zmq.LAST_ENDPOINT)
        for s in (self._wake_r, self._wake_w):
            s.setblocking(False)

        # Publish hand-over: guarded by _qlock, held only for O(1) work on either side.
        self._qlock = threading.Lock()
        self._queue: deque[tuple[str, dict[str, Any]]] = deque(maxlen=publish_queue_len)
        self._dropped_queue = 0      # under _qlock
        self._dropped_socket = 0     # server thread only
        self._published = 0
        self._publish_errors = 0

        # Heartbeats: per-client times under _clients_lock; the newest as one float that the
        # RT loop reads without a lock (a float attribute read is atomic).
        self._clients_lock = threading.Lock()
        self._last_seen: dict[str, float] = {}
        self._last_any = -math.inf

        # Replies the handler deferred: (routing envelope, request id, the deferred).
        self._deferred: list[tuple[list[bytes], int | str, Deferred]] = []

        self._requests = 0
        self._rejected = 0
        self._handler_errors = 0
        self._internal_errors = 0

        self._stop = threading.Event()
        self._closed = False
        self._thread = threading.Thread(target=self._serve, name="rt-ipc-server", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ lifecycle

    def _bind(self, kind: int, endpoint: str) -> zmq.Socket[bytes]:
        sock: zmq.Socket[bytes] = self._ctx.socket(kind)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.MAXMSGSIZE, _HARD_FRAME_LIMIT)   # before bind, or it is ignored
        if self._security is not None:
            self._security.apply(sock)
        try:
            sock.bind(endpoint)
        except zmq.ZMQError as exc:
            sock.close()
            raise ConfigurationError(
                f"cannot bind the RT server to {endpoint}: {exc}; is another `talus rt serve` "
                f"running, or is the address wrong?") from None
        return sock

    def _release(self) -> None:
        for sock in (self._router, self._pub):
            if sock is not None:
                sock.close(linger=0)
        self._wake_r.close()
        self._wake_w.close()
        if self._security is not None:
            self._security.close()      # its ZAP socket lives on the context
        if self._own_context:
            self._ctx.term()

    def close(self) -> None:
        """Stop the server thread and close the sockets; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._wake()
        self._thread.join(timeout=5.0)
        if self._thread.is_alive():
            # A handler is stuck; closing its sockets under it would crash libzmq.
            log.error("RT server thread did not stop within 5 s (handler stuck?); "
                      "sockets left open")
            return
        self._release()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ RT-loop side

    def publish(self, topic: str, payload: dict[str, Any]) -> bool:
        """Queue ``payload`` for publication on ``topic`` ("telemetry" or "event"); never blocks
        on the network.

        The server adds ``v`` and ``topic``; telemetry needs ``t`` (s), events ``t``, ``kind``,
        ``cause``. The dict is handed over: do not mutate it afterwards (it is encoded later on
        the server thread). numpy arrays and scalars are accepted.

        Returns:
            False when the queue was full and the oldest queued message was dropped (counted in
            :attr:`dropped`), or the server is closed; True otherwise.

        Raises:
            InputError: unknown topic or a required key missing (a programming error).
        """
        problem = check_publication(topic, payload)
        if problem is not None:
            raise InputError(problem)
        if self._closed:
            with self._qlock:
                self._dropped_queue += 1
            return False
        with self._qlock:
            queue = self._queue
            was_empty = not queue
            full = len(queue) == queue.maxlen
            if full:
                self._dropped_queue += 1
            queue.append((topic, payload))  # evicts the oldest when full: newest data wins
        if was_empty:
            # One wake-up per batch: later appends find the queue non-empty and the server
            # thread drains everything under the same lock, so none is left behind.
            self._wake()
        return not full

    def heartbeat_age_s(self, now: float | None = None) -> float:
        """Seconds since the newest request from any client (``time.monotonic`` clock);
        ``inf`` when no client ever sent one."""
        t = time.monotonic() if now is None else now
        return t - self._last_any

    def heartbeat_lost(self, now: float | None = None) -> bool:
        """True when some client has sent a request but none for ``heartbeat_timeout_s``."""
        age = self.heartbeat_age_s(now)
        return math.isfinite(age) and age > self.heartbeat_timeout_s

    def last_seen_age_s(self, client: str, now: float | None = None) -> float:
        """Seconds since ``client``'s newest request (monotonic clock); ``inf`` if never seen.
        One dict read, no lock: cheap enough for the RT loop to call every cycle."""
        seen = self._last_seen.get(client)
        if seen is None:
            return math.inf
        return (time.monotonic() if now is None else now) - seen

    def clients(self, now: float | None = None) -> dict[str, float]:
        """Every client id seen so far -> seconds since its last request (monotonic clock)."""
        t = time.monotonic() if now is None else now
        with self._clients_lock:
            return {c: t - seen for c, seen in self._last_seen.items()}

    @property
    def dropped(self) -> int:
        """Publications dropped: evicted from a full hand-over queue, or refused by the socket."""
        return self._dropped_queue + self._dropped_socket

    def stats(self) -> dict[str, int]:
        """Counters: requests, rejected (invalid), handler_errors (TalusError),
        internal_errors, published, dropped, publish_errors (payload not JSON-serializable)."""
        return {"requests": self._requests, "rejected": self._rejected,
                "handler_errors": self._handler_errors, "internal_errors": self._internal_errors,
                "published": self._published, "dropped": self.dropped,
                "publish_errors": self._publish_errors}

    def _wake(self) -> None:
        try:
            self._wake_w.send(b"\0")
        except OSError:
            pass  # buffer full (a wake-up is already pending) or closed during shutdown

    # ------------------------------------------------------------------ server thread

    def _serve(self) -> None:
        assert self._router is not None
        poller = zmq.Poller()
        poller.register(self._router, zmq.POLLIN)
        poller.register(self._wake_r.fileno(), zmq.POLLIN)
        while not self._stop.is_set():
            try:
                events = dict(poller.poll(self._poll_timeout_ms()))
                if self._router in events:
                    self._handle_requests()
                if self._wake_r.fileno() in events:
                    self._drain_wake()
                if self._deferred:
                    self._flush_deferred()
                self._flush_publications()
            except zmq.ContextTerminated:
                return
            except Exception:  # keep serving: a dead server would leave the robot deaf
                log.exception("RT server loop error (continuing)")
                time.sleep(0.01)

    def _poll_timeout_ms(self) -> int:
        """Until the next deferred reply is due (its poll interval or its deadline), at most
        the stop-flag period."""
        if not self._deferred:
            return self._poll_ms
        now = time.monotonic()
        wait_s = min(min(d.next_poll, d.deadline) for _, _, d in self._deferred) - now
        if wait_s <= 0.0 or any(d._notified for _, _, d in self._deferred):
            return 0                           # due now (a new one's next_poll is -inf)
        return min(self._poll_ms, math.ceil(wait_s * 1000.0))

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except OSError:
            pass

    def _handle_requests(self) -> None:
        assert self._router is not None
        for _ in range(_MAX_REQUESTS_PER_TURN):
            try:
                frames = self._router.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                return
            envelope, body = _split_envelope(frames)
            reply = self._reply_to(body)
            if isinstance(reply, tuple):           # deferred: answered by _flush_deferred
                reply[1]._wake = self._wake
                self._deferred.append((envelope, *reply))
                continue
            self._send(envelope, reply)

    def _send(self, envelope: list[bytes], reply: bytes) -> None:
        assert self._router is not None
        try:
            self._router.send_multipart([*envelope, reply], zmq.NOBLOCK)
        except zmq.Again:
            log.warning("RT server: reply dropped (client not reading)")

    def _flush_deferred(self) -> None:
        now = time.monotonic()
        pending = []
        for envelope, request_id, deferred in self._deferred:
            if now < deferred.next_poll and now < deferred.deadline and not deferred._notified:
                pending.append((envelope, request_id, deferred))
                continue
            deferred._notified = False
            deferred.next_poll = now + deferred.poll_interval_s
            try:
                result = deferred.poll()
                if result is None:
                    if now < deferred.deadline:
                        pending.append((envelope, request_id, deferred))
                        continue
                    reply = error_reply(request_id, f"{deferred.what}: no outcome in time")
                else:
                    reply = ok_reply(request_id, result)
            except TalusError as exc:
                self._handler_errors += 1
                reply = error_reply(request_id, str(exc) or type(exc).__name__)
            except Exception as exc:  # a handler bug must not take the server down
                self._internal_errors += 1
                log.exception("RT server: deferred %s failed", deferred.what)
                reply = error_reply(request_id, f"internal error: {type(exc).__name__}: {exc}")
            self._send(envelope, reply)
        self._deferred = pending

    def _reply_to(self, body: list[bytes]) -> bytes | tuple[int | str, Deferred]:
        self._requests += 1
        try:
            if len(body) != 1:
                size = sum(len(f) for f in body)
                raise RequestRejected(
                    f"message too large: {size} bytes > {MAX_MESSAGE_BYTES} bytes allowed"
                    if size > MAX_MESSAGE_BYTES else
                    f"malformed message: expected one frame, got {len(body)}")
            request = decode_request(body[0])
        except RequestRejected as exc:
            self._rejected += 1
            return error_reply(exc.request_id, str(exc))
        self._touch(request.client)
        return self._dispatch(request)

    def _touch(self, client: str) -> None:
        now = time.monotonic()
        with self._clients_lock:
            self._last_seen[client] = now
            if len(self._last_seen) > _MAX_CLIENTS_TRACKED:
                # Forget clients silent for an hour (one-shot CLI calls each bring a new id).
                for c in [c for c, seen in self._last_seen.items() if now - seen > 3600.0]:
                    del self._last_seen[c]
        self._last_any = now

    def _dispatch(self, request: Request) -> bytes | tuple[int | str, Deferred]:
        cmd = request.cmd
        try:
            if cmd == "subscribe_info":
                result: Any = {"pub_endpoint": self.pub_endpoint, "topics": list(TOPICS)}
            else:
                result = getattr(self._handler, cmd)(client=request.client, **request.kwargs())
            if isinstance(result, Deferred):
                return request.id, result
            if result is None:
                result = {}
            if not isinstance(result, dict):
                raise TypeError(f"handler.{cmd} returned {type(result).__name__}, not a dict")
            return ok_reply(request.id, result)
        except TalusError as exc:
            self._handler_errors += 1
            return error_reply(request.id, str(exc) or type(exc).__name__)
        except Exception as exc:  # a handler bug must not take the server down
            self._internal_errors += 1
            log.exception("RT server: %r from client %r failed", cmd, request.client)
            return error_reply(request.id, f"internal error: {type(exc).__name__}: {exc}")

    def _flush_publications(self) -> None:
        assert self._pub is not None
        with self._qlock:
            if not self._queue:
                return
            batch = self._queue
            self._queue = deque(maxlen=batch.maxlen)  # O(1) swap keeps the lock short
        for topic, payload in batch:
            try:
                frames = encode_publication(topic, payload)
            except (TypeError, ValueError) as exc:
                self._publish_errors += 1
                log.warning("RT server: %s payload not published: %s", topic, exc)
                continue
            try:
                # PUB drops silently for a subscriber past its high-water mark; Again is only
                # the belt to those braces.
                self._pub.send_multipart(frames, zmq.NOBLOCK)
                self._published += 1
            except zmq.Again:
                self._dropped_socket += 1


def _split_envelope(frames: list[bytes]) -> tuple[list[bytes], list[bytes]]:
    """Split ROUTER frames into the routing envelope (identities + empty delimiter, as REQ
    sends) and the body; a DEALER peer without a delimiter gets just its identity back."""
    for i in range(1, len(frames)):
        if frames[i] == b"":
            return frames[:i + 1], frames[i + 1:]
    return frames[:1], frames[1:]
