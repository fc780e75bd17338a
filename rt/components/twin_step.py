"""The twin's physics as the first block of the cycle (simulation backend only)."""
from __future__ import annotations

from rt.engine import Component
from rt.twin.twin import SimClock, Twin


class TwinStep(Component):
    """Ports: none. Advances the twin's physics to the loop time at the start of each cycle,
    holding the drive commands written in the previous cycle (the rig's DAC zero-order hold).

    Kept as its own block so the cycle statistics show the simulation's cost apart from the
    controller's: on the real rig this block does not exist.
    """

    def __init__(self, name: str, twin: Twin, clock: SimClock):
        super().__init__(name)
        self.twin = twin
        self.clock = clock
        self._t0: float | None = None

    def update(self, t: float, dt: float) -> int:
        if self._t0 is None:
            self._t0 = t
        now = t - self._t0
        self.clock.t = now
        self.twin.sync(now)
        return 0
