"""Work the GUI thread must not wait for (a database query, an Argon2 password check), run on a
worker thread and answered as a Qt signal: ``done(tag, result, error)``. The product's errors
(``TalusError``) become ``error`` as they are; anything else is a bug: logged with its traceback
and answered as an internal error, so the page never waits for an answer that a pool thread
swallowed."""
from __future__ import annotations

import logging
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from PySide6.QtCore import QObject, Signal

from rt.errors import TalusError

log = logging.getLogger(__name__)


class Background(QObject):
    """A one-thread pool whose results come back on the GUI thread, in submission order."""

    done = Signal(str, object, str)

    def __init__(self, name: str, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)

    def call(self, tag: str, fn: Callable[[], Any]) -> None:
        """Run ``fn()``; ``done(tag, result, "")`` or ``done(tag, None, message)``."""
        self._pool.submit(self._run, tag, fn)

    def _run(self, tag: str, fn: Callable[[], Any]) -> None:
        try:
            result = fn()
        except TalusError as exc:
            self.done.emit(tag, None, str(exc))
            return
        except Exception as exc:      # a bug: logged, and the page told
            log.exception("background task %r failed", tag)
            self.done.emit(tag, None, f"internal error ({type(exc).__name__}: {exc}); "
                                      "the log has the details")
            return
        self.done.emit(tag, result, "")

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
