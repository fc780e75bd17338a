"""The compiled pre-flight driver (issue 16: a 60 s protocol's pre-flight in ≤ 1.5 s).

A pre-flight runs the session's own loop on the in-process twin as fast as possible
(``protocols.session.preflight``): per cycle the twin's block (``TwinStep``: the physics to
the loop's time), the fused segment (``rt.components.fused.FusedChain``: encoders … recorder
in one compiled call), the session tap's row, the graph's delay latches. Every piece of that
cycle is compiled; what was left is the Python around them (the loop, the graph, the
segment's fast path, the twin's sync, the tap's dispatch). :func:`steady_cycles` is that
cycle as one ``@njit`` loop over cycles (preflight6's design, ``docs/worklog/2026-11-26c/
preflight6.md`` §4), run only while the cycle is *steady*: the segment's fast path is in
force (:meth:`FusedChain.run`: the previous cycle ran the whole segment in the kernel, a plan
bound to the in-process twin's devices), the twin's period is fault-free
(``Twin._sync_fused``), and nothing but the kernel runs between two cycles.

It hands back to Python at the first cycle that needs it, at one of two points:

* **before a cycle** (:data:`BACK_BEFORE`): the supervisor's mode output or the drive's
  failed flag changed (the fast path's guard reads them), or the twin's period asked for
  Python (its ATI's random block used up: ``kernels.NEED_DRAWS``; a failed FK). The twin may
  have run whole chunks of that cycle; Python's cycle (``Loop.run(cycles=1)``) continues from
  there (``Twin.sync`` runs the rest), as the per-block loop would have.
* **inside a cycle** (:data:`BACK_INSIDE`): the segment's kernel stopped before its end or
  asked for Python (a stage's Python, a soft stop's latch, the sequencer's end of program, a
  mode switch of the hybrid controller). The twin's period and the kernel have run; Python
  finishes that cycle through the normal path from the kernel's answer
  (``FusedChain._finish``, then the graph's remaining slots, the tap, the latches), exactly
  where the fast path's own call would have returned.

Between hand-backs the driver leaves the state the per-block/fused loop leaves: the twin (its
block, encoder card, ATI bookkeeping in ``ati._packed``, the ``SimClock``'s cell), the
segment's buffers and rings (the kernel's own), the recorder's and the session tap's rows and
counts, the latches, ``Graph._idx``/``_cycles`` and the timing rings (untimed: 0, as
``Graph.timed = False`` writes), ``Loop._cycles``/``_t``/``_dt``, and the Python counters the
fast path keeps (``n_reads``, ``buffer_filled``, the controller's ``_dt``, the segment's
``others_ns``/``_aux``). ``tests/test_preflight_paths.py`` holds the driver's pre-flight to
the per-block one's tap rows and verdict, bit for bit.

Where it does not apply (:meth:`PreflightDriver.why_not`, then every cycle is Python's, as
before): a timed graph, no fused segment, a graph whose slots are not
twin → segment → session tap (→ the twin ankle's truth block and its tap, an ankle setup),
a latch that is not a float64 array, a loop with signals, an interpreted twin.
"""
from __future__ import annotations

from time import thread_time
from typing import Any

import numpy as np
from numba import carray, njit

from rt.components.blocks import SignalTap, tap_row
from rt.components.fused import ALL_HEAD, FusedChain
from rt.components.fused_kernel import (
    A_AUX,
    A_FILLED,
    A_FK,
    A_HYBRID,
    A_IDX,
    A_OTHERS,
    A_PYTHON_OUT,
    A_REC_ROW,
    F_DT,
    F_ESTOP,
    F_FT_T,
    F_HAND,
    F_SIZE,
    F_T,
    N_STAGES,
    T_ARGS,
    T_FARGS,
    T_SIZE,
    _ticks,
    fused_cycle,
)
from rt.components.twin_step import TwinStep
from rt.engine.latches import copy_latches
from rt.epoch import EPOCH
from rt.pointers import f64_at, i64_at
from rt.twin import kernels as tk
from rt.twin.environment import PayloadStep
from rt.twin.twin import _MAX_CHUNK_S, _T_AT, SimClock

#: The plant's rotation and environment state in its block (``TwinPlant.rot``, ``env_state``).
_S_ROT, _S_ENV = tk.B_S + tk.S_ROT, tk.B_S + tk.S_ENV_STATE
_NO_TRUTH = np.zeros(0)
_NO_RING = np.zeros((1, 1))
_NO_I = np.zeros(0, dtype=np.int64)
_NO_LATCHES = np.zeros((0, 3), dtype=np.int64)

#: Why :func:`steady_cycles` returned: every cycle asked for ran; a hand-back before a cycle
#: (nothing of it, or whole twin chunks of it, ran); a hand-back inside a cycle (the twin's
#: period and the segment's kernel ran: Python finishes it from the kernel's answer).
DONE, BACK_BEFORE, BACK_INSIDE = 0, 1, 2
#: ``out`` of :func:`steady_cycles` (int64): cycles completed, why it returned, the kernel's
#: stage reached (inside), filled, whether an FK succeeded, the last others_ns and aux, the
#: graph's ring index after the last completed cycle, the CPU cycle counter's ticks spent in
#: the twin's periods and in the whole call (the twin's share of a pre-flight:
#: ``bench/preflight.py``).
(O_DONE, O_WHY, O_RAN, O_FILLED, O_FK_ANY, O_OTHERS, O_AUX, O_IDX, O_TWIN_TICKS, O_TICKS,
 O_SIZE) = range(11)
#: ``rings`` of :func:`steady_cycles`: the addresses of the twin slot's, the segment's first
#: slot's and the tap slot's timing stores, the graph's cycle store, and (an ankle setup) the
#: twin ankle's truth block's and its tap's stores (int64 each; 0 without).
R_TWIN, R_SEG0, R_TAP, R_CYCLE, R_TRUTH, R_TRUTH_TAP, R_SIZE = range(7)


@njit(cache=True)
def steady_cycles(n, k0, anchor_t, anchor_cycle, period, t0, cell, B, port, codes, ati, draws,
                  n_chunk, rate_hz, tab_addr, plan_mode, cmode, failed, filled, rec_written,
                  rec_cap, tap_ring, tap_written, tap_addr, tap_lens, latches, rings, idx, mask,
                  truth, truth_ring, truth_addr, truth_lens, out):
    """Up to ``n`` steady pre-flight cycles from loop cycle ``k0`` (module docstring): per
    cycle the loop's time (``Loop._run_fast``'s float arithmetic), the twin's fault-free
    period to it in chunks (``Twin._sync_fused``: ``kernels.period_ati``), the segment's
    kernel with the scalars the fast path writes (``fused_cycle``), the session tap's row
    (``tap_row``); with an ankle setup (``truth``: float64[3], else empty) the twin ankle's
    true joint torque (``protocols.session.TwinAnkleTruth.update``: Rᵀ m on the plant's
    rotation and environment state) and its tap's row (``truth_ring``, ``truth_addr``,
    ``truth_lens``; its count is ``tap_written`` too: both taps run every cycle); the
    latches' copies (the graph's table ``latches``: ``rt.engine.latches.copy_latches``), the
    timing stores as an untimed graph writes them. Returns the loop's time of the last cycle
    it touched; ``out`` (``O_*``) says how far it went and why it stopped."""
    tab = carray(i64_at(tab_addr), T_SIZE)
    ia = tab[T_ARGS:T_ARGS + (T_FARGS - T_ARGS)]
    fa = carray(f64_at(tab[T_FARGS]), F_SIZE)
    ring_twin = carray(i64_at(rings[R_TWIN]), mask + 1)
    ring_seg0 = carray(i64_at(rings[R_SEG0]), mask + 1)
    ring_tap = carray(i64_at(rings[R_TAP]), mask + 1)
    ring_cycle = carray(i64_at(rings[R_CYCLE]), mask + 1)
    ankle = truth.shape[0] == 3
    ring_truth = carray(i64_at(rings[R_TRUTH if ankle else R_CYCLE]), mask + 1)
    ring_truth_tap = carray(i64_at(rings[R_TRUTH_TAP if ankle else R_CYCLE]), mask + 1)
    truth_cap = truth_ring.shape[0]
    cap = tap_ring.shape[0]
    t = 0.0
    fk_any = 0
    others = 0
    aux = 0
    why = DONE
    ran = 0
    done = 0
    twin_ticks = 0
    start = _ticks()
    for c in range(n):
        if cmode[0] != plan_mode or failed[0] > 0.5:
            why = BACK_BEFORE                       # the fast path's guard would refuse
            break
        t = anchor_t + (k0 + c - anchor_cycle) * period
        now = t - t0
        cell[0] = now                               # TwinStep: the SimClock, then sync
        left = now - B[_T_AT]
        bits = 0
        tick = _ticks()
        while left > 1e-12:
            chunk = min(_MAX_CHUNK_S, left)
            # ``TwinPlant.substeps``: max(1, round(chunk · rate)), round half to even.
            ns = n_chunk if chunk == _MAX_CHUNK_S else max(1, int(np.rint(chunk * rate_hz)))
            bits = tk.period_ati(B, port, codes, ati, draws, chunk, ns)
            if bits < 0:
                break
            left = now - B[_T_AT]
        twin_ticks += _ticks() - tick
        if bits < 0 or ati[tk.ATI_PENDING] == 0.0:
            why = BACK_BEFORE                       # new random draws, a failed FK: Python's
            break
        ia[A_IDX] = idx
        ia[A_FILLED] = filled
        ia[A_REC_ROW] = rec_written % rec_cap
        fa[F_T] = t
        fa[F_DT] = period
        fa[F_FT_T] = B[_T_AT]
        ran = fused_cycle(tab_addr)
        if ran != N_STAGES or ia[A_PYTHON_OUT] != 0:
            why = BACK_INSIDE
            break
        others = ia[A_OTHERS]
        aux = ia[A_AUX]
        if ia[A_FK] >= 0:
            filled = 1
            fk_any = 1
        rec_written += 1
        # The graph's cycle, untimed (its clock reads 0): the twin's slot 0 − 0, the
        # segment's first slot the call's time minus the other stages', the tap 0.
        ring_twin[idx] = 0
        ring_seg0[idx] = -others
        tap_row(tap_ring, tap_written % cap, t, tap_addr, tap_lens)
        ring_tap[idx] = 0
        if ankle:
            for a in range(3):        # TwinAnkleTruth.update: Rᵀ m, on floats, same order
                truth[a] = (B[_S_ROT + a] * B[_S_ENV + 1] + B[_S_ROT + 3 + a] * B[_S_ENV + 2]
                            + B[_S_ROT + 6 + a] * B[_S_ENV + 3])
            ring_truth[idx] = 0
            tap_row(truth_ring, tap_written % truth_cap, t, truth_addr, truth_lens)
            ring_truth_tap[idx] = 0
        tap_written += 1
        copy_latches(latches)
        ring_cycle[idx] = 0
        idx = (idx + 1) & mask
        done += 1
    out[O_DONE] = done
    out[O_WHY] = why
    out[O_RAN] = ran
    out[O_FILLED] = filled
    out[O_FK_ANY] = fk_any
    out[O_OTHERS] = others
    out[O_AUX] = aux
    out[O_IDX] = idx
    out[O_TWIN_TICKS] = twin_ticks
    out[O_TICKS] = _ticks() - start
    return t


class PreflightDriver:
    """Runs a pre-flight loop (``protocols.session.build_twin_session``'s ``pl`` and session
    ``tap``) through :func:`steady_cycles` where the cycle is steady, and through the loop's
    own cycle (``Loop.run(cycles=1)``) elsewhere; :meth:`run` is ``pl.loop.run(seconds=…)``
    with the same cycles. ``cycles_compiled`` / ``cycles_python`` count who ran them."""

    def __init__(self, pl: Any, tap: SignalTap) -> None:
        self.pl = pl
        self.loop = pl.loop
        self.graph = pl.graph
        self.tap = tap
        self.cycles_compiled = 0
        self.cycles_python = 0
        #: This thread's CPU time in the compiled calls (s), and its share spent in the twin's
        #: periods (s: each call's CPU time × the twin's share of its cycle-counter ticks; the
        #: ticks alone also count the time the process was preempted, on a loaded machine).
        self.compiled_cpu_s = 0.0
        self.twin_cpu_s = 0.0
        self._out = np.zeros(O_SIZE, dtype=np.int64)
        self._static: tuple | None = None
        self._truth: tuple | None = None
        self.why_not = self._check()

    # ------------------------------------------------------------------ applicability
    def _check(self) -> str:
        """"" when the loop's shape allows the driver, else why not (then every cycle is the
        loop's own, as without a driver)."""
        g = self.graph
        seg = g.segment
        if not isinstance(seg, FusedChain):
            return "no fused segment"
        if len(g._pre) != 1 or not isinstance(g._pre[0][1], TwinStep):
            return "the slots before the segment are not the twin's block alone"
        post = [entry[1] for entry in g._post]
        if not post or post[0] is not self.tap or self.tap._signals is None:
            return "the slot after the segment is not the session tap"
        # The twin ankle's truth block is ``protocols.session.TwinAnkleTruth`` (``rt`` does
        # not import ``protocols``: known by its name, its twin and its tap's one signal).
        if len(post) == 3 and type(post[1]).__name__ == "TwinAnkleTruth" \
                and isinstance(post[2], SignalTap) and post[2]._signals is not None \
                and len(post[2]._signals) == 1 \
                and post[2]._signals[0].ctypes.data == post[1].torque.data.ctypes.data \
                and post[1].twin is g._pre[0][1].twin and post[2].capacity == self.tap.capacity:
            # An ankle setup: the twin ankle's truth block and its tap (one row per cycle).
            self._truth = (post[1], post[2])
        elif len(post) != 1:
            return "the slots after the session tap are not the twin ankle's truth and its tap"
        if g._latches and g._latch_table is None:
            return "a delay latch that is not a float64 array"
        if self.loop._signals:
            return "the loop has signals"
        step = g._pre[0][1]
        tw = step.twin
        if not (tw.compiled and type(step.clock) is SimClock and tw.clock is step.clock):
            return "the twin is interpreted or not on its SimClock"
        return ""

    def _steady(self) -> bool:
        """Whether the next cycle may be the driver's: the graph untimed and fused, the
        segment's fast path in force after a whole-segment cycle, the twin's next period
        fault-free on the fused path, no command, nothing requested of the loop."""
        g, loop = self.graph, self.loop
        seg: FusedChain = g.segment
        if g.timed or not g.fused or not g._running or loop._queue._dq \
                or loop._stop_requested:
            return False
        # ``rt.epoch``: nothing changed from outside the cycle since the general cycle that
        # bound the segment's plan (the fast path's own compare, made before each driver run:
        # inside the compiled loop no Python runs that could bump it).
        if not (seg._plan_ok and seg._plan is not None and seg.pending is None
                and seg._next_cycle == g._cycles and seg._gen == g.generation
                and EPOCH.n == seg._plan_epoch):
            return False
        step = g._pre[0][1]
        tw = step.twin
        if step._t0 is None or not step._active or not self.tap._active:
            return False
        if self._truth is not None and not (self._truth[0]._active and self._truth[1]._active
                                            and self._truth[1].written == self.tap.written):
            return False
        return (tw.fused_period and not tw.faults.faults and not tw.ati._faults_possible
                and tw._arrival is None and tw._port_params_of is tw.encoder_port
                and (tw._payload_applied or not isinstance(tw.environment, PayloadStep)))

    # ------------------------------------------------------------------ running
    def run(self, seconds: float) -> int:
        """``Loop.run(seconds=seconds)`` (fast mode): the same cycles at the same times, the
        steady ones compiled. Returns the cycles run."""
        loop = self.loop
        if loop.mode != "fast":
            return loop.run(seconds=seconds)
        loop._prepare_graph()
        anchor_t, anchor_cycle, period = loop._anchor_t, loop._anchor_cycle, loop._period_s
        first = loop._cycles
        # ``Loop._run_fast``'s end: the cycles whose time is within ``seconds`` (half a
        # period of slack), counted with its float arithmetic.
        t_end = anchor_t + (first - anchor_cycle) * period + seconds - 0.5 * period
        last = first
        while anchor_t + (last - anchor_cycle) * period <= t_end:
            last += 1
        while loop._cycles < last:
            if loop._anchor_t != anchor_t or loop._anchor_cycle != anchor_cycle \
                    or loop._period_s != period:
                # A rate command (drained by the loop's own cycle) re-anchored the time base:
                # the end counted again on the new one against the same ``t_end``, as
                # ``Loop._run_fast`` keeps its end and reads the new anchor.
                anchor_t, anchor_cycle, period = (loop._anchor_t, loop._anchor_cycle,
                                                  loop._period_s)
                last = loop._cycles
                while anchor_t + (last - anchor_cycle) * period <= t_end:
                    last += 1
                continue
            if self.why_not or not self._steady():
                loop.run(cycles=1)
                self.cycles_python += 1
                continue
            self._stretch(last - loop._cycles)
        return loop._cycles - first

    def _stretch(self, n: int) -> None:
        """Up to ``n`` cycles in :func:`steady_cycles`, then the Python state those cycles
        leave, then the hand-back's cycle (if any) through the loop."""
        g, loop, tap = self.graph, self.loop, self.tap
        seg: FusedChain = g.segment
        plan = seg._plan
        assert plan is not None
        # The fast path's plan (``FusedChain._make_plan``), and the drive's failed flags.
        (_g, ctl, cmode, hybrid, tw, _ati, port, _mon, _dmon, st, rec, cap, _store,
         _t_at) = plan
        drive_failed = seg._comps[5].failed.data
        step = g._pre[0][1]
        ta, fa = seg._ta, seg._fa
        # The scalars the fast path writes that do not change between steady cycles.
        if hybrid:
            ta[T_ARGS + A_HYBRID] = seg._hybrid_code(ctl)
        inputs = tw.inputs
        fa[F_ESTOP] = 1.0 if inputs.hardware_estop else 0.0
        fa[F_HAND] = 1.0 if inputs.hand_stop else 0.0
        enabled = tw.card_enabled
        card = 0 if enabled[0] else (1 if enabled[1] else -1)
        codes = tw.dac_libs[card].codes3 if card >= 0 else tw._codes
        static = self._static
        if static is None:
            # The graph's own latch table (``rt.engine.latches``; none: no latches).
            latches = g._latch_table if g._latch_table is not None else _NO_LATCHES
            static = self._static = (
                latches,
                np.array([g._stores[g._pre[0][0]].buffer_info()[0],
                          g._stores[g._seg[0][0]].buffer_info()[0],
                          g._stores[g._post[0][0]].buffer_info()[0],
                          g._cycle_store.buffer_info()[0]]
                         + ([g._stores[g._post[1][0]].buffer_info()[0],
                             g._stores[g._post[2][0]].buffer_info()[0]]
                            if self._truth is not None else [0, 0]), dtype=np.int64))
        latches, rings = static
        if self._truth is not None:
            truth_block, truth_tap = self._truth
            truth, truth_ring = truth_block.torque.data, truth_tap.ring
            truth_addr, truth_lens = truth_tap._addr, truth_tap._lens
        else:
            truth, truth_ring, truth_addr, truth_lens = _NO_TRUTH, _NO_RING, _NO_I, _NO_I
        out = self._out
        k0 = loop._cycles
        c0 = thread_time()
        t = steady_cycles(
            n, k0, loop._anchor_t, loop._anchor_cycle, loop._period_s, step._t0,
            tw._clock_cell, tw.plant.B, tw.encoder_port._st, codes, tw.ati._packed,
            tw.ati._state.block, tw._n_chunk, tw.plant.physics_rate_hz, seg._tab_addr,
            seg._plan_mode, cmode, drive_failed, 1 if st._filled else 0, rec.written, cap,
            tap.ring, tap.written, tap._addr, tap._lens, latches, rings,
            g._idx, g._mask, truth, truth_ring, truth_addr, truth_lens, out)
        cpu = thread_time() - c0
        self.compiled_cpu_s += cpu
        if out[O_TICKS] > 0:
            self.twin_cpu_s += cpu * float(out[O_TWIN_TICKS]) / float(out[O_TICKS])
        done = int(out[O_DONE])
        tw._amp_key = None            # the kernel computed amp_volts (``_sync_fused``'s)
        if done:
            period = loop._period_s
            # What the fast path's steady branch and the graph's cycle leave, per cycle.
            seg.others_ns = int(out[O_OTHERS])
            seg._aux = int(out[O_AUX])
            seg.pending = None
            port.n_reads += 9 * done          # the emulated card's count of inb
            if out[O_FK_ANY]:
                st.buffer_filled()
            ctl._dt = period
            rec.written += done
            tap.written += done
            if self._truth is not None:
                self._truth[1].written += done
            g._idx = int(out[O_IDX])
            g._cycles += done
            seg._next_cycle = g._cycles
            loop._cycles = k0 + done
            loop._t = loop._t_current = t
            loop._dt = period
            self.cycles_compiled += done
        why = int(out[O_WHY])
        if why == BACK_INSIDE:
            self._finish_inside(int(out[O_RAN]))
        elif why == BACK_BEFORE:
            loop.run(cycles=1)
            self.cycles_python += 1

    def _finish_inside(self, ran: int) -> None:
        """The cycle whose kernel stopped at ``ran`` (or asked for Python): the loop's own
        cycle, whose twin block finds the twin already there (``Twin.sync``: nothing to
        integrate) and whose segment answers what its fast path answers after that kernel
        call (``FusedChain._finish``), instead of calling the kernel again."""
        g = self.graph
        seg: FusedChain = g.segment

        def answered(t: float, dt: float, idx: int) -> int:
            del seg.run                           # one cycle only
            seg._next_cycle = g._cycles + 1
            return seg._finish(ran, t, dt, ALL_HEAD, 0, False)

        seg.run = answered                        # type: ignore[method-assign]
        try:
            self.loop.run(cycles=1)
        finally:
            seg.__dict__.pop("run", None)
        self.cycles_python += 1

