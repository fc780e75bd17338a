"""``talus bench loop``: the position loop on the twin, timed block by block.

Whole-cycle figures include the ``twin`` block (the simulation's physics and sensor models),
which does not exist on the rig; ``cycle_without_twin_us`` subtracts it cycle by cycle, which is
the figure to compare with the rig's sensors→outputs budget. Twin figures, this machine.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from rt.position_loop import build_sim_position_loop


def _summary(samples_ns: np.ndarray) -> dict[str, float]:
    us = samples_ns / 1e3
    return {"median": float(np.median(us)), "p99": float(np.percentile(us, 99)),
            "max": float(us.max())}


def run_loop_benchmark(controller: str, seconds: float, rate_hz: float = 1000.0,
                       mode: str = "realtime", model=None,
                       cpu_latency_us: int | None = None, fused: bool | None = None) -> dict:
    """``fused``: None keeps the loop's default (the fused chain unless ``TALUS_FUSED_CYCLE=0``);
    False runs every block's ``update`` (the per-block reference), True fuses."""
    extra: dict[str, Any] = {} if cpu_latency_us is None or mode != "realtime" else {
        "cpu_latency_us": cpu_latency_us}
    pl = build_sim_position_loop(controller, duration_s=max(1.0, seconds), rate_hz=rate_hz,
                                 mode=mode, model=model, **extra)
    if fused is not None:
        pl.graph.fused = fused
    cycles = pl.loop.run(seconds=seconds)
    stats = pl.loop.stats()
    graph = pl.graph
    rings = graph.timing_samples()
    cycle_ns = rings["cycle"]
    twin_ns = rings["components"]["twin"]
    valid = (cycle_ns >= 0) & (twin_ns >= 0)
    components = {slot: _summary(ns[ns >= 0]) for slot, ns in rings["components"].items()}
    without = cycle_ns[valid] - twin_ns[valid]
    cycle_ns = cycle_ns[cycle_ns >= 0]
    pl.graph.stop()
    hyg = pl.loop.hygiene
    return {"controller": controller, "rate_hz": rate_hz, "mode": mode, "twin": True,
            "cpu_latency_us": None if hyg is None else hyg.cpu_latency_us,
            "fused": graph.fused,
            "cycles": int(cycles), "deadline_misses": int(stats.misses),
            "cycle_us": _summary(cycle_ns), "cycle_without_twin_us": _summary(without),
            "components": components,
            # A host stall of tens of ms trips ``deadline_overruns`` (or tracking) now and
            # then: the rest of such a run is a stopped loop (its blocks' Python), not the
            # steady cycle; say so next to the figures (guard8).
            "latched": [x["cause"] for x in pl.supervisor.latched()]}
