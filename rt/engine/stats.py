"""Execution-time statistics kept in preallocated ring buffers (the thesis's supervisor measured
every component and the whole cycle; DESIGN 5).

The cycle only stores integers (ns) into int64 arrays allocated once; everything else (means,
percentiles) is computed on demand, off the cycle, from a copy of the window. A slot that held
no sample is ``-1`` and is ignored.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from rt.errors import ConfigurationError

DEFAULT_CAPACITY = 65536
"""Samples kept per ring: 65.5 s of history at 1 kHz, 512 KiB per ring."""


def check_capacity(capacity: int) -> int:
    """Capacities are powers of two so the cycle can wrap an index with a mask."""
    if not isinstance(capacity, int) or capacity < 16 or capacity & (capacity - 1):
        raise ConfigurationError(f"stats capacity must be a power of two ≥ 16, got {capacity!r}")
    return capacity


def new_ring(capacity: int) -> np.ndarray:
    """An int64 ring of ``capacity`` samples, all empty (-1)."""
    return np.full(capacity, -1, dtype=np.int64)


@dataclass(frozen=True)
class TimingStats:
    """Summary of a time series in µs.

    ``count`` counts every sample since the series started (or was reset); ``window`` is how
    many of the most recent ones the other figures describe (at most the ring's capacity).
    ``max_us`` is the window's maximum, ``max_all_us`` the all-time maximum where tracked
    (whole cycle, lateness) and the window's maximum otherwise. NaN when there is no sample.
    """

    count: int
    window: int
    mean_us: float
    p50_us: float
    p99_us: float
    max_us: float
    max_all_us: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def __str__(self) -> str:
        return (f"n={self.count} mean={self.mean_us:.1f} p50={self.p50_us:.1f} "
                f"p99={self.p99_us:.1f} max={self.max_us:.1f} µs")


def _quantiles(x: np.ndarray, qs: tuple[float, ...]) -> list[float]:
    """Linear-interpolated quantiles (numpy's default method) via one ``np.partition``:
    O(n), and unlike ``np.percentile`` it leaves no cached objects behind (``np.percentile``
    grows a ~200 kB internal cache over its first few hundred calls)."""
    n = x.size
    pos = [q * (n - 1) for q in qs]
    kth = sorted({int(p) for p in pos} | {min(int(p) + 1, n - 1) for p in pos})
    part = np.partition(x, kth)
    out = []
    for p in pos:
        lo = int(p)
        hi = min(lo + 1, n - 1)
        out.append(float(part[lo] + (part[hi] - part[lo]) * (p - lo)))
    return out


def summarize(ring: np.ndarray, count: int, max_all_ns: int | None = None) -> TimingStats:
    """Summarise a ring of ns samples (``-1`` = empty) into :class:`TimingStats` (µs)."""
    samples = ring.copy()  # the cycle may be writing concurrently: work on a snapshot
    samples = samples[samples >= 0]
    if samples.size == 0:
        nan = math.nan
        return TimingStats(count, 0, nan, nan, nan, nan,
                           nan if not max_all_ns else max_all_ns / 1e3)
    us = samples.astype(np.float64) / 1e3
    p50, p99 = _quantiles(us, (0.50, 0.99))
    mx = float(us.max())
    mx_all = mx if max_all_ns is None else max(mx, max_all_ns / 1e3)
    return TimingStats(int(count), int(us.size), float(us.mean()), p50, p99, mx,
                       mx_all)


@dataclass(frozen=True)
class SlotStats(TimingStats):
    """Execution time of the component in one graph slot, plus who it is and its lifecycle."""

    component: str
    lifecycle: str


@dataclass(frozen=True)
class Fault:
    """A component moved to error by the graph: when, who, and why.

    ``code`` is the non-zero status ``update`` returned, or ``STATUS_EXCEPTION`` (-1) when it
    raised (``reason`` then names the exception).
    """

    cycle: int
    t: float
    slot: str
    component: str
    code: int
    reason: str


@dataclass(frozen=True)
class GraphStats:
    """``Graph.stats()``: cycle count, whole-cycle and per-slot execution times (µs), faults.

    ``components`` is keyed by slot name, in execution order.
    """

    cycles: int
    cycle: TimingStats
    components: dict[str, SlotStats]
    faults: int

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def table(self) -> str:
        """A fixed-width text table (for the CLI and benchmarks)."""
        rows = [(f"{'slot':<16}{'component':<16}{'state':<13}{'n':>9}{'mean':>9}{'p50':>9}"
                f"{'p99':>9}{'max':>9}  (µs)")]
        for slot, s in self.components.items():
            rows.append(f"{slot:<16}{s.component:<16}{s.lifecycle:<13}{s.count:>9}"
                        f"{s.mean_us:>9.2f}{s.p50_us:>9.2f}{s.p99_us:>9.2f}{s.max_us:>9.2f}")
        c = self.cycle
        rows.append(f"{'(whole cycle)':<45}{c.count:>9}{c.mean_us:>9.2f}{c.p50_us:>9.2f}"
                    f"{c.p99_us:>9.2f}{c.max_us:>9.2f}")
        return "\n".join(rows)
