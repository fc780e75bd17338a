"""Runtime reconfiguration: commands queued by any thread, applied by the loop at a cycle
boundary (DESIGN 5: gains, sample period, controller switch).

A command is submitted through the :class:`~rt.engine.loop.Loop` (``set_rate``,
``set_param``/``set_params``, ``swap``) and immediately returns a :class:`CommandResult`, a
small future. What can be checked without touching the running graph (slot names, rate
range, port compatibility of a swap, configuring the new component) is checked at
submission; a command refused there is returned already completed. The rest happens in the
loop's thread at the start of the next cycle, before any component runs: a command either
applies completely or changes nothing.
"""
from __future__ import annotations

import threading
from collections import deque
from typing import Any

from rt.errors import InputError, TalusError


class CommandResult:
    """Outcome of a command: pending until the loop applies (or refuses) it.

    ``ok`` is None while pending, then True/False; ``error`` says why it was refused; ``cycle``
    is the loop cycle at whose start it was applied (its effects are visible to every
    component's ``update`` in that cycle; a new rate sets the period that follows it).
    """

    __slots__ = ("_event", "cycle", "description", "error", "ok", "value")

    def __init__(self, description: str) -> None:
        self.description = description
        self.ok: bool | None = None
        self.error: str | None = None
        self.cycle: int | None = None
        self.value: Any = None
        self._event = threading.Event()

    def _complete(self, ok: bool, error: str | None = None, cycle: int | None = None,
                  value: Any = None) -> CommandResult:
        self.ok, self.error, self.cycle, self.value = ok, error, cycle, value
        self._event.set()
        return self

    def done(self) -> bool:
        """True once applied or refused."""
        return self._event.is_set()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until done or ``timeout`` (s) passes; returns :meth:`done`. Commands are only
        applied while the loop runs, so give a timeout unless it surely runs."""
        return self._event.wait(timeout)

    def result(self, timeout: float | None = None) -> Any:
        """Wait, then return ``value``; raise TimeoutError if still pending, InputError if
        refused."""
        if not self._event.wait(timeout):
            raise TimeoutError(f"{self.description}: not applied within {timeout} s "
                               "(is the loop running?)")
        if not self.ok:
            raise InputError(f"{self.description}: {self.error}")
        return self.value

    def __repr__(self) -> str:
        status = ("pending" if self.ok is None else
                  f"ok at cycle {self.cycle}" if self.ok else f"refused: {self.error}")
        return f"<CommandResult {self.description}: {status}>"


class Command:
    """Base: ``apply(loop)`` runs in the loop's thread at a boundary; it returns the result's
    value or raises TalusError (nothing changed)."""

    description = "command"

    def __init__(self) -> None:
        self.result = CommandResult(self.description)

    def apply(self, loop: Any) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError


class CommandQueue:
    """Bounded, thread-safe FIFO of commands.

    ``deque.append``/``popleft`` are atomic under the GIL, so the loop drains without a lock;
    the lock only makes the capacity check and the append one step for concurrent submitters.
    """

    def __init__(self, capacity: int = 64) -> None:
        self.capacity = capacity
        self._dq: deque[Command] = deque()
        self._lock = threading.Lock()

    def submit(self, cmd: Command) -> CommandResult:
        with self._lock:
            if len(self._dq) >= self.capacity:
                return cmd.result._complete(
                    False, f"command queue full ({self.capacity} pending); is the loop running?")
            self._dq.append(cmd)
        return cmd.result

    def __len__(self) -> int:
        return len(self._dq)

    def drain(self, loop: Any, cycle: int) -> int:
        """Apply every pending command in order; returns how many were taken."""
        n = 0
        dq = self._dq
        while dq:
            cmd = dq.popleft()
            n += 1
            try:
                value = cmd.apply(loop)
            except TalusError as exc:
                cmd.result._complete(False, str(exc), cycle)
            except Exception as exc:  # noqa: BLE001 - a buggy hook must not kill the loop
                cmd.result._complete(False, f"{type(exc).__name__}: {exc}", cycle)
            else:
                cmd.result._complete(True, None, cycle, value)
        return n

    def cancel_all(self, reason: str) -> None:
        """Refuse everything still pending (e.g. when the loop is discarded)."""
        while self._dq:
            self._dq.popleft().result._complete(False, reason)


class SetRate(Command):
    """Change the loop rate (Hz); applies to the period that follows the cycle it is drained in."""

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.description = f"set_rate({rate_hz} Hz)"
        super().__init__()

    def apply(self, loop: Any) -> float:
        loop._apply_rate(self.rate_hz)
        return self.rate_hz


class SetParams(Command):
    """Replace parameters of the component in a slot (all or nothing); value = the new params."""

    def __init__(self, slot: str, values: dict[str, Any]) -> None:
        self.slot, self.values = slot, dict(values)
        args = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        self.description = f"set_params({slot!r}, {args})"
        super().__init__()

    def apply(self, loop: Any) -> Any:
        loop.graph.set_params(self.slot, **self.values)
        return loop.graph.component(self.slot).params


class Swap(Command):
    """Put a prepared component in its slot (start, handover, switch); value = the new one."""

    def __init__(self, plan: Any) -> None:
        self.plan = plan
        self.description = f"swap({plan.slot!r}, {plan.new.name!r})"
        super().__init__()

    def apply(self, loop: Any) -> Any:
        loop.graph.commit_swap(self.plan)
        return self.plan.new


class Call(Command):
    """Run ``fn(loop)`` in the loop's thread at the next boundary (an event, not a cycle: e.g.
    the twin's environment changing when a patient's foot is placed); value = its return."""

    def __init__(self, fn: Any, description: str) -> None:
        self.fn = fn
        self.description = description
        super().__init__()

    def apply(self, loop: Any) -> Any:
        return self.fn(loop)
