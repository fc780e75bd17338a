"""The supervisor, force-sensor, stop-input and redundant-drive blocks of the loop."""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numba import njit

from rt.components.tare import TARE_ENDED, Tare, tare_cycle
from rt.devices.interfaces import (
    FT_SATURATED,
    FT_STALE,
    ActuatorOutputs,
    DigitalInputs,
    ForceTorqueSensor,
    Wrench,
    new_ft_reading,
)
from rt.drivers.kernels import (
    DAC_RANGES,
    DAC_STATE_SIZE,
    DAC_WRITTEN,
    FC_KEEP_LOG,
    FC_SIZE,
    pci1720_write_fake,
)
from rt.engine import Array, Component, Struct
from rt.epoch import bump
from rt.errors import HardwareError
from rt.model.dynamics import State
from rt.safety import supervisor_kernel as sk
from rt.safety.events import EventLog, Reaction, SafetyEvent, SupervisorMode
from rt.safety.supervisor import Supervisor


@njit(cache=True)
def _force_cycle(raw, wrench, flags, request, tare_port, tare_buf):
    """:class:`ForceReader`'s cycle on the sensor's reading ``raw`` (layout ``FT_*``): the
    wrench and flags to the ports, the reading's validity (fresh, not saturated, finite) and
    the tare's cycle (:func:`rt.components.tare.tare_cycle`, whose answer it returns)."""
    for k in range(6):
        wrench[k] = raw[k]
    stale = raw[FT_STALE] != 0.0
    saturated = raw[FT_SATURATED] != 0.0
    flags[0] = 1.0 if stale else 0.0
    flags[1] = 1.0 if saturated else 0.0
    valid = not (stale or saturated) and math.isfinite(
        raw[0] + raw[1] + raw[2] + raw[3] + raw[4] + raw[5])
    return tare_cycle(wrench, valid, request[0] > 0.5, tare_port, tare_buf)


class ForceReader(Component):
    """Ports: out ``wrench``: float64[6], N and N m, sensor frame, minus the tare's zero (NaN
    when never read); out ``flags``: float64[2] — [stale, saturated] as 0/1; in
    ``tare_request``: float64[1] (a rising edge above 0.5 starts a tare, :mod:`rt.components.
    tare`); out ``tare``: float64[10] — [:class:`TareState`, tares done, :class:`TareRefusal`,
    mean force magnitude of the last tare (N), offset (6: N, N m)].

    A cycle is the sensor's ``read_array`` and one compiled call (:func:`_force_cycle`);
    ``compiled=False`` runs the previous Python body (``Wrench``, ``Tare.cycle_interpreted``),
    the reference of ``tests/test_device_compiled.py``."""

    def __init__(self, name: str, sensor: ForceTorqueSensor, tare: Tare | None = None,
                 compiled: bool = True):
        super().__init__(name)
        self.sensor = sensor
        self.tare = tare or Tare()
        self.compiled = compiled
        self.wrench = self.declare_output("wrench", Array(6), initial=np.full(6, math.nan))
        self.flags = self.declare_output("flags", Array(2))
        self.tare_request = self.declare_input("tare_request", Array(1))
        self.tare_out = self.declare_output("tare", Array(10))
        self._w = Wrench()
        self._raw = new_ft_reading()
        if compiled:
            # Compile (or load from numba's cache) now: the request as the loop binds it, a
            # read-only view; on scratch buffers.
            request = np.zeros(1)
            request.flags.writeable = False
            _force_cycle(self._raw.copy(), np.zeros(6), np.zeros(2), request, np.zeros(10),
                         self.tare._buf.copy())

    def on_start(self) -> None:
        self.sensor.start()

    def update(self, t: float, dt: float) -> int:
        if not self.compiled:
            return self._update_interpreted(t, dt)
        raw = self.sensor.read_array(self._raw)
        out, port = self.wrench.data, self.tare_out.data
        if _force_cycle(raw, out, self.flags.data, self.tare_request.data, port,
                        self.tare._buf) == TARE_ENDED:
            self.tare._end_cycle(out, port)
        return 0

    def _update_interpreted(self, t: float, dt: float) -> int:
        w = self.sensor.read(self._w)
        out = self.wrench.data
        out[0], out[1], out[2], out[3], out[4], out[5] = w.fx, w.fy, w.fz, w.tx, w.ty, w.tz
        self.flags.data[0] = 1.0 if w.stale else 0.0
        self.flags.data[1] = 1.0 if w.saturated else 0.0
        valid = not (w.stale or w.saturated) and math.isfinite(
            w.fx + w.fy + w.fz + w.tx + w.ty + w.tz)
        self.tare.cycle_interpreted(out, valid, self.tare_request.data[0] > 0.5,
                                    self.tare_out.data)
        return 0


class StopInputs(Component):
    """Ports: out ``inputs``: float64[2] — [hardware e-stop, hand-held stop] as 0/1."""

    def __init__(self, name: str, inputs: DigitalInputs):
        super().__init__(name)
        self.device = inputs
        self.stops = self.declare_output("inputs", Array(2))

    def update(self, t: float, dt: float) -> int:
        self.device.read_array(self.stops.data)
        return 0


class SupervisorBlock(Component):
    """Ports: in ``q``: float64[3] m (measured); ``est_status``: float64[1]; ``qd``, ``qdd``:
    float64[3]; ``state``: model ``State``; ``fk_ok``: float64[1]; ``q_ref``, ``qd_ref``:
    float64[3]; ``tau``: float64[3] N; ``wrench``: float64[6]; ``wrench_flags``: float64[2];
    ``inputs``: float64[2]; ``drive_failed``: float64[1] (delayed one cycle).
    Out ``volts``: float64[3] V — the commands less the believed amplifier offsets
    (``drive.amplifier_offset_v``), saturated, zero in a hard stop; ``enable``:
    float64[1] — drives enabled (0 in a hard stop); ``mode``: float64[1] — the latched
    :class:`SupervisorMode` (run, soft stop, hard stop).

    The supervisor owns the right to enable the drives: nothing else writes ``enable``.
    """

    def __init__(self, name: str, supervisor: Supervisor, force_per_volt_n: float):
        super().__init__(name)
        self.sup = supervisor
        self.k = 1.0 / force_per_volt_n
        self.q = self.declare_input("q", Array(3))
        self.est_status = self.declare_input("est_status", Array(1))
        self.qd = self.declare_input("qd", Array(3))
        self.qdd = self.declare_input("qdd", Array(3))
        self.state_in = self.declare_input("state", Struct(State))
        self.fk_ok = self.declare_input("fk_ok", Array(1))
        self.q_ref = self.declare_input("q_ref", Array(3))
        self.qd_ref = self.declare_input("qd_ref", Array(3))
        self.tau = self.declare_input("tau", Array(3))
        self.wrench = self.declare_input("wrench", Array(6))
        self.wrench_flags = self.declare_input("wrench_flags", Array(2))
        self.stops = self.declare_input("inputs", Array(2))
        self.drive_failed = self.declare_input("drive_failed", Array(1))
        self.volts = self.declare_output("volts", Array(3))
        self.enable = self.declare_output("enable", Array(1), initial=np.ones(1))
        self.mode = self.declare_output("mode", Array(1))
        #: Names the graph's components in error (``Graph.failed_components``); wired by the
        #: loop's builder once the graph exists.
        self.failed_components: Callable[[], str | None] = lambda: None

    def update(self, t: float, dt: float) -> int:
        if self.sup.compiled:
            # Checks and outputs in one compiled call on the port buffers (no Python objects
            # unless something new tripped or a request is pending).
            st = self.state_in.data
            self.sup.check_block(t, dt, self.q.data, self.est_status.data, self.qd.data,
                                 self.qdd.data, st.buf, self.fk_ok.data, st.filled,
                                 self.q_ref.data, self.qd_ref.data, self.tau.data,
                                 self.wrench.data, self.wrench_flags.data, self.stops.data,
                                 self.drive_failed.data, self.k, self.volts.data,
                                 self.enable.data, self.mode.data, self.failed_components())
            return 0
        return self._update_interpreted(t, dt)

    def _update_interpreted(self, t: float, dt: float) -> int:
        """The block as it ran before it was compiled (with an ``InterpretedSupervisor``):
        the reference of ``tests/test_supervisor_compiled.py``."""
        st = self.state_in.data
        fk_ok = self.fk_ok.data[0] > 0.5 and st.filled
        roll = pitch = roll_rate = pitch_rate = 0.0
        if fk_ok:
            # The pose from the state's arrays (Q: ..., yaw, pitch, roll), not its
            # Configuration, which the compiled model block does not build.
            Q = st.Q
            roll, pitch = float(Q[11]), float(Q[10])
            S, qd = st.S, st.qd
            roll_rate = S[11, 0] * qd[0] + S[11, 1] * qd[1] + S[11, 2] * qd[2]
            pitch_rate = S[10, 0] * qd[0] + S[10, 1] * qd[1] + S[10, 2] * qd[2]
        w = self.wrench.data
        force = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
        # The force at the DAC's command limit (as the compiled block_cycle computes it).
        self.sup.applied_force_max_n = self.sup.limits.max_command_v / self.k
        share = [0.0, 0.0, 0.0]
        if fk_ok:
            # The same statics as the compiled block's, run as Python (same arithmetic).
            sk.contact_share.py_func(st.buf, w, self.sup._par, share)
        flags = self.wrench_flags.data
        ins = self.stops.data
        reaction = self.sup.check(
            t, dt, self.q.data, int(self.est_status.data[0]), self.qd.data, self.qdd.data,
            fk_ok, roll, pitch, roll_rate, pitch_rate, self.q_ref.data, self.qd_ref.data,
            self.tau.data, force, flags[0] > 0.5, flags[1] > 0.5, ins[0] > 0.5, ins[1] > 0.5,
            self.drive_failed.data[0] > 0.5, -w[2], self.failed_components(), share)
        v = self.volts.data
        if reaction >= Reaction.HARD_STOP:
            v[:] = 0.0
            self.enable.data[0] = 0.0
            self.mode.data[0] = float(SupervisorMode.HARD_STOP)
            return 0
        limit = self.sup.limits.max_command_v
        # Less the believed amplifier offsets while the drives are enabled, clamped on the
        # written volts; the checks above stay on τ (``supervisor_kernel.outputs`` says why).
        offset = self.sup.amplifier_offset_v
        for i in range(3):
            x = self.tau.data[i] * self.k - offset[i]
            v[i] = limit if x > limit else (max(x, -limit))
        self.enable.data[0] = 1.0
        self.mode.data[0] = float(SupervisorMode.of(reaction))
        return 0


_F64 = np.dtype(np.float64)
_SHAPE3 = (3,)


@njit(cache=True)
def _disagreement(measured, last, mismatch, tolerance_v, confirm_cycles):
    """Count each channel's consecutive cycles of amplifier input (``measured``, V) away from
    the last command (``last``, V) by more than ``tolerance_v``; a channel that agrees clears
    its count. Returns the first channel confirmed (``confirm_cycles`` in a row) — the
    channels after it are not counted this cycle — or -1."""
    for i in range(3):
        if abs(measured[i] - last[i]) > tolerance_v:
            mismatch[i] += 1
            if mismatch[i] >= confirm_cycles:
                return i
        else:
            mismatch[i] = 0
    return -1


# RedundantDrive's numbers (float64 array): the last command written (3), the one before it
# (3, restored when a write fails), each channel's disagreement count (3; integers exact), the
# tolerance (V) and the cycles that confirm a disagreement (one array: numba's dispatch costs
# per argument).
_LAST, _BACKUP, _MISMATCH, _TOLERANCE, _CONFIRM, _DRIVE_SIZE = 0, 3, 6, 9, 10, 11


@njit(cache=True)
def _drive_cycle(measured, has_measured, volts, enabled, st):
    """:class:`RedundantDrive`'s arithmetic of a cycle: with a monitor reading, count each
    channel's disagreement with the last command (:func:`_disagreement`'s rule) and return the
    first channel confirmed failed (nothing else done); otherwise the command about to be
    written becomes the last one (0 V when the drives are disabled), the previous one kept in
    the backup, and -1 is returned."""
    if has_measured:
        tolerance_v = st[_TOLERANCE]
        confirm_cycles = st[_CONFIRM]
        for i in range(3):
            if abs(measured[i] - st[_LAST + i]) > tolerance_v:
                st[_MISMATCH + i] += 1.0
                if st[_MISMATCH + i] >= confirm_cycles:
                    return i
            else:
                st[_MISMATCH + i] = 0.0
    for i in range(3):
        st[_BACKUP + i] = st[_LAST + i]
        st[_LAST + i] = volts[i] if enabled else 0.0
    return -1


def _scratch_dac() -> np.ndarray:
    """A PCI-1720 driver state (``rt.drivers.kernels`` ``DAC_*``) on ±10 V, 12 bit, disabled:
    what warming the compiled write needs."""
    dac = np.zeros(DAC_STATE_SIZE)
    for i in range(3):
        dac[DAC_RANGES + 3 * i:DAC_RANGES + 3 * i + 3] = (-10.0, 10.0, 4095.0)
    return dac


@njit(cache=True)
def _drive_cycle_write(measured, has_measured, volts, st, dac, samples, fake_st, owner):
    """:func:`_drive_cycle` of an enabled drive, then (no channel confirmed failed) the active
    card's whole write on the twin's compiled comedilib double
    (``rt.drivers.kernels.pci1720_write_fake``): one call for the drive block's cycle. Returns
    (the failed channel or -1, the codes' answer, the list's answer, whether the answers need
    the driver's Python: a refusal, an incomplete list, or a double that keeps a log)."""
    i = _drive_cycle(measured, has_measured, volts, True, st)
    if i >= 0:
        return i, 0, 0, False
    rc, done = pci1720_write_fake(volts, dac, samples, fake_st, owner)
    return -1, rc, done, rc != DAC_WRITTEN or done != 3 or fake_st[FC_KEEP_LOG] != 0


class RedundantDrive(Component):
    """Ports: in ``volts``: float64[3] V; in ``enable``: float64[1]; out ``failed``: float64[1]
    (1 when a channel has failed on both cards); out ``active_card``: float64[1].

    Writes the commands to the active DAC card. An actuator-channel fault on that card — a
    write error, or the amplifier input (read back through ``monitor``, the rig's current
    monitors) disagreeing with the command for ``confirm_cycles`` cycles — moves all outputs to
    the other card in the same cycle (thesis 3.7.3): the period is kept and an event recorded.
    A monitor answering None has no reading newer than the last command (the twin's rig
    process running late): that cycle neither counts nor clears a disagreement.
    """

    def __init__(self, name: str, cards: Sequence[ActuatorOutputs], log: EventLog,
                 monitor: Callable[[], Sequence[float] | np.ndarray | None] | None = None,
                 tolerance_v: float = 0.1, confirm_cycles: int = 3, compiled: bool = True):
        super().__init__(name)
        self.compiled = compiled
        self.cards = list(cards)
        self.log = log
        self.monitor = monitor
        self.tolerance_v = float(tolerance_v)
        self.confirm_cycles = int(confirm_cycles)
        self.volts = self.declare_input("volts", Array(3))
        self.enable = self.declare_input("enable", Array(1))
        self.failed = self.declare_output("failed", Array(1))
        self.active_card = self.declare_output("active_card", Array(1))
        self._card = 0
        self._compiled_writes = [getattr(c, "compiled_write", None) for c in self.cards]
        self._st = np.zeros(_DRIVE_SIZE)
        self._st[_TOLERANCE] = self.tolerance_v
        self._st[_CONFIRM] = self.confirm_cycles
        self._last = self._st[_LAST:_LAST + 3]
        self._mismatch = self._st[_MISMATCH:_MISMATCH + 3]
        self._zero = np.zeros(3)
        self._measured = np.zeros(3)
        self._enabled = False
        # Compile (or load from numba's cache) now, not in the first cycle: the command as the
        # loop binds it (a read-only view), on a scratch state.
        probe = np.zeros(3)
        probe.flags.writeable = False
        for measured in (self._measured, probe):
            _drive_cycle(measured, True, probe, True, self._st.copy())
            # An int64 scratch with no watched words: the codes only, answer FC_STALE.
            _drive_cycle_write(measured, True, probe, self._st.copy(), _scratch_dac(),
                               np.zeros(3, np.uintc), np.zeros(FC_SIZE, np.int64), 0)
        if not compiled:
            _disagreement(self._measured, self._last.copy(), self._mismatch.copy(),
                          self.tolerance_v, self.confirm_cycles)

    def on_start(self) -> None:
        # Each card's compiled write (None for a card that has none, e.g. a duck-typed one).
        self._compiled_writes = [getattr(c, "compiled_write", None) for c in self.cards]
        self._card = 0
        bump()
        self.cards[0].enable()
        self._enabled = True
        bump()

    def _fail_over(self, t: float, channel: int, why: str) -> bool:
        old = self._card
        if old + 1 >= len(self.cards):
            self.failed.data[0] = 1.0
            bump()
            self.log.append(SafetyEvent(t, "fault", "drive_channel", Reaction.HARD_STOP,
                                        f"channel {channel} failed on the last card ({why})",
                                        {"card": old, "channel": channel}))
            return False
        try:
            self.cards[old].disable()
        except HardwareError:
            pass                               # the failing card may not even disable
        self._card = old + 1
        bump()
        self.cards[self._card].enable()
        self.active_card.data[0] = self._card
        self._mismatch[:] = 0
        self.log.append(SafetyEvent(t, "failover", f"dac_card_{old}", Reaction.FAILOVER,
                                    f"channel {channel} failed on card {old} ({why}); card "
                                    f"{self._card} took over", {"card": old,
                                                                   "channel": channel}))
        return True

    def _all_off(self) -> None:
        """Both cards failed on a channel: every card's outputs to 0 V and disabled, best
        effort (the failed channel may not obey; the others must not keep their last
        command while the supervisor hard-stops)."""
        for card in self.cards:
            try:
                card.write_volts(self._zero)
                card.disable()
            except HardwareError:
                pass
        self._enabled = False
        bump()

    def update(self, t: float, dt: float) -> int:
        if not self.compiled:
            return self._update_interpreted(t, dt)
        if self.failed.data[0] > 0.5:
            if self._enabled:
                self._all_off()
            return 0
        v = self.volts.data
        enabled = self.enable.data[0] > 0.5
        card = self.cards[self._card]
        measured = self.monitor() if enabled and self.monitor is not None and \
            self._enabled else None
        if measured is None:                   # None: no reading newer than the last command
            m, has = v, False
        elif type(measured) is np.ndarray and measured.dtype is _F64 \
                and measured.shape == _SHAPE3:
            m, has = measured, True            # the twin's amplifier inputs: read in place
        else:
            m, has = self._measured, True
            m[0], m[1], m[2] = measured[0], measured[1], measured[2]   # any sequence
        # The twin's cards (a compiled comedilib double): the monitor check, the command
        # stored as the last one and the card's write in one compiled call; the answers that
        # need Python (a failed channel, a refused or failed write) take the same steps below.
        compiled_write = self._compiled_writes[self._card]
        fast = compiled_write() if compiled_write is not None and enabled and self._enabled \
            else None
        if fast is not None:
            i, rc, done, python = _drive_cycle_write(m, has, v, self._st, *fast)
            return self.after_compiled_write(t, i, rc, done, python)
        # One compiled call: the monitor check, and the command stored as the last one.
        i = _drive_cycle(m, has, v, enabled, self._st)
        if i >= 0:
            if not self._fail_over(t, i, "amplifier input disagrees with the command"):
                self._all_off()
                return 0
            return self._finish_cycle(t, v, enabled)
        if enabled != self._enabled:
            try:
                if enabled:
                    card.enable()
                else:
                    card.disable()
            except HardwareError:
                self._last[:] = self._st[_BACKUP:_BACKUP + 3]     # as before this cycle
                raise
            self._enabled = enabled
            bump()
        if not enabled:
            return 0
        try:
            card.write_volts(v)
        except HardwareError as exc:
            self._last[:] = self._st[_BACKUP:_BACKUP + 3]         # nothing was written
            if not self._fail_over(t, -1, f"write failed: {exc}"):
                self._all_off()
                return 0
            self.cards[self._card].write_volts(v)
            self._last[:] = v
        return 0

    def after_compiled_write(self, t: float, i: int, rc: int, done: int, python: bool) -> int:
        """The cycle's rest after :func:`_drive_cycle_write` answered (``i`` the confirmed
        failed channel or -1, ``rc``/``done`` the write's answers, ``python`` whether they
        need the driver's Python): the block's own fast path and the fused cycle's drive
        stage (``rt.components.fused``) both end here."""
        if i < 0:
            if python:
                self._finish_write(t, self.cards[self._card], self.volts.data, rc, done)
            return 0
        if not self._fail_over(t, i, "amplifier input disagrees with the command"):
            self._all_off()
            return 0
        return self._finish_cycle(t, self.volts.data, True)

    def _finish_write(self, t: float, card: Any, v: np.ndarray, rc: int, done: int) -> None:
        """The compiled write's answer that needs Python: what ``card.write_volts`` raising
        leads to in :meth:`update` (a refusal propagates; a failed write fails over)."""
        try:
            card.finish_compiled_write(v, rc, done)
        except HardwareError as exc:
            self._last[:] = self._st[_BACKUP:_BACKUP + 3]         # nothing was written
            if not self._fail_over(t, -1, f"write failed: {exc}"):
                self._all_off()
                return
            self.cards[self._card].write_volts(v)
            self._last[:] = v

    def _finish_cycle(self, t: float, v: np.ndarray, enabled: bool) -> int:
        """The rest of a cycle after the monitor check, in Python (the previous code): the
        interpreted cycle's, and the compiled one's after a failover."""
        card = self.cards[self._card]
        if enabled != self._enabled:
            if enabled:
                card.enable()
            else:
                card.disable()
            self._enabled = enabled
            bump()
        if not enabled:
            self._last[:] = 0.0
            return 0
        try:
            card.write_volts(v)
        except HardwareError as exc:
            if not self._fail_over(t, -1, f"write failed: {exc}"):
                self._all_off()
                return 0
            self.cards[self._card].write_volts(v)
        self._last[:] = v
        return 0

    def _update_interpreted(self, t: float, dt: float) -> int:
        """The block as it ran before :func:`_drive_cycle` (``compiled=False``): the reference
        of ``tests/test_device_compiled.py``."""
        if self.failed.data[0] > 0.5:
            if self._enabled:
                self._all_off()
            return 0
        v = self.volts.data
        enabled = self.enable.data[0] > 0.5
        measured = self.monitor() if enabled and self.monitor is not None and \
            self._enabled else None
        if measured is not None:               # None: no reading newer than the last command
            m = self._measured
            m[0], m[1], m[2] = measured[0], measured[1], measured[2]   # any sequence
            i = _disagreement(m, self._last, self._mismatch, self.tolerance_v,
                              self.confirm_cycles)
            if i >= 0 and not self._fail_over(t, i, "amplifier input disagrees with the "
                                                    "command"):
                self._all_off()
                return 0
        return self._finish_cycle(t, v, enabled)
