"""The full twin as the source of a served sensor (``talus twin serve-ati --env ...``)."""
from __future__ import annotations

import time
from typing import Sequence

import numpy as np

from rt.ati.twin_sensor import AtiSample
from rt.model.description import RobotDescription
from rt.model.dynamics import Dynamics
from rt.twin.backends import TwinActuators
from rt.twin.environment import parse_environment
from rt.twin.twin import Twin


def holding_volts(twin: Twin) -> np.ndarray:
    """Amplifier commands (V) that hold the twin's current pose against gravity (model G)."""
    dyn = Dynamics(twin.description)
    g = dyn.gravity(dyn.state(twin.plant.q))
    return g / twin.description.drive.force_per_volt_n


def twin_wrench_source(env: str, volts: Sequence[float] | None, seed: int,
                       description: RobotDescription | None = None):
    """A ``WrenchSource`` running a twin (of ``description``, default the nominal robot) in
    real time: each call advances the physics to now."""
    twin = Twin(description, environment=parse_environment(env), seed=seed)
    card = TwinActuators(twin, 0)
    card.enable()
    card.write_volts(holding_volts(twin) if volts is None else volts)
    t0: list[float] = []

    def source() -> AtiSample | None:
        now = time.monotonic()
        if not t0:
            t0.append(now)
        twin.sync(now - t0[0])
        return twin.ati_sample

    source.twin = twin          # for tests and introspection
    return source
