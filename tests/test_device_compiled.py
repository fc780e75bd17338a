"""The device side of the cycle compiled (issue 16): the encoder card's block read and decode,
the DAC's validation and codes, the force reader with its tare and the stop inputs give, cycle
by cycle, bit for bit what their interpreted references give on the same recorded inputs, with
faults spliced in (encoder jump, frozen counter, counter wrap, reset hold, stale / dropped /
saturated / non-finite force readings, refused tares, refused DAC commands, failing writes and
dead channels stopping the instruction list part-way)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.ati.rdt import STATUS_ANY_ERROR
from rt.components.safety_blocks import ForceReader, RedundantDrive, StopInputs
from rt.components.tare import Tare, TareRefusal, TareState
from rt.devices.interfaces import DigitalInputs, DigitalInputState
from rt.devices.sampled_ft import SampledForceTorque
from rt.drivers.fake_comedi import FakeComedi
from rt.drivers.fake_pcl833 import FakePcl833Port
from rt.drivers.pci1720 import Pci1720Outputs, code_to_volts
from rt.drivers.pcl833 import COUNTER_MODULUS, Pcl833Encoders
from rt.errors import HardwareError, InputError
from rt.safety.events import EventLog
from rt.twin.twin import Twin


def _recorded_twin(periods: int, seed: int = 3):
    """A recording of the twin under a drive: per period its motor encoders' positions (m),
    its ATI sample (wrench tuple, status, counter) and the volts commanded."""
    twin = Twin(seed=seed)
    twin.place((0.2, 0.2, 0.2))
    card = Pci1720Outputs(device="/dev/comedi0", lib=twin.dac_libs[0])
    card.enable()
    twin.set_card_enabled(0, True)
    enc, ati, volts = [], [], []
    for k in range(periods):
        t = k * 1e-3
        v = np.array([0.8 * math.sin(7.0 * t), -0.6 * math.sin(5.0 * t + 0.3),
                      0.7 * math.cos(9.0 * t)])
        card.write_volts(v)
        twin.sync(t + 1e-3)
        enc.append(twin.plant.encoder_q.copy())
        s = twin.ati_sample
        assert s is not None
        ati.append((s.wrench, s.status, s.ft_sequence))
        volts.append(v)
    return np.array(enc), ati, np.array(volts)


@pytest.fixture(scope="module")
def recorded():
    return _recorded_twin(900)


# --- encoders ----------------------------------------------------------------------------------

def _move_interpreted(port: FakePcl833Port, q: np.ndarray) -> None:
    for axis in range(3):                  # the per-axis Python model, the reference
        port.set_position_m(axis, float(q[axis]))


def test_encoder_block_read_and_decode_equal_the_byte_reads_bit_for_bit(recorded):
    enc_q = recorded[0]
    ports = (FakePcl833Port(sign=(1, -1, 1)), FakePcl833Port(sign=(1, -1, 1)))
    drivers = [Pcl833Encoders(port_io=p, sign=(1, -1, 1), origin_m=(0.01, 0.0, -0.2))
               for p in ports]
    for port in ports:
        port.set_positions_m(enc_q[0])
        port.set_count(2, COUNTER_MODULUS - 40)       # axis 2 crosses the 24-bit wrap
    out_c, out_i = np.zeros(3), np.zeros(3)
    seen_wrap = False
    for k, q in enumerate(enc_q):
        q = q + np.array([0.0, 0.0, -2e-4 * k / 100])  # and keeps going down through it
        compiled_port, interpreted_port = ports
        compiled_port.set_positions_m(q)
        _move_interpreted(interpreted_port, q)
        for port in ports:                             # faults, identical on both cards
            if k == 200:
                port.move_counts(0, 25_000)            # an encoder jump
            if k == 300:
                port.set_frozen(1)
            if k == 420:
                port.set_frozen(1, False)
            if k == 600:
                port.outb(port.base + 7, 0x04)         # channel 3 held in reset ...
            if k == 640:
                port.outb(port.base + 7, 0x00)         # ... and released
        drivers[0].read_positions_m(out_c)
        drivers[1].read_positions_m_interpreted(out_i)
        assert out_c.tolist() == out_i.tolist(), f"cycle {k}"
        assert compiled_port._st.tolist() == interpreted_port._st.tolist(), f"cycle {k}"
        assert drivers[0]._unwrap_state.tolist() == drivers[1]._unwrap_state.tolist()
        assert compiled_port.n_reads == interpreted_port.n_reads == 9 * (k + 1)
        seen_wrap |= compiled_port.count(2) > COUNTER_MODULUS - 30 and k > 0
    assert drivers[0]._unwrap[0].displacement > 25_000 - 100         # the jump is read
    assert seen_wrap or ports[0].count(2) < 1000


def test_a_block_read_of_an_undecoded_port_is_refused_as_inb_refuses_it():
    port = FakePcl833Port()
    ports = np.array([port.base + 2, port.base + 0, port.base + 0x40], dtype=np.int64)
    with pytest.raises(HardwareError) as block:
        port.read_block(ports, np.zeros(3, dtype=np.int64))
    with pytest.raises(HardwareError) as one:
        port.inb(port.base + 0x40)
    assert str(block.value) == str(one.value)
    assert port.n_reads == 3 + 1
    lax = FakePcl833Port(strict=False)
    out = np.zeros(4, dtype=np.int64)
    lax.read_block(np.array([lax.base + 3, lax.base + 14, lax.base + 0x40, lax.base + 2]), out)
    assert out.tolist() == [0, 0, 0xFF, lax.inb(lax.base + 2)]


def test_a_non_finite_position_is_refused_and_changes_nothing_after_it():
    port = FakePcl833Port()
    with pytest.raises(ValueError, match="nan"):
        port.set_positions_m(np.array([0.1, math.nan, 0.1]))
    assert port._encoder_index.tolist()[1:] == [0, 0]


# --- drive ---------------------------------------------------------------------------------------

def _outcome(call, volts):
    try:
        call(volts)
    except (HardwareError, InputError) as exc:
        return type(exc).__name__, str(exc)
    return None


def test_dac_write_equals_the_interpreted_write_bit_for_bit(recorded):
    volts = recorded[2]
    rng = np.random.default_rng(5)
    lsb = 20.0 / 4095
    edge = [np.array([6.0, -6.0, 6.0 + 1e-12]), np.array([-0.0, 0.0, 1e-300]),
            np.array([-10.0 + lsb * 0.5, 2048.5 * lsb - 10.0, 1e9]),   # exact half codes
            np.array([math.nan, 0.0, 0.0]), np.array([0.0, math.inf, 0.0]),
            np.array([0.1, 0.2, 0.3])]
    commands = [*volts, *(rng.uniform(-8.0, 8.0, (400, 3))), *edge]
    libs = (FakeComedi(), FakeComedi())
    cards = [Pci1720Outputs(lib=lib, limit_v=6.0) for lib in libs]
    for k, v in enumerate(commands):
        if k == 50:                                     # disabled: non-zero refused
            for c in cards:
                c.disable()
        if k == 60:
            for c in cards:
                c.enable()
        if k == 80:
            for lib in libs:
                lib.fail_writes = True                  # a failing card
        if k == 83:
            for lib in libs:
                lib.fail_writes = False
        if k in (90, 93, 96):                           # one dead channel, each in turn: the
            for lib in libs:                            # instruction list stops part-way
                lib.fail_channels = {(k - 90) // 3}
        if k == 99:
            for lib in libs:
                lib.fail_channels = set()
        a = _outcome(cards[0].write_volts, v)
        b = _outcome(cards[1].write_volts_interpreted, v)
        assert a == b, f"command {k}: {v}"
        assert cards[0].last_codes == cards[1].last_codes, f"command {k}"
        assert cards[0].last_volts == cards[1].last_volts, f"command {k}"
        assert cards[0].clamped == cards[1].clamped, f"command {k}"
        assert [w[1:] for w in libs[0].writes] == [w[1:] for w in libs[1].writes]
    assert sum(w[-1] == 4095 or w[-1] == 0 for w in libs[0].writes) == 0   # clamp at 6 V
    # A sequence other than a float64[3] array takes the interpreted path: same refusals.
    assert _outcome(cards[0].write_volts, [0.1, 0.2]) == \
        ("InputError", "write_volts needs 3 values, got 2")
    assert _outcome(cards[0].write_volts, np.zeros(4)) == \
        ("InputError", "write_volts needs 3 values, got 4")


class _Amplifiers:
    """The amplifier inputs the current monitors read back: each enabled card's last codes as
    volts, with faults: a dead channel, readings not yet fresh (None), a tuple reading."""

    def __init__(self, libs):
        self.libs = libs
        self.k = 0
        self.out = np.zeros(3)

    def __call__(self):
        k = self.k
        if k % 37 == 5:
            return None                                   # no reading newer than the command
        lib = self.libs[0] if k < 400 else self.libs[1]
        v = np.array([code_to_volts(lib.last_code.get(c, 2048)) for c in range(3)])
        if 150 <= k < 160 or 600 <= k:
            v[1] = 0.0                                    # channel 1 dead (card 0, then 1)
        if k % 11 == 0:
            return tuple(v.tolist())                      # a sequence, not an array
        self.out[:] = v
        return self.out


def _drive(compiled: bool):
    libs = (FakeComedi(), FakeComedi())
    cards = [Pci1720Outputs(device=f"/dev/comedi{i}", lib=lib) for i, lib in enumerate(libs)]
    log = EventLog()
    amps = _Amplifiers(libs)
    blk = RedundantDrive("drive", cards, log, monitor=amps, compiled=compiled)
    blk.volts.data = np.zeros(3)
    blk.enable.data = np.ones(1)
    blk.on_start()
    return blk, libs, amps, log


def test_redundant_drive_equals_the_interpreted_block_on_recorded_commands(recorded):
    """The recorded commands through the compiled and the interpreted drive: a dead channel
    (the monitor disagrees: failover to card 1 after 3 cycles), stale and tuple readings, a
    drive disable and enable, a failing write on card 1, then the last card's channel dead (hard
    stop, every card off). Every cycle: outputs, state, writes and events equal."""
    volts = np.concatenate([recorded[2], recorded[2][:300]])
    drives = [_drive(c) for c in (True, False)]
    for k, v in enumerate(volts):
        outcomes = []
        for blk, libs, amps, _ in drives:
            amps.k = k
            command = np.array(v)
            command.flags.writeable = False
            blk.volts.data = command
            blk.enable.data = np.array([0.0 if 250 <= k < 260 else 1.0])
            libs[1].fail_writes = k == 500
            try:
                blk.update(k * 1e-3, 1e-3)
                outcomes.append(None)
            except HardwareError as exc:
                outcomes.append(str(exc))
        (c, lc, _, ec), (i, li, _, ei) = drives
        assert outcomes[0] == outcomes[1], f"cycle {k}"
        assert c.failed.data.tolist() == i.failed.data.tolist(), f"cycle {k}"
        assert c.active_card.data.tolist() == i.active_card.data.tolist(), f"cycle {k}"
        assert c._st.tolist() == i._st.tolist() or c._last.tolist() == i._last.tolist() and \
            c._mismatch.tolist() == i._mismatch.tolist(), f"cycle {k}"
        assert [w[1:] for w in lc[0].writes + lc[1].writes] == \
            [w[1:] for w in li[0].writes + li[1].writes], f"cycle {k}"
        assert [(e.t, e.kind, e.cause, e.message) for e in ec.snapshot()] == \
            [(e.t, e.kind, e.cause, e.message) for e in ei.snapshot()], f"cycle {k}"
    causes = [e.cause for e in drives[0][3].snapshot()]
    assert causes[:1] == ["dac_card_0"] and "drive_channel" in causes
    assert drives[0][0].failed.data[0] == 1.0


@pytest.mark.parametrize("dead", [0, 2])
def test_redundant_drive_one_call_write_fails_over_on_a_dead_dac_channel(recorded, dead):
    """The drive's one compiled call (monitor check + the card's write on the compiled
    comedilib double) against the interpreted block when a DAC channel of card 0 dies
    mid-run (its list stops part-way: a failed write, failover to card 1 in the same cycle)
    and later one of card 1 (the last card: hard stop, every card off). Every cycle: outputs,
    state, codes, writes and events equal; the fast path ran before the fault."""
    drives = [_drive(c) for c in (True, False)]
    assert drives[0][0].cards[0].compiled_write() is not None
    for k, v in enumerate(recorded[2][:300]):
        outcomes = []
        for blk, libs, amps, _ in drives:
            amps.k = 5                       # no newer reading: the write path alone
            command = np.array(v)
            command.flags.writeable = False
            blk.volts.data = command
            if k == 100:
                libs[0].fail_channels.add(dead)
            if k == 200:
                libs[1].fail_channels = {dead}
            try:
                blk.update(k * 1e-3, 1e-3)
                outcomes.append(None)
            except HardwareError as exc:
                outcomes.append(str(exc))
        (c, lc, _, ec), (i, li, _, ei) = drives
        assert outcomes[0] == outcomes[1], f"cycle {k}"
        assert c.failed.data.tolist() == i.failed.data.tolist(), f"cycle {k}"
        assert c.active_card.data.tolist() == i.active_card.data.tolist(), f"cycle {k}"
        assert c._last.tolist() == i._last.tolist(), f"cycle {k}"
        assert [lib.ao.tolist() for lib in lc] == [lib.ao.tolist() for lib in li], f"cycle {k}"
        assert [w[1:] for w in lc[0].writes + lc[1].writes] == \
            [w[1:] for w in li[0].writes + li[1].writes], f"cycle {k}"
        assert [(e.t, e.kind, e.cause, e.message) for e in ec.snapshot()] == \
            [(e.t, e.kind, e.cause, e.message) for e in ei.snapshot()], f"cycle {k}"
    events = drives[0][3].snapshot()
    assert [(e.t, e.cause) for e in events] == [(0.1, "dac_card_0"), (0.2, "drive_channel")]
    assert f"channel {dead} failed" in events[0].message
    assert drives[0][0].failed.data[0] == 1.0


# --- force reader, tare, stop inputs --------------------------------------------------------

class _Replayed(SampledForceTorque):
    """A polled sensor replaying a recording: (wrench, counter, status, t) or None."""

    def __init__(self, samples):
        super().__init__(timeout_s=0.01)
        self.samples = samples
        self.k = 0

    def _sample(self):
        return self.samples[self.k]


def _force_stream(ati) -> list:
    """The twin's recorded ATI samples (tare on the unloaded platform first), with a dropout,
    a stale stretch (counter stopped), saturated samples, a NaN, a loaded and an unsteady
    stretch for refused tares."""
    out = []
    for k, (w, status, seq) in enumerate(ati):
        w = tuple(w)
        if 150 <= k < 185:
            out.append(None)                                  # dropout: no sample
            continue
        if 300 <= k < 330:
            seq = ati[299][2]                                 # counter stopped: stale
        if 400 <= k < 410:
            status |= STATUS_ANY_ERROR                        # saturated
        if k == 420:
            w = (math.nan, *w[1:])
        if 500 <= k < 700:
            w = (w[0], w[1], w[2] - 60.0, *w[3:])             # a foot resting: loaded
        if 750 <= k < 870:
            w = (w[0], w[1], w[2] + 8.0 * (-1) ** k, *w[3:])  # unsteady
        out.append((w, seq, status, k * 1e-3))
    return out


def _requests(n: int) -> np.ndarray:
    r = np.zeros(n)
    for start, stop in ((5, 40), (150, 200), (300, 350), (520, 560), (760, 800)):
        r[start:stop] = 1.0                                  # five tares asked
    return r


def test_force_reader_and_tare_equal_the_interpreted_block_bit_for_bit(recorded):
    stream = _force_stream(recorded[1])
    requests = _requests(len(stream))
    # A short tare (20 samples in at most 40 cycles), so the stream holds every outcome.
    blocks = [ForceReader("force", _Replayed(stream), Tare(samples=20, max_cycles=40),
                          compiled=c) for c in (True, False)]
    for b in blocks:
        b.sensor.start()
    states, refusals = set(), set()
    for k in range(len(stream)):
        for b in blocks:
            b.sensor.k = k
            request = np.array([requests[k]])
            request.flags.writeable = False
            b.tare_request.data = request
            b.update(k * 1e-3, 1e-3)
        c, i = blocks
        for port in ("wrench", "flags", "tare_out"):
            assert getattr(c, port).data.tolist() == getattr(i, port).data.tolist() or (
                np.array_equal(getattr(c, port).data, getattr(i, port).data, equal_nan=True)
                and np.signbit(getattr(c, port).data).tolist()
                == np.signbit(getattr(i, port).data).tolist()), f"cycle {k}: {port}"
        assert c.tare._buf.tolist() == i.tare._buf.tolist() or np.array_equal(
            c.tare._buf, i.tare._buf, equal_nan=True), f"cycle {k}"
        assert (c.tare.reason, c.tare.refusal, c.tare.mean_force_n == i.tare.mean_force_n or
                math.isnan(i.tare.mean_force_n)) == (i.tare.reason, i.tare.refusal, True)
        states.add(TareState(int(c.tare_out.data[0])))
        refusals.add(c.tare.refusal)
    # The stream exercised every outcome: done, refused (no reading, loaded, unsteady).
    assert states == {TareState.NONE, TareState.MEASURING, TareState.DONE, TareState.REFUSED}
    assert refusals == set(TareRefusal)
    assert blocks[0].tare.count >= 1


def test_the_sensor_array_read_equals_the_wrench_read(recorded):
    stream = _force_stream(recorded[1])
    a, b = _Replayed(stream), _Replayed(stream)
    from rt.devices.interfaces import FT_READ_SIZE, Wrench, new_ft_reading
    raw, w = new_ft_reading(), Wrench()
    for s in (a, b):
        s.start()
    for k in range(len(stream)):
        a.k = b.k = k
        a.read_array(raw)
        b.read(w)
        expect = [w.fx, w.fy, w.fz, w.tx, w.ty, w.tz, w.t, w.sequence, w.status,
                  float(w.stale), float(w.saturated)]
        assert len(expect) == FT_READ_SIZE
        assert np.array_equal(raw, expect, equal_nan=True), f"cycle {k}"


class _Inputs(DigitalInputs):
    def __init__(self):
        self.levels = (False, False)

    def read(self, out: DigitalInputState) -> DigitalInputState:
        out.hardware_estop, out.hand_stop = self.levels
        return out

    def _close(self) -> None:
        pass


def test_stop_inputs_through_the_array_read():
    dev = _Inputs()
    blk = StopInputs("stops", dev)
    for levels in ((False, False), (True, False), (False, True), (True, True)):
        dev.levels = levels
        blk.update(0.0, 1e-3)
        assert blk.stops.data.tolist() == [float(levels[0]), float(levels[1])]


def _device_kernels():
    from rt.components import safety_blocks, tare
    from rt.devices import sampled_ft
    from rt.drivers import kernels as dk

    return (dk.fake_pcl833_read, dk.fake_pcl833_move, dk.fake_pcl833_positions,
            dk.fake_pcl833_set_counts, dk.pcl833_decode, dk.pci1720_codes, tare.tare_cycle,
            safety_blocks._force_cycle, safety_blocks._drive_cycle, sampled_ft._read_sample)


def test_no_device_kernel_compiles_inside_a_cycle():
    """The device kernels are compiled at construction for the argument types the loop passes
    (read-only port views, the twin's sample tuple): a first-cycle compile stalls the loop."""
    from rt.position_loop import build_protocol_loop, build_sim_position_loop, sim_devices
    from rt.twin.environment import FreeMotion
    from rt.twin.twin import SimClock

    pl = build_sim_position_loop("paden_panja", duration_s=1.0)
    clock = SimClock()
    twin = Twin(None, FreeMotion(), clock=clock)
    twin.place((0.2, 0.2, 0.2))
    hybrid = build_protocol_loop(sim_devices(twin, clock), controller="paden_panja")
    before = [len(k.signatures) for k in _device_kernels()]
    pl.loop.run(cycles=30)
    hybrid.loop.run(cycles=30)
    pl.graph.stop()
    hybrid.graph.stop()
    assert [len(k.signatures) for k in _device_kernels()] == before
    assert min(before) >= 1
