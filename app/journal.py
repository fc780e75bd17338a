"""A session in the clinical record (Qt-free): the row is opened before the RT process gets
the session, with the limits and body mass snapshotted by the record, and those — not what the
screen showed earlier — are what the RT process enforces; the row is closed with the outcome,
the summary and the recording's path and sha256 when the RT process publishes ``session_end``
(a refusal closes it as refused). Called from worker threads (the record is thread-safe)."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import yaml


class SessionJournal:
    """Journal of the sessions one logged-in user runs (``actor()`` gives who)."""

    def __init__(self, record: Any, actor: Callable[[], Any]) -> None:
        self.record = record
        self.actor = actor
        self.uid: str | None = None

    def begin(self, code: str, document: dict[str, Any]) -> dict[str, Any]:
        """Open the row; returns the ``patient`` argument of ``session_start``."""
        from patients.session_record import rt_patient

        started = self.record.start_session(self.actor(), code,
                                            yaml.safe_dump(document, sort_keys=False))
        self.uid = started["uid"]
        return rt_patient(started)

    def refused(self, reason: str) -> None:
        """The RT process refused the session (pre-flight): close the row as refused."""
        from patients.models import Outcome

        if self.uid is not None:
            uid, self.uid = self.uid, None
            self.record.finish_session(self.actor(), uid, Outcome.REFUSED,
                                       stopped_by=f"pre-flight: {reason}"[:200])

    def end(self, summary: dict[str, Any]) -> None:
        """The session ended: outcome (``patients.session_record.outcome_of``), summary,
        recording."""
        from patients.session_record import outcome_of

        if self.uid is None:
            return
        uid, self.uid = self.uid, None
        outcome, stopped_by = outcome_of(summary)
        recording = summary.get("recording") or {}
        self.record.finish_session(self.actor(), uid, outcome, stopped_by=stopped_by,
                                   summary=summary, recording_path=recording.get("path"),
                                   recording_sha256=recording.get("sha256"))
