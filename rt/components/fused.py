"""The standard chain's blocks as ONE compiled call per cycle (issue 16).

Estimator → model → reference → controller → supervisor: each block's cycle is already one
numba kernel on its port buffers, but a block still costs its ``update``'s Python and a numba
dispatch (with caches cold between 1 kHz cycles, several times its arithmetic: ref4's
``bench/fused_cycle.py``). :class:`FusedChain` binds those blocks' own buffers once and runs
the five **existing** kernels (:func:`rt.components.fused_kernel.fused_chain`:
``rt.estimation.compiled.block_update``, ``rt.model.kernels.model_state``, ``rt.references.sequencer_kernel.cycle``, the law's kernel
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

The device blocks around the chain join the segment when the graph has them there
(``encoders, force, stops`` before it, ``drive, recorder`` after it; :data:`HEAD`,
:data:`TAIL`), each decided **per cycle by its backend**: memory the twin fills is read by the
kernel (the emulated PCL-833's block read and the driver's decode, the ATI sample the twin's
fused period left with the polled sensor's staleness and the force reader's tare, the stop
levels, the redundant drive's monitor check and write on the compiled comedilib double, the
recorder tap's row); a backend that calls a driver (``/dev/port``, comedi through ctypes, the
ATI's receiver, shared memory) or the twin under a fault keeps its block — a sensor's block
runs just before the call (``Graph.run_blocks``), the drive's and the recorder's after it.
A confirmed failed DAC channel, a refused or failed write, a logging double (the block's
:meth:`RedundantDrive.after_compiled_write`), a tare that ended, a port the card refuses stop
the kernel there and Python finishes the block, as for the middle stages. The segment's first
slot's ring holds the call's whole Python (the checks and the dispatch) besides its stage.
``TALUS_FUSED_DEVICES=0`` keeps the device blocks' ``update`` (the middle chain fused).

The call takes one integer (``fused_kernel.fused_cycle``: the scalars live in the table, written
item by item into ``array`` stores). A steady cycle on the in-process twin (the last one ran the
whole segment in the kernel) takes a fast path (:meth:`FusedChain.run`): a per-binding plan
whose guard is one integer compare (``rt.epoch``: every event that can change from outside the
cycle what the general path decided from bumps it) plus the graph's cycle count and the mode
input, one twin sync, the few scalars that change; anything else takes the general path, which
decides as before (devstage7b: the segment's Python ≈ 37-55 µs loaded → ≈ 10 µs quiet; guard8:
the guard's ≈ 50 attribute reads became the epoch compare).

The blocks after the stop run their ``update`` in the same cycle. A non-standard block, a
block not compiled or not active, or a law without a kernel here runs the whole chain per
block; a swap rebinds the chain to the new block at its cycle (its fade runs the controller
block, as above). ``TALUS_FUSED_CYCLE=0`` in the environment (read when a loop is assembled)
or ``Graph.fused = False`` turns fusion off: the per-block path is the reference.
"""
from __future__ import annotations

import os
import time
from array import array
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from rt.ati.twin_sensor import _A_PENDING as _ATI_PENDING
from rt.components.blocks import (
    STATUS_SENSOR,
    ControllerBlock,
    EncoderReader,
    ModelState,
    RecorderTap,
    SignalTap,
    VelocityEstimation,
)
from rt.components.fused_kernel import (
    _INT_BUFFERS,
    _MATRIX_BUFFERS,
    _U32_BUFFERS,
    A_AUX,
    A_FILLED,
    A_FIRST,
    A_FK,
    A_HAS_MEASURED,
    A_HEAD,
    A_HYBRID,
    A_IDX,
    A_LAW,
    A_NB,
    A_OTHERS,
    A_OWNER,
    A_PYTHON_OUT,
    A_REC_ROW,
    A_TRAJECTORY,
    A_UPTO,
    B_AMAP,
    B_ATI_W,
    B_CTRL_MODE,
    B_DAC,
    B_DENABLE,
    B_DFAILED,
    B_DFAKE,
    B_DMON,
    B_DSAMPLES,
    B_DST,
    B_DVOLTS,
    B_ENABLE,
    B_ENC_Q,
    B_EST,
    B_EST_C,
    B_EST_IO,
    B_EST_OUT,
    B_EST_Q,
    B_EST_S,
    B_FG,
    B_FK,
    B_FREF,
    B_FS,
    B_FT_FLAGS,
    B_FT_RAW,
    B_FT_REQUEST,
    B_FT_ST,
    B_FT_TARE,
    B_FT_TARE_BUF,
    B_FT_WRENCH,
    B_FTAU,
    B_FTF,
    B_FTI,
    B_FWORK,
    B_G0,
    B_G0_SCRATCH,
    B_GAINS,
    B_GEOM,
    B_HFORCE,
    B_HPOSE,
    B_HPREVIEW,
    B_HS,
    B_HWRENCH,
    B_INPUTS,
    B_INTEGRAL,
    B_LAW_STB,
    B_LGEOM,
    B_LIMITS,
    B_LLIMITS,
    B_LPHI,
    B_LQ,
    B_LQD,
    B_LQDD,
    B_MEM,
    B_MOD_Q,
    B_MOD_QD,
    B_MOD_WORK,
    B_MODE,
    B_OUT,
    B_PAR,
    B_PCL_DEC,
    B_PCL_IO,
    B_PCL_PORTS,
    B_PCL_ST,
    B_PHI,
    B_REC_ADDR,
    B_REC_LENS,
    B_REC_RING,
    B_REF_FLAGS,
    B_REF_IO,
    B_REF_MODE,
    B_REF_Q,
    B_REF_TARE,
    B_REF_WRENCH,
    B_SEQ,
    B_SEST,
    B_SFK,
    B_SQ,
    B_SQD,
    B_SQDD,
    B_SQDREF,
    B_SQREF,
    B_SSTB,
    B_STAU,
    B_STB,
    B_STOPS,
    B_TABLE,
    B_TF,
    B_TI,
    B_VOLTS,
    B_WFLAGS,
    B_WORK,
    B_WRENCH,
    F_DT,
    F_ESTOP,
    F_FT_T,
    F_HAND,
    F_NS_PER_TICK,
    F_SIZE,
    F_T,
    F_VPN,
    HEAD_ENCODERS,
    HEAD_FORCE,
    HEAD_STOPS,
    HYBRID_FORCE,
    HYBRID_FORCE_PYTHON,
    HYBRID_POSITION,
    I_DRIVE,
    I_DRIVE_DONE,
    I_DRIVE_RC,
    INFO_SIZE,
    LAW_ADAPTIVE,
    LAW_COMPUTED_TORQUE,
    LAW_PADEN_PANJA,
    LAW_PD_G0,
    LAW_PD_GRAVITY,
    LAW_PID,
    N_BUFFERS,
    N_STAGES,
    NOT_HYBRID,
    ST_CONTROLLER,
    ST_DRIVE,
    ST_ENCODERS,
    ST_ESTIMATOR,
    ST_FORCE,
    ST_MODEL,
    ST_RECORDER,
    ST_REFERENCE,
    ST_STOPS,
    ST_SUPERVISOR,
    T_ADDR,
    T_ARGS,
    T_DIMS,
    T_FARGS,
    T_INFO,
    T_RINGS,
    T_SIZE,
    fused_cycle,
    ticks_now,
)
from rt.components.protocol_blocks import HybridController
from rt.components.safety_blocks import ForceReader, RedundantDrive, StopInputs, SupervisorBlock
from rt.control.adaptive import Adaptive
from rt.control.base import Controller
from rt.control.force import ExplicitForce
from rt.control.laws import (
    ComputedTorquePtp,
    ComputedTorqueTrajectory,
    PadenPanja,
    PdG,
    PdG0,
    Pid,
)
from rt.epoch import EPOCH as _EPOCH
from rt.estimation.compiled import CompiledKalmanEstimator
from rt.references.sequencer import ProgramReference
from rt.safety.events import SupervisorMode

#: The environment variable that turns the fused cycle off ("0") when a loop is assembled.
ENV_FLAG = "TALUS_FUSED_CYCLE"

#: The chain's middle slots, in the graph's order (always fused together).
CHAIN = ("estimator", "model", "reference", "controller", "supervisor")
#: The sensor slots before them that the segment takes when the graph has them there (all
#: three): each fused when its backend is memory this cycle, else its block runs first.
HEAD = ("encoders", "force", "stops")
#: The device slots after them that the segment takes when the graph has them there: the
#: redundant drive and the recorder tap (each fused when its backend is memory, per cycle).
TAIL = ("drive", "recorder")
assert ST_SUPERVISOR - ST_ESTIMATOR + 1 == len(CHAIN) and ST_RECORDER - ST_DRIVE + 1 == len(TAIL)
assert ST_STOPS - ST_ENCODERS + 1 == len(HEAD) == ST_ESTIMATOR
_HEAD_BITS = (HEAD_ENCODERS, HEAD_FORCE, HEAD_STOPS)
ALL_HEAD = HEAD_ENCODERS | HEAD_FORCE | HEAD_STOPS


#: ``TALUS_FUSED_FORCE=0`` (read when a chain binds): the hybrid controller's force mode runs
#: its block even when fused (the state before the force stage; before/after benchmarks).
FORCE_ENV_FLAG = "TALUS_FUSED_FORCE"


#: ``TALUS_FUSED_DEVICES=0`` (read when a loop is assembled): the device blocks (sensors,
#: drive, recorder) keep their ``update`` though the middle chain is fused (the state before
#: the device stages; before/after benchmarks).
DEVICES_ENV_FLAG = "TALUS_FUSED_DEVICES"


def sensors_by_environment() -> bool:
    """False when ``TALUS_FUSED_DEVICES=0`` (or ``false``/``off``/``no``) is set."""
    return os.environ.get(DEVICES_ENV_FLAG, "1").strip().lower() not in ("0", "false", "off",
                                                                         "no")


def enabled_by_environment() -> bool:
    """False when ``TALUS_FUSED_CYCLE=0`` (or ``false``/``off``/``no``) is set."""
    return os.environ.get(ENV_FLAG, "1").strip().lower() not in ("0", "false", "off", "no")


_NO_F = np.zeros(1)
_NO_F0 = np.zeros(0)            # an unbound input port the kernel checks for (empty)
_RUN = float(SupervisorMode.RUN)
_NO_I = np.zeros(1, dtype=np.int64)
_NO_U = np.zeros(1, dtype=np.uint32)
_NO_M = np.zeros((1, 1))
_F64 = np.dtype(np.float64)

#: The methods whose arithmetic the compiled force cycle mirrors: patched (a bench, a test's
#: recorder), the hybrid controller's force mode runs its block.
_MIRRORED = ((HybridController, ("update", "_lead", "_govern", "_beyond")),
             (ExplicitForce, ("update",)))
_ORIGINALS = {(cls, n): cls.__dict__[n] for cls, names in _MIRRORED for n in names}


def _force_unbindable(ctl: HybridController) -> str:
    """"" when the hybrid controller's force mode may run compiled (the exact classes, the
    compiled law, nothing of what the kernel mirrors patched), else why not."""
    if os.environ.get(FORCE_ENV_FLAG, "1").strip().lower() in ("0", "false", "off", "no"):
        return f"{FORCE_ENV_FLAG} is off"
    fl = ctl.force_law
    if type(fl) is not ExplicitForce or not fl.compiled:
        return f"force law {type(fl).__name__} has no compiled force cycle here"
    for obj, (cls, names) in ((ctl, _MIRRORED[0]), (fl, _MIRRORED[1])):
        for n in names:
            if cls.__dict__.get(n) is not _ORIGINALS[(cls, n)] or n in vars(obj):
                return f"{cls.__name__}.{n} is replaced"
    return ""


class LawBinding:
    """What the fused kernel needs of a law: its ``LAW_*`` id and flag, its fixed buffers
    (``B_*`` → array) and ``dynamic()``: the buffers a reset or new gains replace (read
    through the law at each cycle, as its bound cycle reads them) and the adaptive law's
    parameter count."""

    def __init__(self, law_id: int, fixed: dict[int, np.ndarray], trajectory: bool = False,
                 dynamic: Callable[[], tuple[dict[int, np.ndarray], int]] | None = None,
                 watch: Callable[[], object] | None = None):
        self.law_id = law_id
        self.fixed = fixed
        self.trajectory = trajectory
        self.dynamic = dynamic
        #: When those buffers may have been replaced: the law's bound cycle changed (a reset
        #: rebinds it after replacing them) or ``watch()`` changed (the adaptive law's new
        #: gains replace its estimate without rebinding).
        self.watch = watch


def law_binding(law: Controller, st: Any, ref: Any, out: np.ndarray) -> LawBinding | None:
    """``law``'s :class:`LawBinding` on these buffers, or None: only these exact classes (a
    subclass may change the law)."""
    cls = type(law)
    d = getattr(law, "dyn", None)
    if d is None:
        return None
    kin = d.kin
    fixed = {B_TI: d.tree_i, B_TF: d.tree_f, B_LAW_STB: st.buf, B_LQ: ref.q, B_LQD: ref.qd,
             B_LQDD: ref.qdd, B_GAINS: law._gain_array, B_WORK: law._work, B_OUT: out,
             B_INTEGRAL: _NO_F, B_AMAP: _NO_I, B_EST: _NO_F, B_LGEOM: kin.geom,
             B_LLIMITS: kin.limits_array, B_LPHI: kin._phi_guess, B_G0: _NO_F,
             B_G0_SCRATCH: _NO_F}
    if cls is PadenPanja:
        return LawBinding(LAW_PADEN_PANJA, fixed)
    if cls is ComputedTorqueTrajectory or cls is ComputedTorquePtp:
        return LawBinding(LAW_COMPUTED_TORQUE, fixed, cls is ComputedTorqueTrajectory)
    if cls is PdG:
        return LawBinding(LAW_PD_GRAVITY, fixed)
    if cls is PdG0:
        g0 = cast(PdG0, law)
        return LawBinding(LAW_PD_G0, fixed, dynamic=lambda: (
            {B_G0: g0._g0, B_G0_SCRATCH: g0._g0_scratch, B_LPHI: g0.dyn.kin._phi_guess}, 0))
    if cls is Pid:
        pid = cast(Pid, law)
        return LawBinding(LAW_PID, fixed, dynamic=lambda: ({B_INTEGRAL: pid.integral}, 0))
    if cls is Adaptive:
        ad = cast(Adaptive, law)
        return LawBinding(LAW_ADAPTIVE, fixed, dynamic=lambda: (
            {B_AMAP: ad._amap, B_EST: ad._est}, ad._nb), watch=lambda: ad._est)
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


class FusedChain:
    """The graph's fused segment over :data:`CHAIN` (:meth:`rt.engine.graph.Graph.fuse`).

    :meth:`run` is called by the graph in place of the five ``update`` calls; it returns how
    many of them it ran (0: none, the graph runs every block), with each one's time (ns) in
    ``ns`` and, in ``pending``, the Python that completes the last one (the graph times it
    and turns its exception or status into the slot's fault, as for an ``update``)."""

    def __init__(self, slots: tuple[str, ...] = CHAIN) -> None:
        h = len(HEAD) if slots[:len(HEAD)] == HEAD else 0
        mid = slots[h:]
        if mid[:len(CHAIN)] != CHAIN or mid[len(CHAIN):] != TAIL[:len(mid) - len(CHAIN)]:
            raise ValueError(f"a fused chain's slots are (optionally {HEAD}), {CHAIN}, then a "
                             f"start of {TAIL}, not {slots}")
        #: The graph's slots this segment runs (the sensors, the middle chain, the tail).
        self.slots = slots
        #: The segment's first stage and the stage after its last (absolute, ``ST_*``).
        self._first = ST_ENCODERS if h else ST_ESTIMATOR
        self._end = self._first + len(slots)
        self._head: tuple = ()
        self._head_run: list = []
        #: Why each sensor ran its block in the last cycle ("" when fused; ``HEAD`` order).
        self.why_not_sensor = ["not bound yet"] * len(HEAD)
        self.pending: Callable[[float, float], int] | None = None
        self._graph: Any = None
        self._gen = -1
        self._ok = False
        self._tick_ns = 0.0
        # The table in an ``array`` store (its items written from Python at ≈ 30 ns each, a
        # NumPy item costs ≈ 3×) viewed as NumPy for the binding; the call's float scalars in
        # their own store, its address in the table (``fused_kernel.fused_cycle``).
        self._ta = array("q", bytes(8 * T_SIZE))
        self._fa = array("d", bytes(8 * F_SIZE))
        self._tab = tab = np.frombuffer(self._ta, dtype=np.int64)
        tab[T_FARGS] = self._fa.buffer_info()[0]
        self._tab_addr = self._ta.buffer_info()[0]
        #: The steady cycle's plan (:meth:`_make_plan`): what the fast path checks, bound per
        #: binding; ``_plan_ok`` while the last cycle ran the whole segment in the kernel.
        self._plan: tuple | None = None
        self._plan_ok = False
        self._next_cycle = -1
        #: ``rt.epoch.EPOCH.n`` read at the start of the general cycle that made the plan.
        self._plan_epoch = -1
        self._addr = tab[T_ADDR:T_ADDR + N_BUFFERS]
        self._dims = tab[T_DIMS:T_DIMS + 2 * N_BUFFERS].reshape((N_BUFFERS, 2))
        # The graph's rings start at the segment's first stage.
        self._rings = tab[T_RINGS + self._first:T_RINGS + self._end]
        self._info = tab[T_INFO:T_INFO + INFO_SIZE]
        self._drive: RedundantDrive | None = None
        self._rec: SignalTap | None = None
        self._rec_arrays: tuple = ()
        #: Why the drive / the recorder tap run their blocks this cycle ("" when fused).
        self.why_not_drive = self.why_not_recorder = "not bound yet"
        #: The buffer behind each address (kept alive: the kernel writes through them).
        self._bufs: list[np.ndarray] = [_NO_F] * N_BUFFERS
        self._dyn_ids: tuple = ()
        self._law_cycle: object = None
        self._watched: object = None
        self._fref = np.zeros(4)
        #: The hybrid controller's mode its force binding was last checked in (None: never).
        self._seen_in_force: bool | None = None
        self._force_ok = False
        self._ftau: object = None
        #: Why the hybrid controller's force mode runs its block ("" when compiled).
        self.why_not_force = ""
        #: Why the chain runs per block (the last binding's reason), "" when fused.
        self.why_not = "not bound yet"

    def attach(self, graph: Any, rings: list[int]) -> None:
        """Called by ``Graph.fuse``: the graph and its slots' timing rings (addresses of
        int64 stores that live as long as the graph)."""
        self._graph = graph
        self._gen = -1
        self._rings[:] = rings
        self.others_ns = 0
        self._aux = 0

    # ------------------------------------------------------------------ binding
    def prepare(self) -> None:
        """Bind now (the graph starts: off the cycle, so the kernel compiles or loads here)."""
        self._bind()

    def prepare_swap(self, slot: str, new: Any) -> None:
        """Nothing to compile for a new law (one kernel serves every law); kept for the
        graph's protocol."""

    def _bind(self) -> None:
        """Check the chain and bind its buffers (at a lifecycle change of the graph, or when a
        buffer was replaced outside it; never in a steady cycle)."""
        g = self._graph
        self._gen = g.generation
        self._ok = False
        self._plan = None
        self._plan_ok = False
        try:
            self.why_not = self._check_and_bind(g)
            if not self.why_not:
                self._plan = self._make_plan()
        except Exception as exc:  # noqa: BLE001 - an unexpected block state: run per block
            self.why_not = f"binding failed: {type(exc).__name__}: {exc}"
        self._ok = not self.why_not

    def _set(self, k: int, buf: np.ndarray) -> str:
        """Buffer ``k`` of the table; "" or why it cannot be (not C-contiguous float64 or
        int64 of the rank the kernel views it as)."""
        want = (np.int64 if k in _INT_BUFFERS else np.uint32 if k in _U32_BUFFERS
                else np.float64)
        ndim = 2 if k in _MATRIX_BUFFERS else 1
        if (not isinstance(buf, np.ndarray) or buf.dtype != want or buf.ndim != ndim
                or not buf.flags.c_contiguous):
            return f"buffer {k} is not a contiguous {want.__name__}[{ndim}-D] array"
        self._bufs[k] = buf
        self._addr[k] = buf.__array_interface__["data"][0]
        self._dims[k, 0] = buf.shape[0]
        self._dims[k, 1] = buf.shape[1] if ndim == 2 else 0
        return ""

    def _check_and_bind(self, g: Any) -> str:
        comps = [g.component(s) for s in self.slots]
        head = comps[:ST_ESTIMATOR - self._first]
        comps = comps[len(head):]
        est, mod, ref, ctl, sup = comps[:len(CHAIN)]
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
        e = est.state
        kin = mod.model.kin
        st = mod.state_out.data
        s = sup.sup
        bufs = {B_EST_C: e._c, B_EST_S: e._s, B_EST_Q: est.q_meas.data, B_EST_OUT: e._out,
                B_EST_IO: est._io,
                B_GEOM: kin.geom, B_LIMITS: kin.limits_array, B_PHI: kin._phi_guess,
                B_MOD_Q: mod.q_meas.data, B_MOD_QD: mod.qd.data, B_STB: st.buf,
                B_MOD_WORK: mod._work, B_FK: mod.fk_ok.data,
                B_REF_IO: ref._io, B_SEQ: ref._seq, B_REF_Q: ref.q_meas.data,
                B_REF_MODE: ref.mode.data, B_TABLE: ref._table,
                B_REF_WRENCH: ref.wrench.data if ref.wrench.data is not None else _NO_F0,
                B_REF_FLAGS: ref._flags(), B_REF_TARE: ref._tare_port(),
                B_CTRL_MODE: ctl.ctrl_mode.data if hybrid else _NO_F,
                **binding.fixed,
                B_PAR: s._par, B_MEM: s._mem, B_SQ: sup.q.data, B_SEST: sup.est_status.data,
                B_SQD: sup.qd.data, B_SQDD: sup.qdd.data, B_SSTB: sup.state_in.data.buf,
                B_SFK: sup.fk_ok.data, B_SQREF: sup.q_ref.data, B_SQDREF: sup.qd_ref.data,
                B_STAU: sup.tau.data, B_WRENCH: sup.wrench.data,
                B_WFLAGS: sup.wrench_flags.data, B_INPUTS: sup.stops.data,
                B_DFAILED: sup.drive_failed.data, B_VOLTS: sup.volts.data,
                B_ENABLE: sup.enable.data, B_MODE: sup.mode.data,
                B_HS: _NO_F, B_HFORCE: _NO_F, B_HPREVIEW: _NO_F, B_HPOSE: _NO_F,
                B_HWRENCH: _NO_F, B_FTI: _NO_I, B_FTF: _NO_F, B_FG: _NO_F, B_FS: _NO_F,
                B_FWORK: _NO_F, B_FTAU: _NO_F, B_FREF: self._fref,
                B_DST: _NO_F, B_DVOLTS: _NO_F, B_DENABLE: _NO_F, B_DMON: _NO_F, B_DAC: _NO_F,
                B_DSAMPLES: _NO_U, B_DFAKE: _NO_I, B_REC_RING: _NO_M, B_REC_ADDR: _NO_I,
                B_REC_LENS: _NO_I, B_PCL_ST: _NO_I, B_PCL_PORTS: _NO_I, B_PCL_IO: _NO_I,
                B_PCL_DEC: _NO_F, B_ENC_Q: _NO_F, B_ATI_W: _NO_F, B_FT_ST: _NO_F,
                B_FT_RAW: _NO_F, B_FT_WRENCH: _NO_F, B_FT_FLAGS: _NO_F, B_FT_REQUEST: _NO_F,
                B_FT_TARE: _NO_F, B_FT_TARE_BUF: _NO_F, B_STOPS: _NO_F}
        self._head = ()
        if head:
            why = _head_unbindable(head)
            if why:
                return why
            enc, force, stops = head
            self._head = (enc, force, stops)
            self._head_run = [[e] for e in g.segment_run()[:len(HEAD)]]
            self._enc_arrays: tuple = ()
            self._ft_arrays: tuple = ()
            bufs.update({B_ENC_Q: enc.q.data, B_FT_RAW: force._raw,
                         B_FT_WRENCH: force.wrench.data, B_FT_FLAGS: force.flags.data,
                         B_FT_REQUEST: force.tare_request.data, B_FT_TARE: force.tare_out.data,
                         B_FT_TARE_BUF: force.tare._buf, B_STOPS: stops.stops.data})
        self._drive = self._rec = None
        self.why_not_drive = self.why_not_recorder = "not in the segment"
        if len(comps) > ST_DRIVE - ST_ESTIMATOR:
            drv = comps[ST_DRIVE - ST_ESTIMATOR]
            self.why_not_drive = _drive_unbindable(drv)
            if not self.why_not_drive:
                self._drive = drv
                bufs.update({B_DST: drv._st, B_DVOLTS: drv.volts.data,
                             B_DENABLE: drv.enable.data, B_DMON: drv.volts.data})
        if len(comps) > ST_RECORDER - ST_ESTIMATOR:
            rec = comps[ST_RECORDER - ST_ESTIMATOR]
            self.why_not_recorder = _recorder_unbindable(rec)
            if not self.why_not_recorder:
                self._rec = rec
                self._rec_arrays = (rec.ring, rec._addr, rec._lens)
                bufs.update({B_REC_RING: rec.ring, B_REC_ADDR: rec._addr,
                             B_REC_LENS: rec._lens})
        if hybrid:
            bufs.update({B_HS: ctl._hs, B_HFORCE: ctl.force.data,
                         B_HPREVIEW: ctl.force_preview.data, B_HPOSE: ctl.pose.data,
                         B_HWRENCH: ctl.wrench.data})
        self._seen_in_force = None
        self._force_ok = False
        if len(bufs) != N_BUFFERS:
            return "internal: the buffer table is incomplete"
        for k, buf in bufs.items():
            why = self._set(k, buf)
            if why:
                return why
        self._comps = comps
        self._all = (*head, *comps)
        self._est_state = e
        self._law = law
        self._hybrid = hybrid
        self._binding = binding
        self._nb = 0
        self._dyn_ids = ()
        why = self._refresh_law()
        if why:
            return why
        self._table = ref._table
        self._state = st
        self._sup = s
        self._mem, self._par = s._mem, s._par
        self._vpn = float(sup.k)
        return self._warm_up()

    def _refresh_law(self) -> str:
        """The law's buffers a reset or new gains replace, when they changed (by identity;
        the replaced ones stay referenced until then, so an id is never reused meanwhile)."""
        dyn = self._binding.dynamic
        if dyn is None:
            return ""
        bufs, nb = dyn()
        ids = tuple(id(b) for b in bufs.values())
        self._nb = nb
        self._law_cycle = self._law.cycle
        self._watched = None if self._binding.watch is None else self._binding.watch()
        if ids != self._dyn_ids:
            for k, buf in bufs.items():
                why = self._set(k, buf)
                if why:
                    return why
            self._dyn_ids = ids
        return ""

    def _bind_force(self, ctl: HybridController) -> str:
        """The explicit-force law's buffers (checked when the block enters force mode, and
        when a reset replaced its ``tau``): "" or why its force mode runs the block."""
        why = _force_unbindable(ctl)
        if why:
            return why
        fl = ctl.force_law
        d = fl.dyn
        for k, buf in ((B_FTI, d.tree_i), (B_FTF, d.tree_f), (B_FG, fl._fg), (B_FS, fl._fs),
                       (B_FWORK, fl._work), (B_FTAU, fl.tau)):
            why = self._set(k, buf)
            if why:
                return why
        self._ftau = fl.tau
        return ""

    def _hybrid_code(self, ctl: HybridController) -> int:
        """``HYBRID_*`` for this cycle (the force binding re-checked at each entry into force
        mode: whatever was patched or replaced meanwhile is seen there)."""
        inf = ctl._in_force
        if not inf:
            self._seen_in_force = False
            return HYBRID_POSITION
        if ctl._sup_raw != _RUN:
            # A stop's cycles are the block's (a stop may hand the force mode over: the
            # interpreted block decides).
            return HYBRID_FORCE_PYTHON
        if self._seen_in_force is not True or (self._force_ok
                                               and ctl.force_law.tau is not self._ftau):
            self._seen_in_force = True
            self.why_not_force = self._bind_force(ctl)
            self._force_ok = not self.why_not_force
        if not self._force_ok:
            return HYBRID_FORCE_PYTHON
        if not ctl._hs_live:
            ctl._push()               # the kernel takes over the block's force-mode state
        return HYBRID_FORCE

    def _warm_up(self) -> str:
        """Compile (or load from numba's cache) the kernel now, never in a cycle: on copies
        of every buffer (nothing of the loop changes). One kernel for every law and block."""
        global _WARM
        if _WARM:
            return ""
        bufs = [b.copy() for b in self._bufs]
        scratch_rings = np.zeros((N_STAGES, 2), dtype=np.int64)
        tab = self._tab.copy()
        tab[T_ADDR:T_ADDR + N_BUFFERS] = [b.__array_interface__["data"][0] for b in bufs]
        tab[T_RINGS:T_RINGS + N_STAGES] = [r.__array_interface__["data"][0]
                                           for r in scratch_rings]
        fa = np.zeros(F_SIZE)
        fa[F_DT], fa[F_VPN], fa[F_NS_PER_TICK] = 1e-3, self._vpn, 1.0
        tab[T_FARGS] = fa.__array_interface__["data"][0]
        args = tab[T_ARGS:T_FARGS]
        args[:] = 0
        args[A_FIRST], args[A_UPTO] = ST_ESTIMATOR, ST_REFERENCE
        args[A_HYBRID], args[A_LAW] = NOT_HYBRID, LAW_PADEN_PANJA
        try:
            fused_cycle(tab.__array_interface__["data"][0])
        except Exception as exc:  # noqa: BLE001 - refused: the chain runs per block
            return f"the fused kernel failed its warm-up: {type(exc).__name__}: {exc}"
        _WARM = True
        return ""

    # ------------------------------------------------------------------ the cycle
    def run(self, t: float, dt: float, idx: int) -> int:
        """One cycle of the chain, as far as the kernel may go (module docstring); returns
        the number of stages run (0: run the blocks). The stages after the first are timed
        into their slots' rings at ``idx`` by the kernel; ``others_ns`` is their sum.

        A steady cycle (the last one ran the whole segment in the kernel, :meth:`_make_plan`
        bound a plan) checks only that nothing changed between two such cycles from outside
        the cycle (a lifecycle change, a fault plan, a closed device, a request, new gains, a
        program: each bumps ``rt.epoch``) by one compare, syncs the twin once, and writes
        the few scalars that change every cycle; anything else takes the general path below,
        which decides as before (and from which the fast path may only be stricter)."""
        ta, fa = self._ta, self._fa
        plan = self._plan if self._plan_ok else None
        if plan is not None:
            (g, ctl, cmode, hybrid, tw, ati, port, mon, dmon, st, rec, cap, store,
             t_at) = plan
            # Stricter than the general path's checks (module docstring): nothing that may
            # change from outside the cycle changed since the general cycle that made the plan
            # checked it all (``rt.epoch``: the blocks' lifecycle, the graph's generation and
            # failed blocks, a law rebound, the sequencer's and the supervisor's requests, a
            # device closed or a method replaced on it, the drive's card, the twin's clock and
            # faults), the graph's previous cycle was this segment's (not per block:
            # ``Graph.fused`` toggled, a fallback), and the controller's mode input is the
            # plan's (written in the cycle: the fade after a mode change is the block's).
            cycles = g._cycles
            if (_EPOCH.n == self._plan_epoch and cycles == self._next_cycle
                    and cmode[0] == self._plan_mode):
                self._next_cycle = cycles + 1
                tw.sync()
                # The ATI's sample (wrench, counter, status) is read by the kernel where the
                # twin's period left it (``ati._packed``); a sample whose object was built
                # meanwhile is the block's, as in ``compiled_sample``. The twin's faults need
                # no check here: no plan is made while one is scheduled (the encoders'
                # ``compiled_read`` is None then, so the general cycle never fuses every
                # sensor) and scheduling one bumps the epoch (``Faults.schedule``;
                # ``tests/test_fused_epoch.py``).
                if ati._packed[_ATI_PENDING] != 0.0 and (mon is None or mon() is dmon):
                    ta[T_ARGS + A_IDX] = idx
                    ta[T_ARGS + A_FILLED] = st._filled
                    ta[T_ARGS + A_REC_ROW] = rec.written % cap
                    if hybrid:
                        ta[T_ARGS + A_HYBRID] = self._hybrid_code(ctl)
                    fa[F_T] = t
                    fa[F_DT] = dt
                    fa[F_FT_T] = store[t_at]     # ``tw.t`` (two properties)
                    inputs = tw.inputs
                    fa[F_ESTOP] = 1.0 if inputs.hardware_estop else 0.0
                    fa[F_HAND] = 1.0 if inputs.hand_stop else 0.0
                    ran = fused_cycle(self._tab_addr)
                    if ran == N_STAGES and not ta[T_ARGS + A_PYTHON_OUT]:
                        # The whole segment ran: ``_finish``'s steady branch.
                        self.others_ns = ta[T_ARGS + A_OTHERS]
                        port.n_reads += 9             # the emulated card's count of inb
                        if ta[T_ARGS + A_FK] >= 0:
                            st.buffer_filled()
                        ctl._dt = dt
                        self._aux = ta[T_ARGS + A_AUX]
                        rec.written += 1              # the tap's row is in
                        self.pending = None
                        return N_STAGES - ST_ENCODERS
                    return self._finish(ran, t, dt, ALL_HEAD, 0, False)
            self._plan_ok = False
        return self._general(t, dt, idx)

    def _general(self, t: float, dt: float, idx: int) -> int:
        """:meth:`run`'s general path: every check, each sensor's backend asked."""
        # The epoch first, then the checks (``rt.epoch``): an event after this read makes the
        # next cycle's compare differ; one before it is seen by the checks below.
        epoch = _EPOCH.n
        self._next_cycle = self._graph._cycles + 1
        if self._gen != self._graph.generation:
            self._bind()
        if not self._ok:
            return 0
        est, mod, ref, ctl, sup = self._comps[:5]
        if not (est._active and mod._active and ref._active and ctl._active and sup._active):
            return 0
        if self._head and not all(c._active for c in self._head):
            return 0                  # a sensor block in error: every block runs
        s = self._sup
        if est.state is not self._est_state or s._mem is not self._mem \
                or s._par is not self._par:
            self._bind()              # rebuilt outside the graph's lifecycle (a reset)
            if not self._ok:
                return 0
        b = self._binding
        cyc = self._law.cycle
        stale = b.dynamic is not None and (cyc is not self._law_cycle or (
            b.watch is not None and b.watch() is not self._watched))
        if stale and self._refresh_law():
            self._gen = -1
            return 0
        g = self._graph
        upto = self._end
        has_measured, owner, rec_row = False, 0, 0
        mode_raw = ctl._sup_raw if self._hybrid else ctl._mode_raw
        if ref._pending is not None or ref._abort:
            upto = ST_REFERENCE       # the sequencer's event: its cycle is Python's
        else:
            if ref._table is not self._table:
                if self._set(B_TABLE, ref._table):
                    upto = ST_REFERENCE   # a table the kernel cannot view: the block plays it
                else:
                    self._table = ref._table
            raw = ctl.mode.data[0]
            if cyc is None or raw != mode_raw:
                upto = min(upto, ST_CONTROLLER)   # the controller block runs (mode change, fade)
        head = 0
        ft_t = estop = hand = 0.0
        py_ns = 0
        if self._head:
            # Each sensor fused when its backend is memory this cycle; the others run their
            # blocks now, before the call (the three read independent devices).
            head, ft_t, estop, hand = self._sensors()
            if head != ALL_HEAD:
                for k in range(len(HEAD)):
                    if not head & _HEAD_BITS[k]:
                        ns = g.run_blocks(self._head_run[k], t, dt, idx)
                        if k:             # the first slot's time is the call's remainder
                            py_ns += ns
        # As check_block: the failed blocks recorded every cycle (first), then a pending
        # request, heartbeat or failed block sends the supervisor's cycle to Python (and the
        # devices after it run their blocks).
        sup_python = s.python_side_pending(None if not g.failed else g.failed_components())
        if upto > ST_DRIVE:
            if sup_python:
                upto = ST_DRIVE
            else:
                drive = self._drive_args()
                if drive is None:
                    upto = ST_DRIVE
                else:
                    has_measured, owner = drive
                    if upto > ST_RECORDER:
                        rec = self._rec
                        if rec is None or not rec._active or self._rec_changed(rec):
                            upto = ST_RECORDER
                        else:
                            rec_row = rec.written % rec.capacity
        hybrid = self._hybrid_code(ctl) if self._hybrid else NOT_HYBRID
        ta, fa = self._ta, self._fa
        a = T_ARGS
        ta[a + A_FIRST] = self._first
        ta[a + A_UPTO] = upto
        ta[a + A_FILLED] = self._state._filled
        ta[a + A_HYBRID] = hybrid
        ta[a + A_LAW] = b.law_id
        ta[a + A_TRAJECTORY] = b.trajectory
        ta[a + A_NB] = self._nb
        ta[a + A_IDX] = idx
        ta[a + A_HAS_MEASURED] = has_measured
        ta[a + A_OWNER] = owner
        ta[a + A_REC_ROW] = rec_row
        ta[a + A_HEAD] = head
        fa[F_T] = t
        fa[F_DT] = dt
        fa[F_VPN] = self._vpn
        fa[F_NS_PER_TICK] = self._tick_ns
        fa[F_FT_T] = ft_t
        fa[F_ESTOP] = estop
        fa[F_HAND] = hand
        n = self._finish(fused_cycle(self._tab_addr), t, dt, head, py_ns, sup_python)
        # The next cycle may take the fast path when this one ran the whole segment in the
        # kernel with every sensor fused (nothing of the blocks' Python ran).
        if (self._plan is not None and n == len(self.slots) and self.pending is None
                and head == ALL_HEAD and not sup_python and cyc is not None):
            self._plan_mode = mode_raw
            self._plan_epoch = epoch
            drv = self._drive
            assert drv is not None
            self._plan_ok = self._plan_drive_matches(drv)
        return n

    def _finish(self, ran: int, t: float, dt: float, head: int, py_ns: int,
                sup_python: bool) -> int:
        """The call's answers (``fused_kernel.fused_cycle``): the counts the blocks keep,
        the Python that completes the last stage (``pending``); returns the stages run."""
        ta = self._ta
        python = ta[T_ARGS + A_PYTHON_OUT]
        self.others_ns = ta[T_ARGS + A_OTHERS] + py_ns
        if head & HEAD_ENCODERS and not (python and ran == ST_ENCODERS + 1):
            self._enc_port.n_reads += 9           # the emulated card's count of inb
        if ran >= ST_REFERENCE and ta[T_ARGS + A_FK] >= 0:
            self._state.buffer_filled()
        if ran >= ST_SUPERVISOR:
            self._comps[3]._dt = dt   # what the block's update records (for a handover)
        self._aux = ta[T_ARGS + A_AUX]
        pending: Callable[[float, float], int] | None = None
        if ran == ST_DRIVE:
            if python or sup_python:
                pending = self._finish_supervisor
        elif python:
            if ran == ST_ENCODERS + 1:
                pending = self._encoder_refused
            elif ran == ST_FORCE + 1:
                pending = self._tare_ended
            elif ran == ST_MODEL:
                pending = _sensor_fault
            elif ran == ST_CONTROLLER:
                pending = self._play_done
            elif ran == ST_SUPERVISOR:
                pending = self._law_refused
            elif ran == ST_RECORDER:
                pending = self._finish_drive
        elif ran == ST_RECORDER + 1:
            self._rec.written += 1    # type: ignore[union-attr]  # the tap's row is in
        self.pending = pending
        if pending is not None or ran != self._end:
            self._plan_ok = False
        return ran - self._first

    def _make_plan(self) -> tuple | None:
        """The fast path's plan for this binding (:meth:`run`), or None: only for the whole
        segment (:data:`HEAD`, :data:`CHAIN`, :data:`TAIL`) on the in-process twin's
        backends (its encoders, ATI, stop inputs and compiled DAC double, the twin on a
        ``SimClock``). The arrays the kernel views are the backends' own, assigned once in
        their constructors, as are the blocks' backends (``encoders``, ``sensor``,
        ``device``), the drive's monitor and cards, the recorder's ring and the twin's
        plant store. Everything else the general path decides from changes only at an event
        that bumps ``rt.epoch`` after it (a block's lifecycle or a graph change, a request,
        a reset or new gains, ``Device.close``, ``SampledForceTorque.start/stop``, the
        drive's card or enable, ``FaultPlan.schedule``, ``Twin.clock``, a backend's method
        replaced on its instance: ``WatchReplaced``), or in a block's Python, which ends
        the plan; the fast path compares the epoch, then reads what changes in the cycle
        (the mode input, the ATI's pending sample, the monitor's reading, the stop levels)."""
        from rt.twin.backends import (
            TwinActuators,
            TwinDigitalInputs,
            TwinEncoders,
            TwinForceTorque,
        )
        from rt.twin.twin import _T_AT

        if self.slots != HEAD + CHAIN + TAIL or self._drive is None or self._rec is None:
            return None
        enc, force, stops = self._head
        ctl, drv, rec = self._comps[3], self._comps[5], self._comps[6]
        enc_b, ft_b, stops_b = enc.encoders, force.sensor, stops.device
        if type(enc_b) is not TwinEncoders or type(ft_b) is not TwinForceTorque \
                or type(stops_b) is not TwinDigitalInputs:
            return None
        tw = enc_b.twin
        cell = tw._clock_cell
        if ft_b.twin is not tw or stops_b.twin is not tw or cell is None:
            return None
        enc_d = enc_b._driver
        port = enc_d._port
        if port.compiled_block_state() is None:
            return None
        for cw in drv._compiled_writes:
            card_b = getattr(cw, "__self__", None)
            if type(card_b) is not TwinActuators or card_b.twin is not tw:
                return None
        # What the fast path reads every cycle (``dmon``, the monitor's array, is bound by
        # :meth:`_plan_drive_matches`); everything else it relies on bumps ``rt.epoch``.
        return (self._graph, ctl, ctl.mode.data, self._hybrid, tw, tw.ati, port, drv.monitor,
                None, self._state, rec, rec.capacity, tw.plant._store, _T_AT)

    def _plan_drive_matches(self, drv: RedundantDrive) -> bool:
        """Bind the plan's drive part to the active card (the last cycle's): its backend,
        its driver and the double's state; the monitor's reading the bound array (or no
        monitor). False: no fast path."""
        plan = self._plan
        assert plan is not None
        cw = drv._compiled_writes[drv._card]
        card_b = getattr(cw, "__self__", None)
        if card_b is None:
            return False
        card_d = card_b._driver
        mon = plan[7]
        dmon = None
        if mon is not None:
            dmon = mon()
            if dmon is not self._bufs[B_DMON]:
                return False
        if card_d._fake_st is not self._bufs[B_DFAKE]:
            return False
        self._plan = (*plan[:8], dmon, *plan[9:])
        return True

    def _sensors(self) -> tuple[int, float, float, float]:
        """Which sensor stages the kernel runs this cycle (``HEAD_*`` bits) and their
        scalars (the force sample's time; the stop levels), each
        sensor's buffers rebound when its backend's arrays changed."""
        enc, force, stops = self._head
        why = self.why_not_sensor
        head = 0
        bufs = self._bufs
        r = enc.encoders.compiled_read()
        if r is None:
            why[0] = "the backend is not memory this cycle"
        elif (r[0] is not bufs[B_PCL_ST] or r[1] is not bufs[B_PCL_PORTS]
              or r[2] is not bufs[B_PCL_IO] or r[3] is not bufs[B_PCL_DEC]) and (
                self._set(B_PCL_ST, r[0]) or self._set(B_PCL_PORTS, r[1])
                or self._set(B_PCL_IO, r[2]) or self._set(B_PCL_DEC, r[3])):
            self._set(B_PCL_ST, _NO_I)
            why[0] = "the card's arrays cannot be viewed"
        else:
            head = HEAD_ENCODERS
            self._enc_port = r[4]
            why[0] = ""
        ft_t = 0.0
        smp = force.sensor.compiled_sample()
        if smp is None:
            why[1] = "the sensor's sample is not in memory this cycle"
        elif (smp[0] is not bufs[B_ATI_W] or smp[1] is not bufs[B_FT_ST]
              or force.tare._buf is not bufs[B_FT_TARE_BUF]) and (
                self._set(B_ATI_W, smp[0]) or self._set(B_FT_ST, smp[1])
                or self._set(B_FT_TARE_BUF, force.tare._buf)):
            self._set(B_ATI_W, _NO_F)
            why[1] = "the sample's arrays cannot be viewed"
        else:
            head |= HEAD_FORCE
            ft_t = float(smp[2])
            why[1] = ""
        lv = stops.device.compiled_levels()
        estop = hand = 0.0
        if lv is None:
            why[2] = "the inputs are not memory"
        else:
            head |= HEAD_STOPS
            estop, hand = lv
            why[2] = ""
        return head, ft_t, estop, hand

    def _encoder_refused(self, t: float, dt: float) -> int:
        # The kernel's read stopped at a port the card refuses: the same read raises the
        # card's HardwareError (naming the port), as the block's read would.
        enc = self._head[0]
        enc.encoders.read_positions_m(enc.q.data)
        return 0

    def _tare_ended(self, t: float, dt: float) -> int:
        force = self._head[1]
        force.tare._end_cycle(force.wrench.data, force.tare_out.data)
        return 0

    def _drive_args(self) -> tuple[bool, int] | None:
        """The drive stage's (has a monitor reading, the card list's owner) when the drive may
        run fused this cycle (module docstring: the active card on the twin's compiled
        double, enabled, not failed, the monitor an array in place), its buffers rebound to
        the active card; else None (the block runs)."""
        drv = self._drive
        if drv is None or not drv._active or drv.failed.data[0] > 0.5 or not drv._enabled:
            return None
        cw = drv._compiled_writes[drv._card]
        fast = cw() if cw is not None else None
        if fast is None:
            return None
        dac, samples, fake, owner = fast
        bufs = self._bufs
        # Another card (a failover): its driver's buffers.
        if (dac is not bufs[B_DAC] or samples is not bufs[B_DSAMPLES]
                or fake is not bufs[B_DFAKE]) and (self._set(B_DAC, dac)
                                                   or self._set(B_DSAMPLES, samples)
                                                   or self._set(B_DFAKE, fake)):
            self._set(B_DAC, _NO_F)
            return None
        mon = drv.monitor
        if mon is None:
            return False, owner
        measured = mon()
        if measured is None:          # no reading newer than the last command
            return False, owner
        if measured is not bufs[B_DMON] and (
                type(measured) is not np.ndarray or measured.dtype != _F64
                or measured.shape != (3,) or self._set(B_DMON, measured)):
            return None               # any other sequence: the block copies it
        return True, owner

    def _rec_changed(self, rec: SignalTap) -> bool:
        """Whether the tap's ring or signals were replaced since the binding (its start binds
        them again): then the block runs, and the next binding takes the new ones."""
        arrays = self._rec_arrays
        if rec.ring is arrays[0] and rec._addr is arrays[1] and rec._lens is arrays[2]:
            return False
        if rec._signals is None or self._set(B_REC_RING, rec.ring) or \
                self._set(B_REC_ADDR, rec._addr) or self._set(B_REC_LENS, rec._lens):
            self._gen = -1
            return True
        self._rec_arrays = (rec.ring, rec._addr, rec._lens)
        return False

    def _finish_drive(self, t: float, dt: float) -> int:
        drv = self._drive
        assert drv is not None
        info = self._info
        return drv.after_compiled_write(t, int(info[I_DRIVE]), int(info[I_DRIVE_RC]),
                                        int(info[I_DRIVE_DONE]), True)

    def _play_done(self, t: float, dt: float) -> int:
        return self._comps[2].play_done()

    def _law_refused(self, t: float, dt: float) -> int:
        PdG0.refuse_desired(self._comps[3]._ref.q, int(self._aux))
        return 0

    def _finish_supervisor(self, t: float, dt: float) -> int:
        sup = self._comps[4]
        self._sup.finish_block(t, int(self._aux), sup.tau.data, sup.k, sup.volts.data,
                               sup.enable.data, sup.mode.data)
        return 0


_WARM = False


def _sensor_fault(t: float, dt: float) -> int:
    return STATUS_SENSOR


def _drive_unbindable(drv: Any) -> str:
    """"" when the drive slot's block may run its cycle as the fused drive stage (checked
    per cycle too: the active card must be on the twin's compiled double), else why not."""
    if type(drv) is not RedundantDrive:
        return f"drive: {type(drv).__name__} has no fused stage"
    if not drv.compiled:
        return "drive: the interpreted RedundantDrive"
    if drv.__dict__.get("update") is not None or RedundantDrive.__dict__["update"] \
            is not _DRIVE_UPDATE:
        return "drive: RedundantDrive.update is replaced"
    if not any(c is not None for c in drv._compiled_writes):
        return "drive: no card writes through the twin's compiled double"
    return ""


def _head_unbindable(head: list) -> str:
    """"" when the sensor slots hold the standard sensor blocks (each fused per cycle when
    its backend is memory), else why the chain runs per block."""
    enc, force, stops = head
    for comp, cls in ((enc, EncoderReader), (force, ForceReader), (stops, StopInputs)):
        if type(comp) is not cls:
            return f"{cls.__name__}: {type(comp).__name__} has no fused stage"
        if comp.__dict__.get("update") is not None or cls.__dict__["update"] \
                is not _SENSOR_UPDATES[cls]:
            return f"{cls.__name__}.update is replaced"
    if not force.compiled:
        return "force: the interpreted ForceReader"
    return ""


def _recorder_unbindable(rec: Any) -> str:
    if type(rec) is not RecorderTap and type(rec) is not SignalTap:
        return f"recorder: {type(rec).__name__} has no fused stage"
    if rec.__dict__.get("update") is not None or SignalTap.__dict__["update"] is not _TAP_UPDATE:
        return "recorder: SignalTap.update is replaced"
    if rec._signals is None:
        return "recorder: its inputs are not one kind of array (it copies them in Python)"
    return ""


_DRIVE_UPDATE = RedundantDrive.__dict__["update"]
_TAP_UPDATE = SignalTap.__dict__["update"]
_SENSOR_UPDATES = {cls: cls.__dict__["update"] for cls in (EncoderReader, ForceReader, StopInputs)}


def attach(graph: Any, enabled: bool | None = None) -> FusedChain | None:
    """Give ``graph`` the fused chain when its slots hold the standard chain's names in order
    (and after them the tail's, :data:`TAIL`, as far as it has them; the blocks themselves are
    checked at each binding); ``enabled`` None: the environment's :data:`ENV_FLAG`. Returns
    the chain (None when the slots are not there)."""
    order = list(graph.order)
    if CHAIN[0] not in order:
        return None
    i = order.index(CHAIN[0])
    if tuple(order[i:i + len(CHAIN)]) != CHAIN:
        return None
    slots: tuple[str, ...] = CHAIN
    for k in range(len(TAIL) if sensors_by_environment() else 0, 0, -1):
        if tuple(order[i + len(CHAIN):i + len(CHAIN) + k]) == TAIL[:k]:
            slots = CHAIN + TAIL[:k]
            break
    if i >= len(HEAD) and tuple(order[i - len(HEAD):i]) == HEAD and sensors_by_environment():
        slots = HEAD + slots
    chain = FusedChain(slots)
    graph.fuse(chain, enabled_by_environment() if enabled is None else enabled)
    return chain
