"""Pre-flight cost of a protocol: where the CPU goes (reference generation, twin, loop) for a
60 s sine in force, the library's ankle ROM exercise and the gait replay (twin figures).

Run:  .venv/bin/python bench/preflight.py [--repeats 3] [--only sine60,rom,gait] [--json]
      [--no-preflight]   (reference generation only)
      [--twin-ab]        (also the twin's general period, interleaved: before/after)
      [--blocks]         (the loop's per-block times: where the loop's CPU goes)
Target (issue 16): a 60 s protocol's pre-flight ≤ 1.5 s.

Per protocol, each the median of ``--repeats`` runs, interleaved (run r of every protocol
before run r + 1 of any), in this thread's CPU time (``time.thread_time``: on a machine shared
with other jobs the figure that does not depend on the load) and wall-clock time:

* ``references``: ``make_generator`` + ``validate()`` (the whole reference computed), compiled
  (``protocols.reference_kernels``, the default) and interpreted (``joint_references`` and
  per-sample ``Kinematics.fk``, the reference implementation), side by side;
* ``preflight``: ``protocols.session.preflight`` whole, split into the references, the twin
  (its block, ``TwinStep.update``: the period's physics, encoder card and ATI sample) and the
  loop (the rest: blocks, supervisor, drivers, tap, the device reads' no-op ``Twin.sync``).
  A ``thread_time`` read costs ≈ 0.7 µs here (a system call on this VM), so the twin block's
  timing adds ≈ 1.5 µs to every cycle: the figures are corrected by that overhead, measured
  at start-up (``timing_overhead``; before twin7 every ``Twin.sync``, four a cycle, was timed
  uncorrected: ≈ 6 µs a cycle counted as the twin's);
* ``per 60 s``: the pre-flight's CPU scaled to a 60 s protocol (pre-flight simulates the
  protocol plus its approach and rest, so the scaling is by the protocol's duration).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import time
from collections.abc import Iterator
from pathlib import Path

from protocols import base, generators, session
from protocols.generators import make_generator
from protocols.library import load_protocol
from rt.components.twin_step import TwinStep
from rt.model import RobotModel
from rt.preflight import driver as driver_mod
from rt.twin.twin import Twin

LIBRARY = Path(__file__).resolve().parent.parent / "protocols" / "library"
PATIENT_KG = 70.0


def protocols() -> dict[str, object]:
    """The benchmark's protocols: a 60 s sine (the library's, 56 cycles), the ROM, the gait."""
    sine = load_protocol(LIBRARY / "sine_fz.yaml")
    sine60 = sine.model_copy(update={"cycles": 56, "name": "Sine Fz 60 s"})
    return {"sine60": sine60, "rom": load_protocol(LIBRARY / "ankle_rom.yaml"),
            "gait": load_protocol(LIBRARY / "gait_replay.yaml"),
            "assist": load_protocol(LIBRARY / "active_assist.yaml")}


@contextlib.contextmanager
def interpreted_references() -> Iterator[None]:
    """The generators' interpreted reference path (what the compiled one falls back to)."""
    path_refs, fk_path = base.path_joint_references, generators.fk_path
    base.path_joint_references = base.joint_references          # type: ignore[assignment]
    generators.fk_path = lambda *args: 0                         # type: ignore[assignment]
    try:
        yield
    finally:
        base.path_joint_references = path_refs                   # type: ignore[assignment]
        generators.fk_path = fk_path                             # type: ignore[assignment]


def references_time(protocol, model: RobotModel, compiled: bool) -> dict:
    ctx = contextlib.nullcontext() if compiled else interpreted_references()
    with ctx:
        c0, t0 = time.thread_time(), time.perf_counter()
        gen = make_generator(protocol, dt=1e-3, kinematics=model.kin,
                             patient_weight_kg=PATIENT_KG, base_dir=LIBRARY)
        report = gen.validate()
        cpu, wall = time.thread_time() - c0, time.perf_counter() - t0
    assert report.ok, report.violations
    return {"cpu_s": cpu, "wall_s": wall, "duration_s": report.duration_s}


def _timed(fn, spent: dict, key: str):
    """``fn`` with its CPU added to ``spent[key]`` and its calls to ``spent[key + '_calls']``."""
    calls = key + "_calls"

    def run(*args):
        c = time.thread_time()
        try:
            return fn(*args)
        finally:
            spent[key] += time.thread_time() - c
            spent[calls] += 1
    return run


def timing_overhead(n: int = 20000, repeats: int = 5) -> tuple[float, float]:
    """CPU s that timing one call with :func:`_timed` adds (inside the timed interval, and in
    all: the wrapper's call and its clock reads), medians of ``repeats`` rounds of ``n`` calls
    of a no-op."""
    def noop(*args):
        return 0
    inside, whole = [], []
    for _ in range(repeats):
        spent = {"x": 0.0, "x_calls": 0}
        run = _timed(noop, spent, "x")
        c0 = time.thread_time()
        for _ in range(n):
            run(None, 0.0, 0.0)
        c1 = time.thread_time()
        for _ in range(n):
            noop(None, 0.0, 0.0)
        c2 = time.thread_time()
        inside.append(spent["x"] / n)
        whole.append(((c1 - c0) - (c2 - c1)) / n)
    return statistics.median(inside), statistics.median(whole)


def preflight_time(protocol, model: RobotModel, fused: bool = True,
                   blocks: dict | None = None,
                   overhead: tuple[float, float] = (0.0, 0.0)) -> dict:
    """``session.preflight`` whole, with the CPU of ``validate()`` and of the twin's block.

    ``fused``: the twin's fault-free period as one compiled call (``Twin.fused_period``, the
    default) or the general path, for a before/after in one process. ``blocks``: filled with
    the loop's per-block execution times (``Graph.stats()``: where the loop's CPU goes; the
    graph is timed for it, ``session.PREFLIGHT_TIMED``). ``overhead``: :func:`timing_overhead`,
    taken off the figures once per timed call.
    """
    spent = {"twin": 0.0, "twin_calls": 0, "references": 0.0, "references_calls": 0}
    build = session.build_twin_session
    drivers: list = []
    make_driver = driver_mod.PreflightDriver

    def keep_driver(*args, **kwargs):
        drivers.append(make_driver(*args, **kwargs))
        return drivers[-1]

    def capture(*args, **kwargs):
        out = build(*args, **kwargs)
        if blocks is not None:
            blocks["pl"] = out[3]
        return out
    step = TwinStep.update
    validate = {cls: cls.validate for cls in (base.TableGenerator,
                                              generators.ActiveAssistGenerator)}
    TwinStep.update = _timed(step, spent, "twin")               # type: ignore[method-assign]
    Twin.fused_period = fused
    session.build_twin_session = capture                         # type: ignore[assignment]
    driver_mod.PreflightDriver = keep_driver                     # type: ignore[assignment, misc]
    session.PREFLIGHT_TIMED = blocks is not None
    for cls, fn in validate.items():
        cls.validate = _timed(fn, spent, "references")           # type: ignore[method-assign]
    try:
        setup = session.SessionSetup(protocol=protocol, base_dir=LIBRARY,
                                     patient_weight_kg=PATIENT_KG)
        c0, t0 = time.thread_time(), time.perf_counter()
        result = session.preflight(setup, model)
        cpu, wall = time.thread_time() - c0, time.perf_counter() - t0
    finally:
        TwinStep.update = step                                   # type: ignore[method-assign]
        Twin.fused_period = True
        session.build_twin_session = build                       # type: ignore[assignment]
        driver_mod.PreflightDriver = make_driver                 # type: ignore[misc]
        session.PREFLIGHT_TIMED = False
        for cls, fn in validate.items():
            cls.validate = fn                                    # type: ignore[method-assign]
    inside, whole = overhead
    calls = spent["twin_calls"] + spent["references_calls"]
    cpu -= calls * whole
    spent["twin"] -= spent["twin_calls"] * inside
    spent["references"] -= spent["references_calls"] * inside
    duration = result["predicted"]["duration_s"]
    # The driver's compiled cycles do not call the twin's block: their twin periods' share is
    # measured inside the compiled loop (``PreflightDriver.twin_cpu_s``), added here.
    compiled = sum(d.cycles_compiled for d in drivers)
    spent["twin"] += sum(d.twin_cpu_s for d in drivers)
    spent["twin_calls"] += compiled
    if blocks is not None:
        stats = blocks.pop("pl").graph.stats()
        blocks.update({slot: {"p50_us": c.p50_us, "mean_us": c.mean_us, "count": c.count}
                       for slot, c in stats.components.items()})
        blocks["(whole cycle)"] = {"p50_us": stats.cycle.p50_us, "mean_us": stats.cycle.mean_us,
                                   "count": stats.cycle.count}
    return {"cpu_s": cpu, "wall_s": wall, "duration_s": duration,
            "references_cpu_s": spent["references"], "twin_cpu_s": spent["twin"],
            "loop_cpu_s": cpu - spent["twin"] - spent["references"],
            "cpu_per_60s": cpu / duration * 60.0,
            "twin_us_per_cycle": spent["twin"] / max(spent["twin_calls"], 1) * 1e6,
            "cycles": spent["twin_calls"], "cycles_compiled": compiled,
            "timing_overhead_s": calls * whole}


def _median(runs: list[dict]) -> dict:
    out = dict(runs[0])
    for key, value in runs[0].items():
        if isinstance(value, float):
            out[key] = statistics.median(r[key] for r in runs)
    out["repeats"] = len(runs)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", default="sine60,rom,gait",
                        help="comma-separated subset of sine60, rom, gait, assist")
    parser.add_argument("--no-preflight", action="store_true",
                        help="time the reference generation only")
    parser.add_argument("--twin-ab", action="store_true",
                        help="also run every pre-flight with the twin's general (unfused) "
                             "period, interleaved: the fused period's before/after")
    parser.add_argument("--blocks", action="store_true",
                        help="print the loop's per-block times (µs) of each protocol's last "
                             "pre-flight")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    library = protocols()
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in library]
    if unknown:
        parser.error(f"unknown protocol(s) {unknown}; choose from {sorted(library)}")
    model = RobotModel.load()
    for name in names:                   # load (or compile) every kernel once, not timed
        references_time(library[name], model, True)
    refs: dict[str, dict[bool, list[dict]]] = {n: {True: [], False: []} for n in names}
    pre: dict[str, list[dict]] = {n: [] for n in names}
    unfused: dict[str, list[dict]] = {n: [] for n in names}
    blocks: dict[str, dict] = {n: {} for n in names}
    overhead = (0.0, 0.0)
    if not args.no_preflight:
        session.preflight(session.SessionSetup(protocol=library[names[0]], base_dir=LIBRARY,
                                               patient_weight_kg=PATIENT_KG), model)
        overhead = timing_overhead()
    for _ in range(args.repeats):
        for name in names:
            for compiled in (False, True):
                refs[name][compiled].append(references_time(library[name], model, compiled))
            if not args.no_preflight:
                if args.twin_ab:
                    unfused[name].append(preflight_time(library[name], model, fused=False,
                                                        overhead=overhead))
                pre[name].append(preflight_time(library[name], model,
                                                blocks=blocks[name] if args.blocks else None,
                                                overhead=overhead))
    result = {name: {"references_interpreted": _median(refs[name][False]),
                     "references_compiled": _median(refs[name][True]),
                     "preflight": _median(pre[name]) if pre[name] else None,
                     "preflight_unfused_twin": _median(unfused[name]) if unfused[name] else None,
                     "blocks": blocks[name] or None}
              for name in names}
    if args.json:
        print(json.dumps(result))
        return
    print(f"pre-flight costs, median of {args.repeats} interleaved runs, CPU s (this thread) / "
          "wall s (twin figures, this machine)")
    for name, r in result.items():
        ri, rc = r["references_interpreted"], r["references_compiled"]
        print(f"{name} ({ri['duration_s']:g} s protocol)")
        print(f"  references: interpreted {ri['cpu_s']:.3f} / {ri['wall_s']:.3f}, compiled "
              f"{rc['cpu_s']:.3f} / {rc['wall_s']:.3f} "
              f"(×{ri['cpu_s'] / max(rc['cpu_s'], 1e-9):.0f} CPU)")
        for label, key in (("pre-flight", "preflight"),
                           ("pre-flight, twin's general period", "preflight_unfused_twin")):
            p = r[key]
            if p is None:
                continue
            print(f"  {label}: {p['cpu_s']:.2f} / {p['wall_s']:.2f} — references "
                  f"{p['references_cpu_s']:.3f}, twin {p['twin_cpu_s']:.2f} "
                  f"({p['twin_cpu_s'] / p['cpu_s'] * 100:.0f} %, "
                  f"{p['twin_us_per_cycle']:.1f} µs a cycle: "
                  f"{1e3 / p['twin_us_per_cycle']:.0f}× real time), loop "
                  f"{p['loop_cpu_s']:.2f} ({p['loop_cpu_s'] / p['cpu_s'] * 100:.0f} %); "
                  f"{p['cpu_per_60s']:.2f} s CPU per 60 s of protocol (timing overhead "
                  f"{p['timing_overhead_s']:.3f} s taken off)")
        if r["blocks"]:
            print("  loop blocks, µs per cycle (median / mean, last run; the timing's own "
                  "overhead included):")
            for slot, b in r["blocks"].items():
                print(f"    {slot:<18} {b['p50_us']:8.1f} / {b['mean_us']:8.1f}  "
                      f"({b['count']} cycles)")


if __name__ == "__main__":
    main()
