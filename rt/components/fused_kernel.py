"""The fused cycle's kernel (issue 16): the standard chain's block kernels called from one
numba function, on the blocks' own buffers reached through a table of addresses — the five
middle blocks (estimator → supervisor) and, after them, the device blocks whose backend is
memory (the twin's redundant drive on its compiled comedilib double, the recorder tap).

Kept apart from :mod:`rt.components.fused` (the Python side: binding, checks, the graph's
segment) so that editing that side does not invalidate numba's on-disk cache of this one
(numba keys a cache on its source file). Every stage calls the existing kernel of its block
with the arguments the block passes; nothing of their arithmetic is here.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from llvmlite import ir  # type: ignore[import-untyped]
from numba import carray, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from rt.components import hybrid_kernel as hyk
from rt.components.blocks import tap_row
from rt.components.safety_blocks import _drive_cycle_write, _force_cycle
from rt.components.tare import TARE_ENDED
from rt.control import kernels as ck
from rt.devices.sampled_ft import _read_sample
from rt.drivers import kernels as dk
from rt.estimation.compiled import block_update
from rt.model.kernels import model_state
from rt.model.kinematics import FK_MAX_ITERATIONS, FK_STEP_TOL_RAD
from rt.pointers import f64_at, i64_at, u32_at
from rt.references import sequencer_kernel as rk
from rt.safety import supervisor_kernel as svk

#: The stages, in the graph's order, numbered absolutely: the sensors (run by Python before
#: the call: their backends call drivers or Python objects), the five middle blocks, the drive
#: and the recorder tap. A segment covers a consecutive run of them (``first`` .. ``upto``).
(ST_ENCODERS, ST_FORCE, ST_STOPS, ST_ESTIMATOR, ST_MODEL, ST_REFERENCE, ST_CONTROLLER,
 ST_SUPERVISOR, ST_DRIVE, ST_RECORDER, N_STAGES) = range(11)

# ``info`` (int64) the kernel fills: stages it ran (absolute: the stage after the last one
# run), whether the last one needs Python, the estimator's status, FK's status, the
# reference's answer, the law's status, the supervisor's, and the drive's answers (failed
# channel or -1, the codes' answer, the list's answer).
(I_RAN, I_PYTHON, I_EST, I_FK, I_REF, I_LAW, I_SUP, I_DRIVE, I_DRIVE_RC, I_DRIVE_DONE,
 INFO_SIZE) = range(11)
_EST_JUMP = -3          # EstimatorStatus.JUMP: published, the supervisor's business


@intrinsic
def _ticks(typingctx: Any) -> Any:
    """The CPU's cycle counter (x86: rdtsc) read inside a kernel: a stage's time costs no
    clock call (``perf_counter_ns`` costs ≈ 0.3 µs on this VM)."""
    sig = types.int64()

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        fnty = ir.FunctionType(ir.IntType(64), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.readcyclecounter")
        return builder.call(fn, [])
    return sig, codegen


@njit(cache=True)
def ticks_now() -> int:
    return _ticks()  # type: ignore[call-arg]


# ---- the buffers: one table of addresses (and shapes) instead of ~57 array arguments.
# numba's dispatch unboxes each array argument (≈ 0.5 µs apiece here): passing the blocks'
# buffers one by one cost more than the five blocks' own Python. The kernel rebuilds each
# buffer as a view of the same memory (``carray``); :class:`FusedChain` holds a reference to
# every buffer whose address is in the table and re-reads the addresses whenever one of them
# may have been replaced (a reset, new gains, a new program's table), before the call.
(B_EST_C, B_EST_S, B_EST_Q, B_EST_OUT, B_EST_IO,
 B_GEOM, B_LIMITS, B_PHI, B_MOD_Q, B_MOD_QD, B_STB, B_MOD_WORK, B_FK,
 B_REF_IO, B_SEQ, B_REF_Q, B_REF_MODE, B_TABLE, B_CTRL_MODE,
 B_TI, B_TF, B_LAW_STB, B_LQ, B_LQD, B_LQDD, B_GAINS, B_WORK, B_OUT, B_INTEGRAL, B_AMAP,
 B_EST, B_LGEOM, B_LLIMITS, B_LPHI, B_G0, B_G0_SCRATCH,
 B_PAR, B_MEM, B_SQ, B_SEST, B_SQD, B_SQDD, B_SSTB, B_SFK, B_SQREF, B_SQDREF, B_STAU,
 B_WRENCH, B_WFLAGS, B_INPUTS, B_DFAILED, B_VOLTS, B_ENABLE, B_MODE,
 # The hybrid controller's force mode (``force_stage``): its state, its input ports, the
 # explicit-force law's tree, gains, state, work, its own copy of the command, the reference.
 B_HS, B_HFORCE, B_HPREVIEW, B_HPOSE, B_HWRENCH, B_FTI, B_FTF, B_FG, B_FS, B_FWORK, B_FTAU,
 B_FREF,
 # The redundant drive on the twin's compiled comedilib double (``drive_stage``): its state,
 # its command and enable inputs, the amplifier-input monitor's array, the active card's
 # driver state, its list's samples (uint32) and the double's state; the recorder tap's ring
 # (a matrix) and its signals' addresses and lengths (``recorder_stage``).
 B_DST, B_DVOLTS, B_DENABLE, B_DMON, B_DAC, B_DSAMPLES, B_DFAKE,
 B_REC_RING, B_REC_ADDR, B_REC_LENS,
 # The sensors on memory (``sensor_stages``): the encoder card's emulation state, the
 # driver's ports to read, its read/unwrap state and decode constants, its output; the polled
 # force sensor's device sample and own state, the reader's reading, wrench, flags, tare
 # request, tare port and tare state; the stop inputs' output.
 B_PCL_ST, B_PCL_PORTS, B_PCL_IO, B_PCL_DEC, B_ENC_Q,
 B_ATI_W, B_FT_ST, B_FT_RAW, B_FT_WRENCH, B_FT_FLAGS, B_FT_REQUEST, B_FT_TARE, B_FT_TARE_BUF,
 B_STOPS,
 # The sequencer's wrench, wrench flags and tare input ports (its tare wait, its compliant
 # hold: ``sequencer_kernel.cycle``; an unbound port: an empty array).
 B_REF_WRENCH, B_REF_FLAGS, B_REF_TARE, N_BUFFERS) = range(94)
_INT_BUFFERS = (B_TI, B_AMAP, B_FTI, B_DFAKE, B_REC_ADDR, B_REC_LENS, B_PCL_ST, B_PCL_PORTS,
                B_PCL_IO)
_U32_BUFFERS = (B_DSAMPLES,)
_MATRIX_BUFFERS = (B_TABLE, B_REC_RING)

LAW_PADEN_PANJA, LAW_COMPUTED_TORQUE, LAW_PD_GRAVITY, LAW_PD_G0, LAW_PID, LAW_ADAPTIVE = range(6)

# ``hybrid``: what the controller slot holds. A ControllerBlock (NOT_HYBRID); a hybrid
# controller in position mode (HYBRID_POSITION); in force mode with its compiled force cycle
# bound (HYBRID_FORCE) or not (HYBRID_FORCE_PYTHON: its block runs). A switch between the
# modes (``ctrl_mode`` against the mode the block is in) always runs the block.
NOT_HYBRID, HYBRID_POSITION, HYBRID_FORCE, HYBRID_FORCE_PYTHON = range(4)


@njit(cache=True, inline="always")
def _v(addr, dims, i):
    return carray(f64_at(addr[i]), dims[i, 0])


@njit(cache=True, inline="always")
def _vi(addr, dims, i):
    return carray(i64_at(addr[i]), dims[i, 0])


@njit(cache=True, inline="always")
def _vu(addr, dims, i):
    return carray(u32_at(addr[i]), dims[i, 0])


@njit(cache=True)
def _law(dt, law, trajectory, nb, a, d):
    """The law's kernel (``LAW_*``), called as its bound cycle calls it; returns its status
    (< 0: PD+G0's FK at the desired position refused)."""
    ti, tf, stb = _vi(a, d, B_TI), _v(a, d, B_TF), _v(a, d, B_LAW_STB)
    q, qd, qdd = _v(a, d, B_LQ), _v(a, d, B_LQD), _v(a, d, B_LQDD)
    gains, work, out = _v(a, d, B_GAINS), _v(a, d, B_WORK), _v(a, d, B_OUT)
    if law == LAW_PADEN_PANJA:
        ck.paden_panja(ti, tf, stb, q, qd, qdd, gains, work, out)
    elif law == LAW_COMPUTED_TORQUE:
        ck.computed_torque(ti, tf, stb, q, qd, qdd, gains, trajectory, work, out)
    elif law == LAW_PD_GRAVITY:
        ck.pd_gravity(ti, tf, stb, q, qd, gains, work, out)
    elif law == LAW_PD_G0:
        return ck.pd_gravity_desired(ti, tf, _v(a, d, B_LGEOM), _v(a, d, B_LLIMITS),
                                     _v(a, d, B_LPHI), stb, q, qd, gains, _v(a, d, B_G0),
                                     _v(a, d, B_G0_SCRATCH), out)
    elif law == LAW_PID:
        ck.pid(stb, q, qd, gains, _v(a, d, B_INTEGRAL), dt, False, out)
    elif law == LAW_ADAPTIVE:
        ck.adaptive(ti, tf, stb, q, qd, qdd, _vi(a, d, B_AMAP), _v(a, d, B_EST), dt, False, out)
    return 0


@njit(cache=True)
def force_stage(dt, a, d):
    """The hybrid controller's steady force-mode cycle
    (:func:`rt.components.hybrid_kernel.force_cycle`) on its block's buffers."""
    hyk.force_cycle(_v(a, d, B_HS), _v(a, d, B_HFORCE), _v(a, d, B_HPREVIEW), _v(a, d, B_HPOSE),
                    _v(a, d, B_HWRENCH), _vi(a, d, B_FTI), _v(a, d, B_FTF), _v(a, d, B_LAW_STB),
                    _v(a, d, B_FG), _v(a, d, B_FS), _v(a, d, B_FWORK), _v(a, d, B_OUT),
                    _v(a, d, B_FTAU), _v(a, d, B_FREF), dt)
    return 0


@njit(cache=True)
def drive_stage(has_measured, owner, a, d, info):
    """The redundant drive's cycle on the twin's compiled double
    (``rt.components.safety_blocks._drive_cycle_write``: the monitor check, the command kept
    as the last one and the active card's whole write) on its block's buffers; its answers go
    to ``info``. Returns whether they need the block's Python (a confirmed failed channel, a
    refused or incomplete write, a double that keeps a log)."""
    i, rc, done, python = _drive_cycle_write(
        _v(a, d, B_DMON), has_measured, _v(a, d, B_DVOLTS), _v(a, d, B_DST), _v(a, d, B_DAC),
        _vu(a, d, B_DSAMPLES), _vi(a, d, B_DFAKE), owner)
    info[I_DRIVE] = i
    info[I_DRIVE_RC] = rc
    info[I_DRIVE_DONE] = done
    return i >= 0 or python


#: ``head`` bits: which sensor stages the kernel runs (the others ran in Python before it).
HEAD_ENCODERS, HEAD_FORCE, HEAD_STOPS = 1 << ST_ENCODERS, 1 << ST_FORCE, 1 << ST_STOPS


@njit(cache=True)
def sensor_stages(stamps, info, head, ft_t, estop, hand, a, d):
    """The sensor stages the kernel runs (``head``): the encoder card's emulated block read
    and the driver's decode (``rt.drivers.kernels``: what ``Pcl833Encoders.read_positions_m``
    does on the twin's card), the polled force sensor's sample (``_read_sample`` on the
    device's sample — wrench, counter and status in its memory, ``B_ATI_W`` — and its time) and the force reader's cycle with its tare
    (``_force_cycle``), the stop levels. Returns False where Python must finish the stage
    (a port the card refuses; a tare that ended), ``info[I_RAN]`` then the stage after it."""
    for k in range(ST_ENCODERS, ST_ESTIMATOR):
        stamps[k] = _ticks()
        if head & (1 << k):
            if k == ST_ENCODERS:
                io = _vi(a, d, B_PCL_IO)
                if dk.fake_pcl833_read(_vi(a, d, B_PCL_ST), _vi(a, d, B_PCL_PORTS),
                                       io[dk.PCL_RAW:dk.PCL_RAW + 9]) >= 0:
                    stamps[k + 1] = _ticks()
                    info[I_RAN] = k + 1
                    info[I_PYTHON] = 1
                    return False
                dk.pcl833_decode(io, _v(a, d, B_PCL_DEC), _v(a, d, B_ENC_Q))
            elif k == ST_FORCE:
                raw = _v(a, d, B_FT_RAW)
                w = _v(a, d, B_ATI_W)
                _read_sample(w, int(w[6]), int(w[7]), ft_t, _v(a, d, B_FT_ST), raw)
                if _force_cycle(raw, _v(a, d, B_FT_WRENCH), _v(a, d, B_FT_FLAGS),
                                _v(a, d, B_FT_REQUEST), _v(a, d, B_FT_TARE),
                                _v(a, d, B_FT_TARE_BUF)) == TARE_ENDED:
                    stamps[k + 1] = _ticks()
                    info[I_RAN] = k + 1
                    info[I_PYTHON] = 1
                    return False
            else:
                out = _v(a, d, B_STOPS)
                out[0] = estop
                out[1] = hand
        info[I_RAN] = k + 1
    return True


@njit(cache=True)
def recorder_stage(t, row, a, d):
    """The recorder tap's row (``rt.components.blocks.tap_row``) on its block's buffers."""
    ring = carray(f64_at(a[B_REC_RING]), (d[B_REC_RING, 0], d[B_REC_RING, 1]))
    tap_row(ring, row, t, _vi(a, d, B_REC_ADDR), _vi(a, d, B_REC_LENS))
    return 0


# ``tab`` (int64), everything the kernel reads or writes besides the blocks' buffers, in one
# argument: the buffers' addresses and shapes, the timing rings' addresses, the stamps and
# the info.
T_ADDR = 0
T_DIMS = T_ADDR + N_BUFFERS
T_RINGS = T_DIMS + 2 * N_BUFFERS
T_STAMPS = T_RINGS + N_STAGES
T_INFO = T_STAMPS + N_STAGES + 1
T_ARGS = T_INFO + INFO_SIZE
# The call's scalars (devstage7b): numba's dispatch boxes and types each argument (22 of them
# cost ≈ 4-7 µs a cycle here), so they live in memory the Python side writes item by item
# (``array`` stores: ≈ 30 ns each) and :func:`fused_cycle` takes one int, this table's
# address. Integers in ``tab`` at ``T_ARGS``; floats in a float64 store at ``tab[T_FARGS]``.
(A_FIRST, A_UPTO, A_FILLED, A_HYBRID, A_LAW, A_TRAJECTORY, A_NB, A_IDX, A_HAS_MEASURED,
 A_OWNER, A_REC_ROW, A_HEAD, A_PYTHON_OUT, A_OTHERS, A_AUX, A_FK, A_SIZE) = range(17)
T_FARGS = T_ARGS + A_SIZE
T_SIZE = T_FARGS + 1
(F_T, F_DT, F_VPN, F_NS_PER_TICK, F_FT_T, F_ESTOP, F_HAND, F_SIZE) = range(8)


@njit(cache=True)
def fused_chain(tab, t, dt, first, upto, filled, volts_per_n, hybrid, law, trajectory, nb, idx,
                ns_per_tick, has_measured, owner, rec_row, head, ft_t, estop, hand):
    """:func:`sensor_stages` (``head``: those the kernel runs; when the segment starts at
    ``first`` = ``ST_ENCODERS``), then :func:`_chain`, then each stage the kernel ran after
    the segment's first timed into its slot's ring (the graph's timing
    rings' addresses, in ``tab``, at ``idx``). Returns (the stage after the last one run,
    whether the last needs Python, the ns those later stages took, the supervisor's or the
    law's answer, FK's status)."""
    a = tab[T_ADDR:T_ADDR + N_BUFFERS]
    d = tab[T_DIMS:T_DIMS + 2 * N_BUFFERS].reshape((N_BUFFERS, 2))
    rings = tab[T_RINGS:T_RINGS + N_STAGES]
    stamps = tab[T_STAMPS:T_STAMPS + N_STAGES + 1]
    info = tab[T_INFO:T_INFO + INFO_SIZE]
    info[I_RAN] = first
    info[I_PYTHON] = 0
    if first >= ST_ESTIMATOR or sensor_stages(stamps, info, head, ft_t, estop, hand, a, d):
        _chain(stamps, info, t, dt, upto, filled, volts_per_n, hybrid, law, trajectory, nb, a,
               d, has_measured, owner, rec_row)
    ran = info[I_RAN]
    others = 0
    for j in range(first + 1, ran):
        if j < ST_ESTIMATOR and not head & (1 << j):
            continue                        # a sensor block Python ran: its ring is written
        ns = np.int64((stamps[j + 1] - stamps[j]) * ns_per_tick)
        carray(i64_at(rings[j]), idx + 1)[idx] = ns
        others += ns
    aux = info[I_SUP] if ran == ST_SUPERVISOR + 1 else info[I_LAW]
    return ran, info[I_PYTHON], others, aux, info[I_FK]


@njit(cache=True)
def _chain(stamps, info, t, dt, upto, filled, volts_per_n, hybrid, law, trajectory, nb, a, d,
           has_measured, owner, rec_row):
    """The stages (module docstring) from the estimator up to stage ``upto`` (exclusive,
    absolute), stopping where Python must run; ``stamps[k]`` the cycle counter before stage
    ``k`` and ``stamps[k + 1]`` after it; ``a``/``d`` the buffers' addresses and shapes
    (``B_*``)."""
    info[I_RAN] = ST_ESTIMATOR
    stamps[ST_ESTIMATOR] = _ticks()
    status = block_update(_v(a, d, B_EST_C), _v(a, d, B_EST_S), _v(a, d, B_EST_Q), dt,
                          _v(a, d, B_EST_OUT), _v(a, d, B_EST_IO))
    stamps[ST_MODEL] = _ticks()
    info[I_RAN] = ST_MODEL
    info[I_EST] = status
    if status < 0 and status != _EST_JUMP:
        info[I_PYTHON] = 1                  # the block returns STATUS_SENSOR: a fault
        return
    fk = model_state(_v(a, d, B_GEOM), _v(a, d, B_LIMITS), _v(a, d, B_PHI), _v(a, d, B_MOD_Q),
                     _v(a, d, B_MOD_QD), _v(a, d, B_STB), FK_STEP_TOL_RAD, FK_MAX_ITERATIONS,
                     _v(a, d, B_MOD_WORK))
    _v(a, d, B_FK)[0] = 1.0 if fk >= 0 else 0.0
    stamps[ST_REFERENCE] = _ticks()
    info[I_RAN] = ST_REFERENCE
    info[I_FK] = fk
    if upto <= ST_REFERENCE:
        return
    table = carray(f64_at(a[B_TABLE]), (d[B_TABLE, 0], d[B_TABLE, 1]))
    # The sequencer's steady cycles, an approach's, a return's and a brake's samples among
    # them (the move's plan is in B_SEQ: ``rt.references.approach_kernel``), a force
    # program's tare wait, a force ramp-down and a force stop's compliant hold.
    r = rk.cycle(_v(a, d, B_REF_IO), _v(a, d, B_SEQ), _v(a, d, B_REF_Q), _v(a, d, B_REF_MODE),
                 table, dt, _v(a, d, B_REF_WRENCH), _v(a, d, B_REF_FLAGS),
                 _v(a, d, B_REF_TARE))
    info[I_REF] = r
    if r == rk.NEED_PYTHON:                 # nothing written: the block runs its cycle
        return
    stamps[ST_CONTROLLER] = _ticks()
    info[I_RAN] = ST_CONTROLLER
    if r == rk.PLAY_DONE:                   # the return is planned in Python
        info[I_PYTHON] = 1
        return
    if upto <= ST_CONTROLLER:
        return
    if hybrid == NOT_HYBRID:
        ls = _law(dt, law, trajectory, nb, a, d)
    else:
        # The hybrid controller's steady cycles; a switch of mode is its block's (Python).
        force = _v(a, d, B_CTRL_MODE)[0] > 0.5
        if force != (hybrid != HYBRID_POSITION) or hybrid == HYBRID_FORCE_PYTHON:
            return
        if force:
            ls = force_stage(dt, a, d)
        else:
            ls = _law(dt, law, trajectory, nb, a, d)
    stamps[ST_SUPERVISOR] = _ticks()
    info[I_RAN] = ST_SUPERVISOR
    info[I_LAW] = ls
    if ls < 0:
        info[I_PYTHON] = 1                  # PD+G0's refused FK raises in Python
        return
    if upto <= ST_SUPERVISOR:
        return
    new = svk.block_cycle(_v(a, d, B_PAR), _v(a, d, B_MEM), t, dt, _v(a, d, B_SQ),
                          _v(a, d, B_SEST), _v(a, d, B_SQD), _v(a, d, B_SQDD),
                          _v(a, d, B_SSTB), _v(a, d, B_SFK), filled or fk >= 0,
                          _v(a, d, B_SQREF), _v(a, d, B_SQDREF), _v(a, d, B_STAU),
                          _v(a, d, B_WRENCH), _v(a, d, B_WFLAGS), _v(a, d, B_INPUTS),
                          _v(a, d, B_DFAILED), volts_per_n, _v(a, d, B_VOLTS),
                          _v(a, d, B_ENABLE), _v(a, d, B_MODE))
    stamps[ST_DRIVE] = _ticks()
    info[I_RAN] = ST_DRIVE
    info[I_SUP] = new
    if new != 0:
        info[I_PYTHON] = 1                  # something new tripped: finish_block
        return
    # The drive: only enabled (a disabling cycle switches its card off in Python).
    if upto <= ST_DRIVE or _v(a, d, B_DENABLE)[0] <= 0.5:
        return
    python = drive_stage(has_measured, owner, a, d, info)
    stamps[ST_RECORDER] = _ticks()
    info[I_RAN] = ST_RECORDER
    if python:
        info[I_PYTHON] = 1                  # a failover, a refused write, a log: the block's
        return
    if upto <= ST_RECORDER:
        return
    recorder_stage(t, rec_row, a, d)
    stamps[N_STAGES] = _ticks()
    info[I_RAN] = N_STAGES


@njit(cache=True)
def fused_cycle(tab_addr):
    """:func:`fused_chain` with its scalars read from memory (``tab`` at ``tab_addr``: the
    ``A_*`` integers at ``T_ARGS``, the ``F_*`` floats at ``tab[T_FARGS]``): one integer
    argument. Returns the stage after the last one run; whether it needs Python, the ns of
    the later stages, the supervisor's or the law's answer and FK's status go to ``A_PYTHON_OUT``,
    ``A_OTHERS``, ``A_AUX``, ``A_FK``."""
    tab = carray(i64_at(tab_addr), T_SIZE)
    ia = tab[T_ARGS:T_ARGS + A_SIZE]
    fa = carray(f64_at(tab[T_FARGS]), F_SIZE)
    ran, python, others, aux, fk = fused_chain(
        tab, fa[F_T], fa[F_DT], ia[A_FIRST], ia[A_UPTO], ia[A_FILLED] != 0, fa[F_VPN],
        ia[A_HYBRID], ia[A_LAW], ia[A_TRAJECTORY] != 0, ia[A_NB], ia[A_IDX],
        fa[F_NS_PER_TICK], ia[A_HAS_MEASURED] != 0, ia[A_OWNER], ia[A_REC_ROW], ia[A_HEAD],
        fa[F_FT_T], fa[F_ESTOP], fa[F_HAND])
    ia[A_PYTHON_OUT] = python
    ia[A_OTHERS] = others
    ia[A_AUX] = aux
    ia[A_FK] = fk
    return ran
