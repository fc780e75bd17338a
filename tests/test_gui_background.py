"""Background work answers every call: a product error as its message, a bug as an internal
error (logged), never silence (a pool thread used to swallow it and the page waited forever)."""
from __future__ import annotations

import gui_support  # noqa: F401  (offscreen platform before Qt)

from app.background import Background
from rt.errors import InputError


def test_every_call_is_answered(qtbot, caplog) -> None:
    worker = Background("test-bg")
    answers: list[tuple[str, object, str]] = []
    worker.done.connect(lambda tag, result, error: answers.append((tag, result, error)))

    def bug() -> None:
        raise KeyError("oops")

    def refused() -> None:
        raise InputError("body mass 900 kg is outside 2..400 kg")

    worker.call("ok", lambda: 42)
    worker.call("refused", refused)
    worker.call("bug", bug)
    qtbot.waitUntil(lambda: len(answers) == 3, timeout=30_000)
    worker.close()
    assert answers[0] == ("ok", 42, "")
    assert answers[1] == ("refused", None, "body mass 900 kg is outside 2..400 kg")
    assert answers[2][0] == "bug" and answers[2][1] is None
    assert "internal error (KeyError" in answers[2][2]
    assert any("background task 'bug' failed" in r.getMessage() for r in caplog.records)
