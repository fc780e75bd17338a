"""A fused compiled cycle, prototype (issue 16): estimator → model → reference → controller →
supervisor as ONE numba call, timed per stage by the CPU's cycle counter read inside the
kernel, against the same five blocks called one by one as the graph calls them (each timed
with ``perf_counter_ns``). Not wired into the loop: a measurement of what fusing would buy.

    .venv/bin/python bench/fused_cycle.py [--cycles 3000] [--controller paden_panja]
                                          [--pace-us 800]

Both run the Paden-Panja (or computed torque) cycle on the twin's state after a few hundred
loop cycles; the fused run works on copies of every buffer so the two never share state.
``--pace-us`` sleeps that long between cycles (as the 1 kHz loop does, so caches are as cold
as in the loop); 0 = back to back. Interleaved: blocks, fused, fused on one arena, blocks ...
Prints medians and p99 (µs) of the whole of the five and, for the fused calls, of each stage
and of the call's own overhead (dispatch: the call's wall time minus the stages). The fused
call is run twice: with every buffer its own argument (33 arrays) and with every buffer a
slice of one arena (5 arrays) — numba's dispatch unboxes each array argument.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from rt.control import kernels as ck
from rt.estimation.compiled import block_update
from rt.model.kernels import model_state
from rt.position_loop import build_sim_position_loop
from rt.references import sequencer_kernel as rk
from rt.safety import supervisor_kernel as svk


@intrinsic
def _cycles(typingctx):  # type: ignore[no-untyped-def]
    """The CPU's cycle counter (x86: rdtsc) read inside a kernel."""
    sig = types.int64()

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        fnty = ir.FunctionType(ir.IntType(64), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.readcyclecounter")
        return builder.call(fn, [])
    return sig, codegen


@njit(cache=False)
def fused(stamps, t, dt,
          est_c, est_s, z, est_out, est_io,
          geom, limits, phi, stb, tol, maxit, mwork,
          ref_io, seq, mode, table,
          ti, tf, gains, cwork, tau, law,
          par, mem, est_status, fk_filled, wrench, wrench_flags, inputs, drive_failed,
          volts_per_n, volts, enable, sup_mode):
    stamps[0] = _cycles()
    block_update(est_c, est_s, z, dt, est_out, est_io)
    stamps[1] = _cycles()
    fk = model_state(geom, limits, phi, z, est_io[3:6], stb, tol, maxit, mwork)
    fk_ok = np.empty(1)
    fk_ok[0] = 1.0 if fk >= 0 else 0.0
    stamps[2] = _cycles()
    rk.cycle(ref_io, seq, z, mode, table, dt)
    stamps[3] = _cycles()
    if law == 0:
        ck.paden_panja(ti, tf, stb, ref_io[0:3], ref_io[3:6], ref_io[6:9], gains, cwork, tau)
    else:
        ck.computed_torque(ti, tf, stb, ref_io[0:3], ref_io[3:6], ref_io[6:9], gains, True,
                           cwork, tau)
    stamps[4] = _cycles()
    new = svk.block_cycle(par, mem, t, dt, z, est_status, est_io[3:6], est_io[6:9], stb, fk_ok,
                          fk_filled, ref_io[0:3], ref_io[3:6], tau, wrench, wrench_flags, inputs,
                          drive_failed, volts_per_n, volts, enable, sup_mode)
    stamps[5] = _cycles()
    return new


@njit(cache=False)
def fused_packed(stamps, t, dt, o, arena, tree_i, table, tol, maxit, fk_filled, volts_per_n,
                 law):
    """``fused`` with every buffer a slice of one arena (offsets ``o``: start of each of the
    buffers below, in ``_PACKED`` order, then the end): five array arguments instead of 33,
    so the call's dispatch no longer unboxes 30 arrays."""
    est_c = arena[o[0]:o[1]]
    est_s = arena[o[1]:o[2]]
    z = arena[o[2]:o[3]]
    est_out = arena[o[3]:o[4]]
    est_io = arena[o[4]:o[5]]
    geom = arena[o[5]:o[6]]
    limits = arena[o[6]:o[7]]
    phi = arena[o[7]:o[8]]
    stb = arena[o[8]:o[9]]
    mwork = arena[o[9]:o[10]]
    ref_io = arena[o[10]:o[11]]
    seq = arena[o[11]:o[12]]
    mode = arena[o[12]:o[13]]
    tf = arena[o[13]:o[14]]
    gains = arena[o[14]:o[15]]
    cwork = arena[o[15]:o[16]]
    tau = arena[o[16]:o[17]]
    par = arena[o[17]:o[18]]
    mem = arena[o[18]:o[19]]
    est_status = arena[o[19]:o[20]]
    wrench = arena[o[20]:o[21]]
    wrench_flags = arena[o[21]:o[22]]
    inputs = arena[o[22]:o[23]]
    drive_failed = arena[o[23]:o[24]]
    volts = arena[o[24]:o[25]]
    enable = arena[o[25]:o[26]]
    sup_mode = arena[o[26]:o[27]]
    fk_ok = arena[o[27]:o[28]]
    stamps[0] = _cycles()
    block_update(est_c, est_s, z, dt, est_out, est_io)
    stamps[1] = _cycles()
    fk = model_state(geom, limits, phi, z, est_io[3:6], stb, tol, maxit, mwork)
    fk_ok[0] = 1.0 if fk >= 0 else 0.0
    stamps[2] = _cycles()
    rk.cycle(ref_io, seq, z, mode, table, dt)
    stamps[3] = _cycles()
    if law == 0:
        ck.paden_panja(tree_i, tf, stb, ref_io[0:3], ref_io[3:6], ref_io[6:9], gains, cwork,
                       tau)
    else:
        ck.computed_torque(tree_i, tf, stb, ref_io[0:3], ref_io[3:6], ref_io[6:9], gains, True,
                           cwork, tau)
    stamps[4] = _cycles()
    new = svk.block_cycle(par, mem, t, dt, z, est_status, est_io[3:6], est_io[6:9], stb, fk_ok,
                          fk_filled, ref_io[0:3], ref_io[3:6], tau, wrench, wrench_flags, inputs,
                          drive_failed, volts_per_n, volts, enable, sup_mode)
    stamps[5] = _cycles()
    return new


def _ro(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cycles", type=int, default=3000)
    p.add_argument("--controller", default="paden_panja",
                   choices=["paden_panja", "computed_torque"])
    p.add_argument("--pace-us", type=float, default=800.0)
    args = p.parse_args(argv)
    pl = build_sim_position_loop(args.controller, duration_s=30.0)
    pl.loop.run(cycles=500)
    g = pl.graph
    est, mod, ref = g.component("estimator"), g.component("model"), g.component("reference")
    ctl, sup = g.component("controller"), g.component("supervisor")
    blocks = [est, mod, ref, ctl, sup]

    # The fused call's own copies of every buffer.
    kin = mod.model.kin
    law = ctl.controller
    e = est.state
    stb = mod.state_out.data.buf.copy()
    s = sup.sup
    cp = np.copy
    fargs = (cp(e._c), cp(e._s), _ro(cp(est.q_meas.data)), cp(e._out), cp(est._io),
             kin.geom, kin.limits_array, cp(kin._phi_guess), stb, 1e-12, 50, cp(mod._work),
             cp(ref._io), cp(ref._seq), _ro(cp(ref.mode.data)), ref._table,
             law.dyn.tree_i, law.dyn.tree_f, cp(law._gain_array), cp(law._work), cp(ctl.tau.data),
             0 if args.controller == "paden_panja" else 1,
             cp(s._par), cp(s._mem), _ro(cp(sup.est_status.data)), True,
             _ro(cp(sup.wrench.data)), _ro(cp(sup.wrench_flags.data)), _ro(cp(sup.stops.data)),
             _ro(cp(sup.drive_failed.data)), sup.k, cp(sup.volts.data), cp(sup.enable.data),
             cp(sup.mode.data))
    stamps = np.zeros(6, dtype=np.int64)
    fused(stamps, 0.5, 1e-3, *fargs)            # compile
    # The same buffers packed into one arena (fresh copies: a third independent state).
    parts = [e._c, e._s, est.q_meas.data, e._out, est._io, kin.geom.ravel(),
             kin.limits_array.ravel(), kin._phi_guess, mod.state_out.data.buf, mod._work,
             ref._io, ref._seq, ref.mode.data, law.dyn.tree_f, law._gain_array, law._work,
             ctl.tau.data, s._par, s._mem, sup.est_status.data, sup.wrench.data,
             sup.wrench_flags.data, sup.stops.data, sup.drive_failed.data, sup.volts.data,
             sup.enable.data, sup.mode.data, np.ones(1)]
    offsets = np.concatenate([[0], np.cumsum([len(np.ravel(x)) for x in parts])]).astype(
        np.int64)
    arena = np.concatenate([np.ravel(np.asarray(x, dtype=np.float64)) for x in parts])
    pargs = (offsets, arena, law.dyn.tree_i, ref._table, 1e-12, 50, True, sup.k,
             0 if args.controller == "paden_panja" else 1)
    pstamps = np.zeros(6, dtype=np.int64)
    fused_packed(pstamps, 0.5, 1e-3, *pargs)    # compile

    # Cycle counter → ns, against the monotonic clock over ~0.2 s.
    c0, n0 = int(_tsc_now()), time.perf_counter_ns()
    time.sleep(0.2)
    c1, n1 = int(_tsc_now()), time.perf_counter_ns()
    ns_per_tick = (n1 - n0) / (c1 - c0)

    pc = time.perf_counter_ns
    n = args.cycles
    blk = np.zeros((n, len(blocks)))
    fz = np.zeros((n, 6))
    fp = np.zeros((n, 6))
    pace = args.pace_us * 1e-6
    t = 0.5
    for i in range(n):
        if pace:
            time.sleep(pace)
        prev = pc()
        for j, b in enumerate(blocks):
            b.update(t, 1e-3)
            now = pc()
            blk[i, j] = now - prev
            prev = now
        if pace:
            time.sleep(pace)
        a = pc()
        fused(stamps, t, 1e-3, *fargs)
        wall = pc() - a
        fz[i, :5] = np.diff(stamps) * ns_per_tick
        fz[i, 5] = wall - (stamps[5] - stamps[0]) * ns_per_tick
        if pace:
            time.sleep(pace)
        a = pc()
        fused_packed(pstamps, t, 1e-3, *pargs)
        wall = pc() - a
        fp[i, :5] = np.diff(pstamps) * ns_per_tick
        fp[i, 5] = wall - (pstamps[5] - pstamps[0]) * ns_per_tick
        t += 1e-3
    names = ["estimator", "model", "reference", "controller", "supervisor"]
    us = 1e-3
    print(f"{args.controller}, {n} cycles, pace {args.pace_us:g} µs, medians / p99 (µs)")
    def cell(x: np.ndarray) -> str:
        return f"{np.median(x) * us:7.2f} / {np.percentile(x, 99) * us:6.1f}"

    print(f"{'stage':14s} {'blocks':>16s} {'fused, 33 args':>16s} {'fused, arena':>16s}")
    for j, name in enumerate(names):
        print(f"{name:14s} {cell(blk[:, j])} {cell(fz[:, j])} {cell(fp[:, j])}")
    print(f"{'call overhead':14s} {'':>16s} {cell(fz[:, 5])} {cell(fp[:, 5])}")
    whole_b, whole_f, whole_p = blk.sum(axis=1), fz.sum(axis=1), fp.sum(axis=1)
    print(f"{'whole five':14s} {cell(whole_b)} {cell(whole_f)} {cell(whole_p)}")
    print(f"ratio of medians to the blocks': 33 args {np.median(whole_f) / np.median(whole_b):.2f}"
          f", arena {np.median(whole_p) / np.median(whole_b):.2f}")
    pl.graph.stop()
    return 0


@njit(cache=False)
def _tsc_now():
    return _cycles()


if __name__ == "__main__":
    raise SystemExit(main())
