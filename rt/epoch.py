"""The process's invalidation epoch: one counter every event that may end the fused cycle's
steady fast path bumps (``rt.components.fused``, issue 16).

Why: the fast path used to re-check ≈ 50 flags and identities every cycle (the blocks'
lifecycle, the sequencer's and the supervisor's requests, devices closed or a method replaced,
the drive's card, a law rebound, ...), ≈ 3-4 µs of attribute reads. Each of those changes only
at an event outside the steady cycle; the code that makes the change bumps :data:`EPOCH`
afterwards, and the fast path compares one integer with the value it read before its last
general cycle checked everything.

Order, so that no event is missed with no lock: the writer changes its state *first*, then
bumps; the reader reads the epoch *first*, then checks the state. A bump from another thread
(an IPC request) either lands before the general cycle's read (its state change was seen by
that cycle's checks) or after it (the next fast-path compare differs). ``n += 1`` is not
atomic across threads, but a lost increment still leaves the counter different from any value
read before the writer's own read, which is all the compare needs.

One counter for the process, not per object: events are rare (operator requests, lifecycle,
faults), a bump by another graph costs this one a single general cycle, and the fast path then
needs one compare instead of one per source.
"""
from __future__ import annotations


class Epoch:
    """A mutable integer (``n``) cheap to read from Python (a slot)."""

    __slots__ = ("n",)

    def __init__(self) -> None:
        self.n = 0


#: The process's epoch (read ``EPOCH.n``; bump with :func:`bump`).
EPOCH = Epoch()


def bump() -> None:
    """Something the fused cycle's fast path relies on changed (call *after* the change)."""
    EPOCH.n += 1
