"""Cyclic garbage collection held to the GUI thread while windows are open (app/main_thread_gc)."""
from __future__ import annotations

import gc
import threading

import gui_support  # noqa: F401  (offscreen platform before Qt)

from app.main_thread_gc import MainThreadGc, collect_by_generation


class _Cycle:
    def __init__(self) -> None:
        self.me = self


def test_windows_hold_automatic_collection_off_until_the_last_closes(qapp) -> None:
    assert gc.isenabled()
    a, b = MainThreadGc(), MainThreadGc()
    a.start()
    b.start()
    a.start()                                   # idempotent
    assert not gc.isenabled() and MainThreadGc.holders() == 2
    a.stop()
    assert not gc.isenabled()                   # b still open
    b.stop()
    b.stop()                                    # idempotent
    assert gc.isenabled() and MainThreadGc.holders() == 0


def test_a_worker_thread_never_collects_while_a_window_is_open(qapp) -> None:
    """Garbage cycles made by a worker thread are not collected there (what deadlocked Qt),
    but by the GUI thread's tick."""
    holder = MainThreadGc()
    holder.start()
    try:
        collected_in_worker = []
        gc.callbacks.append(lambda phase, info: phase == "start" and collected_in_worker.append(
            threading.current_thread() is not threading.main_thread()))

        def worker() -> None:
            for _ in range(20 * gc.get_threshold()[0]):     # many generations' worth
                _Cycle()

        t = threading.Thread(target=worker)
        t.start()
        t.join()
        assert not any(collected_in_worker)
        assert gc.get_count()[0] > gc.get_threshold()[0]   # the cycles are waiting
        collect_by_generation()                               # the GUI thread's tick
        assert gc.get_count()[0] < gc.get_threshold()[0]
    finally:
        gc.callbacks.pop()
        holder.stop()
    assert gc.isenabled()


def test_release_all_gives_collection_back_and_old_holders_stay_quiet(qapp) -> None:
    a = MainThreadGc()
    a.start()
    MainThreadGc.release_all()
    assert gc.isenabled() and MainThreadGc.holders() == 0
    b = MainThreadGc()
    b.start()
    a.stop()                                    # from before release_all: no effect on b's
    assert not gc.isenabled() and MainThreadGc.holders() == 1
    b.stop()
    assert gc.isenabled()
