"""The position loop on the twin for minutes, at 1 kHz and at 2 kHz: histograms of the cycles'
lateness and execution time (twin figures, this machine; DESIGN §10, issue 16).

    .venv/bin/python bench/loop_10min.py [--seconds 600] [--rates 1000 2000]
        [--controller paden_panja] [--cpu-latency-us 0] [--out DIR] [--force]

Runs ``build_sim_position_loop`` in realtime mode (the product's loop: sleep, then spin to
each deadline) for ``--seconds`` per rate, in one ``Loop.run`` as the RT process does (a loop
re-entered after a pause stops at once: until 2026-11-26e this bench chunked by ``run`` and
measured a stopped loop); every ``--chunk`` seconds the loop copies its new timing samples in
its own thread at a cycle boundary (the rings hold 65536 cycles), folded here into 1 µs
histograms. Prints, per rate,
median / p99 / max of lateness, whole cycle and cycle without the twin block (the rig has no
twin), and the deadline misses (cycles later than 20 % of the period), and
the host's steal time per chunk beside that chunk's misses (``/proc/stat``; ``--chunk 1`` for a
finer split; on 20 s chunks, 2026-11-26b, the misses did not follow the steal: Pearson 0.01
over 30 chunks, so the VM's steal counter does not explain them at that scale). Writes
``loop_10min.json`` (figures and histograms) and ``loop_10min.png`` into ``--out`` (default:
the current directory); an existing file is refused unless ``--force`` (then replaced only once
the new one is complete).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from rt.position_loop import build_sim_position_loop

BIN_US = 1.0
MAX_US = 5000.0                 # last bin collects everything above (its count is reported)
N_BINS = int(MAX_US / BIN_US) + 1
WARM_UP_S = 2.0


def _fold(hist: np.ndarray, samples_ns: np.ndarray) -> None:
    us = samples_ns[samples_ns >= 0] / 1e3
    idx = np.minimum((us / BIN_US).astype(np.int64), N_BINS - 1)
    hist += np.bincount(idx, minlength=N_BINS)


def _percentile(hist: np.ndarray, q: float) -> float:
    """The q-th percentile (µs) from a 1 µs histogram: the bin's upper edge (a bound)."""
    total = hist.sum()
    if total == 0:
        return float("nan")
    k = int(np.searchsorted(np.cumsum(hist), q / 100.0 * total))
    return (k + 1) * BIN_US


def _summary(hist: np.ndarray, max_ns: float) -> dict:
    return {"median_us": _percentile(hist, 50.0), "p99_us": _percentile(hist, 99.0),
            "p999_us": _percentile(hist, 99.9), "max_us": max_ns / 1e3,
            "count": int(hist.sum()), "above_histogram": int(hist[-1])}


def _steal_jiffies() -> int:
    """The host's steal time over every CPU (USER_HZ ticks, /proc/stat's 8th field): time this
    VM's vCPUs were ready to run and the hypervisor ran something else. 0 where not reported."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) if fields[0] == "cpu" and len(fields) > 8 else 0
    except (OSError, ValueError):
        return 0


def _new_samples(ring: np.ndarray, end: int, n: int) -> np.ndarray:
    """The ``n`` samples a ring of power-of-two length wrote before position ``end`` (a
    running count), oldest first."""
    cap = len(ring)
    n = min(n, cap)
    return ring[np.arange(end - n, end) % cap].copy()


def run_rate(rate_hz: float, seconds: float, chunk_s: float, controller: str,
             cpu_latency_us: int | None = 0) -> dict:
    # PM QoS as the RT process has it by default (RtConfig.cpu_latency_us 0); None: not asked.
    extra = {} if cpu_latency_us is None else {"cpu_latency_us": cpu_latency_us}
    pl = build_sim_position_loop(controller, duration_s=WARM_UP_S + seconds + 10.0,
                                 rate_hz=rate_hz, mode="realtime", **extra)
    loop, graph = pl.loop, pl.graph
    twin_slot = graph._order.index("twin")
    hists = {k: np.zeros(N_BINS, dtype=np.int64) for k in ("lateness", "cycle", "without_twin")}
    maxes = dict.fromkeys(hists, 0.0)
    # One ``Loop.run`` for the whole span, as the RT process runs its loop: a loop that leaves
    # ``run`` and enters it again stops at once (the twin catches up the pause: an
    # ``encoder_jump`` hard stop; 2026-11-26e), so chunking by ``run`` measured a stopped loop.
    # The timing rings (65536 cycles) are copied every ``chunk_s`` instead, in the loop's own
    # thread at a cycle boundary (``Loop.call``: exact, ≈ 0.3 ms of copying once per chunk, in
    # the idle time before the next deadline), and folded here.
    marks = {"cycles": 0, "lat": 0}

    def copy_rings(_loop) -> tuple[np.ndarray, ...]:
        cycles, lat_count = graph._cycles, loop._lat_count
        n_cyc, n_lat = cycles - marks["cycles"], lat_count - marks["lat"]
        marks["cycles"], marks["lat"] = cycles, lat_count
        return (_new_samples(graph._cycle_ring, cycles, n_cyc),
                _new_samples(graph._rings[twin_slot], cycles, n_cyc),
                _new_samples(loop._lat_ring, loop._lat_idx, n_lat))

    runner = threading.Thread(target=loop.run, kwargs={"seconds": WARM_UP_S + seconds},
                              name="loop_10min", daemon=True)
    runner.start()
    # Warm-up, not counted: the first cycles load numba's cached kernels (the twin's too) and
    # fault in memory; a clinic's loop is started well before a protocol runs.
    time.sleep(WARM_UP_S)
    loop.call(copy_rings, "loop_10min: warm-up mark").result(timeout=10.0)
    warm = loop.stats()
    wall0 = time.monotonic()
    # Per chunk: the loop's misses beside the host's steal time over the same span, so a run
    # says whether its misses come with the hypervisor taking the vCPU (nothing the loop can do).
    chunks: list[dict] = []
    misses_before = warm.misses
    done = False
    while not done:
        steal0 = _steal_jiffies()
        runner.join(timeout=chunk_s)
        done = not runner.is_alive()
        steal1 = _steal_jiffies()
        cycle, twin, lat = (copy_rings(loop) if done else
                            loop.call(copy_rings, "loop_10min: timing rings").result(timeout=10.0))
        now_misses = loop.stats().misses
        chunks.append({"cycles": len(cycle), "misses": int(now_misses - misses_before),
                       "steal_ms": 1000.0 * (steal1 - steal0) / os.sysconf("SC_CLK_TCK")})
        misses_before = now_misses
        ok = (cycle >= 0) & (twin >= 0)
        for key, samples in (("lateness", lat), ("cycle", cycle[cycle >= 0]),
                             ("without_twin", cycle[ok] - twin[ok])):
            _fold(hists[key], samples)
            if samples.size:
                maxes[key] = max(maxes[key], float(samples.max()))
    latched = [x["cause"] for x in pl.supervisor.latched()]
    stats = pl.loop.stats()
    pl.graph.stop()
    cycles = int(stats.lateness.count - warm.lateness.count)
    misses = int(stats.misses - warm.misses)
    hyg = pl.loop.hygiene
    return {"rate_hz": rate_hz, "controller": controller, "seconds": seconds,
            "cpu_latency_us": None if hyg is None else hyg.cpu_latency_us,
            "wall_s": time.monotonic() - wall0, "cycles": cycles,
            "deadline_misses": misses,
            "miss_percent": 100.0 * misses / cycles if cycles else float("nan"),
            "miss_tolerance_us": stats.miss_tolerance_us,
            "rephases": int(stats.rephases - warm.rephases), "warm_up_s": WARM_UP_S,
            "chunks": chunks, "steal": _steal_summary(chunks),
            # A stop latched during the run: its figures are a stopped loop's, not steady ones.
            "latched": latched,
            "lateness": _summary(hists["lateness"], maxes["lateness"]),
            "cycle": _summary(hists["cycle"], maxes["cycle"]),
            "cycle_without_twin": _summary(hists["without_twin"], maxes["without_twin"]),
            "histograms_us": {k: {"bin_us": BIN_US, "counts": h.tolist()}
                              for k, h in hists.items()}}


def _steal_summary(chunks: list[dict]) -> dict:
    """How the misses split between chunks with and without host steal time."""
    stolen = [c for c in chunks if c["steal_ms"] > 0]
    clean = [c for c in chunks if c["steal_ms"] == 0]
    return {"chunks": len(chunks), "chunks_with_steal": len(stolen),
            "steal_ms_total": sum(c["steal_ms"] for c in chunks),
            "misses_in_chunks_with_steal": sum(c["misses"] for c in stolen),
            "misses_in_chunks_without_steal": sum(c["misses"] for c in clean),
            "cycles_in_chunks_without_steal": sum(c["cycles"] for c in clean)}


def _write_atomic(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _plot(results: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(results), 2, figsize=(11, 3.6 * len(results)), squeeze=False)
    for row, r in zip(axes, results):
        for ax, keys, title in ((row[0], ("lateness",), "lateness"),
                                (row[1], ("cycle", "without_twin"), "cycle time")):
            for key in keys:
                counts = np.array(r["histograms_us"][key]["counts"])
                nz = np.nonzero(counts)[0]
                hi = min(int(nz.max()) + 2, N_BINS) if nz.size else 10
                x = np.arange(hi) * BIN_US
                ax.step(x, np.maximum(counts[:hi], 0.5), where="post",
                        label=key.replace("_", " "))
            ax.set_yscale("log")
            ax.set_xlabel("µs")
            ax.set_ylabel("cycles")
            ax.set_title(f"{r['rate_hz']:g} Hz, {r['seconds']:g} s: {title}")
            ax.legend()
        row[0].axvline(r["miss_tolerance_us"], color="r", lw=0.8)
    fig.tight_layout()
    _write_atomic(path, lambda tmp: fig.savefig(tmp, format="png", dpi=90))
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=600.0, help="per rate (default 600)")
    p.add_argument("--rates", type=float, nargs="+", default=[1000.0, 2000.0])
    p.add_argument("--chunk", type=float, default=20.0, help="seconds per timing chunk")
    p.add_argument("--controller", default="paden_panja")
    p.add_argument("--out", type=Path, default=Path("."))
    p.add_argument("--cpu-latency-us", type=int, default=0,
                   help="PM QoS wake-up bound while the loop runs, as the RT process's default "
                        "(0); -1: not requested")
    p.add_argument("--force", action="store_true", help="replace existing outputs")
    args = p.parse_args(argv)
    if not -1 <= args.cpu_latency_us <= 10_000:
        p.error(f"--cpu-latency-us must be in [-1, 10000], got {args.cpu_latency_us}")
    if not (args.seconds > 0 and np.isfinite(args.seconds)):
        p.error(f"--seconds must be > 0, got {args.seconds}")
    if not (0 < args.chunk <= 30.0):
        p.error("--chunk must be in (0, 30] s (the timing rings hold 65536 cycles)")
    if any(r * args.chunk > 65536 for r in args.rates):
        p.error("--chunk × rate must stay below 65536 cycles")
    json_path = args.out / "loop_10min.json"
    png_path = args.out / "loop_10min.png"
    for path in (json_path, png_path):
        if path.exists() and not args.force:
            p.error(f"{path} exists; pass --force to replace it")
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for rate in args.rates:
        r = run_rate(rate, args.seconds, args.chunk, args.controller,
                     None if args.cpu_latency_us < 0 else args.cpu_latency_us)
        results.append(r)
        print(f"{rate:g} Hz, {args.seconds:g} s ({r['cycles']} cycles, {args.controller}, "
              f"twin): misses {r['deadline_misses']} ({r['miss_percent']:.3f} %, "
              f"> {r['miss_tolerance_us']:.0f} µs late), re-phased {r['rephases']}x")
        if r["latched"]:
            print(f"  STOPPED during the run ({', '.join(r['latched'])}): not steady figures")
        st = r["steal"]
        print(f"  host steal: {st['steal_ms_total']:.0f} ms over {st['chunks_with_steal']} of "
              f"{st['chunks']} chunks; misses in those chunks {st['misses_in_chunks_with_steal']}, "
              f"in the others {st['misses_in_chunks_without_steal']} "
              f"(of {st['cycles_in_chunks_without_steal']} cycles)")
        for key in ("lateness", "cycle", "cycle_without_twin"):
            s = r[key]
            print(f"  {key:20s} median {s['median_us']:7.0f}  p99 {s['p99_us']:7.0f}  "
                  f"p99.9 {s['p999_us']:7.0f}  max {s['max_us']:9.1f} µs")
        sys.stdout.flush()
    doc = {"benchmark": "loop_10min", "figures": "twin figures, this machine",
           "histogram_bin_us": BIN_US, "results": results}
    _write_atomic(json_path, lambda tmp: Path(tmp).write_text(json.dumps(doc)))
    _plot(results, png_path)
    print(f"wrote {json_path} and {png_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
