"""The full twin as the source of a served sensor (``talus twin serve-ati --env ...``)."""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence

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


#: Most twin time one call simulates (s). Between calls the twin's time follows the clock,
#: but a long pause (nobody streaming for 30 s) is not replayed: replaying it made the first
#: record after 30 s of idle arrive 2.6 s late. 10 ms of twin time cost ≤ 0.5 ms (the twin
#: runs ≥ 20× real time), within one 1 kHz sample period; the twin simply pauses while idle.
MAX_CATCH_UP_S = 0.010


def twin_wrench_source(env: str, volts: Sequence[float] | None, seed: int,
                       description: RobotDescription | None = None,
                       clock: Callable[[], float] = time.monotonic):
    """A ``WrenchSource`` running a twin (of ``description``, default the nominal robot) in
    real time: each call advances the physics by the clock time since the previous call, at
    most ``MAX_CATCH_UP_S``."""
    twin = Twin(description, environment=parse_environment(env), seed=seed)
    card = TwinActuators(twin, 0)
    card.enable()
    card.write_volts(holding_volts(twin) if volts is None else volts)
    last: list[float] = []
    twin_t = [0.0]

    def source() -> AtiSample | None:
        now = clock()
        if last:
            twin_t[0] += min(max(now - last[0], 0.0), MAX_CATCH_UP_S)
            last[0] = now
        else:
            last.append(now)
        twin.sync(twin_t[0])
        return twin.ati_sample

    source.twin = twin  # type: ignore[attr-defined]  # for tests and introspection
    return source
