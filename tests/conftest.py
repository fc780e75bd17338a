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
