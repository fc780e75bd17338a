"""Argument types shared by every ``talus`` command group.

argparse calls a ``type=`` callable on the raw string; raising ``argparse.ArgumentTypeError``
makes it print the usage and ``argument --x: <message>`` and exit with code 2, before the
command runs. Every group uses these instead of bare ``float``/``int``, so ``nan``, ``inf``,
negative durations, out-of-range ports and misspelt names are refused the same way everywhere.

    p.add_argument("--seconds", type=finite_float(lo=0.0, lo_open=True, hi=3600.0))
    p.add_argument("--port", type=port_number())
    p.add_argument("--controller", type=name_choice(CONTROLLER_NAMES))
"""
from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable

#: Longest duration any command runs or waits for (s): one hour.
MAX_SECONDS = 3600.0
#: Largest seed numpy's SeedSequence and the twin's streams accept here (uint32).
MAX_SEED = 2**32 - 1


def _bound(value: float | None, missing: str) -> str:
    if value is None:
        return missing
    return str(value) if isinstance(value, int) else f"{value:g}"


def _interval(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    left = "(" if lo_open else "["
    right = ")" if hi_open else "]"
    return f"{left}{_bound(lo, '-inf')}, {_bound(hi, 'inf')}{right}"


def finite_float(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
                 hi_open: bool = False, unit: str = "") -> Callable[[str], float]:
    """A float that is finite and inside [lo, hi] (open ends with ``lo_open``/``hi_open``)."""
    where = _interval(lo, hi, lo_open, hi_open) + (f" {unit}" if unit else "")

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number in {where}, got {text}")
        below = lo is not None and (value <= lo if lo_open else value < lo)
        above = hi is not None and (value >= hi if hi_open else value > hi)
        if below or above:
            raise argparse.ArgumentTypeError(f"must be in {where}, got {text}")
        return value

    parse.__name__ = "number"  # argparse names the type in its "invalid ..." fallback
    return parse


def bounded_int(lo: int | None = None, hi: int | None = None) -> Callable[[str], int]:
    """A decimal integer inside [lo, hi]."""
    where = _interval(lo, hi, False, False)

    def parse(text: str) -> int:
        if len(text) > 20:  # no 4000-digit integers (Python refuses them with ValueError)
            raise argparse.ArgumentTypeError(f"must be an integer in {where}, got {text[:20]}…")
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"must be in {where}, got {value}")
        return value

    parse.__name__ = "integer"
    return parse


def seconds(*, allow_zero: bool = False, hi: float = MAX_SECONDS) -> Callable[[str], float]:
    """A duration or a timeout (s): finite, > 0 (or ≥ 0), at most ``hi``."""
    return finite_float(0.0, hi, lo_open=not allow_zero, unit="s")


def rate_hz(lo: float, hi: float) -> Callable[[str], float]:
    """A rate (Hz) inside [lo, hi]."""
    return finite_float(lo, hi, unit="Hz")


def port_number(*, allow_zero: bool = True) -> Callable[[str], int]:
    """A TCP/UDP port: 1..65535, or 0 (= pick an ephemeral port) when ``allow_zero``."""
    return bounded_int(0 if allow_zero else 1, 65535)


def seed() -> Callable[[str], int]:
    """A random seed: 0..2**32-1."""
    return bounded_int(0, MAX_SEED)


def canonical_name(text: str) -> str:
    """Names where ``-`` and ``_`` are the same and case does not matter: ``paden-panja``."""
    return text.strip().lower().replace("-", "_")


def name_choice(choices: Iterable[str]) -> Callable[[str], str]:
    """One of ``choices``, accepting ``-`` for ``_`` and any case; returns the declared spelling."""
    known = {canonical_name(c): c for c in choices}

    def parse(text: str) -> str:
        try:
            return known[canonical_name(text)]
        except KeyError:
            raise argparse.ArgumentTypeError(f"unknown name {text!r}; choose from "
                                             f"{', '.join(sorted(known.values()))}") from None

    parse.__name__ = "name"
    return parse
