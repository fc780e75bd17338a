"""Streaming min/max/mean decimation for plots of long recordings.

An hour at 1 kHz is 3.6 million samples per signal; a page plot needs a few thousand points.
:class:`EnvelopeDecimator` keeps at most ``2 × target`` time buckets whatever the length:
samples are added in blocks, and when the buckets outgrow the budget their width doubles and
neighbours merge. Each bucket keeps min, max and mean, so peaks survive (a plot draws the
min–max envelope and the mean) and a short session keeps its full detail (buckets of one
sample).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Envelope:
    """Decimated signal: bucket centre time (s), mean, min and max (the signal's unit)."""

    t: np.ndarray
    mean: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


class EnvelopeDecimator:
    """Min/max/mean per time bucket, for samples added in time order (NaNs ignored).

    Args:
        target: buckets wanted (between ``target`` and ``2 × target`` are kept).
        width_s: the initial bucket width (s), the loop period for full detail.
    """

    def __init__(self, target: int = 2000, width_s: float = 1e-3):
        if target < 2 or width_s <= 0:
            raise ValueError("target must be >= 2 and width_s > 0")
        self.target = target
        self.width = width_s
        self.t0: float | None = None
        self._k = np.empty(0, dtype=np.int64)
        self._lo = np.empty(0)
        self._hi = np.empty(0)
        self._sum = np.empty(0)
        self._n = np.empty(0, dtype=np.int64)

    def add(self, t: np.ndarray, y: np.ndarray) -> None:
        """Add samples at times ``t`` (s, non-decreasing across calls) with values ``y``."""
        ok = np.isfinite(t) & np.isfinite(y)
        t, y = t[ok], y[ok]
        if not len(t):
            return
        if self.t0 is None:
            self.t0 = float(t[0])
        k = np.floor((t - self.t0) / self.width).astype(np.int64)
        self._merge(k, y, y, y, np.ones(len(y), dtype=np.int64))
        while len(self._k) > 2 * self.target:
            self.width *= 2.0
            self._merge_into_self(self._k // 2)

    def _merge_into_self(self, k: np.ndarray) -> None:
        lo, hi, s, n = self._lo, self._hi, self._sum, self._n
        self._k = np.empty(0, dtype=np.int64)
        self._lo = self._hi = self._sum = np.empty(0)
        self._n = np.empty(0, dtype=np.int64)
        self._group(k, lo, hi, s, n)

    def _merge(self, k: np.ndarray, lo: np.ndarray, hi: np.ndarray, s: np.ndarray,
               n: np.ndarray) -> None:
        if len(self._k) and k[0] <= self._k[-1]:
            # The block continues the last bucket: fold that bucket back in.
            k = np.concatenate(([self._k[-1]], k))
            lo = np.concatenate(([self._lo[-1]], lo))
            hi = np.concatenate(([self._hi[-1]], hi))
            s = np.concatenate(([self._sum[-1]], s))
            n = np.concatenate(([self._n[-1]], n))
            self._k, self._lo, self._hi = self._k[:-1], self._lo[:-1], self._hi[:-1]
            self._sum, self._n = self._sum[:-1], self._n[:-1]
        self._group(np.maximum.accumulate(k), lo, hi, s, n)

    def _group(self, k: np.ndarray, lo: np.ndarray, hi: np.ndarray, s: np.ndarray,
               n: np.ndarray) -> None:
        start = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
        self._k = np.concatenate((self._k, k[start]))
        self._lo = np.concatenate((self._lo, np.minimum.reduceat(lo, start)))
        self._hi = np.concatenate((self._hi, np.maximum.reduceat(hi, start)))
        self._sum = np.concatenate((self._sum, np.add.reduceat(s, start)))
        self._n = np.concatenate((self._n, np.add.reduceat(n, start)))

    def envelope(self) -> Envelope:
        """The buckets so far (empty arrays when nothing finite was added)."""
        if self.t0 is None:
            e = np.empty(0)
            return Envelope(e, e, e, e)
        t = self.t0 + (self._k + 0.5) * self.width
        return Envelope(t, self._sum / self._n, self._lo.copy(), self._hi.copy())
