"""The real rig's loop assembly (``--backend rig``) run against the twin's register-level fakes.

Everything above the device files is the rig's code: the example rig config, the registry, the
PCL-833, PCI-1720 and comedi DI drivers, the RDT client, the loop in real time. Below them the
twin plays the physical world: its physics advances in its own thread (on the rig the world
does not wait for the loop), its PCL-833 port counts the sliders, its comedi doubles take the
DAC codes and the enable lines (relays choosing the card that drives the amplifiers), and its
ATI sensor is served over UDP RDT on loopback.
"""
from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from rt.ati.rdt_server import RdtServer
from rt.devices.interfaces import DigitalInputState
from rt.devices.rig_config import AmplifierMonitor, AtiRdt, RigConfig
from rt.drivers.comedi_dio import ComediDigitalInputs
from rt.drivers.fake_comedi import FakeComedi, FakeComediSystem
from rt.errors import BackendUnavailableError, ConfigurationError, HardwareError
from rt.model import RobotModel
from rt.position_loop import build_position_loop
from rt.rig_devices import rig_devices
from rt.safety.limits import RobotLimits
from rt.service import RtConfig, load_config
from rt.twin.twin import Twin

EXAMPLE = Path(__file__).resolve().parents[1] / "rt" / "data" / "rig_example.yaml"
HOLD_Q = (0.2, 0.2, 0.2)


class TwinWorld:
    """The twin behind the rig's device files (module docstring). ``dio`` is the digital I/O
    card (enable relays, stop inputs); ``max_excursion_m`` the largest slider distance from
    ``HOLD_Q`` seen by the physics thread; ``enabled_history`` the card-enable changes."""

    def __init__(self, rig: RigConfig, twin: Twin, rdt: RdtServer,
                 period_s: float = 0.0005) -> None:
        self.rig, self.twin, self.rdt, self.period_s = rig, twin, rdt, period_s
        stop = rig.stop_inputs
        self.dio = FakeComedi(dio_subdevices=(stop.subdevice,
                                              *{c.enable_line.subdevice for c in rig.dac_cards}))
        cards = {c.device: twin.dac_libs[k] for k, c in enumerate(rig.dac_cards)}
        self.comedi = FakeComediSystem({**cards, stop.device: self.dio})
        self.release_stops()
        self.max_excursion_m = 0.0
        self.enabled_history: list[tuple[float, list[bool]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="twin-world", daemon=True)

    def press_estop(self) -> None:
        s = self.rig.stop_inputs
        self.dio.set_input(s.subdevice, s.estop_channel, 1 - s.healthy_level)

    def release_stops(self) -> None:
        s = self.rig.stop_inputs
        for ch in (s.estop_channel, s.hand_stop_channel):
            self.dio.set_input(s.subdevice, ch, s.healthy_level)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        t0 = time.monotonic()
        twin, lines = self.twin, [c.enable_line for c in self.rig.dac_cards]
        while not self._stop.is_set():
            enabled = [self.dio.level(line.subdevice, line.channel) == int(line.active_high)
                       for line in lines]
            if enabled != twin.card_enabled:
                for k, on in enumerate(enabled):
                    twin.set_card_enabled(k, on)
                self.enabled_history.append((twin.t, enabled))
            twin.sync(time.monotonic() - t0)
            self.max_excursion_m = max(self.max_excursion_m,
                                       float(np.max(np.abs(twin.plant.q - HOLD_Q))))
            self._stop.wait(self.period_s)

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5.0)
        self.rdt.close()


def _test_rig(world_port: int) -> RigConfig:
    """The example rig, with the ATI at the loopback server and the counters reset while the
    sliders stand at HOLD_Q: the only changes a site would make in its own copy."""
    rig = load_config(EXAMPLE).rig
    assert rig is not None
    return rig.model_copy(update={
        "force_torque": AtiRdt(host="127.0.0.1", port=world_port),
        "encoders": rig.encoders.model_copy(update={"origin_m": HOLD_Q})})


def test_example_config_is_the_thesis_rig() -> None:
    cfg = load_config(EXAMPLE)
    assert cfg.backend == "rig" and cfg.rig is not None
    rig = cfg.rig
    assert rig.encoders.base == 0x220 and rig.encoders.input_mode == "x1"
    assert [c.device for c in rig.dac_cards] == ["/dev/comedi0", "/dev/comedi1"]
    assert all(c.range_index == 3 for c in rig.dac_cards)
    assert rig.force_torque.backend == "ati_rdt" and rig.force_torque.port == 49152
    assert RigConfig() == rig        # the documented defaults are the example's values


@pytest.mark.parametrize("change, message", [
    ({"dac_cards": [{"device": "/dev/comedi0"}, {"device": "/dev/comedi0"}]}, "distinct devices"),
    ({"dac_cards": [{"device": "/dev/comedi0"}, {"device": "/dev/comedi1"}]},
     "distinct enable lines"),
    ({"stop_inputs": {"subdevice": 1, "estop_channel": 0}}, "distinct from the enable lines"),
    ({"encoders": {"base": 0x400}}, "less than or equal"),
    ({"force_torque": {"backend": "ati_serial"}}, "ati_rdt"),
    ({"dac_cards": []}, "at least 1"),
    ({"encoders": {"sign": [1, 2, 1]}}, "sign"),
])
def test_bad_rig_configs_are_refused_naming_the_problem(change, message, tmp_path) -> None:
    base = {"schema_version": 1, "backend": "rig", "rig": change}
    with pytest.raises(Exception, match=message):
        RtConfig.model_validate(base)


def test_without_the_cards_the_rig_backend_says_what_is_missing() -> None:
    rig = RigConfig(encoders={"port_path": "/nonexistent/port"})
    with pytest.raises(BackendUnavailableError, match="/nonexistent/port does not exist"):
        rig_devices(rig, RobotModel.load().description)


def test_stop_inputs_are_fail_safe() -> None:
    card = FakeComedi(dio_subdevices=(0,))
    lib = FakeComediSystem({"/dev/comedi2": card})
    with ComediDigitalInputs("/dev/comedi2", 0, 0, 1, healthy_level=1, lib=lib) as stops:
        state = DigitalInputState()
        assert stops.read(state).hardware_estop and state.hand_stop   # unpowered chain: pressed
        card.set_input(0, 0, 1)
        card.set_input(0, 1, 1)
        assert not stops.read(state).hardware_estop and not state.hand_stop
        card.set_input(0, 1, 0)
        assert stops.read(state).hand_stop and not state.hardware_estop
        card.set_input(0, 1, 1)
        card.fail_dio_reads = True                                   # cannot see: stop
        assert stops.read(state).hardware_estop and state.hand_stop
        assert stops.read_failures == 2
    with pytest.raises(ConfigurationError, match="no line 9"):
        ComediDigitalInputs("/dev/comedi2", 0, 9, 1, lib=lib)
    with pytest.raises(BackendUnavailableError, match="/dev/comedi7 does not exist"):
        ComediDigitalInputs("/dev/comedi7", 0, 0, 1, lib=lib)


@contextlib.contextmanager
def running_rig(robot, monitor: bool = False) -> Iterator[tuple]:
    """The rig's loop holding HOLD_Q in real time on the twin's fakes: yields (loop, world,
    devices); with ``monitor`` the amplifier inputs are read back by an analog-input card."""
    twin = Twin(robot.description, seed=3)
    twin.place(HOLD_Q)
    rdt = RdtServer(lambda: twin.ati_sample, host="127.0.0.1", port=0)
    rig = _test_rig(rdt.port)
    if monitor:
        rig = rig.model_copy(update={"amplifier_monitor": AmplifierMonitor()})
    world = TwinWorld(rig, twin, rdt)
    world.comedi.devices[AmplifierMonitor().device] = FakeComedi(
        ai_source=lambda ch: float(twin.amp_volts[ch]))
    devices = None
    pl = None
    try:
        devices = rig_devices(rig, robot.description, port_io=twin.encoder_port,
                              comedi=world.comedi)
        # Tolerant of a late loop (CI shares its cores): 5 late cycles in a row, or the
        # tracking error of a held command, would stop the robot before the DAC fault this
        # test is about; those checks have their own tests.
        pl = build_position_loop(devices, "paden_panja", mode="realtime", start_program=False,
                                 model=robot, robot_limits=RobotLimits(
                                     deadline_overruns=1000, max_tracking_error_m=0.05))
        world.start()
        pl.loop.start()
        yield pl, world, devices
    finally:
        if pl is not None:
            pl.loop.stop()
            pl.graph.stop()
        if devices is not None and devices.close is not None:
            devices.close()
        world.close()


START_ATTEMPTS = 3


@contextlib.contextmanager
def settled_rig(robot, settle_s: float, monitor: bool = False) -> Iterator[tuple]:
    """``running_rig`` after ``settle_s`` of holding with nothing latched. The twin's physics
    runs in a thread of this process: on a loaded machine it can stall and then catch up in
    one step, which the loop rightly reads as an encoder jump and stops on. That start-up stop
    is not what these tests are about (the jump check has its own tests), so a start that
    latched a stop before the fault is injected is retried, at most ``START_ATTEMPTS`` times."""
    causes: list[dict] = []
    for _attempt in range(START_ATTEMPTS):
        with contextlib.ExitStack() as stack:
            pl, world, devices = stack.enter_context(running_rig(robot, monitor=monitor))
            time.sleep(settle_s)
            if not pl.supervisor.causes:
                yield pl, world, devices
                return
            causes.append(dict(pl.supervisor.causes))
    pytest.fail(f"every start latched a stop before the fault was injected: {causes}")


def test_rig_assembly_runs_two_seconds_on_the_fakes_and_fails_over(robot) -> None:
    with settled_rig(robot, settle_s=1.0) as (pl, world, devices):
        twin = world.twin
        healthy_wrench = pl.graph.output("force.wrench").copy()
        healthy_flags = pl.graph.output("force.flags").copy()
        truth = twin.ati_sample.wrench
        assert pl.graph.output("drive.active_card")[0] == 0
        twin.dac_libs[0].fail_writes = True           # card 0 dies mid-run
        deadline = time.monotonic() + 5.0             # a bound: the next write fails over
        while time.monotonic() < deadline and not any(
                e.kind == "failover" for e in pl.events.snapshot()):
            time.sleep(0.01)
        time.sleep(0.5)                               # then runs on card 1 for a while
        q_meas = pl.graph.output("encoders.q").copy()
        q_true = twin.plant.q.copy()
        mode_before_estop = float(pl.graph.output("supervisor.mode")[0])
        world.press_estop()
        time.sleep(0.2)
        mode_after_estop = float(pl.graph.output("supervisor.mode")[0])
    stats = pl.loop.stats()
    assert stats.cycles > 500        # ≈ 2200 at 1 kHz; a loaded machine stalls the loop
    # The encoders read the twin's sliders through the real driver: within a count or two
    # plus the motion between the two reads (the robot holds still).
    np.testing.assert_allclose(q_meas, q_true, atol=1e-4)
    # The ATI over RDT: streaming, fresh, the twin's own values (free motion: only its noise
    # and bias, < 1 N; a few ms between the two reads).
    assert devices.force.counters.received > 500 and healthy_flags[0] == 0.0
    np.testing.assert_allclose(healthy_wrench[:3], truth[:3], atol=3.0)
    # Failover: one event, card 1 drives, the relays followed (card 0 off, card 1 on, never
    # both at once); the e-stop then dropped both.
    failovers = [e for e in pl.events.snapshot() if e.kind == "failover"]
    assert len(failovers) == 1 and failovers[0].cause == "dac_card_0", \
        [e.as_dict() for e in pl.events.snapshot()]
    states = [h[1] for h in world.enabled_history]
    assert states[0] == [True, False] and [False, True] in states
    assert [True, True] not in states and states[-1] == [False, False]
    # Held through the fault: the physics never saw the sliders move more than 1 mm.
    assert world.max_excursion_m < 1e-3, world.max_excursion_m
    assert mode_before_estop < 3.0
    # The hardware e-stop input latches a hard stop with its cause.
    assert mode_after_estop == 3.0 and "estop_hardware" in pl.supervisor.causes


def test_rt_serve_rig_without_the_cards_fails_with_one_line(tmp_path, capsys) -> None:
    """The example config's backend is honoured (no --backend needed); a missing card is one
    clear error and exit code 2. The port device is pointed at a path that does not exist so
    the test never touches a real machine's I/O ports."""
    from talus.cli import main as talus_main

    text = EXAMPLE.read_text().replace("port_path: /dev/port", "port_path: /nonexistent/port")
    config = tmp_path / "rig.yaml"
    config.write_text(text)
    assert talus_main(["rt", "serve", "--config", str(config), "--seconds", "1"]) == 2
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and "/nonexistent/port does not exist" in out[0]
    assert talus_main(["rt", "serve", "--backend", "rig", "--seconds", "1"]) == 2
    assert "needs the config's rig: section" in capsys.readouterr().out


def test_rig_devices_with_the_ati_on_can(robot) -> None:
    """The CAN variant of the rig's sensor, on python-can's virtual bus (PLATFORM.md: no vcan
    here) with the twin's ATI answering as the Net F/T CAN device."""
    from rt.ati.can_client import AtiCanResponder
    from rt.devices.interfaces import Wrench
    from rt.devices.rig_config import AtiCan

    twin = Twin(robot.description, seed=4)
    twin.place(HOLD_Q)
    twin.sync(0.01)
    rig = _test_rig(1).model_copy(update={
        "force_torque": AtiCan(channel="talus-rig-can-test", interface="virtual")})
    world_rdt = RdtServer(lambda: twin.ati_sample, host="127.0.0.1", port=0)
    world = TwinWorld(rig, twin, world_rdt)
    with AtiCanResponder(lambda: twin.ati_sample, channel="talus-rig-can-test"):
        devices = rig_devices(rig, robot.description, port_io=twin.encoder_port,
                              comedi=world.comedi)
        try:
            devices.force.start()
            deadline = time.monotonic() + 5.0
            w = Wrench()
            while devices.force.read(w).stale and time.monotonic() < deadline:
                time.sleep(0.01)
            assert not w.stale
            np.testing.assert_allclose(w.as_tuple()[:3], twin.ati_sample.wrench[:3], atol=0.5)
            q = devices.encoders.read_positions_m(np.zeros(3))
            np.testing.assert_allclose(q, twin.plant.q, atol=2.5e-5)
        finally:
            devices.close()
            world.close()


def test_the_amplifier_monitor_catches_a_dead_dac_channel(robot) -> None:
    """A channel that accepts writes but outputs nothing: only the read-back sees it, and the
    second card takes over within a few cycles, the sliders held."""
    with settled_rig(robot, settle_s=0.7, monitor=True) as (pl, world, _devices):
        commanded = float(pl.graph.output("supervisor.volts")[1])
        assert abs(commanded) > 0.1          # holding against gravity: a dead 0 V is visible
        world.twin.faults.schedule("dac_dead", world.twin.t, card=0, channel=1)
        time.sleep(0.5)
        active = pl.graph.output("drive.active_card")[0]
    failovers = [e for e in pl.events.snapshot() if e.kind == "failover"]
    assert len(failovers) == 1 and "channel 1 failed on card 0" in failovers[0].message
    assert active == 1 and world.max_excursion_m < 1e-3, world.max_excursion_m


class _RecordingCard:
    """An ActuatorOutputs that remembers what it was told."""

    def __init__(self) -> None:
        self.volts = np.zeros(3)
        self.enabled = False

    def enable(self) -> None:
        self.enabled = True

    def disable(self) -> None:
        self.enabled = False

    def write_volts(self, volts) -> None:
        self.volts = np.array(volts, dtype=float)


def test_a_monitor_with_no_fresh_reading_neither_fails_over_nor_hides_a_dead_channel() -> None:
    """RedundantDrive: cycles whose monitor answers None (the rig process late) neither count
    nor clear a disagreement; fresh readings that disagree for ``confirm_cycles`` cycles in a
    row still fail over to the second card."""
    from rt.components.safety_blocks import RedundantDrive
    from rt.safety.events import EventLog

    readings: list = [None]                          # the first cycle: nothing read yet
    cards = [_RecordingCard(), _RecordingCard()]
    drive = RedundantDrive("drive", cards, EventLog(), monitor=lambda: readings.pop(0),
                           confirm_cycles=3)
    drive.enable._bind(np.ones(1), "test.enable")    # the inputs a builder would connect
    drive.volts._bind(np.array([1.0, -1.0, 0.5]), "test.volts")
    drive.on_start()
    drive.update(0.0, 0.001)
    readings.extend([None] * 50)                     # a long-late rig: no reading at all
    for k in range(50):
        drive.update(0.001 * (k + 1), 0.001)
    assert drive.active_card.data[0] == 0 and drive.failed.data[0] == 0.0
    dead = (1.0, 0.0, 0.5)                           # channel 1 outputs nothing
    readings.extend([dead, None, dead, None, None, dead])
    for k in range(5):
        drive.update(0.1 + 0.001 * k, 0.001)
    assert drive.active_card.data[0] == 0            # two fresh disagreements so far
    drive.update(0.2, 0.001)
    assert drive.active_card.data[0] == 1 and cards[1].enabled and not cards[0].enabled
    np.testing.assert_array_equal(cards[1].volts, (1.0, -1.0, 0.5))


def test_amplifier_monitor_reads_volts_and_refuses_bad_wiring() -> None:
    from rt.drivers.comedi_ai import ComediAmplifierMonitor

    card = FakeComedi(ai_source=lambda ch: (0.5, -1.25, 5.9)[ch])
    lib = FakeComediSystem({"/dev/comedi3": card})
    with ComediAmplifierMonitor("/dev/comedi3", lib=lib, volts_per_volt=2.0) as mon:
        np.testing.assert_allclose(mon.read_volts(), (1.0, -2.5, 11.8), atol=2 * 20 / 4095)
        card.fail_ai_reads = True
        with pytest.raises(HardwareError, match="comedi_data_read on /dev/comedi3"):
            mon.read_volts()
    with pytest.raises(ConfigurationError, match="no input 16"):
        ComediAmplifierMonitor("/dev/comedi3", channels=(0, 1, 16), lib=lib)
    with pytest.raises(ConfigurationError, match="no voltage range 7"):
        ComediAmplifierMonitor("/dev/comedi3", range_index=7, lib=lib)
