"""Force mode in the fused cycle (issue 16): a force program's loop before/after, twin figures.

Run:  .venv/bin/python bench/force_fused.py [--repeats 3] [--only sine60,gait] [--parts]

"before" is the state before the force stage: the hybrid controller's force mode runs its
block (``TALUS_FUSED_FORCE=0``) and a previewed program's PLAY reads ahead in Python
(``ProgramReference.compiled_read_ahead = False``), so the fused kernel stops after the model
on every PLAY cycle. "after" is the default: the read-ahead and the force-mode cycle compiled,
the whole chain one call. The two alternate in one process (run r of both before run r + 1),
each a whole ``protocols.session.preflight`` (bench/preflight.py's ``preflight_time``: this
thread's CPU time, independent of the machine's load as far as anything is), and the loop's
per-block medians (``Graph.stats()``: wall-clock µs per slot, the fused estimator slot
charged the call's whole overhead).

``--parts``: in a "before" run, time the pieces of the force-mode cycle that ran in Python
(each wrapped: µs per call, the wrapper's own cost measured on an empty function and
subtracted): the hybrid controller's ``update`` whole and its ``_lead``, ``_govern``, the
law's ``ExplicitForce.update`` (its compiled kernel and dispatch), the sequencer's ``update``
and its ``_read_ahead``.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Self

from rt.components import fused
from rt.components.protocol_blocks import HybridController
from rt.control.force import ExplicitForce
from rt.model import RobotModel
from rt.references.sequencer import ProgramReference

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("_preflight_bench", HERE / "preflight.py")
assert _spec is not None and _spec.loader is not None
pf = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(pf)

SLOTS = ("estimator", "model", "reference", "controller", "supervisor")


def configure(after: bool) -> None:
    if after:
        os.environ.pop(fused.FORCE_ENV_FLAG, None)
    else:
        os.environ[fused.FORCE_ENV_FLAG] = "0"
    ProgramReference.compiled_read_ahead = after


class Parts:
    """Wraps methods with a per-call timer (ns, ``perf_counter_ns``)."""

    TARGETS: tuple[tuple[type, str], ...] = (
        (HybridController, "update"), (HybridController, "_lead"),
        (HybridController, "_govern"), (ExplicitForce, "update"),
        (ProgramReference, "update"), (ProgramReference, "_read_ahead"))

    def __init__(self) -> None:
        self.ns: dict[str, list[int]] = {f"{c.__name__}.{n}": [] for c, n in self.TARGETS}
        self._saved: list[tuple[type, str, Callable]] = []
        self.overhead_ns = self._overhead()

    @staticmethod
    def _wrap(fn: Callable, sink: list[int]) -> Callable:
        clock = time.perf_counter_ns

        def timed(*args: Any) -> Any:
            t0 = clock()
            try:
                return fn(*args)
            finally:
                sink.append(clock() - t0)
        return timed

    def _overhead(self) -> float:
        sink: list[int] = []
        f = self._wrap(lambda: None, sink)
        for _ in range(20000):
            f()
        return float(statistics.median(sink))

    def __enter__(self) -> Self:
        for cls, name in self.TARGETS:
            fn = cls.__dict__[name]
            self._saved.append((cls, name, fn))
            setattr(cls, name, self._wrap(fn, self.ns[f"{cls.__name__}.{name}"]))
        return self

    def __exit__(self, *exc: object) -> None:
        for cls, name, fn in self._saved:
            setattr(cls, name, fn)

    def report(self) -> str:
        lines = [f"  (wrapper overhead {self.overhead_ns / 1e3:.2f} µs subtracted)"]
        for key, v in self.ns.items():
            if v:
                v.sort()
                med = max(0.0, v[len(v) // 2] - self.overhead_ns) / 1e3
                p99 = max(0.0, v[int(0.99 * (len(v) - 1))] - self.overhead_ns) / 1e3
                lines.append(f"  {key:32s} calls {len(v):7d}  median {med:6.2f} µs  "
                             f"p99 {p99:6.2f} µs")
        return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", default="sine60,gait")
    ap.add_argument("--parts", action="store_true")
    args = ap.parse_args()
    model = RobotModel.load()
    library = pf.protocols()
    names = [n for n in args.only.split(",") if n]
    if args.parts:
        configure(after=False)
        for name in names:
            with Parts() as parts:
                pf.preflight_time(library[name], model)
            print(f"{name} before: the force-mode cycle's Python, per call")
            print(parts.report())
    runs: dict[tuple[str, bool], list[dict]] = {}
    for r in range(args.repeats):
        for name in names:
            for after in (False, True):
                configure(after)
                blocks: dict = {}
                out = pf.preflight_time(library[name], model, blocks=blocks)
                out["blocks"] = blocks
                runs.setdefault((name, after), []).append(out)
                print(f"run {r} {name:7s} {'after ' if after else 'before'} "
                      f"CPU {out['cpu_s']:.2f} s ({out['cpu_per_60s']:.2f} s per 60 s), "
                      f"loop {out['loop_cpu_s']:.2f} s", flush=True)
    configure(after=True)
    print("\nmedians (loaded machine: compare the ratios; twin figures)")
    for name in names:
        b, a = runs[(name, False)], runs[(name, True)]

        def med(rs: list[dict], key: str) -> float:
            return statistics.median(x[key] for x in rs)

        def slot(rs: list[dict], s: str) -> float:
            return statistics.median(x["blocks"][s]["p50_us"] for x in rs)
        print(f"{name}: pre-flight CPU per 60 s {med(b, 'cpu_per_60s'):.2f} -> "
              f"{med(a, 'cpu_per_60s'):.2f} s ({med(a, 'cpu_per_60s') / med(b, 'cpu_per_60s'):.2f}"
              f"); loop CPU {med(b, 'loop_cpu_s'):.2f} -> {med(a, 'loop_cpu_s'):.2f} s")
        five_b = sum(slot(b, s) for s in SLOTS)
        five_a = sum(slot(a, s) for s in SLOTS)
        print("  per-slot p50 µs: " + ", ".join(
            f"{s} {slot(b, s):.1f} -> {slot(a, s):.1f}" for s in SLOTS))
        print(f"  five middle slots {five_b:.1f} -> {five_a:.1f} µs ({five_a / five_b:.2f}); "
              f"whole cycle {slot(b, '(whole cycle)'):.1f} -> {slot(a, '(whole cycle)'):.1f} µs"
              f" ({slot(a, '(whole cycle)') / slot(b, '(whole cycle)'):.2f})")


if __name__ == "__main__":
    main()
