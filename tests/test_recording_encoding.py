"""Recording encodings (issue 16): fixed-point protobuf (``talus.v4``, today's, one message per
cycle: tests/test_recording_v4.py; ``talus.v3``: three 1 kHz channels, no time in the
payloads, the drive command as the DAC's code) round trip within half a quantum, the
time rebuilt from the log time exactly as ``talus.v2`` stored it, read by the official mcap
reader with ``mcap_protobuf``; recordings of the previous encodings (``talus.v2`` with
``t_us``, float32 protobuf, JSON before issue 16) still read everywhere; the size per hour of
a generated 10 s recording."""
from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap_protobuf.decoder import DecoderFactory

from rt.drivers.pci1720 import code_to_volts, volts_to_code
from rt.errors import InputError
from rt.recording.channels import (
    ANKLE_PROTO,
    ANKLE_PROTO_V2,
    CHANNELS,
    EVENTS,
    JSONSCHEMA_METADATA_KEY,
    METADATA,
    PROTOS,
    REFERENCE,
    REFERENCE_PROTO,
    REFERENCE_PROTO_F32,
    REFERENCE_PROTO_V2,
    STATE,
    STATE_PROTO,
    STATE_PROTO_F32,
    STATE_PROTO_V2,
    TIME_ORIGIN_NS_KEY,
    WRENCH,
    WRENCH_PROTO,
    WRENCH_PROTO_V2,
    Encoding,
    LoopClock,
)
from rt.recording.protobuf_codec import ProtoCodecError
from rt.recording.reader import export_csv, read_recording, recover
from rt.recording.writer import STATE_LAYOUT, SessionRecorder
from rt.safety.events import Reaction, SafetyEvent
from talus.cli import main as talus_main

RATE_HZ = 1000
META = {"protocol_name": "sine_fz", "protocol_version": "1",
        "parameters": {"kind": "sine_fz", "amplitude_n": 100.0, "mean_n": 300.0},
        "patient_id": "P-0001", "robot_description": "talus_nominal"}
START_WALL_NS = 1_790_000_000_000_000_000
ENCODER_M = 2e-5            # robot_nominal.yaml encoder.m_per_count


class _Ring:
    """A RingSource over a precomputed table of rows (t first)."""

    def __init__(self, rows: np.ndarray):
        self.rows = rows
        self.written = 0

    def drain(self, start: int) -> tuple[np.ndarray, int]:
        end = self.written
        return self.rows[start:end].copy(), end


def session_signals(seconds: float, seed: int = 0) -> dict[str, np.ndarray]:
    """A session-like 1 kHz stream: the platform moving ±10 mm at 0.5 Hz, encoder-quantized
    positions, a noisy velocity estimate, controller forces with noise, the ATI's forces
    (300 ± 100 N at 1 Hz with 1.5 N noise) — the noise is what compression cannot remove."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE_HZ)
    t = np.arange(n) / RATE_HZ
    phase = np.arange(3) * 2 * np.pi / 3
    q_ref = 0.2 + 0.01 * np.sin(2 * np.pi * 0.5 * t[:, None] + phase)
    q = np.round((q_ref + rng.normal(0, 3e-5, (n, 3))) / ENCODER_M) * ENCODER_M
    qd = np.gradient(q_ref, 1.0 / RATE_HZ, axis=0) + rng.normal(0, 2e-3, (n, 3))
    tau = 150.0 + 2e4 * (q_ref - q) + rng.normal(0, 2.0, (n, 3))
    volts = np.clip(tau / 400.0, -10, 10)
    state = np.hstack([t[:, None], q, qd, q_ref, tau, volts])
    fz_ref = 300.0 + 100.0 * np.sin(2 * np.pi * t)
    wrench = np.column_stack([t, rng.normal(0, 0.3, n), rng.normal(0, 0.3, n),
                              -(fz_ref + rng.normal(0, 1.5, n)), rng.normal(0, 0.01, (n, 3))])
    return {"state": state, "wrench": wrench, "fz_ref": fz_ref}


def record(path: Path, sig: dict[str, np.ndarray], encoding: str, events: bool = True,
           chunk_size: int = 256 * 1024) -> dict:
    """Record ``sig`` as a session does: state from a ring, wrench and reference queued,
    paced so nothing is dropped; a safety event every second."""
    ring = _Ring(sig["state"])
    rec = SessionRecorder(path, META, start_wall_ns=START_WALL_NS, encoding=encoding,
                          chunk_size=chunk_size)
    rec.attach_state_ring(ring, start=0)
    n = len(sig["state"])
    for k0 in range(0, n, 500):
        for k in range(k0, min(n, k0 + 500)):
            w = sig["wrench"][k]
            t = float(w[0])
            rec.wrench(t, *map(float, w[1:]), stale=k % 7 == 0, saturated=k % 11 == 0)
            rec.reference(t, force=[0.0, 0.0, float(sig["fz_ref"][k])],
                          phase="play" if k > 100 else "approach")
            if events and k % 1000 == 999:
                rec.event(SafetyEvent(t=t, kind="warn", cause="force_high",
                                      reaction=Reaction.WARN, message="force near its limit",
                                      values={"fz_n": float(w[3])}).as_dict())
        ring.written = min(n, k0 + 500)
        assert rec.wait_for_room(0.01, timeout_s=30.0)
    summary = rec.close()
    assert summary["complete"] and summary["dropped_total"] == 0
    return summary


def f32(x: float) -> float:
    return float(np.float32(x))


#: Quanta of the fixed-point state fields (rt.recording.channels), SI units per count.
STATE_QUANTA = {"t": 1e-6, "q": 1e-6, "qd": 1e-6, "q_ref": 1e-6, "tau": 1e-3, "volts": 1e-3}
WRENCH_QUANTA = {"t": 1e-6, "fx": 1e-3, "fy": 1e-3, "fz": 1e-3, "tx": 1e-3, "ty": 1e-3,
                 "tz": 1e-3}


def fixed(x: float, quantum: float) -> float:
    """What a fixed-point field reads back: the nearest count, as the decimal double."""
    per = round(1.0 / quantum)
    return float(np.rint(x * per)) / per


def dac(v: float) -> float:
    """What ``talus.v3``'s ``volts_dac`` reads back: the voltage of the PCI-1720's code."""
    return code_to_volts(volts_to_code(v))


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The same 2 s session recorded in every encoding: fixed-point protobuf v4 (today's), v3,
    v2, float32 protobuf and JSON (the previous ones)."""
    d = tmp_path_factory.mktemp("enc")
    sig = session_signals(2.0)
    out = {"sig": sig}
    for enc in ("protobuf", "protobuf-v3", "protobuf-v2", "protobuf-f32", "json"):
        out[enc] = d / f"{enc}.mcap"
        out[enc + "_summary"] = record(out[enc], sig, enc)
    return out


# ------------------------------------------------------------------ round trip, every channel

#: talus.v4's quanta where they differ from v3's (rt.recording.channels: 0.1 mm/s, 0.1 N,
#: the ATI's forces and the reference force 1/16 N, its torques 2 mN·m).
V4_STATE_QUANTA = {**STATE_QUANTA, "qd": 1e-4, "tau": 0.1}
V4_WRENCH_QUANTA = {**WRENCH_QUANTA, "fx": 1 / 16, "fy": 1 / 16, "fz": 1 / 16, "tx": 2e-3,
                    "ty": 2e-3, "tz": 2e-3}
QUANTA = {"protobuf": (V4_STATE_QUANTA, V4_WRENCH_QUANTA, 1 / 16),
          "protobuf-v3": (STATE_QUANTA, WRENCH_QUANTA, 1e-3),
          "protobuf-v2": (STATE_QUANTA, WRENCH_QUANTA, 1e-3)}


@pytest.mark.parametrize("enc", ["protobuf", "protobuf-v3", "protobuf-v2"])
def test_every_channel_round_trips_through_fixed_point_protobuf(pair: dict, enc: str) -> None:
    """Each value is its nearest count of the field's quantum: within half a quantum (v3:
    0.5 µm, 0.5 µm/s, 0.5 mN, 0.5 mN·m, 0.5 µs; v2's volts 0.5 mV; v4: 0.05 mm/s, 0.05 N for
    tau, 12.5 mN for the ATI's and the reference's forces), bools exact; encoder positions
    (multiples of 20 µm) exactly; v3's and v4's volts are the voltage of the DAC's code for
    the command (within half a code, 2.44 mV); their t, rebuilt from the log time, is v2's
    t_us."""
    sig = pair["sig"]
    state_quanta, wrench_quanta, ref_quantum = QUANTA[enc]
    data = read_recording(pair[enc])
    assert pair[enc + "_summary"]["encoding"] == enc
    n = len(sig["state"])
    assert len(data[STATE]) == len(data[WRENCH]) == len(data[REFERENCE]) == n
    for k in range(0, n, 37):
        row = sig["state"][k]
        m = data[STATE][k]
        for name, cols in (("t", 0), ("q", 1), ("qd", 4), ("q_ref", 7), ("tau", 10),
                           ("volts", 13)):
            quantum = state_quanta[name]
            values = row[cols:cols + (1 if name == "t" else 3)]
            got = np.atleast_1d(np.array(m[name], dtype=float))
            if name == "volts" and enc != "protobuf-v2":
                assert got.tolist() == [dac(v) for v in values]
                assert np.all(np.abs(got - values) <= 20 / 4095 / 2 * (1 + 1e-9))
                continue
            assert got.tolist() == [fixed(v, quantum) for v in values], name
            assert np.all(np.abs(got - values) <= quantum / 2 * (1 + 1e-9)), name
        assert m["q"] == pytest.approx(row[1:4], abs=1e-12)     # encoder counts: exact
        w = sig["wrench"][k]
        assert data[WRENCH][k] == {
            **{key: fixed(w[i], wrench_quanta[key]) for i, key in enumerate(wrench_quanta)},
            "stale": k % 7 == 0, "saturated": k % 11 == 0}
        assert data[REFERENCE][k] == {"t": fixed(w[0], 1e-6),
                                      "force": [0.0, 0.0, fixed(sig["fz_ref"][k],
                                                               ref_quantum)],
                                      "phase": "play" if k > 100 else "approach"}
    # The rare channels stay JSON, exact.
    assert len(data[EVENTS]) == n // 1000 and data[EVENTS][0]["values"] == {
        "fz_n": float(sig["wrench"][999][3])}
    assert data[METADATA][0]["parameters"] == META["parameters"]


def test_every_channel_round_trips_through_float32_protobuf(pair: dict) -> None:
    """The previous encoding (float32, t double) is still written on request and read."""
    sig = pair["sig"]
    data = read_recording(pair["protobuf-f32"])
    assert pair["protobuf-f32_summary"]["encoding"] == "protobuf-f32"
    n = len(sig["state"])
    assert len(data[STATE]) == len(data[WRENCH]) == len(data[REFERENCE]) == n
    for k in range(0, n, 37):
        row = sig["state"][k]
        m = data[STATE][k]
        assert m["t"] == row[0]                                   # double: exact
        for name, cols in (("q", 1), ("qd", 4), ("q_ref", 7), ("tau", 10), ("volts", 13)):
            # float32: the nearest float32, i.e. within half a float32 step of the value.
            assert m[name] == [f32(v) for v in row[cols:cols + 3]], name
            step = np.spacing(np.float32(np.abs(row[cols:cols + 3]))).astype(float)
            assert np.all(np.abs(np.array(m[name]) - row[cols:cols + 3]) <= step / 2)
        w = sig["wrench"][k]
        assert data[WRENCH][k] == {"t": w[0], "fx": f32(w[1]), "fy": f32(w[2]),
                                   "fz": f32(w[3]), "tx": f32(w[4]), "ty": f32(w[5]),
                                   "tz": f32(w[6]), "stale": k % 7 == 0,
                                   "saturated": k % 11 == 0}
        assert data[REFERENCE][k] == {"t": w[0], "force": [0.0, 0.0, f32(sig["fz_ref"][k])],
                                      "phase": "play" if k > 100 else "approach"}
    # The rare channels stay JSON, exact.
    assert len(data[EVENTS]) == n // 1000 and data[EVENTS][0]["values"] == {
        "fz_n": float(sig["wrench"][999][3])}
    assert data[METADATA][0]["parameters"] == META["parameters"]


def test_the_json_encoding_is_exact_and_reads_as_the_same_dicts(pair: dict) -> None:
    pb, js = read_recording(pair["protobuf-f32"]), read_recording(pair["json"])
    fx, v4 = read_recording(pair["protobuf-v3"]), read_recording(pair["protobuf"])
    assert pair["json_summary"]["encoding"] == "json"
    assert set(pb) == set(js)
    for topic in (STATE, WRENCH, REFERENCE):
        assert len(pb[topic]) == len(js[topic])
        for a, b in zip(pb[topic][::101], js[topic][::101]):
            assert a.keys() == b.keys()
            for key, va in a.items():
                vb = b[key]
                if isinstance(vb, list):
                    assert va == [f32(x) for x in vb], key
                elif isinstance(vb, float) and key != "t":
                    assert va == f32(vb), key
                else:
                    assert va == vb, key
        # Fixed point: the same keys, every number within half its quantum of JSON's (the
        # DAC's half code for v3's and v4's volts).
        for enc, fixed_point in (("protobuf-v3", fx), ("protobuf", v4)):
            state_quanta, wrench_quanta, ref_quantum = QUANTA[enc]
            quanta = {**state_quanta, **wrench_quanta, "force": ref_quantum}
            for a, b in zip(fixed_point[topic][::101], js[topic][::101]):
                assert a.keys() == b.keys()
                for key, vb in b.items():
                    va = a[key]
                    if isinstance(vb, (float, list)):
                        atol = 10 / 4095 if key == "volts" else quanta[key] / 2
                        assert np.allclose(va, vb, rtol=0, atol=atol * (1 + 1e-9)), (
                            enc, topic, key)
                    else:
                        assert va == vb, key
    # Events carry the host wall clock of their creation (each recording made its own).
    assert [{**e, "wall": 0} for e in pb[EVENTS]] == [{**e, "wall": 0} for e in js[EVENTS]]
    assert [{**e, "wall": 0} for e in fx[EVENTS]] == [{**e, "wall": 0} for e in js[EVENTS]]
    assert [{**e, "wall": 0} for e in v4[EVENTS]] == [{**e, "wall": 0} for e in js[EVENTS]]


def test_every_field_of_the_protobuf_messages_round_trips() -> None:
    """Optional fields too (qd_ref, position, mode), and non-finite values read as None, as
    the JSON recordings' nulls."""
    ref = {"t": 12.345, "force": [1.5, -2.25, 300.0], "position": [0.2, 0.21, 0.22],
           "phase": "hold", "mode": "force"}
    got = REFERENCE_PROTO_F32.decode(REFERENCE_PROTO_F32.encode(ref))
    assert got == {**ref, "force": [1.5, -2.25, 300.0], "position": [f32(0.2), f32(0.21),
                                                                     f32(0.22)]}
    # Fixed point: decimal values on the quantum come back as the same doubles (v3 without
    # the time: the reader adds it from the log time).
    no_t = {k: v for k, v in ref.items() if k != "t"}
    assert REFERENCE_PROTO_V2.decode(REFERENCE_PROTO_V2.encode(ref)) == ref
    assert REFERENCE_PROTO.decode(REFERENCE_PROTO.encode(ref)) == no_t
    assert REFERENCE_PROTO.decode(REFERENCE_PROTO.encode(
        {"t": 1.0, "force": [0.0001, 0.0006, -2.0004]})) == {"force": [0.0, 0.001, -2.0]}
    assert REFERENCE_PROTO_V2.decode(REFERENCE_PROTO_V2.encode({"t": 1.0})) == {"t": 1.0}
    assert REFERENCE_PROTO.decode(REFERENCE_PROTO.encode({"t": 1.0})) == {}
    for proto in (STATE_PROTO, STATE_PROTO_V2, STATE_PROTO_F32):
        state = {"t": 0.001, "q": [0.1, 0.2, math.nan], "qd": [0.0, 0.0, math.inf],
                 "q_ref": [0.1, 0.2, 0.3], "tau": [1.0, 2.0, 3.0], "volts": [-1.0, 0.0, 1.0],
                 "qd_ref": [0.5, 0.5, 0.5]}
        got = proto.decode(proto.encode(state))
        cast = f32 if proto is STATE_PROTO_F32 else float
        assert got["q"] == [cast(0.1), cast(0.2), None] and got["qd"] == [0.0, 0.0, None]
        assert got["qd_ref"] == [0.5, 0.5, 0.5]
        assert got.get("t") == (None if proto is STATE_PROTO else 0.001)
        assert got["volts"] == ([dac(-1.0), dac(0.0), dac(1.0)] if proto is STATE_PROTO
                                else [-1.0, 0.0, 1.0])
    w = {"t": 2.0, "fx": 1.0, "fy": 2.0, "fz": -300.0, "tx": 0.0, "ty": 0.0, "tz": 0.0,
         "stale": False, "saturated": True}
    assert WRENCH_PROTO_V2.decode(WRENCH_PROTO_V2.encode(w)) == w
    assert WRENCH_PROTO.decode(WRENCH_PROTO.encode(w)) == {k: v for k, v in w.items()
                                                           if k != "t"}
    # A value beyond the type's range is refused naming the field (a ring's is marked as
    # not finite: the writer cannot refuse it).
    with pytest.raises(ProtoCodecError, match="tau_mn"):
        STATE_PROTO.encode({**state, "tau": [1e7, 0.0, 0.0]})
    rows = np.zeros((1, 16))
    rows[0, 10] = 1e7
    rows[0, 13] = math.nan
    got = STATE_PROTO.decode(STATE_PROTO.row_encoder(STATE_LAYOUT.fields)(rows)[0])
    assert got["tau"] == [None, 0.0, 0.0] and got["volts"] == [None, dac(0.0), dac(0.0)]
    ankle = {"t": 0.01, "plantarflexion_deg": 12.5, "inversion_deg": -3.25,
             "abduction_deg": 0.5, "plantarflexion_torque_nm": 20.0,
             "inversion_torque_nm": -1.5, "abduction_torque_nm": 0.25,
             "centre_displacement_mm": [1.0, -0.5, 0.125], "platform_roll_deg": 2.0,
             "platform_pitch_deg": -8.0}
    assert ANKLE_PROTO_V2.decode(ANKLE_PROTO_V2.encode(ankle)) == ankle    # exact in float32
    assert ANKLE_PROTO.decode(ANKLE_PROTO.encode(ankle)) == {k: v for k, v in ankle.items()
                                                             if k != "t"}


def test_the_protobuf_library_reads_our_bytes_and_we_read_its() -> None:
    """Our hand-made wire bytes are protobuf: the field library parses them to the same
    values (fixed point: the counts, under the wire names with units), and what it
    serializes (defaults omitted, another field order) we decode."""
    factory = DecoderFactory()
    from mcap.records import Schema

    state = {"t": 0.0, "q": [0.1, 0.2, 0.3], "qd": [0.0] * 3, "q_ref": [0.1, 0.2, 0.3],
             "tau": [0.0, 5.0, 0.0], "volts": [0.0] * 3}
    ref = {"t": 0.5, "position": [0.1, 0.2, 0.3], "mode": "position"}
    cases = ((STATE_PROTO_F32, state), (REFERENCE_PROTO_F32, ref), (STATE_PROTO_V2, state),
             (REFERENCE_PROTO_V2, ref), (STATE_PROTO, state), (REFERENCE_PROTO, ref))
    for schema_id, (proto, msg) in enumerate(cases, start=1):
        schema = Schema(id=schema_id, name=proto.name, encoding="protobuf",
                        data=proto.file_descriptor_set)
        decode = factory.decoder_for("protobuf", schema)
        assert decode is not None
        parsed = decode(proto.encode(msg))
        for key, value in msg.items():
            if key == "t" and not proto.carries_t:
                continue                          # v3: the time is the message's log time
            field = next(f for f in proto.fields if f.dict_key == key)
            got = getattr(parsed, field.name)
            got = list(got) if isinstance(value, list) else got
            if field.code_range is not None:      # the DAC's codes
                want = [volts_to_code(v) for v in value]
            elif field.scale is not None:         # counts of the quantum
                per = round(1 / field.scale)
                want = [round(v * per) for v in value] if isinstance(value, list) \
                    else round(value * per)
            else:
                want = [f32(v) for v in value] if isinstance(value, list) else value
            assert got == want, (proto.name, key)
        theirs = parsed.SerializeToString()      # t = 0 omitted: not our fixed layout
        if proto in (STATE_PROTO_V2, STATE_PROTO_F32):
            assert theirs != proto.encode(msg)
        elif proto is STATE_PROTO:                # no zero scalar left: the same bytes
            assert theirs == proto.encode(msg)
        assert proto.decode(theirs) == proto.decode(proto.encode(msg))


def test_bad_messages_are_refused_naming_the_field(tmp_path: Path) -> None:
    with pytest.raises(ProtoCodecError, match="q_ref"):
        STATE_PROTO.encode({"t": 0.0, "q": [0.0] * 3, "qd": [0.0] * 3, "tau": [0.0] * 3,
                            "volts": [0.0] * 3})
    with pytest.raises(ProtoCodecError, match="3 values"):
        STATE_PROTO.encode({"t": 0.0, "q": [0.0] * 2, "qd": [0.0] * 3, "q_ref": [0.0] * 3,
                            "tau": [0.0] * 3, "volts": [0.0] * 3})
    with pytest.raises(ProtoCodecError):
        STATE_PROTO.decode(b"\x0a\x05ab")        # a field cut short
    with SessionRecorder(tmp_path / "bad.mcap", META) as rec:
        with pytest.raises(InputError, match="phase"):
            rec.publish(REFERENCE, {"t": 0.0, "phase": 3})
        with pytest.raises(InputError, match="'t'"):
            rec.publish(REFERENCE, {"force": [0.0, 0.0, 1.0]})
        with pytest.raises(InputError, match="position"):
            rec.attach_ring(STATE, _Ring(np.zeros((1, 4))), (("t", 1), ("position", 3)))
    s = rec.close()
    assert s["complete"] and s["messages"][REFERENCE] == 0    # nothing written


# ------------------------------------------------------------------ Foxglove / mcap readers

def test_channels_use_the_well_known_encodings_and_mcap_protobuf_decodes_them(
        pair: dict) -> None:
    """talus.v3's three channels (v4's cycle: tests/test_recording_v4.py)."""
    sig = pair["sig"]
    with open(pair["protobuf-v3"], "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        by_topic = {c.topic: c for c in summary.channels.values()}
        for topic in (STATE, WRENCH, REFERENCE):
            ch = by_topic[topic]
            schema = summary.schemas[ch.schema_id]
            assert ch.message_encoding == MessageEncoding.Protobuf == "protobuf"
            assert schema.encoding == SchemaEncoding.Protobuf == "protobuf"
            assert schema.name == PROTOS[Encoding.PROTOBUF_V3][topic].name
            assert schema.name.startswith("talus.v3.")
            assert json.loads(ch.metadata[JSONSCHEMA_METADATA_KEY]) == CHANNELS[topic].schema
            assert ch.metadata[TIME_ORIGIN_NS_KEY] == str(START_WALL_NS)
        for topic in (EVENTS, METADATA):
            assert by_topic[topic].message_encoding == "json"
            assert summary.schemas[by_topic[topic].schema_id].encoding == "jsonschema"
        seen = {STATE: 0, WRENCH: 0, REFERENCE: 0}
        for _, channel, message, proto in reader.iter_decoded_messages(
                topics=list(seen)):
            k = seen[channel.topic]
            seen[channel.topic] += 1
            if k % 250:
                continue
            # The log time is the cycle's time; counts of µm, mN (the units in the wire
            # names), the DAC's codes.
            assert message.log_time == message.publish_time == \
                START_WALL_NS + round(sig["state"][k][0] * 1e6) * 1000
            assert not hasattr(proto, "t_us")
            if channel.topic == STATE:
                assert list(proto.q_um) == [round(v * 1e6) for v in sig["state"][k][1:4]]
                assert list(proto.volts_dac) == [volts_to_code(v)
                                                 for v in sig["state"][k][13:16]]
            elif channel.topic == WRENCH:
                assert proto.fz_mn == round(sig["wrench"][k][3] * 1e3)
            else:
                assert list(proto.force_mn) == [0, 0, round(sig["fz_ref"][k] * 1e3)]
        assert all(v == len(sig["state"]) for v in seen.values())


# ------------------------------------------------------------------ old recordings still read

def test_json_recordings_still_read_by_info_export_recover(pair: dict, tmp_path: Path,
                                                            capsys) -> None:
    for enc in ("json", "protobuf-f32", "protobuf-v2", "protobuf-v3", "protobuf"):
        path = pair[enc]
        assert talus_main(["record", "info", str(path)]) == 0
        info = json.loads(capsys.readouterr().out)
        assert info["complete"] and not info["corrupt"]
        assert info["messages"][STATE] == len(pair["sig"]["state"])
        messages, rinfo = recover(path)
        assert messages == read_recording(path) and rinfo["complete"]
        out = tmp_path / f"{enc}_state.csv"
        assert talus_main(["record", "export", str(path), "--out", str(out)]) == 0
        assert json.loads(capsys.readouterr().out)["rows"] == len(pair["sig"]["state"])
    # The same CSV columns from every encoding (the protobuf channel's JSON Schema says them).
    header = [(tmp_path / f"{e}_state.csv").read_text().splitlines()[0]
              for e in ("json", "protobuf-f32", "protobuf-v2", "protobuf-v3", "protobuf")]
    assert len(set(header)) == 1 and "qd_ref0" in header[0] and ",t," in header[0]
    # v3's and v4's t columns (rebuilt from the log time) are v2's t_us.
    rows = [(tmp_path / f"{e}_state.csv").read_text().splitlines()[1:]
            for e in ("protobuf-v2", "protobuf-v3", "protobuf")]
    assert [r.split(",")[:2] for r in rows[0]] == [r.split(",")[:2] for r in rows[1]] \
        == [r.split(",")[:2] for r in rows[2]]
    wrench = export_csv(pair["json"], WRENCH, tmp_path / "w.csv")
    assert wrench["rows"] == len(pair["sig"]["state"])


def test_report_reader_gives_the_same_figures_from_both_encodings(pair: dict) -> None:
    from reports.session_data import session_input_from_recording

    a = session_input_from_recording(pair["json"])
    for enc in ("protobuf-f32", "protobuf-v2", "protobuf-v3", "protobuf"):
        b = session_input_from_recording(pair[enc])
        assert a.figures is not None and b.figures is not None
        assert a.figures["samples"] == b.figures["samples"] == len(pair["sig"]["state"])
        # A figure of a difference (force error = reference - measured) moves by up to one
        # quantum with fixed point (half a quantum each): 1 mN, the largest quantum of v2
        # and v3; v4's: a force error 1/16 N (its forces' quantum).
        _close(a.figures, b.figures, f"{enc} figures",
               1e-6 if enc == "protobuf-f32" else 1 / 16 if enc == "protobuf" else 1e-3)


def _close(a: object, b: object, where: str, abs_tol: float = 1e-6) -> None:
    """Equal, floats within what the encodings move them: float32, relative 6e-8 per value;
    fixed point, half a quantum (0.5 mN on a 300 N force, 2e-6 relative; 0.5 µm on a 0.2 m
    stroke). The figures are sums, extremes and angles of them: 1e-5 relative or 1e-6
    absolute (a figure near 0) leaves a wide margin."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            _close(a[key], b[key], f"{where}.{key}", abs_tol)
    elif isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{where}[{i}]", abs_tol)
    elif isinstance(a, float) and isinstance(b, float) and math.isfinite(a):
        assert b == pytest.approx(a, rel=1e-5, abs=abs_tol), where
    else:
        assert a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b)), where


def test_a_killed_protobuf_recording_is_recovered(tmp_path: Path) -> None:
    """The crash path (a file without footer) reads protobuf chunks as JSON ones; the SIGKILL
    test of test_recording.py runs the whole thing in a child process."""
    sig = session_signals(1.0)
    path = tmp_path / "whole.mcap"
    record(path, sig, "protobuf", events=False, chunk_size=16 * 1024)   # many chunks
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    messages, info = recover(cut)
    assert not info["complete"]
    n = len(messages[STATE])
    assert 0 < n < len(sig["state"])
    assert [m["t"] for m in messages[STATE]] == [fixed(t, 1e-6) for t in sig["state"][:n, 0]]


# ------------------------------------------------------------------ size per hour

#: Issue 16's target for a 1 kHz session (state, wrench, reference and the rest), MB per hour.
TARGET_MB_PER_HOUR = 150.0


def test_size_per_hour_of_a_generated_10_s_recording(tmp_path: Path) -> None:
    """10 s of the session-like stream in both encodings, extrapolated to an hour.

    The measured figure is printed; the assertions are what the encoding guarantees whatever
    the noise: below half the JSON file. Issue 16's 150 MB/h is not reached on a noisy
    stream (the float32 noise of qd, tau, volts and the wrench does not compress: the closing
    note has the breakdown), so the bound asserted is the encoding's, not the target.
    """
    sig = session_signals(10.0, seed=1)
    sizes = {}
    for enc in ("protobuf", "json"):
        s = record(tmp_path / f"{enc}.mcap", sig, enc, events=True)
        sizes[enc] = s["bytes"] * 360 / 1e6          # 10 s → 1 h
    print(f"\nMB per hour at 1 kHz: protobuf {sizes['protobuf']:.0f}, json "
          f"{sizes['json']:.0f} (target {TARGET_MB_PER_HOUR:.0f})")
    assert sizes["protobuf"] < sizes["json"] / 2


def test_row_encoder_is_the_per_message_encoder() -> None:
    """The numpy block encoder and the one-message encoder write the same bytes (v3: the ring
    row's time column is skipped; v2: t_us first)."""
    rows = session_signals(0.05)["state"]
    names = [n for n, _ in STATE_LAYOUT.fields]
    for proto, size in ((STATE_PROTO, 5 * (2 + 12)), (STATE_PROTO_V2, 9 + 5 * (2 + 12))):
        enc = proto.row_encoder(STATE_LAYOUT.fields)(rows)
        for row, data in zip(rows, enc):
            msg = {"t": row[0]}
            for i, name in enumerate(names[1:]):
                msg[name] = row[1 + 3 * i:4 + 3 * i].tolist()
            assert data == proto.encode(msg)
            assert len(data) == proto.fixed_size == size
    enc = STATE_PROTO_V2.row_encoder(STATE_LAYOUT.fields)(rows)
    assert struct.unpack_from("<Bq", enc[0]) == (0x09, round(rows[0][0] * 1e6))


def test_volts_are_the_dac_codes_the_pci1720_driver_writes() -> None:
    """v3's ``volts_dac`` is ``rt.drivers.pci1720.volts_to_code`` of the command, halves and
    the range's ends included, in the ring encoder and the one-message encoder alike."""
    step = 20 / 4095
    volts = np.concatenate([np.linspace(-12.0, 12.0, 2001), -10 + (np.arange(-3, 4100) + 0.5)
                            * step, [-6.0, 6.0, 0.0, -0.0, 1e-12]])
    rows = np.zeros((len(volts), 16))
    rows[:, 13] = volts
    rows[:, 14] = -volts
    enc = STATE_PROTO.row_encoder(STATE_LAYOUT.fields)(rows)
    for v, data in zip(volts.tolist(), enc):
        code = struct.unpack_from("<3i", data, len(data) - 12)
        assert code[0] == volts_to_code(v) and code[1] == volts_to_code(-v)
        assert STATE_PROTO.decode(data)["volts"][:2] == [code_to_volts(code[0]),
                                                        code_to_volts(code[1])]
        msg = STATE_PROTO.encode({"q": [0.0] * 3, "qd": [0.0] * 3, "q_ref": [0.0] * 3,
                                  "tau": [0.0] * 3, "volts": [v, -v, 0.0]})
        assert msg == data


def test_the_loop_time_rebuilt_from_the_log_time_is_the_microsecond_time() -> None:
    """Whatever the time origin (an RT process up for days, a wall clock with ns digits),
    ``LoopClock`` gives back ``round(t × 1e6) / 1e6``, what v2's ``t_us`` held."""
    rng = np.random.default_rng(3)
    for origin_ns, loop_t0 in ((START_WALL_NS, 0.0), (1_764_103_456_789_012_345, 12.3456789),
                               (1_764_103_456_000_000_001, 345_678.901_234_567)):
        clock = LoopClock(origin_ns, loop_t0, 1e-6)
        t = loop_t0 + np.concatenate([np.arange(0, 3600, 0.001)[::997],
                                      rng.uniform(0, 3600, 2000)])
        for x in t.tolist():
            log_time = origin_ns + round((clock.quantize(x) - loop_t0) * 1e9)
            assert clock(log_time) == fixed(x, 1e-6)


#: A recording written by the float32 protobuf writer as it was on 2026-11-25 (main at
#: 3c13f86, ``tests.test_recording_encoding.record(path, session_signals(0.3, seed=7),
#: "protobuf", events=True)``): the previous encoding, made by the previous code.
PREVIOUS = Path(__file__).parent / "data" / "recording_protobuf_float32_2026-11-25.mcap"


#: A ``talus.v2`` recording (fixed point, ``t_us``, volts in mV) written by the writer of
#: 2026-11-25 before ``talus.v3`` (bde1a66, ``record(path, session_signals(0.3, seed=7),
#: "protobuf", events=True)``).
PREVIOUS_V2 = Path(__file__).parent / "data" / "recording_protobuf_v2_2026-11-25.mcap"


def test_a_talus_v2_recording_still_reads(tmp_path: Path, capsys) -> None:
    sig = session_signals(0.3, seed=7)
    assert talus_main(["record", "info", str(PREVIOUS_V2)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["complete"] and not info["corrupt"] and info["messages"][STATE] == 300
    data = read_recording(PREVIOUS_V2)
    for k in (0, 150, 299):
        row = sig["state"][k]
        assert data[STATE][k]["t"] == fixed(row[0], 1e-6)
        assert data[STATE][k]["volts"] == [fixed(v, 1e-3) for v in row[13:16]]
        assert data[WRENCH][k]["fz"] == fixed(sig["wrench"][k][3], 1e-3)
        assert data[REFERENCE][k]["t"] == fixed(row[0], 1e-6)
    out = tmp_path / "state.csv"
    assert talus_main(["record", "export", str(PREVIOUS_V2), "--out", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["rows"] == 300
    messages, rinfo = recover(PREVIOUS_V2)
    assert messages == data and rinfo["complete"]


def test_a_recording_of_the_previous_writer_still_reads(tmp_path: Path, capsys) -> None:
    sig = session_signals(0.3, seed=7)
    assert talus_main(["record", "info", str(PREVIOUS)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["complete"] and not info["corrupt"] and info["messages"][STATE] == 300
    data = read_recording(PREVIOUS)
    for k in (0, 150, 299):
        row = sig["state"][k]
        assert data[STATE][k]["t"] == row[0]
        assert data[STATE][k]["tau"] == [f32(v) for v in row[10:13]]
        assert data[WRENCH][k]["fz"] == f32(sig["wrench"][k][3])
    out = tmp_path / "state.csv"
    assert talus_main(["record", "export", str(PREVIOUS), "--out", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["rows"] == 300
    assert "qd_ref0" in out.read_text().splitlines()[0]
