"""The standard chain's five middle blocks as ONE compiled call per cycle (issue 16).

Estimator → model → reference → controller → supervisor: each block's cycle is already one
numba kernel on its port buffers, but a block still costs its ``update``'s Python and a numba
dispatch (with caches cold between 1 kHz cycles, several times its arithmetic: ref4's
``bench/fused_cycle.py``). :class:`FusedChain` binds those blocks' own buffers once and runs
the five **existing** kernels (``rt.estimation.compiled.block_update``,
``rt.model.kernels.model_state``, ``rt.references.sequencer_kernel.cycle``, the law's kernel
in ``rt.control.kernels``, ``rt.safety.supervisor_kernel.block_cycle``) from one kernel,
reading the CPU's cycle counter between stages, so the graph's per-slot timing rings keep
their meaning (:meth:`rt.engine.graph.Graph.fuse`). No arithmetic is copied here: the
kernels are called with the arguments the blocks pass, on the same buffers, so a fused cycle
is the per-block cycle bit for bit (``tests/test_fused_cycle.py`` replays sessions through
both).

Whatever needs Python stops the kernel exactly where the blocks would run Python:

* before the reference stage when a program is requested or aborted (the sequencer's event);
* after the estimator when its status faults the block (the graph records the fault);
* after the reference when it answers ``PLAY_DONE`` (the return is planned in Python:
  :meth:`ProgramReference.play_done`); ``NEED_PYTHON`` writes nothing, and the reference
  block then runs its own cycle;
* before the controller when the supervisor's mode changed (the block may reset its law), a
  bumpless offset fades (the law has no bound cycle), or the hybrid controller is in force
  mode or switches to it this cycle (the force law and its mode switch are Python);
* after the controller when PD+G0's FK at the desired position fails (it raises, as the
  block does);
* after the supervisor when something new tripped or a request, a heartbeat or a failed
  block is pending (:meth:`Supervisor.finish_block`).

The blocks after the stop run their ``update`` in the same cycle. A swap, a non-standard
block, a block not compiled or not active, or a law without a kernel here runs the whole
chain per block. ``TALUS_FUSED_CYCLE=0`` in the environment (read when a loop is assembled)
or ``Graph.fused = False`` turns fusion off: the per-block path is the reference.
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, typeof, types
from numba.core import cgutils
from numba.extending import intrinsic

from rt.components.blocks import STATUS_SENSOR, ControllerBlock, ModelState, VelocityEstimation
from rt.components.protocol_blocks import HybridController
from rt.components.safety_blocks import SupervisorBlock
from rt.control import kernels as ck
from rt.control.adaptive import Adaptive
from rt.control.base import Controller
from rt.control.laws import (
    ComputedTorquePtp,
    ComputedTorqueTrajectory,
    PadenPanja,
    PdG,
    PdG0,
    Pid,
)
from rt.estimation.compiled import CompiledKalmanEstimator, block_update
from rt.model.kernels import model_state
from rt.model.kinematics import FK_MAX_ITERATIONS, FK_STEP_TOL_RAD
from rt.references import sequencer_kernel as rk
from rt.references.sequencer import ProgramReference
from rt.safety import supervisor_kernel as svk

#: The environment variable that turns the fused cycle off ("0") when a loop is assembled.
ENV_FLAG = "TALUS_FUSED_CYCLE"

#: The chain's slots, in the graph's order.
CHAIN = ("estimator", "model", "reference", "controller", "supervisor")
N_STAGES = len(CHAIN)

# ``info`` (int64) the kernel fills: stages it ran, whether the last one needs Python, the
# estimator's status, FK's status, the reference's answer, the law's status, the supervisor's.
I_RAN, I_PYTHON, I_EST, I_FK, I_REF, I_LAW, I_SUP, INFO_SIZE = 0, 1, 2, 3, 4, 5, 6, 7
_EST_JUMP = -3          # EstimatorStatus.JUMP: published, the supervisor's business


def enabled_by_environment() -> bool:
    """False when ``TALUS_FUSED_CYCLE=0`` (or ``false``/``off``/``no``) is set."""
    return os.environ.get(ENV_FLAG, "1").strip().lower() not in ("0", "false", "off", "no")


@intrinsic
def _ticks(typingctx):  # type: ignore[no-untyped-def]
    """The CPU's cycle counter (x86: rdtsc) read inside a kernel: a stage's time costs no
    clock call (``perf_counter_ns`` costs ≈ 0.3 µs on this VM)."""
    sig = types.int64()

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        fnty = ir.FunctionType(ir.IntType(64), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.readcyclecounter")
        return builder.call(fn, [])
    return sig, codegen


@njit(cache=True)
def ticks_now() -> int:
    return _ticks()


# ---- the laws: ``L`` one tuple of the same types whatever the law (unused fields hold
# placeholders), so one kernel serves every law and is cached on disk like every kernel of
# the loop; each law's kernel is called exactly as its bound cycle calls it (``_bound_kernel``).
LAW_PADEN_PANJA, LAW_COMPUTED_TORQUE, LAW_PD_GRAVITY, LAW_PD_G0, LAW_PID, LAW_ADAPTIVE = range(6)
(L_ID, L_TI, L_TF, L_STB, L_Q, L_QD, L_QDD, L_GAINS, L_WORK, L_OUT, L_TRAJECTORY, L_INTEGRAL,
 L_AMAP, L_EST, L_NB, L_GEOM, L_LIMITS, L_PHI, L_GQ, L_G, L_STD, L_ZERO3, L_MWORK) = range(23)


@njit(cache=True)
def _law(dt, L):
    """The law's kernel (``L[L_ID]``); returns its status (< 0: PD+G0's FK refused)."""
    law = L[0]
    if law == LAW_PADEN_PANJA:
        ck.paden_panja(L[1], L[2], L[3], L[4], L[5], L[6], L[7], L[8], L[9])
    elif law == LAW_COMPUTED_TORQUE:
        ck.computed_torque(L[1], L[2], L[3], L[4], L[5], L[6], L[7], L[10], L[8], L[9])
    elif law == LAW_PD_GRAVITY:
        ck.pd_gravity(L[1], L[2], L[3], L[4], L[5], L[7], L[8], L[9])
    elif law == LAW_PD_G0:
        return ck.pd_gravity_desired(L[1], L[2], L[15], L[16], L[17], L[3], L[4], L[5], L[7],
                                     L[18], L[19], L[20], L[21], FK_STEP_TOL_RAD,
                                     FK_MAX_ITERATIONS, L[22], L[8], L[9])
    elif law == LAW_PID:
        ck.pid(L[3], L[4], L[5], L[7], L[11], dt, False, L[9])
    elif law == LAW_ADAPTIVE:
        ck.adaptive(L[1], L[2], L[3], L[4], L[5], L[6], L[7], L[12], L[13], L[14], dt, False,
                    L[8], L[9])
    return 0


@njit(cache=True)
def fused_chain(stamps, info, t, dt, upto, filled, volts_per_n, hybrid, E, M, fk_out, R,
                ctrl_mode, L, S):
    """The five stages (module docstring) up to stage ``upto`` (exclusive), stopping where
    Python must run; ``stamps`` the cycle counter before the first and after each stage."""
    info[I_RAN] = 0
    info[I_PYTHON] = 0
    stamps[0] = _ticks()
    status = block_update(E[0], E[1], E[2], dt, E[3], E[4])
    stamps[1] = _ticks()
    info[I_RAN] = 1
    info[I_EST] = status
    if status < 0 and status != _EST_JUMP:
        info[I_PYTHON] = 1                  # the block returns STATUS_SENSOR: a fault
        return
    fk = model_state(M[0], M[1], M[2], M[3], M[4], M[5], M[6], M[7], M[8])
    fk_out[0] = 1.0 if fk >= 0 else 0.0
    stamps[2] = _ticks()
    info[I_RAN] = 2
    info[I_FK] = fk
    if upto <= 2:
        return
    r = rk.cycle(R[0], R[1], R[2], R[3], R[4], dt)
    info[I_REF] = r
    if r == rk.NEED_PYTHON:                 # nothing written: the block runs its cycle
        return
    stamps[3] = _ticks()
    info[I_RAN] = 3
    if r == rk.PLAY_DONE:                   # the return is planned in Python
        info[I_PYTHON] = 1
        return
    # The hybrid controller's position mode only (its force law and switches are Python).
    if upto <= 3 or (hybrid and (ctrl_mode[0] > 0.5)):
        return
    ls = _law(dt, L)
    stamps[4] = _ticks()
    info[I_RAN] = 4
    info[I_LAW] = ls
    if ls < 0:
        info[I_PYTHON] = 1                  # PD+G0's refused FK raises in Python
        return
    if upto <= 4:
        return
    new = svk.block_cycle(S[0], S[1], t, dt, S[2], S[3], S[4], S[5], S[6], S[7],
                          filled or fk >= 0, S[8], S[9], S[10], S[11], S[12], S[13], S[14],
                          volts_per_n, S[15], S[16], S[17])
    stamps[5] = _ticks()
    info[I_RAN] = 5
    info[I_SUP] = new


LawArgs = Callable[[], tuple]
_NO_F = np.zeros(1)
_NO_I = np.zeros(1, dtype=np.int64)


def law_binding(law: Controller, st: Any, ref: Any, out: np.ndarray
                ) -> LawArgs | None:
    """A function giving ``L`` for ``law`` now (arrays a reset or new gains replace are read
    through the law at each call, as its bound cycle reads them), or None: only these exact
    classes (a subclass may change the law)."""
    cls = type(law)
    d = getattr(law, "dyn", None)
    if d is None:
        return None
    kin = d.kin
    ti, tf, stb, q, qd, qdd, out_ = d.tree_i, d.tree_f, st.buf, ref.q, ref.qd, ref.qdd, out
    geom, limits, phi = kin.geom, kin.limits_array, kin._phi_guess
    std = np.zeros_like(stb)

    def pack(law_id: int, gains: np.ndarray, work: np.ndarray, trajectory: bool = False,
             integral: np.ndarray = _NO_F, amap: np.ndarray = _NO_I, est: np.ndarray = _NO_F,
             nb: int = 0, gq: np.ndarray = _NO_F, g: np.ndarray = _NO_F,
             std_: np.ndarray = std, zero3: np.ndarray = _NO_F, mwork: np.ndarray = _NO_F
             ) -> tuple:
        return (law_id, ti, tf, stb, q, qd, qdd, gains, work, out_, trajectory, integral, amap,
                est, nb, geom, limits, phi, gq, g, std_, zero3, mwork)

    if cls is PadenPanja:
        a = pack(LAW_PADEN_PANJA, law._gain_array, law._work)
        return lambda: a
    if cls is ComputedTorqueTrajectory or cls is ComputedTorquePtp:
        b = pack(LAW_COMPUTED_TORQUE, law._gain_array, law._work,
                 cls is ComputedTorqueTrajectory)
        return lambda: b
    if cls is PdG:
        c = pack(LAW_PD_GRAVITY, law._gain_array, law._work)
        return lambda: c
    if cls is PdG0:
        g0 = law
        return lambda: pack(LAW_PD_G0, g0._gain_array, g0._work, gq=g0._gq, g=g0._g,
                            std_=g0._std.buf, zero3=g0._zero3, mwork=g0._mwork)
    if cls is Pid:
        pid = law
        return lambda: pack(LAW_PID, pid._gain_array, law._work, integral=pid.integral)
    if cls is Adaptive:
        ad = law
        return lambda: pack(LAW_ADAPTIVE, ad._gain_array, ad._work, amap=ad._amap,
                            est=ad._est, nb=ad._nb)
    return None


_NS_PER_TICK: float | None = None


def ns_per_tick() -> float:
    """The cycle counter's period (ns), measured once per process against the monotonic
    clock over 20 ms; 0 when the counter does not advance (no fusion then)."""
    global _NS_PER_TICK
    if _NS_PER_TICK is None:
        c0, n0 = ticks_now(), time.perf_counter_ns()
        time.sleep(0.02)
        c1, n1 = ticks_now(), time.perf_counter_ns()
        _NS_PER_TICK = (n1 - n0) / (c1 - c0) if c1 > c0 else 0.0
    return _NS_PER_TICK


def _scratch(x: Any) -> Any:
    """A copy of ``x`` of the same numba type (arrays keep their read-only flag)."""
    if isinstance(x, tuple):
        return tuple(_scratch(v) for v in x)
    if isinstance(x, np.ndarray):
        c = x.copy()
        c.flags.writeable = x.flags.writeable
        return c
    return x


class FusedChain:
    """The graph's fused segment over :data:`CHAIN` (:meth:`rt.engine.graph.Graph.fuse`).

    :meth:`run` is called by the graph in place of the five ``update`` calls; it returns how
    many of them it ran (0: none, the graph runs every block), with each one's time (ns) in
    ``ns`` and, in ``pending``, the Python that completes the last one (the graph times it
    and turns its exception or status into the slot's fault, as for an ``update``)."""

    slots = CHAIN

    def __init__(self) -> None:
        self.ns = [0] * N_STAGES
        self.pending: Callable[[float, float], int] | None = None
        self._graph: Any = None
        self._gen = -1
        self._ok = False
        self._tick_ns = 0.0
        self._stamps = np.zeros(N_STAGES + 1, dtype=np.int64)
        self._info = np.zeros(INFO_SIZE, dtype=np.int64)
        self._warm: set = set()
        #: Why the chain runs per block (the last binding's reason), "" when fused.
        self.why_not = "not bound yet"

    def attach(self, graph: Any) -> None:
        self._graph = graph
        self._gen = -1

    # ------------------------------------------------------------------ binding
    def _bind(self) -> None:
        """Check the chain and bind its buffers (at a lifecycle change of the graph, never in
        a steady cycle)."""
        g = self._graph
        self._gen = g.generation
        self._ok = False
        self.why_not = self._check_and_bind(g)
        self._ok = not self.why_not

    def _check_and_bind(self, g: Any) -> str:
        comps = [g.component(s) for s in CHAIN]
        est, mod, ref, ctl, sup = comps
        if type(est) is not VelocityEstimation or not isinstance(est.state,
                                                                 CompiledKalmanEstimator):
            return "estimator: not the compiled VelocityEstimation"
        if type(mod) is not ModelState or not mod.compiled:
            return "model: not the compiled ModelState"
        if type(ref) is not ProgramReference or not ref.compiled:
            return "reference: not the compiled ProgramReference"
        if type(sup) is not SupervisorBlock or not sup.sup.compiled:
            return "supervisor: not the compiled SupervisorBlock"
        if type(ctl) is ControllerBlock:
            law, hybrid = ctl.controller, False
        elif type(ctl) is HybridController:
            law, hybrid = ctl.position, True
        else:
            return f"controller: {type(ctl).__name__} has no fused path"
        binding = law_binding(law, ctl.state_in.data, ctl._ref, ctl.tau.data)
        if binding is None:
            return f"controller: law {type(law).__name__} has no fused path"
        if not self._tick_ns:
            self._tick_ns = ns_per_tick()
        if not self._tick_ns:
            return "the CPU cycle counter does not advance here"
        self._comps = comps
        self._est_state = est.state
        self._law = law
        self._hybrid = hybrid
        self._law_args = binding
        self._law_cycle = law.cycle
        e = est.state
        self._E = (e._c, e._s, est.q_meas.data, e._out, est._io)
        kin = mod.model.kin
        st = mod.state_out.data
        self._state = st
        self._M = (kin.geom, kin.limits_array, kin._phi_guess, mod.q_meas.data, mod.qd.data,
                   st.buf, FK_STEP_TOL_RAD, FK_MAX_ITERATIONS, mod._work)
        self._fk = mod.fk_ok.data
        self._table = ref._table
        self._R = (ref._io, ref._seq, ref.q_meas.data, ref.mode.data, ref._table)
        self._ctrl_mode = ctl.ctrl_mode.data if hybrid else np.zeros(1)
        s = sup.sup
        self._S = (s._par, s._mem, sup.q.data, sup.est_status.data, sup.qd.data, sup.qdd.data,
                   sup.state_in.data.buf, sup.fk_ok.data, sup.q_ref.data, sup.qd_ref.data,
                   sup.tau.data, sup.wrench.data, sup.wrench_flags.data, sup.stops.data,
                   sup.drive_failed.data, sup.volts.data, sup.enable.data, sup.mode.data)
        self._sup = s
        self._vpn = float(sup.k)
        return self._warm_up()

    def prepare(self) -> None:
        """Bind now (the graph starts: off the cycle, so a kernel compiles or loads here)."""
        self._bind()

    def prepare_swap(self, slot: str, new: Any) -> None:
        """A block is being prepared for ``slot`` off the cycle (``Graph.prepare_swap``): warm
        the fused kernel of its law now, so the binding at the swap's cycle compiles nothing."""
        if slot != CHAIN[3] or not self._ok:
            return
        if type(new) is ControllerBlock:
            law = new.controller
        elif type(new) is HybridController:
            law = new.position
        else:
            return
        ref = SimpleNamespace(q=new.q_ref.data, qd=new.qd_ref.data, qdd=new.qdd_ref.data)
        binding = law_binding(law, new.state_in.data, ref, new.tau.data)
        if binding is None:
            return
        law_args = self._law_args
        try:
            self._law_args = binding
            self._warm_up()
        finally:
            self._law_args = law_args

    def _args(self, upto: int, t: float, dt: float, filled: bool, L: tuple) -> tuple:
        return (self._stamps, self._info, t, dt, upto, filled, self._vpn, self._hybrid,
                self._E, self._M, self._fk, self._R, self._ctrl_mode, L, self._S)

    def _warm_up(self) -> str:
        """Compile (or load from numba's cache) the kernel for these buffers' types, on
        copies (nothing of the loop changes), for writable and read-only tables (a prepared
        session's arrive read-only through shared memory); never in a cycle."""
        args = self._args(N_STAGES, 0.0, 1e-3, False, self._law_args())
        key = (tuple(str(typeof(a)) for a in args[8:]))
        if key in self._warm:
            return ""
        scratch = _scratch(args)
        if [str(typeof(a)) for a in scratch] != [str(typeof(a)) for a in args]:
            return "the buffers' types cannot be reproduced for the warm-up"
        for ro in (False, True):
            r = list(scratch[11])
            table = np.zeros((1, 9))
            table.flags.writeable = not ro
            r[4] = table
            a = list(scratch)
            a[11] = tuple(r)
            try:
                fused_chain(*a)
            except Exception as exc:  # noqa: BLE001 - refused: the chain runs per block
                return f"the fused kernel failed its warm-up: {type(exc).__name__}: {exc}"
        self._warm.add(key)
        return ""

    # ------------------------------------------------------------------ the cycle
    def run(self, t: float, dt: float) -> int:
        """One cycle of the chain, as far as the kernel may go (module docstring); returns
        the number of stages run (0: run the five blocks)."""
        if self._gen != self._graph.generation:
            self._bind()
        if not self._ok:
            return 0
        est, mod, ref, ctl, sup = self._comps
        if not (est._active and mod._active and ref._active and ctl._active and sup._active):
            return 0
        if est.state is not self._est_state:
            self._gen = -1            # rebuilt outside the graph's lifecycle: bind again
            return 0
        law = self._law
        upto = N_STAGES
        if ref._pending is not None or ref._abort:
            upto = 2                  # the sequencer's event: its cycle is Python's
        else:
            if ref._table is not self._table:
                r = self._R
                self._table = ref._table
                self._R = (r[0], r[1], r[2], r[3], ref._table)
            raw = ctl.mode.data[0]
            cyc = law.cycle
            if cyc is None or raw != (ctl._sup_raw if self._hybrid else ctl._mode_raw) or (
                    self._hybrid and ctl._in_force):
                upto = 3              # the controller block runs (mode change, fade, force)
            elif cyc is not self._law_cycle:
                self._law_cycle = cyc
        st = self._state
        info = self._info
        fused_chain(self._stamps, info, t, dt, upto, st.filled, self._vpn, self._hybrid,
                     self._E, self._M, self._fk, self._R, self._ctrl_mode, self._law_args(),
                     self._S)
        ran = int(info[I_RAN])
        if ran >= 2 and info[I_FK] >= 0:
            st.buffer_filled()
        if ran >= 4:
            ctl._dt = dt              # what the block's update records (for a handover)
        pending: Callable[[float, float], int] | None = None
        if info[I_PYTHON]:
            if ran == 1:
                pending = _sensor_fault
            elif ran == 3:
                pending = self._play_done
            elif ran == 4:
                q_d = self._comps[3]._ref.q
                status = int(info[I_LAW])

                def pending(t: float, dt: float) -> int:
                    PdG0.refuse_desired(q_d, status)
                    return 0
        elif ran == 5 and (info[I_SUP] or self._sup.python_side_pending(
                self._graph.failed_components())):
            pending = self._finish_supervisor
        self.pending = pending
        stamps = self._stamps
        k = self._tick_ns
        ns = self.ns
        for j in range(1, ran):
            ns[j] = int((stamps[j + 1] - stamps[j]) * k)
        return ran

    def _play_done(self, t: float, dt: float) -> int:
        return self._comps[2].play_done()

    def _finish_supervisor(self, t: float, dt: float) -> int:
        sup = self._comps[4]
        self._sup.finish_block(t, int(self._info[I_SUP]), sup.tau.data, sup.k, sup.volts.data,
                               sup.enable.data, sup.mode.data)
        return 0


def _sensor_fault(t: float, dt: float) -> int:
    return STATUS_SENSOR


def attach(graph: Any, enabled: bool | None = None) -> FusedChain | None:
    """Give ``graph`` the fused chain when its slots hold the standard chain's names in order
    (the blocks themselves are checked at each binding); ``enabled`` None: the environment's
    :data:`ENV_FLAG`. Returns the chain (None when the slots are not there)."""
    order = list(graph.order)
    if CHAIN[0] not in order:
        return None
    i = order.index(CHAIN[0])
    if tuple(order[i:i + N_STAGES]) != CHAIN:
        return None
    chain = FusedChain()
    graph.fuse(chain, enabled_by_environment() if enabled is None else enabled)
    return chain
