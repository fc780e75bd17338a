"""The graph's one-cycle delays copied in one compiled call (``Graph._end_cycle``).

Why: each delayed connection's latch was a Python copy (``dst[...] = src``, ≈ 0.4-0.8 µs
for a one-element array), four of them in the position loop: ≈ 2-3 µs of every cycle's
Python (guard8's cycle profile). When every latch is a float64 C-contiguous array, the graph
keeps their addresses in one table and copies them all with :func:`copy_latches` (one
dispatch of one array argument); otherwise it keeps the Python copies.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from rt.pointers import f64_at


@njit(cache=True)
def copy_latches(table: np.ndarray) -> None:  # pragma: no cover - compiled
    """Row ``i`` of ``table`` (int64[k, 3]): destination address, source address, length:
    copy ``length`` float64 from the source to the destination, in row order."""
    for i in range(table.shape[0]):
        dst = f64_at(table[i, 0])
        src = f64_at(table[i, 1])
        for j in range(table[i, 2]):
            dst[j] = src[j]


def _flat_f64(a: Any) -> bool:
    return (type(a) is np.ndarray and a.dtype == np.float64 and a.ndim == 1
            and a.flags.c_contiguous)


def latch_table(pairs: list[tuple[Any, Any]]) -> np.ndarray | None:
    """The address table of ``pairs`` (latch buffer, source buffer) for :func:`copy_latches`,
    or None when one of them is not a float64 C-contiguous 1-D array of the same length as its
    partner (the Python copies then). The caller keeps the arrays referenced (the addresses
    are valid only while they live)."""
    if not pairs:
        return None
    rows = []
    for dst, src in pairs:
        if not (_flat_f64(dst) and _flat_f64(src)) or dst.shape != src.shape \
                or not dst.flags.writeable:
            return None
        rows.append((dst.ctypes.data, src.ctypes.data, dst.shape[0]))
    table = np.array(rows, dtype=np.int64)
    copy_latches(table[:0])           # compile (or load from the cache) now, not in a cycle
    return table
