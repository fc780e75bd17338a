"""The pre-flight a ``session_start`` may reuse (issue 14: Start to motion).

A GUI runs ``session_preflight`` before it enables Start (the clinician sees the predicted
peaks or the refusal), then sends ``session_start`` with the same protocol and patient. The
pre-flight simulates the whole protocol on the twin (seconds of CPU): running it twice made
Start→motion 16.9 s for an 18 s sine. The RT process therefore keeps the prepared session of
the last passing ``session_preflight`` (:class:`PreflightKeeper`, **one** entry) and a
``session_start`` takes it instead of pre-flighting again when, and only when, everything the
pre-flight depended on is unchanged:

* the **key** (:class:`PreflightKey`) is equal: the protocol document, the patient argument as
  the RT process parsed it (code, body mass, limits, ankle setup), the robot (its description,
  the machine's limits, the loop rate, twin or hardware) and the start state the pre-flight
  assumed (supervisor mode, controller, the twin's session environment);
* the client asking is the one that asked for the pre-flight;
* it is younger than ``max_age_s`` (``RtConfig.preflight_reuse_s``): past it, what the RT
  process cannot see may have changed (the foot repositioned, the clinician's intent);
* no fault or failover was logged since it was requested, and no motion ran (the sequencer's
  program epoch is the same);
* the robot is where it was (every slider within :data:`POSE_TOLERANCE_M`).

Dropped at once: by another ``session_preflight`` (one entry), by any change of owner except
the pre-flight's own client taking control of a robot nobody controlled, by ``run``,
``set_gains`` and ``session_start`` (an entry is used at most once). The check happens again
in the session's worker for what is too slow for the IPC thread (a data file re-hashed).

Nothing here talks to the loop: the service passes what it read (``q``, the event log, the
epoch); the rules are plain functions of those, tested without a robot.
"""
from __future__ import annotations

import hashlib
import json
import math
import threading
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

#: The robot counts as where the pre-flight started while every slider is within this of its
#: position then (m). 0.5 mm is 25 encoder counts (20 µm each): far above the encoders'
#: one-count jitter at rest, far below any displacement a program or a push would make.
POSE_TOLERANCE_M = 0.5e-3
#: Default reuse window (s): a clinician checks the protocol, places the foot and presses
#: Start within minutes; longer, and the session should be checked again.
DEFAULT_MAX_AGE_S = 300.0
#: Event kinds that invalidate a kept pre-flight (a stop, a card switched over).
INVALIDATING_KINDS = ("fault", "failover")


def canonical_sha256(obj: Any) -> str:
    """sha256 of ``obj`` as canonical JSON (sorted keys, no spaces, NaN refused): two
    documents have the same digest exactly when they are the same JSON value (1 and 1.0 are
    not: a conservative key never matches what it should not)."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False,
                      ensure_ascii=False, default=_json_default)
    return hashlib.sha256(text.encode()).hexdigest()


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "model_dump"):
        return obj.model_dump(mode="json")
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    raise TypeError(f"{type(obj).__name__} is not part of a pre-flight key")


@dataclass(frozen=True)
class PreflightKey:
    """What a pre-flight's result depends on, each part a sha256 (hex)."""

    protocol: str
    patient: str
    robot: str
    start: str

    def differences(self, other: PreflightKey) -> list[str]:
        """The parts that differ, by name (empty when equal)."""
        return [f.name for f in fields(self) if getattr(self, f.name) != getattr(other, f.name)]

    def as_dict(self) -> dict[str, str]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass
class KeptPreflight:
    """One ``session_preflight``: what it was asked with and, once it passed, its result."""

    id: str
    client: str
    key: PreflightKey
    #: Slider positions (m), the event log's count, the sequencer's program epoch: at request.
    q: np.ndarray
    events: int
    epoch: int
    requested: float            # monotonic s
    requested_wall: float       # Unix s
    finished: float = math.nan  # monotonic s; NaN while running
    prepared: Any = None        # the PreparedSession once it passed

    def describe(self, now: float, reused: bool) -> dict[str, Any]:
        """What the recording's metadata and the reply say about the pre-flight a session ran
        on."""
        return {"id": self.id, "reused": reused, "requested_wall": self.requested_wall,
                "age_s": None if math.isnan(self.finished) else round(now - self.finished, 3),
                "key": self.key.as_dict()}


def why_not_reusable(kept: KeptPreflight | None, client: str, key: PreflightKey, now: float,
                     max_age_s: float, q: np.ndarray, events: list[Any], event_count: int,
                     epoch: int, dropped: str | None = None) -> str | None:
    """None when ``kept`` may be reused for this ``session_start``, else why not (a sentence).

    ``events`` is the event log's snapshot (its newest ``len(events)`` events of
    ``event_count``), ``q`` the sliders' positions now (m), ``epoch`` the sequencer's;
    ``dropped`` why the last one was dropped (said when none is kept)."""
    if kept is None:
        return "no passing pre-flight is kept" + (f" ({dropped})" if dropped else "")
    if kept.prepared is None:
        return f"pre-flight {kept.id} has not finished"
    if kept.client != client:
        return f"pre-flight {kept.id} was asked for by another client"
    parts = kept.key.differences(key)
    if parts:
        return f"pre-flight {kept.id} was for another {' and '.join(parts)}"
    age = now - kept.finished
    if not age <= max_age_s:
        return f"pre-flight {kept.id} expired ({age:.0f} s old, kept {max_age_s:.0f} s)"
    if epoch != kept.epoch:
        return f"a motion ran since pre-flight {kept.id}"
    oldest = events[0].id if events else event_count + 1
    if event_count > kept.events and oldest > kept.events + 1:
        return f"too many events since pre-flight {kept.id} to check them"
    for e in events:
        if e.id > kept.events and e.kind in INVALIDATING_KINDS:
            return f"a {e.kind} ({e.cause}) happened since pre-flight {kept.id}"
    moved = float(np.max(np.abs(np.asarray(q, dtype=float) - kept.q)))
    if not moved <= POSE_TOLERANCE_M:
        return (f"the robot moved {moved * 1e3:.2f} mm since pre-flight {kept.id} (more than "
                f"{POSE_TOLERANCE_M * 1e3:.1f} mm)")
    return None


class PreflightKeeper:
    """The one kept pre-flight; every method is safe from any thread."""

    def __init__(self, max_age_s: float = DEFAULT_MAX_AGE_S) -> None:
        self.max_age_s = float(max_age_s)
        self._lock = threading.Lock()
        self._kept: KeptPreflight | None = None
        #: Why the last entry was dropped (for status and tests).
        self.dropped_because: str | None = None

    @property
    def kept(self) -> KeptPreflight | None:
        return self._kept

    def begin(self, entry: KeptPreflight) -> None:
        """A pre-flight was requested: it replaces whatever was kept."""
        with self._lock:
            if self._kept is not None:
                self.dropped_because = f"pre-flight {entry.id} replaced it"
            self._kept = entry

    def passed(self, entry: KeptPreflight, prepared: Any, now: float) -> bool:
        """Keep ``entry``'s result, unless it was dropped while it ran; True when kept."""
        if self.max_age_s <= 0.0:
            self.drop("reuse is disabled (preflight_reuse_s = 0)")
            return False
        with self._lock:
            if self._kept is not entry:
                return False
            entry.prepared = prepared
            entry.finished = now
            return True

    def failed(self, entry: KeptPreflight) -> None:
        with self._lock:
            if self._kept is entry:
                self._kept = None
                self.dropped_because = f"pre-flight {entry.id} refused the protocol"

    def drop(self, because: str) -> None:
        with self._lock:
            if self._kept is not None:
                self._kept = None
                self.dropped_because = because

    def keep_only_for(self, client: str, because: str) -> None:
        """Drop the kept pre-flight unless ``client`` asked for it."""
        with self._lock:
            if self._kept is not None and self._kept.client != client:
                self._kept = None
                self.dropped_because = because

    def take(self) -> KeptPreflight | None:
        """Remove and return the kept pre-flight (a session start uses it at most once)."""
        with self._lock:
            kept, self._kept = self._kept, None
            if kept is not None:
                self.dropped_because = f"pre-flight {kept.id} was taken by a session start"
            return kept
