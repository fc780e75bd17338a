"""The GUI's connection watcher (``app.rt_link.RtLink``) tells a late RT process from a lost
one: a status reply later than the old 0.5 s cut-off (seen at load ≈ 9 on this VM) keeps the
link connected, with no flicker; no reply within ``stale_after_s`` is a lost link at once.
A fake client stands in for the RT process (what is under test is the watcher's judgement)."""
from __future__ import annotations

import gui_support  # noqa: F401  (offscreen platform before Qt)
import pytest

from app import rt_link
from app.rt_link import RtLink
from rt.ipc.client import RtUnavailableError


class _FakeRt:
    """Answers ``status`` after :attr:`delay_s` (within its timeout), else fails as RtClient
    does when no reply comes in time; no publisher (the telemetry check stays idle)."""

    delay_s = 0.0
    calls = 0

    def __init__(self, endpoint: str, client_id: str | None = None, timeout_s: float = 1.0,
                 **_kw: object) -> None:
        self.endpoint = endpoint
        self.client_id = client_id
        self.timeout_s = timeout_s

    def status(self) -> dict:
        import time

        type(self).calls += 1
        if self.delay_s > self.timeout_s:
            time.sleep(self.timeout_s)
            raise RtUnavailableError(f"no reply within {self.timeout_s:g} s (fake)")
        time.sleep(self.delay_s)
        return {"state": "run", "owner": None, "session": None, "latched": []}

    def subscribe_info(self) -> dict:
        raise RtUnavailableError("no publisher (fake)")

    def close(self) -> None:
        pass


@pytest.fixture()
def link(monkeypatch, qtbot):
    monkeypatch.setattr(rt_link, "RtClient", _FakeRt)
    monkeypatch.setattr(_FakeRt, "delay_s", 0.7)
    monkeypatch.setattr(_FakeRt, "calls", 0)
    link = RtLink("tcp://127.0.0.1:9", name="watch test")
    changes: list[bool] = []
    link.connection_changed.connect(lambda connected, _reason: changes.append(connected))
    link.changes = changes            # type: ignore[attr-defined]
    link.start()
    try:
        yield link
    finally:
        link.close()


def test_a_late_status_reply_is_not_a_lost_connection(link, qtbot):
    # Replies 0.7 s late: connected, and it stays so over several replies (no flicker).
    qtbot.waitUntil(lambda: link.connected, timeout=10_000)
    calls = _FakeRt.calls
    qtbot.waitUntil(lambda: _FakeRt.calls >= calls + 4, timeout=20_000)
    assert link.changes == [True] and link.connected

    # Nothing answers any more: lost within stale_after_s (plus the reply in flight).
    _FakeRt.delay_s = float("inf")
    qtbot.waitUntil(lambda: not link.connected, timeout=10_000)
    assert link.changes == [True, False]
