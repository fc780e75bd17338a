"""The RT process's side of the rig process: device backends over shared memory ("twin_shm").

The twin runs in another process (``rt.twin.rig``, ``talus twin rig --shm NAME``), like the
rig's hardware. These backends implement ``rt.devices.interfaces`` over its segment
(``rt.twin.shm``) and keep the real driver code paths in the RT process:

* ``ShmEncoders``: the real ``Pcl833Encoders`` driver reads a local ``FakePcl833Port`` whose
  live counters are set from the shared counters before every read, so latch, byte reads and
  24-bit decoding run as on the rig. Positions are absolute (the rig's counters are homed).
* ``ShmActuators``: the real ``Pci1720Outputs`` driver writes to a local ``FakeComedi``; after
  every write / enable / disable the codes and the card's enable flag go to the command block,
  stamped with ``time.monotonic()`` (the rig applies them at that instant).
* ``ShmForceTorque``, ``ShmDigitalInputs``: the ATI sample and the stop inputs.
* ``ShmRig``: the handle they share: attach by name, ``feed_watchdog()`` (once per RT
  cycle), ``rearm()``, ``amplifier_state()``, ``rig_time()``, ``close()`` (safe twice).

Each backend takes ``rig``: a ``ShmRig`` to share (not closed by the backend) or a segment
name (the backend attaches its own handle and closes it). Reads raise ``HardwareError`` when
the rig stopped or has not published for ``rig_timeout_s`` (default 50 ms): a dead rig is a
sensor fault. Writes never check: like a DAC, they do not know whether anything listens.

One process writes commands (the RT process); within it a lock per segment serializes the
writers (actuator cards, watchdog feeding thread), as the seqlock needs a single writer.
"""
from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Self

import numpy as np

from rt.devices.interfaces import ActuatorOutputs, DigitalInputs, DigitalInputState, EncoderBank
from rt.devices.sampled_ft import SampledForceTorque
from rt.drivers.fake_comedi import FakeComedi
from rt.drivers.fake_pcl833 import FakePcl833Port
from rt.drivers.pci1720 import Pci1720Outputs
from rt.drivers.pcl833 import COUNTER_MASK, MIDPOINT, Pcl833Encoders
from rt.errors import ConfigurationError, HardwareError, InputError
from rt.twin import shm as layout

DEFAULT_RIG_TIMEOUT_S = 0.05


@dataclass(frozen=True)
class AmplifierState:
    """The amplifiers as the rig last published them.

    ``volts``: inputs actually applied (V, 0.0 exactly while disabled); ``watchdog``:
    "waiting" (never fed), "fed" or "tripped"; trip times are NaN until a trip; monotonic
    times are ``time.monotonic()`` seconds, comparable across processes.
    """

    volts: tuple[float, float, float]
    drives_enabled: bool
    watchdog: str
    tripped: bool
    trips: int
    trip_rig_time_s: float
    trip_monotonic_s: float
    feed_seen_monotonic_s: float
    rig_time_s: float
    rig_monotonic_s: float
    heartbeat: int


class ShmRig:
    """Handle on a running rig process's segment ``name`` (see module docstring).

    ``sensors`` holds typed views of the last consistent sensor snapshot (refreshed by
    :meth:`read`); the header values (``rig_pid``, ``epoch_monotonic_s``, ``period_s``,
    ``watchdog_timeout_s``, ``m_per_count``, ``command_limit_v``) are attributes.
    """

    def __init__(self, name: str, rig_timeout_s: float = DEFAULT_RIG_TIMEOUT_S):
        if not rig_timeout_s > 0.0:
            raise ConfigurationError(f"rig_timeout_s must be positive, got {rig_timeout_s}")
        self.seg: layout.RigSegment | None = layout.attach_segment(name)
        self.name = name
        self.rig_timeout_s = float(rig_timeout_s)
        h = self.seg.header
        self.rig_pid = int(h.rig_pid[0])
        self.epoch_monotonic_s = float(h.epoch_monotonic_s[0])
        self.period_s = float(h.period_s[0])
        self.watchdog_timeout_s = float(h.watchdog_timeout_s[0])
        self.m_per_count = float(h.m_per_count[0])
        self.command_limit_v = float(h.command_limit_v[0])
        self._lock = self.seg.writer_lock()
        self._pid = os.getpid()
        self._rig_state = h.rig_state          # shared view: the rig updates it at exit
        self._sensor_block = self.seg.sensors
        self._cmd_block = self.seg.commands
        self._cmd = self.seg.commands.shared   # shared views, written under the seqlock
        #: Views of the last consistent sensor snapshot (a private copy: never torn).
        self.sensors = self.seg.sensors.local
        self.read()

    # ------------------------------------------------------------------ sensors
    def read(self) -> bool:
        """Refresh ``sensors`` from the segment; False if no consistent copy could be made
        within ≈ 1 ms (the previous snapshot is kept)."""
        self._check_open()
        return self._sensor_block.read()

    def read_sensors(self) -> None:
        """Refresh ``sensors`` and check the rig is alive (``HardwareError`` if not)."""
        self._check_open()
        self._sensor_block.read()
        state = int(self._rig_state[0])
        if state != layout.RIG_RUNNING:
            raise HardwareError(
                f"the rig process on {self.name!r} is {layout.RIG_STATE_NAMES.get(state, state)}"
                f"; sensors are no longer updated")
        age = time.monotonic() - float(self.sensors.rig_monotonic_s[0])
        if age > self.rig_timeout_s:
            raise HardwareError(
                f"the rig process on {self.name!r} (pid {self.rig_pid}) has not published for "
                f"{age * 1e3:.1f} ms (limit {self.rig_timeout_s * 1e3:.0f} ms): is it running?")

    def rig_time(self) -> float:
        """Twin time of the latest snapshot (s since the rig's epoch)."""
        self.read()
        return float(self.sensors.rig_time_s[0])

    def heartbeat(self) -> int:
        """The rig's period counter in the latest snapshot."""
        self.read()
        return int(self.sensors.heartbeat[0])

    @property
    def rig_state(self) -> str:
        """"running", "stopped" (clean exit) or "failed" as the rig's header says."""
        self._check_open()
        state = int(self._rig_state[0])
        return layout.RIG_STATE_NAMES.get(state, str(state))

    def amplifier_state(self) -> AmplifierState:
        """The amplifier and watchdog state of the latest snapshot (refreshed here)."""
        self.read()
        s = self.sensors
        return AmplifierState(
            volts=(float(s.amp_volts[0]), float(s.amp_volts[1]), float(s.amp_volts[2])),
            drives_enabled=bool(s.drives_enabled[0]),
            watchdog=layout.WD_STATE_NAMES.get(int(s.watchdog_state[0]), "?"),
            tripped=bool(s.watchdog_tripped[0]),
            trips=int(s.trips[0]),
            trip_rig_time_s=float(s.trip_rig_time_s[0]),
            trip_monotonic_s=float(s.trip_monotonic_s[0]),
            feed_seen_monotonic_s=float(s.feed_seen_monotonic_s[0]),
            rig_time_s=float(s.rig_time_s[0]),
            rig_monotonic_s=float(s.rig_monotonic_s[0]),
            heartbeat=int(s.heartbeat[0]))

    def applied_volts(self) -> tuple[float, float, float] | None:
        """The amplifier inputs the rig applied after this handle's latest card write, or
        None while the rig has not yet read the commands of this handle's last completed cycle
        (its ``feed_seen`` is behind our feed counter).

        Why: the rig is a separate process; on a loaded machine it can run a period late, and a
        readback that predates the command is not a disagreement between command and output.
        The real current monitors are sampled after the DAC settles, so they are never stale.
        """
        self.read()
        s = self.sensors
        if int(s.feed_seen[0]) != int(self._cmd.feed[0]) or int(s.watchdog_tripped[0]):
            # Not yet read, or the watchdog holds every amplifier off: that is the watchdog's
            # fault (:meth:`watchdog_tripped`), not a channel's.
            return None
        return (float(s.amp_volts[0]), float(s.amp_volts[1]), float(s.amp_volts[2]))

    def watchdog_tripped(self) -> bool:
        """True while the amplifier watchdog holds the drives off (latched until a re-arm) and
        no re-arm of this handle is still on its way to the rig (the rig reads it at its next
        period; until then the outcome is not known)."""
        self.read()
        s = self.sensors
        return bool(s.watchdog_tripped[0]) and int(s.rearm_seen[0]) == int(self._cmd.rearm[0])

    # ------------------------------------------------------------------ commands
    def feed_watchdog(self) -> None:
        """Feed the amplifier watchdog (call once per RT cycle; ≈ 2 µs)."""
        self._check_open()
        cmd = self._cmd
        with self._lock:
            token = self._cmd_block.begin_write()
            cmd.feed[0] += 1
            cmd.writer_pid[0] = self._pid
            self._cmd_block.end_write(token)

    def rearm(self) -> None:
        """Ask the rig to re-arm a tripped watchdog; honoured only while it is being fed."""
        self._check_open()
        cmd = self._cmd
        with self._lock:
            token = self._cmd_block.begin_write()
            cmd.rearm[0] += 1
            cmd.writer_pid[0] = self._pid
            self._cmd_block.end_write(token)

    def write_card(self, card: int, enabled: bool, codes: Sequence[int]) -> None:
        """Publish card ``card``'s enable flag and DAC codes (channels 0-2, -1 = never
        written), stamped with ``time.monotonic()``. Used by ``ShmActuators``."""
        self._check_open()
        if card not in (0, 1):
            raise InputError(f"the rig has DAC cards 0 and 1, not {card}")
        cmd = self._cmd
        base = 3 * card
        with self._lock:
            token = self._cmd_block.begin_write()
            cmd.card_enabled[card] = enabled
            for ch in range(3):
                cmd.dac_codes[base + ch] = codes[ch]
            cmd.write_count[0] += 1
            cmd.write_monotonic_s[0] = time.monotonic()
            cmd.writer_pid[0] = self._pid
            self._cmd_block.end_write(token)

    # ------------------------------------------------------------------ lifecycle
    @property
    def closed(self) -> bool:
        return self.seg is None

    def _check_open(self) -> None:
        if self.seg is None:
            raise HardwareError(f"ShmRig {self.name!r} is closed; attach a new one")

    def close(self) -> None:
        """Detach from the segment (the rig keeps running). Safe to call twice."""
        seg, self.seg = self.seg, None
        if seg is None:
            return
        self._rig_state = None  # type: ignore[assignment]  # unpinned; closed: never read
        self._cmd = None  # type: ignore[assignment]
        self._sensor_block = None  # type: ignore[assignment]
        self._cmd_block = None  # type: ignore[assignment]
        seg.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _rig_handle(rig: ShmRig | str, rig_timeout_s: float) -> tuple[ShmRig, bool]:
    """(handle, owned): a shared ``ShmRig`` as is, a name attached here (owned)."""
    if isinstance(rig, ShmRig):
        if rig.closed:
            raise HardwareError(f"ShmRig {rig.name!r} is closed; attach a new one")
        return rig, False
    if isinstance(rig, str):
        return ShmRig(rig, rig_timeout_s), True
    raise ConfigurationError(f"rig must be a ShmRig or a shared-memory name, got {rig!r}")


class ShmEncoders(EncoderBank):
    """The real PCL-833 driver over the rig's counters (absolute positions, m).

    ``reset()`` behaves as the card's counter reset: positions restart at 0 from here, for
    this handle only (the rig's counters are untouched, so other readers keep absolute
    positions).
    """

    def __init__(self, rig: ShmRig | str, m_per_count: float | None = None,
                 rig_timeout_s: float = DEFAULT_RIG_TIMEOUT_S):
        self.rig, self._owns_rig = _rig_handle(rig, rig_timeout_s)
        try:
            mpc = self.rig.m_per_count if m_per_count is None else float(m_per_count)
            self.m_per_count = mpc
            self._counts = self.rig.sensors.counts     # view of the private snapshot
            self._offset = np.zeros(3, dtype=np.int64)  # counts added by reset(), mod 2**24
            self._port = FakePcl833Port(m_per_count=mpc)
            self._load_counts()
            # reset_on_open=False: the driver starts from the counters' current (homed) values.
            self._driver = Pcl833Encoders(port_io=self._port, m_per_count=mpc,
                                          reset_on_open=False)
        except BaseException:
            if self._owns_rig:
                self.rig.close()
            raise

    def _load_counts(self) -> None:
        self.rig.read_sensors()
        self._port.set_counts(self._counts, self._offset)      # one compiled call

    def read_counts(self) -> tuple[int, ...]:
        self._check_open()
        self._load_counts()
        return self._driver.read_counts()

    def read_positions_m(self, out: np.ndarray) -> np.ndarray:
        self._check_open()
        self._load_counts()
        return self._driver.read_positions_m(out)

    def reset(self) -> None:
        self._check_open()
        self.rig.read_sensors()
        self._driver.reset()
        counts = self._counts
        for axis in range(3):
            self._offset[axis] = (MIDPOINT - int(counts[axis])) & COUNTER_MASK

    def _close(self) -> None:
        self._driver.close()
        if self._owns_rig:
            self.rig.close()


class ShmActuators(ActuatorOutputs):
    """One of the rig's two PCI-1720 cards (``card`` 0 or 1) through the real driver.

    ``limit_v`` defaults to the rig's amplifier clamp (6 V). ``rig`` is also the watchdog:
    the RT loop must call ``rig.feed_watchdog()`` every cycle for the drives to stay on.
    """

    def __init__(self, rig: ShmRig | str, card: int = 0, limit_v: float | None = None,
                 rig_timeout_s: float = DEFAULT_RIG_TIMEOUT_S):
        if card not in (0, 1):
            raise HardwareError(f"the rig has DAC cards 0 and 1, not {card}")
        self.rig, self._owns_rig = _rig_handle(rig, rig_timeout_s)
        self.card = card
        self._codes = [layout.NO_CODE] * 3
        try:
            self._lib = FakeComedi(keep_log=False)
            limit = self.rig.command_limit_v if limit_v is None else limit_v
            self._driver = Pci1720Outputs(device=f"/dev/comedi{card}", lib=self._lib,
                                          limit_v=limit)
            self._publish()                    # the driver wrote 0 V to every channel
        except BaseException:
            if self._owns_rig:
                self.rig.close()
            raise

    def _publish(self) -> None:
        ao = self._lib.codes3.tolist()          # NO_CODE (-1) where never written
        codes = self._codes
        for ch in range(3):
            codes[ch] = ao[ch]
        self.rig.write_card(self.card, self._driver.enabled, codes)

    def enable(self) -> None:
        self._check_open()
        try:
            self._driver.enable()
        finally:
            self._publish()

    def disable(self) -> None:
        if self.closed:
            return
        try:
            self._driver.disable()
        finally:
            self._publish()

    @property
    def enabled(self) -> bool:
        return self._driver.enabled

    def write_volts(self, volts: Sequence[float] | np.ndarray) -> None:
        """Command ``volts`` (V) per axis: clamped, quantized (12 bit), published to the rig."""
        self._check_open()
        try:
            self._driver.write_volts(volts)
        finally:
            self._publish()

    @property
    def last_volts(self) -> list[float]:
        """The quantized voltages the last write produced (V)."""
        return list(self._driver.last_volts)

    @property
    def last_codes(self) -> list[int]:
        """The DAC codes of the last write."""
        return list(self._driver.last_codes)

    def _close(self) -> None:
        try:
            self._driver.close()               # 0 V and disabled ...
            if not self.rig.closed:
                self._publish()                # ... as the rig sees it
        finally:
            if self._owns_rig:
                self.rig.close()


class ShmForceTorque(SampledForceTorque):
    """The rig's ATI sensor. ``stale`` when its sample counter has not advanced for
    ``timeout_s`` of rig time; ``Wrench.t`` is the snapshot's ``time.monotonic()`` (s)."""

    def __init__(self, rig: ShmRig | str, timeout_s: float = 0.05,
                 rig_timeout_s: float = DEFAULT_RIG_TIMEOUT_S):
        super().__init__(timeout_s)
        self.rig, self._owns_rig = _rig_handle(rig, rig_timeout_s)
        self._s = self.rig.sensors

    def _sample(self):
        self.rig.read_sensors()
        s = self._s
        if not s.ft_valid[0]:
            return None
        return s.wrench, int(s.ft_sequence[0]), int(s.ft_status[0]), float(s.rig_monotonic_s[0])

    def _close(self) -> None:
        super()._close()
        if self._owns_rig:
            self.rig.close()


class ShmDigitalInputs(DigitalInputs):
    """The rig's stop inputs (hardware e-stop chain, hand-held stop)."""

    def __init__(self, rig: ShmRig | str, rig_timeout_s: float = DEFAULT_RIG_TIMEOUT_S):
        self.rig, self._owns_rig = _rig_handle(rig, rig_timeout_s)
        self._s = self.rig.sensors

    def read(self, out: DigitalInputState) -> DigitalInputState:
        self._check_open()
        self.rig.read_sensors()
        out.hardware_estop = bool(self._s.hardware_estop[0])
        out.hand_stop = bool(self._s.hand_stop[0])
        return out

    def _close(self) -> None:
        if self._owns_rig:
            self.rig.close()
