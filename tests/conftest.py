"""Shared fixtures. Hypothesis runs derandomized so every CI run checks the same examples."""
from __future__ import annotations

import pytest
from hypothesis import HealthCheck, settings

from rt.model import RobotModel

# A throw-away PostgreSQL server and the sqlite/postgresql ``database_url`` fixture.
pytest_plugins = ("pg_server",)

settings.register_profile("talus", derandomize=True, max_examples=60, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("talus")


@pytest.fixture(scope="session")
def robot() -> RobotModel:
    """The nominal twin model (shared: tests must not leave a payload on it)."""
    return RobotModel.load()


@pytest.fixture()
def fresh_robot() -> RobotModel:
    """A private model a test may modify (payloads)."""
    return RobotModel.load()


@pytest.fixture(scope="session")
def scratch_robot() -> RobotModel:
    """A model whose payload property tests set explicitly in every example."""
    return RobotModel.load()


@pytest.fixture(autouse=True)
def _gui_garbage_on_the_main_thread(request):
    """A GUI test's windows hold cyclic collection to the GUI thread (app/main_thread_gc.py);
    one left open by a test must not keep it off for the rest of the session, and its Qt
    objects must be freed here, on the main thread, not later by a collection in some worker
    thread (the deadlock that module describes)."""
    yield
    if "gui" not in request.module.__name__:
        return
    import gc

    from app.main_thread_gc import MainThreadGc
    MainThreadGc.release_all()
    gc.collect()
