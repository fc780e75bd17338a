"""Where the RT process loses its deadlines during a recorded session (twin figures).

Runs a real RT process (``rt.service.serve``, backend sim, realtime, the production session
factory) once per *variant*, each variant switching one suspect off or one remedy on, the
variants interleaved (``--reps`` rounds of all of them) so that they share the machine's load.
Per run: idle, then one recorded sine-Fz session (``--duration`` s); the RT loop's deadline
misses (cycles starting > 20 % of a period late) and lateness p99/max are reported per phase:
idle, pre-flight (session_start → reply), session (reply → end), and whether the supervisor
stopped the session.

    .venv/bin/python bench/rt_deadlines.py [--variants base,no_recorder,...] [--reps 2]
        [--duration 10] [--json]

Variants (``--list``): see :data:`VARIANTS`. The variant is applied inside the RT process
(``--serve VARIANT``, the child this script starts), by replacing one piece before ``serve``.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

_HERE = str(Path(__file__).resolve().parent)
sys.path[:] = [p for p in sys.path if str(Path(p or ".").resolve()) != _HERE]

#: token → what it changes (applied by :func:`_apply` in the RT process). A variant is one or
#: more tokens joined by ``+``; ``base`` is the RT process as it is now.
VARIANTS: dict[str, str] = {
    "base": "the RT process as it is",
    "shipped": "as before this branch: ordinary-priority service threads, pre-flight worker "
               "at nice 0, float32 recording",
    "no_peer_prio": "the RT process's other threads at ordinary priority",
    "worker_nice10": "the pre-flight worker at nice 10",
    "f32": "recording in float32 protobuf (the previous encoding)",
    "json": "recording in JSON (before issue 16)",
    "v2": "recording in talus.v2 fixed point (t_us in the payloads, volts in mV)",
    "v3": "recording in talus.v3 (three 1 kHz channels; the default is talus.v4, one message "
          "per cycle)",
    "no_recorder": "sessions not recorded (a recorder that drops every message)",
    "no_record_rows": "the pump does not feed the recorder's wrench/reference/ankle channels",
    "no_figures": "the pump computes no session figures (SessionFigures.add skipped)",
    "no_telemetry": "telemetry published at 0.2 Hz instead of 60 Hz",
    "no_fifo": "the loop thread without SCHED_FIFO (plain CFS thread)",
    "peer_prio": "the RT process's other threads at SCHED_FIFO 1 (RtConfig.service_priority)",
    "hold1": "the loop holds the GIL for its cycle (Loop gil_hold_s=0.001), no guard",
    "hold5": "as hold1 with 5 ms",
    "no_gil_hold": "one GIL switch interval (0.2 ms) during cycles too (as no_guard)",
    "no_guard": "the loop shares the GIL by the 0.2 ms switch interval (RtConfig "
                "gil_guard_us=None: the default before 2026-11-26)",
    "guard": "the loop's GIL guard: awake 400 µs before each deadline, holding the GIL to the "
             "cycle's end (RtConfig gil_guard_us=400: the default since 2026-11-26)",
    "guard200": "the loop's GIL guard 200 µs before each deadline (RtConfig gil_guard_us)",
    "si50": "a 50 µs GIL switch interval (instead of 200 µs)",
    "qos": "every CPU's wake-up latency bounded to 0 µs through PM QoS while the loop runs "
           "(RtConfig cpu_latency_us=0: idle vCPUs poll instead of halting; the default since "
           "2026-11-26)",
    "no_qos": "no PM QoS request (RtConfig cpu_latency_us=None: the default before 2026-11-26)",
    "unaligned": "telemetry and the session pump on free-running timers (as before branch "
                 "rtloop3), not woken by the loop right after a cycle",
    "no_hb": "the bench client sends no heartbeat while idle (only from the session start)",
}

PATIENT = {"id": "BENCH", "weight_kg": 70.0}


# ------------------------------------------------------------------------------ RT process
def _apply(variant: str, config: Any, holder: dict[str, Any], ext: dict[str, Any]) -> Any:
    import functools

    from rt import service
    from rt.recording import writer

    tokens = set(variant.split("+")) - {"base"}
    if "shipped" in tokens:
        tokens |= {"no_peer_prio", "f32", "no_guard"}
    real_build = service.build_rt_loop

    def build(cfg: Any) -> Any:
        pl, tap = real_build(cfg)
        holder["pl"] = pl
        return pl, tap
    service.build_rt_loop = build
    if "no_peer_prio" in tokens:
        config = config.model_copy(update={"service_priority": None})
    elif "peer_prio" in tokens:
        config = config.model_copy(update={"service_priority": 1})
    if "worker_nice10" in tokens:
        ext["sessions"].worker_nice = 10
    if "f32" in tokens or "json" in tokens or "v2" in tokens or "v3" in tokens:
        writer.SessionRecorder = functools.partial(  # type: ignore[misc]
            writer.SessionRecorder, encoding="json" if "json" in tokens else
            "protobuf-v2" if "v2" in tokens else "protobuf-v3" if "v3" in tokens
            else "protobuf-f32")
    if "no_recorder" in tokens:
        class NullRecorder:
            def __init__(self, path: Any, metadata: Any, **kw: Any) -> None:
                self.path = path

            def __getattr__(self, name: str) -> Any:
                return lambda *a, **k: True

            def close(self, *a: Any, **k: Any) -> dict[str, Any]:
                return {"sha256": None, "bytes": 0}
        writer.SessionRecorder = NullRecorder  # type: ignore[misc,assignment]
    if "no_record_rows" in tokens:
        service.record_rows = lambda *a, **k: None  # type: ignore[assignment]
    if "no_figures" in tokens:
        import protocols.session as psession
        psession.SessionFigures.add = lambda self, rows: None  # type: ignore[method-assign]
    if "no_guard" in tokens:
        config = config.model_copy(update={"gil_guard_us": None})
    elif "guard200" in tokens:
        config = config.model_copy(update={"gil_guard_us": 200.0})
    elif "guard" in tokens:
        config = config.model_copy(update={"gil_guard_us": 400.0})
    if "qos" in tokens:
        config = config.model_copy(update={"cpu_latency_us": 0})
    if "no_qos" in tokens:
        config = config.model_copy(update={"cpu_latency_us": None})
    if "unaligned" in tokens:
        from rt.engine import loop as loopmod

        class FreeTimer:
            """A CycleSignal stand-in that fires on its own period, whatever the loop does."""

            def __init__(self, every: int) -> None:
                self.period = every / config.rate_hz

            def wait(self, timeout: float) -> bool:
                time.sleep(min(timeout, self.period))
                return True

            def close(self) -> None:
                pass
        loopmod.Loop.cycle_signal = lambda self, every: FreeTimer(every)  # type: ignore
    if "no_telemetry" in tokens:
        config = config.model_copy(update={"telemetry_hz": 0.2})
    loop_kw: dict[str, Any] = {}
    if "no_fifo" in tokens:
        loop_kw["rt_priority"] = None
    if "si50" in tokens:
        loop_kw["switch_interval_s"] = 0.00005
        service.SWITCH_INTERVAL_S = 0.00005
    if "no_gil_hold" in tokens or "hold5" in tokens or "hold1" in tokens:
        config = config.model_copy(update={"gil_guard_us": None})     # the hold alone
    if "hold5" in tokens:
        loop_kw["gil_hold_s"] = 0.005
    elif "hold1" in tokens:
        loop_kw["gil_hold_s"] = 0.001
    if loop_kw:
        import rt.position_loop as plmod
        plmod.Loop = functools.partial(plmod.Loop, **loop_kw)  # type: ignore[misc]
    return config


def serve_variant(variant: str, recordings: str) -> int:
    from rt.service import RtConfig, serve
    from talus.composition import rt_extensions

    config = RtConfig(backend="sim", endpoint="tcp://127.0.0.1:*",
                      pub_endpoint="tcp://127.0.0.1:*", heartbeat_timeout_s=1.0,
                      recordings_dir=recordings)
    holder: dict[str, Any] = {}
    ext = rt_extensions()
    config = _apply(variant, config, holder, ext)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())

    def ready(server: Any) -> None:
        print(json.dumps({"serving": {"endpoint": server.endpoint,
                                      "pub_endpoint": server.pub_endpoint}}), flush=True)

    serve(config, stop, ready, **ext)
    pl = holder["pl"]
    lat = pl.loop.lateness_samples()
    cyc = pl.graph.timing_samples()["cycle"]
    h = pl.loop.hygiene
    print(json.dumps({"done": {"cycles": pl.loop.cycles,
                               "lateness_ns": lat.tolist(), "cycle_ns": cyc.tolist(),
                               "fifo": None if h is None else h.fifo}}), flush=True)
    return 0


# ------------------------------------------------------------------------------ client
def _phase(lat: Any, cyc: Any, first: int, last: int, total: int, tol_ns: float) -> dict:
    import numpy as np

    n = len(lat)
    lo, hi = max(0, first - (total - n)), max(0, last - (total - n))
    seg = np.asarray(lat[lo:hi], dtype=float)
    cseg = np.asarray(cyc[lo:hi], dtype=float)
    if not len(seg):
        return {"cycles": 0}
    return {"cycles": len(seg), "misses": int((seg > tol_ns).sum()),
            "misses_per_1000": round(1000.0 * float((seg > tol_ns).mean()), 2),
            "late_p99_us": round(float(np.percentile(seg, 99)) / 1e3, 1),
            "late_max_us": round(float(seg.max()) / 1e3, 1),
            "cycle_p50_us": round(float(np.percentile(cseg, 50)) / 1e3, 1),
            "cycle_p99_us": round(float(np.percentile(cseg, 99)) / 1e3, 1)}


def run_variant(variant: str, doc: dict, idle_s: float) -> dict[str, Any]:
    from rt.ipc.client import RtClient

    tmp = tempfile.mkdtemp(prefix="talus-deadlines-")
    proc = subprocess.Popen([sys.executable, __file__, "--serve", variant, "--recordings", tmp],
                            stdout=subprocess.PIPE, text=True)
    out: dict[str, Any] = {"variant": variant}
    try:
        line = proc.stdout.readline()  # type: ignore[union-attr]
        endpoint = json.loads(line)["serving"]["endpoint"]
        with RtClient(endpoint, timeout_s=5.0) as c:
            c.control_acquire("deadlines bench")
            idle_hb = "no_hb" not in variant.split("+")
            if idle_hb:
                c.start_heartbeat(0.05)
            time.sleep(2.0)                       # the loop settles (compiled kernels loaded)
            s0 = c.status()
            time.sleep(idle_s)
            s1 = c.status()
            if not idle_hb:
                c.start_heartbeat(0.05)
            t0 = time.monotonic()
            try:
                started = c.session_start(doc, PATIENT)
                sid = started["session_id"]
                out["recording"] = started["recording"]
            except Exception as exc:      # noqa: BLE001 - a refusal is a figure here
                out["refused"] = str(exc)
                sid = None
            out["start_s"] = round(time.monotonic() - t0, 2)
            s2 = c.status()
            while sid is not None and c.session_status()["session"] == sid:
                time.sleep(0.2)
            s3 = c.status()
            out["stops"] = [f["cause"] for f in s3["latched"]]
            c.stop_heartbeat()
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            rest = proc.communicate(timeout=120)[0]
        except subprocess.TimeoutExpired:
            proc.kill()
            rest = proc.communicate()[0]
    if '{"done"' not in rest:
        out["error"] = "the RT process did not report (killed after 120 s)"
        return out
    done = next(json.loads(x)["done"] for x in rest.splitlines() if x.startswith('{"done"'))
    lat, cyc, total = done["lateness_ns"], done["cycle_ns"], done["cycles"]
    tol = 0.2e6
    out["fifo"] = done["fifo"]
    out["idle"] = _phase(lat, cyc, s0["cycles"], s1["cycles"], total, tol)
    out["preflight"] = _phase(lat, cyc, s1["cycles"], s2["cycles"], total, tol)
    out["session"] = _phase(lat, cyc, s2["cycles"], s3["cycles"], total, tol)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--serve", help=argparse.SUPPRESS)
    ap.add_argument("--recordings", help=argparse.SUPPRESS)
    ap.add_argument("--variants", default="shipped,base")
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--duration", type=float, default=10.0, help="sine cycles (1 Hz), s")
    ap.add_argument("--idle", type=float, default=3.0)
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.serve:
        return serve_variant(args.serve, args.recordings)
    if args.list:
        for k, v in VARIANTS.items():
            print(f"{k:16s} {v}")
        return 0
    from protocols.library import LIBRARY_DIR
    from protocols.rt_session import protocol_document

    doc = protocol_document(LIBRARY_DIR / "sine_fz.yaml")
    doc.update(cycles=max(1, int(args.duration)), ramp_in_s=1.0, ramp_out_s=1.0)
    variants = args.variants.split(",")
    unknown = [v for v in variants if not set(v.split("+")) <= set(VARIANTS)]
    if unknown:
        ap.error(f"unknown variants {unknown}; --list")
    results = []
    for rep in range(args.reps):
        for v in variants:
            load = os.getloadavg()[0]
            r = run_variant(v, doc, args.idle)
            r["rep"], r["load1"] = rep, round(load, 2)
            results.append(r)
            if args.json:
                print(json.dumps(r), flush=True)
            else:
                ph = " | ".join(
                    f"{p} {r.get(p, {}).get('misses_per_1000', '-')}/1000 late p99 "
                    f"{r.get(p, {}).get('late_p99_us', '-')} max "
                    f"{r.get(p, {}).get('late_max_us', '-')} µs, cycle p50/p99 "
                    f"{r.get(p, {}).get('cycle_p50_us', '-')}/"
                    f"{r.get(p, {}).get('cycle_p99_us', '-')} µs"
                    for p in ("idle", "preflight", "session"))
                print(f"rep {rep} {v:15s} load {r['load1']:5.2f} start {r.get('start_s')} s "
                      f"stops {r.get('stops') or '-'} {r.get('refused', '')} "
                      f"{r.get('error', '')}\n    {ph}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
