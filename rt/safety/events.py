"""Safety events: what happened, when, why, with which values, and what was done about it."""
from __future__ import annotations

import enum
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field


class Reaction(enum.IntEnum):
    """Escalating reactions; a latched fault keeps the highest one until a reset."""

    NONE = 0
    WARN = 1
    SOFT_STOP = 2     # jerk-limited braking to a hold, drives stay enabled (stop category 2)
    HARD_STOP = 3     # outputs to zero, drives disabled (stop category 0)
    FAILOVER = 4      # an actuator channel moved to the redundant card (not a stop)


class SupervisorMode(enum.IntEnum):
    """What the supervisor lets the loop do, carried on its ``mode`` port (float64[1]) to the
    reference and the controller one cycle late. A warning does not change the mode."""

    RUN = 0
    SOFT_STOP = 2     # brake to a hold, ramp force down, drives enabled
    HARD_STOP = 3     # outputs zero, drives disabled

    @classmethod
    def of(cls, reaction: Reaction) -> SupervisorMode:
        """The mode a latched reaction puts the loop in."""
        if reaction >= Reaction.HARD_STOP and reaction != Reaction.FAILOVER:
            return cls.HARD_STOP
        return cls.SOFT_STOP if reaction == Reaction.SOFT_STOP else cls.RUN

    @classmethod
    def from_port(cls, value: float) -> SupervisorMode:
        """The mode a ``mode`` port carries."""
        return cls(int(value))


@dataclass
class SafetyEvent:
    """One event. ``t`` is loop time (s), ``wall`` the host's wall clock (s since the epoch)."""

    t: float
    kind: str                    # "fault", "warn", "reset", "reset_refused", "failover"
    cause: str                   # machine-readable cause, e.g. "rom_roll_max", "estop_gui"
    reaction: Reaction
    message: str
    values: dict = field(default_factory=dict)
    wall: float = field(default_factory=time.time)
    #: Sequence number given by the log (1, 2, ...): what a reset acknowledges.
    id: int = 0

    def as_dict(self) -> dict:
        d = asdict(self)
        d["reaction"] = self.reaction.name.lower()
        return d


class EventLog:
    """Bounded, thread-safe record of events; ``listener`` (e.g. the IPC publisher, which must
    not block) is called with each new event's dict."""

    def __init__(self, capacity: int = 4096, listener: Callable[[dict], object] | None = None):
        self._events: deque[SafetyEvent] = deque(maxlen=capacity)
        self._lock = threading.Lock()
        self.listener = listener
        self.count = 0

    def append(self, event: SafetyEvent) -> None:
        # Events are rare (a fault, a reset): allocating one here is acceptable in the cycle.
        with self._lock:
            self.count += 1
            event.id = self.count
            self._events.append(event)
        if self.listener is not None:
            self.listener(event.as_dict())

    def snapshot(self) -> list[SafetyEvent]:
        with self._lock:
            return list(self._events)

    def first(self, cause_prefix: str = "") -> SafetyEvent | None:
        for e in self.snapshot():
            if e.cause.startswith(cause_prefix):
                return e
        return None
